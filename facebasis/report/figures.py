"""Figures that only read results (arrays, rigs, histories) and write images.

Conventions of every figure of the package (checked by :func:`lint_figure` in the tests):

* sized for a paper: :data:`COLUMN` (3.3 in) or :data:`PAGE` (7 in) wide, every text at least
  :data:`MIN_FONT_PT` (8 pt) at that size;
* every numeric axis and colour bar labelled with its unit in parentheses (lengths in cm: the
  built-in face and ICT-FaceKit are both modelled in cm; ratios are "(dimensionless)");
* every labelled series in a legend, legends outside the data (beside or below the axes).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .render import draw_mesh, project

#: Widths of a one-column and a two-column (page-wide) figure, inches.
COLUMN = 3.3
PAGE = 7.0
#: Smallest font size of any text, points.
MIN_FONT_PT = 8.0
#: The unit of ratios and weights in axis labels.
DIMENSIONLESS = "dimensionless"

#: Callables ``hook(fig, path)`` run by :func:`save` before a figure is written (the tests add
#: :func:`lint_figure` here).
SAVE_HOOKS: list = []

_STYLE = {"font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8, "xtick.labelsize": 8,
          "ytick.labelsize": 8, "legend.fontsize": 8, "figure.titlesize": 9, "legend.title_fontsize": 8,
          "pdf.fonttype": 42, "ps.fonttype": 42, "axes.spines.top": False, "axes.spines.right": False}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(_STYLE)
    return plt


#: the software tag of every figure (PNG Software, PDF/SVG Creator): facebasis.atomic recognises its
#: own figures by it, so a later run may replace them and never a user's own file of the same name
SOFTWARE = "facebasis (matplotlib)"


def save(fig, path: Path, formats=("png",)) -> list[Path]:
    """Save a figure in each format (atomically per file) and close it."""
    import io

    from ..atomic import atomic_write_bytes

    for hook in SAVE_HOOKS:
        hook(fig, Path(path))
    paths = []
    for fmt in formats:
        buf = io.BytesIO()
        # no creation date in PDF/SVG metadata: the same result gives the same file
        meta = {"CreationDate": None, "Creator": SOFTWARE} if fmt == "pdf" else (
            {"Date": None, "Creator": SOFTWARE} if fmt == "svg" else {"Software": SOFTWARE})
        fig.savefig(buf, format=fmt, dpi=200, bbox_inches="tight", pad_inches=0.03,
                    metadata=meta)
        p = Path(path).with_suffix("." + fmt)
        atomic_write_bytes(p, buf.getvalue())
        paths.append(p)
    _pyplot().close(fig)
    return paths


def unit(label: str, u: str) -> str:
    """``"label (u)"``."""
    return f"{label} ({u})"


def legend_outside(ax_or_fig, handles=None, labels=None, where="below", ncol=1, **kw):
    """A legend outside the data: below the axes (default), to the ``right`` or ``above``; for a
    figure, below all axes."""
    from matplotlib.figure import Figure

    if handles is None:
        handles, labels = ax_or_fig.get_legend_handles_labels()
    if isinstance(ax_or_fig, Figure):
        return ax_or_fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=ncol,
                                frameon=False, **kw)
    place = {"below": dict(loc="upper center", bbox_to_anchor=(0.5, -0.22)),
             "right": dict(loc="center left", bbox_to_anchor=(1.02, 0.5)),
             "above": dict(loc="lower center", bbox_to_anchor=(0.5, 1.02))}[where]
    return ax_or_fig.legend(handles, labels, ncol=ncol, frameon=False, **place, **kw)


# ----------------------------------------------------------------------------------------------
# checks of a drawn figure (used by the tests through SAVE_HOOKS)

_NUMBER = re.compile(r"^[\s\-−+.0-9eE×,%]*$")
_MATH = re.compile(r"\\mathdefault|\\times|\\cdot|[{}$^]")
_UNIT = re.compile(r"\([^()]*\S[^()]*\)\s*$")


def _tick_texts(axis):
    return [t.get_text() for t in axis.get_ticklabels() if t.get_visible() and t.get_text().strip()]


def lint_figure(fig) -> list[str]:
    """Problems of a figure against the conventions above: an axis with visible numeric ticks and
    no label or no "(unit)" at its end; an axis with categorical ticks and no label; a labelled
    series missing from every legend; a legend inside an axes that covers data points; a text
    smaller than :data:`MIN_FONT_PT`. Returns one string per problem (empty: none)."""
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle
    from matplotlib.text import Text

    fig.canvas.draw()
    problems = []
    legends = [a.get_legend() for a in fig.axes if a.get_legend() is not None] + list(fig.legends)
    legend_labels = {t.get_text() for lg in legends for t in lg.get_texts()}
    for k, ax in enumerate(fig.axes):
        name = f"axes {k} ({ax.get_title() or ax.get_label() or '?'})"
        if ax.axison:
            for which, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
                if not axis.get_visible():
                    continue
                ticks = _tick_texts(axis)
                if not ticks:
                    continue
                label = axis.get_label().get_text().strip()
                if not label:
                    problems.append(f"{name}: {which} axis has ticks but no label")
                elif all(_NUMBER.match(_MATH.sub("", t)) for t in ticks) and not _UNIT.search(label):
                    problems.append(f"{name}: {which} label {label!r} has no (unit)")
        handles, labels = ax.get_legend_handles_labels()
        for lab in labels:
            if lab not in legend_labels:
                problems.append(f"{name}: series {lab!r} is in no legend")
        lg = ax.get_legend()
        if lg is not None and lg.get_visible():
            box = lg.get_window_extent()
            inside = ax.bbox.overlaps(box)
            if inside:
                pts = []
                for art in ax.get_children():
                    if isinstance(art, Line2D) and art.get_visible() and len(art.get_xydata()):
                        xy = art.get_transform().transform(art.get_xydata())
                        if art.get_linestyle() not in ("None", "", " ") and len(xy) > 1:
                            t = np.linspace(0.0, 1.0, 25)[:, None, None]  # points along each segment
                            xy = np.concatenate([xy, ((1 - t) * xy[:-1] + t * xy[1:]).reshape(-1, 2)])
                        pts.append(xy)
                    elif isinstance(art, Collection) and art.get_visible() and len(art.get_offsets()):
                        pts.append(art.get_offset_transform().transform(art.get_offsets()))
                    elif isinstance(art, Rectangle) and art is not ax.patch and art.get_visible():
                        pts.append(art.get_window_extent().get_points())
                pts = np.concatenate(pts) if pts else np.zeros((0, 2))
                pts = pts[np.isfinite(pts).all(1)]
                hit = ((pts[:, 0] > box.x0) & (pts[:, 0] < box.x1) & (pts[:, 1] > box.y0) & (pts[:, 1] < box.y1))
                if hit.any():
                    problems.append(f"{name}: legend covers {int(hit.sum())} data points")
    for t in fig.findobj(Text):
        if t.get_visible() and t.get_text().strip() and t.get_fontsize() < MIN_FONT_PT - 1e-9:
            problems.append(f"text {t.get_text()[:30]!r} is {t.get_fontsize():.1f} pt")
    return problems


# ----------------------------------------------------------------------------------------------
# renders

def face_crop(V, deltas=None, view="front", pad=0.04, rel=0.2):
    """A crop ((x0, x1), (y0, y1)) in view coordinates around the part of a mesh that moves: the
    vertices that move by more than ``rel`` of their shape's own maximum in some shape, at rest and
    where that shape takes them (an opened jaw stays in the frame; all vertices without ``deltas``
    or when none moves), from the 0.5th to the 99.5th percentile of their view coordinates (a shape
    that drags the neck along does not widen the crop to the whole head), padded by ``pad`` of the
    larger side."""
    V = np.asarray(V, float)
    pts = V
    if deltas is not None and len(deltas):
        D = np.asarray(deltas, float)
        mag = np.linalg.norm(D, axis=2)
        peak = mag.max(1, keepdims=True)
        moving = mag > rel * np.where(peak > 0, peak, np.inf)          # (k, n)
        if moving.any(0).sum() >= 3:  # the moving vertices at rest and where their shapes take them
            pts = np.concatenate([V[moving.any(0)], (V[None] + D)[moving]])
    P = project(pts, view)[:, :2]
    lo, hi = np.percentile(P, 0.5, axis=0), np.percentile(P, 99.5, axis=0)
    m = pad * float((hi - lo).max())
    return ((lo[0] - m, hi[0] + m), (lo[1] - m, hi[1] + m))


def shape_error_grid(template, truth, results: dict, names, path: Path, view="front", formats=("png",)):
    """Rows: shapes; columns: the true shape, then each result coloured by per-vertex error (cm)."""
    plt = _pyplot()
    cols = 1 + len(results)
    fig, axes = plt.subplots(len(names), cols, figsize=(PAGE * cols / 4, 2.2 * len(names)), squeeze=False,
                             layout="constrained")
    # each result's shapes matched to the truth's by name (a rig read from a folder may be in file order)
    errs = {k: np.linalg.norm(r.deltas[r.index(list(truth.names))] - truth.deltas, axis=2) for k, r in results.items()}
    vmax = max(float(np.percentile(e[truth.index(names)], 99.5)) for e in errs.values())
    mapper = None
    for row, name in enumerate(names):
        i = truth.index([name])[0]
        draw_mesh(axes[row, 0], truth.neutral + truth.deltas[i], truth.faces, view=view)
        axes[row, 0].set_title(f"{name}\n(truth)")
        for col, (label, res) in enumerate(results.items(), start=1):
            mapper = draw_mesh(axes[row, col], res.neutral + res.deltas[res.index([name])[0]], res.faces,
                               values=errs[label][i], vmin=0.0, vmax=vmax, cmap="magma_r", view=view)
            rms = float(np.sqrt((errs[label][i] ** 2).mean()))
            axes[row, col].set_title(f"{label}\nRMS {rms:.3f} cm")
    if mapper is not None:
        cb = fig.colorbar(mapper, ax=axes, shrink=0.5, aspect=30, extend="max")
        cb.set_label(unit("per-vertex error against the truth", "cm"))
    fig.suptitle(f"per-vertex error of each method ({view} view)")
    return save(fig, path, formats)


def demo_figures(folder: Path, template, person, results: dict) -> list[Path]:
    """Renders of the two default faces and error maps of each result against the person's truth."""
    plt = _pyplot()
    folder.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 4, figsize=(PAGE, 4.2))
    rows = ((template, "template", ""), (person, "person", " (truth)"))
    for ax_row, (rig, who, note) in zip(axes, rows):
        for ax, shape in zip(ax_row, (None, "jawOpen", "mouthSmile_L", "eyeBlink_L")):
            V = rig.neutral if shape is None else rig.shape(shape)
            draw_mesh(ax, V, rig.faces)
            ax.set_title(f"{who}\n{shape or 'neutral'}{note if shape else ''}")
    paths = save(fig, folder / "default_faces")
    names = ["jawOpen", "mouthSmile_L", "mouthPucker", "cheekPuff_R"]  # rows of the error grid
    paths += shape_error_grid(template, person, results, names, folder / "error_maps")
    return paths


