"""Shaded mesh renders with matplotlib (no OpenGL): painter's algorithm over triangles.

Used by the report code for faces and per-vertex error maps; reads arrays, never solves.
"""

from __future__ import annotations

import numpy as np

# the rasteriser and its shading live in geometry: retarget's preview videos may not import report
from ..geometry.raster import SKIN_RGB, rasterize_mesh, shade

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
              face_mask=None, highlight=None, crop=None, color=SKIN_RGB, highlight2=None,
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
    rgb = rgb * shade(n)[:, None]
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



#: displacement colours for renders: skin (no motion) through orange to a dark red (the largest);
#: the largest value stays a colour, so a strongly moving region never reads as a hole
HEAT_COLORS = ((0.85, 0.78, 0.72), (0.98, 0.62, 0.25), (0.82, 0.16, 0.08), (0.45, 0.0, 0.12))


def heat_cmap():
    """The :data:`HEAT_COLORS` colour map (matplotlib)."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list("facebasis_heat", HEAT_COLORS)


def render_image(V, F, crop, width: int, values=None, vmin=0.0, vmax=1.0, cmap=None, view="front",
                 supersample: int = 2, background=(255, 255, 255)) -> np.ndarray:
    """A shaded image of a mesh inside a crop, rasterised with numpy (no matplotlib polygons).

    The mesh is projected with :func:`project`, the ``crop`` ((x0, x1), (y0, y1)) in view coordinates
    fills the image, and :func:`facebasis.geometry.raster.rasterize_mesh` draws it (z-buffer, flat
    shading as :func:`draw_mesh`, back faces culled) at ``supersample`` times the size, averaged down.
    Memory is one image: a figure of many shapes keeps images, not polygon collections.

    Parameters
    ----------
    V : (n, 3) vertices; F : (m, 3) triangles
    crop : ((x0, x1), (y0, y1)) in view coordinates
    width : image width in pixels (the height follows the crop's aspect)
    values : optional (n,) per-vertex scalars coloured by ``cmap`` between ``vmin`` and ``vmax``
    cmap : a matplotlib colour map (default :func:`heat_cmap`)

    Returns
    -------
    (height, width, 3) uint8
    """

    (x0, x1), (y0, y1) = crop
    ss = max(1, int(supersample))
    W = int(width) * ss
    scale = W / (x1 - x0)
    H = max(1, int(round((y1 - y0) * scale / ss))) * ss
    P = project(V, view)
    Q = np.column_stack([(P[:, 0] - x0) * scale, (y1 - P[:, 1]) * scale, P[:, 2]])
    F = np.asarray(F)
    if values is None:
        color = SKIN_RGB
    else:
        cmap = heat_cmap() if cmap is None else cmap
        t = (np.asarray(values, float)[F].mean(1) - vmin) / ((vmax - vmin) or 1.0)
        color = np.asarray(cmap(np.clip(t, 0.0, 1.0)))[:, :3]
    img = rasterize_mesh(Q, F, (H, W), color=color, background=background)
    if ss > 1:
        img = img.reshape(H // ss, ss, W // ss, ss, 3).mean((1, 3)).round().astype(np.uint8)
    return img

