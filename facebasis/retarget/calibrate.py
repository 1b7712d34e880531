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
the residual part has no depth (the rest face of :func:`calibrate_rest` may take the skin's, :mod:`.restdepth`).

Every calibration takes a :class:`.framefit.FrameSolver` (frozen) and returns an :class:`IdentityCalibration`
(frozen): the offset and the neutral landmarks it settled on. None changes the solver it is given; the caller
builds the one it needs (``solver.with_neutral(calibration.neutral)``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .framefit import FrameSolver
from .onesided import demand_ratio
from .pose import PI, fit_pose_affine
from .restdepth import rest_offset

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
    scale : median scale s (px per rig unit) of the same pilot fits as ``noise`` (the s_ref of the
        pixel noise model, :attr:`.framefit.FrameSolver.pixel_scale`; nan with ``noise``)
    applied : False when the offset lowered the pilot residual by less than :data:`MIN_GAIN` (then
        nothing is applied: offset and baseline are 0 and rms_after, noise those of the rig's neutral)
    rest_applied, quantile_applied : ``identity="auto"``: the rest face (:func:`calibrate_rest`) /
        the quantile baseline on top of it (:func:`calibrate_identity`) was kept
    rest_anchored : the rest face is the posture of the capture's first frame (:func:`rest_frames`)
    rest_start : the landmark evidence that the take starts at rest (:mod:`.reststart`; None: none)
    demand_ratio : negative-weight demand of the anchored rest face over the commonest posture's
        (:func:`.onesided.demand_ratio`; nan when the anchor was not tried)
    neutral : (L, 3) the calibrated neutral landmarks: the solver's ``v0`` plus ``offset``, as the
        rounds added it up (kept beside ``offset`` so that a solver built on it is bit for bit the
        one the calibration measured; ``v0 + offset`` may differ in the last bit). None only when
        the result was built by hand
    """

    offset: np.ndarray
    baseline: np.ndarray
    frames: np.ndarray
    rms_before: float
    rms_after: float
    noise: float = float("nan")
    applied: bool = False
    rest_applied: bool = False
    quantile_applied: bool = False
    neutral: np.ndarray | None = None
    rest_anchored: bool = False
    rest_start: bool | None = None
    demand_ratio: float = float("nan")
    scale: float = float("nan")


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


def calibrate_identity(solver: FrameSolver, landmarks, visible, n_frames: int = CALIBRATION_FRAMES,
                       rounds: int = CALIBRATION_ROUNDS, quantile: float = BASELINE_QUANTILE) -> IdentityCalibration:
    """Estimate the static landmark offset of a capture (the quantile baseline and the residual
    part of the module docstring); ``solver`` is left as it is.

    Parameters
    ----------
    solver : :class:`.framefit.FrameSolver` (its ``v0``, ``D``, ``solve_frame``); the pilot fits use
        :meth:`~.framefit.FrameSolver.pilot` of it
    landmarks : (T, L, 2) pixels (no NaN; lost landmarks are marked in ``visible``)
    visible : (T, L) bool
    n_frames, rounds, quantile : see :data:`CALIBRATION_FRAMES`, :data:`CALIBRATION_ROUNDS`,
        :data:`BASELINE_QUANTILE`

    Returns
    -------
    IdentityCalibration (``neutral`` is ``solver.v0`` itself when the offset is not applied)
    """

    P = np.asarray(landmarks, np.float64)
    vis = np.asarray(visible, bool)
    frames = pilot_frames(vis, n_frames)
    L, k, F = solver.v0.shape[0], solver.D.shape[2], len(frames)
    v_start = solver.v0
    baseline = np.zeros(k)
    if F == 0:
        return IdentityCalibration(np.zeros((L, 3)), baseline, frames, float("nan"), float("nan"),
                                   neutral=v_start)                                          # not applied
    # in-plane landmark motion of the shapes: the residual part is kept orthogonal to it, so it can
    # neither absorb an expression nor undo the weights' lower bound (a negative shape direction)
    # (an orthonormal basis of their span from the SVD: the motion is rank-deficient when landmarks
    # cannot tell shapes apart, and QR would add arbitrary directions outside the span)
    Q = span_basis(solver.D[:, :2].reshape(2 * L, k))
    # plain least squares in the pilot fits (no sparsity, no contour sliding): the offset must
    # explain every landmark coordinate, the jaw line's along-contour position included
    pilot = solver.pilot()
    states = [None] * F
    rms_first = rms = noise = noise_first = scale = scale_first = float("nan")
    for rnd in range(rounds + 1):
        out = [pilot.solve_frame(P[f], vis[f], states[j]) for j, f in enumerate(frames)]
        states = [o.state for o in out]
        X = np.array([o.x for o in out])
        S = np.array([o.s for o in out])
        Rs = np.array([o.R for o in out])
        Ts = np.array([o.t for o in out])
        res = np.array([o.rms for o in out])
        rms = float(np.nanmedian(res))
        noise, scale = float(np.nanmedian(res / S)), float(np.nanmedian(S))
        if rnd == 0:
            rms_first, noise_first, scale_first = rms, noise, scale
        if rnd == rounds or (rnd == 1 and not rms <= (1.0 - MIN_GAIN) * rms_first):
            break                           # measured the calibrated fit, or the first update gained nothing
        good = res <= OUTLIER * np.nanmedian(res)        # frames the tracker lost take no part
        if good.sum() < max(4, F // 2):
            good = np.ones(F, bool)
        c = np.quantile(X[good], quantile, axis=0)                             # (k,) >= 0
        Qf = pilot.v0[None] + np.einsum("lck,fk->flc", pilot.D, X)             # fitted shapes (F, L, 3)
        fit = (S[:, None, None] * np.einsum("fij,flj->fli", np.einsum("ij,fjk->fik", PI, Rs), Qf)
               + Ts[:, None])
        off = back_project(np.array([o.flat for o in out]) - fit, S, Rs)       # (F, L, 3), as the model saw them
        off[~vis[frames] | ~good[:, None]] = np.nan
        o = np.nan_to_num(np.nanmedian(off, axis=0))[:, :2].reshape(-1)        # (2L,) robust
        o = o - Q @ (Q.T @ o)
        delta = pilot.D @ c
        delta[:, :2] += o.reshape(L, 2)
        pilot = pilot.shifted(delta)
        baseline += c
        states = [(np.clip(x - c, 0.0, 1.0), s, R, t) for (x, s, R, t) in states]   # warm start
    if not rms <= (1.0 - MIN_GAIN) * rms_first:     # nothing static to explain (e.g. the rig's own face)
        return IdentityCalibration(np.zeros((L, 3)), np.zeros(k), frames, rms_first, rms_first, noise_first, False,
                                   neutral=v_start, scale=scale_first)
    return IdentityCalibration(pilot.v0 - v_start, baseline, frames, rms_first, rms, noise, True, neutral=pilot.v0,
                               scale=scale)


def first_frame_offset(solver: FrameSolver, p, visible) -> np.ndarray:
    """``identity="first-frame"``: the offset (L, 3) that makes the neutral, posed on frame 0,
    match it exactly; ``solver`` is left as it is.

    The pose of frame 0 (landmarks p (L, 2), visible (L,) bool) is fitted with all weights 0; each
    visible landmark's image residual ``r_l`` is carried back into the rig frame in-plane,
    ``delta_l = R^T Pi^T r_l / s`` (no depth). Lost landmarks keep their rig position (offset 0). The
    shift has no depth, so it is exact while the head keeps frame 0's orientation and approximate as
    it turns away (tested: weight error 0.04 instead of 0.24 under +-5 degrees).
    """
    from ..errors import InputError
    vis = np.asarray(visible, bool)
    if vis.sum() < 4:
        raise InputError("first-frame neutral: expected at least 4 visible landmarks on frame 0")
    v0 = solver.v0
    s, R, t = fit_pose_affine(v0[vis], p[vis])
    s, R, t, _, pf = solver.fit_pose(v0, p, vis, s, R, t, rounds=3, iterations=10)   # pf: as the model sees them
    r = np.where(vis[:, None], pf - (s * (v0 @ R.T @ PI.T) + t), 0.0)
    return (r @ PI @ R) / s


#: share of the pilot frames that forms the capture's densest cluster of faces (the rest face)
REST_SHARE = 0.25
#: the rest offset is kept only if it lowers the median residual of the full pilot fits by this
#: fraction: an offset that is an expression (a capture with no rest, e.g. the synthetic benchmark's
#: rig face with 11 shapes each on half the time) makes those fits worse (measured 0.63 -> 0.71 px)
#: and is dropped; another person's face lowers it (ICT identities 1-3: 4-17%; the real clips 30-40%)
REST_MIN_GAIN = 0.02
#: pilot frames of the rest calibration (evenly spaced)
REST_FRAMES = 100
#: the first frame's rest face is kept only if its pilot fits' negative-weight demand (:mod:`.onesided`)
#: is at most this multiple of the commonest posture's: the demand of landmark noise alone is
#: ~0.1 rig units^2 for any neutral on the real clips, a first frame mid-sentence multiplies it by 2-7
#: (reports/retarget/plausibility.md)
ANCHOR_DEMAND_RATIO = 1.25
#: the first frame's posture is taken as the rest face (the median of the pilot faces around it) when
#: at least this fraction of the densest cluster's size lies within that cluster's radius of it
REST_ANCHOR_MIN = 0.2
#: with the landmark evidence of a start at rest (:mod:`.reststart`), the anchored rest face is still
#: refused above this demand ratio (a held expression, not rest); measured in reports/retarget/rest_cuts.md
ANCHOR_DEMAND_MAX = 2.0


def rest_offsets(solver, landmarks, visible, frames, poses=None):
    """Per pilot frame, the in-plane offset of every landmark from ``solver.v0`` with all weights 0.

    Each frame's pose is fitted to ``v0`` alone (the contour landmarks measured across the contour,
    :func:`.pose.contour_weights`) and its image residual carried back into the rig frame,
    ``R^T Pi^T r / s`` (no depth). Returns (offsets (F, L, 3) with NaN for lost landmarks, poses,
    rms residuals (F,) px)."""
    from .pose import contour_weights

    P, vis = landmarks, visible
    L = solver.v0.shape[0]
    out, new_poses, rms = np.full((len(frames), L, 3), np.nan), [], np.zeros(len(frames))
    for j, f in enumerate(frames):
        v = vis[f]
        W = contour_weights(P[f], solver.contour, solver.contour_slide)
        W = None if W is None else W[v]
        s, R, t = fit_pose_affine(solver.v0[v], P[f][v]) if poses is None else poses[j]
        s, R, t, rms[j], pf = solver.fit_pose(solver.v0, P[f], v, s, R, t, rounds=2, iterations=4, sqrtw=W)
        new_poses.append((s, R, t))
        o = ((pf - (s * (solver.v0 @ R.T @ PI.T) + t)) @ PI @ R) / s
        out[j, v] = o[v]
    return out, new_poses, rms


def _distances(offsets) -> np.ndarray:
    """(F, F) rms landmark distances between the in-plane offsets (F, L, 3) of the frames."""
    Z = np.nan_to_num(offsets[:, :, :2].reshape(len(offsets), -1))
    return np.sqrt(np.maximum(((Z[:, None] - Z[None]) ** 2).mean(2), 0.0))     # F <= REST_FRAMES


def densest_frames(offsets, share: float = REST_SHARE) -> np.ndarray:
    """Indices of the densest ``share`` of the frames: the frame whose ``K = share F`` nearest
    neighbours (rms landmark distance of the offsets (F, L, 3)) are closest, and those neighbours
    (the frame itself first)."""
    d = _distances(offsets)
    K = min(len(d), max(3, int(round(share * len(d)))))
    near = np.argsort(d, axis=1, kind="stable")[:, :K]
    return near[np.argmin(np.take_along_axis(d, near, 1).mean(1))]


def rest_frames(offsets, share: float = REST_SHARE, anchor: int | None = None,
                min_share: float = REST_ANCHOR_MIN, window=None) -> tuple[np.ndarray, bool]:
    """The frames whose median is the rest face, and whether they are the anchor's.

    Without ``anchor``: :func:`densest_frames`. With ``anchor`` (a frame index: the capture's first
    frame in :func:`calibrate_rest`): the frames within the densest cluster's radius (the distance
    of its ``K``-th member from its centre) of the anchor, the anchor included, if there are at
    least ``max(3, min_share K)`` of them, i.e. the anchor's posture recurs about as densely as the
    capture's commonest posture; else :func:`densest_frames`. A take usually starts at rest
    (the classic first-frame neutral) while a talking clip's commonest posture is speech (lips
    parted): when the first frame's posture recurs, it is the rest face; when it does not (a take
    that starts on an expression), the commonest posture is.

    With ``window`` (indices of the offsets of the take's first half second, at rest by the landmark
    evidence of :mod:`.reststart`): the anchor's posture is the median of the window's faces (not one
    frame) and the window's frames with those within the densest cluster's radius of that posture
    are the rest frames, anchored whether or not the posture recurs (the window itself holds it).

    Returns (indices, anchored)."""
    dense = densest_frames(offsets, share)
    if window is not None:
        d = _distances(offsets)
        Z = np.nan_to_num(offsets[:, :, :2].reshape(len(offsets), -1))
        posture = np.median(Z[np.asarray(window)], axis=0)
        near = np.sqrt(((Z - posture[None]) ** 2).mean(1)) <= d[dense[0], dense[-1]]
        return np.union1d(np.asarray(window), np.flatnonzero(near)), True
    if anchor is None:
        return dense, False
    d = _distances(offsets)
    around = np.flatnonzero(d[anchor] <= d[dense[0], dense[-1]])
    if len(around) >= max(3, min_share * len(dense)):
        return around, True
    return dense, False


def _fitted_rms(solver: FrameSolver, landmarks, visible, frames) -> float:
    """Median over the frames of the rms landmark residual (px) of the full fit (pose and weights,
    :meth:`.framefit.FrameSolver.pilot` with the contour sliding) with ``solver.v0``."""
    pilot = solver.pilot(plain=False)                  # the contour slides, as in the frames' solve
    res = [pilot.solve_frame(landmarks[f], visible[f], None).rms for f in frames]
    return float(np.nanmedian(res))


def calibrate_rest(solver: FrameSolver, landmarks, visible, n_frames: int = REST_FRAMES,
                   rounds: int = CALIBRATION_ROUNDS, share: float = REST_SHARE,
                   anchor: bool = False, window=None, rms_before: float | None = None) -> IdentityCalibration:
    """The person's rest face: the densest cluster of the capture's pose-normalised faces.

    A face at rest is where a capture spends most of its time, and comes back to between
    expressions; expressions are excursions from it in many directions. Up to ``n_frames`` evenly
    spaced pilot frames are posed on ``solver.v0`` with all weights 0 (:func:`rest_offsets`), their
    landmark offsets from it compared, and the landmark-wise median of the densest ``share`` of them
    (:func:`densest_frames`) is added to ``v0`` (each frame's offset in the skin's tangent plane with
    the solver's ``normals``, :func:`.restdepth.rest_offset`, else no depth); ``rounds`` times, each round
    posing on the updated neutral. Unlike the quantile baseline (:func:`calibrate_identity`), this
    needs no weights of the pilot frames, so landmark noise fitted by weak shapes cannot leak into
    the neutral, and the offset is not restricted to the shapes' span. ``solver`` is left as it is.

    It is kept only if it lowers the median residual of the full pilot fits (pose and weights) by
    :data:`REST_MIN_GAIN` or more: on a capture of the rig's own face the shapes already fit every
    frame and the rig's neutral stays (the weights are then exactly those of ``identity="rig"``).
    ``anchor``: the first frame's posture when it recurs (:func:`rest_frames`); ``window`` (frame
    indices of the take's start, at rest by :func:`.reststart.rest_start`): their median posture,
    the window's frames joining the pilot frames. ``rms_before``: the rig neutral's residual of an
    earlier call on the same capture and solver (the same check frames: not fitted again).

    Returns
    -------
    IdentityCalibration (``baseline`` zeros; ``rms_before`` / ``rms_after`` the full pilot fits' median
    residuals, px, with the rig's and the calibrated neutral)
    """
    P = np.asarray(landmarks, np.float64)
    vis = np.asarray(visible, bool)
    frames = pilot_frames(vis, n_frames)
    L, k = solver.v0.shape[0], solver.D.shape[2]
    v_start = solver.v0
    if len(frames) == 0:
        return IdentityCalibration(np.zeros((L, 3)), np.zeros(k), frames, float("nan"), float("nan"), neutral=v_start)
    check = frames[np.unique(np.linspace(0, len(frames) - 1, min(len(frames), CALIBRATION_FRAMES)).round().astype(int))]
    win = None
    if window is not None:                  # the take's start window joins the pilot frames
        frames = np.union1d(frames, np.asarray(window, np.int64))
        win = np.searchsorted(frames, np.asarray(window, np.int64))
    before = _fitted_rms(solver, P, vis, check) if rms_before is None else rms_before
    fits = []  # the offset lifted onto the skin (restdepth.py) and flat: the one the check frames fit better
    for normals in (solver.normals, None)[: 1 + (solver.normals is not None)]:
        poses, moved = None, solver
        for _ in range(rounds):
            O, poses, _ = rest_offsets(moved, P, vis, frames, poses)
            near, anchored = rest_frames(O, share, 0 if anchor else None, window=win)
            moved = moved.shifted(rest_offset(O[near], np.array([poses[j][1] for j in near]), normals))
        fits.append((_fitted_rms(moved, P, vis, check), moved, anchored))
    after, moved, anchored = min(fits, key=lambda f: f[0])
    if not after <= (1.0 - REST_MIN_GAIN) * before:
        return IdentityCalibration(np.zeros((L, 3)), np.zeros(k), frames, before, before, float("nan"), False,
                                   neutral=v_start)
    return IdentityCalibration(moved.v0 - v_start, np.zeros(k), frames, before, after, float("nan"), True,
                               neutral=moved.v0, rest_anchored=anchored)


def calibrate_auto(solver: FrameSolver, landmarks, visible, anchor: bool = True, start=None) -> IdentityCalibration:
    """``identity="auto"``: the person's neutral from the capture; ``solver`` is left as it is.

    1. The commonest posture: the quantile baseline (:func:`calibrate_identity`) on the rig's
       neutral, and on the rest face of the densest cluster (:func:`calibrate_rest` without anchor);
       the one whose full pilot fits (pose and weights, the same pilot frames) leave the lower median
       residual. The rest face assumes the capture comes back to a face at rest; a capture that
       never does (every frame some expression) moves it into an expression, after which frames need
       negative weights and fit worse than with the quantile baseline alone, which is then kept.
    2. With ``anchor`` (the default), the take's start posture replaces it. A talking clip's
       commonest posture is speech (lips parted), not rest: with it as the neutral, closed lips read
       as an expression (mouthStretch on cap13's calm start). ``start`` (a :class:`.reststart.RestStart`,
       the landmark evidence of a 68-point capture) decides: a start that is not still with closed
       lips is never anchored; one that is gives the rest face of its window's median posture
       (:func:`rest_frames`), kept unless, as a neutral, it demands more than :data:`ANCHOR_DEMAND_MAX`
       times the negative weight of step 1's (:func:`.onesided.negative_demand`: a rig's shapes are
       one-sided; a closed-lip smile held at the start is not rest). Without evidence (``start``
       None: other layouts), the first frame's posture is taken when it recurs through the capture
       and demands at most :data:`ANCHOR_DEMAND_RATIO` times step 1's (the test before the evidence).

    The result records ``rest_start`` (the evidence's verdict, None without it) and ``demand_ratio``
    (nan when the anchor was not tried).
    """
    v_start = solver.v0
    quant = calibrate_identity(solver, landmarks, visible)
    common = replace(quant, quantile_applied=quant.applied)
    rest = calibrate_rest(solver, landmarks, visible, anchor=False)
    if rest.applied:
        both = calibrate_identity(solver.with_neutral(rest.neutral), landmarks, visible)   # the baseline on the rest face
        if both.rms_after < quant.rms_after:
            common = IdentityCalibration(both.neutral - v_start, both.baseline, both.frames, quant.rms_before,
                                         both.rms_after, both.noise, True, True, both.applied, neutral=both.neutral,
                                         scale=both.scale)
    verdict = None if start is None else start.at_rest
    common = replace(common, rest_start=verdict)
    if not anchor or verdict is False:
        return common
    window = None if start is None else start.frames
    first = calibrate_rest(solver, landmarks, visible, anchor=True, window=window, rms_before=rest.rms_before)
    if not (first.applied and first.rest_anchored):
        return common
    ratio = demand_ratio(solver, first.neutral, common.neutral, landmarks, visible,
                         pilot_frames(visible, CALIBRATION_FRAMES))
    limit = ANCHOR_DEMAND_RATIO if start is None else ANCHOR_DEMAND_MAX
    if ratio <= limit:
        return replace(first, rest_applied=True, rest_start=verdict, demand_ratio=ratio)
    return replace(common, demand_ratio=ratio)


__all__ = ["IdentityCalibration", "calibrate_auto", "ANCHOR_DEMAND_MAX", "calibrate_identity", "calibrate_rest",
           "first_frame_offset", "rest_offsets", "densest_frames", "REST_SHARE", "REST_FRAMES", "pilot_frames",
           "back_project", "CALIBRATION_FRAMES", "CALIBRATION_ROUNDS", "BASELINE_QUANTILE", "MIN_GAIN", "OUTLIER"]
