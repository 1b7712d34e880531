"""Exact contact benchmark: ``python -m problems.bench_contact [--no-crosscheck] [--exclude NAME ...]``.

ICT's 53 expressions transferred onto identity seed 0 scaled 3x (as ``bench virtual``) with
:func:`facebasis.contact.exact.contact_transfer`. New pairs = intersecting pairs not in the target
neutral nor in the template shape (same triangles), split into layer crossings and local folds
(triangles within ``LOCAL_FOLD_EDGES`` median edges along the target neutral), counted by the
package's own counter :func:`facebasis.contact.penetration.penetration_report` (the cross-check, not
timed). Change away from the lips and lids relative to the motion: as ``bench_virtual``,
``||d - d_plain|| / ||d_plain||`` over every shape and every vertex outside both zones.

Writes ``reports/contact/contact.md`` and ``reports/contact/contact.csv``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent / "reports" / "contact"


def _cpu() -> float:
    """CPU seconds of this process and its reaped children (the forked workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m problems.bench_contact")
    parser.add_argument("--no-crosscheck", action="store_true", help="skip the full counter cross-check")
    parser.add_argument("--exclude", nargs="*", default=["mouthClose"], metavar="NAME",
                        help="shapes left as plain transfer (default mouthClose: ICT's corrective pressing the lips "
                             "together on top of jawOpen; a bare --exclude transfers all with contact)")
    parser.add_argument("--workers", type=int, default=None, help="processes (default: the available cores)")
    parser.add_argument("--no-write", action="store_true", help="print only, do not write reports/contact")
    parser.add_argument("--rig", action="store_true",
                        help="instead: `rig --contact` on the ICT person case (held-out error with and without)")
    parser.add_argument("--stiffness", type=float, default=None,
                        help="with --rig: beta of the correction energy x^T (L + beta I) x (default RIG_STIFFNESS)")
    parser.add_argument("--seed", type=int, default=0, help="with --rig: the person problem's seed (default 0)")
    parser.add_argument("--truth", action="store_true",
                        help="with --rig: also correct the person's true rig (what contact costs a perfect rig)")
    parser.add_argument("--rounds", type=int, default=None,
                        help="with --rig: solve-and-check rounds of the stiff pass (default RIG_ROUNDS)")
    args = parser.parse_args(argv)
    if args.rig:
        return rig_case(args)

    from facebasis.contact.exact import contact_transfer
    from facebasis.contact.penetration import LOCAL_FOLD_EDGES, pair_set, penetration_report
    from facebasis.geometry.mesh import median_edge_length
    from problems.bench import _machine
    from problems.ict import ict_available, ict_identity, ict_path, ict_random_identity, ict_rig, ict_zones

    if not ict_available():
        print(f"ICT data not found at {ict_path()}", file=sys.stderr)
        return 2
    print(f"machine: {_machine()}")
    rig = ict_rig()
    F = rig.faces
    c, _ = ict_random_identity(0)
    B0 = ict_identity(3.0 * c)
    load0 = os.getloadavg()
    t0, c0 = time.perf_counter(), _cpu()
    res = contact_transfer(rig, B0, exclude=args.exclude, allow_target_pairs=True, workers=args.workers)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    load1 = os.getloadavg()
    print(f"contact transfer: ICT {rig.n_vertices} vertices, {len(F)} triangles, {rig.n_shapes} expressions onto "
          f"identity seed 0 scaled 3x: {wall:.2f} s wall  [target <= 30 s], {cpu:.2f} s CPU (all processes); load "
          f"average {load0[0]:.2f} before, {load1[0]:.2f} after (1 min); excluded: {', '.join(args.exclude) or 'none'}")
    print("  where the time goes: " + ", ".join(f"{k} {v:.2f} s" for k, v in res.seconds.items() if k != "workers")
          + f"; {res.seconds.get('workers', 1)} worker process(es)")
    shapes = [s for s in res.shapes if not s.excluded]
    print(f"  per shape (s): plain check + solves + exact checks, sum {sum(s.seconds for s in shapes):.2f}, "
          f"max {max(s.seconds for s in shapes):.2f} ({max(shapes, key=lambda s: s.seconds).name})")
    print(res.table())

    zones = ict_zones()
    layered = zones["lips"] | zones["lids"]
    outside = ~layered
    plain, out = res.plain.deltas, res.rig.deltas
    diff = np.linalg.norm(out - plain, axis=2)
    motion = np.linalg.norm(plain, axis=2)
    rel_out = float(np.linalg.norm(diff[:, outside]) / np.linalg.norm(motion[:, outside]))
    rel_all = float(np.linalg.norm(diff) / np.linalg.norm(motion))
    print(f"  change away from the lips and lids relative to the motion: {rel_out:.4f}  [target <= 0.05]; max "
          f"{diff[:, outside].max():.4f} cm there; everywhere {rel_all:.4f}")
    rows = []
    totals = np.zeros(6, np.int64)
    if not args.no_crosscheck:
        t = time.perf_counter()
        neutral_pairs = pair_set(B0, F)
        lips_lids = {"lips": zones["lips"], "lids": zones["lids"]}
        local_within = LOCAL_FOLD_EDGES * median_edge_length(B0, F)
        for k, s in enumerate(res.shapes):
            i = rig.names.index(s.name)
            tp = pair_set(rig.neutral + rig.deltas[i], F)
            counts = []
            for D in (plain[k], out[k]):
                rep = penetration_report(B0 + D, F, zones=lips_lids, reference_pairs=(neutral_pairs, tp), rest=B0,
                                         local_within=local_within)
                counts.append((rep.count(), rep.count(local=False), rep.count("lids")))
            rows.append((s, counts, float(np.linalg.norm(diff[k, outside]) / max(np.linalg.norm(motion[k, outside]), 1e-300))))
            if not s.excluded:  # the target is on the shapes given to the contact solve
                totals += np.array(counts[0] + counts[1])
        excl = [r for r in rows if r[0].excluded]
        print(f"  cross-check with penetration_report (full exact counter, {time.perf_counter() - t:.1f} s, not timed), "
              f"shapes solved with contact: plain {totals[0]} new pairs ({totals[1]} layer crossings, "
              f"{totals[0] - totals[1]} local folds, lids {totals[2]}) -> contact {totals[3]} new pairs ({totals[4]} layer "
              f"crossings, {totals[3] - totals[4]} local folds, lids {totals[5]})  [target 0, 0 at the lids]"
              + ("; excluded, left as plain transfer: " + ", ".join(f"{r[0].name} {r[1][1][0]} new pairs (lids "
                                                                   f"{r[1][1][2]})" for r in excl) if excl else ""))
        agree = all(r[1][1][0] == r[0].new_pairs_left for r in rows if not r[0].excluded)
        print(f"  solver's own count agrees with penetration_report on every shape: {agree}")
    if args.no_write or args.no_crosscheck:
        return 0
    REPORTS.mkdir(parents=True, exist_ok=True)
    header = ["expression", "excluded", "plain_new_pairs", "plain_layer_crossings", "plain_lids", "contact_new_pairs",
              "contact_layer_crossings", "contact_lids", "constrained_pairs", "rows", "iterations", "qp_iterations",
              "moved_vertices", "min_distance_cm", "relative_change_outside_lips_lids", "seconds"]
    table = []
    for s, counts, rel in rows:
        table.append([s.name, int(s.excluded), *counts[0], *counts[1], s.constrained_pairs, s.rows, s.iterations,
                      s.solver_iterations, s.moved, "" if np.isnan(s.min_distance) else f"{s.min_distance:.5f}",
                      f"{rel:.4f}", f"{s.seconds:.3f}"])
    with open(REPORTS / "contact.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(table)
    md = [f"Command: `python -m problems.bench_contact{' --exclude ' + ' '.join(args.exclude) if args.exclude != ['mouthClose'] else ''}` "
          f"(excluded: {', '.join(args.exclude) or 'none'}).",
          "",
          f"Contact transfer of {len(rows)} ICT expressions onto identity seed 0 scaled 3x: {wall:.2f} s wall, "
          f"{cpu:.2f} s CPU over all processes ({res.seconds.get('workers', 1)} worker processes), load average {load0[0]:.2f} before, "
          f"{load1[0]:.2f} after; new pairs of the shapes solved with contact {totals[0]} plain -> {totals[3]} with "
          "contact (penetration_report; excluded shapes are plain transfer, their rows below); "
          f"change away from lips and lids relative to the motion {rel_out:.4f}.",
          "",
          "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    md += ["| " + " | ".join(str(v) for v in r) + " |" for r in table]
    md.append("| total, shapes solved with contact | | " + " | ".join(str(v) for v in totals.tolist()) + " | | | | | | | "
              f"{rel_out:.4f} | {wall:.2f} |")
    (REPORTS / "contact.md").write_text("\n".join(md) + "\n")
    print(f"  wrote {REPORTS / 'contact.md'} and contact.csv")
    return 0


def _passes(contact) -> str:
    """Which pass ended each corrected shape: the stiff energy, its transfer-energy fallback, or the
    last resort pulling vertices back towards the neutral (ContactSolver.correct)."""
    shapes = [s for s in contact.shapes if not s.excluded and s.plain_new_pairs]
    fb = [s.name for s in shapes if s.fallback]
    rt = [f"{s.name} ({s.retreated} vertices)" for s in shapes if s.retreated]
    stiff = sum(1 for s in shapes if not s.fallback and not s.retreated)
    return (f"{len(shapes)} shapes corrected: {stiff} by the stiff energy"
            + (f", {len(fb)} by the transfer-energy fallback ({', '.join(fb)})" if fb else "")
            + (f"; ended by the last resort (pulled back towards the neutral): {', '.join(rt)}" if rt
               else "; no last resort needed"))


def rig_case(args) -> int:
    """Example-based generation on ``ict_person_problem(seed)`` (as ``bench generation``), then exact
    contact on the generated rig (as ``facebasis rig --contact``): new pairs before/after by the
    package's counter, and the held-out reproduction error with and without contact. With ``--truth``
    the person's true rig (which the held-out expressions come from, error 0) is corrected as well:
    the error contact costs even a perfect rig. Writes ``reports/contact/rig_contact.md`` unless
    ``--no-write``."""
    from facebasis.contact.exact import RIG_STIFFNESS, contact_correct
    from facebasis.contact.penetration import penetration_report
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import BlendshapeGenerator
    from problems.bench import _machine
    from problems.generation import ict_person_problem

    print(f"machine: {_machine()}")
    beta = RIG_STIFFNESS if args.stiffness is None else args.stiffness
    pp = ict_person_problem(seed=args.seed)
    p = pp.problem
    t = time.perf_counter()
    gen = BlendshapeGenerator(p)
    res = gen.run()
    print(f"generation: {time.perf_counter() - t:.2f} s")
    load0 = os.getloadavg()
    t, c0 = time.perf_counter(), _cpu()
    # ICT's identities intersect themselves a little where the template neutral does not (74 pairs for
    # seed 0): allowed, as `rig --contact --contact-allow-target-pairs` does
    rounds = {} if args.rounds is None else {"max_iterations": args.rounds}
    contact = contact_correct(res.rig, p.template, transfer=gen.dt, exclude=args.exclude, workers=args.workers,
                              stiffness=beta, allow_target_pairs=True, **rounds)
    wall, cpu = time.perf_counter() - t, _cpu() - c0
    load1 = os.getloadavg()
    lines = [f"contact on the generated rig (stiffness {beta:g}): {wall:.2f} s wall, {cpu:.2f} s CPU (all processes); "
             f"load average {load0[0]:.2f} -> {load1[0]:.2f}; excluded: {', '.join(args.exclude) or 'none'}; "
             f"solver's exact check: {'no new pair left' if contact.ok else 'NEW PAIRS LEFT'}"]
    F, B0 = p.template.faces, p.target_neutral
    before = after = truth_pairs = 0
    for k, name in enumerate(res.rig.names):
        i = p.template.names.index(name)
        refs = (B0, p.template.neutral + p.template.deltas[i])
        nb = len(penetration_report(B0 + res.rig.deltas[k], F, references=refs).new)
        na = len(penetration_report(B0 + contact.rig.deltas[k], F, references=refs).new)
        truth_pairs += len(penetration_report(B0 + pp.truth.deltas[pp.truth.names.index(name)], F, references=refs).new)
        before += nb
        after += na if name not in args.exclude else 0
    lines.append(f"new pairs by penetration_report: generated {before}, with contact {after} (not excluded shapes); "
                 f"the true rig has {truth_pairs}")
    lines.append(_passes(contact))
    e0 = heldout_error(res.rig, pp.heldout, p.pair_indices)
    e1 = heldout_error(contact.rig, pp.heldout, p.pair_indices)
    lines.append(f"held-out relative error: without contact {e0:.4f}, with contact {e1:.4f} ({100 * (e1 / e0 - 1):+.2f} %)  "
                 "[target: not worse by more than 5 %]")
    moved = np.linalg.norm((contact.rig.deltas - res.rig.deltas).reshape(len(res.rig.names), -1), axis=1)
    top = np.argsort(-moved)[:5]
    lines.append("largest corrections (norm over vertices, cm): "
                 + ", ".join(f"{res.rig.names[k]} {moved[k]:.2f}" for k in top))
    if args.truth:
        tc = contact_correct(pp.truth, p.template, transfer=gen.dt, exclude=args.exclude, workers=args.workers,
                             stiffness=beta, allow_target_pairs=True, **rounds)
        et = heldout_error(tc.rig, pp.heldout, p.pair_indices)
        lines.append("the true rig: " + _passes(tc) + f"; exact check: {'no new pair left' if tc.ok else 'NEW PAIRS LEFT'}")
        lines.append(f"the true rig with contact: held-out error 0 -> {et:.4f} (what intersection-free shapes cost "
                     f"even a perfect rig; in quadrature with {e0:.4f}: {np.hypot(e0, et):.4f})")
    for line in lines:
        print("  " + line)
    print(contact.table())
    if not args.no_write:
        REPORTS.mkdir(parents=True, exist_ok=True)
        cmd = ("python -m problems.bench_contact --rig" + (f" --stiffness {args.stiffness:g}" if args.stiffness is not None else "")
               + (f" --rounds {args.rounds}" if args.rounds is not None else "")
               + (f" --seed {args.seed}" if args.seed else "") + (" --truth" if args.truth else ""))
        text = [f"Command: `{cmd}` (ICT person case, seed {args.seed}).", ""] + [f"- {line}" for line in lines]
        text += ["", "Per generated shape (the solver's report: rounds of solve + exact check, ADMM iterations, "
                 "smallest distance kept between constrained triangles in cm):", "", "```", contact.table(), "```", ""]
        out = REPORTS / f"rig_contact{'_seed%d' % args.seed if args.seed else ''}.md"
        out.write_text("\n".join(text))
        print(f"  wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
