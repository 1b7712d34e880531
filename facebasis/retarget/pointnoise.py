"""Per-landmark noise of a capture: the rig fit's heteroscedastic landmark noise model.

The rig fit of :mod:`.rigdrive` weighs every landmark's residual alike (up to a contour's sliding,
:func:`.pose.contour_weights`). A capture's landmarks are not alike: a detector places the jaw line,
the outer brows or an eyelid found by a search less reliably than a nose tip or a mouth corner,
and the person's face may differ from the rig's at some points in ways no shape reproduces (a brow
whose arch is not the rig's). Such a point, weighted like the others, is read as an expression: on a
tracking-only cut of cap13 that starts at rest (from 24 s), the left brow's outer points (residual
3-14 times the typical landmark's) drove browDown_L to a median of 0.17 over the cut's frames while
browDown_R stayed at 0 (median left/right difference 0.29, the owner's bound 0.2).

Model. Landmark l's residual after the contour's whitening, ``e_l = W_l (p_l - s Pi R q_l - t) / s``
(rig units), is Gaussian with its own standard deviation: ``e_l ~ N(0, sigma_l^2 I)``. The maximum
likelihood fit weighs it by ``1 / sigma_l^2``; relative to a reference r that is the square-root
weight

    w_l = r / max(sigma_l, r),      r = max(median_l sigma_l, sigma_floor),

applied to both steps of every frame (pose and weights, :attr:`.framefit.FrameSolver.point_weights`).
A landmark is only ever trusted less than the typical one, never more: a point the rig reproduces
exactly (its residual ~0) would otherwise outweigh the face. ``sigma_floor`` is the noise below which
the fit does not look, :data:`FLOOR_FRACTION` of the face's rms landmark radius (:func:`noise_floor`;
0.012 cm on ICT-FaceKit, about 0.1 px on a face 50 px wide): on landmarks that clean (a synthetic
capture without noise) what the pilot fits leave is the priors' bias, not noise, and every weight
stays 1. ``sigma_l`` is estimated once per
capture, from frames fitted each on its own with the settings of the pilot fits (every shape free
at the ridge floor, no temporal term, the contour sliding as the frames will be solved:
:meth:`.framefit.FrameSolver.pilot`), as the root of the median over those frames of
``|e_l|^2`` (robust to the frames the rig cannot follow at all; the median of a chi-square with 2
degrees of freedom is the same factor 2 ln 2 for every landmark, so it cancels in ``w``), shrunk
towards the landmarks' median as if :data:`PRIOR_FRAMES` more frames had shown it. What the rig
can reproduce with its shapes (weights in [0, 1]) does not count as noise: a brow that really lowers
is fitted by browDown and keeps its weight; a face that would need negative weights (a neutral that
is itself an expression) does.

The "auto" ridge stays set from the shared noise estimate (:meth:`.rigdrive.RigRetargeter.pilot_stats`).
Setting it from the per-point reference instead (``median_l sigma_l / sqrt(ln 2)``, the same value
for noise alike on every landmark) is the consistent maximum-likelihood choice, but the real
"noise" holds model mismatch the ridge was calibrated on: on the rest cuts of the shared clips it
let weights loose (a scratch run on the rest cuts, not kept in a report: cuts at rest meeting the
calm bound 0.15, dlib 5/6 -> 4/6, MediaPipe 4/5 -> 3/5; left/right <= 0.2, 6/6 -> 3/6, 5/5 -> 1/5,
tracking only 7/7 -> 5/7).
"""

from __future__ import annotations

import numpy as np


#: how landmark noise is shared among the landmarks (:class:`.rigdrive.RigRetargeter` ``point_noise``)
POINT_NOISE_MODES = ("per-point", "shared")
#: a landmark seen in fewer pilot frames than this keeps the weight 1 (too little evidence)
MIN_SEEN = 5
#: pseudo-frames of the landmarks' median noise each landmark's estimate is shrunk towards
PRIOR_FRAMES = 10.0
#: noise below this fraction of the face's rms landmark radius is not weighed by (the floor)
FLOOR_FRACTION = 0.002


def point_sigmas(solver, landmarks, visible, frames, prior_frames: float = PRIOR_FRAMES) -> np.ndarray:
    """Per-landmark noise ``sigma_l`` (L,) in rig units (module docstring), nan where unknown.

    Each landmark's mean square over the frames that saw it is shrunk towards the landmarks' median
    as if ``prior_frames`` more frames had shown that (``(n_l s_l^2 + n_0 r^2) / (n_l + n_0)``): from
    few frames alone the estimates scatter and landmarks would lose weight by chance (same noise on
    every landmark, 5 frames: about 7 of 68 below half weight; 40 frames: none).

    Parameters
    ----------
    solver : :class:`.framefit.FrameSolver` on the person's neutral (its :meth:`~.framefit.FrameSolver.pilot`
        settings fit the frames, keeping the contour's sliding)
    landmarks : (T, L, 2) px, without NaN
    visible : (T, L) bool
    frames : frame indices to fit (each on its own; :func:`.calibrate.pilot_frames`)
    prior_frames : n_0
    """
    pilot = solver.pilot(plain=False)
    L = landmarks.shape[1]
    sq = []
    for f in frames:
        vis = np.asarray(visible[f], bool)
        if vis.sum() < 4:
            continue
        fit = pilot.solve_frame(landmarks[f], vis, None)
        if np.isfinite(fit.rms) and fit.s > 0:
            r = pilot.whitened_residual(landmarks[f], fit)
            sq.append(np.where(vis, (r ** 2).sum(1), np.nan))
    if not sq:
        return np.full(L, np.nan)
    sq = np.array(sq)
    seen = np.isfinite(sq).sum(0)
    known = seen >= MIN_SEEN
    if not known.any():
        return np.full(L, np.nan)
    med = np.nanmedian(np.where(seen[None] > 0, sq, 0.0), axis=0)          # (L,) median squared residual
    ref = np.median(med[known])
    shrunk = (seen * med + prior_frames * ref) / (seen + prior_frames)
    return np.where(known, np.sqrt(shrunk), np.nan)


def point_weights(sigma, floor: float = 0.0) -> np.ndarray:
    """Square-root weights ``w_l = r / max(sigma_l, r)``, ``r = max(median sigma, floor)`` (L,) in
    (0, 1] of the noise ``sigma`` (L,) (module docstring); a landmark without an estimate (nan), or
    every landmark when r is 0 (a noise-free capture without a floor), keeps 1."""
    sigma = np.asarray(sigma, np.float64)
    known = np.isfinite(sigma)
    w = np.ones(len(sigma))
    if not known.any():
        return w
    ref = max(float(np.median(sigma[known])), float(floor))
    if ref <= 0.0:
        return w
    w[known] = ref / np.maximum(sigma[known], ref)
    return w


def noise_floor(neutral_landmarks, fraction: float = FLOOR_FRACTION) -> float:
    """``fraction`` of the rms radius of the neutral landmarks (L, 3) about their centroid: the floor of
    :func:`point_weights` in rig units, so that it does not depend on the rig's unit."""
    v = np.asarray(neutral_landmarks, np.float64)
    return float(fraction * np.sqrt(np.mean(np.sum((v - v.mean(0)) ** 2, axis=1))))


__all__ = ["POINT_NOISE_MODES", "MIN_SEEN", "PRIOR_FRAMES", "FLOOR_FRACTION", "point_sigmas", "point_weights",
           "noise_floor"]
