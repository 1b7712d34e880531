"""Does lambda matter? Held-out error over a grid of (final alpha, final lambda) (ICT person problems).

``python -m problems.grid_alpha_lambda --m 20 --seed 1 [--heldout 200]``: for every final alpha
``a`` and final lambda ``l`` of the grid, the fixed schedule (alpha 5a -> a, lambda 10 l -> l, the
default's ratios; certified weights, no IPOPT) on the person problem, scored by the held-out error
over ``--heldout`` expressions as a ratio to deformation transfer's, and the mean absolute error of
the training weights against the truth. Writes ``reports/examples_study/grid_alpha_lambda_m<m>_seed<s>.md``
and ``.json``. A question for ``alpha="auto"``: would cross-validating lambda as well reach a target
that no alpha reaches?
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ALPHAS = (0.003, 0.01, 0.03, 0.1)
LAMBDAS = (1.0, 10.0, 100.0, 1000.0)


def main(argv=None) -> int:
    from facebasis.atomic import atomic_write_bytes
    from facebasis.geometry.transfer import deformation_transfer
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem
    from problems.ict import ict_available, ict_path

    ap = argparse.ArgumentParser(prog="python -m problems.grid_alpha_lambda")
    ap.add_argument("--m", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--heldout", type=int, default=200)
    ap.add_argument("--out", default="reports/examples_study")
    args = ap.parse_args(argv)
    for flag, value in (("--m", args.m), ("--heldout", args.heldout)):
        if value < 1:
            ap.error(f"{flag}: expected a positive count, found {value}")
    if not ict_available():
        print(f"ICT data not found at {ict_path()}", file=sys.stderr)
        return 2
    pp = ict_person_problem(seed=args.seed, n_train=args.m, n_heldout=args.heldout)
    p = pp.problem
    dt = heldout_error(deformation_transfer(p.template, p.target_neutral), pp.heldout, p.pair_indices)
    base = BlendshapeGenerator(p, GenerationOptions(ipopt="never"))
    rows, t0, c0 = [], time.perf_counter(), time.process_time()
    for a in ALPHAS:
        for lam in LAMBDAS:
            res = base.with_options(GenerationOptions(alpha=(5 * a, a), lam=(10 * lam, lam), ipopt="never")).run()
            ratio = heldout_error(res.rig, pp.heldout, p.pair_indices) / dt
            werr = float(np.abs(res.weights - pp.true_weights).mean())
            rows.append({"alpha": a, "lam": lam, "heldout_over_dt": ratio, "weight_error": werr})
            print(f"m {args.m} seed {args.seed} alpha {a:g} lambda {lam:g}: held-out / DT {ratio:.3f}, "
                  f"weight error {werr:.3f}", flush=True)
    best = min(rows, key=lambda r: r["heldout_over_dt"])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = f"grid_alpha_lambda_m{args.m}_seed{args.seed}"
    meta = {"m": args.m, "seed": args.seed, "heldout": args.heldout, "dt_heldout": dt, "rows": rows,
            "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0, "load": os.getloadavg()[0]}
    atomic_write_bytes(out / f"{name}.json", json.dumps(meta, indent=1).encode())
    lines = [f"# Held-out error / deformation transfer's over final (alpha, lambda), m = {args.m}, seed {args.seed}",
             "", f"Command: `python -m problems.grid_alpha_lambda --m {args.m} --seed {args.seed} --heldout "
             f"{args.heldout}` ({args.heldout} held-out expressions; schedules alpha 5a -> a, lambda 10 l -> l; "
             "mean |weight error| of the training weights in brackets).", "",
             "| final alpha \\ final lambda | " + " | ".join(f"{lam:g}" for lam in LAMBDAS) + " |",
             "|---|" + "---|" * len(LAMBDAS)]
    for a in ALPHAS:
        cells = [f"{r['heldout_over_dt']:.3f} ({r['weight_error']:.3f})" for r in rows if r["alpha"] == a]
        lines.append(f"| {a:g} | " + " | ".join(cells) + " |")
    lines += ["", f"Best: alpha {best['alpha']:g}, lambda {best['lam']:g}: {best['heldout_over_dt']:.3f} "
              f"(the default lambda schedule ends at 10)."]
    atomic_write_bytes(out / f"{name}.md", ("\n".join(lines) + "\n").encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
