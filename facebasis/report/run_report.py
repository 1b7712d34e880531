"""Paper-style figures and tables, made only from stored results (never re-solving).

* :func:`report_run` - a ``facebasis rig`` output folder: convergence, weights, residuals, the
  generated shapes rendered with their displacement (PNG + PDF); tables of the per-iteration
  history, per-example residuals and weights (Markdown + CSV); an ``index.md`` with the run's key
  numbers and what each file shows (links relative, only files written).
* :func:`sweep_report`, :func:`formulation_report` - study results (:mod:`facebasis.report.sweep`);
* :func:`penetration_figure` - close-ups of lips and lids (:mod:`facebasis.report.penetration`).
  Both are importable from here as well.

Figures are PNG plus PDF (vector) by default; tables are CSV and Markdown. Files are written
atomically.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import InputError
from .figures import _pyplot, convergence_figure, save
from .penetration import penetration_figure  # noqa: F401  (re-exported)
from .sweep import formulation_report, sweep_report  # noqa: F401  (re-exported)
from .tables import csv_table, markdown_table, write_table  # noqa: F401  (re-exported)

FORMATS = ("png", "pdf")


def _write_text(path: Path, text: str) -> Path:
    atomic_write_bytes(path, text.encode())
    return path


# ----------------------------------------------------------------------------------------------
# a rig run

def _rel(path: Path, start: Path) -> str:
    """``path`` relative to ``start`` (posix), never absolute."""
    import os

    return Path(os.path.relpath(Path(path).resolve(), Path(start).resolve())).as_posix()


#: What each file of a run report shows (for index.md).
RUN_FILES = {
    "convergence": "E_fit and E_reg (cm²) with the alpha schedule; the weight-step objective split into the fit "
                   "of the examples and the prior part (which scales with lambda, drawn with its schedule); the "
                   "constraint residuals; per iteration.",
    "weights": "The solved weights of each training expression (rows) on each shape (columns), 0 to 1.",
    "residuals": "Relative residual of each training expression after the run; red above the "
                 "missing-expression threshold (dashed).",
    "shapes": "Every generated shape, front view, coloured by its displacement divided by the shape's own "
              "maximum (one scale per shape; the maximum, in the rig's units, under its name), cropped to the "
              "vertices that move by at least half of some shape's maximum.",
    "crossval": "Cross-validation of `--alpha auto`: pooled and per-fold held-out error against the final "
                "alpha, the chosen alpha marked.",
    "history": "Per-iteration history: schedule, energies, objectives, constraint residuals, IPOPT status, times.",
    "residuals_table": "Per-example relative residual and whether it is flagged missing.",
    "weights_table": "The solved weights, one row per training expression.",
}


def _run_tables(out: Path, history: dict, weights: dict, residuals: dict) -> list[Path]:
    its = history["iterations"]
    keys = [k for k in ("iteration", "alpha", "lam", "e_fit", "e_reg", "weight_objective", "weight_prior",
                        "ipopt_objective", "max_complementarity", "max_bound_violation", "ipopt_max_complementarity",
                        "ipopt_max_bound_violation", "ipopt_status", "ipopt_iterations", "basis_seconds",
                        "weight_seconds") if its and k in its[0]]
    header = [{"e_fit": "E_fit (cm²)", "e_reg": "E_reg (cm²)", "weight_objective": "weight objective (cm²)",
               "weight_prior": "of it, prior (cm²)",
               "ipopt_objective": "IPOPT objective (cm²)", "lam": "lambda (cm²)",
               "basis_seconds": "basis step (s)", "weight_seconds": "weight step (s)"}.get(k, k) for k in keys]
    paths = write_table(out, "history", header,
                        [[("" if isinstance(h[k], float) and not np.isfinite(h[k]) else h[k]) for k in keys] for h in its])
    r = residuals["relative_residual"]
    missing = set(residuals.get("missing", []))
    paths += write_table(out, "residuals_table", ("example", "relative residual", "missing (above threshold)"),
                         [(n, float(v), "yes" if n in missing else "no") for n, v in r.items()])
    shapes, examples = history["shapes"], history["examples"]
    paths += write_table(out, "weights_table", ["example"] + list(shapes),
                         [[e] + [float(weights.get(e, {}).get(s, 0.0)) for s in shapes] for e in examples],
                         floatfmt="{:.3f}")
    return paths


def _run_index(run: Path, out: Path, history: dict, residuals: dict, paths: list[Path], written_as=None) -> Path:
    its = history["iterations"]
    r = residuals["relative_residual"]
    first, last = its[0], its[-1]
    opts = history.get("options", {})
    key = [f"- {len(history['shapes'])} shapes, {len(history['examples'])} training expressions, "
           f"{len(its)} iterations ({history.get('seconds', float('nan')):.3g} s"
           f" + {history.get('precompute_seconds', float('nan')):.3g} s precomputation).",
           f"- alpha {first['alpha']:.3g} -> {last['alpha']:.3g}, lambda {first['lam']:.3g} -> {last['lam']:.3g}"
           + (f" (weight measure: {opts['weight_measure']})" if "weight_measure" in opts else "") + ".",
           f"- E_fit {first['e_fit']:.4g} -> {last['e_fit']:.4g} cm² ({first['e_fit'] / max(last['e_fit'], 1e-300):.3g}x lower), "
           f"E_reg {first['e_reg']:.4g} -> {last['e_reg']:.4g} cm².",
           f"- Relative residual of the training expressions: median {np.median(list(r.values())):.3g}, "
           f"max {max(r.values()):.3g} ({max(r, key=r.get)}); threshold {residuals['threshold']:.3g}; missing: "
           f"{', '.join(residuals.get('missing', [])) or 'none'}.",
           f"- Certified weights: max |x_a x_b| {max(h['max_complementarity'] for h in its):.3g}, max bound violation "
           f"{max(0.0, max(h['max_bound_violation'] for h in its)):.3g}; IPOPT statuses: "
           f"{', '.join(sorted(set(h.get('ipopt_status', '?') for h in its)))}."]
    existing = [p for p in dict.fromkeys(paths) if p.is_file() and p.parent.resolve() == out.resolve()]
    figs, tabs = {}, {}
    for p in existing:
        (figs if p.suffix in (".png", ".pdf", ".svg") else tabs).setdefault(p.stem, []).append(p.name)
    lines = [f"# Rig run report: {Path(run).resolve().name}", "",
             f"Figures and tables of the `facebasis rig` output folder `{_rel(run, written_as or out)}` (relative to this file), "
             "made by `facebasis report` from its history.json, weights.json and residuals.json.", "",
             "## Key numbers", ""] + key + ["", "## Figures", "", "| figure | what it shows |", "|---|---|"]
    lines += [f"| {' '.join(f'[`{n}`]({n})' for n in names)} | {RUN_FILES.get(stem, '')} |" for stem, names in figs.items()]
    lines += ["", "## Tables (Markdown + CSV)", "", "| table | what it holds |", "|---|---|"]
    lines += [f"| {' '.join(f'[`{n}`]({n})' for n in names)} | {RUN_FILES.get(stem, '')} |" for stem, names in tabs.items()]
    return _write_text(out / "index.md", "\n".join(lines) + "\n")


def crossval_figure(run_dir, path: Path, formats=FORMATS) -> list[Path]:
    """The cross-validation curve of ``facebasis rig --alpha auto`` (``crossval.json`` of the run
    folder; none without it): pooled and per-fold held-out error against the final alpha, the
    choice marked. Only reads the file."""
    from .figures import COLUMN, DIMENSIONLESS, legend_outside, unit

    cv_path = Path(run_dir) / "crossval.json"
    if not cv_path.is_file():
        return []
    try:
        cv = json.loads(cv_path.read_text())
        grid, errors, best = cv["grid"], cv["errors"], float(cv["best_alpha"])
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{cv_path}: expected grid, errors and best_alpha, found an unreadable file ({exc})") from exc
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(COLUMN, 2.6))
    for f, row in enumerate(cv.get("fold_errors", [])):
        ax.plot(grid, row, "-", color="0.75", lw=0.8, label="one fold" if f == 0 else None)
    # coarse candidates (--cv-candidates coarse) score the path on the first folds only; the chosen
    # alpha's error over all folds is chosen_error
    coarse = cv.get("coarse_folds")
    pooled = f"pooled over the first {coarse} folds" if coarse else "pooled over the folds"
    ax.plot(grid, errors, "o-", color="tab:blue", label=pooled)
    if coarse and cv.get("chosen_error") is not None:
        ax.plot([best], [float(cv["chosen_error"])], "s", color="tab:red", ms=5, label="chosen, all folds")
    ax.axvline(best, color="tab:red", ls="--", lw=1, label=f"chosen alpha {best:g}")
    ax.set_xscale("log")
    ax.set_xlabel(unit("final alpha (schedule 5a -> a)", DIMENSIONLESS))
    ax.set_ylabel(unit("held-out relative error", DIMENSIONLESS))
    h, lab = ax.get_legend_handles_labels()
    legend_outside(ax, h, lab, where="above", ncol=2)
    return save(fig, path, formats)


def check_run_folder(run_dir) -> Path:
    """``RUN_DIR/history.json`` of a ``facebasis rig`` output folder; InputError naming the folder if absent."""
    hist_path = Path(run_dir) / "history.json"
    if not hist_path.is_file():
        raise InputError(f"{run_dir}: expected history.json (a `facebasis rig` output folder), found no such file")
    return hist_path


def report_run(run_dir, out=None, formats=FORMATS, renders_dir=None, written_as=None) -> list[Path]:
    """Figures and tables of a ``facebasis rig`` output folder (written to ``RUN_DIR/report`` by
    default) and an ``index.md`` naming each file with what it shows and the run's key numbers.

    ``renders_dir``: where the shape renders go (default ``out``); renders elsewhere are not listed
    in the index (used for faces that must not be committed with the report); ``written_as``: the
    folder ``out`` will become (when ``out`` is a staging folder), for the index's relative paths."""
    from ..geometry.rig import load_rig_folder
    from .figures import COLUMN, DIMENSIONLESS, PAGE, legend_outside, unit

    run = Path(run_dir)
    hist_path = check_run_folder(run)
    try:
        history = json.loads(hist_path.read_text())
        weights = json.loads((run / "weights.json").read_text())
        residuals = json.loads((run / "residuals.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{run}: expected readable history.json, weights.json and residuals.json ({exc})") from exc
    out = Path(out) if out is not None else run / "report"
    paths = convergence_figure(history, out / "convergence", formats)
    shapes = history["shapes"]
    examples = history["examples"]
    plt = _pyplot()
    # solved weights, examples x shapes
    W = np.array([[weights.get(e, {}).get(s, 0.0) for s in shapes] for e in examples])
    width = min(PAGE, max(COLUMN, 0.13 * len(shapes) + 1.6))
    fig, ax = plt.subplots(figsize=(width, 0.14 * len(examples) + 1.9))
    im = ax.imshow(W, aspect="auto", cmap="viridis", vmin=0, vmax=1, interpolation="nearest")
    ax.set_xticks(range(len(shapes)), shapes, rotation=90)
    ax.set_yticks(range(len(examples)), examples)
    ax.set_xlabel("shape")
    ax.set_ylabel("training expression")
    ax.set_title("solved weights (complementarity pairs exact)")
    fig.colorbar(im, ax=ax, fraction=0.04, pad=0.02).set_label(unit("weight", DIMENSIONLESS))
    paths += save(fig, out / "weights", formats)
    # residuals with the missing-expression threshold
    r = residuals["relative_residual"]
    names = list(r)
    fig, ax = plt.subplots(figsize=(min(PAGE, max(COLUMN, 0.14 * len(r) + 1.2)), 2.4))
    vals = [r[n] for n in names]
    missing = set(residuals.get("missing", []))
    colors = ["tab:red" if n in missing else "tab:blue" for n in names]
    ax.bar(range(len(names)), vals, color=colors)
    from matplotlib.patches import Patch

    handles = [Patch(color="tab:blue", label="reproduced"), Patch(color="tab:red", label="missing (above threshold)"),
               ax.axhline(residuals["threshold"], color="k", ls="--", lw=1, label="missing-expression threshold")]
    ax.set_xticks(range(len(names)), names, rotation=90)
    ax.set_xlabel("training expression")
    ax.set_ylabel(unit(r"$\|B_0 + Bx_j - T_j\| / \|T_j - B_0\|$", DIMENSIONLESS))
    legend_outside(ax, handles, [h.get_label() for h in handles], where="above", ncol=2)
    paths += save(fig, out / "residuals", formats)
    paths += crossval_figure(run, out / "crossval", formats)
    # the generated shapes, coloured by displacement
    rig = load_rig_folder(run, "neutral.obj")
    renders = out if renders_dir is None else Path(renders_dir)
    paths += shapes_figure(rig, renders / "shapes", formats=formats)
    paths += _run_tables(out, history, weights, residuals)
    paths.append(_run_index(run, out, history, residuals, paths, written_as))
    return paths


def shapes_figure(rig, path: Path, names=None, view="front", formats=("png", "pdf"), cols: int | None = None,
                  normalise: bool = True, panel_px: int = 200) -> list[Path]:
    """Every shape of a rig rendered with its per-vertex displacement (heat map), cropped to the
    part of the face that moves (:func:`~facebasis.report.figures.face_crop` with ``rel=0.5``: the
    vertices that move by at least half of some shape's maximum).

    Each panel is rasterised with numpy (:func:`facebasis.report.render.render_image`) straight
    into one image of the whole grid, one shape at a time, so memory is that image plus one
    shape's render however many shapes there are (not a matplotlib polygon collection per shape);
    the figure shows the grid image with vector titles and colour bar.

    Parameters
    ----------
    rig : :class:`facebasis.geometry.rig.Rig` (neutral (n, 3), faces (m, 3), deltas (k, n, 3))
    path : output path without suffix
    names : shapes to show (default all, in the rig's order)
    normalise : each shape on its own scale (displacement / the shape's maximum, the maximum in the
        rig's units in the panel title), so small shapes (lids) show as well as the jaw; otherwise
        one scale for all
    panel_px : width of one panel's render in pixels
    """
    from ..progress import progress
    from .figures import DIMENSIONLESS, PAGE, face_crop, unit
    from .render import heat_cmap, render_image

    plt = _pyplot()
    names = list(rig.names if names is None else names)
    if cols is None:  # as many as the longest name allows at 8 pt (about 0.066 in a character)
        cols = int(np.clip(PAGE // (0.066 * max(map(len, names)) + 0.1), 4, 8))
    cols = max(1, min(cols, len(names)))
    rows = int(np.ceil(len(names) / cols))
    crop = face_crop(rig.neutral, rig.deltas, view, rel=0.5)
    aspect = (crop[1][1] - crop[1][0]) / (crop[0][1] - crop[0][0])
    pw_px = int(panel_px)
    ph_px = max(1, int(round(pw_px * aspect)))
    gap = max(2, pw_px // 40)
    canvas = np.full((rows * (ph_px + gap), cols * (pw_px + gap), 3), 255, np.uint8)
    mag_all = None if normalise else np.linalg.norm(rig.deltas, axis=2)
    vmax_all = 1.0 if normalise else (float(np.percentile(mag_all, 99.5)) or 1.0)
    cmap = heat_cmap()
    peaks = []
    for k, name in enumerate(progress(names, desc="rendering shapes")):
        i = rig.index([name])[0]
        mag = np.linalg.norm(rig.deltas[i], axis=1)
        peak = float(mag.max())
        peaks.append(peak)
        vals = mag / (peak or 1.0) if normalise else mag
        img = render_image(rig.neutral + rig.deltas[i], rig.faces, crop, pw_px, values=vals, vmin=0.0,
                           vmax=vmax_all, cmap=cmap, view=view)
        r, c = divmod(k, cols)
        h = min(img.shape[0], ph_px)
        canvas[r * (ph_px + gap): r * (ph_px + gap) + h, c * (pw_px + gap): c * (pw_px + gap) + pw_px] = img[:h]
    # layout (inches): the grid image, a title band over each panel row, the colour bar under all
    pw = PAGE / cols
    ph = pw * (ph_px + gap) / (pw_px + gap)
    title_h, top, bottom = 0.3, 0.3, 0.55
    H = top + rows * (ph + title_h) + bottom
    fig = plt.figure(figsize=(PAGE, H))
    for r in range(rows):  # one axis per row of panels: a title band above each
        y0 = H - top - r * (ph + title_h) - title_h - ph
        ax = fig.add_axes((0, y0 / H, 1, ph / H))
        ax.imshow(canvas[r * (ph_px + gap):(r + 1) * (ph_px + gap)], interpolation="antialiased",
                  extent=(0, cols * (pw_px + gap), ph_px + gap, 0))
        ax.set_xlim(0, cols * (pw_px + gap))
        ax.axis("off")
        for c in range(cols):
            k = r * cols + c
            if k < len(names):
                label = f"{names[k]}\nmax {peaks[k]:.2f}" if normalise else names[k]
                fig.text((c + 0.5) * pw / PAGE, (y0 + ph + 0.02) / H, label, fontsize=8, ha="center", va="bottom")
    import matplotlib.cm as mcm
    import matplotlib.colors as mcolors

    cax = fig.add_axes((0.2, 0.28 / H, 0.6, 0.1 / H))
    cb = fig.colorbar(mcm.ScalarMappable(mcolors.Normalize(0, vmax_all), cmap), cax=cax, orientation="horizontal")
    cb.set_label(unit("displacement / the shape's maximum", DIMENSIONLESS) if normalise
                 else unit("displacement", "mesh units"))
    fig.suptitle(f"{len(names)} shapes, front view cropped to the moving face; "
                 + ("each on its own colour scale (its maximum displacement, mesh units, under its name)"
                    if normalise else "one colour scale"), y=1 - 0.06 / H, va="top", fontsize=8)
    return save(fig, path, formats)


__all__ = ["check_run_folder", "report_run", "sweep_report", "formulation_report", "penetration_figure", "shapes_figure",
           "markdown_table", "write_table"]
