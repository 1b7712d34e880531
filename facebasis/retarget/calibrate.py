"""Identity calibration: the person's neutral landmarks estimated from the capture itself.

A generic rig's neutral landmarks v0_l are not the filmed person's; fitted as they are, the static
difference (face shape, and landmark conventions that differ from the rig's landmark vertices)
is read as expression in every frame. :mod:`.rigdrive` can take frame 0 as the neutral
(``identity="first-frame"``), which is wrong whenever the capture starts on an expression. This
module estimates a static per-landmark offset ``delta_l`` (rig frame, (L, 3)) from the whole
capture instead (``identity="auto"``), with no neutral frame required and no identity basis (a rig
folder from ``facebasis rig`` has none):

    p_fl  ~=  s_f Pi R_f (v0_l + delta_l + sum_i x_fi d_il) + t_f                    (model)

``delta`` is split into the part the expression shapes can produce and the rest:

1. *expression part*, ``D c``: pilot frames (up to :data:`CALIBRATION_FRAMES`, evenly spaced over
   the capture) are fitted one by one (pose and bounded weights, the solver of :mod:`.rigdrive`, no
   temporal term, ridge :data:`.rigdrive.RIDGE_FLOOR`); the baseline ``c_i`` of shape i is the
   :data:`BASELINE_QUANTILE` quantile of its weights over those frames. A shape that stays on in
   (nearly) every frame is taken as part of the face, not as expression; a shape at rest in at least
   that fraction of the frames gets c_i = 0 and is untouched. This is the prior that keeps ``delta``
   from absorbing expressions: only what is present all the time moves into the neutral.
2. *residual part*: the landmark residual each pilot frame leaves, carried back into the rig frame
   in-plane (``R_f^T Pi^T r_fl / s_f``, no depth, as for the first-frame neutral), and its median
   over the pilot frames, projected orthogonally to the
   in-plane landmark motion of all shapes. It holds the differences no shape spans; the projection
   keeps it from absorbing an expression and from undoing the weights' lower bound (a free offset
   would move the neutral against a shape so that noise can be fitted with weights on both sides
   of it: measured 0.084 instead of 0.035 weight error at 1 px noise on ICT).

Pilot frames whose residual exceeds :data:`OUTLIER` times the median (where tracking failed) take
no part in either. The two are added to ``v0`` and the pilot fits repeated (warm-started) for :data:`CALIBRATION_ROUNDS`
rounds. The result is kept only if it lowers the median pilot residual by :data:`MIN_GAIN` or more;
otherwise the rig's neutral stays (a capture of the rig's own face gives exactly the weights of
``identity="rig"``). Limits: an expression held through more than ``1 - BASELINE_QUANTILE`` of the
capture is taken as the person's neutral; a face that differs from the rig's in the negative
direction of a shape stays unexplained (the shape rests at 0 and the residual keeps the difference);
the residual part has no depth, so it is exact for the head orientations of the pilot frames and
approximate away from them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .pose import PI

#: pilot frames (evenly spaced) of the calibration
CALIBRATION_FRAMES = 40
#: singular values of the shapes' landmark motion below this fraction of the largest are not in its span
SPAN_RTOL = 1e-10
#: pilot rounds (the first cold, the others warm-started from the previous round)
CALIBRATION_ROUNDS = 3
#: quantile of a shape's pilot weights taken as its static baseline (part of the person's face)
BASELINE_QUANTILE = 0.1
#: the offset is kept only if it lowers the median pilot residual by at least this fraction: on a
#: capture of the rig's own face (noise only) it fits noise and is dropped, so the weights are
#: exactly those of identity "rig" (measured in reports/retarget)
MIN_GAIN = 0.1
#: pilot frames whose rms residual exceeds this multiple of the median are left out of the estimate
#: (frames where tracking failed; measured on a clip whose tracking collapses after ~40 s)
OUTLIER = 2.0


def span_basis(M: np.ndarray, rtol: float = SPAN_RTOL) -> np.ndarray:
    """Orthonormal basis (n, r) of the column span of ``M`` (n, k), r its numerical rank (singular
    values above ``rtol`` times the largest). Unlike a QR factorisation, it adds no directions
    outside the span when ``M`` is rank-deficient (landmarks that cannot tell shapes apart)."""
    U, sv, _ = np.linalg.svd(np.asarray(M, np.float64), full_matrices=False)
    return U[:, sv > rtol * sv[0]] if sv.size and sv[0] > 0 else U[:, :0]


@dataclass(frozen=True)
class IdentityCalibration:
    """Result of :func:`calibrate_identity`.

    Attributes
    ----------
    offset : (L, 3) static landmark offset added to the rig's neutral landmarks (rig units)
    baseline : (k,) baseline weights moved into the neutral (sum over rounds of the quantiles)
    frames : (F,) pilot frame indices
    rms_before, rms_after : median over the pilot frames of the rms landmark residual (px) of the
        first round (the rig's own neutral) and after the last update
    noise : median over the pilot frames of rms residual / scale after the last update (rig units;
        the landmark noise of the "auto" ridge, :meth:`.rigdrive.RigRetargeter.estimate_noise`)
    applied : False when the offset lowered the pilot residual by less than :data:`MIN_GAIN` (then
        nothing is applied: offset and baseline are 0 and rms_after, noise those of the rig's neutral)
    """

    offset: np.ndarray
    baseline: np.ndarray
    frames: np.ndarray
    rms_before: float
    rms_after: float
    noise: float = float("nan")
    applied: bool = False


def pilot_frames(visible, n: int = CALIBRATION_FRAMES) -> np.ndarray:
    """Up to ``n`` evenly spaced frame indices with at least 4 visible landmarks; visible (T, L)."""
    vis = np.asarray(visible, bool)
    usable = np.flatnonzero(vis.sum(1) >= 4)
    if len(usable) == 0:
        return usable
    pick = np.unique(np.linspace(0, len(usable) - 1, min(len(usable), n)).round().astype(int))
    return usable[pick]


def back_project(residual, scale, rotation) -> np.ndarray:
    """In-plane image residuals (F, L, 2) px -> rig-frame offsets (F, L, 3): ``R_f^T Pi^T r / s_f``."""
    M = np.einsum("ij,fjk->fik", PI, rotation)                 # (F, 2, 3) = Pi R_f
    return np.einsum("fli,fik->flk", residual, M) / np.asarray(scale)[:, None, None]


def calibrate_identity(solver, landmarks, visible, n_frames: int = CALIBRATION_FRAMES,
                       rounds: int = CALIBRATION_ROUNDS, quantile: float = BASELINE_QUANTILE) -> IdentityCalibration:
    """Estimate the static landmark offset of a capture and apply it to ``solver.v0``.

    Parameters
    ----------
    solver : :class:`facebasis.retarget.rigdrive.RigRetargeter` (its ``v0``, ``D``, ``solve_frame``;
        ``v0`` is updated in place to the calibrated neutral landmarks)
    landmarks : (T, L, 2) pixels (no NaN; lost landmarks are marked in ``visible``)
    visible : (T, L) bool
    n_frames, rounds, quantile : see :data:`CALIBRATION_FRAMES`, :data:`CALIBRATION_ROUNDS`,
        :data:`BASELINE_QUANTILE`

    Returns
    -------
    IdentityCalibration
    """
    from .rigdrive import RIDGE_FLOOR

    P = np.asarray(landmarks, np.float64)
    vis = np.asarray(visible, bool)
    frames = pilot_frames(vis, n_frames)
    L, k, F = solver.v0.shape[0], solver.D.shape[2], len(frames)
    v_start = solver.v0.copy()
    baseline = np.zeros(k)
    if F == 0:
        return IdentityCalibration(np.zeros((L, 3)), baseline, frames, float("nan"), float("nan"))  # not applied
    # in-plane landmark motion of the shapes: the residual part is kept orthogonal to it, so it can
    # neither absorb an expression nor undo the weights' lower bound (a negative shape direction)
    # (an orthonormal basis of their span from the SVD: the motion is rank-deficient when landmarks
    # cannot tell shapes apart, and QR would add arbitrary directions outside the span)
    Q = span_basis(solver.D[:, :2].reshape(2 * L, k))
    keep = solver.smooth, solver.ridge
    solver.smooth, solver.ridge = 0.0, RIDGE_FLOOR
    states = [None] * F
    rms_first = rms = noise = noise_first = float("nan")
    try:
        for rnd in range(rounds + 1):
            out = [solver.solve_frame(P[f], vis[f], states[j]) for j, f in enumerate(frames)]
            states = [o[:4] for o in out]
            X = np.array([o[0] for o in out])
            S = np.array([o[1] for o in out])
            Rs = np.array([o[2] for o in out])
            Ts = np.array([o[3] for o in out])
            res = np.array([o[4] for o in out])
            rms = float(np.nanmedian(res))
            noise = float(np.nanmedian(res / S))
            if rnd == 0:
                rms_first, noise_first = rms, noise
            if rnd == rounds or (rnd == 1 and not rms <= (1.0 - MIN_GAIN) * rms_first):
                break                           # measured the calibrated fit, or the first update gained nothing
            good = res <= OUTLIER * np.nanmedian(res)        # frames the tracker lost take no part
            if good.sum() < max(4, F // 2):
                good = np.ones(F, bool)
            c = np.quantile(X[good], quantile, axis=0)                             # (k,) >= 0
            Qf = solver.v0[None] + np.einsum("lck,fk->flc", solver.D, X)           # fitted shapes (F, L, 3)
            fit = (S[:, None, None] * np.einsum("fij,flj->fli", np.einsum("ij,fjk->fik", PI, Rs), Qf)
                   + Ts[:, None])
            off = back_project(P[frames] - fit, S, Rs)                             # (F, L, 3)
            off[~vis[frames] | ~good[:, None]] = np.nan
            o = np.nan_to_num(np.nanmedian(off, axis=0))[:, :2].reshape(-1)        # (2L,) robust
            o = o - Q @ (Q.T @ o)
            delta = solver.D @ c
            delta[:, :2] += o.reshape(L, 2)
            solver.v0 = solver.v0 + delta
            baseline += c
            states = [(np.clip(x - c, 0.0, 1.0), s, R, t) for (x, s, R, t) in states]   # warm start
    finally:
        solver.smooth, solver.ridge = keep
    if not rms <= (1.0 - MIN_GAIN) * rms_first:     # nothing static to explain (e.g. the rig's own face)
        solver.v0 = v_start
        return IdentityCalibration(np.zeros((L, 3)), np.zeros(k), frames, rms_first, rms_first, noise_first, False)
    return IdentityCalibration(solver.v0 - v_start, baseline, frames, rms_first, rms, noise, True)


__all__ = ["IdentityCalibration", "calibrate_identity", "pilot_frames", "back_project", "CALIBRATION_FRAMES",
           "CALIBRATION_ROUNDS", "BASELINE_QUANTILE", "MIN_GAIN", "OUTLIER"]
