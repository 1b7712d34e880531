"""Figures and tables of study results (never re-solving): parameter sweeps and formulations.

* :func:`sweep_report` - a results table of :mod:`facebasis.report.studies`: alpha and lambda sweeps
  (held-out and training error), the alpha x lambda heat map, initial-weight robustness, the method
  comparison (table + figure).
* :func:`formulation_report` - the weight-step formulation comparison (:mod:`facebasis.rigging.formulations`).

Figures are PNG plus PDF (vector) by default; tables are CSV and Markdown, written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from .figures import _pyplot, save
from .tables import csv_table, write_table

FORMATS = ("png", "pdf")


def _write_text(path: Path, text: str) -> Path:
    atomic_write_bytes(path, text.encode())
    return path



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
    """Figures and tables of a results table (rows of :func:`facebasis.report.studies.read_table`):
    one figure per parameter sweep (alpha, lambda), the alpha x lambda heat map, the noise study and
    the methods table and figure, each for the studies the table holds."""
    out = Path(out)
    plt = _pyplot()
    paths: list[Path] = []
    paths += _parameter_sweeps(plt, rows, out, formats)
    for study, figure in (("grid", _grid_heatmap), ("noise", _noise_figure), ("methods", _methods_report)):
        rs = _rows(rows, study)
        if rs:
            paths += figure(plt, rows, rs, out, formats)
    return paths


def _parameter_sweeps(plt, rows, out, formats) -> list[Path]:
    """The alpha and lambda sweeps: held-out and training error against the constant parameter."""
    from .figures import COLUMN, DIMENSIONLESS, legend_outside, unit

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
            if metric == "heldout_error" and np.isfinite(m).any():  # the minimum, read off the curve itself
                i = int(np.nanargmin(m))
                ax.plot([xs[i]], [m[i]], marker="*", ms=11, color="tab:red", ls="none",
                        label=f"lowest held-out error ({m[i]:.3g} at {xs[i]:.3g})")
        dt = [r["heldout_error"] for r in _rows(rows, "methods") if r["method"] == "deformation transfer"]
        if dt:
            ax.axhline(float(np.mean(dt)), color="0.4", ls=":", lw=1, label="deformation transfer (held-out)")
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel(unit("relative error", DIMENSIONLESS))
        legend_outside(ax, where="below")
        seeds = f"mean ± std over {n_seeds} seeds" if n_seeds > 1 else "n = 1 seed"
        ax.set_title(f"{study} sweep ({rs[0]['problem']} face, {seeds})")
        paths += save(fig, out / note, formats)
    return paths


def _grid_heatmap(plt, rows, rs, out, formats) -> list[Path]:
    """The held-out error over the alpha x lambda grid (rows ``rs`` of the grid study)."""
    from .figures import COLUMN, DIMENSIONLESS, unit

    paths: list[Path] = []
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
    return paths


def _noise_figure(plt, rows, rs, out, formats) -> list[Path]:
    """Rig change and held-out error against the initial-weight noise (rows ``rs`` of the noise study)."""
    from .figures import DIMENSIONLESS, PAGE, unit

    paths: list[Path] = []
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
    return paths


def _methods_report(plt, rows, rs, out, formats) -> list[Path]:
    """The methods table (mean and std over seeds) and its bar figure (rows ``rs`` of the methods study)."""
    from .figures import DIMENSIONLESS, PAGE, unit

    paths: list[Path] = []
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
    fig, axes = plt.subplots(1, 2, figsize=(PAGE, 3.0), layout="constrained", width_ratios=(1.6, 1))
    floor = 1e-16  # gaps at or below rounding are drawn at the floor
    for mth in methods:  # the gap distribution of every method: fraction of instances within each gap
        gaps = np.sort([max(abs(r["relative_gap"]), floor) for r in rows if r["method"] == mth])
        axes[0].step(gaps, np.arange(1, len(gaps) + 1) / len(gaps), where="post", label=mth)
    axes[0].set_xscale("log")
    axes[0].axvline(1e-6, color="k", ls="--", lw=0.8, label="reached: gap < 1e-6")
    axes[0].set_xlabel(unit("relative gap to the certified optimum", DIMENSIONLESS))
    n_inst = len({r["instance"] for r in rows})
    axes[0].set_ylabel(unit(f"fraction of the {n_inst} instances\nwith gap ≤ x", DIMENSIONLESS))
    axes[0].set_ylim(0, 1.02)
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
    fig.suptitle("weight step (eq. 5): IPOPT formulations and the cancel-pairs heuristic against the certified "
                 "optimum\n"
                 "(gap = |objective − certified| / max(1, |certified|))")
    return paths + save(fig, out / "formulations", formats)


__all__ = ["sweep_report", "formulation_report"]
