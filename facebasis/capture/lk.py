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


def lk_refine(ref_img, img, ref_points: np.ndarray, guess: np.ndarray, windows: np.ndarray, levels: int = 1,
              max_shift: float = 1.0, fb_threshold: float | None = None) -> LKResult:
    """Drift correction: refine frame-to-frame positions against the first frame's appearance.

    The template update with drift correction of Matthews, Ishikawa & Baker (2004, "The template
    update problem", strategy 3), per landmark with a translation warp: LK is run from the
    *reference* (first) frame's patch at ``ref_points`` into ``img``, starting at ``guess`` (the
    frame-to-frame estimate, ``cv2.OPTFLOW_USE_INITIAL_FLOW``), over few pyramid levels. The
    refined position is accepted where LK converged within ``max_shift`` of the guess (and, with
    ``fb_threshold``, where tracking it back lands within that distance of the reference point);
    elsewhere (the appearance changed too much: an opened mouth, a closed eye) the frame-to-frame
    estimate stands. Frame-to-frame errors then no longer add up over the take.

    Parameters
    ----------
    ref_img, img : ndarray
        Reference (first) frame and new frame, from :func:`build_pyramid`.
    ref_points : ndarray, shape (L, 2)
        Landmarks in the reference frame.
    guess : ndarray, shape (L, 2)
        Frame-to-frame positions in the new frame.
    windows : ndarray, shape (L, 2) int
        LK window per point.
    levels : int
        Pyramid levels above the base image (the guess is close: 1 is enough).
    max_shift : float
        Largest accepted move from the guess (pixels).
    fb_threshold : float, optional
        Backward check limit (pixels); None skips the backward pass.

    Returns
    -------
    LKResult
        ``points``: refined positions where accepted, else ``guess``; ``ok``: accepted;
        ``fb_error``: distance moved from the guess (``inf`` where LK failed).
    """
    import cv2

    p0 = np.asarray(ref_points, np.float32).reshape(-1, 1, 2)
    g = np.asarray(guess, np.float32).reshape(-1, 1, 2)
    out = g.copy()
    moved = np.full(len(p0), np.inf)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    wins, group = np.unique(windows, axis=0, return_inverse=True)
    group = group.ravel()
    for k, w in enumerate(wins):  # one call per window size (a handful of groups)
        idx = np.flatnonzero(group == k)
        ws = (int(w[0]), int(w[1]))
        p1, st, _ = cv2.calcOpticalFlowPyrLK(ref_img, img, p0[idx], g[idx].copy(), winSize=ws, maxLevel=levels,
                                             criteria=crit, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        good = st.ravel() == 1
        if fb_threshold is not None:
            pb, st2, _ = cv2.calcOpticalFlowPyrLK(img, ref_img, p1, p0[idx].copy(), winSize=ws, maxLevel=levels,
                                                  criteria=crit, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
            good &= (st2.ravel() == 1) & (np.linalg.norm((pb - p0[idx]).reshape(-1, 2), axis=1) <= fb_threshold)
        out[idx] = p1
        moved[idx] = np.where(good, np.linalg.norm((p1 - g[idx]).reshape(-1, 2), axis=1), np.inf)
    pts = out.reshape(-1, 2).astype(float)
    ok = (moved <= max_shift) & np.all(np.isfinite(pts), axis=1)
    return LKResult(np.where(ok[:, None], pts, np.asarray(guess, float)), ok, moved)


def local_affine(V0: np.ndarray, Vt: np.ndarray, centres: np.ndarray, sigma: float) -> np.ndarray:
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
    """
    d0 = V0[None, :, :] - V0[centres][:, None, :]          # (P, N, 2)
    dt = Vt[None, :, :] - Vt[centres][:, None, :]
    w = np.exp(-(d0 ** 2).sum(-1) / (2 * sigma ** 2))      # (P, N)
    M = np.einsum("pn,pna,pnb->pab", w, d0, d0)
    Nm = np.einsum("pn,pna,pnb->pab", w, dt, d0)
    det = M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
    ok = det > 1e-9 * np.maximum(M[:, 0, 0] + M[:, 1, 1], 1e-12) ** 2
    Minv = np.stack([np.stack([M[:, 1, 1], -M[:, 0, 1]], -1), np.stack([-M[:, 1, 0], M[:, 0, 0]], -1)], 1)
    Minv = Minv / np.where(ok, det, 1.0)[:, None, None]
    A = np.einsum("pab,pbc->pac", Nm, Minv)
    return np.where(ok[:, None, None], A, np.eye(2)[None])


def patch_grid(windows: np.ndarray, samples: int = 11) -> np.ndarray:
    """Sample offsets of each point's LK window, ``(L, S, 2)`` (a ``samples x samples`` grid)."""
    u = np.linspace(-1.0, 1.0, samples)
    gx, gy = np.meshgrid(u, u)
    unit = np.stack([gx.ravel(), gy.ravel()], 1)            # (S, 2)
    half = (np.asarray(windows, float) - 1.0) / 2.0          # (L, 2)
    return unit[None] * half[:, None, :]


def template_align(template: np.ndarray, offsets: np.ndarray, prep, guess: np.ndarray, A: np.ndarray,
                   iterations: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Align first-frame patches to the new frame under a known local affine (drift correction).

    Gauss-Newton on the translation ``p`` of ``sum_k w_k (I_t(p + A o_k) - mean - (T_k - mean))^2``
    per point (zero-mean patches: insensitive to a brightness offset), started at ``guess``. ``A``
    (from :func:`local_affine`, the mesh's deformation since frame 0) warps the template's sample
    grid, so a stretched lip or a rotated head does not bias the match as a translation-only
    template would (Matthews, Ishikawa & Baker 2004 drift correction with the warp of Baker &
    Matthews' LK framework restricted to translation once the affine part is known).

    Parameters
    ----------
    template : ndarray, shape (L, S)
        Frame-0 samples at ``p0 + offsets`` (blurred image).
    offsets : ndarray, shape (L, S, 2)
        Sample offsets (:func:`patch_grid`).
    prep : tuple
        ``(image, gx, gy)`` of the new frame (:func:`facebasis.capture.meshtrack.prepare_image`).
    guess : ndarray, shape (L, 2)
    A : ndarray, shape (L, 2, 2)
    iterations : int

    Returns
    -------
    points : ndarray, shape (L, 2)
    zncc : ndarray, shape (L,)
        Zero-mean normalised correlation of the aligned patch with the template.
    conditioning : ndarray, shape (L,)
        Smallest eigenvalue over the largest of the Gauss-Newton matrix (aperture problem when ~0).
    """
    from .particle import sample

    img, gx, gy = prep
    off = np.einsum("lab,lsb->lsa", A, offsets)            # (L, S, 2)
    r2 = (offsets ** 2 / np.maximum((offsets ** 2).max(1, keepdims=True), 1e-12)).sum(-1)
    w = np.exp(-r2)                                         # (L, S) Gaussian window
    w = w / w.sum(1, keepdims=True)
    T = template - (w * template).sum(1, keepdims=True)
    p = np.asarray(guess, float).copy()
    for _ in range(iterations):
        X = p[:, None, :] + off
        I = sample(img, X)
        J = np.stack([sample(gx, X), sample(gy, X)], -1)    # (L, S, 2)
        I = I - (w * I).sum(1, keepdims=True)
        J = J - (w[..., None] * J).sum(1, keepdims=True)
        r = I - T
        H = np.einsum("ls,lsa,lsb->lab", w, J, J)
        b = np.einsum("ls,lsa,ls->la", w, J, r)
        det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] ** 2
        det = np.where(det > 1e-18, det, np.inf)
        dp = -np.stack([H[:, 1, 1] * b[:, 0] - H[:, 0, 1] * b[:, 1],
                        H[:, 0, 0] * b[:, 1] - H[:, 0, 1] * b[:, 0]], 1) / det[:, None]
        step = np.linalg.norm(dp, axis=1, keepdims=True)
        p = p + dp * np.minimum(1.0, 1.0 / np.maximum(step, 1e-12))   # at most 1 px per step
        if float(step.max()) < 1e-2:
            break
    X = p[:, None, :] + off
    I = sample(img, X)
    I = I - (w * I).sum(1, keepdims=True)
    zn = (w * I * T).sum(1) / np.sqrt((w * I * I).sum(1) * (w * T * T).sum(1) + 1e-12)
    tr = H[:, 0, 0] + H[:, 1, 1]
    disc = np.sqrt(np.maximum((H[:, 0, 0] - H[:, 1, 1]) ** 2 / 4 + H[:, 0, 1] ** 2, 0))
    cond = (tr / 2 - disc) / np.maximum(tr / 2 + disc, 1e-18)
    return p, zn, cond
