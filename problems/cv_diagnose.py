"""Why does ``alpha="auto"`` pick a worse alpha than the best fixed one? (ICT person problems; a study.)

``python -m problems.cv_diagnose --m 80 --seed 2 [--grid A ...] [--big 200] [--skip PART ...] [--out DIR]``;
``python -m problems.cv_diagnose --summary --out DIR`` prints the table of all cases in DIR.

For one person problem (m training expressions, seed) it measures, per candidate final alpha ``a``
(schedule ``(5 a, a)``, certified weights, no IPOPT):

* ``fixed``: the held-out error of the fresh 10-iteration run on all training expressions, on the
  benchmark's 20 held-out expressions and on ``--big`` further expressions drawn the same way from
  an independent stream (how noisy is a 20-expression held-out set?);
* ``chain_full``: the same for the warm-started continuation the cross-validation used (largest
  alpha first with the full schedule, then ``cv_chain_iterations`` alternations per candidate),
  on all training expressions;
* ``cv_chain``: the cross-validation curve as :func:`~facebasis.rigging.crossval.cross_validate_alpha`
  computes it with ``candidates="chain"``; ``cv_cold``: every candidate of every fold solved from
  the rough weights with the fresh schedule (``candidates="cold"``).

Writes ``cv_diagnose_m<m>_seed<seed>.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np


def big_heldout(pp, count: int, seed: int) -> np.ndarray:
    """``count`` further expressions (count, n, 3) drawn like the benchmark's held-out set, from
    their own stream (``seed + 5000``)."""
    from facebasis.rigging.synthetic import sparse_weights

    pairs = pp.problem.pair_indices
    X = sparse_weights(np.random.default_rng(seed + 5000), count, pp.problem.template.n_shapes,
                       [tuple(p) for p in pairs], cover=False)
    return pp.truth.evaluate(X)


def summary_table(folder) -> str:
    """Markdown table of every ``cv_diagnose_*.json`` in ``folder``: per case the choices of the
    curves present and the held-out errors (20 / big set, as ratios to deformation transfer) of the
    rig each way of returning it gives."""
    rows = []
    for path in sorted(Path(folder).glob("cv_diagnose_m*_seed*.json")):
        d = json.loads(path.read_text())
        dt = d["dt"]

        def r(v):
            return f"{v[0] / dt[0]:.3f} / {v[1] / dt[1]:.3f}"

        fixed, chain = d.get("fixed", {}), d.get("chain_full", {})
        cells = [f"{d['m']}", f"{d['seed']}", f"{dt[0]:.4f} / {dt[1]:.4f}"]
        for mode, results in (("cv_chain", chain), ("cv_cold", fixed)):
            cv = d.get(mode)
            if cv is None:
                cells.append("-")
                continue
            a = str(float(cv["best"]))
            got = results.get(a)
            cells.append(f"{float(a):g} (CV {min(cv['errors']):.4f}): " + (r(got) if got else "not run"))
        for results in (fixed, chain):
            if results:
                b20 = min(results, key=lambda k: results[k][0])
                bbig = min(results, key=lambda k: results[k][1])
                cells.append(f"{float(b20):g}: {results[b20][0] / dt[0]:.3f}; {float(bbig):g}: {results[bbig][1] / dt[1]:.3f}")
            else:
                cells.append("-")
        rows.append("| " + " | ".join(cells) + " |")
    head = ["| m | seed | DT error (20 / big) | path CV choice -> path rig, /DT (20 / big) | "
            "cold CV choice -> fresh rig, /DT (20 / big) | best fresh alpha: /DT on 20; on big | "
            "best path alpha: /DT on 20; on big |", "|---|---|---|---|---|---|---|"]
    return "\n".join(head + rows) + "\n"


def main(argv=None) -> int:
    from facebasis.atomic import atomic_write_json
    from facebasis.rigging.cvcurve import DEFAULT_GRID
    from facebasis.rigging.crossval import cross_validate_alpha
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem

    ap = argparse.ArgumentParser(prog="python -m problems.cv_diagnose")
    ap.add_argument("--m", type=int, default=80)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--grid", type=float, nargs="+", default=list(DEFAULT_GRID))
    ap.add_argument("--big", type=int, default=200)
    ap.add_argument("--skip", nargs="*", default=[], choices=["fixed", "chain_full", "cv_chain", "cv_cold"])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "reports" / "examples_study"))
    ap.add_argument("--summary", action="store_true", help="only print the table of the results in --out")
    args = ap.parse_args(argv)
    if args.summary:
        print(summary_table(args.out), end="")
        return 0
    grid = tuple(sorted(args.grid))
    pp = ict_person_problem(seed=args.seed, n_train=args.m)
    p = pp.problem
    pairs = p.pair_indices
    H = pp.heldout
    B = big_heldout(pp, args.big, args.seed)
    base = GenerationOptions(ipopt="never")
    gen = BlendshapeGenerator(p, base)
    out = {"m": args.m, "seed": args.seed, "grid": list(grid), "big": args.big, "load_start": os.getloadavg()[0]}
    path = Path(args.out) / f"cv_diagnose_m{args.m}_seed{args.seed}.json"

    def save():
        atomic_write_json(path, out)

    def errs(rig):
        return [heldout_error(rig, H, pairs), heldout_error(rig, B, pairs)]

    from facebasis.geometry.transfer import deformation_transfer
    out["dt"] = errs(deformation_transfer(p.template, p.target_neutral))
    if "fixed" not in args.skip:
        c0 = time.process_time()
        out["fixed"] = {}
        for a in grid:
            res = gen.with_options(dataclasses.replace(base, alpha=(5 * a, a))).run()
            out["fixed"][str(a)] = errs(res.rig)
            print("fixed", a, out["fixed"][str(a)], flush=True)
        out["fixed_cpu"] = time.process_time() - c0
        save()
    if "chain_full" not in args.skip:
        out["chain_full"] = {}
        X = None
        for a in grid[::-1]:
            if X is None:
                res = gen.with_options(dataclasses.replace(base, alpha=(5 * a, a))).run()
            else:
                res = gen.run(X0=X, schedule=[(a, base.lam[1])] * base.cv_chain_iterations)
            X = res.weights
            out["chain_full"][str(a)] = errs(res.rig)
            print("chain_full", a, out["chain_full"][str(a)], flush=True)
        save()
    for mode in ("chain", "cold"):
        if f"cv_{mode}" in args.skip:
            continue
        kw = {} if mode == "chain" else {"candidates": "cold"}
        try:
            cv = cross_validate_alpha(gen, grid=grid, **kw)
        except TypeError:  # a crossval without the candidates option
            continue
        out[f"cv_{mode}"] = {"errors": list(cv.errors), "fold_errors": [list(f) for f in cv.fold_errors],
                             "best": cv.best_alpha, "cpu": cv.cpu_seconds, "wall": cv.seconds}
        print(f"cv_{mode}", cv.best_alpha, [round(e, 4) for e in cv.errors], flush=True)
        save()
    out["load_end"] = os.getloadavg()[0]
    save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
