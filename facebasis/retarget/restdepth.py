"""Depth of the rest face: an in-plane landmark offset lifted onto the rig's skin.

The rest face of :func:`.calibrate.calibrate_rest` is a static offset ``delta_l`` of each landmark
from the rig's neutral. A frame at pose (s, R) shows only ``s Pi R delta_l``: carrying its image
residual ``r_l`` back into the rig frame gives ``d_l = R^T Pi^T r_l / s``, the offset in the plane
facing that frame's camera, and any ``delta_l = d_l + alpha v`` along the frame's viewing direction
``v = R^T e_z`` shows the same image (to first order under perspective). The in-plane choice (alpha = 0,
then the rig-frame depth dropped: the model before this module; dropping the depth changes the image by
about ``d tan(theta) sin(theta)``, 5% at 13 degrees) holds near the head orientation of the frames it
was measured on and not as the head turns away: a rest face measured on a head turned by -13 degrees and used on frames
turned by +5 leaves a residual the expression shapes take (measured on the dlib cut of cap12 from 20 s,
:mod:`problems.rest_cuts`: its calm frames at yaw -12.8 degrees against +6.2 over the cut read as
jawLeft 0.186).

The depth comes from the skin. A detector's landmark convention that differs from the rig's landmark
vertex (a brow point a little higher, a lip corner a little further out) slides the point *along* the
face, in the tangent plane at the vertex, ``n_l . delta_l = 0`` (n_l the unit vertex normal of the
rig's neutral, :func:`landmark_normals`); a face shape of its own moves it along the normal as well.
With a Gaussian prior ``delta_l ~ N(0, sigma_t^2 (I - n n^T) + sigma_n^2 n n^T)`` (tangent slides
larger than normal ones), the most probable offset showing ``d_l`` is

    alpha = -(n_l . d_l) (n_l . v) / ((n_l . v)^2 + eps),  eps = sigma_n^2 / (sigma_t^2 - sigma_n^2)   (T1)

eps -> 0 the pure tangent plane, eps -> inf the in-plane offset. Where the skin faces the camera
(brows, nose, outer lips) it lifts ``d_l`` into the tangent plane; only where the view grazes the skin
(n . v -> 0) does it leave ``d_l`` in-plane: the depth gain |n.v| / ((n.v)^2 + eps) peaks at 1/(2 sqrt eps)
= 1.58 at 72 degrees between normal and view, so ICT's jaw-line landmarks at a frontal view (n_z 0.19-0.41)
get the largest depth, not the least. :data:`TANGENT_EPS` = 0.1 (sigma_t ~ 3.3 sigma_n), chosen on the cut
reported below.

The lift is right for a landmark convention and wrong for a face that differs from the rig along the
normal: for an offset h n it returns h (n - v / (n . v)), a depth error h / (n . v) against the flat
model's ~h (n . v) (review of this module: a nose 0.5 deeper on the built-in face, residual 0.34 -> 0.70 px;
ICT identities 1-3 at 15 degrees of head motion, weight error 0.0151 / 0.0208 / 0.0281 -> 0.0182 / 0.0243 /
0.0228). :func:`.calibrate.calibrate_rest` therefore builds the rest face both ways and keeps the one whose
check frames (several head orientations) fit better: on those ICT identities it keeps the flat one (weight
errors as without the lift), on the dlib cut below the lifted one. Each rest frame's offset is lifted with
its own rotation before the landmark-wise median (:func:`rest_offset`), so frames at different head
orientations agree on one 3D offset.

Measured (reports/retarget/rest_cuts.md; ``rest_depth="none"`` is the *previous* variant): the dlib
cut of cap12 from 20 s 0.186 -> 0.136 (jawLeft), L/R 0.158 -> 0.138, residual 1.966 -> 1.942 px;
tried and worse there: eps 0.3 or 1 and a depth estimated from the frames' own rotations (least
squares over the rest frames with a N(0, mean |d|^2) prior on the depth): the start's rest face then
passes the 2% residual gate of :func:`.calibrate.calibrate_rest` but the residual over the cut rises
to 2.95-3.09 px (weights small by shrinkage, as without the gate). Limits: on ICT's random identities
(pure 3D face shape, no landmark convention; ``problems.bench_retarget``'s identity table) the offset
is mostly along the normal and (T1) costs a little (weight error 0.0112 -> 0.0119 on identity 1, 200
frames); the quantile baseline's residual part and the first-frame neutral keep in-plane offsets (from
one view the tangent lift measured worse: 0.0099 -> 0.0110). What is left on the turned calm frames
of that cut is the jaw line (5.7 px rms against 3.3 over the cut): a silhouette, where the face's
outline slides over the skin as the head turns, which no fixed offset of a vertex reproduces.
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
