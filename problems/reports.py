"""Regenerate the figures and tables of ``reports/default`` and ``reports/ict``:
``python -m problems.reports --data {default,ict}`` (``python -m problems.reproduce --list`` names the
command behind every other folder of ``reports/``).

Runs, from scratch, into ``reports/<data>/``:

* the studies (alpha, lambda, alpha x lambda, initial-weight noise, method comparison) on Dask
  -> ``results.csv`` and its figures/tables (:func:`facebasis.report.run_report.sweep_report`);
* one example-based run written like ``facebasis rig`` -> ``run/`` and its report (convergence,
  weights, residuals, shapes) and ``run/rig.glb``; per-vertex error maps against the person's true
  shapes from three views (``error_maps_*``);
* the weight-step formulation comparison on the suite of :mod:`problems.weights_suite`
  -> ``formulations.*``;
* the penetration close-ups (plain transfer / virtual edges / exact contact, remaining pairs in red)
  and their counts -> ``penetration.*`` (``--only penetration``: this part alone).

``default`` needs nothing; ``ict`` reads ``../shared/data/ict/ict_face.npz``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def _run_folder(pp, out: Path):
    """An example-based run written as `facebasis rig` writes it, with its inputs as files."""
    from facebasis.rigging.problem import GenerationOptions
    from facebasis.rigging.generation import generate_blendshapes
    from facebasis.rigging.runs import write_problem_inputs, write_rig_run

    p = pp.problem
    options = GenerationOptions()
    res = generate_blendshapes(p, options)
    run = out / "run"
    if run.exists():
        shutil.rmtree(run)
    examples_dir, weights_file = write_problem_inputs(out / "run_inputs", p)
    write_rig_run(run, res, options, p, examples_dir, weights_file, relative_to=run)
    return run, res.rig


def _error_maps(pp, generated, out: Path, data: str) -> list[Path]:
    """Per-vertex error against the person's true shapes, deformation transfer vs the generated rig,
    from three views (renders of the built-in face only; ICT faces are not rendered into the repo)."""
    from facebasis.report.figures import shape_error_grid
    from facebasis.geometry.transfer import deformation_transfer

    p = pp.problem
    dt = deformation_transfer(p.template, p.target_neutral)
    names = ["jawOpen", "mouthSmile_L", "mouthPucker", "eyeBlink_L"]
    paths = []
    for view in ("front", "left", "below"):
        paths += shape_error_grid(p.template, pp.truth, {"deformation transfer": dt, "example-based": generated},
                                  names, out / f"error_maps_{view}", view=view)
    return paths


def _crop(Vs, mask, view="front", pad=0.12):
    """A crop around the zone ``mask`` over every mesh of ``Vs`` (the neutral and the shown
    expressions, so that an opened jaw stays in the frame)."""
    from facebasis.report.render import project

    P = np.concatenate([project(V[mask], view) for V in Vs])
    # 1st-99th percentile: a few far zone vertices (e.g. deep in a mouth socket) do not widen the crop
    lo, hi = np.percentile(P[:, :2], 1, axis=0), np.percentile(P[:, :2], 99, axis=0)
    m = pad * float((hi - lo).max())
    return (view, ((lo[0] - m, hi[0] + m), (lo[1] - m, hi[1] + m)))


def _vertex_mask(zone, n: int) -> np.ndarray:
    """A zone given as a boolean mask or as vertex indices, as a boolean mask of n vertices."""
    zone = np.asarray(zone)
    if zone.dtype == bool:
        return zone
    mask = np.zeros(n, bool)
    mask[zone.astype(np.int64)] = True
    return mask


def _penetration(data: str, out: Path) -> list[Path]:
    """Plain transfer, virtual edges and exact contact (``transfer --contact``) on a target with thinner
    / reshaped layers; counts per expression (table) and close-ups (figure)."""
    from facebasis.contact.exact import contact_transfer
    from facebasis.contact.penetration import LOCAL_FOLD_EDGES, pair_set, penetration_report
    from facebasis.report.penetration import penetration_figure
    from facebasis.report.tables import write_table
    from facebasis.geometry.transfer import DeformationTransfer
    from facebasis.contact.virtual_edges import detect_virtual_edges
    from facebasis.geometry.mesh import median_edge_length

    if data == "ict":
        from problems.ict import ict_identity, ict_random_identity, ict_rig, ict_zones

        template = ict_rig()
        c, _ = ict_random_identity(0)
        target = ict_identity(3.0 * c)
        zones = ict_zones()
        show = ("mouthClose", "jawForward", "mouthShrugLower", "eyeBlink_L")
        label = "ICT onto identity seed 0 scaled 3x"
        exclude = ("mouthClose",)  # ICT's corrective pressing the lips together on top of jawOpen
    else:
        from facebasis.defaults.face import default_person, default_template, region_masks

        template = default_template()
        target = default_person().neutral
        masks = region_masks()
        zones = {"lips": masks["lips"] | masks["mouth_socket"], "lids": masks["eyelids"]}
        show = ("mouthPucker", "jawOpen", "eyeBlink_L")
        label = "built-in template onto the built-in person"
        exclude = ()
    F = template.faces
    ve = detect_virtual_edges(template.neutral, F)
    plain = DeformationTransfer(template, target).transfer()
    guarded = DeformationTransfer(template, target, virtual_edges=ve).transfer()
    t = time.perf_counter()
    contact = contact_transfer(template, target, exclude=exclude, allow_target_pairs=True)
    contact_s = time.perf_counter() - t
    excluded = {s.name for s in contact.shapes if s.excluded}
    neutral_pairs = pair_set(target, F)
    local_within = LOCAL_FOLD_EDGES * median_edge_length(target, F)  # closer along the target neutral: a local fold
    rows, arrays = [], {"faces": F}
    for i, name in enumerate(template.names):
        refs = (neutral_pairs, pair_set(template.neutral + template.deltas[i], F))
        counts = []
        for kind, rig in (("plain", plain), ("ve", guarded), ("contact", contact.rig)):
            X = target + rig.deltas[i]
            rep = penetration_report(X, F, reference_pairs=refs, rest=target, local_within=local_within)
            new = rep.new
            counts.append((len(new), rep.count(local=False)))
            if name in show:
                arrays[f"{name}/{kind}"] = X
                arrays[f"{name}/{kind}_hits"] = np.unique(new[~rep.local].ravel())
                arrays[f"{name}/{kind}_local_hits"] = np.unique(new[rep.local].ravel())
                if kind == "contact" and name in excluded:
                    arrays[f"{name}/contact_note"] = "excluded"
        shape = contact.shapes[i]
        rows.append((name + (" (excluded from contact)" if name in excluded else ""), counts[0][0], counts[1][0],
                     counts[2][0], counts[0][1], counts[1][1], counts[2][1], shape.iterations,
                     shape.solver_iterations, "" if np.isnan(shape.min_distance) else f"{shape.min_distance:.5f}"))
    total = tuple(sum(r[j] for r in rows) for j in range(1, 7))
    rows.append(("total",) + total + ("", "", ""))
    paths = write_table(out, "penetration", ("expression", "new pairs, plain transfer", "new pairs, virtual edges",
                                             "new pairs, contact", "layer crossings, plain",
                                             "layer crossings, virtual edges", "layer crossings, contact",
                                             "contact rounds", "contact QP iterations", "contact min distance"), rows)
    arrays["kinds"] = ("plain", "ve", "contact")
    arrays["names"] = [n for n in show if f"{n}/plain" in arrays]
    shown = [template.neutral] + [arrays[f"{n}/{k}"] for n in arrays["names"] for k in arrays["kinds"]]
    arrays["crops"] = {z: _crop(shown, zones[z]) for z in ("lips", "lids")}
    # the triangles of each zone (a corner in it): each close-up counts its own zone's triangles
    arrays["zone_faces"] = {z: np.flatnonzero(np.asarray(_vertex_mask(zones[z], len(target)))[F].any(1))
                            for z in ("lips", "lids")}
    paths += penetration_figure(arrays, out)
    print(f"  penetration ({label}): {total[0]} new intersecting pairs with plain transfer, {total[1]} with "
          f"virtual edges ({len(ve)} edges), {total[2]} with exact contact ({contact_s:.1f} s; excluded: "
          f"{', '.join(sorted(excluded)) or 'none'}); layer crossings (triangles >= {LOCAL_FOLD_EDGES:g} median edges "
          f"apart along the target neutral) {total[3]}, {total[4]} and {total[5]}")
    return paths


def _report_of_a_run(data: str, seed: int, out: Path, person_problem, report_run):
    """One example-based run with default options, written like ``facebasis rig``, and its report."""
    print("run: example-based generation, default options")
    pp = person_problem(data, seed)
    run, generated = _run_folder(pp, out)
    # ICT renders (faces) go to reports/ict/renders/ (not committed, see .gitignore) and stay out of
    # the committed index; the built-in face's renders are part of the report
    report_run(run, out / "run_report", renders_dir=out / "renders" if data == "ict" else None)
    return pp, generated


def _shown(path: Path) -> str:
    """``path`` relative to the working folder when inside it, else as given."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m problems.reports", description=__doc__.splitlines()[0])
    parser.add_argument("--data", choices=("default", "ict"), default="default")
    parser.add_argument("--out", default=None, help="output folder (default reports/<data>)")
    parser.add_argument("--seeds", default="0", help="problem seeds of the studies (default 0)")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--scheduler", default=None)
    parser.add_argument("--only", choices=("penetration", "run", "figures"), default=None,
                        help="regenerate only this part (penetration: the counts and close-ups, no studies; "
                             "run: the example-based run and its report; figures: the study figures and "
                             "tables redrawn from the stored results.csv, nothing solved)")
    args = parser.parse_args(argv)
    if args.data == "ict":
        from problems.ict import ict_available, ict_path

        if not ict_available():
            print(f"ICT data not found at {ict_path()}", file=sys.stderr)
            return 2
    out = Path(args.out) if args.out else REPO / "reports" / args.data
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.only == "penetration":
        _penetration(args.data, out)
        print(f"{_shown(out)}: penetration regenerated ({args.data} data) in {time.perf_counter() - t0:.0f} s")
        return 0
    from facebasis.report.run_report import formulation_report, report_run, sweep_report
    from facebasis.report.studies import STUDIES, person_problem, read_table, run_tasks, study_tasks, write_table

    seeds = tuple(int(s) for s in args.seeds.split(","))
    if args.only == "figures":
        sweep_report(read_table(out / "results.csv"), out)
        print(f"{_shown(out)}: study figures redrawn from results.csv in {time.perf_counter() - t0:.0f} s")
        return 0
    if args.only == "run":
        _report_of_a_run(args.data, seeds[0], out, person_problem, report_run)
        print(f"{_shown(out)}: run and its report regenerated ({args.data} data) in {time.perf_counter() - t0:.0f} s")
        return 0
    tasks = [t for st in STUDIES for t in study_tasks(st, args.data, seeds)]
    print(f"studies: {len(tasks)} tasks on {args.scheduler or 'a local Dask cluster'}")
    rows = run_tasks(tasks, scheduler=args.scheduler, workers=args.workers)
    write_table(rows, out / "results.csv")
    sweep_report(read_table(out / "results.csv"), out)
    pp, generated = _report_of_a_run(args.data, seeds[0], out, person_problem, report_run)
    _error_maps(pp, generated, out, args.data)
    print("formulations: weight-step suite")
    from facebasis.rigging.formulations import compare_formulations
    from problems.weights_suite import weight_suite

    formulation_report(compare_formulations(weight_suite(args.data)), out)
    print("penetration")
    _penetration(args.data, out)
    print(f"{_shown(out)} regenerated ({args.data} data) in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