# ----------------------------------------------------------------------------------------------
# a rig run

def convergence_figure(history: dict, path: Path, formats=("png",)) -> list[Path]:
    """Convergence of a rig run, three panels stacked for a column: E_fit and E_reg with the alpha
    schedule; the weight step's objective split into its fit of the examples and its prior part
    (which scales with lambda, drawn with the lambda schedule; the total as well, and IPOPT's total
    where it ran); the constraint residuals. Reads ``history.json`` content (a history without
    ``weight_prior`` shows the total only)."""
    plt = _pyplot()
    its = history["iterations"]
    i = np.array([h["iteration"] for h in its])
    fig, axes = plt.subplots(3, 1, figsize=(COLUMN, 7.6), sharex=True,
                             gridspec_kw=dict(hspace=0.62, top=0.9, bottom=0.07, left=0.2, right=0.8))
    ax = axes[0]
    h1 = ax.semilogy(i, [h["e_fit"] for h in its], "o-", ms=4, label=r"$E_{fit}$ (eq. 2)")
    h2 = ax.semilogy(i, [h["e_reg"] for h in its], "s-", ms=4, label=r"$E_{reg}$ (eq. 3)")
    ax.set_ylabel(unit("basis-step energy", "cm²"))
    ax2 = ax.twinx()
    h3 = ax2.plot(i, [h["alpha"] for h in its], "k--", lw=1, label=r"$\alpha$ (right axis)")
    ax2.set_ylabel(unit(r"$\alpha$", DIMENSIONLESS))
    ax2.spines["right"].set_visible(True)
    legend_outside(ax, h1 + h2 + h3, [h.get_label() for h in h1 + h2 + h3], where="above", ncol=2)
    ax = axes[1]
    # the two curves coincide when IPOPT reaches the optimum: large open circles under small crosses
    total = np.array([h["weight_objective"] for h in its], float)
    prior = np.array([h.get("weight_prior", np.nan) for h in its], float)
    ipopt = np.array([h["ipopt_objective"] for h in its], float)
    if np.isfinite(prior).all():
        # the objective's prior part scales with lambda; its fit part (eq. 5's first term) is what the
        # alternation improves, so it is drawn apart (the total then mostly traces lambda's schedule)
        h1 = ax.semilogy(i, total - prior, "o-", ms=7, mfc="none", label="fit of the examples (certified)")
        h1 += ax.semilogy(i, np.maximum(prior, 1e-300), "s:", ms=4, color="tab:green",
                          label=r"prior $\lambda\|x - \tilde x\|^2$")
        h1 += ax.semilogy(i, total, "-", lw=0.8, color="0.6", label="total (fit + prior)")
        ax.set_ylabel(unit("eq. 5 terms", "cm²"))
    else:  # a history written before the prior part was recorded
        h1 = ax.semilogy(i, total, "o-", ms=7, mfc="none", label="certified (B&B)")
        ax.set_ylabel(unit("eq. 5 objective", "cm²"))
    h2 = ax.semilogy(i, ipopt, "x--", ms=5, label=f"IPOPT total ({int(np.isfinite(ipopt).sum())} of {len(i)} iter.)")
    ax2 = ax.twinx()
    h3 = ax2.plot(i, [h["lam"] for h in its], "k--", lw=1, label=r"$\lambda$ (right axis)")
    ax2.set_ylabel(unit(r"$\lambda$", "cm²"))
    ax2.spines["right"].set_visible(True)
    legend_outside(ax, h1 + h2 + h3, [h.get_label() for h in h1 + h2 + h3], where="above", ncol=2)
    ax = axes[2]
    floor = 1e-20  # values at or below it (exact zeros included) are drawn on this floor
    hs = []
    # drawn largest first, so points on the same value stay visible inside each other
    for key, style, ms, label in (("max_complementarity", "o-", 8, r"certified: max $|x_a x_b|$"),
                                  ("max_bound_violation", "s:", 4, "certified: bound violation"),
                                  ("ipopt_max_complementarity", "x--", 6, r"IPOPT: max $|x_a x_b|$"),
                                  ("ipopt_max_bound_violation", "+--", 9, "IPOPT: bound violation")):
        vals = np.array([max(h[key], floor) if np.isfinite(h[key]) else np.nan for h in its])
        kw = dict(mfc="none") if style[0] == "o" else {}
        hs += ax.semilogy(i, vals, style, label=label, ms=ms, **kw)
    ax.axhline(floor, color="0.6", lw=0.8)
    ax.text(i[0], floor * 10, r"$\leq 10^{-20}$ (incl. exact 0)", fontsize=8, color="0.3")
    ax.set_ylim(floor / 10, 1.0)
    ax.set_xlabel(unit("iteration", "count"))
    ax.set_ylabel(unit("residual", DIMENSIONLESS))
    legend_outside(ax, where="above", ncol=2)
    for a in axes:
        a.xaxis.get_major_locator().set_params(integer=True)
    return save(fig, path, formats)


