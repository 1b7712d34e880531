"""Close-ups of lips and lids: plain transfer, virtual edges, exact contact; intersecting triangles in red.

Made only from arrays saved by the penetration study (``python -m problems.reports``), never re-solving.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import _pyplot, save
from .render import HIGHLIGHT2_RGB, HIGHLIGHT_RGB, draw_mesh

#: column headings of the kinds of result a close-up can show
KIND_LABELS = {"plain": "plain transfer", "ve": "virtual edges", "contact": "exact contact"}


def _equal_aspect_crop(crop, aspect):
    """``crop`` grown (never shrunk) about its centre to width / height = ``aspect``."""
    (x0, x1), (y0, y1) = crop
    w, h = x1 - x0, y1 - y0
    if w / h < aspect:
        w = h * aspect
    else:
        h = w / aspect
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    return ((cx - w / 2, cx + w / 2), (cy - h / 2, cy + h / 2))


def penetration_figure(data: dict, out, formats=("png",), aspect: float | None = None) -> list[Path]:
    """Close-ups of lips and lids: plain transfer / virtual edges / exact contact, intersecting triangles in red.

    ``data`` (as saved by the penetration study): ``faces`` (m, 3); ``kinds`` the columns per zone
    (default ``("plain", "ve")``; ``"contact"`` for exact contact, headings in ``KIND_LABELS``); for each
    expression name and kind, ``<name>/<kind>`` vertex arrays and ``<name>/<kind>_hits`` face index
    arrays; ``crops`` {zone: (view, ((x0, x1), (y0, y1)))}; ``names``. Optional
    ``<name>/<kind>_local_hits``: triangles of local folds, drawn in orange (``*_hits`` then holds the
    layer crossings, in red); optional ``<name>/<kind>_note``: text added to the panel title (e.g.
    "excluded"); optional ``zone_faces`` {zone: face indices}: the triangles of each zone, whose
    highlighted ones each panel counts (without it: the highlighted triangles whose centre is inside
    the panel's crop).

    Every panel has the same size: each crop is grown to width / height = ``aspect`` (default: the
    widest crop's) and shown
    exactly (triangles clipped at its border).
    """
    from matplotlib.patches import Patch

    from .figures import PAGE

    plt = _pyplot()
    out = Path(out)
    F = np.asarray(data["faces"])
    names = list(data["names"])
    if aspect is None:  # the widest crop's, within 1.2 - 2.2
        aspect = max((c[0][1] - c[0][0]) / (c[1][1] - c[1][0]) for _, c in data["crops"].values())
        aspect = float(np.clip(aspect, 1.2, 2.2))
    zones = {z: (view, _equal_aspect_crop(crop, aspect)) for z, (view, crop) in data["crops"].items()}
    zone_faces = data.get("zone_faces") or {}
    kinds = tuple(data.get("kinds", ("plain", "ve")))
    cols = len(kinds) * len(zones)
    pw = PAGE / cols
    ph = pw / aspect
    wide = len(kinds) < 3  # narrow panels (three kinds): titles on up to three lines
    title_h, head_h, left, bottom = (0.36, 0.36, 0.22, 0.55) if wide else (0.62, 0.5, 0.22, 0.55)
    H = head_h + len(names) * (ph + title_h) + bottom
    W = PAGE + left
    fig = plt.figure(figsize=(W, H))
    local_any = any(f"{n}/{k}_local_hits" in data for n in names for k in kinds)
    for row, name in enumerate(names):
        y0 = H - head_h - row * (ph + title_h) - title_h - ph
        size = float(np.clip(72.0 * (ph + title_h) / (0.62 * max(len(name), 1)), 8.0, 9.0))  # fits the row
        fig.text(0.5 * left / W, (y0 + 0.5 * (ph + title_h)) / H, name, rotation=90, ha="center", va="center",
                 fontsize=size)
        col = 0
        for zone, (view, crop) in zones.items():
            for kind in kinds:
                hl = np.zeros(len(F), bool)
                hl[np.asarray(data[f"{name}/{kind}_hits"], np.int64)] = True
                local = data.get(f"{name}/{kind}_local_hits")
                hl2 = None
                if local is not None:
                    hl2 = np.zeros(len(F), bool)
                    hl2[np.asarray(local, np.int64)] = True
                    hl2 &= ~hl
                ax = fig.add_axes(((left + col * pw + 0.02 * pw) / W, y0 / H, 0.96 * pw / W, 0.96 * ph / H))
                X = np.asarray(data[f"{name}/{kind}"], float)
                draw_mesh(ax, X, F, view=view, crop=crop, highlight=hl, highlight2=hl2)
                if zone in zone_faces:
                    inzone = np.zeros(len(F), bool)
                    inzone[np.asarray(zone_faces[zone], np.int64)] = True
                else:
                    from .render import project

                    c = project(X, view)[F].mean(1)
                    (a0, a1), (b0, b1) = crop
                    inzone = (c[:, 0] > a0) & (c[:, 0] < a1) & (c[:, 1] > b0) & (c[:, 1] < b1)
                parts = [f"{int((hl & inzone).sum())} crossing"]
                if hl2 is not None:
                    parts.append(f"{int((hl2 & inzone).sum())} fold")
                note = data.get(f"{name}/{kind}_note")
                if note:
                    parts.append(f"({note})")
                ax.set_title((", " if wide else "\n").join(parts), fontsize=8, pad=2)
                if row == 0:
                    label = KIND_LABELS.get(kind, kind)
                    fig.text((left + (col + 0.5) * pw) / W, (H - 0.05) / H,
                             f"{zone}: {label}" if wide else f"{zone}:\n{label}", ha="center",
                             va="top", fontsize=9, fontweight="bold")
                col += 1
    handles = [Patch(color=HIGHLIGHT_RGB, label="layer crossing (intersecting triangles ≥ 2 median edges apart along "
                                                "the surface); panel titles count the zone's triangles")]
    if local_any:
        handles.append(Patch(color=HIGHLIGHT2_RGB, label="local fold (intersecting triangles closer along the surface)"))
    fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.0), ncol=1, frameon=False)
    return save(fig, out / "penetration_closeups", formats)


__all__ = ["penetration_figure", "KIND_LABELS"]
