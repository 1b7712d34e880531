"""The ``facebasis`` command line: a thin layer over the library.

Every user error is a :class:`~facebasis.errors.FacebasisError`: it is printed as ``error: ...``
on stderr and the command exits with status 2. Outputs are written atomically.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .errors import FacebasisError


def _add_rig_folder_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--template", required=True, help="template rig folder (neutral + one mesh per blendshape)")
    p.add_argument("--neutral", default="neutral.obj", help="file name of the neutral inside the rig folder")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB",
                   help="ignore rig-folder files matching this glob (repeatable), e.g. 'identity*'")


def _virtual_edges_for(args, template):
    """``--virtual-edges [EDGES.json]``: read the file, or detect on the template's neutral."""
    if args.virtual_edges is None:
        return None
    from .virtual_edges import VirtualEdges, detect_virtual_edges

    if args.virtual_edges == "detect":
        ve = detect_virtual_edges(template.neutral, template.faces, name=f"template {template.source}")
        print(f"virtual edges: {len(ve)} detected on the template neutral in {ve.seconds:.2f} s")
        return ve
    ve = VirtualEdges.read(args.virtual_edges, template.n_vertices)
    print(f"virtual edges: {len(ve)} from {args.virtual_edges}")
    return ve


def _add_virtual_edge_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--virtual-edges", nargs="?", const="detect", default=None, metavar="EDGES.json",
                   help="add the virtual-edge energy against penetration (seed 004); without a file the "
                        "edges are detected on the template neutral with the default parameters")
    p.add_argument("--virtual-weight", type=float, default=None,
                   help="weight of the virtual-edge energy (default: facebasis.virtual_edges.DEFAULT_VIRTUAL_WEIGHT)")
    p.add_argument("--virtual-mode", choices=("proportional", "gradient"), default="proportional",
                   help="virtual-edge targets: the template's gap motion scaled down to a thinner target "
                        "gap (proportional, default) or the local gradient only (gradient)")


def cmd_transfer(args) -> int:
    from .atomic import atomic_directory
    from .rig import load_rig_folder, load_target_neutral, write_shapes
    from .transfer import DeformationTransfer

    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    ve = _virtual_edges_for(args, template)
    t0 = time.perf_counter()
    result = DeformationTransfer(template, target, virtual_edges=ve, virtual_weight=args.virtual_weight,
                                 virtual_mode=args.virtual_mode).transfer()
    seconds = time.perf_counter() - t0
    with atomic_directory(args.out) as stage:
        write_shapes(stage, result)
    print(f"transferred {result.n_shapes} shapes onto {args.target} in {seconds:.3f} s -> {args.out}")
    return 0


def _pair_of_floats(text: str, name: str) -> tuple[float, float]:
    from .errors import InputError

    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise InputError(f"{name}: expected two numbers FIRST,LAST, found {text!r}") from exc
    if len(vals) == 1:
        vals = vals * 2
    if len(vals) != 2:
        raise InputError(f"{name}: expected two numbers FIRST,LAST, found {text!r}")
    return vals[0], vals[1]


def _describe_pairs(pairs, given: int) -> str:
    """``"3 exclusive pairs: a:b, c:d, e:f"`` (and how many repeats of a pair were merged)."""
    text = f"{len(pairs)} exclusive pairs" + (": " + ", ".join(f"{a}:{b}" for a, b in pairs) if pairs else "")
    if given > len(pairs):
        text += f" ({given - len(pairs)} repeated pair(s) merged)"
    return text


