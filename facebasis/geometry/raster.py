"""Flat-shaded rasterisation of a triangle mesh into an RGB image with numpy (no OpenGL).

The video-frame counterpart of :func:`facebasis.report.render.draw_mesh` (same shading), fast
enough for a preview video: see :func:`rasterize_mesh`.
"""

from __future__ import annotations

import numpy as np


SKIN_RGB = (0.85, 0.78, 0.72)
LIGHT = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])


def rasterize_mesh(P, F, size, color=SKIN_RGB, background=(255, 255, 255), out=None) -> np.ndarray:
    """Flat-shaded image of a mesh already in pixel coordinates, for video frames (no OpenGL).

    The same shading as :func:`facebasis.report.render.draw_mesh` (``0.25 + 0.75 |n . light|``), but rasterised with numpy
    instead of a matplotlib PolyCollection (which needs ~0.3 s for a 28k-triangle face): front-facing
    triangles are cut into pixel rows (one span per triangle and row whose
    pixel centres it covers, from its edges' crossings of the row), the spans are expanded into
    pixels, and a z-buffer keeps the nearest triangle per pixel (``np.maximum.at`` on a key of the
    triangle's quantised mean depth and its index; flat shading needs no per-pixel depth). No
    Python loop over triangles or pixels; at most 2^22 triangles.

    Parameters
    ----------
    P : (n, 3) x right and y down in pixels, z towards the viewer
    F : (m, 3) triangles (counter-clockwise seen from the viewer in a y-up frame)
    size : (height, width) of the image
    color : RGB in [0, 1] of the surface; background : RGB uint8
    out : optional (height, width, 3) uint8 array to draw into (else a new one)

    Returns
    -------
    (height, width, 3) uint8
    """
    H, W = int(size[0]), int(size[1])
    img = np.empty((H, W, 3), np.uint8) if out is None else out
    img[:] = np.asarray(background, np.uint8)
    tri = np.asarray(P, np.float32)[np.asarray(F)]                       # (m, 3, 3), float32: half the traffic
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]                     # < 0: front-facing (y down)
    ty, tx = tri[:, :, 1], tri[:, :, 0]                                  # (elementwise: axis-1 reductions
    ymin = np.minimum(np.minimum(ty[:, 0], ty[:, 1]), ty[:, 2])          #  over 3 are slow in numpy)
    ymax = np.maximum(np.maximum(ty[:, 0], ty[:, 1]), ty[:, 2])
    y0 = np.maximum(np.ceil(ymin - 0.5), 0).astype(np.int64)             # first pixel row
    y1 = np.minimum(np.floor(ymax - 0.5), H - 1).astype(np.int64)        # last pixel row
    keep = ((area < -1e-12) & (y1 >= y0) & (np.maximum(np.maximum(tx[:, 0], tx[:, 1]), tx[:, 2]) >= 0)
            & (np.minimum(np.minimum(tx[:, 0], tx[:, 1]), tx[:, 2]) <= W))
    if not keep.any():
        return img
    tri, y0, y1 = tri[keep], y0[keep], y1[keep]
    n = np.cross(e1[keep], e2[keep])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-300
    rgb = np.clip(np.outer(0.25 + 0.75 * np.abs(n @ LIGHT), np.asarray(color, float)) * 255.0, 0, 255).astype(np.uint8)
    # z-buffer key: the triangle's mean depth quantised to 2^20 levels in the high bits, its index in
    # the low ones (no sort: the largest key at a pixel is the nearest triangle)
    z = tri[:, 0, 2] + tri[:, 1, 2] + tri[:, 2, 2]
    span = float(z.max() - z.min())
    zq = ((z - z.min()) * ((2 ** 20 - 1) / span if span > 0 else 0.0)).astype(np.int64)
    key = (zq << 22) | np.arange(len(z), dtype=np.int64)
    # per triangle and edge (a -> b): x at the row, x = xa + (y - ya) dx/dy, on ya <= y <= yb
    a, b = tri[:, [0, 1, 2], :2], tri[:, [1, 2, 0], :2]                  # (m, 3, 2)
    lo_y, hi_y = np.minimum(a[..., 1], b[..., 1]), np.maximum(a[..., 1], b[..., 1])
    dy = b[..., 1] - a[..., 1]
    slope = np.where(dy != 0, (b[..., 0] - a[..., 0]) / np.where(dy != 0, dy, 1.0), 0.0)
    coef = np.concatenate([a[..., 0], a[..., 1], slope, lo_y, hi_y], axis=1)       # (m, 15)
    rows = y1 - y0 + 1
    tid = np.repeat(np.arange(len(rows)), rows)
    yc = (y0[tid] + (np.arange(int(rows.sum())) - np.repeat(np.cumsum(rows) - rows, rows))).astype(np.float32) + 0.5
    c = coef[tid]                                                        # (S, 15) one gather
    ycol = yc[:, None]
    x = c[:, 0:3] + (ycol - c[:, 3:6]) * c[:, 6:9]
    on = (ycol >= c[:, 9:12]) & (ycol <= c[:, 12:15])
    xa, xb = np.where(on, x, np.inf), np.where(on, x, -np.inf)
    xl = np.minimum(np.minimum(xa[:, 0], xa[:, 1]), xa[:, 2])
    xr = np.maximum(np.maximum(xb[:, 0], xb[:, 1]), xb[:, 2])
    x0 = np.maximum(np.ceil(xl - 0.5), 0)
    x1 = np.minimum(np.floor(xr - 0.5), W - 1)
    cnt = np.maximum(x1 - x0 + 1, 0).astype(np.int64)
    start = (yc.astype(np.int64) * W + np.where(cnt > 0, x0, 0).astype(np.int64))
    pid = np.repeat(np.arange(len(cnt)), cnt)
    pix = np.repeat(start, cnt) + (np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    zbuf = np.full(H * W, -1, np.int64)
    np.maximum.at(zbuf, pix, key[tid[pid]])                              # nearest triangle per pixel
    hit = zbuf >= 0
    img.reshape(-1, 3)[hit] = rgb[zbuf[hit] & ((1 << 22) - 1)]
    return img


__all__ = ["rasterize_mesh", "SKIN_RGB", "LIGHT"]
