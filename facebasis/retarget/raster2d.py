"""Piecewise-affine image warps: a triangle mesh's destination pixels mapped to their source points.

Every destination pixel inside a moved triangle takes the colour of the corresponding point (same
barycentric coordinates) of that triangle at its source position, sampled bilinearly (the 2D
reproduction's warp, Wu & Ju 2016, used by :mod:`.warp2d`). Pixels outside the mesh keep the
source image.

The rasteriser is a vectorised scanline: the (triangle, row) pairs of all bounding boxes are
enumerated at once (``np.repeat`` of per-triangle row counts), each pair's exact pixel span follows
from the triangle's three barycentric (edge) functions, and the spans are expanded to pixels whose
source coordinates go into a ``cv2.remap`` map. No Python loop runs over pixels or triangles.
"""

from __future__ import annotations

import numpy as np

#: a pixel counts as inside a triangle if all its barycentric coordinates are >= -INSIDE_TOL
INSIDE_TOL = 1e-5


def _edge_functions(dst: np.ndarray, faces: np.ndarray):
    """Barycentric (edge) functions of the destination triangles in closed form.

    Returns a, b, c (M, 3) with ``lambda_i(x, y) = a_i x + b_i y + c_i`` (vertex i's barycentric
    coordinate) and ``ok`` (M,) False for degenerate (zero-area) triangles.
    """
    X, Y = dst[faces, 0], dst[faces, 1]                          # (M, 3)
    Xj, Yj = np.roll(X, -1, axis=1), np.roll(Y, -1, axis=1)      # vertex i+1
    Xk, Yk = np.roll(X, -2, axis=1), np.roll(Y, -2, axis=1)      # vertex i+2
    det = (Y[:, 1] - Y[:, 2]) * (X[:, 0] - X[:, 2]) + (X[:, 2] - X[:, 1]) * (Y[:, 0] - Y[:, 2])
    scale = np.maximum(np.abs(X).max(1), np.abs(Y).max(1)) + 1.0
    ok = np.abs(det) > 1e-12 * scale ** 2
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    a = (Yj - Yk) * inv
    b = (Xk - Xj) * inv
    c = -(a * Xk + b * Yk)
    return a, b, c, ok


_GRIDS: dict = {}


def _identity_maps(height: int, width: int):
    key = (height, width)
    if key not in _GRIDS:
        if len(_GRIDS) > 8:
            _GRIDS.clear()
        _GRIDS[key] = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    gx, gy = _GRIDS[key]
    return gx.copy(), gy.copy()


def rasterize_maps(dst, src, faces, height: int, width: int, with_ids: bool = True):
    """Backward maps of the piecewise-affine warp taking the mesh ``src`` to ``dst``.

    Scanline rasterisation, vectorised over all triangles: the (triangle, row) pairs of every
    bounding box are enumerated with ``np.repeat``; for each the exact pixel span inside the
    triangle follows from its three barycentric (edge) functions ``lambda_i = a_i x + b_i y + c_i
    >= 0``; the spans are expanded to pixels with ``np.repeat`` again, and the source coordinates
    ``sum_i lambda_i src_i`` (an affine function of the pixel) are stepped along each span.

    Parameters
    ----------
    dst : (N, 2) destination vertex positions (pixels, x right, y down; pixel (r, c) has its
        centre at x = c, y = r, as in ``cv2.remap``)
    src : (N, 2) the same vertices on the source image
    faces : (M, 3) triangles
    height, width : output size
    with_ids : also return the triangle-id map

    Returns
    -------
    map_x, map_y : (height, width) float32 source coordinates (identity outside the mesh)
    tri : (height, width) int32 triangle id of each pixel, -1 outside the mesh (None unless
        ``with_ids``)

    Where destination triangles overlap (a folded mesh), the triangle with the larger id wins.
    """
    dst = np.asarray(dst, np.float64)
    src = np.asarray(src, np.float64)
    faces = np.asarray(faces, np.int64)
    a, b, c, ok = _edge_functions(dst, faces)
    # the affine source map of each triangle: source = sum_i lambda_i src_i
    SX, SY = src[faces, 0], src[faces, 1]
    ax, bx, cx = (a * SX).sum(1), (b * SX).sum(1), (c * SX).sum(1)
    ay, by, cy = (a * SY).sum(1), (b * SY).sum(1), (c * SY).sum(1)
    # per edge, the span bound along x as a function of the row y:  lambda_i >= -tol  <=>
    # a_i x >= -tol - c_i - b_i y  (a lower bound if a_i > 0, an upper bound if a_i < 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.where(a != 0, (-INSIDE_TOL - c) / a, 0.0)
        q = np.where(a != 0, -b / a, 0.0)
    lower, upper = a > 0, a < 0
    Dy = dst[faces, 1]
    y0 = np.clip(np.ceil(Dy.min(1) - INSIDE_TOL), 0, height).astype(np.int64)
    y1 = np.clip(np.floor(Dy.max(1) + INSIDE_TOL), -1, height - 1).astype(np.int64)
    rows = np.where(ok, np.maximum(y1 - y0 + 1, 0), 0)
    map_x, map_y = _identity_maps(height, width)
    tri_map = np.full((height, width), -1, np.int32) if with_ids else None
    n_pairs = int(rows.sum())
    if n_pairs == 0:
        return map_x, map_y, tri_map
    # (triangle, row) pairs
    t = np.repeat(np.arange(len(faces)), rows)
    y = (np.repeat(y0 - (np.cumsum(rows) - rows), rows) + np.arange(n_pairs)).astype(np.float64)
    lo = np.full(n_pairs, -np.inf)
    hi = np.full(n_pairs, np.inf)
    for i in range(3):      # the three edges of every triangle at once
        bound = p[t, i] + q[t, i] * y
        lo = np.where(lower[t, i], np.maximum(lo, bound), lo)
        hi = np.where(upper[t, i], np.minimum(hi, bound), hi)
    xs = np.maximum(np.ceil(lo), 0.0)
    xe = np.minimum(np.floor(hi), width - 1.0)
    cnt = np.where(xe >= xs, xe - xs + 1, 0).astype(np.int64)
    total = int(cnt.sum())
    if total == 0:
        return map_x, map_y, tri_map
    axt, ayt = ax[t], ay[t]
    sx0 = (axt * xs + bx[t] * y + cx[t]).astype(np.float32)
    sy0 = (ayt * xs + by[t] * y + cy[t]).astype(np.float32)
    off = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    flat = np.repeat((y * width + xs).astype(np.int64), cnt) + off
    off = off.astype(np.float32)
    map_x.reshape(-1)[flat] = np.repeat(sx0, cnt) + off * np.repeat(axt.astype(np.float32), cnt)
    map_y.reshape(-1)[flat] = np.repeat(sy0, cnt) + off * np.repeat(ayt.astype(np.float32), cnt)
    if with_ids:
        tri_map.reshape(-1)[flat] = np.repeat(t.astype(np.int32), cnt)
    return map_x, map_y, tri_map


def warp_image(image, src, dst, faces) -> np.ndarray:
    """Piecewise-affine warp of ``image`` (H, W[, C]) moving mesh vertices ``src`` (N, 2) to ``dst``
    (N, 2), bilinear sampling; pixels outside the moved mesh keep ``image``."""
    import cv2

    img = np.asarray(image)
    map_x, map_y, _ = rasterize_maps(dst, src, faces, img.shape[0], img.shape[1], with_ids=False)
    return cv2.remap(img, map_x, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


__all__ = ["rasterize_maps", "warp_image", "INSIDE_TOL"]