def cmd_rig(args) -> int:
    from .atomic import atomic_directory
    from .examples import load_examples, load_weights, parse_pairs
    from .generation import GenerationOptions, GenerationProblem, BlendshapeGenerator
    from .results import write_rig_run
    from .rig import load_rig_folder, load_target_neutral

    # everything is validated before any solving starts
    options = GenerationOptions(iterations=args.iterations, alpha=_pair_of_floats(args.alpha, "--alpha"),
                                lam=_pair_of_floats(args.lam, "--lambda"), virtual_weight=args.virtual_weight,
                                virtual_mode=args.virtual_mode)
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    names, examples = load_examples(args.examples, template)
    X0 = load_weights(args.weights, names, template.names)
    ve = _virtual_edges_for(args, template)
    pairs = parse_pairs(args.exclusive)
    problem = GenerationProblem(template, target, examples, X0, names, pairs, ve)
    print(f"template {template.n_shapes} shapes, {template.n_vertices} vertices; {len(names)} training "
          f"expressions; {_describe_pairs(problem.exclusive, len(args.exclusive))}")
    gen = BlendshapeGenerator(problem, options)

    def progress(rec, total):
        flag = "" if rec.ipopt_success else f"  [IPOPT: {rec.ipopt_status}]"
        print(f"  iteration {rec.iteration}/{total}: alpha {rec.alpha:.3g} lambda {rec.lam:.3g} "
              f"E_fit {rec.e_fit:.4g} E_reg {rec.e_reg:.4g} weight objective {rec.weight_objective:.6g} "
              f"(IPOPT {rec.ipopt_iterations} it, {rec.basis_seconds + rec.weight_seconds:.2f} s){flag}", flush=True)

    result = gen.run(progress)
    with atomic_directory(args.out) as stage:
        write_rig_run(stage, result, options, problem, args.examples, args.weights)
    failed = [h for h in result.history if not h.ipopt_success]
    for h in failed:
        print(f"warning: IPOPT returned {h.ipopt_status} at iteration {h.iteration}; its answer was replaced "
              "by the certified optimum (branch and bound)", file=sys.stderr)
    for name in result.missing:
        print(f"warning: training expression {name} keeps a relative residual of "
              f"{result.residuals[names.index(name)]:.3f} > {options.missing_threshold}: the template "
              "may lack a shape it needs (missing expression)", file=sys.stderr)
    print(f"generated {template.n_shapes} blendshapes in {result.seconds + result.precompute_seconds:.2f} s -> {args.out}")
    return 0


def cmd_virtual_edges(args) -> int:
    from .meshio import read_mesh
    from .penetration import parse_region
    from .virtual_edges import detect_virtual_edges

    V, F = read_mesh(args.mesh, check_degenerate=True)
    mask = parse_region(args.region, len(V)) if args.region else None
    ve = detect_virtual_edges(V, F, cap=args.cap, ratio=args.ratio, per_vertex=args.per_vertex,
                              spacing=args.spacing, vertex_mask=mask, name=str(args.mesh))
    ve.write(args.out)
    print(f"{len(ve)} virtual edges ({ve.candidates} candidate pairs with distance < {ve.cap:.4g} and "
          f"geodesic/Euclidean >= {ve.ratio:g}) in {ve.seconds:.2f} s -> {args.out}")
    if args.figure:
        from .figures import virtual_edges_figure

        paths = virtual_edges_figure(V, F, ve.edges, Path(args.figure), title=f"{args.mesh}: {len(ve)} virtual edges")
        print(f"figure -> {', '.join(map(str, paths))}")
    return 0


def cmd_penetration(args) -> int:
    from .meshio import read_mesh, read_mesh_like
    from .penetration import parse_region, penetration_report, region_faces

    V, F = read_mesh(args.mesh)
    refs = [read_mesh_like(r, len(V), F, str(args.mesh)) for r in args.reference]
    face_mask = region_faces(F, parse_region(args.region, len(V))) if args.region else None
    rest, within = None, None
    if args.rest is not None:
        from .virtual_edges import median_edge_length

        rest = read_mesh_like(args.rest, len(V), F, str(args.mesh))
        if not (args.local_within > 0):
            from .errors import InputError

            raise InputError(f"--local-within: expected a positive number of edge lengths, found {args.local_within}")
        within = args.local_within * median_edge_length(rest, F)
    rep = penetration_report(V, F, refs, face_mask, rest=rest, local_within=within)
    where = f" in region {args.region} ({int(face_mask.sum())} triangles)" if face_mask is not None else ""
    print(f"{args.mesh}: {len(rep.pairs)} intersecting triangle pairs{where}")
    if refs:
        print(f"  new relative to {len(refs)} reference(s): {len(rep.new)}")
    if rest is not None:
        print(f"  {'new' if refs else 'all'}: {rep.count(local=False)} layer crossings, {rep.count(local=True)} local folds "
              f"(triangles within {args.local_within:g} median edges = {within:.4g} along {args.rest})")
    shown = rep.new if refs else rep.pairs
    for a, b in shown[: args.show].tolist():
        print(f"  triangles {a} {F[a].tolist()} x {b} {F[b].tolist()}")
    return 0


