"""Pyramidal Lucas-Kanade tracking of landmarks with region-dependent windows (Wu & Ju 2016, sec. 4.1).

Points are grouped by window size and each group is tracked with one call of
``cv2.calcOpticalFlowPyrLK``. A forward-backward check
(track ``I_n -> I_{n+1}`` then back) flags unreliable points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LKResult:
    """Lucas-Kanade measurements for one frame.

    Attributes
    ----------
    points : ndarray, shape (L, 2)
        Tracked positions in the new frame (pixels).
    ok : ndarray, shape (L,)
        LK converged and the forward-backward error is below the threshold.
    fb_error : ndarray, shape (L,)
        Forward-backward error (pixels); ``inf`` where LK failed.
    """

    points: np.ndarray
    ok: np.ndarray
    fb_error: np.ndarray


def build_pyramid(img_u8: np.ndarray, win: tuple[int, int], levels: int):
    """Image handed to LK for a frame.

    OpenCV 5's Python binding of ``calcOpticalFlowPyrLK`` no longer accepts prebuilt pyramids, so
    this returns the contiguous uint8 image and OpenCV builds the pyramid inside each call.
    """
    return np.ascontiguousarray(img_u8)


def lk_track(prev_pyr, next_pyr, points: np.ndarray, windows: np.ndarray, levels: int = 3,
             fb_threshold: float = 1.0) -> LKResult:
    """Track points from the previous to the next frame.

    Parameters
    ----------
    prev_pyr, next_pyr : ndarray
        Images from :func:`build_pyramid`.
    points : ndarray, shape (L, 2)
        Positions in the previous frame.
    windows : ndarray, shape (L, 2) int
        LK window ``(width, height)`` per point.
    levels : int
        Pyramid levels above the base image.
    fb_threshold : float
        Maximum forward-backward error (pixels) for ``ok``.

    Returns
    -------
    LKResult
    """
    import cv2

    pts = np.asarray(points, np.float32).reshape(-1, 1, 2)
    out = pts.copy()
    fb = np.full(len(pts), np.inf)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    wins, group = np.unique(windows, axis=0, return_inverse=True)
    group = group.ravel()
    for g, w in enumerate(wins):  # one call per window size (a handful of groups)
        idx = np.flatnonzero(group == g)
        p0 = pts[idx]
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev_pyr, next_pyr, p0, None, winSize=(int(w[0]), int(w[1])),
                                              maxLevel=levels, criteria=crit)
        pb, st2, _ = cv2.calcOpticalFlowPyrLK(next_pyr, prev_pyr, p1, None, winSize=(int(w[0]), int(w[1])),
                                              maxLevel=levels, criteria=crit)
        good = (st1.ravel() == 1) & (st2.ravel() == 1)
        err = np.linalg.norm((pb - p0).reshape(-1, 2), axis=1)
        out[idx] = p1
        fb[idx] = np.where(good, err, np.inf)
    pts_out = out.reshape(-1, 2).astype(float)
    ok = np.isfinite(fb) & (fb <= fb_threshold) & np.all(np.isfinite(pts_out), axis=1)
    return LKResult(pts_out, ok, fb)


def local_affine_factor(V0: np.ndarray, centres: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame-0 part of :func:`local_affine`, computed once per take.

    Returns
    -------
    wd0 : ndarray, shape (P, 2, N)
        ``w_ij d0_ij`` (transposed for batched products).
    Minv : ndarray, shape (P, 2, 2)
        Inverse of ``sum_j w_ij d0_ij d0_ij^T`` (identity where singular).
    ok : ndarray, shape (P,) bool
        Where that matrix is invertible.
    """
    d0 = V0[None, :, :] - V0[centres][:, None, :]          # (P, N, 2)
    w = np.exp(-(d0 ** 2).sum(-1) / (2 * sigma ** 2))      # (P, N)
    wd0 = np.ascontiguousarray((w[..., None] * d0).transpose(0, 2, 1))   # (P, 2, N): batched products
    M = wd0 @ d0
    det = M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
    ok = det > 1e-9 * np.maximum(M[:, 0, 0] + M[:, 1, 1], 1e-12) ** 2
    Minv = np.stack([np.stack([M[:, 1, 1], -M[:, 0, 1]], -1), np.stack([-M[:, 1, 0], M[:, 0, 0]], -1)], 1)
    Minv = Minv / np.where(ok, det, 1.0)[:, None, None]
    return wd0, np.where(ok[:, None, None], Minv, np.eye(2)[None]), ok


