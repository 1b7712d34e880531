"""Benchmark: mouth expressions registered through the rig, with and without the scan-to-model pairs.

    python -m problems.bench_mouth_basin --seeds 3 [--persons detail in-space] [--scan-pairs 0 5000]
        [--schedules joint after] [--out reports/registration/mouth_basin]
    python -m problems.bench_mouth_basin --table --out reports/registration/mouth_basin

Issue #27's expression fit (``geometry/shapemodel.py``: the registered neutral plus the template's expressions
transferred to it, bounded weights, then the regional stage) once landed with the lips closed over an opened
mouth's hole (seed 3 detail jawOpen, ``mouthClose`` 0.97, ``jawOpen`` 0.90: p95 1.98 cm). This bench builds
the persons of :mod:`problems.bench_registration_rig` (seeded ICT identity from all 100 modes, personalised
expressions; ``detail``: plus a smooth normal field up to 2.5 mm), registers the neutral scan once (the
library's defaults: the same neutral for every method) and then the mouth scans below with each
``--scan-pairs`` value (``ModelFitOptions.scan_pairs`` of the whole-expression fit, eq. S1 of
``geometry/scanpairs.py``; 0: the model-to-scan pairs alone, the previous fit) and, for values above 0, each
``--schedules`` value (``RegistrationOptions.expression_pairs_schedule``, geometry/pairschedule.py: ``joint``, the
pairs from the first round; ``after``, the one-sided fit first, then continued with the pairs, the fit with the
smaller eq. S2 kept: the row also gives both fits' eq. S2, which one was kept and each one's face p95 before the
regional stage, so that the choice can be checked against the truth). Scans
(:func:`problems.bench_registration.make_scan`: another topology, ~100k vertices, shuffled, 0.2 mm noise,
holes at the ears, mouth and eyes, a random rigid motion; no landmarks): the rig bench's own neutral,
jawOpen, mouthSmile_L and mouthPucker scans (its generator, drawn in its order), then from the same generator
mouthFunnel, mouthClose and jawOpen + mouthClose (the lips closed: they must stay closed) and jawOpen at 0.5,
and from a second generator jawOpen at 0.3 and 0.7 (an opened mouth: a hole between the lips), all of the
person's own (personalised) rig.

Writes ``seed<S>.csv`` per run, keeping the rows of other methods already in it (a method run again replaces
its rows; one row per person, scan and method: error median / p95 / max on the face,
cm, in the scan's frame; CPU and wall seconds; the load; the whole fit's jawOpen, mouthClose and
mouthShrugLower weights) and with ``--table`` ``mouth_basin.md`` from every ``seed*.csv`` in ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import time
from pathlib import Path

import numpy as np

from problems.bench_registration import _ears, _ict_setup, make_scan
from problems.csvrows import csv_bytes

#: the rig bench's own single-shape scans (its generator continued after its neutral and its 12 training scans),
#: then more from the same generator, then from a second one (seeded 7000 + seed)
SCANS = (("jawOpen", {"jawOpen": 1.0}), ("mouthSmile_L", {"mouthSmile_L": 1.0}), ("mouthPucker", {"mouthPucker": 1.0}),
         ("mouthFunnel", {"mouthFunnel": 1.0}), ("mouthClose", {"mouthClose": 1.0}),
         ("jawOpen + mouthClose", {"jawOpen": 1.0, "mouthClose": 1.0}), ("jawOpen 0.5", {"jawOpen": 0.5}))
SECOND = (("jawOpen 0.3", {"jawOpen": 0.3}), ("jawOpen 0.7", {"jawOpen": 0.7}))
WEIGHTS = ("jawOpen", "mouthClose", "mouthShrugLower")  #: the whole fit's weights reported per scan
TARGETS = {"median": 0.05, "p95": 0.2, "cpu": 10.0}
CANDIDATES = ("one_sided", "continued")  #: the two fits of the ``after`` schedule, in its order


def methods(scan_pairs, schedules) -> list[tuple[int, str]]:
    """``(scan_pairs, schedule)`` pairs to run: 0 once (``one-sided``), every other value with each schedule."""
    return [(sp, sch) for sp in scan_pairs for sch in (("one-sided",) if sp == 0 else schedules)]


def _capture():
    """Wrap the expression stage's :func:`~facebasis.geometry.pairschedule.whole_expression_fit` to record its
    ``info`` (eq. S2 of both fits, which one was kept, the fits): a list, cleared by the caller per scan."""
    import facebasis.geometry.expressionregions as er
    from facebasis.geometry.pairschedule import whole_expression_fit

    seen = []

    def spy(*a, **k):
        out = whole_expression_fit(*a, **k)
        seen.append(out[1])
        return out

    er.whole_expression_fit = spy
    return seen


def run_person(seed: int, kind: str, scan_pairs, schedules=("joint", "after"), log=print) -> list[dict]:
    """Register one person's neutral, then its mouth scans with each ``(scan_pairs, schedule)`` method; rows."""
    from facebasis.geometry.registration import Registration, RegistrationOptions
    from facebasis.geometry.shapemodel import ShapeBasis
    from problems.bench_registration_rig import person

    d, F, T, face, keep, head = _ict_setup()
    names = [str(s) for s in d["expression_names"]]
    ident = ShapeBasis(tuple(str(s) for s in d["identity_names"][:100]), d["identity_deltas"][:100].astype(np.float64),
                       "ICT identity modes")
    expr = ShapeBasis(tuple(names), d["expression_deltas"].astype(np.float64), "ICT expressions")
    pp = person(seed, 12, kind == "detail")
    B0, truth = pp.problem.target_neutral, pp.truth
    rng = np.random.default_rng(2000 + seed)  # the rig bench's generator and its draws, in its order
    ears = _ears(B0, head)
    scans = [("neutral", B0, *make_scan(B0, F, keep, ears, rng))]
    for V in pp.problem.examples:  # the rig bench's training scans: drawn (the generator's state), not used
        make_scan(V, F, keep, ears, rng)
    for table, gen in ((SCANS, rng), (SECOND, np.random.default_rng(7000 + seed))):
        for nm, w in table:
            v = np.zeros(len(names))
            for k, x in w.items():
                v[names.index(k)] = x
            Vt = truth.evaluate(v[None])[0]
            scans.append((nm, Vt, *make_scan(Vt, F, keep, ears, gen)))
    base = RegistrationOptions()
    _, _, S, G, R, t = scans[0]
    neutral = Registration(T, F, base, name="ICT neutral", identity=ident, expressions=expr).register(S, G).vertices
    rows, seen = [], _capture()
    for sp, sch in methods(scan_pairs, schedules):
        opts = dataclasses.replace(base, expression_fit=dataclasses.replace(base.expression_fit, scan_pairs=sp),
                                   expression_pairs_schedule="joint" if sch == "one-sided" else sch)
        reg = Registration(T, F, opts, name="ICT neutral", identity=ident, expressions=expr)
        E = reg.person_expressions(neutral)
        for nm, Vt, S, G, R, t in scans[1:]:
            seen.clear()
            t0, c0 = time.perf_counter(), time.process_time()
            res = reg.register(S, G, start=neutral, expressions=E, name=nm)
            sec, cpu = time.perf_counter() - t0, time.process_time() - c0
            truth = (Vt @ R.T + t)[face]
            e = np.linalg.norm(res.vertices[face] - truth, axis=1)
            w = res.model.coefficients
            info = seen[0]
            whole = [float(np.percentile(np.linalg.norm(res.similarity.apply(f.vertices)[face] - truth, axis=1), 95))
                     for f in info.get("fits", ())]  # each candidate's face p95 before the regional stage
            row = {"seed": seed, "person": kind, "scan": nm, "scan_pairs": sp, "schedule": sch,
                   "err_median": float(np.median(e)), "err_p95": float(np.percentile(e, 95)), "err_max": float(e.max()),
                   "seconds": sec, "cpu_seconds": cpu, "load": os.getloadavg()[0],
                   **{f"w_{k}": float(w[names.index(k)]) for k in WEIGHTS},
                   "kept": info.get("kept", ""), **{f"s2_{c}": (info["s2"][i] if "s2" in info else "")
                                                    for i, c in enumerate(CANDIDATES)},
                   **{f"whole_p95_{c}": (whole[i] if whole else "") for i, c in enumerate(CANDIDATES)}}
            rows.append(row)
            log(f"seed {seed} {kind:8s} scan_pairs {sp:5d} {sch:9s} {nm:21s} median {row['err_median']:.4f} p95 "
                f"{row['err_p95']:.4f} max {row['err_max']:.3f} | jawOpen {row['w_jawOpen']:.2f} mouthClose "
                f"{row['w_mouthClose']:.2f} mouthShrugLower {row['w_mouthShrugLower']:.2f} | {row['kept']} "
                f"{' '.join(str(row['s2_' + c])[:6] for c in CANDIDATES)} | {cpu:.1f} s CPU "
                f"{sec:.1f} s wall load {row['load']:.1f}")
    return rows


