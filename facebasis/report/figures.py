"""Figures that only read results (arrays, rigs, histories) and write images."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .render import draw_mesh


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: Path, formats=("png",)) -> list[Path]:
    """Save a figure in each format (atomically per file) and close it."""
    import io

    from ..atomic import atomic_write_bytes

    paths = []
    for fmt in formats:
        buf = io.BytesIO()
        # no creation date in PDF/SVG metadata: the same result gives the same file
        meta = {"CreationDate": None} if fmt == "pdf" else ({"Date": None} if fmt == "svg" else None)
        fig.savefig(buf, format=fmt, dpi=150, bbox_inches="tight", metadata=meta)
        p = Path(path).with_suffix("." + fmt)
        atomic_write_bytes(p, buf.getvalue())
        paths.append(p)
    _pyplot().close(fig)
    return paths


def shape_error_grid(template, truth, results: dict, names, path: Path, view="front"):
    """Rows: shapes; columns: the true shape, then each result coloured by per-vertex error (cm)."""
    plt = _pyplot()
    cols = 1 + len(results)
    fig, axes = plt.subplots(len(names), cols, figsize=(2.6 * cols, 2.9 * len(names)), squeeze=False)
    errs = {k: np.linalg.norm(r.deltas - truth.deltas, axis=2) for k, r in results.items()}
    vmax = max(float(np.percentile(e[truth.index(names)], 99.5)) for e in errs.values())
    mapper = None
    for row, name in enumerate(names):
        i = truth.index([name])[0]
        draw_mesh(axes[row, 0], truth.neutral + truth.deltas[i], truth.faces, view=view)
        axes[row, 0].set_title(f"{name}\n(truth)", fontsize=8)
        for col, (label, res) in enumerate(results.items(), start=1):
            mapper = draw_mesh(axes[row, col], res.neutral + res.deltas[i], res.faces,
                               values=errs[label][i], vmin=0.0, vmax=vmax, cmap="magma_r", view=view)
            rms = float(np.sqrt((errs[label][i] ** 2).mean()))
            axes[row, col].set_title(f"{label}\nRMS {rms:.3f}", fontsize=8)
    if mapper is not None:
        cb = fig.colorbar(mapper, ax=axes, fraction=0.02, pad=0.01)
        cb.set_label("per-vertex error")
    return save(fig, path)


def demo_figures(folder: Path, template, person, results: dict) -> list[Path]:
    """Renders of the two default faces and error maps of each result against the person's truth."""
    plt = _pyplot()
    folder.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 4, figsize=(12, 7))
    rows = ((template, "template", ""), (person, "person", " (truth)"))
    for ax_row, (rig, who, note) in zip(axes, rows):
        for ax, shape in zip(ax_row, (None, "jawOpen", "mouthSmile_L", "eyeBlink_L")):
            V = rig.neutral if shape is None else rig.shape(shape)
            draw_mesh(ax, V, rig.faces)
            ax.set_title(f"{who} {shape or 'neutral'}{note if shape else ''}", fontsize=9)
    paths = save(fig, folder / "default_faces")
    names = ["jawOpen", "mouthSmile_L", "mouthPucker", "cheekPuff_R"]  # rows of the error grid
    paths += shape_error_grid(template, person, results, names, folder / "error_maps")
    return paths


def convergence_figure(history: dict, path: Path, formats=("png",)) -> list[Path]:
    """Convergence of a rig run: E_fit, E_reg, weight objective and complementarity residual per
    iteration, with the alpha / lambda schedule on a second axis. Reads ``history.json`` content."""
    plt = _pyplot()
    its = history["iterations"]
    i = np.array([h["iteration"] for h in its])
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    ax = axes[0]
    ax.semilogy(i, [h["e_fit"] for h in its], "o-", label=r"$E_{fit}$ (eq. 2)")
    ax.semilogy(i, [h["e_reg"] for h in its], "s-", label=r"$E_{reg}$ (eq. 3)")
    ax.set_xlabel("iteration")
    ax.set_ylabel("basis-step energy")
    ax2 = ax.twinx()
    ax2.plot(i, [h["alpha"] for h in its], "k--", lw=1, label=r"$\alpha$")
    ax2.set_ylabel(r"$\alpha$")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[1]
    ax.semilogy(i, [h["weight_objective"] for h in its], "o-", label="certified (branch and bound)")
    ax.semilogy(i, [h["ipopt_objective"] for h in its], "x--", label="IPOPT")
    ax.set_xlabel("iteration")
    ax.set_ylabel("weight-step objective (eq. 5)")
    ax2 = ax.twinx()
    ax2.plot(i, [h["lam"] for h in its], "k--", lw=1)
    ax2.set_ylabel(r"$\lambda$")
    ax.legend(fontsize=8)
    ax = axes[2]
    floor = 1e-20  # values at or below it (exact zeros included) are drawn on this floor
    for key, style, label in (("ipopt_max_complementarity", "x--", "IPOPT: max |x_a x_b|"),
                              ("ipopt_max_bound_violation", "+--", "IPOPT: bound violation"),
                              ("max_complementarity", "o-", "certified: max |x_a x_b|"),
                              ("max_bound_violation", "s:", "certified: bound violation")):
        ax.semilogy(i, [max(h[key], floor) for h in its], style, label=label, ms=4)
    ax.axhline(floor, color="0.6", lw=0.8)
    ax.text(i[0], floor * 3, "<= 1e-20 (incl. exact 0)", fontsize=7, color="0.4")
    ax.set_ylim(floor / 10, 1.0)
    ax.set_xlabel("iteration")
    ax.set_ylabel("constraint residual")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path, formats)


def virtual_edges_figure(V, F, edges, path: Path, views=("front", "below"), title: str = "", formats=("png",)):
    """The mesh with its virtual edges drawn as red segments, whole face and zoomed on the edges."""
    from .render import project

    plt = _pyplot()
    E = np.asarray(edges, np.int64).reshape(-1, 2)
    fig, axes = plt.subplots(1, 2 * len(views), figsize=(5.0 * 2 * len(views), 5.5), squeeze=False)
    for col, view in enumerate(views):
        P = project(V, view)
        for j, zoom in enumerate((False, True)):
            ax = axes[0, 2 * col + j]
            crop = None
            if zoom and len(E):
                lo, hi = P[E.ravel(), :2].min(0), P[E.ravel(), :2].max(0)
                pad = 0.08 * float((hi - lo).max())
                crop = ((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad))
            draw_mesh(ax, V, F, view=view, crop=crop)
            if len(E):
                seg = np.stack([P[E[:, 0], :2], P[E[:, 1], :2]], 1)
                from matplotlib.collections import LineCollection

                ax.add_collection(LineCollection(seg, colors=(0.85, 0.05, 0.05), linewidths=0.6 if zoom else 0.3))
            ax.set_title(f"{view}{' (zoom)' if zoom else ''}", fontsize=9)
    fig.suptitle(title or f"{len(E)} virtual edges", fontsize=10)
    return save(fig, path, formats)
