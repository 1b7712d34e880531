"""``facebasis transfer``, ``rig``, ``export``, ``verify``: deformation transfer and example-based
rig generation (Gao, Tan, Guo, Fan 2015) with certified weights."""

from __future__ import annotations

import sys
import time

from .common import add_rig_folder_args, add_virtual_edge_args, describe_pairs, pair_of_floats, virtual_edges_for


def cmd_transfer(args) -> int:
    from ..atomic import atomic_directory
    from ..geometry.rig import load_rig_folder, load_target_neutral, write_shapes
    from ..geometry.transfer import DeformationTransfer

    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    ve = virtual_edges_for(args, template)
    t0 = time.perf_counter()
    result = DeformationTransfer(template, target, virtual_edges=ve, virtual_weight=args.virtual_weight,
                                 virtual_mode=args.virtual_mode).transfer()
    seconds = time.perf_counter() - t0
    with atomic_directory(args.out) as stage:
        write_shapes(stage, result)
    print(f"transferred {result.n_shapes} shapes onto {args.target} in {seconds:.3f} s -> {args.out}")
    return 0


def cmd_rig(args) -> int:
    from ..atomic import atomic_directory
    from ..geometry.rig import load_rig_folder, load_target_neutral
    from ..rigging.examples import load_examples, load_weights, parse_pairs
    from ..rigging.generation import BlendshapeGenerator, GenerationOptions, GenerationProblem
    from ..rigging.runs import write_rig_run

    # everything is validated before any solving starts
    options = GenerationOptions(iterations=args.iterations, alpha=pair_of_floats(args.alpha, "--alpha"),
                                lam=pair_of_floats(args.lam, "--lambda"), virtual_weight=args.virtual_weight,
                                virtual_mode=args.virtual_mode)
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    names, examples = load_examples(args.examples, template)
    X0 = load_weights(args.weights, names, template.names)
    ve = virtual_edges_for(args, template)
    pairs = parse_pairs(args.exclusive)
    problem = GenerationProblem(template, target, examples, X0, names, pairs, ve)
    print(f"template {template.n_shapes} shapes, {template.n_vertices} vertices; {len(names)} training "
          f"expressions; {describe_pairs(problem.exclusive, len(args.exclusive))}")
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


def cmd_verify(args) -> int:
    from ..rigging.examples import parse_pairs
    from ..rigging.verify import verify_run

    report = verify_run(args.run_dir, tolerance=args.tolerance, check_pairs=parse_pairs(args.exclusive))
    print(f"{report.run_dir}: {len(report.examples)} examples, lambda {report.lam:g}, tolerance {report.tolerance:g} "
          "(relative objective gap of the stored weights to the certified global optimum)")
    print(f"exclusive pairs of the run: {describe_pairs(report.pairs, len(report.pairs))}")
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


def cmd_export(args) -> int:
    from ..geometry.gltf import write_glb
    from ..geometry.rig import load_rig_folder

    rig = load_rig_folder(args.rig, args.neutral, args.exclude)
    out = write_glb(rig, args.out)
    print(f"{rig.n_shapes} morph targets, {rig.n_vertices} vertices -> {out}")
    return 0


def register(sub) -> None:
    """Add this group's subcommands to the ``facebasis`` parser."""
    from ..rigging.generation import GenerationOptions

    defaults = GenerationOptions()
    alpha = ",".join(f"{a:g}" for a in defaults.alpha)
    lam = ",".join(f"{a:g}" for a in defaults.lam)
    p = sub.add_parser("transfer", help="deformation transfer of a template rig onto a target neutral")
    add_rig_folder_args(p)
    p.add_argument("--target", required=True, help="target neutral mesh (.obj/.ply), template topology")
    p.add_argument("--out", required=True, help="output folder: <shape>.obj for every template shape")
    add_virtual_edge_args(p)
    p.set_defaults(func=cmd_transfer)

    p = sub.add_parser("rig", help="example-based blendshape generation (Gao et al. 2015)")
    add_rig_folder_args(p)
    p.add_argument("--target", required=True, help="target neutral mesh, template topology")
    p.add_argument("--examples", required=True, help="folder of training expression meshes (names = file stems)")
    p.add_argument("--weights", required=True, help='rough weights JSON: {"ex00": {"jawOpen": 0.8}}')
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--iterations", type=int, default=defaults.iterations,
                   help=f"alternations (default {defaults.iterations})")
    p.add_argument("--alpha", default=alpha, help=f"alpha schedule FIRST,LAST (default {alpha})")
    p.add_argument("--lambda", dest="lam", default=lam, help=f"lambda schedule FIRST,LAST (default {lam})")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="mutually exclusive shape pairs (complementarity x_a x_b = 0); give several after one "
                        "flag (--exclusive A:B C:D) or repeat the flag; every pair is kept")
    add_virtual_edge_args(p)
    p.set_defaults(func=cmd_rig)

    p = sub.add_parser("export", help="a rig folder as glTF 2.0 (.glb) with one morph target per shape")
    p.add_argument("rig", help="rig folder (neutral + one mesh per blendshape), e.g. a `facebasis rig` output")
    p.add_argument("--neutral", default="neutral.obj", help="file name of the neutral inside the folder (default neutral.obj)")
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
