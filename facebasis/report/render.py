"""Shaded mesh renders with matplotlib (no OpenGL): painter's algorithm over triangles.

Used by the report code for faces and per-vertex error maps; reads arrays, never solves.
"""

from __future__ import annotations

import numpy as np

VIEWS = {"front": (0.0, 0.0), "left": (0.0, 60.0), "right": (0.0, -60.0), "below": (-35.0, 0.0)}


def _rotation(elev_deg: float, azim_deg: float) -> np.ndarray:
    e, a = np.radians(elev_deg), np.radians(azim_deg)
    Ry = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(e), -np.sin(e)], [0, np.sin(e), np.cos(e)]])
    return Rx @ Ry


def project(V, view="front") -> np.ndarray:
    """View coordinates (n, 3) of points V under a named view or (elevation, azimuth)."""
    elev, azim = VIEWS[view] if isinstance(view, str) else view
    return np.asarray(V, float) @ _rotation(elev, azim).T


HIGHLIGHT_RGB = np.array([0.9, 0.05, 0.05])   # red
HIGHLIGHT2_RGB = np.array([1.0, 0.6, 0.0])    # orange


def draw_mesh(ax, V, F, values=None, view="front", cmap="viridis", vmin=None, vmax=None,
              face_mask=None, highlight=None, crop=None, color=(0.85, 0.78, 0.72), highlight2=None,
              rasterized=True):
    """Draw a shaded mesh into a matplotlib axis (camera looks along -z after the view rotation).

    Parameters
    ----------
    ax : matplotlib axis
    V : (n, 3), F : (m, 3)
    values : optional (n,) per-vertex scalars shown as colours (shading still applied)
    view : a key of ``VIEWS`` or an (elevation, azimuth) pair in degrees
    face_mask : optional (m,) bool, triangles to draw
    highlight : optional (m,) bool, triangles drawn in red (e.g. intersecting ones)
    highlight2 : optional (m,) bool, triangles drawn in orange (e.g. local folds); red wins where both
    crop : optional ((xmin, xmax), (ymin, ymax)) in view coordinates: the axis shows exactly this
        rectangle (triangles with a corner inside it are drawn and clipped at its border, so the
        edges of the crop are straight)
    rasterized : draw the triangles as an image in vector outputs (PDF/SVG stay small; text and
        colour bars stay vector)

    Returns
    -------
    The PolyCollection, or a ScalarMappable for a colour bar when ``values`` is given.
    """
    import matplotlib.cm as cm
    import matplotlib.colors as mcolors
    from matplotlib.collections import PolyCollection

    elev, azim = VIEWS[view] if isinstance(view, str) else view
    P = np.asarray(V, float) @ _rotation(elev, azim).T
    F = np.asarray(F)
    keep = np.ones(len(F), bool) if face_mask is None else np.asarray(face_mask, bool)
    tri = P[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-300
    light = np.array([0.3, 0.4, 1.0])
    light /= np.linalg.norm(light)
    shade = 0.25 + 0.75 * np.abs(n @ light)
    depth = tri[:, :, 2].mean(1)
    if crop is not None:
        (x0, x1), (y0, y1) = crop
        inside = (tri[:, :, 0] > x0) & (tri[:, :, 0] < x1) & (tri[:, :, 1] > y0) & (tri[:, :, 1] < y1)
        keep &= inside.any(1)
    order = np.flatnonzero(keep)[np.argsort(depth[keep], kind="stable")]
    if values is not None:
        vals = np.asarray(values, float)[F].mean(1)
        norm = mcolors.Normalize(vmin=np.min(vals) if vmin is None else vmin,
                                 vmax=np.max(vals) if vmax is None else vmax)
        mapper = cm.ScalarMappable(norm=norm, cmap=cmap)
        rgb = mapper.to_rgba(vals)[:, :3]
    else:
        mapper = None
        rgb = np.tile(np.asarray(color, float), (len(F), 1))
    rgb = rgb * shade[:, None]
    if highlight2 is not None:
        rgb[np.asarray(highlight2, bool)] = HIGHLIGHT2_RGB
    if highlight is not None:
        rgb[np.asarray(highlight, bool)] = HIGHLIGHT_RGB
    coll = PolyCollection(tri[order][:, :, :2], facecolors=np.clip(rgb[order], 0, 1),
                          edgecolors="none", linewidths=0, antialiased=False, rasterized=rasterized)
    ax.add_collection(coll)
    if crop is not None:
        ax.set_xlim(*crop[0])
        ax.set_ylim(*crop[1])
    else:
        pts = tri[order][:, :, :2].reshape(-1, 2) if len(order) else P[:, :2]
        ax.set_xlim(pts[:, 0].min(), pts[:, 0].max())
        ax.set_ylim(pts[:, 1].min(), pts[:, 1].max())
    ax.set_aspect("equal")
    ax.axis("off")
    return mapper if mapper is not None else coll


SKIN_RGB = (0.85, 0.78, 0.72)
LIGHT = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])


def rasterize_mesh(P, F, size, color=SKIN_RGB, background=(255, 255, 255), out=None) -> np.ndarray:
    """Flat-shaded image of a mesh already in pixel coordinates, for video frames (no OpenGL).

    The same shading as :func:`draw_mesh` (``0.25 + 0.75 |n . light|``), but rasterised with numpy
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
