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