def local_affine(V0: np.ndarray, Vt: np.ndarray, centres: np.ndarray, sigma: float,
                 factor: tuple | None = None) -> np.ndarray:
    """Per-point linear part of the local affine map from frame 0 to frame t, ``(P, 2, 2)``.

    Weighted least squares over all mesh vertices with Gaussian weights of their frame-0 distance to
    each centre: ``A_i = (sum_j w_ij dt_ij d0_ij^T) (sum_j w_ij d0_ij d0_ij^T)^-1`` with
    ``d0_ij = V0_j - V0_i``, ``dt_ij = Vt_j - Vt_i`` (``i`` = ``centres``).

    Parameters
    ----------
    V0, Vt : ndarray, shape (N, 2)
        Mesh vertices in frame 0 and frame t.
    centres : ndarray, shape (P,) int
        Vertex indices of the points.
    sigma : float
        Width of the weights (pixels, frame 0).
    factor : tuple, optional
        :func:`local_affine_factor` of ``(V0, centres, sigma)``: everything that depends on frame 0
        only, so a tracker computes it once and each frame costs two batched products.
    """
    wd0, Minv, ok = local_affine_factor(V0, centres, sigma) if factor is None else factor
    dt = Vt[None, :, :] - Vt[centres][:, None, :]          # (P, N, 2)
    A = (wd0 @ dt).transpose(0, 2, 1) @ Minv
    return np.where(ok[:, None, None], A, np.eye(2)[None])


def patch_grid(windows: np.ndarray, samples: int = 11) -> np.ndarray:
    """Sample offsets of each point's LK window, ``(L, S, 2)`` (a ``samples x samples`` grid)."""
    u = np.linspace(-1.0, 1.0, samples)
    gx, gy = np.meshgrid(u, u)
    unit = np.stack([gx.ravel(), gy.ravel()], 1)            # (S, 2)
    half = (np.asarray(windows, float) - 1.0) / 2.0          # (L, 2)
    return unit[None] * half[:, None, :]


