"""Paper-style figures and tables, made only from stored results (never re-solving).

* :func:`report_run` - a ``facebasis rig`` output folder: convergence, weights, residuals, the
  generated shapes rendered with their displacement (PNG + PDF); tables of the per-iteration
  history, per-example residuals and weights (Markdown + CSV); an ``index.md`` with the run's key
  numbers and what each file shows (links relative, only files written).
* :func:`sweep_report` - a results table of :mod:`facebasis.report.studies`: alpha and lambda sweeps
  (held-out and training error), the alpha x lambda heat map, initial-weight robustness, the method
  comparison (table + figure).
* :func:`formulation_report` - the weight-step formulation comparison (:mod:`facebasis.rigging.formulations`).
* :func:`penetration_figure` - close-ups of lips and lids with and without virtual edges, the
  intersecting triangles in red, from arrays saved by the penetration study.

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
from .render import HIGHLIGHT2_RGB, HIGHLIGHT_RGB, draw_mesh
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
    "convergence": "E_fit and E_reg (cm²) with the alpha schedule, the weight-step objective (certified and "
                   "IPOPT) with the lambda schedule, and the constraint residuals, per iteration.",
    "weights": "The solved weights of each training expression (rows) on each shape (columns), 0 to 1.",
    "residuals": "Relative residual of each training expression after the run; red above the "
                 "missing-expression threshold (dashed).",
    "shapes": "Every generated shape, coloured by its displacement divided by the shape's own maximum "
              "(one scale per shape; the maximum in cm is in each panel's title), cropped to the moving face.",
    "crossval": "Cross-validation of `--alpha auto`: pooled and per-fold held-out error against the final "
                "alpha, the chosen alpha marked.",
    "history": "Per-iteration history: schedule, energies, objectives, constraint residuals, IPOPT status, times.",
    "residuals_table": "Per-example relative residual and whether it is flagged missing.",
    "weights_table": "The solved weights, one row per training expression.",
}


def _run_tables(out: Path, history: dict, weights: dict, residuals: dict) -> list[Path]:
    its = history["iterations"]
    keys = [k for k in ("iteration", "alpha", "lam", "e_fit", "e_reg", "weight_objective", "ipopt_objective",
                        "max_complementarity", "max_bound_violation", "ipopt_max_complementarity",
                        "ipopt_max_bound_violation", "ipopt_status", "ipopt_iterations", "basis_seconds",
                        "weight_seconds") if its and k in its[0]]
    header = [{"e_fit": "E_fit (cm²)", "e_reg": "E_reg (cm²)", "weight_objective": "weight objective (cm²)",
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


def _run_index(run: Path, out: Path, history: dict, residuals: dict, paths: list[Path]) -> Path:
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
           f"{max(h['max_bound_violation'] for h in its):.3g}; IPOPT statuses: "
           f"{', '.join(sorted(set(h.get('ipopt_status', '?') for h in its)))}."]
    existing = [p for p in dict.fromkeys(paths) if p.is_file() and p.parent.resolve() == out.resolve()]
    figs, tabs = {}, {}
    for p in existing:
        (figs if p.suffix in (".png", ".pdf", ".svg") else tabs).setdefault(p.stem, []).append(p.name)
    lines = [f"# Rig run report: `{_rel(run, out)}`", "",
             f"Figures and tables of the `facebasis rig` output folder `{_rel(run, out)}` (relative to this file), "
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
    ax.plot(grid, errors, "o-", color="tab:blue", label="pooled over the folds")
    ax.axvline(best, color="tab:red", ls="--", lw=1, label=f"chosen alpha {best:g}")
    ax.set_xscale("log")
    ax.set_xlabel(unit("final alpha (schedule 5a -> a)", DIMENSIONLESS))
    ax.set_ylabel(unit("held-out relative error", DIMENSIONLESS))
    h, lab = ax.get_legend_handles_labels()
    legend_outside(ax, h, lab, where="above", ncol=2)
    return save(fig, path, formats)


def report_run(run_dir, out=None, formats=FORMATS, renders_dir=None) -> list[Path]:
    """Figures and tables of a ``facebasis rig`` output folder (written to ``RUN_DIR/report`` by
    default) and an ``index.md`` naming each file with what it shows and the run's key numbers.

    ``renders_dir``: where the shape renders go (default ``out``); renders elsewhere are not listed
    in the index (used for faces that must not be committed with the report)."""
    from ..geometry.rig import load_rig_folder
    from .figures import COLUMN, DIMENSIONLESS, PAGE, legend_outside, unit

    run = Path(run_dir)
    hist_path = run / "history.json"
    if not hist_path.is_file():
        raise InputError(f"{run}: expected history.json (a `facebasis rig` output folder), found no such file")
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
    paths.append(_run_index(run, out, history, residuals, paths))
    return paths


def shapes_figure(rig, path: Path, names=None, view="front", formats=("png", "pdf"), cols: int | None = None,
                  normalise: bool = True) -> list[Path]:
    """Every shape of a rig rendered with its per-vertex displacement (heat map), cropped to the
    part of the face that moves. ``normalise``: each shape on its own scale (displacement / the
    shape's maximum, the maximum in cm in the panel title), so small shapes (lids) show as well as
    the jaw; otherwise one scale in cm for all."""
    from .figures import PAGE, DIMENSIONLESS, face_crop, unit

    plt = _pyplot()
    names = list(rig.names if names is None else names)
    if cols is None:  # as many as the longest name allows at 8 pt (about 0.066 in a character)
        cols = int(np.clip(PAGE // (0.066 * max(map(len, names)) + 0.1), 4, 8))
    cols = max(1, min(cols, len(names)))
    rows = int(np.ceil(len(names) / cols))
    crop = face_crop(rig.neutral, rig.deltas, view)
    aspect = (crop[1][1] - crop[1][0]) / (crop[0][1] - crop[0][0])
    # explicit layout (inches): equal panels of the crop's aspect, a title band over each, the colour
    # bar under all
    pw, title_h, top, bottom = PAGE / cols, 0.36, 0.3, 0.62
    ph = pw * aspect
    H = top + rows * (ph + title_h) + bottom
    fig = plt.figure(figsize=(PAGE, H))
    axes = np.empty((rows, cols), object)
    for r in range(rows):
        for c in range(cols):
            y0 = H - top - r * (ph + title_h) - title_h - ph
            axes[r, c] = fig.add_axes(((c * pw + 0.02 * pw) / PAGE, y0 / H, 0.96 * pw / PAGE, 0.96 * ph / H))
    mag = np.linalg.norm(rig.deltas, axis=2)
    vmax_all = float(np.percentile(mag, 99.5)) or 1.0
    mapper = None
    for ax, name in zip(axes.ravel(), names):
        i = rig.index([name])[0]
        peak = float(mag[i].max())
        vals, vmax = (mag[i] / (peak or 1.0), 1.0) if normalise else (mag[i], vmax_all)
        mapper = draw_mesh(ax, rig.neutral + rig.deltas[i], rig.faces, values=vals, vmin=0, vmax=vmax,
                           cmap="magma_r", view=view, crop=crop)
        ax.set_title(f"{name}\nmax {peak:.2f} cm" if normalise else name, fontsize=8, pad=2)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    if mapper is not None:
        cax = fig.add_axes((0.2, 0.3 / H, 0.6, 0.1 / H))
        cb = fig.colorbar(mapper, cax=cax, orientation="horizontal")
        cb.set_label(unit("displacement / the shape's maximum", DIMENSIONLESS) if normalise
                     else unit("displacement", "cm"))
    fig.suptitle(f"{len(names)} shapes, " + ("each on its own colour scale (maximum displacement in its title)"
                                              if normalise else "one colour scale"), y=1 - 0.08 / H, va="top")
    return save(fig, path, formats)


# ----------------------------------------------------------------------------------------------
# studies

def _rows(rows, study):
    return [r for r in rows if r["study"] == study]


def _by(rows, key):
    vals = sorted({r[key] for r in rows if r[key] is not None})
    return vals


def _mean_std(rows, key, group_key, group_vals):
    m, s = [], []
    for v in group_vals:
        xs = [r[key] for r in rows if r[group_key] == v and r[key] is not None]
        m.append(np.mean(xs) if xs else np.nan)
        s.append(np.std(xs) if xs else np.nan)
    return np.array(m), np.array(s)


def _bar_labels(ax, ys, vals, errs=None, fmt="{:.3g}"):
    """Values written at the end of horizontal bars (after the error bar, if any)."""
    span = ax.get_xlim()[1]
    for y, v, e in zip(ys, vals, errs if errs is not None else [0.0] * len(vals)):
        e = 0.0 if e is None or not np.isfinite(e) else e
        ax.text(v + e + 0.015 * span, y, fmt.format(v) + (f" ± {fmt.format(e)}" if e > 0 else ""),
                va="center", ha="left", fontsize=8)


def sweep_report(rows, out, formats=FORMATS) -> list[Path]:
    """Figures and tables of a results table (rows of :func:`facebasis.report.studies.read_table`)."""
    from .figures import COLUMN, DIMENSIONLESS, PAGE, legend_outside, unit

    out = Path(out)
    plt = _pyplot()
    paths: list[Path] = []
    for study, key, label, note in (("alpha", "alpha0", unit(r"$\alpha$, constant over the run", DIMENSIONLESS), "alpha_sweep"),
                                    ("lambda", "lam0", unit(r"$\lambda$, constant over the run", "cm²"), "lambda_sweep")):
        rs = _rows(rows, study)
        if not rs:
            continue
        xs = _by(rs, key)
        n_seeds = len(_by(rs, "seed"))
        fig, ax = plt.subplots(figsize=(COLUMN, 3.3), layout="constrained")
        for metric, style, lab in (("heldout_error", "o-", "held-out expressions (weights refitted)"),
                                   ("train_error", "s--", "training expressions")):
            m, s = _mean_std(rs, metric, key, xs)
            ax.errorbar(xs, m, yerr=s if n_seeds > 1 else None, fmt=style, ms=4, capsize=2, label=lab)
        dt = [r["heldout_error"] for r in _rows(rows, "methods") if r["method"] == "deformation transfer"]
        if dt:
            ax.axhline(float(np.mean(dt)), color="0.4", ls=":", lw=1, label="deformation transfer (held-out)")
        if study == "alpha":
            ax.axvspan(min(xs), 0.05, color="tab:red", alpha=0.08, label=r"$\alpha < 0.05$ (seed 000: overfitting)")
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel(unit("relative error", DIMENSIONLESS))
        legend_outside(ax, where="below")
        seeds = f"mean ± std over {n_seeds} seeds" if n_seeds > 1 else "n = 1 seed"
        ax.set_title(f"{study} sweep ({rs[0]['problem']} face, {seeds})")
        paths += save(fig, out / note, formats)
    rs = _rows(rows, "grid")
    if rs:
        A, L = _by(rs, "alpha0"), _by(rs, "lam0")
        H = np.full((len(A), len(L)), np.nan)
        for i, a in enumerate(A):
            for j, v in enumerate(L):
                xs = [r["heldout_error"] for r in rs if r["alpha0"] == a and r["lam0"] == v]
                H[i, j] = np.mean(xs) if xs else np.nan
        fig, ax = plt.subplots(figsize=(COLUMN, 3.0), layout="constrained")
        im = ax.imshow(H, origin="lower", cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(L)), [f"{v:.3g}" for v in L])
        ax.set_yticks(range(len(A)), [f"{a:.2g}" for a in A])
        mid = np.nanmean([np.nanmin(H), np.nanmax(H)])
        for i in range(len(A)):
            for j in range(len(L)):
                ax.text(j, i, f"{H[i, j]:.3f}", ha="center", va="center", fontsize=8,
                        color="w" if H[i, j] < mid else "k")
        ax.set_xlabel(unit(r"$\lambda$", "cm²"))
        ax.set_ylabel(unit(r"$\alpha$", DIMENSIONLESS))
        n_seeds = len(_by(rs, "seed"))
        ax.set_title(f"held-out error over α × λ ({rs[0]['problem']} face, " +
                     (f"mean of {n_seeds} seeds)" if n_seeds > 1 else "n = 1 seed)"))
        fig.colorbar(im, ax=ax).set_label(unit("held-out relative error", DIMENSIONLESS))
        paths += save(fig, out / "alpha_lambda_heatmap", formats)
    rs = _rows(rows, "noise")
    if rs:
        xs = _by(rs, "noise")
        fig, axes = plt.subplots(1, 2, figsize=(PAGE, 2.6), layout="constrained")
        for ax, metric, lab in ((axes[0], "rig_change", r"rig change $\|B(\nu) - B(0)\| / \|B(0)\|$"),
                                (axes[1], "heldout_error", "held-out relative error")):
            ax.set_title(lab)
            lab = "rig change" if metric == "rig_change" else "held-out error"
            m, s = _mean_std(rs, metric, "noise", xs)
            ax.errorbar(xs, m, yerr=s, fmt="o-", ms=4, capsize=3)
            ax.set_xlabel(unit(r"initial-weight noise $\nu$, uniform in $[-\nu, \nu]$", DIMENSIONLESS))
            ax.set_ylabel(unit(lab, DIMENSIONLESS))
        n_seeds = len(_by(rs, "noise_seed"))
        fig.suptitle(f"robustness to the initial weights ({rs[0]['problem']} face; mean and std over "
                     f"{n_seeds} noise seeds)")
        paths += save(fig, out / "noise_robustness", formats)
    rs = _rows(rows, "methods")
    if rs:
        methods = list(dict.fromkeys(r["method"] for r in rs))
        table = []
        for mth in methods:
            sel = [r for r in rs if r["method"] == mth]
            he = [r["heldout_error"] for r in sel]
            se = [r["shape_error"] for r in sel if r["shape_error"] is not None]
            secs = [r["seconds"] for r in sel]
            several = len(sel) > 1  # no std of one seed
            table.append((mth, float(np.mean(he)), float(np.std(he)) if several else "", float(np.mean(secs)),
                          float(np.std(secs)) if several else "", float(np.mean(se)) if se else "", len(sel)))
        header = ("method", "held-out error (mean)", "held-out error (std over seeds)", "seconds (mean)",
                  "seconds (std)", "median shape error vs truth", "seeds")
        paths += write_table(out, "methods", header, table)
        n = max(t[6] for t in table)
        fig, axes = plt.subplots(1, 2, figsize=(PAGE, 2.5), layout="constrained", sharey=True)
        ys = np.arange(len(table))
        for ax, mcol, scol, color, lab in ((axes[0], 1, 2, "tab:blue", unit("held-out relative error", DIMENSIONLESS)),
                                           (axes[1], 3, 4, "tab:gray", unit("time, single thread", "s"))):
            vals = [t[mcol] for t in table]
            errs = [t[scol] or 0.0 for t in table] if n > 1 else None
            ax.barh(ys, vals, xerr=errs, color=color, capsize=3)
            ax.set_xlim(0, 1.45 * max(v + (e or 0) for v, e in zip(vals, errs or [0] * len(vals))))
            _bar_labels(ax, ys, vals, errs)
            ax.set_xlabel(lab)
        axes[0].set_yticks(ys, [t[0] for t in table])
        axes[0].set_ylabel("method")
        axes[0].invert_yaxis()
        seeds = f"mean ± std over {n} seeds" if n > 1 else "n = 1 seed, no error bars"
        fig.suptitle(f"methods on the {rs[0]['problem']} face ({seeds})")
        paths += save(fig, out / "methods", formats)
    return paths


# ----------------------------------------------------------------------------------------------
# formulation comparison and penetration

def formulation_report(rows, out, formats=FORMATS) -> list[Path]:
    """Table and figure of :func:`facebasis.rigging.formulations.compare_formulations` rows."""
    from ..rigging.formulations import summarise_comparison

    out = Path(out)
    summary = summarise_comparison(rows)
    header = ("method", "reached optimum", "instances", "worst gap", "max |x_a x_b|", "max bound violation",
              "median ms", "max ms", "IPOPT statuses")
    table = [(s["method"], s["reached"], s["instances"], s["worst_relative_gap"], s["max_complementarity"],
              s["max_bound_violation"], s["median_ms"], s["max_ms"], s["statuses"]) for s in summary]
    paths = write_table(out, "formulations", header, table)
    raw = [(r["instance"], r["kind"], r["method"], r["objective"], r["certified_objective"], r["relative_gap"],
            r["max_complementarity"], r["max_bound_violation"], r["seconds"], r["statuses"]) for r in rows]
    _write_text(out / "formulations_per_instance.csv",
                csv_table(("instance", "kind", "method", "objective", "certified", "relative gap", "max |x_a x_b|",
                           "bound violation", "seconds", "statuses"), raw))
    paths.append(out / "formulations_per_instance.csv")
    plt = _pyplot()
    from .figures import DIMENSIONLESS, PAGE, legend_outside, unit

    methods = [s["method"] for s in summary if s["method"] != "certified"]
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(PAGE, 3.0), layout="constrained", width_ratios=(1.6, 1))
    for k, mth in enumerate(methods):
        gaps = [max(abs(r["relative_gap"]), 1e-16) for r in rows if r["method"] == mth]
        kind_idx = [kinds.index(r["kind"]) for r in rows if r["method"] == mth]
        axes[0].scatter(np.array(kind_idx) + 0.15 * (k - 1.5), gaps, s=9, label=mth)
    axes[0].set_yscale("log")
    axes[0].axhline(1e-6, color="k", ls="--", lw=0.8, label="reached: gap < 1e-6")
    axes[0].set_xticks(range(len(kinds)), kinds, rotation=30, ha="right")
    axes[0].set_xlabel("instance kind")
    axes[0].set_ylabel(unit("relative gap to the certified optimum", DIMENSIONLESS))
    legend_outside(axes[0], where="above", ncol=3)
    axes[1].bar(range(len(summary)), [s["median_ms"] for s in summary], color="tab:gray")
    axes[1].set_xticks(range(len(summary)), [s["method"] for s in summary], rotation=30, ha="right")
    axes[1].set_xlabel("method")
    axes[1].set_ylabel(unit("median time per instance", "ms"))
    top = max(s["median_ms"] for s in summary)
    axes[1].set_ylim(0, 1.25 * top)
    for i, s in enumerate(summary):
        axes[1].text(i, s["median_ms"] + 0.02 * top, f"{s['reached']}/{s['instances']}", ha="center", va="bottom",
                     fontsize=8)
    axes[1].set_title("bar labels: instances reaching the optimum")
    fig.suptitle("weight step (eq. 5): IPOPT formulations against the certified optimum\n"
                 "(gap = |objective − certified| / max(1, |certified|))")
    return paths + save(fig, out / "formulations", formats)


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
    """Close-ups of lips and lids: plain transfer vs virtual edges, intersecting triangles in red.

    ``data`` (as saved by the penetration study): ``faces`` (m, 3); for each expression name
    ``<name>/plain`` and ``<name>/ve`` vertex arrays and ``<name>/plain_hits``, ``<name>/ve_hits``
    face index arrays; ``crops`` {zone: (view, ((x0, x1), (y0, y1)))}; ``names``. Optional
    ``<name>/plain_local_hits``, ``<name>/ve_local_hits``: triangles of local folds, drawn in orange
    (``*_hits`` then holds the layer crossings, in red); optional ``zone_faces`` {zone: face indices}:
    the triangles of each zone, whose highlighted ones each panel counts (without it: the
    highlighted triangles whose centre is inside the panel's crop).

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
    cols = 2 * len(zones)
    pw = PAGE / cols
    ph = pw / aspect
    title_h, head_h, left, bottom = 0.36, 0.36, 0.22, 0.55
    H = head_h + len(names) * (ph + title_h) + bottom
    W = PAGE + left
    fig = plt.figure(figsize=(W, H))
    local_any = any(f"{n}/{k}_local_hits" in data for n in names for k in ("plain", "ve"))
    for row, name in enumerate(names):
        y0 = H - head_h - row * (ph + title_h) - title_h - ph
        fig.text(0.5 * left / W, (y0 + 0.5 * ph) / H, name, rotation=90, ha="center", va="center", fontsize=9)
        col = 0
        for zone, (view, crop) in zones.items():
            for kind in ("plain", "ve"):
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
                what = f"{int((hl & inzone).sum())} crossing"
                if hl2 is not None:
                    what += f", {int((hl2 & inzone).sum())} fold"
                ax.set_title(what, fontsize=8, pad=2)
                if row == 0:
                    label = "plain transfer" if kind == "plain" else "virtual edges"
                    fig.text((left + (col + 0.5) * pw) / W, (H - 0.05) / H, f"{zone}: {label}", ha="center",
                             va="top", fontsize=9, fontweight="bold")
                col += 1
    handles = [Patch(color=HIGHLIGHT_RGB, label="layer crossing (intersecting triangles ≥ 2 median edges apart along "
                                                "the surface); panel titles count the zone's triangles")]
    if local_any:
        handles.append(Patch(color=HIGHLIGHT2_RGB, label="local fold (intersecting triangles closer along the surface)"))
    fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.0), ncol=1, frameon=False)
    return save(fig, out / "penetration_closeups", formats)


__all__ = ["report_run", "sweep_report", "formulation_report", "penetration_figure", "shapes_figure",
           "markdown_table", "write_table"]
