"""Benchmarks: ``python -m problems.bench {transfer,rig,all} [--repeat N]``.

Prints wall times (file I/O excluded; median of ``--repeat`` warm runs and the first, cold run)
and peak traced memory (numpy allocations, via tracemalloc, in a separate run so tracing does not
distort the timings). Uses ``../shared/data/ict/ict_face.npz``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import tracemalloc


def _timed(fn, repeat):
    t0 = time.perf_counter()
    out = fn()
    cold = time.perf_counter() - t0
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, cold, times, peak


def _machine():
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def bench_transfer(repeat: int) -> dict:
    import numpy as np

    from facebasis.transfer import DeformationTransfer
    from problems.ict import ict_random_identity, ict_rig

    rig = ict_rig()
    _, target = ict_random_identity(seed=0)

    def run():
        return DeformationTransfer(rig, target).transfer()

    out, cold, times, peak = _timed(run, repeat)
    print(f"transfer: ICT {rig.n_vertices} vertices, {len(rig.faces)} triangles, {rig.n_shapes} expressions "
          f"onto identity seed 0")
    print(f"  wall (setup + factorisation + all shapes): median {statistics.median(times):.3f} s, "
          f"min {min(times):.3f} s over {repeat} warm runs; cold first run {cold:.3f} s  [target <= 1.0 s]")
    print(f"  peak traced memory {peak / 2**20:.1f} MiB")
    rel = np.linalg.norm(out.deltas - rig.deltas) / np.linalg.norm(rig.deltas)
    print(f"  relative difference to ICT's additive expressions: {rel:.4f}")
    return {"median_s": statistics.median(times), "cold_s": cold, "peak_mib": peak / 2**20}


def bench_rig(repeat: int) -> dict:
    import numpy as np

    from facebasis.generation import generate_blendshapes, reproduction_error
    from facebasis.transfer import deformation_transfer
    from facebasis.weights import WeightSolver
    from problems.generation import ict_person_problem

    pp = ict_person_problem(seed=0)
    p = pp.problem
    res, cold, times, peak = _timed(lambda: generate_blendshapes(p), max(1, repeat // 2))
    k = p.template.n_shapes
    print(f"rig: ICT {p.template.n_vertices} vertices, {k} shapes, {len(p.examples)} training expressions, "
          f"{len(p.exclusive)} exclusive pairs, default schedule ({len(res.history)} iterations)")
    print(f"  wall (precompute + all iterations): median {statistics.median(times):.2f} s over {len(times)} warm "
          f"runs; cold first run {cold:.2f} s  [target <= 3.0 s]; peak traced memory {peak / 2**20:.0f} MiB")
    print(f"  precompute {res.precompute_seconds:.2f} s; per iteration: basis step + reconstruction "
          f"{np.mean([h.basis_seconds for h in res.history]):.3f} s, weight step (IPOPT + polish) "
          f"{np.mean([h.weight_seconds for h in res.history]):.3f} s")
    print(f"  IPOPT statuses {sorted(set(h.ipopt_status for h in res.history))}, iterations "
          f"{[h.ipopt_iterations for h in res.history]}")
    print(f"  max complementarity {max(h.max_complementarity for h in res.history):.1e} (IPOPT raw "
          f"{max(h.ipopt_max_complementarity for h in res.history):.1e}), max bound violation "
          f"{max(h.max_bound_violation for h in res.history):.1e} (IPOPT raw "
          f"{max(h.ipopt_max_bound_violation for h in res.history):.1e})")
    dt = deformation_transfer(p.template, p.target_neutral)
    tpl = p.template.with_neutral(p.target_neutral, p.template.deltas)
    solver = WeightSolver(k, len(pp.heldout), p.pair_indices)
    out = {}
    print("  held-out expressions (weights refitted, bounds + complementarity, no prior):")
    for name, rig in (("template deltas unchanged", tpl), ("deformation transfer", dt), ("example-based", res.rig)):
        err = reproduction_error(rig, pp.heldout, p.pair_indices, solver=solver)
        shape_err = np.linalg.norm(rig.deltas - pp.truth.deltas, axis=(1, 2)) / np.linalg.norm(pp.truth.deltas, axis=(1, 2))
        out[name] = err
        print(f"    {name:26s} relative error {err:.4f}; per-shape error vs truth: median {np.median(shape_err):.3f}, "
              f"max {shape_err.max():.3f} ({p.template.names[int(shape_err.argmax())]})")
    print(f"  ratio example-based / deformation transfer on held-out: {out['example-based'] / out['deformation transfer']:.3f}"
          "  [target <= 0.5]")
    print(f"  training fit (relative residual): median {np.median(res.residuals):.4f}, max {res.residuals.max():.4f}; "
          f"weight error mean |x - x_true| {np.abs(res.weights - pp.true_weights).mean():.4f} "
          f"(initial {np.abs(p.initial_weights - pp.true_weights).mean():.4f})")
    return out


BENCHES = {"transfer": bench_transfer, "rig": bench_rig}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m problems.bench")
    parser.add_argument("which", nargs="?", default="all", choices=sorted(BENCHES) + ["all"])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    from problems.ict import ict_available, ict_path

    if not ict_available():
        print(f"ICT data not found at {ict_path()}", file=sys.stderr)
        return 2
    print(f"machine: {_machine()}")
    for name in (sorted(BENCHES) if args.which == "all" else [args.which]):
        BENCHES[name](args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
