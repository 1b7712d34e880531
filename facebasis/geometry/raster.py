"""Flat-shaded rasterisation of a triangle mesh into an RGB image with numpy (no OpenGL).

The video-frame counterpart of :func:`facebasis.report.render.draw_mesh` (same shading), fast
enough for a preview video: see :func:`rasterize_mesh`.
"""

from __future__ import annotations

import numpy as np


SKIN_RGB = (0.85, 0.78, 0.72)
LIGHT = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])


def shade(normals) -> np.ndarray:
    """Flat shading ``0.25 + 0.75 |n . LIGHT|`` (m,) of unit triangle normals (m, 3): both sides lit alike."""
    return 0.25 + 0.75 * np.abs(normals @ LIGHT)


def rasterize_mesh(P, F, size, color=SKIN_RGB, background=(255, 255, 255), out=None) -> np.ndarray:
    """Flat-shaded image of a mesh already in pixel coordinates, for video frames (no OpenGL).

    The same shading as :func:`facebasis.report.render.draw_mesh` (:func:`shade`), but
    rasterised with numpy instead of a matplotlib PolyCollection (slow and memory-hungry for
    tens of thousands of triangles): front-facing triangles are cut into pixel rows (one span per triangle and
    row whose pixel centres it covers, between the long edge of the y-sorted triangle and its
    current short edge), the spans are expanded into pixels, and a z-buffer keeps the nearest triangle per pixel (``np.maximum.at`` on a key of the
    triangle's quantised mean depth and its index; flat shading needs no per-pixel depth). No
    Python loop over triangles or pixels; at most 2^22 triangles.

    Parameters
    ----------
    P : (n, 3) x right and y down in pixels, z towards the viewer
    F : (m, 3) triangles (counter-clockwise seen from the viewer in a y-up frame)
    size : (height, width) of the image
    color : RGB in [0, 1] of the surface, one (3,) or one per triangle (m, 3); background : RGB uint8
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
    col = np.asarray(color, float)
    col = col[keep] if col.ndim == 2 else col
    rgb = np.clip(shade(n)[:, None] * col * 255.0, 0, 255).astype(np.uint8)
    # z-buffer key: the triangle's mean depth quantised to 2^20 levels in the high bits, its index in
    # the low ones (no sort: the largest key at a pixel is the nearest triangle)
    z = tri[:, 0, 2] + tri[:, 1, 2] + tri[:, 2, 2]
    span = float(z.max() - z.min())
    zq = ((z - z.min()) * ((2 ** 20 - 1) / span if span > 0 else 0.0)).astype(np.int64)
    key = (zq << 22) | np.arange(len(z), dtype=np.int64)
    # vertices sorted by y (top t, middle m, bottom b): each row's span lies between the long edge
    # t -> b and the short edge t -> m above the middle vertex, m -> b below it
    ty, tx = tri[:, :, 1], tri[:, :, 0]
    o = np.argsort(ty, axis=1)
    r = np.arange(len(tri))[:, None]
    sy, sx = ty[r, o], tx[r, o]                                          # (m, 3) sorted by y

    def slope(i, j):
        d = sy[:, j] - sy[:, i]
        return np.where(d > 0, (sx[:, j] - sx[:, i]) / np.where(d > 0, d, 1), 0).astype(np.float32)

    coef = np.stack([sx[:, 0], sy[:, 0], slope(0, 2), slope(0, 1), sx[:, 1], sy[:, 1], slope(1, 2)], 1)
    rows = y1 - y0 + 1
    tid = np.repeat(np.arange(len(rows)), rows)
    yc = (y0[tid] + (np.arange(int(rows.sum())) - np.repeat(np.cumsum(rows) - rows, rows))).astype(np.float32) + 0.5
    c = coef[tid]                                                        # (S, 7) one gather
    x_long = c[:, 0] + (yc - c[:, 1]) * c[:, 2]
    x_short = np.where(yc < c[:, 5], c[:, 0] + (yc - c[:, 1]) * c[:, 3], c[:, 4] + (yc - c[:, 5]) * c[:, 6])
    xl = np.minimum(x_long, x_short)
    xr = np.maximum(x_long, x_short)
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
