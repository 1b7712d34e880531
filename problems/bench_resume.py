"""Resume (§5) against a run from scratch: ``facebasis rig --resume`` on the ICT person problem.

``python -m problems.bench_resume [--seed 0] [--first 20] [--more 20] [--keep DIR] [--json OUT.json]``

On ``ict_person_problem(seed, first + more)`` (training expressions 0..first-1 are the first batch,
first..first+more-1 the new ones), as separate CLI processes on files in a temporary folder
(outside the repository; ``--keep DIR`` keeps them there):

1. ``facebasis rig`` from the first batch (``run_first``);
2. ``facebasis rig --resume run_first --examples MORE --weights MORE.json`` (``resumed``);
3. ``facebasis rig`` from scratch on all first + more expressions (``scratch``).

Wall and CPU time (user + system of the child process) of each, with the load average, and the
difference of the resumed to the scratch result: relative difference of the blendshape deltas
(``||D_resumed - D_scratch|| / ||D_scratch||``, overall and the worst shape), the weight
difference (max and mean |x_resumed - x_scratch| over all training expressions and shapes), and
the held-out error (20 held-out expressions, weights refitted: certified, bounds + complementarity,
no prior) and the error to the person's true rig of both. All runs use the CLI's default options
(paper schedule, ``--ipopt`` default) and ICT's exclusive pairs.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _run(cmd) -> tuple[float, float, str]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return wall, cpu, proc.stdout


def bench_resume(root: Path, seed: int = 0, first: int = 20, more: int = 20) -> dict:
    import numpy as np

    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import Rig, load_rig_folder, write_rig_folder
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.examples import load_weights
    from facebasis.rigging.runs import write_problem_inputs
    from problems.generation import ICT_EXCLUSIVE, ict_person_problem

    pp = ict_person_problem(seed=seed, n_train=first + more)
    p = pp.problem
    names = list(p.example_names)

    def part(idx):
        return dataclasses.replace(p, examples=p.examples[idx], initial_weights=p.initial_weights[idx],
                                   example_names=tuple(names[i] for i in idx))

    write_rig_folder(root / "template", p.template)
    write_mesh(root / "target.obj", p.target_neutral, p.template.faces)
    ex_a, w_a = write_problem_inputs(root / "first", part(list(range(first))))
    ex_b, w_b = write_problem_inputs(root / "more", part(list(range(first, first + more))))
    ex_all, w_all = write_problem_inputs(root / "all", p)

    exe = [sys.executable, "-m", "facebasis.cli", "rig"]
    pairs = ["--exclusive"] + [f"{a}:{b}" for a, b in ICT_EXCLUSIVE]
    common = ["--template", root / "template", "--target", root / "target.obj"]
    out = {"seed": seed, "first": first, "more": more, "load_average_before": os.getloadavg(), "runs": {}}
    print(f"resume: ICT seed {seed}, {first} + {more} training expressions; load average "
          f"{os.getloadavg()[0]:.2f} (1 min) on {os.cpu_count()} cores before the runs", flush=True)
    cmds = {
        "run_first": exe + common + ["--examples", ex_a, "--weights", w_a] + pairs + ["--out", root / "run_first"],
        "resumed": exe + ["--resume", root / "run_first", "--examples", ex_b, "--weights", w_b,
                          "--out", root / "resumed"],
        "scratch": exe + common + ["--examples", ex_all, "--weights", w_all] + pairs + ["--out", root / "scratch"],
    }
    for key, cmd in cmds.items():
        wall, cpu, stdout = _run(cmd)
        load = os.getloadavg()[0]
        out["runs"][key] = {"command": " ".join(map(str, cmd)), "wall_s": wall, "cpu_s": cpu, "load_average_after": load}
        print(f"  {key:10s} wall {wall:6.1f} s, CPU {cpu:6.1f} s (load average {load:.2f} after)", flush=True)
    out["resume_plus_first_wall_s"] = out["runs"]["run_first"]["wall_s"] + out["runs"]["resumed"]["wall_s"]
    out["resume_plus_first_cpu_s"] = out["runs"]["run_first"]["cpu_s"] + out["runs"]["resumed"]["cpu_s"]

    shape_names = list(p.template.names)
    rigs = {k: load_rig_folder(root / k, "neutral.obj") for k in cmds}
    rigs = {k: Rig(r.neutral, r.faces, tuple(shape_names), r.deltas[r.index(shape_names)], f"{k} run")
            for k, r in rigs.items()}
    res, scr = rigs["resumed"], rigs["scratch"]
    dd = res.deltas - scr.deltas
    per_shape = np.linalg.norm(dd, axis=(1, 2)) / np.maximum(np.linalg.norm(scr.deltas, axis=(1, 2)), 1e-30)
    W = {k: load_weights(root / k / "weights.json", names, shape_names) for k in ("resumed", "scratch")}
    dw = np.abs(W["resumed"] - W["scratch"])
    truth = pp.truth.deltas
    out["difference"] = {
        "deltas_relative": float(np.linalg.norm(dd) / np.linalg.norm(scr.deltas)),
        "deltas_relative_worst_shape": float(per_shape.max()),
        "worst_shape": shape_names[int(per_shape.argmax())],
        "weights_max_abs": float(dw.max()), "weights_mean_abs": float(dw.mean()),
        "weights_max_abs_new_examples": float(dw[first:].max()),
        "weights_max_abs_first_examples": float(dw[:first].max()),
    }
    out["heldout"] = {k: heldout_error(r, pp.heldout, p.pair_indices) for k, r in rigs.items()}
    out["truth_relative_error"] = {k: float(np.linalg.norm(r.deltas - truth) / np.linalg.norm(truth))
                                   for k, r in rigs.items()}
    d = out["difference"]
    print(f"  resumed vs scratch: deltas differ by {d['deltas_relative']:.2e} relative (worst shape "
          f"{d['worst_shape']} {d['deltas_relative_worst_shape']:.2e}); weights max |diff| "
          f"{d['weights_max_abs']:.2e} (first batch {d['weights_max_abs_first_examples']:.2e}, new "
          f"{d['weights_max_abs_new_examples']:.2e}), mean {d['weights_mean_abs']:.2e}")
    for k in cmds:
        print(f"  held-out error {k:10s} {out['heldout'][k]:.4f}   error to the true rig "
              f"{out['truth_relative_error'][k]:.4f}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m problems.bench_resume", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--first", type=int, default=20, help="training expressions of the first run (default 20)")
    ap.add_argument("--more", type=int, default=20, help="training expressions added by --resume (default 20)")
    ap.add_argument("--keep", default=None, help="keep the files in this folder (outside the repository)")
    ap.add_argument("--json", default=None, help="write the numbers to this JSON file")
    args = ap.parse_args(argv)
    from problems.ict import ict_available, ict_path

    if not ict_available():
        print(f"ICT data not found at {ict_path()}", file=sys.stderr)
        return 2
    if args.keep:
        root = Path(args.keep).absolute()
        if root == REPO or REPO in root.parents:
            print(f"--keep {root}: expected a folder outside the repository (ICT data is never stored in it)",
                  file=sys.stderr)
            return 2
        root.mkdir(parents=True, exist_ok=True)
        out = bench_resume(root, args.seed, args.first, args.more)
    else:
        with tempfile.TemporaryDirectory(prefix="facebasis-bench-resume-") as tmp:
            out = bench_resume(Path(tmp), args.seed, args.first, args.more)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
