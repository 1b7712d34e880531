"""One-sidedness of a neutral: how much a capture's frames would need negative weights with it.

A blendshape rig's expression shapes are one-sided deltas from its neutral (weights in [0, 1]): the
neutral is the face from which every expression is reached with non-negative weights. A candidate
neutral that is itself an expression (lips parted mid-sentence, a smile) leaves the capture's faces
that are nearer rest than it unexplainable with those bounds: fitted with weights >= 0 they leave a
residual that negative weights would remove (closing lips need a negative jawOpen). This measures
that demand, to choose between candidate rest faces (:func:`.calibrate.calibrate_auto`).

For each frame, the bounded fit of :meth:`.framefit.FrameSolver.pilot` (the contour sliding, as
the frames are solved) gives the pose and the residual r (whitened, the pose's 6 linearised
directions projected out as in the weight step); the demand is the part of ``||r||^2`` that
non-positive steps y of the shapes remove, with the "auto" ridge of that frame:

    demand_f = ||r||^2 - min_{y >= 0} ( ||r + E y||^2 + rho ||y||^2 )

(a non-negative least-squares problem, :func:`scipy.optimize.nnls`: a small dense problem per frame,
2L + k rows by k columns, where an active-set NNLS is exact and fast). Landmark noise alone gives a
floor (weak shapes fit some noise on either side), equal for every candidate neutral.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from .framefit import FrameSolver
from .pose import PI, contour_weights, pose_jacobian, whiten

#: prior standard deviation of a weight in the ridge of the demand's fit (the "auto" rule's)
DEMAND_PRIOR_STD = 0.5


def negative_demand(solver: FrameSolver, landmarks, visible, frames) -> np.ndarray:
    """Per frame (F,), the residual (rig units^2) that negative weights would remove (module docstring).

    Parameters
    ----------
    solver : the frame solver on the candidate neutral (its ``pilot(plain=False)`` fits the frames)
    landmarks : (T, L, 2) pixels, no NaN
    visible : (T, L) bool
    frames : (F,) frame indices
    """
    P = np.asarray(landmarks, np.float64)
    vis = np.asarray(visible, bool)
    pilot = solver.pilot(plain=False)
    k = solver.n_shapes
    out = np.full(len(frames), np.nan)
    for j, f in enumerate(frames):
        v = vis[f]
        if v.sum() < 4:
            continue
        fit = pilot.solve_frame(P[f], v, None)
        W = contour_weights(P[f], solver.contour, solver.contour_slide)
        W = None if W is None else W[v]
        M = PI @ fit.R
        q = solver.landmarks3d(fit.x)[v]
        E = whiten(np.einsum("ij,ljk->lik", M, solver.D[v]).reshape(-1, k), W)
        r = solver.whitened_residual(P[f], fit)[v].reshape(-1)
        Qp, _ = np.linalg.qr(whiten(pose_jacobian(q @ fit.R.T), W))
        E = E - Qp @ (Qp.T @ E)
        r = r - Qp @ (Qp.T @ r)
        rho = max(1e-3, (fit.rms / fit.s / DEMAND_PRIOR_STD) ** 2)
        y, _ = nnls(np.vstack([-E, np.sqrt(rho) * np.eye(k)]), np.concatenate([r, np.zeros(k)]))
        out[j] = r @ r - np.sum((r + E @ y) ** 2) - rho * (y @ y)
    return out


def demand_ratio(solver: FrameSolver, first, common, landmarks, visible, frames) -> float:
    """The median demand over ``frames`` (:func:`negative_demand`) of the neutral ``first`` (L, 3)
    over that of the neutral ``common`` (inf when only the latter's is 0)."""
    a = np.nanmedian(negative_demand(solver.with_neutral(first), landmarks, visible, frames))
    b = np.nanmedian(negative_demand(solver.with_neutral(common), landmarks, visible, frames))
    return float(a / b) if b > 0 else (1.0 if a <= 0 else float("inf"))


__all__ = ["negative_demand", "demand_ratio", "DEMAND_PRIOR_STD"]
