"""Benchmarks: ``python -m problems.bench {transfer,rig,rig-scale,basis,weights,virtual,cli,all} [--repeat N] [--m M ...]``.

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


#: CPU seconds (all threads of this process) of each warm run of the last _timed call
LAST_CPU: list = []


def _timed(fn, repeat):
    t0 = time.perf_counter()
    out = fn()
    cold = time.perf_counter() - t0
    times = []
    LAST_CPU.clear()
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        LAST_CPU.append(time.process_time() - c0)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, cold, times, peak


def _machine():
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def bench_transfer(repeat: int) -> dict:
    import numpy as np

    from facebasis.geometry.transfer import DeformationTransfer
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
    import dataclasses

    import numpy as np

    from facebasis.rigging.problem import GenerationOptions
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import generate_blendshapes
    from facebasis.geometry.transfer import deformation_transfer
    from problems.generation import ict_person_problem

    pp = ict_person_problem(seed=0)
    p = pp.problem
    res, cold, times, peak = _timed(lambda: generate_blendshapes(p), max(1, repeat))
    k = p.template.n_shapes
    print(f"rig: ICT {p.template.n_vertices} vertices, {k} shapes, {len(p.examples)} training expressions, "
          f"{len(p.exclusive)} exclusive pairs, default schedule ({len(res.history)} iterations)")
    print(f"  wall (precompute + all iterations): median {statistics.median(times):.2f} s over {len(times)} warm "
          f"runs (CPU median {statistics.median(LAST_CPU):.2f} s; load average {os.getloadavg()[0]:.2f}); cold "
          f"first run {cold:.2f} s  [target <= 3.0 s]; peak traced memory {peak / 2**20:.0f} MiB")
    basis = sum(h.basis_seconds for h in res.history)
    weight = sum(h.weight_seconds for h in res.history)
    total = res.precompute_seconds + res.seconds
    print(f"  last warm run {times[-1]:.2f} s = precompute {res.precompute_seconds:.2f} + basis steps with "
          f"reconstruction {basis:.2f} ({len(res.history)} x {basis / len(res.history):.3f}) + weight steps "
          f"{weight:.2f} + other {total - res.precompute_seconds - basis - weight:.2f} (bookkeeping) + outside "
          f"the generator {times[-1] - total:.2f}")
    print(f"  IPOPT statuses {sorted(set(h.ipopt_status for h in res.history))}, iterations "
          f"{[h.ipopt_iterations for h in res.history]}")
    print(f"  max complementarity {max(h.max_complementarity for h in res.history):.1e} (IPOPT raw "
          f"{max(h.ipopt_max_complementarity for h in res.history):.1e}), max bound violation "
          f"{max(h.max_bound_violation for h in res.history):.1e} (IPOPT raw "
          f"{max(h.ipopt_max_bound_violation for h in res.history):.1e})")
    dt = deformation_transfer(p.template, p.target_neutral)
    tpl = p.template.with_neutral(p.target_neutral, p.template.deltas)
    out = {}
    print("  held-out expressions, seed 0 (weights refitted, bounds + complementarity, no prior):")
    for name, rig in (("template deltas unchanged", tpl), ("deformation transfer", dt), ("example-based", res.rig)):
        err = heldout_error(rig, pp.heldout, p.pair_indices)
        shape_err = np.linalg.norm(rig.deltas - pp.truth.deltas, axis=(1, 2)) / np.linalg.norm(pp.truth.deltas, axis=(1, 2))
        out[name] = err
        print(f"    {name:26s} relative error {err:.4f}; per-shape error vs truth: median {np.median(shape_err):.3f}, "
              f"max {shape_err.max():.3f} ({p.template.names[int(shape_err.argmax())]})")
    print(f"  training fit (relative residual): median {np.median(res.residuals):.4f}, max {res.residuals.max():.4f}; "
          f"weight error mean |x - x_true| {np.abs(res.weights - pp.true_weights).mean():.4f} "
          f"(initial {np.abs(p.initial_weights - pp.true_weights).mean():.4f})")
    print("  held-out error / deformation transfer's, three person problems  [target <= 0.5 with 20 training]:")
    print(f"    {'seed':>4s} {'DT error':>9s} {'20 train':>9s} {'20, true x fixed':>17s} {'80 train':>9s}")
    ratios = []
    for seed in (0, 1, 2):
        row = []
        # the target neutral and the held-out expressions depend on the seed only (their own random
        # streams), so deformation transfer's error is computed once per seed
        q20 = pp if seed == 0 else ict_person_problem(seed=seed)
        e_dt = heldout_error(deformation_transfer(q20.problem.template, q20.problem.target_neutral), q20.heldout,
                             q20.problem.pair_indices)
        for q, oracle in ((q20, False), (q20, True), (ict_person_problem(seed=seed, n_train=80), False)):
            prob, opts = q.problem, GenerationOptions()
            if oracle:  # the true weights, held fixed: what the basis step can learn from these examples
                prob = dataclasses.replace(prob, initial_weights=q.true_weights)
                opts = GenerationOptions(lam=(1e8, 1e8))
            rig = generate_blendshapes(prob, opts).rig
            row.append(heldout_error(rig, q.heldout, prob.pair_indices) / e_dt)
        ratios.append(row)
        print(f"    {seed:4d} {e_dt:9.4f} {row[0]:9.3f} {row[1]:17.3f} {row[2]:9.3f}")
    out["ratio_20"] = [r[0] for r in ratios]
    return out


def bench_weights(repeat: int, independent: str | None = None) -> dict:
    """The weight-problem suite: certified solver timing and the IPOPT formulation comparison."""
    import numpy as np

    from facebasis.rigging.formulations import compare_formulations, summarise_comparison
    from problems.weights_suite import weight_suite

    suite = weight_suite("ict")
    ict = [i for i in suite if i.k == 53]
    print(f"weights: suite of {len(suite)} instances ({len(ict)} with 53 ICT shapes and "
          f"{max(len(i.pairs) for i in ict)} exclusive pairs)")
    times, nodes = [], []
    for inst in ict:
        best = min((inst.certify() for _ in range(max(1, repeat))), key=lambda c: c.seconds)
        times.append(best.seconds)
        nodes.append(best.nodes)
    order = np.argsort(times)[::-1]
    print(f"  certified branch and bound per example: median {1e3 * np.median(times):.1f} ms, max "
          f"{1e3 * max(times):.1f} ms ({ict[order[0]].name}, {nodes[order[0]]} nodes), "
          f"{sum(t <= 0.05 for t in times)}/{len(times)} within 50 ms  [target <= 50 ms]; nodes median "
          f"{int(np.median(nodes))}, max {max(nodes)}")
    slow = [f"{ict[i].name} {1e3 * times[i]:.0f} ms" for i in order if times[i] > 0.05]
    if slow:
        print(f"  over 50 ms: {', '.join(slow)}")
    rows = compare_formulations(suite)
    print(f"  {'method':11s} {'reached':>9s} {'worst gap':>10s} {'min gap':>10s} {'max|xa xb|':>10s} "
          f"{'bound viol':>10s} {'median ms':>9s} {'max ms':>8s}  IPOPT statuses")
    for r in summarise_comparison(rows):
        print(f"  {r['method']:11s} {r['reached']:4d}/{r['instances']:<4d} {r['worst_relative_gap']:10.2e} "
              f"{r['most_negative_gap']:10.2e} {r['max_complementarity']:10.1e} {r['max_bound_violation']:10.1e} "
              f"{r['median_ms']:9.1f} {r['max_ms']:8.1f}  {r['statuses']}")
    from facebasis.rigging.formulations import HEURISTICS

    for method in HEURISTICS:  # the industrial heuristic: how far above the optimum, by instance kind
        for kind in dict.fromkeys(r["kind"] for r in rows):
            g = np.array([r["relative_gap"] for r in rows if r["method"] == method and r["kind"] == kind])
            above = g[g > 1e-6]
            print(f"  {method} on {kind}: {len(above)}/{len(g)} above the optimum"
                  + (f"; gap median {np.median(above):.3g}, range {above.min():.3g}-{above.max():.3g} "
                     "(relative)" if len(above) else ""))
    if independent is not None:  # an independent global MIQP solver as referee (optional, never in CI)
        from problems.independent import referee

        ref = referee(suite, independent)
        agree = sum(r["agree"] for r in ref)
        worst = max(ref, key=lambda r: abs(r["relative_difference"]))
        print(f"  independent referee {independent}: {agree}/{len(ref)} instances agree with the certified optimum "
              f"within 1e-6 relative (largest difference {worst['relative_difference']:.2e} at {worst['instance']}, "
              f"referee minus certified); median time certified {np.median([r['certified_ms'] for r in ref]):.1f} ms, "
              f"{independent} {np.median([r['referee_ms'] for r in ref]):.1f} ms; statuses "
              f"{', '.join(sorted({r['status'] for r in ref}))}")
    return {"certified_max_ms": 1e3 * max(times)}


def bench_virtual(repeat: int) -> dict:
    """Virtual edges on ICT: detection time, and new intersecting pairs over the 53 expressions
    transferred onto a target outside the identity space (identity seed 0 scaled 3x)."""
    import numpy as np

    from facebasis.contact.penetration import LOCAL_FOLD_EDGES, pair_set, penetration_report
    from facebasis.geometry.transfer import DeformationTransfer
    from facebasis.contact.virtual_edges import detect_virtual_edges
    from facebasis.geometry.mesh import median_edge_length
    from problems.ict import ict_identity, ict_random_identity, ict_rig, ict_zones

    rig = ict_rig()
    F = rig.faces
    zones = ict_zones()
    layered = zones["lips"] | zones["lids"]
    times = []
    for _ in range(max(1, repeat)):
        ve_all = detect_virtual_edges(rig.neutral, F)
        times.append(ve_all.seconds)
    ve_mask = detect_virtual_edges(rig.neutral, F, vertex_mask=layered)
    E = ve_all.edges
    print(f"virtual: detection on the ICT neutral ({rig.n_vertices} vertices), defaults (cap {ve_all.cap:.3f} cm, "
          f"ratio {ve_all.ratio:g}, {ve_all.per_vertex} per vertex): median {np.median(times):.3f} s, "
          f"min {min(times):.3f} s over {len(times)} runs  [target <= 1 s]")
    print(f"  {len(E)} edges from {ve_all.candidates} candidate pairs: {int(zones['lips'][E].all(1).sum())} in the "
          f"lips zone, {int(zones['lids'][E].all(1).sum())} in the lids zone, "
          f"{int((~layered[E]).any(1).sum())} with an end elsewhere; masked to lips + lids: {len(ve_mask)} edges")
    c, _ = ict_random_identity(0)
    B0 = ict_identity(3.0 * c)
    neutral_pairs = pair_set(B0, F)
    template_pairs = [pair_set(rig.neutral + d, F) for d in rig.deltas]
    lips_lids = {"lips": zones["lips"], "lids": zones["lids"]}

    local_within = LOCAL_FOLD_EDGES * median_edge_length(B0, F)

    def new_pairs(result):  # per expression: new pairs (all, lips, lids), then layer crossings only (same)
        out = []
        for i, d in enumerate(result.deltas):
            rep = penetration_report(B0 + d, F, zones=lips_lids, reference_pairs=(neutral_pairs, template_pairs[i]),
                                     rest=B0, local_within=local_within)
            out.append([rep.count(z, local) for local in (None, False) for z in (None, "lips", "lids")])
        return np.array(out)

    t0 = time.perf_counter()
    plain = DeformationTransfer(rig, B0).transfer()
    t_plain = time.perf_counter() - t0
    base = new_pairs(plain)
    print(f"  target: identity seed 0 scaled 3x ({len(neutral_pairs)} intersecting pairs in its neutral); new pairs = "
          "not in the target neutral nor in the template shape (same triangles)")
    print(f"  plain transfer ({t_plain:.2f} s): {base[:, 0].sum()} new pairs over {rig.n_shapes} expressions "
          f"(lips {base[:, 1].sum()}, lids {base[:, 2].sum()}, elsewhere {base[:, 0].sum() - base[:, 1].sum() - base[:, 2].sum()})")
    print(f"    of which layer crossings (triangles >= {LOCAL_FOLD_EDGES:g} median edges = {local_within:.3f} cm apart along the target "
          f"neutral): {base[:, 3].sum()} (lips {base[:, 4].sum()}, lids {base[:, 5].sum()}); local folds "
          f"{base[:, 0].sum() - base[:, 3].sum()}")
    results, counts = {}, {}
    outside = ~layered
    for label, ve, mode, w in (("gradient, w 1", ve_all, "gradient", 1.0), ("gradient, w 3", ve_all, "gradient", 3.0),
                               ("gradient, w 1, lips+lids mask", ve_mask, "gradient", 1.0),
                               ("proportional, w 1", ve_all, "proportional", 1.0)):
        t0 = time.perf_counter()
        res = DeformationTransfer(rig, B0, virtual_edges=ve, virtual_weight=w, virtual_mode=mode).transfer()
        secs = time.perf_counter() - t0
        cnt = new_pairs(res)
        diff = np.linalg.norm(res.deltas - plain.deltas, axis=2)
        motion = np.linalg.norm(plain.deltas, axis=2)
        rel_out = np.linalg.norm(diff[:, outside]) / np.linalg.norm(motion[:, outside])
        red = 1.0 - cnt[:, 0].sum() / max(1, base[:, 0].sum())
        results[label], counts[label] = red, cnt
        print(f"  {label:31s} ({secs:.2f} s): {cnt[:, 0].sum():5d} new pairs (lips {cnt[:, 1].sum()}, lids "
              f"{cnt[:, 2].sum()}), {100 * red:5.1f}% fewer than plain [target >= 90%, none at the lids]; away from lips "
              f"and lids: max difference to plain {diff[:, outside].max():.3f} cm, relative {rel_out:.3f}")
        red_x = 1.0 - cnt[:, 3].sum() / max(1, base[:, 3].sum())
        print(f"    layer crossings {cnt[:, 3].sum():5d} (lips {cnt[:, 4].sum()}, lids {cnt[:, 5].sum()}), {100 * red_x:5.1f}% "
              f"fewer than plain; local folds {cnt[:, 0].sum() - cnt[:, 3].sum()}")
    best = max(results, key=results.get)
    print("  per expression, plain -> " + best + " (largest 12 by plain count):")
    cnt = counts[best]
    order = np.argsort(-base[:, 0])[:12]
    print("    " + ", ".join(f"{rig.names[i]} {base[i, 0]}->{cnt[i, 0]}" for i in order))
    order = np.argsort(-cnt[:, 3])[:8]
    print("  layer crossings left with " + best + " (largest 8; plain -> virtual edges): "
          + ", ".join(f"{rig.names[i]} {base[i, 3]}->{cnt[i, 3]}" for i in order))
    return results


def bench_rig_scale(repeat: int, ms=(20, 40, 80, 160)) -> dict:
    """Seconds of a full generation (precompute + 10 alternations) against the number of training
    expressions, wall and CPU, with the machine's load (other processes share the cores)."""
    import numpy as np

    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from facebasis.rigging.basis import use_direct
    from problems.generation import ict_person_problem

    targets = {80: 6.0, 160: 12.0}
    print("rig-scale: ICT person problem seed 0, default options (ipopt at the final alternation), "
          f"{os.cpu_count()} cores; load average before each run in brackets")
    print(f"  {'m':>4s} {'wall s':>7s} {'CPU s':>7s} {'target':>7s} {'precompute':>10s} {'basis+rec':>9s} "
          f"{'weights':>8s} {'form':>9s}  load")
    out = {}
    for m in ms:
        pp = ict_person_problem(seed=0, n_train=m)
        walls, cpus = [], []
        for _ in range(max(1, repeat)):
            load = os.getloadavg()[0]
            t0, c0 = time.perf_counter(), time.process_time()
            gen = BlendshapeGenerator(pp.problem, GenerationOptions())
            res = gen.run()
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        k = pp.problem.template.n_shapes
        tgt = targets.get(m)
        flag = "" if tgt is None else ("  ok" if min(walls) <= tgt else "  MISSED")
        print(f"  {m:4d} {min(walls):7.2f} {cpus[int(np.argmin(walls))]:7.2f} {('<= %g' % tgt) if tgt else '':>7s} "
              f"{res.precompute_seconds:10.2f} {sum(h.basis_seconds for h in res.history):9.2f} "
              f"{sum(h.weight_seconds for h in res.history):8.2f} {'direct' if use_direct(k, m) else 'Woodbury':>9s}"
              f"  [{load:.1f}]{flag}", flush=True)
        out[m] = {"wall_s": min(walls), "cpu_s": cpus[int(np.argmin(walls))]}
    return out


