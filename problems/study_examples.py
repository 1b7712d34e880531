"""Study: held-out error against the number of training expressions (ICT person problems).

``python -m problems.study_examples [--m 10 20 40 80 160] [--seeds 0 1 2] [--out reports/examples_study]
[--grid A ...] [--redo] [--methods METHOD ...] [--candidates path|cold] [--heldout N]``

For every (m, seed): template deltas, deformation transfer, example-based generation with the
paper's schedule (unobserved shapes fitted, the paper; and kept at their transfer, the default),
``alpha="auto"`` (k-fold cross-validation), and the oracle (true weights held fixed). Scores:
held-out relative error with refitted weights (certified; bounds + complementarity, no prior),
the per-shape error of the shapes no training expression activates, and their weight error.
Rows are merged into ``rows.json`` as every (m, seed) case finishes, under a file lock and written
atomically, so an interrupted run loses at most the case under way and several processes (e.g. one
per seed) may share one output folder; a rerun skips cases already there (``--redo`` recomputes
them). The figure ``heldout_vs_m.png`` and ``summary.md`` are redrawn from all rows.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import fcntl
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

METHODS = ("template deltas", "deformation transfer", "paper (unobserved fitted)", "paper (unobserved kept)",
           "alpha auto", "oracle (true weights)")


def run_case(m: int, seed: int, grid: tuple[float, ...] = (), methods=METHODS, candidates: str = "path",
             n_heldout: int = 20) -> list[dict]:
    from facebasis.geometry.transfer import deformation_transfer
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem

    pp = ict_person_problem(seed=seed, n_train=m, n_heldout=n_heldout)
    p = pp.problem
    unseen = np.flatnonzero(pp.true_weights.max(axis=0) == 0)
    rows = []

    def score(name, rig, seconds, cpu, weights=None, extra=None):
        err = heldout_error(rig, pp.heldout, p.pair_indices)
        d = np.linalg.norm(rig.deltas - pp.truth.deltas, axis=(1, 2)) / np.linalg.norm(pp.truth.deltas, axis=(1, 2))
        row = {"m": m, "seed": seed, "method": name, "heldout": err, "n_heldout": n_heldout, "seconds": seconds,
               "cpu_seconds": cpu,
               "n_unseen": int(len(unseen)), "unseen_shape_error": float(d[unseen].mean()) if len(unseen) else None,
               "seen_shape_error": float(np.delete(d, unseen).mean()),
               "unseen_weight_error": (float(np.abs(weights[:, unseen]).mean()) if weights is not None and len(unseen)
                                       else None),
               "initial_unseen_weight_error": float(np.abs(p.initial_weights[:, unseen]).mean()) if len(unseen) else None,
               "load_average": os.getloadavg()[0]}
        row.update(extra or {})
        rows.append(row)
        print(f"  m {m:3d} seed {seed} {name:28s} held-out {err:.4f}  unseen shapes {len(unseen):2d} "
              f"(shape error {row['unseen_shape_error'] if len(unseen) else float('nan'):.3f})  {seconds:6.1f} s",
              flush=True)

    def timed(fn):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        return out, time.perf_counter() - t0, time.process_time() - c0

    if "template deltas" in methods:
        tpl = p.template.with_neutral(p.target_neutral, p.template.deltas)
        score("template deltas", tpl, 0.0, 0.0)
    if "deformation transfer" in methods:
        dt, s, c = timed(lambda: deformation_transfer(p.template, p.target_neutral))
        score("deformation transfer", dt, s, c)
    base = GenerationOptions(ipopt="never")
    if "paper (unobserved fitted)" in methods:
        res, s, c = timed(lambda: BlendshapeGenerator(p, dataclasses.replace(base, unobserved="fit")).run())
        score("paper (unobserved fitted)", res.rig, s, c, res.weights)
    if "paper (unobserved kept)" in methods:
        res, s, c = timed(lambda: BlendshapeGenerator(p, base).run())
        score("paper (unobserved kept)", res.rig, s, c, res.weights, {"unobserved": list(res.unobserved)})
    if "alpha auto" in methods:
        auto = dataclasses.replace(base, alpha="auto", cv_grid=grid, cv_candidates=candidates)
        res, s, c = timed(lambda: BlendshapeGenerator(p, auto).run())
        cv = res.crossval
        score("alpha auto", res.rig, s, c, res.weights,
              {"best_alpha": cv.best_alpha, "cv_seconds": cv.seconds, "cv_cpu_seconds": cv.cpu_seconds,
               "cv_grid": list(cv.grid), "cv_errors": list(cv.errors), "cv_candidates": cv.candidates,
               "final_alternations": len(res.history)})
    if "oracle (true weights)" in methods:
        oracle = dataclasses.replace(p, initial_weights=pp.true_weights)
        res, s, c = timed(lambda: BlendshapeGenerator(oracle, dataclasses.replace(base, lam=(1e8, 1e8))).run())
        score("oracle (true weights)", res.rig, s, c, res.weights)
    return rows


@contextlib.contextmanager
def _locked(out: Path):
    fd = os.open(out, os.O_RDONLY)  # lock the folder itself: no lock file left behind
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def load_rows(out: Path) -> list[dict]:
    path = out / "rows.json"
    return json.loads(path.read_text()) if path.is_file() else []


def merge_rows(out: Path, new: list[dict]) -> list[dict]:
    """Merge ``new`` rows into ``out/rows.json`` under the lock (the old rows of the same case and
    method replaced), write it atomically, and return all rows."""
    from facebasis.atomic import atomic_write_bytes

    cases = {(r["m"], r["seed"], r["method"]) for r in new}
    with _locked(out):
        rows = [r for r in load_rows(out) if (r["m"], r["seed"], r["method"]) not in cases] + list(new)
        rows.sort(key=lambda r: (r["m"], r["seed"], METHODS.index(r["method"])))
        atomic_write_bytes(out / "rows.json", json.dumps(rows, indent=1).encode())
        summarise(rows, out)
    return rows


def summarise(rows, out: Path) -> None:
    from facebasis.report.figures import _pyplot, save

    ms = sorted({r["m"] for r in rows})
    table = {}
    for r in rows:
        table.setdefault((r["method"], r["m"]), []).append(r)
    counts = sorted({r.get("n_heldout", 20) for r in rows})
    lines = ["# Held-out error against the number of training expressions (ICT person problems)", "",
             "Relative held-out error `||B0 + Bx - T|| / ||T - B0||` over "
             f"{' / '.join(map(str, counts))} held-out expressions per seed, weights "
             "refitted (bounds + complementarity, no prior); mean over the seeds run (n in brackets). Made by "
             "`python -m problems.study_examples`.", "",
             "| method | " + " | ".join(f"m = {m}" for m in ms) + " |", "|---|" + "---|" * len(ms)]
    for meth in METHODS:
        cells = []
        for m in ms:
            rs = table.get((meth, m), [])
            cells.append(f"{np.mean([r['heldout'] for r in rs]):.4f} ({len(rs)})" if rs else "-")
        lines.append(f"| {meth} | " + " | ".join(cells) + " |")
    lines += ["", "Ratios to deformation transfer, per seed (alpha auto / DT; target <= 0.85 at m = 20, <= 0.35 at "
              "m = 80; and never above min(DT, template deltas)):", ""]
    for m in ms:
        for seed in sorted({r["seed"] for r in rows if r["m"] == m}):
            get = {r["method"]: r for r in rows if r["m"] == m and r["seed"] == seed}
            if "alpha auto" not in get:
                continue
            a, d, t = get["alpha auto"]["heldout"], get["deformation transfer"]["heldout"], get["template deltas"]["heldout"]
            lines.append(f"- m = {m}, seed {seed}: auto/DT = {a / d:.3f}, auto <= min(DT, template) "
                         f"{'yes' if a <= min(d, t) else 'NO'}; chosen alpha {get['alpha auto']['best_alpha']:g}"
                         f" ({get['alpha auto'].get('cv_candidates', 'path scored, fresh schedule returned (before the fix)')}"
                         + (f", {get['alpha auto']['final_alternations']} final alternations"
                            if "final_alternations" in get["alpha auto"] else "") + "); "
                         f"(grid {min(get['alpha auto']['cv_grid']):g} .. {max(get['alpha auto']['cv_grid']):g}); "
                         f"cross-validation {get['alpha auto']['cv_seconds']:.1f} s wall, "
                         f"{get['alpha auto']['cv_cpu_seconds']:.1f} s CPU; paper run "
                         f"{get['paper (unobserved kept)']['seconds']:.1f} s"
                         + (f" (load average {get['alpha auto']['load_average']:.1f})"
                            if "load_average" in get["alpha auto"] else ""))
    lines += ["", "Shapes no training expression activates (mean per-shape error vs the truth; mean |weight| of "
              "those shapes in the training expressions, whose truth is 0):", ""]
    for m in ms:
        for meth in ("template deltas", "deformation transfer", "paper (unobserved fitted)", "paper (unobserved kept)",
                     "alpha auto"):
            rs = [r for r in table.get((meth, m), []) if r["n_unseen"]]
            if not rs:
                continue
            we = [r["unseen_weight_error"] for r in rs if r["unseen_weight_error"] is not None]
            lines.append(f"- m = {m}, {meth}: {np.mean([r['n_unseen'] for r in rs]):.1f} unseen shapes, shape error "
                         f"{np.mean([r['unseen_shape_error'] for r in rs]):.3f}"
                         + (f", weight error {np.mean(we):.3f} (rough initial {np.mean([r['initial_unseen_weight_error'] for r in rs]):.3f})"
                            if we else ""))
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.2, 3.6))
    for meth, style in zip(METHODS, ("s--", "o--", "v-", "^-", "D-", "x:")):
        xs = [m for m in ms if (meth, m) in table]
        vals = [[r["heldout"] for r in table[(meth, m)]] for m in xs]
        ys = np.array([np.mean(v) for v in vals])
        lo, hi = ys - [min(v) for v in vals], [max(v) for v in vals] - ys
        ax.errorbar(xs, ys, yerr=[lo, hi], fmt=style, capsize=2, ms=4, lw=1, label=meth)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(ms, [f"{m}\n({len({r['seed'] for r in rows if r['m'] == m})} seed"
                       f"{'s' if len({r['seed'] for r in rows if r['m'] == m}) > 1 else ''})" for m in ms])
    from matplotlib.ticker import FormatStrFormatter, NullLocator

    ax.xaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FormatStrFormatter("%.2f"))
    ax.yaxis.set_minor_formatter(FormatStrFormatter("%.2f"))
    ax.tick_params(axis="y", which="minor", labelsize=7)
    ax.set_xlabel("training expressions m (log scale)")
    ax.set_ylabel("held-out relative error\n||B0 + Bx - T|| / ||T - B0|| (log)")
    seeds = sorted({r["seed"] for r in rows})
    ax.set_title(f"ICT person problems, seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}, "
                 f"{' / '.join(map(str, counts))} held-out expressions each: mean"
                 + (", bars min..max over the seeds" if len(seeds) > 1 else ""), fontsize=8)
    # legend outside the axes: never over the data
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    save(fig, out / "heldout_vs_m", ("png",))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m problems.study_examples")
    ap.add_argument("--m", type=int, nargs="+", default=[10, 20, 40, 80, 160])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", default="reports/examples_study")
    ap.add_argument("--grid", type=float, nargs="+", default=[],
                    help="candidate final alphas of alpha auto (default: the library's default grid)")
    ap.add_argument("--redo", action="store_true", help="recompute cases already in rows.json")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS, metavar="METHOD",
                    help="only these methods (their rows replaced; the others of the case kept)")
    ap.add_argument("--candidates", default="path", choices=("path", "cold"),
                    help="cross-validation candidates of alpha auto (GenerationOptions.cv_candidates)")
    ap.add_argument("--heldout", type=int, default=20,
                    help="held-out expressions scored per case (default 20; a folder's rows should share one count)")
    args = ap.parse_args(argv)
    if args.heldout < 1:
        ap.error(f"--heldout: expected a positive count, found {args.heldout}")
    counts = {r.get("n_heldout", 20) for r in load_rows(Path(args.out))}
    if counts and counts != {args.heldout}:  # ratios between methods must share one held-out set
        ap.error(f"--heldout: expected {', '.join(map(str, sorted(counts)))} as in {args.out}/rows.json (a folder's "
                 f"rows share one count), found {args.heldout}; use another --out")
    from problems.ict import ict_available, ict_path

    if not ict_available():
        print(f"ICT data not found at {ict_path()}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for m in args.m:
        for seed in args.seeds:
            done = {(r["m"], r["seed"]) for r in load_rows(out) if r["method"] == args.methods[-1]}
            if (m, seed) in done and not args.redo:
                continue
            merge_rows(out, run_case(m, seed, tuple(args.grid), tuple(args.methods), args.candidates, args.heldout))
    with _locked(out):
        summarise(load_rows(out), out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
