"""What the landmarks can see: how well a rig's landmark vertices determine each blendshape.

The landmark Jacobian (frontal view, neutral pose) of the projected landmarks with respect to the
weights and the weak-perspective pose (:mod:`.pose`); per shape its landmark motion, the part of it
no other shape or pose change can produce, and its most parallel other shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.rig import Rig
from .pose import PI, pose_jacobian


@dataclass(frozen=True)
class Identifiability:
    """How well the landmarks determine each shape (frontal view, neutral pose).

    Attributes
    ----------
    names : k shape names
    motion : (k,) rms landmark motion per unit weight (rig units); ~0 means the landmarks do not
        see the shape at all
    independence : (k,) ``||(I - P_others) J_i|| / ||J_i||``: the part of the shape's landmark motion
        that no combination of the other shapes and the pose (scale, rotation, translation) can
        produce; ~0 means it cannot be told apart (without bounds and exclusive pairs)
    closest : (k,) name of the other shape whose landmark motion is most parallel
    cosine : (k,) signed cosine with it (-1: exactly opposite, e.g. mouthLeft / mouthRight)
    singular_values : singular values of the column-normalised landmark Jacobian [shapes | pose]
    """

    names: tuple[str, ...]
    motion: np.ndarray
    independence: np.ndarray
    closest: tuple[str, ...]
    cosine: np.ndarray
    singular_values: np.ndarray

    def weak(self, motion_tol: float = 0.02, independence_tol: float = 0.1) -> list[str]:
        """Shapes the landmarks see too little of, or cannot separate from the others/pose."""
        return [n for n, m, i in zip(self.names, self.motion, self.independence)
                if m < motion_tol or i < independence_tol]


def landmark_jacobian(rig: Rig, indices) -> np.ndarray:
    """(2L, k + 6) Jacobian of the projected landmarks (frontal, s = 1) with respect to the weights
    and the pose (log s, rotation vector, t), at the neutral."""
    idx = np.asarray(indices, np.int64)
    D = rig.deltas[:, idx]                         # (k, L, 3)
    Jw = np.einsum("ij,klj->lik", PI, D).reshape(-1, rig.n_shapes)
    Jp = pose_jacobian(rig.neutral[idx])
    return np.concatenate([Jw, Jp], axis=1)


def identifiability(rig: Rig, indices) -> Identifiability:
    """Which shapes the landmarks can tell apart (see :class:`Identifiability`)."""
    J = landmark_jacobian(rig, indices)
    k = rig.n_shapes
    L = len(indices)
    norms = np.linalg.norm(J, axis=0)
    motion = norms[:k] / np.sqrt(L)
    Jn = J / np.where(norms > 0, norms, 1.0)
    indep = np.zeros(k)
    for i in range(k):                 # k small least-squares problems (shapes, not vertices)
        if norms[i] <= 1e-12:
            continue
        others = np.delete(Jn, i, axis=1)
        coef, *_ = np.linalg.lstsq(others, Jn[:, i], rcond=1e-10)
        indep[i] = float(np.linalg.norm(Jn[:, i] - others @ coef))
    C = Jn[:, :k].T @ Jn[:, :k]
    np.fill_diagonal(C, 0.0)
    j = np.argmax(np.abs(C), axis=1)
    cos = C[np.arange(k), j]
    sv = np.linalg.svd(Jn, compute_uv=False)
    return Identifiability(rig.names, motion, indep, tuple(rig.names[i] for i in j), cos, sv)



__all__ = ["Identifiability", "identifiability", "landmark_jacobian"]