def write_table(out: Path) -> Path:
    """``mouth_basin.md`` from every ``seed*.csv`` under ``out``: per scan pairs value, every scan's
    figures and a line of totals (scans over the targets, worst p95, CPU)."""
    from facebasis.atomic import atomic_write_bytes

    rows = [r for p in sorted(out.glob("seed*.csv")) for r in _rows(p)]
    mkey = lambda r: (int(r["scan_pairs"]), r["schedule"])  # noqa: E731
    methods = sorted({mkey(r) for r in rows}, key=lambda m: (m[0], m[1] != "joint"))
    label = lambda m: str(m[0]) if m[0] == 0 else f"{m[0]} {m[1]}"  # noqa: E731
    lines = ["# Mouth scans through the rig, with and without the scan-to-model pairs (cm, face vertices)", "",
             "Written by `python -m problems.bench_mouth_basin --table` from `seed*.csv` (commands: "
             "`python -m problems.reproduce registration-mouth-basin --dry-run`). `scan_pairs 0`: the model-to-scan "
             "pairs alone (the previous expression fit); otherwise that many scan vertices also pair with their "
             "nearest model vertex (eq. S1 of geometry/scanpairs.py), from the first round (`joint`) or `after` a "
             "one-sided fit, continued from it, the one with the smaller eq. S2 kept (geometry/pairschedule.py). "
             "Targets: median <= 0.05, p95 <= 0.2 cm, <= 10 s CPU per scan.", ""]
    for m in methods:
        sel = [r for r in rows if mkey(r) == m]
        bad = [r for r in sel if float(r["err_median"]) > TARGETS["median"] or float(r["err_p95"]) > TARGETS["p95"]]
        cpu = np.array([float(r["cpu_seconds"]) for r in sel])
        worst = max(sel, key=lambda r: float(r["err_p95"]))
        lines.append(f"**scan_pairs {label(m)}**: {len(sel)} scans, {len(bad)} over the targets; worst p95 "
                     f"{float(worst['err_p95']):.3f} (seed {worst['seed']} {worst['person']} {worst['scan']}); CPU "
                     f"median {np.median(cpu):.1f} s, max {cpu.max():.1f} s; load {min(float(r['load']) for r in sel):.1f}-"
                     f"{max(float(r['load']) for r in sel):.1f}.")
        lines += _choice_lines(sel)
    lines += ["", "| seed | person | scan | " + " | ".join(f"p95 / median, pairs {label(m)} | weights jawOpen, mouthClose, "
                                                          f"mouthShrugLower ({label(m)}) | CPU s ({label(m)})"
                                                          for m in methods)
              + " |", "|" + "---|" * (3 + 3 * len(methods))]
    key = lambda r: (int(r["seed"]), r["person"], r["scan"])  # noqa: E731
    for k in dict.fromkeys(key(r) for r in rows):
        cells = []
        for m in methods:
            r = next((r for r in rows if key(r) == k and mkey(r) == m), None)
            cells += ["", "", ""] if r is None else [
                f"{float(r['err_p95']):.3f} / {float(r['err_median']):.3f}",
                ", ".join(f"{float(r['w_' + w]):.2f}" for w in WEIGHTS), f"{float(r['cpu_seconds']):.1f}"]
        lines.append(f"| {k[0]} | {k[1]} | {k[2]} | " + " | ".join(cells) + " |")
    atomic_write_bytes(out / "mouth_basin.md", ("\n".join(lines) + "\n").encode())
    return out / "mouth_basin.md"


