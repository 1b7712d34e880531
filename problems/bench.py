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


BENCHES = {"transfer": bench_transfer}


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