def bench_basis(repeat: int, ms=(80,)) -> dict:
    """One basis step (eq. 2-4, every triangle of ICT) per number of training expressions: LAPACK
    dposv through SciPy's C pointer without the GIL (the default) against SciPy's wrapper, on one
    thread and on the machine's cores; wall and CPU seconds, best of ``repeat``."""
    from concurrent.futures import ThreadPoolExecutor
    from unittest import mock

    import numpy as np
    from threadpoolctl import threadpool_limits

    from facebasis.rigging import spdsolve
    from facebasis.rigging.basis import basis_rows, use_direct
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.workers import available_cores
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem

    cores = available_cores()
    print(f"basis: one basis step on ICT (28,068 triangles, k = 53), {cores} cores; load average in brackets; "
          f"GIL-free dposv pointer {'found' if spdsolve.kernel() is not None else 'NOT found (SciPy wrapper used)'}")
    out = {}
    for m in ms:
        pp = ict_person_problem(seed=0, n_train=m)
        gen = BlendshapeGenerator(pp.problem, GenerationOptions())
        X = np.ascontiguousarray(pp.problem.initial_weights.T)
        k = X.shape[0]
        results = {}
        for kernel in (True, False):
            for threads in (1, cores):
                pool = ThreadPoolExecutor(threads) if threads > 1 else None
                walls, cpus = [], []
                with mock.patch.object(spdsolve, "_KERNEL", [spdsolve.kernel() if kernel else None]), \
                        threadpool_limits(1):
                    for _ in range(max(1, repeat)):
                        t0, c0 = time.perf_counter(), time.process_time()
                        rows, _, _ = basis_rows(X, gen.R, gen.A_tilde, gen.w, 0.5, executor=pool)
                        walls.append(time.perf_counter() - t0)
                        cpus.append(time.process_time() - c0)
                if pool is not None:
                    pool.shutdown()
                results[(kernel, threads)] = rows
                label = f"{'dposv pointer, no GIL' if kernel else 'scipy wrapper (GIL)':22s} {threads} thread(s)"
                i = int(np.argmin(walls))
                print(f"  m {m:3d} ({'direct' if use_direct(k, m) else 'Woodbury'}) {label}: {walls[i]:.3f} s wall, "
                      f"{cpus[i]:.3f} s CPU  [{os.getloadavg()[0]:.1f}]", flush=True)
                out[(m, kernel, threads)] = walls[i]
        ref = results[(False, 1)]
        same = all(np.array_equal(r, ref) for r in results.values())
        print(f"  m {m:3d}: all four give bit-identical blendshape frames: {same}")
    return out


