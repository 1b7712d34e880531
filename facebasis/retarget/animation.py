"""Animated glTF 2.0 (``.glb``): one mesh with morph targets plus a glTF animation of their weights
and, for a retargeted rig, of the head's rotation and translation.

The file holds what :func:`facebasis.geometry.gltf.gltf_document` writes (positions in metres from
the source ``unit``, normals, the template's UVs and materials when a layout is given, one morph
target per shape, names in ``mesh.extras.targetNames``), and one animation of node 0 with LINEAR
samplers whose input accessor holds the key times (seconds, ``frame / fps``):

* ``weights``: per key one weight per morph target (``count = T * k``); Blender's importer turns
  it into shape-key fcurves, three.js plays it with an ``AnimationMixer``;
* ``rotation`` / ``translation`` (optional): the head pose solved by ``retarget``
  (:func:`pose_channels`).

A vertex animation (``animate3d``: a mesh moved frame by frame) is written compactly by
:func:`compact_vertex_animation`: morph targets over a small PCA basis of the per-frame
displacements, not one target per frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import InputError
from ..geometry.gltf import DEFAULT_UNIT, _finish, glb_container, gltf_document, unit_scale


def animated_glb_bytes(neutral, faces, targets, names: Sequence[str], times, weights, *,
                       name: str = "face", animation_name: str = "capture", unit: str = DEFAULT_UNIT,
                       layout=None, rotation=None, translation=None, extras: dict | None = None) -> bytes:
    """Serialise a morph-target mesh with a weight (and optionally node pose) animation as GLB.

    Parameters
    ----------
    neutral : (n, 3) rest positions (source unit); faces : (m, 3) triangles
    targets : (k, n, 3) morph-target deltas (source unit); names : k target names
    times : (T,) strictly increasing key times in seconds
    weights : (T, k) morph weights per key (any finite values; the rig and mesh writers of this
        package keep them in [0, 1])
    unit : source unit of ``neutral`` and ``targets`` (written in metres)
    layout : the template OBJ's layout (UVs, materials) or None
    rotation : (T, 4) node rotations (x, y, z, w) or None; translation : (T, 3) metres or None
    """
    V = np.asarray(neutral, np.float32)
    F = np.asarray(faces)
    D = np.asarray(targets, np.float32)
    t = np.asarray(times, np.float64).reshape(-1)
    W = np.asarray(weights, np.float64)
    k = len(D)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise InputError(f"animated glTF: expected neutral (n, 3) and faces (m, 3), found {V.shape}, {F.shape}")
    if D.shape != (k, len(V), 3) or len(names) != k:
        raise InputError(f"animated glTF: expected {len(names)} targets of shape ({len(V)}, 3), found {D.shape}")
    if W.shape != (len(t), k) or len(t) < 1:
        raise InputError(f"animated glTF: expected weights of shape ({len(t)}, {k}), found {W.shape}")
    if not (np.isfinite(W).all() and np.isfinite(t).all() and np.isfinite(D).all() and np.isfinite(V).all()):
        raise InputError("animated glTF: expected finite positions, targets, times and weights, found NaN/inf")
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        raise InputError("animated glTF: expected strictly increasing key times")
    anim = {"times": t, "weights": W, "rotation": rotation, "translation": translation, "name": animation_name}
    doc, buf, _ = gltf_document(neutral, faces, targets, names, unit=unit, layout=layout, name=name,
                                weights=W[0] if k else None, animation=anim, extras=extras)
    return glb_container(_finish(doc, buf), buf.chunks)


def frame_times(n_frames: int, fps: float) -> np.ndarray:
    """Key times ``frame / fps`` in seconds, (T,)."""
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"fps: expected a positive number, found {fps}")
    return np.arange(int(n_frames), dtype=np.float64) / float(fps)


def pose_channels(scale, rotation, translation, unit: str = DEFAULT_UNIT) -> tuple[np.ndarray, np.ndarray]:
    """glTF node rotation and translation of a weak-perspective head pose (:mod:`.pose`).

    The pose maps rig points q to pixels ``p = s Pi R q + t`` (``Pi`` drops z and flips y, image y
    down). R (rig axes to camera axes: x right, y up, z towards the camera) is glTF's frame too (y up,
    a camera looking down -z), so the node rotation is R as a unit quaternion (x, y, z, w), signs
    chosen so consecutive keys are on the same side (LINEAR keys then turn the short way). The
    translation is the rig origin's image motion since frame 0 in rig units at each frame's own
    scale, in metres: ``x = u (t_x - t_x[0]) / s``, ``y = -u (t_y - t_y[0]) / s``, ``z = 0``
    (``u`` metres per rig unit; a weak-perspective camera sees no depth: the change of ``s``, the
    head nearing or leaving the camera, is not turned into motion).

    Parameters
    ----------
    scale : (T,) pixels per rig unit; rotation : (T, 3, 3) or (T, 3) rotation vectors (radians);
    translation : (T, 2) pixels; unit : the rig's unit

    Returns
    -------
    quaternions (T, 4) (x, y, z, w), translations (T, 3) metres
    """
    from scipy.spatial.transform import Rotation

    s = np.asarray(scale, np.float64).reshape(-1)
    R = np.asarray(rotation, np.float64)
    t = np.asarray(translation, np.float64)
    T = len(s)
    if R.shape not in ((T, 3, 3), (T, 3)) or t.shape != (T, 2):
        raise InputError(f"head pose: expected scale (T,), rotation (T, 3, 3) or (T, 3) and translation (T, 2), found "
                         f"{s.shape}, {R.shape}, {t.shape}")
    if not (np.isfinite(s).all() and (s > 0).all() and np.isfinite(R).all() and np.isfinite(t).all()):
        raise InputError("head pose: expected finite positive scales and finite rotations and translations")
    rot = Rotation.from_matrix(R) if R.ndim == 3 else Rotation.from_rotvec(R)
    q = rot.as_quat()  # (x, y, z, w)
    flip = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0, -1.0, 1.0))
    q[1:] *= flip[:, None]
    metres = unit_scale(unit, "unit")
    move = np.zeros((T, 3))
    move[:, 0] = metres * (t[:, 0] - t[0, 0]) / s
    move[:, 1] = -metres * (t[:, 1] - t[0, 1]) / s
    return q, move


def write_rig_animation(path, rig, weights, fps: float, *, unit: str = DEFAULT_UNIT, pose=None,
                        layout=None) -> Path:
    """The rig's morph targets and an animation of its weights (T, k) at ``fps``, written atomically.

    ``pose``: None, or (scale (T,), rotation (T, 3, 3), translation (T, 2) pixels) of the head
    (a ``RetargetResult``'s fields), animated as the node's rotation and translation
    (:func:`pose_channels`)."""
    W = np.asarray(weights, np.float64)
    if W.ndim != 2 or W.shape[1] != rig.n_shapes:
        raise InputError(f"rig animation: expected weights of shape (T, {rig.n_shapes}), found {W.shape}")
    rotation = translation = None
    extras = {}
    if pose is not None:
        rotation, translation = pose_channels(*pose, unit=unit)
        extras["headPose"] = ("node rotation = the solved head rotation; node translation = the head's image "
                              "motion since frame 0 in metres at each frame's scale, z = 0 (weak perspective)")
    path = Path(path)
    atomic_write_bytes(path, animated_glb_bytes(rig.neutral, rig.faces, rig.deltas, rig.names,
                                                frame_times(len(W), fps), W, unit=unit,
                                                layout=layout if layout is not None else rig.layout,
                                                rotation=rotation, translation=translation, extras=extras))
    return path


# ---------------------------------------------------------------------- vertex animation, compact
#: largest vertex error of a compact vertex animation, metres (1 mm, 1/200 of a face's height; on
#: a real 765-frame webcam clip driving the built-in face (head motion included, 6.7 cm at most)
#: the mean vertex error is then about 0.03 mm)
VERTEX_TOLERANCE_M = 1e-3
#: most PCA components kept (the error reached with them is reported when the bound is not met)
MAX_BASIS = 96


@dataclass(frozen=True)
class CompactMotion:
    """A vertex animation as morph targets over a small basis.

    Positions of frame f: ``rest + targets[0] * weights[f, 0] + sum_j targets[j] weights[f, j]``
    with every weight in [0, 1]: target 0 ("offset", weight 1 on every frame) is the mean
    displacement plus the lowest coefficient of each component; targets 1..r are the r principal
    components of the displacements, each scaled by its coefficient range.

    Attributes
    ----------
    targets : (r + 1, n, 3); names : r + 1; weights : (T, r + 1)
    max_error : largest vertex distance to the frames (source unit); tolerance : the bound aimed at
    rank : r; singular_values : of the centred displacements (T,) (or the ones computed)
    """

    targets: np.ndarray
    names: tuple
    weights: np.ndarray
    max_error: float
    tolerance: float
    rank: int
    singular_values: np.ndarray


def _motion_basis(Xc: np.ndarray, cap: int, seed: int):
    """Right singular vectors (R, 3n) float32 (R <= cap, numerically nonzero ones only) and the
    singular values of the centred displacements ``Xc`` (T, 3n) float32: exact through the T x T
    Gram matrix for T <= 256, else a seeded randomized range finder with one power iteration
    (Halko et al. 2011, alg. 4.3-4.4) and the small factor's k x k Gram matrix."""
    T = len(Xc)
    if T <= 256:
        ev, U = np.linalg.eigh((Xc @ Xc.T).astype(np.float64))
        order = np.argsort(ev)[::-1]
        sv = np.sqrt(np.maximum(ev[order], 0.0))
        keep = sv[:cap] > sv[0] * 1e-6 if sv[0] > 0 else np.zeros(cap, bool)
        Vt = ((U[:, order[:cap]][:, keep].T @ Xc) / sv[:cap][keep, None]).astype(np.float32)
    else:
        rng = np.random.default_rng(seed)
        Y = Xc @ rng.standard_normal((Xc.shape[1], cap + 10)).astype(np.float32)
        for _ in range(1):  # a power iteration, orthonormalised on the small (T, k) side only
            Q, _ = np.linalg.qr(Y)
            Y = Xc @ (Xc.T @ Q)
        Q, _ = np.linalg.qr(Y)
        B = Q.T @ Xc  # (k, 3n): its right singular vectors from the k x k Gram matrix
        ev, W = np.linalg.eigh((B @ B.T).astype(np.float64))
        order = np.argsort(ev)[::-1][:cap]
        sv = np.sqrt(np.maximum(ev[order], 0.0))
        keep = sv > (sv[0] * 1e-6 if len(sv) and sv[0] > 0 else np.inf)
        Vt = (W[:, order[keep]].T.astype(np.float32) @ B) / sv[keep, None].astype(np.float32)
    return np.ascontiguousarray(Vt, dtype=np.float32), sv


def _smallest_rank(Xc: np.ndarray, Vt: np.ndarray, C: np.ndarray, n: int, tolerance: float) -> int:
    """The fewest leading components r of the basis ``Vt`` (R, 3n) whose reconstruction
    ``C[:, :r] Vt[:r]`` keeps every vertex of every frame of ``Xc`` (T, 3n) within ``tolerance``
    (R when none does): bisection on a subset of frames (every 8th and the 64 with the most residual
    energy), then on every frame above it if the full check fails (see
    :func:`compact_vertex_animation`)."""
    T = len(Xc)
    energy = np.einsum("ij,ij->i", Xc, Xc, dtype=np.float64)
    cum = np.cumsum(np.square(C, dtype=np.float64), axis=1)

    def error(r: int, frames=None) -> float:
        idx = np.arange(T) if frames is None else frames
        worst = 0.0
        for a in range(0, len(idx), 128):  # frames in blocks: memory stays at 128 frames
            f = idx[a:a + 128]
            E = Xc[f] - C[f, :r] @ Vt[:r]
            worst = max(worst, float(np.sqrt(np.einsum("fvc,fvc->fv", *(E.reshape(len(f), n, 3),) * 2).max())))
        return worst

    def subset(r: int) -> np.ndarray:
        resid = energy - (cum[:, r - 1] if r else 0.0)
        top = np.argsort(resid)[-64:]
        return np.union1d(top, np.arange(0, T, 8))

    R = len(Vt)
    lo, hi = -1, R  # on the subset: error(lo) > tolerance, hi passes (R taken as passing)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if error(mid, subset(mid)) <= tolerance:
            hi = mid
        else:
            lo = mid
    r, err = hi, error(hi)
    if err > tolerance and r < R:  # the subset missed a frame: bisection on every frame above r
        lo, hi, err_hi = r, R, error(R)
        if err_hi <= tolerance:
            while hi - lo > 1:
                mid = (lo + hi) // 2
                e = error(mid)
                if e <= tolerance:
                    hi, err_hi = mid, e
                else:
                    lo = mid
        r = hi
    return r


def compact_vertex_animation(rest, frames, tolerance: float, max_basis: int = MAX_BASIS,
                             seed: int = 0) -> CompactMotion:
    """PCA of the per-frame displacements ``frames - rest`` with the fewest components r whose
    reconstruction keeps every vertex of every frame within ``tolerance`` (source unit), at most
    ``max_basis`` (then the error reached is reported in ``max_error``).

    The basis is the right singular vectors of the centred displacement matrix X (T, 3n), float32
    (exact SVD through the T x T Gram matrix for T <= 256, else a seeded randomized range finder
    with one power iteration, Halko et al. 2011, alg. 4.3-4.4, and the small factor's singular
    vectors from its k x k Gram matrix); coefficients are the exact projections
    ``(X - mean) V_r^T``, so the reported error is the error of the written animation (float32
    storage aside). r is found by bisection on the largest vertex error measured on a subset of
    frames (every 8th and the 64 with the most residual energy ``|X_f|^2 - |C_f,:r|^2``), which can
    only under-estimate it, then checked on every frame (bisection on all frames above it if the
    check fails), so r is the smallest for which the error over all frames meets the bound.

    Parameters
    ----------
    rest : (n, 3); frames : (T, n, 3); tolerance : > 0, source unit
    """
    rest = np.asarray(rest, np.float64)
    P = np.asarray(frames)
    if P.ndim != 3 or P.shape[1:] != rest.shape:
        raise InputError(f"vertex animation: expected frames (T, {len(rest)}, 3), found {P.shape}")
    if not np.isfinite(P).all():
        raise InputError("vertex animation: expected finite frames, found NaN/inf")
    if not tolerance > 0:
        raise InputError(f"vertex animation: expected a tolerance > 0, found {tolerance}")
    T, n = P.shape[:2]
    X = (np.asarray(P, np.float32) - rest.astype(np.float32)).reshape(T, -1)
    mean = X.mean(0, dtype=np.float64).astype(np.float32)
    Xc = X - mean
    del X
    Vt, sv = _motion_basis(Xc, int(min(max_basis, T, 3 * n)), seed)
    C = Xc @ Vt.T  # (T, R) exact projections
    r = _smallest_rank(Xc, Vt, C, n, tolerance)
    C, B = C[:, :r].astype(np.float64), Vt[:r].astype(np.float64).reshape(r, n, 3)
    base = rest + mean.astype(np.float64).reshape(n, 3)
    err = 0.0  # the error reported: of the written basis, in float64, on every frame
    for a in range(0, T, 128):
        E = np.asarray(P[a:a + 128], np.float64) - base - np.tensordot(C[a:a + 128], B, axes=(1, 0))
        err = max(err, float(np.sqrt(np.einsum("fvc,fvc->fv", E, E).max())))
    cmin, cmax = C.min(0), C.max(0)
    span = np.where(cmax - cmin > 0, cmax - cmin, 1.0)
    offset = (mean.astype(np.float64).reshape(n, 3) + np.tensordot(cmin, B, axes=(0, 0)))[None]
    targets = np.concatenate([offset, B * span[:, None, None]])
    weights = np.concatenate([np.ones((T, 1)), (C - cmin) / span], axis=1)
    names = ("offset",) + tuple(f"motion{j:02d}" for j in range(r))
    return CompactMotion(targets, names, weights, err, float(tolerance), r, np.asarray(sv, np.float64))


def vertex_animation_glb_bytes(rest, faces, frames, times, *, unit: str = DEFAULT_UNIT,
                               tolerance_m: float = VERTEX_TOLERANCE_M, max_basis: int = MAX_BASIS,
                               layout=None, name: str = "face") -> tuple[bytes, CompactMotion]:
    """A vertex animation (frames (T, n, 3) of the mesh ``rest`` (n, 3), ``faces``) as GLB over a
    compact morph basis (:func:`compact_vertex_animation`, bound ``tolerance_m`` metres); returns
    (bytes, the basis). The bound and the error reached are recorded in ``asset.extras``."""
    metres = unit_scale(unit, "unit")
    motion = compact_vertex_animation(rest, frames, tolerance_m / metres, max_basis)
    extras = {"vertexAnimation": {"basis": motion.rank, "maxVertexErrorMetres": motion.max_error * metres,
                                  "toleranceMetres": tolerance_m,
                                  "scheme": "PCA of the per-frame displacements; weights in [0, 1]; "
                                            "target 'offset' has weight 1 on every frame"}}
    data = animated_glb_bytes(rest, faces, motion.targets, motion.names, times, motion.weights, unit=unit,
                              layout=layout, name=name, extras=extras)
    return data, motion


__all__ = ["animated_glb_bytes", "frame_times", "pose_channels", "write_rig_animation", "CompactMotion",
           "compact_vertex_animation", "vertex_animation_glb_bytes", "VERTEX_TOLERANCE_M", "MAX_BASIS"]
