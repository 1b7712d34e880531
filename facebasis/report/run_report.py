"""Paper-style figures and tables, made only from stored results (never re-solving).

* :func:`report_run` - a ``facebasis rig`` output folder: convergence, weights, residuals, the
  generated shapes rendered with their displacement.
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

import csv
import io
import json
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import InputError
from .figures import _pyplot, convergence_figure, save
from .render import draw_mesh

FORMATS = ("png", "pdf")


def _write_text(path: Path, text: str) -> Path:
    atomic_write_bytes(path, text.encode())
    return path


def markdown_table(header, rows, floatfmt="{:.4g}") -> str:
    def cell(v):
        return floatfmt.format(v) if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def csv_table(header, rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def write_table(out: Path, name: str, header, rows) -> list[Path]:
    """``name.csv`` and ``name.md`` in ``out``."""
    return [_write_text(out / f"{name}.csv", csv_table(header, rows)),
            _write_text(out / f"{name}.md", markdown_table(header, rows))]


# ----------------------------------------------------------------------------------------------
# a rig run

def report_run(run_dir, out=None, formats=FORMATS) -> list[Path]:
    """Figures of a ``facebasis rig`` output folder (written to ``RUN_DIR/report`` by default)."""
    from ..geometry.rig import load_rig_folder

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
    fig, ax = plt.subplots(figsize=(max(6, 0.22 * len(shapes) + 2), max(3, 0.25 * len(examples) + 1.5)))
    im = ax.imshow(W, aspect="auto", cmap="viridis", vmin=0, vmax=1)
    ax.set_xticks(range(len(shapes)), shapes, rotation=90, fontsize=6)
    ax.set_yticks(range(len(examples)), examples, fontsize=6)
    ax.set_title("solved weights (complementarity pairs exact)", fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.03)
    paths += save(fig, out / "weights", formats)
    # residuals with the missing-expression threshold
    r = residuals["relative_residual"]
    fig, ax = plt.subplots(figsize=(max(5, 0.3 * len(r) + 1), 3))
    names = list(r)
    vals = [r[n] for n in names]
    colors = ["tab:red" if n in residuals.get("missing", []) else "tab:blue" for n in names]
    ax.bar(range(len(names)), vals, color=colors)
    ax.axhline(residuals["threshold"], color="k", ls="--", lw=1, label="missing-expression threshold")
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=7)
    ax.set_ylabel(r"$\|B_0 + Bx_j - T_j\| / \|T_j - B_0\|$")
    ax.legend(fontsize=7)
    paths += save(fig, out / "residuals", formats)
    # the generated shapes, coloured by displacement
    rig = load_rig_folder(run, "neutral.obj")
    paths += shapes_figure(rig, out / "shapes", formats=("png",))
    lines = ["# Report of " + str(run), ""] + [f"- {p.name}" for p in paths]
    paths.append(_write_text(out / "index.md", "\n".join(lines) + "\n"))
    return paths


def shapes_figure(rig, path: Path, names=None, view="front", formats=("png",), cols: int = 8) -> list[Path]:
    """Every shape of a rig rendered with its per-vertex displacement (heat map)."""
    plt = _pyplot()
    names = list(rig.names if names is None else names)
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(1.9 * cols, 2.2 * rows), squeeze=False)
    mag = np.linalg.norm(rig.deltas, axis=2)
    vmax = float(np.percentile(mag, 99.5)) or 1.0
    mapper = None
    for ax, name in zip(axes.ravel(), names):
        i = rig.index([name])[0]
        mapper = draw_mesh(ax, rig.neutral + rig.deltas[i], rig.faces, values=mag[i], vmin=0, vmax=vmax,
                           cmap="magma_r", view=view)
        ax.set_title(name, fontsize=7)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    if mapper is not None:
        fig.colorbar(mapper, ax=axes, fraction=0.015, pad=0.01).set_label("displacement")
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


def sweep_report(rows, out, formats=FORMATS) -> list[Path]:
    """Figures and tables of a results table (rows of :func:`facebasis.report.studies.read_table`)."""
    out = Path(out)
    plt = _pyplot()
    paths: list[Path] = []
    for study, key, label, note in (("alpha", "alpha0", r"$\alpha$ (constant over the run)", "alpha_sweep"),
                                    ("lambda", "lam0", r"$\lambda$ (constant over the run)", "lambda_sweep")):
        rs = _rows(rows, study)
        if not rs:
            continue
        xs = _by(rs, key)
        fig, ax = plt.subplots(figsize=(5.2, 3.6))
        for metric, style, lab in (("heldout_error", "o-", "held-out expressions (weights refitted)"),
                                   ("train_error", "s--", "training expressions")):
            m, s = _mean_std(rs, metric, key, xs)
            ax.errorbar(xs, m, yerr=s if len(_by(rs, "seed")) > 1 else None, fmt=style, ms=4, capsize=2, label=lab)
        dt = [r["heldout_error"] for r in _rows(rows, "methods") if r["method"] == "deformation transfer"]
        if dt:
            ax.axhline(float(np.mean(dt)), color="0.4", ls=":", lw=1, label="deformation transfer (held-out)")
        if study == "alpha":
            ax.axvspan(min(xs), 0.05, color="tab:red", alpha=0.08, label=r"$\alpha < 0.05$ (seed: overfitting)")
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("relative error")
        ax.legend(fontsize=7)
        ax.set_title(f"{study} sweep ({rs[0]['problem']} face, {len(_by(rs, 'seed'))} seed(s))", fontsize=9)
        fig.tight_layout()
        paths += save(fig, out / note, formats)
    rs = _rows(rows, "grid")
    if rs:
        A, L = _by(rs, "alpha0"), _by(rs, "lam0")
        H = np.full((len(A), len(L)), np.nan)
        for i, a in enumerate(A):
            for j, v in enumerate(L):
                xs = [r["heldout_error"] for r in rs if r["alpha0"] == a and r["lam0"] == v]
                H[i, j] = np.mean(xs) if xs else np.nan
        fig, ax = plt.subplots(figsize=(5.2, 4.0))
        im = ax.imshow(H, origin="lower", cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(L)), [f"{v:.3g}" for v in L])
        ax.set_yticks(range(len(A)), [f"{a:.3g}" for a in A])
        for i in range(len(A)):
            for j in range(len(L)):
                ax.text(j, i, f"{H[i, j]:.3f}", ha="center", va="center", fontsize=6, color="w")
        ax.set_xlabel(r"$\lambda$")
        ax.set_ylabel(r"$\alpha$")
        ax.set_title("held-out error over alpha x lambda", fontsize=9)
        fig.colorbar(im, ax=ax)
        fig.tight_layout()
        paths += save(fig, out / "alpha_lambda_heatmap", formats)
    rs = _rows(rows, "noise")
    if rs:
        xs = _by(rs, "noise")
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
        for ax, metric, lab in ((axes[0], "rig_change", r"$\|B(\nu) - B(0)\| / \|B(0)\|$"),
                                (axes[1], "heldout_error", "held-out error")):
            m, s = _mean_std(rs, metric, "noise", xs)
            ax.errorbar(xs, m, yerr=s, fmt="o-", capsize=3)
            ax.set_xlabel(r"initial-weight noise $\nu$ (uniform in $[-\nu, \nu]$)")
            ax.set_ylabel(lab)
        n_seeds = len(_by(rs, "noise_seed"))
        fig.suptitle(f"robustness to initial weights ({n_seeds} noise seeds, mean and std)", fontsize=9)
        fig.tight_layout()
        paths += save(fig, out / "noise_robustness", formats)
    rs = _rows(rows, "methods")
    if rs:
        methods = list(dict.fromkeys(r["method"] for r in rs))
        table = []
        for mth in methods:
            sel = [r for r in rs if r["method"] == mth]
            table.append((mth, float(np.mean([r["heldout_error"] for r in sel])),
                          float(np.mean([r["seconds"] for r in sel])),
                          "" if sel[0]["shape_error"] is None else float(np.mean([r["shape_error"] for r in sel])),
                          len(sel)))
        header = ("method", "held-out error", "seconds", "median shape error vs truth", "problems")
        paths += write_table(out, "methods", header, table)
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
        axes[0].barh(range(len(table)), [t[1] for t in table], color="tab:blue")
        axes[0].set_yticks(range(len(table)), [t[0] for t in table], fontsize=8)
        axes[0].set_xlabel("held-out relative error")
        axes[1].barh(range(len(table)), [t[2] for t in table], color="tab:gray")
        axes[1].set_yticks(range(len(table)), [""] * len(table))
        axes[1].set_xlabel("seconds (single thread)")
        fig.tight_layout()
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
    methods = [s["method"] for s in summary if s["method"] != "certified"]
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for k, mth in enumerate(methods):
        gaps = [max(abs(r["relative_gap"]), 1e-16) for r in rows if r["method"] == mth]
        kind_idx = [kinds.index(r["kind"]) for r in rows if r["method"] == mth]
        axes[0].scatter(np.array(kind_idx) + 0.15 * (k - 1.5), gaps, s=9, label=mth)
    axes[0].set_yscale("log")
    axes[0].axhline(1e-6, color="k", ls="--", lw=0.8)
    axes[0].set_xticks(range(len(kinds)), kinds, rotation=30, fontsize=7)
    axes[0].set_ylabel("|objective - certified| / max(1, |certified|)")
    axes[0].legend(fontsize=7)
    axes[1].bar(range(len(summary)), [s["median_ms"] for s in summary], color="tab:gray")
    axes[1].set_xticks(range(len(summary)), [s["method"] for s in summary], fontsize=8)
    axes[1].set_ylabel("median ms per instance")
    for i, s in enumerate(summary):
        axes[1].text(i, s["median_ms"], f"{s['reached']}/{s['instances']}", ha="center", va="bottom", fontsize=7)
    fig.suptitle("weight step (eq. 5): IPOPT formulations against the certified optimum", fontsize=9)
    fig.tight_layout()
    return paths + save(fig, out / "formulations", formats)


def penetration_figure(data: dict, out, formats=("png",)) -> list[Path]:
    """Close-ups of lips and lids: plain transfer vs virtual edges, intersecting triangles in red.

    ``data`` (as saved by the penetration study): ``faces`` (m, 3); for each expression name
    ``<name>/plain`` and ``<name>/ve`` vertex arrays and ``<name>/plain_hits``, ``<name>/ve_hits``
    face index arrays; ``crops`` {zone: (view, ((x0, x1), (y0, y1)))}; ``names``. Optional
    ``<name>/plain_local_hits``, ``<name>/ve_local_hits``: triangles of local folds, drawn in orange
    (``*_hits`` then holds the layer crossings, in red).
    """
    plt = _pyplot()
    out = Path(out)
    F = data["faces"]
    names = list(data["names"])
    zones = data["crops"]
    fig, axes = plt.subplots(len(names), 2 * len(zones), figsize=(3.2 * 2 * len(zones), 3.0 * len(names)), squeeze=False)
    for row, name in enumerate(names):
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
                ax = axes[row, col]
                draw_mesh(ax, data[f"{name}/{kind}"], F, view=view, crop=crop, highlight=hl, highlight2=hl2)
                label = "plain transfer" if kind == "plain" else "virtual edges"
                what = (f"{int(hl.sum())} triangles intersect" if hl2 is None else
                        f"{int(hl.sum())} in layer crossings (red), {int(hl2.sum())} in local folds (orange)")
                ax.set_title(f"{name}, {zone}: {label}\n{what}", fontsize=7)
                col += 1
    fig.tight_layout()
    return save(fig, out / "penetration_closeups", formats)


__all__ = ["report_run", "sweep_report", "formulation_report", "penetration_figure", "shapes_figure",
           "markdown_table", "write_table"]
