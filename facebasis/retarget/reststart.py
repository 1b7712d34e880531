"""Does a take start at rest? Evidence from the landmarks of its first half second, not from weights.

:func:`.calibrate.calibrate_auto` may take the first frame's posture as the person's rest face (the
rig's neutral): a take usually starts neutral, while a talking clip's commonest posture is speech
(lips parted), which read as the neutral turns closed lips into an expression. Whether the first
frame *is* at rest was decided before by a weight-based test alone (the negative-weight demand of
the first frame's neutral at most 1.25 times the commonest posture's, :mod:`.onesided`), which
flips with capture noise (two dlib captures of the same clip: 1.13 and above 1.25). This module
decides it from what a person would look at, on the 68-point iBUG layout:

* **still**: over the first :data:`START_MIN` seconds, every frame's landmarks, after a
  similarity alignment onto their median face (scale, rotation, translation: head motion is not
  expression), lie within :data:`STILL_TOL` times the face width (rms over the landmarks) of that
  median face: the tolerance of the owner's calm frames, held for 0.3 s (a posture held, not a
  frame passed through mid-sentence: speech moves the lips at 3-5 Hz). The window is those frames
  and the following ones up to :data:`START_WINDOW` seconds while they stay within the tolerance;
* **lips closed**: the window's median inner-lip gap (mean of the 61-67, 62-66, 63-65 distances,
  over the distance between the eye centres) is at most :data:`LIP_MARGIN` above the capture's
  :data:`LIP_QUANTILE` quantile of the same gap. Relative to the capture because detectors place
  closed inner lips differently (dlib ~0.025, MediaPipe's 68-point subset ~0.005 of the eye
  distance on the same frames); a margin of 0.03 of the eye distance is ~2 mm on an adult face,
  where the speech posture of the shared clips is 0.08 (0.5 cm) and an open mouth 0.25-0.35; and
  never above :data:`LIP_MAX`.

Both hold: the take starts at rest, and the window's frames (a median over 0.3-0.5 s, not one
frame) give the anchored rest face. Either fails: the take starts on an expression or mid-sentence,
and no anchoring happens, whatever the weights say. Other landmark layouts give no evidence
(``None``) and keep the weight-based test. Pure functions of numpy arrays, vectorised over frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: seconds at the start of a take whose posture is tested (and, at rest, forms the anchored rest face)
START_WINDOW = 0.5
#: the first this many seconds must hold the posture (a start at rest held shorter than the window
#: still counts: the window then ends where the face leaves it)
START_MIN = 0.3
#: a still start: every frame within this fraction of the face width (rms) of the start's median face
STILL_TOL = 0.015
#: closed lips: window gap at most this far (fraction of the eye distance) above the capture's low quantile
LIP_MARGIN = 0.03
#: the quantile of the capture's inner-lip gaps taken as its closed lips
LIP_QUANTILE = 0.05
#: closed lips are never farther apart than this fraction of the eye distance (~5 mm, the speech
#: posture of the shared clips): a tracking-only capture keeps its first frame's lip thickness, so
#: its own low quantile follows a start with parted lips
LIP_MAX = 0.08
#: iBUG 68 inner-lip point pairs (upper, lower) measured for the gap
INNER_LIP_PAIRS = ((61, 67), (62, 66), (63, 65))


@dataclass(frozen=True)
class RestStart:
    """Landmark evidence on a take's start (:func:`rest_start`).

    Attributes
    ----------
    frames : (n,) int64 the window's frame indices (frames with at most a tenth of the landmarks
        lost, in the first :data:`START_MIN` to :data:`START_WINDOW` seconds; frame 0 first)
    deviation : largest rms distance of a frame of the first :data:`START_MIN` seconds from their
        median face, aligned, in face widths
    gap : the window's median inner-lip gap over the eye distance
    closed_gap : the capture's closed-lip gap (its :data:`LIP_QUANTILE` quantile)
    still, closed : the two tests
    """

    frames: np.ndarray
    deviation: float
    gap: float
    closed_gap: float
    still: bool
    closed: bool

    @property
    def at_rest(self) -> bool:
        """The take starts at rest: still and lips closed."""
        return bool(self.still and self.closed)


def align_similarity(P, ref) -> np.ndarray:
    """Each frame's landmarks P (T, L, 2) aligned onto ``ref`` (L, 2) by the least-squares similarity
    (Umeyama's closed form, written with complex numbers: ``z_ref ~ a z + b``); (T, L, 2)."""
    P = np.asarray(P, np.float64)
    ref = np.asarray(ref, np.float64)
    za = (P[..., 0] - P[..., 0].mean(1, keepdims=True)) + 1j * (P[..., 1] - P[..., 1].mean(1, keepdims=True))
    mr = ref.mean(0)
    zb = (ref[:, 0] - mr[0]) + 1j * (ref[:, 1] - mr[1])
    a = (np.conj(za) * zb[None]).sum(1) / np.maximum((np.abs(za) ** 2).sum(1), 1e-300)
    z = a[:, None] * za + (mr[0] + 1j * mr[1])
    return np.stack([z.real, z.imag], -1)


def inner_lip_gap(P) -> np.ndarray:
    """(T,) inner-lip gap of 68-point iBUG landmarks P (T, 68, 2): mean of the 61-67, 62-66, 63-65
    distances over the distance between the eye centres (36-41, 42-47)."""
    P = np.asarray(P, np.float64)
    up, lo = np.array(INNER_LIP_PAIRS).T
    gap = np.linalg.norm(P[:, up] - P[:, lo], axis=2).mean(1)
    eyes = np.linalg.norm(P[:, 36:42].mean(1) - P[:, 42:48].mean(1), axis=1)
    return gap / np.maximum(eyes, 1e-12)


def rest_start(landmarks, visible, fps: float, window: float = START_WINDOW) -> RestStart | None:
    """Whether a take starts at rest (module docstring), from landmarks (T, 68, 2) px and visible
    (T, 68) bool at ``fps`` frames per second; None when the landmarks are not the 68-point iBUG
    layout, frame 0 has more than a tenth of them lost or fewer than 3 frames of the first
    :data:`START_MIN` seconds count."""
    P = np.asarray(landmarks, np.float64)
    vis = np.asarray(visible, bool)
    if P.ndim != 3 or P.shape[1:] != (68, 2):
        return None
    n = max(3, int(round(window * float(fps))))
    n_core = min(n, max(3, int(round(START_MIN * float(fps)))))
    # a landmark the tracker marked lost still has the filter's estimate: a frame counts unless more
    # than a tenth of its landmarks are lost (or any is missing)
    full = (vis.mean(1) >= 0.9) & np.isfinite(P).all((1, 2))
    frames = np.flatnonzero(full[:n])
    core = frames < n_core
    if core.sum() < 3 or frames[0] != 0:
        return None
    ref = np.median(align_similarity(P[frames[core]], np.median(P[frames[core]], axis=0)), axis=0)
    A = align_similarity(P[frames], ref)             # onto the core's median face, in its own frame
    width = float(np.linalg.norm(ref[0] - ref[16]))
    d = np.sqrt(((A - ref[None]) ** 2).sum(2).mean(1)) / max(width, 1e-12)
    dev = float(d[core].max())
    leave = np.flatnonzero(~core & (d > STILL_TOL))   # the window ends where the face leaves the posture
    frames = frames[:leave[0]] if len(leave) else frames
    W = P[frames]
    gaps = inner_lip_gap(P[full])
    gap = float(np.median(inner_lip_gap(W)))
    closed_gap = float(np.quantile(gaps, LIP_QUANTILE))
    return RestStart(frames.astype(np.int64), dev, gap, closed_gap, dev <= STILL_TOL, gap <= min(closed_gap + LIP_MARGIN, LIP_MAX))


__all__ = ["RestStart", "rest_start", "inner_lip_gap", "align_similarity", "START_WINDOW", "START_MIN", "STILL_TOL",
           "LIP_MARGIN", "LIP_QUANTILE", "LIP_MAX", "INNER_LIP_PAIRS"]
