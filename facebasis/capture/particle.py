"""CONDENSATION particle filter that stabilises Lucas-Kanade landmark tracking (Wu & Ju 2016, sec. 4.1).

The paper stabilises LK with CONDENSATION (Isard & Blake) "as in [22]" without giving the model, so
the model here is our choice:

* state: one particle set of ``N`` 2D positions per landmark, shape ``(L, N, 2)``;
* motion model: each particle moves by the *neighbour-predicted* displacement (the Gaussian-weighted
  mean LK displacement of the other landmarks that were tracked confidently this frame, so head
  motion carries a point that LK lost), falling back to a damped constant velocity when no landmark
  is confident, plus Gaussian process noise;
* likelihood: (a) a Gaussian around the LK measurement, only where LK is confident (status 1,
  forward-backward error small, normalised cross-correlation (NCC) of the patch at the LK point with
  the template high), applied Rao-Blackwellised: each particle is a small Gaussian fused with the
  measurement analytically, which removes most Monte-Carlo noise from the estimate; (b) the patch appearance: ``exp((NCC - 1) / tau)`` with the best of two
  templates, the first-frame patch and the patch of the last confident frame; (c) optionally a
  Gaussian around a per-frame detection (``--detector`` mode);
* estimate: weighted mean; then systematic resampling, vectorised over landmarks.

A landmark whose LK measurement is rejected is reported ``lost`` for that frame and carried by the
filter; it recovers once LK, started from the filter's estimate, finds it again. Randomness comes
from a seeded ``numpy.random.Generator``: the same input gives the same output.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FilterOptions:
    """Options of the CONDENSATION filter (lengths in pixels for a face of reference size;
    they are multiplied by the face scale, see :func:`facebasis.capture.landmarks.face_scale`).

    Attributes
    ----------
    n_particles : int
        Particles per landmark (16: with drift-corrected measurements 32 changed the landmark error
        by under 0.005 px on the ground-truth benchmark and cost a quarter of the frame time).
    process_noise : float
        Standard deviation of the motion model noise.
    measurement_sigma : float
        Standard deviation of the LK measurement likelihood.
    detection_sigma : float
        Standard deviation of the detection likelihood (``--detector`` mode).
    appearance_tau : float
        Temperature of the appearance likelihood ``exp((NCC - 1) / tau)``.
    patch_radius : int
        Template half size; templates are ``(2r+1) x (2r+1)`` samples spaced by the face scale.
    recovery_factor : float
        In the frame after a point was lost, its LK likelihood is widened by this factor.
    ncc_accept : float
        LK measurements whose patch NCC is below this are rejected (point reported lost).
    template_update : float
        NCC (against the first-frame template) above which the last-confident template is renewed.
    gate : float
        LK measurements farther than this from the motion prediction are rejected.
    neighbour_sigma : float
        Width of the neighbour weights, as a fraction of the face width.
    velocity_damping : float
        Factor on the previous velocity when no neighbour prediction exists.
    seed : int
        Seed of the random generator.
    """

    n_particles: int = 16
    process_noise: float = 1.5
    measurement_sigma: float = 0.5
    detection_sigma: float = 3.0
    appearance_tau: float = 0.1
    patch_radius: int = 4
    recovery_factor: float = 4.0
    ncc_accept: float = 0.8
    gate: float = 4.0
    template_update: float = 0.85
    neighbour_sigma: float = 0.2
    velocity_damping: float = 0.5
    seed: int = 0


def patch_offsets(radius: int) -> np.ndarray:
    """Pixel offsets of a ``(2r+1)^2`` square patch, shape ``(S, 2)``."""
    r = np.arange(-radius, radius + 1, dtype=np.float32)
    gx, gy = np.meshgrid(r, r)
    return np.stack([gx.ravel(), gy.ravel()], 1)


def _remap_points(img: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, int, tuple]:
    import cv2

    shape = pts.shape[:-1]
    flat = pts.reshape(-1, 2)
    n = len(flat)
    cols = 1024 if n > 1024 else max(n, 1)
    pad = (-n) % cols
    xy = np.zeros((n + pad, 2), np.float32)      # one interleaved CV_32FC2 map: no x / y split copies
    xy[:n] = flat
    return cv2.remap(img, xy.reshape(-1, cols, 2), None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), n, shape


def sample(img: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear samples of a float32 image at points ``(..., 2)`` -> ``(...)`` (border replicated)."""
    out, n, shape = _remap_points(img, pts)
    return out.ravel()[:n].reshape(shape)