def virtual_edges_figure(V, F, edges, path: Path, views=("front", "below"), title: str = "", formats=("png",)):
    """The mesh with its virtual edges, whole face and zoomed on the edges. Edges are coloured by
    their length (the gap they span, mesh units) and drawn translucent, more so the more there are,
    so that thousands of edges across a mouth read as a density, not as a solid red patch."""
    from matplotlib.collections import LineCollection

    plt = _pyplot()
    E = np.asarray(edges, np.int64).reshape(-1, 2)
    length = np.linalg.norm(np.asarray(V)[E[:, 0]] - np.asarray(V)[E[:, 1]], axis=1) if len(E) else np.zeros(0)
    alpha = float(np.clip(25.0 / np.sqrt(max(len(E), 1)), 0.1, 0.9))
    norm = plt.Normalize(float(length.min()), float(length.max()) or 1.0) if len(E) else None
    fig, axes = plt.subplots(len(views), 2, figsize=(PAGE, 3.2 * len(views)), squeeze=False)
    lines = None
    for row, view in enumerate(views):
        P = project(V, view)
        for j, zoom in enumerate((False, True)):
            ax = axes[row, j]
            crop = None
            if zoom and len(E):
                lo, hi = P[E.ravel(), :2].min(0), P[E.ravel(), :2].max(0)
                pad = 0.08 * float((hi - lo).max())
                crop = ((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad))
            draw_mesh(ax, V, F, view=view, crop=crop)
            if len(E):
                seg = np.stack([P[E[:, 0], :2], P[E[:, 1], :2]], 1)
                lines = LineCollection(seg, cmap="plasma", norm=norm, alpha=alpha, linewidths=0.6 if zoom else 0.3)
                lines.set_array(length)
                ax.add_collection(lines)
            ax.set_title(f"{view}{' (zoom)' if zoom else ''}")
    if lines is not None:
        fig.colorbar(lines, ax=axes.ravel().tolist(), fraction=0.03, pad=0.02).set_label("edge length (mesh units)")
    fig.suptitle(title or f"{len(E)} virtual edges")
    return save(fig, path, formats)
