"""Depth of the rest face: an in-plane landmark offset lifted onto the rig's skin.

The static offset ``delta_l`` of :mod:`.calibrate` (the person's rest face against the rig's neutral)
is seen in the image only: a frame at pose (s, R) shows ``s Pi R delta_l``, and carrying its image
residual ``r_l`` back into the rig frame gives ``d_l = R^T Pi^T r_l / s``, the offset in the plane
facing that frame's camera. Any ``delta_l = d_l + alpha v`` along the frame's viewing direction
``v = R^T e_z`` shows the same image; the in-plane choice (alpha = 0) is exact at that frame's head
orientation and wrong as the head turns away from it: a rest face measured on a head turned by -13
degrees, used on frames turned by +5, leaves a residual of ``s |delta_z| sin(18 deg)`` per landmark
that the expression shapes take (measured: jawLeft 0.19 on the calm frames of cap12's dlib cut from
20 s, :mod:`problems.rest_cuts`).

The depth comes from the skin: a landmark convention that differs from the rig's landmark vertex (a
brow point a little higher, a lip corner a little further out) slides the point *along* the face,
and a face shape that differs from the rig's mostly as well at the landmarks the image can see (the
visible part of a change along the normal is what a frame shows of it). So the offset is taken in
the tangent plane of the rig's neutral at the landmark vertex, ``n_l . delta_l = 0`` (n_l the unit
vertex normal, :func:`landmark_normals`):

    alpha = -(n_l . d_l) (n_l . v) / ((n_l . v)^2 + eps)                                   (T1)

the least-squares solution of ``n_l . (d_l + alpha v) = 0`` with a Tikhonov term ``eps alpha^2``:
exact where the skin faces the camera (n_l . v ~ 1, the brows, nose, lips), and damped to the
in-plane offset where the view grazes the skin (the jaw line's silhouette points, n_l . v -> 0, where
the tangent plane holds the viewing direction and the depth is not determined). :data:`TANGENT_EPS`
= 0.1 halves alpha at 72 degrees between the normal and the view. Each pilot frame's offset is lifted
with its own rotation before the median over frames, so frames at different head orientations agree
on one 3D offset when the tangent assumption holds.
"""

from __future__ import annotations

import numpy as np

#: Tikhonov weight eps of (T1): alpha is halved where (n . v)^2 = eps (72 degrees between normal and view)
TANGENT_EPS = 0.1
#: rest_depth modes of :class:`.rigdrive.RigRetargeter`: "tangent" (T1) or "none" (in-plane, depth 0)
REST_DEPTH_MODES = ("tangent", "none")


def landmark_normals(vertices, faces, indices) -> np.ndarray | None:
    """Area-weighted unit vertex normals (L, 3) of the landmark vertices ``indices`` (L,) of a mesh
    ``vertices`` (n, 3), ``faces`` (m, 3); None for a mesh without triangles. A landmark vertex that
    no triangle touches (or whose triangles cancel) gets the zero vector (no depth: (T1) gives alpha 0)."""
    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces, np.int64).reshape(-1, 3)
    if len(F) == 0:
        return None
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])        # (m, 3), twice the area
    vn = np.zeros_like(V)
    for c in range(3):                                                        # the three corners
        np.add.at(vn, F[:, c], fn)
    n = vn[np.asarray(indices, np.int64)]
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def lift_offsets(offsets, rotations, normals, eps: float | None = None, flat: bool = False) -> np.ndarray:
    """In-plane rig-frame offsets (F, L, 3) (``R_f^T Pi^T r / s_f``) moved along each frame's viewing
    direction ``v_f = R_f^T e_z`` onto the tangent plane of the landmark normals (L, 3) by (T1);
    rotations (F, 3, 3); eps: :data:`TANGENT_EPS` if None. NaN offsets (lost landmarks) stay NaN.
    ``normals`` None: the offsets as given, their rig-frame depth set to 0 if ``flat`` (no depth)."""
    d = np.asarray(offsets, np.float64)
    if normals is None:
        return np.concatenate([d[..., :2], np.zeros_like(d[..., 2:])], -1) if flat else d
    n = np.asarray(normals, np.float64)
    eps = TANGENT_EPS if eps is None else float(eps)
    v = np.asarray(rotations, np.float64)[:, 2, :]                               # (F, 3): R^T e_z
    nv = v @ n.T                                                                  # (F, L)
    alpha = -np.einsum("flc,lc->fl", d, n) * nv / (nv ** 2 + eps)
    return d + alpha[:, :, None] * v[:, None, :]


def rest_offset(offsets, rotations, normals) -> np.ndarray:
    """The rest offset (L, 3) of the rest frames' in-plane offsets (F, L, 3) (NaN: lost) at rotations
    (F, 3, 3): the landmark-wise median of the offsets lifted by (T1) (normals (L, 3)); normals None:
    the median of their rig-frame x, y with depth 0 (the model before this module)."""
    return np.nan_to_num(np.nanmedian(lift_offsets(offsets, rotations, normals, flat=True), axis=0))


__all__ = ["landmark_normals", "lift_offsets", "rest_offset", "TANGENT_EPS", "REST_DEPTH_MODES"]
