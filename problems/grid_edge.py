"""Grid-edge check of ``alpha="auto"`` (one-off; kept with its output grid_edge_m20_seed0.json).

    python -m problems.grid_edge 20 0 [--out reports/examples_study]

On the ICT person problem (m training expressions, seed): cross-validation over the grid extended down
to 1e-4, its choice and held-out error, and the held-out error of the fixed schedule (5a, a) for every
grid alpha. Writes ``OUT/grid_edge_m{m}_seed{seed}.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

GRID = (1e-4, 3e-4, 1e-3, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0)


def grid_edge(m: int, seed: int) -> dict:
    """Cross-validation over ``GRID`` and the fixed schedules' held-out errors on one ICT person problem."""
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem

    pp = ict_person_problem(seed=seed, n_train=m)
    p = pp.problem
    print("load", os.getloadavg(), flush=True)
    t0, c0 = time.perf_counter(), time.process_time()
    res = BlendshapeGenerator(p, GenerationOptions(ipopt="never", alpha="auto", cv_grid=GRID)).run()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    cv = res.crossval
    out = {"m": m, "seed": seed, "grid": cv.grid, "errors": cv.errors, "best": cv.best_alpha,
           "heldout": heldout_error(res.rig, pp.heldout, p.pair_indices), "wall": wall, "cpu": cpu,
           "load": os.getloadavg()}
    fixed = {}
    for a in GRID:  # the fixed schedule (5a, a) at each grid alpha
        r = BlendshapeGenerator(p, GenerationOptions(ipopt="never", alpha=(5 * a, a))).run()
        fixed[a] = heldout_error(r.rig, pp.heldout, p.pair_indices)
        print(a, fixed[a], flush=True)
    out["heldout_fixed"] = fixed
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("m", type=int, help="training expressions")
    ap.add_argument("seed", type=int, help="person seed")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "reports" / "examples_study"))
    args = ap.parse_args(argv)
    from facebasis.atomic import atomic_write_json

    out = grid_edge(args.m, args.seed)
    print(json.dumps(out, indent=1))
    atomic_write_json(Path(args.out) / f"grid_edge_m{args.m}_seed{args.seed}.json", out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