def template_align(template: np.ndarray, offsets: np.ndarray, prep, guess: np.ndarray, A: np.ndarray,
                   iterations: int = 8, affine: bool = True,
                   affine_damping: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Align first-frame patches to the new frame (drift correction, affine warp).

    Gauss-Newton on ``sum_k w_k (I_t(p + A o_k) - mean - (T_k - mean))^2`` per point over the
    translation ``p`` and (``affine=True``) the linear part ``A`` of the warp, started at ``guess``
    and at ``A`` from :func:`local_affine` (the mesh's deformation since frame 0). This is the
    affine warp of the Lucas-Kanade framework (Baker & Matthews 2004) used as the drift-correction
    step of Matthews, Ishikawa & Baker (2004): a stretched lip or a turned head does not bias the
    match as a translation-only template would. Zero-mean patches make it insensitive to a
    brightness offset; a damping ``affine_damping`` times the mean diagonal of the normal matrix on
    the ``A`` block keeps weakly textured patches near the mesh's ``A``.

    Parameters
    ----------
    template : ndarray, shape (L, S)
        Frame-0 samples at ``p0 + offsets`` (blurred image).
    offsets : ndarray, shape (L, S, 2)
        Sample offsets (:func:`patch_grid`).
    prep : ndarray, shape (H, W, 3) float32
        The new frame's blurred image and its x, y gradients stacked (:func:`drift_image`), so that one
        remap samples all three.
    guess : ndarray, shape (L, 2)
    A : ndarray, shape (L, 2, 2)
    iterations : int
    affine : bool
        Also solve for ``A`` (else translation only under the given ``A``).
    affine_damping : float

    Returns
    -------
    points : ndarray, shape (L, 2)
    zncc : ndarray, shape (L,)
        Zero-mean normalised correlation of the aligned patch with the template.
    A : ndarray, shape (L, 2, 2)
        Final linear part.
    """
    from .particle import sample_channels

    L = len(template)
    r2 = (offsets ** 2 / np.maximum((offsets ** 2).max(1, keepdims=True), 1e-12)).sum(-1)
    w = np.exp(-r2)                                         # (L, S) Gaussian window
    w = w / w.sum(1, keepdims=True)
    T = template - (w * template).sum(1, keepdims=True)
    p = np.asarray(guess, float).copy()
    A = np.asarray(A, float).copy()
    npar = 6 if affine else 2
    for _ in range(iterations):
        X = p[:, None, :] + offsets @ A.transpose(0, 2, 1)
        IG = sample_channels(prep, X)                       # (L, S, 3)
        I, G = IG[..., 0], IG[..., 1:]                      # G: (L, S, 2)
        if affine:   # d X / d A_ab = e_a o_b
            J = np.concatenate([G, G[..., :1] * offsets, G[..., 1:] * offsets], -1)   # (L, S, 6)
        else:
            J = G
        I = I - (w * I).sum(1, keepdims=True)
        J = J - (w[..., None] * J).sum(1, keepdims=True)
        r = I - T
        Jw = (J * w[..., None]).transpose(0, 2, 1)          # (L, P, S): batched BLAS products
        H = Jw @ J
        b = (Jw @ r[..., None])[..., 0]
        if affine:
            d = affine_damping * np.diagonal(H, axis1=1, axis2=2)[:, 2:].mean(1)
            H[:, np.arange(2, 6), np.arange(2, 6)] += d[:, None]
        H[:, np.arange(npar), np.arange(npar)] += 1e-12
        dq = -np.linalg.solve(H, b[..., None])[..., 0]
        step = np.linalg.norm(dq[:, :2], axis=1, keepdims=True)
        scale = np.minimum(1.0, 1.0 / np.maximum(step, 1e-12))   # at most 1 px per step
        dq = dq * scale
        p = p + dq[:, :2]
        if affine:
            A = A + dq[:, 2:].reshape(L, 2, 2)
        if float(step.max()) < 1e-2:
            break
    X = p[:, None, :] + offsets @ A.transpose(0, 2, 1)
    I = sample_channels(prep, X)[..., 0]
    I = I - (w * I).sum(1, keepdims=True)
    zn = (w * I * T).sum(1) / np.sqrt((w * I * I).sum(1) * (w * T * T).sum(1) + 1e-12)
    return p, zn, A


def drift_image(gray: np.ndarray, points: np.ndarray, sigma: float, margin: float):
    """Blurred image and gradients (:func:`facebasis.capture.meshtrack.prepare_image`) of the box around
    ``points (L, 2)`` widened by ``margin`` pixels (the part the drift correction samples), stacked
    (h, w, 3) float32, and the box's top-left corner ``(2,)``: points in it are ``points - corner``."""
    import cv2

    from .meshtrack import prepare_image

    h, w = gray.shape
    pts = np.asarray(points, float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if not len(pts):
        return cv2.merge(list(prepare_image(gray, sigma))), np.zeros(2)
    x0, y0 = np.clip(np.floor(pts.min(0) - margin).astype(int), 0, [w - 1, h - 1])
    x1, y1 = np.clip(np.ceil(pts.max(0) + margin).astype(int) + 1, [x0 + 1, y0 + 1], [w, h])
    box = prepare_image(np.ascontiguousarray(gray[y0:y1, x0:x1]), sigma)
    return cv2.merge(list(box)), np.array([x0, y0], float)


class DriftTemplates:
    """First-frame patches of the drift correction, sampled on a ``samples x samples`` grid over each
    point's LK window, and on a denser ``dense_samples`` grid for the points in ``dense``.

    The patches are taken from, and aligned on, the image blurred by ``sigma`` (``drift_blur`` of
    :class:`facebasis.capture.options.TrackerOptions` times the face scale) in a box around the
    points (:func:`drift_image`). A thin feature, such as a closed mouth's lip line on which the
    inner-lip points sit, can fall between the rows of a 7 x 7 grid over a 15 px window (2.3 px
    apart) at that small blur, and the alignment then slides along it (a drawn 1 px lip line: the
    inner-lip points 2.1 px off on average over 11 frames); a 15 x 15 grid (1 px apart) sees it
    (0.75 px). Only those few points pay for the denser grid.

    Parameters
    ----------
    gray : ndarray, shape (H, W) float32
        Frame 0 (grey levels).
    points : ndarray, shape (L, 2)
    windows : ndarray, shape (L, 2)
        LK windows (the patch extents).
    dense : ndarray, shape (P,) int
        Points sampled on the dense grid.
    sigma : float
        Blur in pixels.
    margin : float
        Width of the box around the points (pixels): the largest window plus the largest motion.
    samples, dense_samples : int
    """

    def __init__(self, gray: np.ndarray, points: np.ndarray, windows: np.ndarray, dense: np.ndarray,
                 sigma: float, margin: float, samples: int = 7, dense_samples: int = 15):
        from .particle import sample

        self.sigma, self.margin = float(sigma), float(margin)
        stacked, o = drift_image(gray, points, self.sigma, self.margin)
        image = np.ascontiguousarray(stacked[..., 0])
        is_dense = np.zeros(len(points), bool)
        is_dense[np.asarray(dense, np.int64)] = True
        self.groups = []
        for idx, n in ((np.flatnonzero(~is_dense), samples), (np.flatnonzero(is_dense), dense_samples)):
            if len(idx):
                off = patch_grid(windows[idx], n)
                self.groups.append((idx, off, sample(image, points[idx, None, :] - o + off)))

    def align(self, gray: np.ndarray, guess: np.ndarray, A: np.ndarray, around: np.ndarray,
              **kw) -> tuple[np.ndarray, np.ndarray]:
        """:func:`template_align` of every group on ``gray (H, W)`` from ``guess (L, 2)`` and ``A (L, 2, 2)``;
        the image is blurred in the box around ``guess`` and ``around (K, 2)`` (the previous points).
        Returns points ``(L, 2)`` and their ZNCC ``(L,)``."""
        prep, o = drift_image(gray, np.concatenate([guess, around]), self.sigma, self.margin)
        p, zn = np.array(guess, float) - o, np.zeros(len(guess))
        for idx, off, tmpl in self.groups:
            p[idx], zn[idx], _ = template_align(tmpl, off, prep, p[idx], A[idx], **kw)
        return p + o, zn
