"""Benchmark of ``--alpha auto``'s cost and choice (#26 §1) on ICT person problems.

``python -m problems.bench_cv [--m 20 80] [--seeds 0 1 2] [--candidates deletion path] [--heldout 200]
[--ipopt final|never] [--out reports/cv_speed]``

For every (m, seed): the default run (``GenerationOptions()``, what ``facebasis rig`` runs) and
``alpha="auto"`` with every ``--candidates`` procedure, each timed (wall and CPU seconds, the load
average beside them), with the chosen alpha and the held-out error of the returned rig on
``--heldout`` expressions the cross-validation never saw (refitted certified weights). Rows are
written as each run finishes to ``OUT/rows_m{m}_seed{seed}_{candidates}.json`` (one file per run,
so several processes can share the folder); ``--summary`` prints the table of all rows and
``--csv FILE`` writes them as CSV (one line per run, with its ratio to the default run of its case
and the held-out error relative to the ``--reference`` procedure's; the table of #26 is
``reports/examples_study/cv_speed.csv``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path



def run(m: int, seed: int, candidates, n_heldout: int, out: Path, default: bool = True, ipopt: str = "final") -> None:
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem

    pp = ict_person_problem(seed=seed, n_train=m, n_heldout=n_heldout)
    p = pp.problem
    runs = (["default"] if default else []) + list(candidates)
    for name in runs:
        opts = (GenerationOptions(ipopt=ipopt) if name == "default"
                else GenerationOptions(alpha="auto", cv_candidates=name, ipopt=ipopt))
        load0 = os.getloadavg()[0]
        t0, c0 = time.perf_counter(), time.process_time()
        res = BlendshapeGenerator(p, opts).run()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        err = heldout_error(res.rig, pp.heldout, p.pair_indices)
        cv = res.crossval
        row = {"m": m, "seed": seed, "run": name, "ipopt": ipopt, "wall": wall, "cpu": cpu,
               "load": [load0, os.getloadavg()[0]],
               "alpha": res.options.alpha[1], "heldout": err, "n_heldout": n_heldout,
               "alternations": len(res.history),
               "cv": None if cv is None else {"grid": cv.grid, "errors": cv.errors, "seconds": cv.seconds,
                                              "cpu_seconds": cv.cpu_seconds, "candidates": cv.candidates}}
        (out / f"rows_m{m}_seed{seed}_{name}.json").write_text(json.dumps(row, indent=1))
        print(f"m {m:3d} seed {seed} {name:8s} alpha {row['alpha']:8.4g} held-out {err:.4f} wall {wall:6.1f} s "
              f"cpu {cpu:6.1f} s load {load0:.1f}", flush=True)


def summary(out: Path) -> str:
    rows = [json.loads(f.read_text()) for f in sorted(out.glob("rows_*.json"))]
    cases = sorted({(r["m"], r["seed"]) for r in rows})
    names = sorted({r["run"] for r in rows if r["run"] != "default"})
    lines = ["| m | seed | default wall / cpu s | " + " | ".join(
        f"{n}: alpha, held-out, wall / cpu s (x default)" for n in names) + " |",
             "|---" * (3 + len(names)) + "|"]
    for m, seed in cases:
        by = {r["run"]: r for r in rows if (r["m"], r["seed"]) == (m, seed)}
        d = by.get("default")
        cells = [str(m), str(seed), f"{d['wall']:.1f} / {d['cpu']:.1f}" if d else "-"]
        for n in names:
            r = by.get(n)
            if r is None:
                cells.append("-")
                continue
            ratio = (f" ({r['wall'] / d['wall']:.1f}x / {r['cpu'] / d['cpu']:.1f}x)" if d else "")
            cells.append(f"{r['alpha']:g}, {r['heldout']:.4f}, {r['wall']:.1f} / {r['cpu']:.1f}{ratio}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(out: Path, path: Path, reference: str = "deletion") -> None:
    """Every row of ``out`` as one CSV line: case, run, alpha, held-out error (and its ratio to the
    ``reference`` run of the same case), wall / CPU seconds (and their ratio to the default run),
    alternations, candidates scored, the load average before / after."""
    import csv

    rows = [json.loads(f.read_text()) for f in sorted(out.glob("rows_*.json"))]
    by = {(r["m"], r["seed"], r["run"]): r for r in rows}
    cols = ["m", "seed", "run", "ipopt", "alpha", "heldout", "heldout_vs_" + reference, "wall_s", "cpu_s",
            "wall_x_default", "cpu_x_default", "alternations", "candidates_scored", "load_before", "load_after"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in sorted(rows, key=lambda r: (r["m"], r["seed"], r["run"] != "default", r["run"])):
            d, ref = by.get((r["m"], r["seed"], "default")), by.get((r["m"], r["seed"], reference))
            w.writerow([r["m"], r["seed"], r["run"], r["ipopt"], f"{r['alpha']:g}", f"{r['heldout']:.5f}",
                        f"{r['heldout'] / ref['heldout']:.4f}" if ref else "", f"{r['wall']:.2f}", f"{r['cpu']:.2f}",
                        f"{r['wall'] / d['wall']:.2f}" if d else "", f"{r['cpu'] / d['cpu']:.2f}" if d else "",
                        r["alternations"], len(r["cv"]["grid"]) if r.get("cv") else "",
                        f"{r['load'][0]:.2f}", f"{r['load'][1]:.2f}"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--m", type=int, nargs="+", default=[20, 80])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--candidates", nargs="+", default=["coarse", "deletion"])
    ap.add_argument("--heldout", type=int, default=200)
    ap.add_argument("--no-default", action="store_true", help="skip the default run")
    ap.add_argument("--ipopt", default="final", choices=("final", "never", "every"),
                    help="GenerationOptions.ipopt of both runs (final: what facebasis rig runs; never: the "
                         "certified weight step only, no IPOPT cross-check)")
    ap.add_argument("--out", default="reports/cv_speed")
    ap.add_argument("--summary", action="store_true", help="print the table of the rows in --out")
    ap.add_argument("--csv", default=None, metavar="FILE", help="also write the rows of --out as CSV to FILE")
    ap.add_argument("--reference", default="deletion",
                    help="the procedure the held-out errors are compared with in the CSV (default deletion)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not args.summary:
        for m in args.m:
            for seed in args.seeds:
                run(m, seed, args.candidates, args.heldout, out, default=not args.no_default, ipopt=args.ipopt)
    print(summary(out))
    if args.csv:
        write_csv(out, Path(args.csv), args.reference)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
