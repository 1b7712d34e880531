"""Eyelids that blink: lids placed in the frame of the tracked eye corners (beyond the paper).

A blink closes a 3-5 px eye opening on a webcam face in two or three frames, and the eye changes its
appearance as it does (the lid covers iris and white). Lucas-Kanade on a lid point (a 5 x 15 window
over the whole eye), the drift correction against the first frame's open eye, and the particle
filter that trusts both (0.5 px) far more than a detection (1-3 px) held the lids where they were;
a lid point also slides freely along the lid line (the aperture problem: an edge gives no motion
along itself). On the shared clips the tracked eye opening correlated with dlib's on the same frames
at -0.06 / 0.57 tracking only and 0.67 / 0.52 with ``--detector dlib`` (cap12 / cap13; dlib and
MediaPipe agree at 0.85 / 0.87): reports/capture/expression.csv.

Each lid point (iBUG 37, 38, 40, 41 and 43, 44, 46, 47) is written in its eye's frame, the similarity
that takes the eye corners (36, 39 / 42, 45) to ``-1/2`` and ``1/2`` in the complex plane:
``z = (p - m) / (c_1 - c_0)`` with ``m`` the corners' midpoint (:func:`lid_coordinates`), and placed
back on the *tracked* corners, ``p = m + (c_1 - c_0) z`` (:func:`place_lids`), which Lucas-Kanade
follows well (rigid, textured). ``z`` comes from:

* a detection (detector mode, :class:`Eyelids`): the detector sees the lid whatever its
  appearance; an exponential average of gain ``g`` (``TrackerOptions.detected_lids``) smooths its
  jitter (dlib's integer coordinates: 0.17 px on the opening, per frame),
  ``z_t = z_{t-1} + g (z_t^det - z_{t-1})``, at the price of a lag of ``(1 - g) / g`` frames;
* without a detection (``TrackerOptions.lid_search``, :class:`LidSearch`): the along-eye coordinate
  stays frame 0's (no evidence along the lid line), and each lid is searched across the eye for the
  first-frame profile of its *outer* side (upper lid: from 0.6 of the opening above the lid line to
  0.2 below; lower lid mirrored): the skin and lashes there keep their look while the lid covers the
  eye. The two points of a lid share one shift, scored by their mean ZNCC less a quadratic pull
  towards where the tracker put them; a match below ZNCC 0.5 leaves the tracker's lid.
"""

from __future__ import annotations

import numpy as np

from facebasis.errors import parameter_error

#: per eye: (corner, corner) and its lid points (upper two, lower two), iBUG 68
EYE_CORNERS = np.array([[36, 39], [42, 45]], np.int64)
EYE_LIDS = np.array([[37, 38, 40, 41], [43, 44, 46, 47]], np.int64)
#: lid search: half width of the profile along the eye (corner distances), candidate shifts on each
#: side of the first-frame position, smallest accepted ZNCC
LID_HALF_WIDTH, LID_STEPS, LID_ZNCC, LID_PRIOR = 0.08, 16, 0.5, 0.2
#: lid search of an eye closed or squinting on frame 0 (lid gap under LID_SQUINT corner distances):
#: its profiles and search steps are scaled by LID_OPEN_TYPICAL instead of its gap, and its lids may
#: open up to LID_OPEN_WIDE. An open adult eye is ~10 mm high for ~30 mm between the corners (0.3-0.35;
#: dlib's frame-0 landmarks on the benchmark faces: 0.24-0.39, the synthetic cartoon's 0.37), a wide
#: open eye ~0.45, a squint under 0.2. The earlier floor of 0.02 left a closed eye a search range
#: under a pixel, and its lids never opened. Eyes open on frame 0 are searched as before.
LID_SQUINT, LID_OPEN_TYPICAL, LID_OPEN_WIDE = 0.2, 0.3, 0.45
#: blur of the image the lid profiles are sampled on (pixels at reference face size)
LID_BLUR = 0.5


def lid_coordinates(lm: np.ndarray) -> np.ndarray:
    """Lid points of 68 landmarks ``(68, 2)`` in their eye's corner frame: complex ``(2, 4)``,
    ``(p - m) / (c_1 - c_0)`` (NaN where the corners coincide or a point is not finite)."""
    z = lm[..., 0] + 1j * lm[..., 1]
    c0, c1 = z[EYE_CORNERS[:, 0]], z[EYE_CORNERS[:, 1]]
    axis = c1 - c0
    with np.errstate(all="ignore"):
        out = (z[EYE_LIDS] - 0.5 * (c0 + c1)[:, None]) / axis[:, None]
    return np.where(np.abs(axis)[:, None] > 1e-9, out, np.nan)