def cmd_verify(args) -> int:
    from .verify import verify_run

    from .examples import parse_pairs

    report = verify_run(args.run_dir, tolerance=args.tolerance, check_pairs=parse_pairs(args.exclusive))
    print(f"{report.run_dir}: {len(report.examples)} examples, lambda {report.lam:g}, tolerance {report.tolerance:g} "
          "(relative objective gap of the stored weights to the certified global optimum)")
    print(f"exclusive pairs of the run: {_describe_pairs(report.pairs, len(report.pairs))}")
    print(report.table())
    bad = [e.name for e in report.examples if not e.ok]
    if report.checked:
        print("pairs named with --exclusive (largest |x_a x_b| of the stored weights over all examples):")
        for chk in report.checked:
            flag = "ok" if chk.ok else "BREACHED"
            print(f"  {chk.a}:{chk.b}  {chk.max_product:.3g}  at {chk.worst_example}  "
                  f"({'a constraint of the run' if chk.in_run else 'not a constraint of the run'})  {flag}")
        breached = [f"{c.a}:{c.b}" for c in report.checked if not c.ok]
        if breached:
            print(f"NOT EXCLUSIVE: the stored weights breach {len(breached)} pair(s) named with --exclusive "
                  f"({', '.join(breached)})", file=sys.stderr)
            return 1
    if bad:
        print(f"NOT OPTIMAL: {len(bad)} of {len(report.examples)} stored answers ({', '.join(bad)})", file=sys.stderr)
        return 1
    print(f"all {len(report.examples)} stored answers are certified optimal")
    return 0


def cmd_report(args) -> int:
    from .report import report_run, sweep_report

    target = Path(args.path)
    formats = tuple(args.formats.split(","))
    if target.suffix.lower() == ".csv":
        from .studies import read_table

        out = Path(args.out) if args.out else target.with_suffix("")
        paths = sweep_report(read_table(target), out, formats)
        if not paths:
            from .errors import InputError

            raise InputError(f"{target}: expected rows of at least one study, found none")
    else:
        paths = report_run(target, args.out, formats)
    print(f"{len(paths)} files -> {paths[0].parent}")
    return 0


def cmd_sweep(args) -> int:
    from .studies import STUDIES, run_tasks, study_tasks, write_table

    studies = STUDIES if args.study == "all" else tuple(args.study.split(","))
    seeds = tuple(int(s) for s in args.seeds.split(","))
    tasks = [t for st in studies for t in study_tasks(st, args.problem, seeds)]
    where = args.scheduler or f"a local Dask cluster of {args.workers or 'all'} worker processes"
    print(f"{len(tasks)} tasks ({', '.join(studies)}) on problem {args.problem}, seeds {list(seeds)}, on {where}")
    rows = run_tasks(tasks, scheduler=args.scheduler, workers=args.workers, progress=not args.quiet)
    write_table(rows, args.out)
    print(f"results table ({len(rows)} rows) -> {args.out}; figures: facebasis report {args.out}")
    return 0


def cmd_export(args) -> int:
    from .export import write_glb
    from .rig import load_rig_folder

    rig = load_rig_folder(args.rig, args.neutral, args.exclude)
    out = write_glb(rig, args.out)
    print(f"{rig.n_shapes} morph targets, {rig.n_vertices} vertices -> {out}")
    return 0