def _choice_lines(sel: list) -> list[str]:
    """For the ``after`` schedule's rows: how often eq. S2 kept the fit with the smaller face p95 before the
    regional stage (the truth; a difference under 0.01 cm counts as a tie), and the rows where it did not."""
    sel = [r for r in sel if r.get("kept")]
    if not sel:
        return []
    p95 = lambda r, c: float(r["whole_p95_" + c])  # noqa: E731
    other = {"one-sided": "continued", "continued": "one-sided"}
    wrong = [r for r in sel if p95(r, r["kept"].replace("-", "_")) > p95(r, other[r["kept"]].replace("-", "_")) + 0.01]
    kept = sum(r["kept"] == "continued" for r in sel)
    out = [f"  eq. S2 kept the continued fit on {kept} of {len(sel)} scans; it kept the fit with the larger whole-fit "
           f"face p95 (by more than 0.01 cm) on {len(wrong)}."]
    out += [f"  - seed {r['seed']} {r['person']} {r['scan']}: kept {r['kept']} (S2 {float(r['s2_one_sided']):.4f} / "
            f"{float(r['s2_continued']):.4f} h, whole p95 {p95(r, 'one_sided'):.3f} / {p95(r, 'continued'):.3f} cm)"
            for r in wrong]
    return out


def main(argv=None):
    from facebasis.atomic import atomic_write_bytes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3])
    ap.add_argument("--persons", nargs="+", choices=("in-space", "detail"), default=["detail", "in-space"])
    ap.add_argument("--scan-pairs", type=int, nargs="+", default=[0, 5000],
                    help="ModelFitOptions.scan_pairs of the whole-expression fit; one method per value")
    ap.add_argument("--schedules", nargs="+", choices=("joint", "after"), default=["joint", "after"],
                    help="RegistrationOptions.expression_pairs_schedule for each --scan-pairs value above 0")
    ap.add_argument("--out", default="reports/registration/mouth_basin")
    ap.add_argument("--table", action="store_true", help="only write mouth_basin.md from the seed*.csv files")
    args = ap.parse_args(argv)
    if any(v < 0 for v in args.scan_pairs):  # before any person is built
        ap.error(f"--scan-pairs: expected integers >= 0, found {args.scan_pairs}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.table:
        return print(write_table(out))
    ran = set(methods(args.scan_pairs, args.schedules))
    for seed in args.seeds:
        old = _rows(out / f"seed{seed}.csv")
        old = [r for r in old if (int(r["scan_pairs"]), r["schedule"]) not in ran]
        rows = []
        for kind in args.persons:
            rows += run_person(seed, kind, args.scan_pairs, args.schedules)
            atomic_write_bytes(out / f"seed{seed}.csv", csv_bytes(old + rows))  # after every person: kept if stopped


def _rows(path: Path) -> list[dict]:
    """The rows of a ``seed<S>.csv`` (none if absent), with the columns written since (``schedule``: rows before
    it had the pairs from the first round; the ``after`` schedule's columns empty)."""
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r.setdefault("schedule", "one-sided" if int(r["scan_pairs"]) == 0 else "joint")
        for k in ("kept", *(f"s2_{c}" for c in CANDIDATES), *(f"whole_p95_{c}" for c in CANDIDATES)):
            r.setdefault(k, "")
    return rows


if __name__ == "__main__":
    main()