def sample_channels(img: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear samples of a float32 image of C channels (H, W, C) at points ``(..., 2)`` -> ``(..., C)``
    (one remap for all channels; the same values as :func:`sample` on each channel)."""
    out, n, shape = _remap_points(img, pts)
    C = img.shape[2]
    return out.reshape(-1, C)[:n].reshape(shape + (C,))


def _normalise(p: np.ndarray) -> np.ndarray:
    p = p - p.mean(-1, keepdims=True)
    return p / np.sqrt((p * p).sum(-1, keepdims=True) + 1e-8)


def ncc(patches: np.ndarray, templates: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation of ``patches (L, ..., S)`` with ``templates (L, S)`` -> ``(L, ...)``."""
    a = _normalise(patches)
    t = _normalise(templates)
    t = t.reshape(t.shape[0], *([1] * (a.ndim - 2)), t.shape[-1])
    return (a * t).sum(-1)


def neighbour_weights(landmarks: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian weights between landmarks, zero diagonal, shape ``(L, L)``."""
    d2 = ((landmarks[:, None] - landmarks[None]) ** 2).sum(-1)
    W = np.exp(-d2 / (2 * sigma ** 2))
    np.fill_diagonal(W, 0.0)
    return W


class CondensationFilter:
    """Per-landmark CONDENSATION filter.

    Parameters
    ----------
    image : ndarray, shape (H, W) float32
        First frame, grey in ``[0, 1]``.
    landmarks : ndarray, shape (L, 2)
        First-frame landmarks.
    scale : float
        Face scale (multiplies the length options).
    options : FilterOptions
    """

    def __init__(self, image: np.ndarray, landmarks: np.ndarray, scale: float = 1.0,
                 options: FilterOptions = FilterOptions()):
        self.opt = options
        self.scale = float(scale)
        self.rng = np.random.default_rng(options.seed)
        lm = np.asarray(landmarks, float)
        self.L = len(lm)
        # (2r+1)^2 samples spaced by the face scale: the cost does not grow with the resolution
        self.offsets = patch_offsets(max(2, int(options.patch_radius))) * np.float32(self.scale)
        self.template0 = sample(image, lm[:, None, :] + self.offsets[None])  # (L, S)
        self.template = self.template0.copy()
        from .landmarks import face_width

        self.W = neighbour_weights(lm, options.neighbour_sigma * face_width(lm))
        self.particles = np.repeat(lm[:, None, :], options.n_particles, axis=1)  # (L, N, 2)
        self.estimate = lm.copy()
        self.velocity = np.zeros_like(lm)
        self.was_lost = np.zeros(self.L, bool)

    def place(self, idx: np.ndarray, points: np.ndarray) -> None:
        """Put landmarks ``idx`` (P,) at ``points`` (P, 2): their particles are moved by the same
        shift and their velocity is kept, so a caller that places points by a model (the inner lips
        of :class:`facebasis.capture.tracker.FaceTracker`) keeps the filter consistent."""
        shift = np.asarray(points, float) - self.estimate[idx]
        self.particles[idx] += shift[:, None, :]
        self.estimate[idx] = points

    def appearance(self, image: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """Best NCC of the patches at ``pts (L, ..., 2)`` against the two templates -> ``(L, ...)``.

        The patches are normalised once and compared with both (normalised) templates at once."""
        a = _normalise(sample(image, pts[..., None, :] + self.offsets))        # (L, ..., S)
        t = _normalise(np.stack([self.template0, self.template], 1))           # (L, 2, S)
        L, S = t.shape[0], t.shape[-1]
        c = a.reshape(L, -1, S) @ t.transpose(0, 2, 1)                        # (L, K, 2): batched products
        return c.max(-1).reshape(a.shape[:-1])

    def step(self, image: np.ndarray, measured: np.ndarray, measured_ok: np.ndarray,
             detections: np.ndarray | None = None, detection_sigma: np.ndarray | None = None,
             trusted: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Advance one frame.

        Parameters
        ----------
        image : ndarray, shape (H, W) float32
            The new frame, grey in ``[0, 1]``.
        measured : ndarray, shape (L, 2)
            LK positions in the new frame.
        measured_ok : ndarray, shape (L,) bool
            LK status and forward-backward check.
        detections : ndarray, shape (L, 2), optional
            Detected landmarks in the new frame (extra observations); rows of NaN are ignored.
        detection_sigma : ndarray, shape (L,), optional
            Standard deviation of each detection in pixels (the detector's measured noise, see
            :class:`facebasis.capture.detect.DetectionNoise`); default ``detection_sigma`` of the
            options times the face scale.
        trusted : ndarray, shape (L,) bool, optional
            Measurements verified elsewhere (drift correction against the first frame): confident
            whatever the NCC and gate tests say.

        Returns
        -------
        estimate : ndarray, shape (L, 2)
        lost : ndarray, shape (L,) bool
            LK measurement rejected in this frame (the point is carried by the filter).
        """
        o, s = self.opt, self.scale
        prev = self.estimate
        ncc_lk = self.appearance(image, measured[:, None, :])[:, 0]
        conf = measured_ok & (ncc_lk >= o.ncc_accept)
        trusted = np.zeros(self.L, bool) if trusted is None else np.asarray(trusted, bool)
        # motion model: neighbour-predicted displacement, else damped constant velocity
        disp = np.where(conf[:, None], measured - prev, 0.0)
        Wc = self.W * conf[None, :]
        wsum = Wc.sum(1, keepdims=True)
        pred = np.where(wsum > 1e-3, (Wc @ disp) / np.maximum(wsum, 1e-12), o.velocity_damping * self.velocity)
        # gate: an LK measurement far from the motion prediction is rejected as an outlier
        conf &= np.linalg.norm(measured - (prev + pred), axis=1) <= o.gate * s
        conf |= trusted
        sp2 = (o.process_noise * s) ** 2
        # a point lost in the previous frame gets a weak LK likelihood for one frame, so the
        # appearance against the templates can pull it back onto its feature (recovery)
        sm2 = (o.measurement_sigma * s) ** 2 * np.where(self.was_lost, o.recovery_factor ** 2, 1.0)[:, None, None]
        P = self.particles + pred[:, None, :] + np.sqrt(sp2) * self.rng.standard_normal(self.particles.shape)
        # Rao-Blackwellised measurement update: every particle is a Gaussian N(x_i, sp2) whose
        # fusion with a confident LK measurement z is analytic (mean mu_i, variance post2), and
        # whose weight carries the marginal likelihood N(z; x_i, sp2 + sm2). Lost points: mu_i = x_i.
        c3 = conf[:, None, None]
        k = np.where(c3, sp2 / (sp2 + sm2), 0.0)
        mu = P + k * (measured[:, None, :] - P)
        post_sd = np.sqrt(np.where(c3, sp2 * sm2 / (sp2 + sm2), sp2))
        d2 = ((P - measured[:, None, :]) ** 2).sum(-1)
        logw = -np.where(conf[:, None], d2 / (2 * (sp2 + sm2[..., 0])), 0.0)
        # appearance likelihood of every particle (at its fused mean)
        logw = logw + (self.appearance(image, mu) - 1.0) / o.appearance_tau
        # per-frame detections, if any
        if detections is not None:
            det = np.asarray(detections, float)
            dvalid = np.all(np.isfinite(det), axis=1)
            dd2 = ((mu - np.where(dvalid[:, None], det, 0.0)[:, None, :]) ** 2).sum(-1)
            sd2 = ((o.detection_sigma * s) ** 2 if detection_sigma is None
                   else np.asarray(detection_sigma, float)[:, None] ** 2)
            logw = logw - np.where(dvalid[:, None], dd2 / (2 * sd2), 0.0)
        logw = logw - logw.max(1, keepdims=True)
        w = np.exp(logw)
        w /= w.sum(1, keepdims=True)
        est = (w[..., None] * mu).sum(1)
        # systematic resampling of the mixture components, all landmarks at once
        N = P.shape[1]
        cum = np.cumsum(w, axis=1)
        cum[:, -1] = 1.0
        u = (self.rng.random((self.L, 1)) + np.arange(N)[None]) / N
        rows = np.arange(self.L)[:, None]
        idx = np.searchsorted((cum + rows).ravel(), (u + rows).ravel()).reshape(self.L, N) - rows * N
        idx = np.clip(idx, 0, N - 1)
        self.particles = mu[rows, idx] + post_sd * self.rng.standard_normal(P.shape)
        # renew the last-confident template where the estimate still looks like the first frame
        patch = sample(image, est[:, None, :] + self.offsets[None])
        renew = conf & (ncc(patch, self.template0) >= o.template_update)
        self.template = np.where(renew[:, None], patch, self.template)
        self.velocity = est - prev
        self.estimate = est
        self.was_lost = ~conf
        return est.copy(), ~conf