def cmd_demo(args) -> int:
    from .demo import run_demo

    run_demo(Path(args.out), quick=args.quick, log=print)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from .penetration import LOCAL_FOLD_EDGES

    parser = argparse.ArgumentParser(prog="facebasis", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="run the main job on the built-in default face")
    p.add_argument("--out", default="facebasis-demo", help="output folder (default: ./facebasis-demo)")
    p.add_argument("--quick", action="store_true", help="fewer iterations (for smoke tests)")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("transfer", help="deformation transfer of a template rig onto a target neutral")
    _add_rig_folder_args(p)
    p.add_argument("--target", required=True, help="target neutral mesh (.obj/.ply), template topology")
    p.add_argument("--out", required=True, help="output folder: <shape>.obj for every template shape")
    _add_virtual_edge_args(p)
    p.set_defaults(func=cmd_transfer)

    p = sub.add_parser("rig", help="example-based blendshape generation (seed 000)")
    _add_rig_folder_args(p)
    p.add_argument("--target", required=True, help="target neutral mesh, template topology")
    p.add_argument("--examples", required=True, help="folder of training expression meshes (names = file stems)")
    p.add_argument("--weights", required=True, help='rough weights JSON: {"ex00": {"jawOpen": 0.8}}')
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--iterations", type=int, default=10, help="alternations (default 10)")
    p.add_argument("--alpha", default="0.5,0.1", help="alpha schedule FIRST,LAST (default 0.5,0.1)")
    p.add_argument("--lambda", dest="lam", default="100,10", help="lambda schedule FIRST,LAST (default 100,10)")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="mutually exclusive shape pairs (complementarity x_a x_b = 0); give several after one "
                        "flag (--exclusive A:B C:D) or repeat the flag; every pair is kept")
    _add_virtual_edge_args(p)
    p.set_defaults(func=cmd_rig)

    p = sub.add_parser("virtual-edges", help="detect virtual edges across thin layers (seed 004)")
    p.add_argument("mesh", help="neutral mesh (.obj/.ply)")
    p.add_argument("--out", required=True, help="output EDGES.json")
    p.add_argument("--cap", type=float, default=None, help="Euclidean cap in mesh units (default 3.3 median edge lengths)")
    p.add_argument("--ratio", type=float, default=2.0, help="geodesic/Euclidean floor (default 2)")
    p.add_argument("--per-vertex", type=int, default=4, help="edges kept per vertex (default 4)")
    p.add_argument("--spacing", type=float, default=None,
                   help="exclusion radius around chosen ends, mesh units (default 0: no exclusion)")
    p.add_argument("--region", default=None, metavar="START:END", help="only vertices START..END-1 as ends")
    p.add_argument("--figure", default=None, metavar="PNG", help="also draw the edges over the mesh")
    p.set_defaults(func=cmd_virtual_edges)

    p = sub.add_parser("penetration", help="count intersecting triangle pairs exactly")
    p.add_argument("mesh", help="mesh to check")
    p.add_argument("--reference", action="append", default=[], metavar="REF",
                   help="same-topology mesh whose intersecting pairs are not new (repeatable)")
    p.add_argument("--region", default=None, metavar="START:END", help="only triangles with all vertices in START..END-1")
    p.add_argument("--rest", default=None, metavar="REST",
                   help="rest mesh (e.g. the target neutral): split the pairs into local folds and layer crossings")
    p.add_argument("--local-within", type=float, default=LOCAL_FOLD_EDGES, metavar="K",
                   help="with --rest: triangles closer than K median edge lengths along REST are a local fold "
                        f"(default {LOCAL_FOLD_EDGES:g})")
    p.add_argument("--show", type=int, default=10, help="list this many pairs (default 10)")
    p.set_defaults(func=cmd_penetration)

    p = sub.add_parser("report", help="figures of a `facebasis rig` folder or of a `facebasis sweep` table")
    p.add_argument("path", help="rig output folder, or results .csv of `facebasis sweep`")
    p.add_argument("--out", default=None, help="output folder (default: RUN_DIR/report, or the CSV's name)")
    p.add_argument("--formats", default="png,pdf", help="figure formats (default png,pdf)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("sweep", help="alpha / lambda / noise / method studies in parallel (Dask)")
    p.add_argument("--problem", default="default", choices=("default", "ict"),
                   help="person problem: the built-in face (default) or ICT (needs ../shared)")
    p.add_argument("--study", default="all", help="alpha, lambda, grid, noise, methods, a comma list, or all")
    p.add_argument("--seeds", default="0", help="problem seeds, comma separated (default 0)")
    p.add_argument("--out", required=True, help="results table (.csv)")
    p.add_argument("--scheduler", default=None, help="address of a Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("export", help="a rig folder as glTF 2.0 (.glb) with one morph target per shape")
    p.add_argument("rig", help="rig folder (neutral + one mesh per blendshape), e.g. a `facebasis rig` output")
    p.add_argument("--neutral", default="neutral.obj", help="file name of the neutral inside the folder")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB", help="ignore matching files")
    p.add_argument("--out", required=True, help="output .glb")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("verify", help="certify the stored weights of a `facebasis rig` output folder")
    p.add_argument("run_dir", help="output folder of `facebasis rig` (with inputs.json)")
    p.add_argument("--tolerance", type=float, default=1e-6,
                   help="largest relative objective gap accepted (default 1e-6); exit status 1 beyond it")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="also report the largest product x_a x_b of the stored weights over these pairs "
                        "(several after one flag or repeated); exit status 1 if any exceeds 1e-8")
    p.set_defaults(func=cmd_verify)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except FacebasisError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