def bench_cli(repeat: int, facex: str | None = None) -> dict:
    from problems.bench_cli import bench_cli as run

    return run(repeat, facex)


BENCHES = {"transfer": bench_transfer, "rig": bench_rig, "rig-scale": bench_rig_scale, "basis": bench_basis,
           "weights": bench_weights,
           "virtual": bench_virtual,
           "cli": bench_cli}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m problems.bench")
    parser.add_argument("which", nargs="?", default="all", choices=sorted(BENCHES) + ["all"])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--m", type=int, nargs="+", default=[20, 40, 80, 160], metavar="M",
                        help="rig-scale, basis: the numbers of training expressions to time")
    parser.add_argument("--facex", default=None, metavar="DIR",
                        help="cli: also time ICT-FaceKit's raw FaceXModel folder (as it ships) onto identity003")
    parser.add_argument("--independent", default=None, metavar="NAME",
                        help="weights: also solve every suite instance with an independent global MIQP solver "
                             "(gurobi, if gurobipy is installed) and report agreement and time")
    args = parser.parse_args(argv)
    from problems.ict import ict_available, ict_path

    if not ict_available():
        print(f"ICT data not found at {ict_path()}", file=sys.stderr)
        return 2
    print(f"machine: {_machine()}")
    for name in (sorted(BENCHES) if args.which == "all" else [args.which]):
        if name == "cli":
            bench_cli(args.repeat, args.facex)
        elif name == "rig-scale":
            bench_rig_scale(args.repeat, tuple(args.m))
        elif name == "basis":
            bench_basis(args.repeat, tuple(args.m))
        elif name == "weights":
            bench_weights(args.repeat, args.independent)
        else:
            BENCHES[name](args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
