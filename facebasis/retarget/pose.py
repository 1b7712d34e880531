"""Weak-perspective head pose: ``p ~= s Pi R q + t`` for rig points q (L, 3) seen at p (L, 2).

Scale s (pixels per rig unit), rotation R (3 x 3), image translation t (2,) and
Pi = [[1, 0, 0], [0, -1, 0]] (the rig's +y is the image's up; image y grows downwards). Closed-form
start (affine camera fit, rows orthonormalised by SVD), then Gauss-Newton on
(log s, rotation increment, t). Used by :mod:`.rigdrive` (the pose half of the model there).
"""

from __future__ import annotations

import numpy as np

#: the rig's +y up becomes the image's -y (down)
PI = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def rotation_from_vector(w) -> np.ndarray:
    """Rodrigues: rotation vector (3,) -> (3, 3)."""
    w = np.asarray(w, np.float64)
    th = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / th ** 2 * (K @ K)


def rotation_to_vector(R) -> np.ndarray:
    """Inverse Rodrigues: (3, 3) -> rotation vector (3,) (angle in radians times the axis)."""
    R = np.asarray(R, np.float64)
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-8:
        return v / 2.0
    if np.pi - th < 1e-6:
        w, V = np.linalg.eigh((R + R.T) / 2.0)
        return V[:, -1] * th
    return v * th / (2.0 * np.sin(th))


def project_landmarks(points, scale, rotation, translation) -> np.ndarray:
    """Weak perspective ``s Pi R q + t`` of points (..., L, 3) -> (..., L, 2); scale (...,),
    rotation (..., 3, 3), translation (..., 2)."""
    q = np.asarray(points, np.float64)
    R = np.asarray(rotation, np.float64)
    s = np.asarray(scale, np.float64)
    u = np.einsum("...ij,...lj->...li", PI @ R, q)
    return s[..., None, None] * u + np.asarray(translation, np.float64)[..., None, :]


def fit_pose_affine(q, p) -> tuple[float, np.ndarray, np.ndarray]:
    """Closed-form weak-perspective pose of 3D points q (L, 3) seen at p (L, 2): least-squares affine
    camera, rows orthonormalised by SVD. Returns (s, R (3, 3), t (2,))."""
    qc, pc = q - q.mean(0), p - p.mean(0)
    M, *_ = np.linalg.lstsq(qc, pc, rcond=None)          # p ~= q M: M (3, 2)
    M = M.T                                              # (2, 3) ~= s Pi R
    U, S, Vt = np.linalg.svd(M, full_matrices=False)
    rows = U @ Vt                                        # nearest matrix with orthonormal rows
    s = float(S.mean())
    r1, r2 = rows[0], -rows[1]                           # undo Pi
    R = np.stack([r1, r2, np.cross(r1, r2)])
    t = p.mean(0) - s * (PI @ R @ q.mean(0))
    return s, R, t


def whiten(M, sqrtw):
    """Apply per-landmark 2 x 2 weights ``sqrtw`` (L, 2, 2) to a stacked (2L,) or (2L, m) array
    (None: unchanged)."""
    if sqrtw is None:
        return M
    M = np.asarray(M)
    L = len(sqrtw)
    if M.ndim == 1:
        return np.einsum("lij,lj->li", sqrtw, M.reshape(L, 2)).reshape(-1)
    return np.einsum("lij,ljm->lim", sqrtw, M.reshape(L, 2, -1)).reshape(2 * L, -1)


def fit_pose_gn(q, p, s, R, t, iterations: int = 4, sqrtw=None) -> tuple[float, np.ndarray, np.ndarray, float]:
    """Gauss-Newton on (log s, rotation increment w (R <- exp(w) R), t) for ``s Pi R q + t ~= p``.

    q : (L, 3); p : (L, 2); sqrtw : optional (L, 2, 2) per-landmark square-root weights of the
    residual (:func:`contour_weights`). Returns (s, R, t, rms residual in pixels, unweighted).
    """
    for _ in range(iterations):
        u = q @ R.T                                      # (L, 3) rotated points
        r = whiten((s * (u @ PI.T) + t - p).reshape(-1), sqrtw)         # (2L,)
        J = whiten(pose_jacobian(u) * np.array([s, s, s, s, 1.0, 1.0]), sqrtw)
        H = J.T @ J
        H[np.diag_indices(6)] *= 1.0 + 1e-9
        step = -np.linalg.solve(H + 1e-12 * np.eye(6), J.T @ r)
        s = s * float(np.exp(np.clip(step[0], -0.5, 0.5)))
        R = rotation_from_vector(step[1:4]) @ R
        t = t + step[4:]
        if np.abs(step).max() < 1e-10:
            break
    res = s * (q @ R.T @ PI.T) + t - p
    return s, R, t, float(np.sqrt(np.mean(np.sum(res ** 2, axis=1))))


def pose_jacobian(u) -> np.ndarray:
    """(2L, 6) derivative of ``Pi u + t`` (rig units, s = 1) for rotated points u (L, 3) with respect
    to (log s, rotation increment w with R <- exp(w) R, t)."""
    L = len(u)
    J = np.zeros((L, 2, 6))
    J[:, 0, 0], J[:, 1, 0] = u[:, 0], -u[:, 1]
    # d(Pi exp(w) u)/dw = Pi (-[u]x): x-row [0, u3, -u2], y-row [u3, 0, -u1] (with Pi's sign)
    J[:, 0, 2], J[:, 0, 3] = u[:, 2], -u[:, 1]
    J[:, 1, 1], J[:, 1, 3] = u[:, 2], -u[:, 0]
    J[:, 0, 4] = 1.0
    J[:, 1, 5] = 1.0
    return J.reshape(-1, 6)



def contour_weights(p, contour, slide: float, n_landmarks: int | None = None) -> np.ndarray | None:
    """Per-landmark square-root weights (L, 2, 2) that let contour landmarks slide along the contour.

    A silhouette landmark (the jaw line of the 68-point iBUG set, points 0-16) marks where the
    face's outline is, not a fixed point of the face: as the head turns it slides along the outline,
    and a detector places it along the outline with much larger error than across it. Its residual
    is therefore measured across the contour in full and along it with weight ``slide``
    (``W_l = n n^T + slide t t^T``, t the unit tangent from the neighbouring contour landmarks of
    the observation ``p`` (L, 2), n the normal); other landmarks keep the identity. ``slide`` 1 or
    an empty ``contour``: None (plain least squares).
    """
    idx = np.asarray(contour, np.int64)
    if len(idx) < 3 or slide >= 1.0:
        return None
    L = len(p) if n_landmarks is None else n_landmarks
    c = np.asarray(p, np.float64)[idx]
    tan = np.gradient(c, axis=0)                         # central differences, one-sided at the ends
    tan /= np.linalg.norm(tan, axis=1, keepdims=True) + 1e-300
    W = np.tile(np.eye(2), (L, 1, 1))
    W[idx] = (np.eye(2)[None] - tan[:, :, None] * tan[:, None, :]) + np.sqrt(slide) * tan[:, :, None] * tan[:, None, :]
    return W


#: former private name (kept for callers of the old module)
_pose_jacobian = pose_jacobian

__all__ = ["PI", "whiten", "contour_weights", "rotation_from_vector", "rotation_to_vector", "project_landmarks", "fit_pose_affine", "fit_pose_gn",
           "pose_jacobian"]