def place_lids(lm: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Landmarks ``(68, 2)`` with the lid points put at ``coords`` (complex ``(2, 4)``) in the frame of
    their eye's corners (the inverse of :func:`lid_coordinates`)."""
    z = lm[..., 0] + 1j * lm[..., 1]
    c0, c1 = z[EYE_CORNERS[:, 0]], z[EYE_CORNERS[:, 1]]
    p = 0.5 * (c0 + c1)[:, None] + (c1 - c0)[:, None] * coords
    out = np.array(lm, float, copy=True)
    out[EYE_LIDS.ravel()] = np.stack([p.real.ravel(), p.imag.ravel()], 1)
    return out


class Eyelids:
    """The lids of a take (see the module docstring): running lid coordinates fed by each frame's
    detection, or, without one, searched by a :class:`LidSearch`.

    Parameters
    ----------
    n_landmarks : int
        Landmarks of the take; the model acts only on 68 (iBUG) points.
    gain : float
        ``g`` in ``[0, 1]``: weight of each frame's detected lid coordinates (0: detections are not
        used for the lids, which are then placed as without one).
    search : LidSearch, optional
        Finds the lids without a detection (None: the tracker's own lids are kept).
    z0 : ndarray, complex (2, 4), optional
        Frame 0's lid coordinates: without a detection the lids keep their along-eye coordinate
        (``z0.real``), on which the lid line gives no evidence.
    """

    def __init__(self, n_landmarks: int, gain: float, search: "LidSearch | None" = None, z0=None):
        self.search = search if n_landmarks == 68 else None
        self.z0 = None if z0 is None or n_landmarks != 68 else np.asarray(z0)
        if isinstance(gain, bool) or not isinstance(gain, (int, float, np.floating)) or not 0.0 <= gain <= 1.0:
            raise parameter_error("detected_lids", "a number in [0, 1]", repr(gain))
        self.active = n_landmarks == 68 and gain > 0
        self.gain = float(gain)
        self._z = None     # complex (2, 4): last frame's coordinates

    def follow(self, lm: np.ndarray, detections: np.ndarray | None, filt=None, gray=None) -> np.ndarray:
        """Landmarks ``(68, 2)`` with the lids placed from ``detections`` ``(68, 2)``; without a detection
        (or for an eye whose points the detection leaves NaN), where the :class:`LidSearch` (if any)
        finds them on ``gray``, else the tracker's own across the eye at frame 0's along-eye place. ``filt`` (a :class:`facebasis.capture.particle.CondensationFilter`) is moved
        along so the next frame starts from the placed lids."""
        if (detections is None or not self.active) and self.z0 is None and (self.search is None or gray is None):
            self._z = None
            return lm
        own = lid_coordinates(lm)
        frame_ok = np.all(np.isfinite(own), axis=1, keepdims=True)     # (2, 1): the eye's corners apart
        if detections is None or not self.active:
            z = self._undetected(own, lm, gray)
        else:
            det = lid_coordinates(np.asarray(detections, float))
            prev = own if self._z is None else np.where(np.isfinite(self._z), self._z, own)
            seen = np.all(np.isfinite(det), axis=1, keepdims=True)
            # an eye the detector missed is placed as on a frame without a detection
            fallback = own if seen.all() else self._undetected(own, lm, gray)
            z = np.where(seen, prev + self.gain * (np.where(seen, det, 0) - prev), fallback)
            z = np.where(np.isfinite(z), z, fallback)
        z = np.where(frame_ok, z, np.nan)
        self._z = z
        out = place_lids(lm, z)
        out = np.where(np.isfinite(out), out, lm)     # collapsed eye corners: the tracker's points stand
        if filt is not None:
            filt.place(EYE_LIDS.ravel(), out[EYE_LIDS.ravel()])
        return out


    def _undetected(self, own: np.ndarray, lm: np.ndarray, gray) -> np.ndarray:
        """Lid coordinates (2, 4) complex without a detection: the :class:`LidSearch`'s where it finds
        the lid, else the tracker's ``own`` across the eye at frame 0's along-eye coordinate (if
        ``z0`` is known; the lid line gives no evidence along itself)."""
        if self.z0 is not None:
            own = self.z0.real + 1j * own.imag
        z = own if self.search is None or gray is None else self.search.search(gray, lm)
        return np.where(np.isfinite(z), z, own)


class LidSearch:
    """Tracking-only lids: each lid point searched along its eye's vertical axis for its first-frame
    look across the lid line (see the module docstring).

    Parameters
    ----------
    gray : ndarray, shape (H, W) float32
        Frame 0.
    lm : ndarray, shape (68, 2)
        Frame 0's landmarks.
    sigma : float
        Blur (pixels) of the image the profiles are sampled on.
    zncc : float
        Smallest accepted zero-mean NCC of the best match.
    """

    def __init__(self, gray: np.ndarray, lm: np.ndarray, sigma: float, zncc: float = LID_ZNCC):
        self.sigma, self.zncc = float(sigma), float(zncc)
        self.z0 = lid_coordinates(lm)                                         # (2, 4)
        v = self.z0.imag
        gap = 0.5 * ((v[:, 3] - v[:, 0]) + (v[:, 2] - v[:, 1]))       # (2,) signed: the corners' order
        self.down = np.where(gap < 0, -1.0, 1.0)                       # eye-frame sign of "towards the lower lid"
        closed = np.abs(gap) < LID_SQUINT                              # (2,) closed or squinting on frame 0
        self.open0 = np.where(closed, LID_OPEN_TYPICAL, np.abs(gap))
        # towards opening each lid may travel 0.6 of the opening; a closed eye's up to a wide open eye
        reach = np.where(closed, (LID_OPEN_WIDE - np.abs(gap)) / self.open0, 0.6)    # (2,) openings
        u = np.linspace(-LID_HALF_WIDTH, LID_HALF_WIDTH, 5)
        # across the lid line mostly on the side away from the eye (skin, lashes), which a closing
        # lid does not change: upper lids from 0.6 opening above to 0.2 below, lower lids mirrored
        w = np.linspace(-0.6, 0.2, 7)[None, :] * np.array([1, 1, -1, -1])[:, None]        # (4, 7)
        w = w[None] * (self.down * self.open0)[:, None, None]                              # (2, 4, 7)
        # (2, 4, S) complex offsets in eye-frame units: along the eye by u, across by w
        self.offsets = (u[None, None, :, None] + 1j * w[:, :, None, :]).reshape(2, 4, -1)
        steps = np.linspace(-1.0, 1.0, 2 * LID_STEPS + 1)
        # upper lids (first two) search further down, lower lids further up: (2, 4, K) in openings
        self.shifts = np.stack([np.stack([np.interp(steps, [-1, 0, 1], [-r, 0, 1.0])] * 2
                                         + [np.interp(steps, [-1, 0, 1], [-1.0, 0, r])] * 2) for r in reach])
        self.template = self._sample(gray, lm, self.z0[..., None])[..., 0, :]       # (2, 4, S)

    def _sample(self, gray, lm, z):
        """Grey levels at the profiles around eye-frame coordinates z (2, 4, K) -> (2, 4, K, S)."""
        import cv2

        from .particle import sample

        c = lm[..., 0] + 1j * lm[..., 1]
        c0, c1 = c[EYE_CORNERS[:, 0]], c[EYE_CORNERS[:, 1]]
        p = 0.5 * (c0 + c1)[:, None, None, None] + (c1 - c0)[:, None, None, None] * (
            z[..., None] + self.offsets[:, :, None, :])
        xy = np.stack([p.real, p.imag], -1)
        ok = np.isfinite(xy).all(-1)
        xy = np.where(ok[..., None], xy, 0.0)
        h, w = gray.shape
        lo = np.clip(np.floor(xy.reshape(-1, 2).min(0)) - 4, 0, [w - 1, h - 1]).astype(int)
        hi = np.clip(np.ceil(xy.reshape(-1, 2).max(0)) + 5, lo + 1, [w, h]).astype(int)
        box = np.ascontiguousarray(gray[lo[1]:hi[1], lo[0]:hi[0]])
        if self.sigma > 0:
            box = cv2.GaussianBlur(box, (0, 0), self.sigma)
        return sample(box, (xy - lo).astype(np.float32))

    def search(self, gray: np.ndarray, lm: np.ndarray) -> np.ndarray:
        """Lid coordinates (2, 4) complex found on ``gray`` around the eye corners of ``lm`` (68, 2);
        NaN where the best match is below ``zncc``."""
        from .particle import _normalise

        own = lid_coordinates(lm)
        v0 = self.z0.imag
        scale = (self.down * self.open0)[:, None, None]
        cand = self.z0.real[..., None] + 1j * (v0[..., None] + self.shifts * scale)
        prof = self._sample(gray, lm, cand)                                     # (2, 4, K, S)
        zn = (_normalise(prof) * _normalise(self.template)[:, :, None, :]).sum(-1)   # (2, 4, K)
        # one shift per lid (its two points move together), scored by their mean ZNCC less a
        # quadratic pull towards where the tracker put the lid (in openings)
        zn = 0.5 * (zn[:, [0, 2]] + zn[:, [1, 3]])                               # (2, 2, K): upper, lower
        tracked = (own.imag - v0) / scale[..., 0]                                # (2, 4) in openings
        prior = 0.5 * (tracked[:, [0, 2]] + tracked[:, [1, 3]])
        sh = self.shifts[:, [0, 2]]                                              # (2, 2, K)
        score = zn - LID_PRIOR * (sh - prior[..., None]) ** 2
        k = np.argmax(score, -1)
        best = np.take_along_axis(zn, k[..., None], -1)[..., 0]                  # (2, 2)
        km, kp = np.clip(k - 1, 0, sh.shape[-1] - 1), np.clip(k + 1, 0, sh.shape[-1] - 1)
        f = lambda i: np.take_along_axis(score, i[..., None], -1)[..., 0]
        a, b_, c = f(km), f(k), f(kp)
        den = a - 2 * b_ + c
        frac = np.where((den < -1e-9) & (km < k) & (kp > k), 0.5 * (a - c) / np.where(den < -1e-9, den, -1.0), 0.0)
        step = sh[..., 1] - sh[..., 0]                                           # (2, 2)
        shift = np.take_along_axis(sh, k[..., None], -1)[..., 0] + frac * step
        shift4 = shift[:, [0, 0, 1, 1]] * scale[..., 0]
        best = best[:, [0, 0, 1, 1]]
        z = self.z0.real + 1j * (v0 + shift4)
        # the upper lid never below the lower one: crossed pairs meet halfway
        up, lo = z[:, [0, 1]], z[:, [3, 2]]
        crossed = self.down[:, None] * (up.imag - lo.imag) > 0
        mid = 0.5 * (up.imag + lo.imag)
        z[:, [0, 1]] = np.where(crossed, up.real + 1j * mid, up)
        z[:, [3, 2]] = np.where(crossed, lo.real + 1j * mid, lo)
        return np.where(best >= self.zncc, z, complex(np.nan, np.nan))


def check_lid_options(options) -> None:
    """Refuse bad ``detected_lids`` / ``lid_search`` of a
    :class:`facebasis.capture.options.TrackerOptions` (raises ``InputError``); called by the tracker with
    its other option checks, before any work."""
    gain = options.detected_lids
    if isinstance(gain, bool) or not isinstance(gain, (int, float, np.floating)) or not 0.0 <= gain <= 1.0:
        raise parameter_error("detected_lids", "a number in [0, 1]", repr(gain))
    if not isinstance(options.lid_search, (bool, np.bool_)):
        raise parameter_error("lid_search", "True or False", repr(options.lid_search))


def eyelid_model(gray: np.ndarray, lm: np.ndarray, scale: float, options) -> Eyelids:
    """The eyelid model of a take from frame 0 ``gray`` (H, W) and its landmarks ``lm`` (L, 2), the face
    scale and :class:`facebasis.capture.options.TrackerOptions` (``detected_lids``, ``lid_search``)."""
    check_lid_options(options)
    search = LidSearch(gray, lm, LID_BLUR * scale) if options.lid_search and len(lm) == 68 else None
    return Eyelids(len(lm), options.detected_lids, search, None if search is None else search.z0)


__all__ = ["EYE_CORNERS", "EYE_LIDS", "Eyelids", "LidSearch", "check_lid_options", "eyelid_model", "lid_coordinates", "place_lids"]
