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


def cmd_transfer(args) -> int:
    from .atomic import atomic_directory
    from .rig import load_rig_folder, load_target_neutral, write_shapes
    from .transfer import DeformationTransfer

    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    t0 = time.perf_counter()
    result = DeformationTransfer(template, target).transfer()
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


def cmd_rig(args) -> int:
    from .atomic import atomic_directory, atomic_write_json
    from .examples import load_examples, load_weights, parse_pairs, weights_to_json
    from .generation import GenerationOptions, GenerationProblem, BlendshapeGenerator
    from .rig import load_rig_folder, load_target_neutral, write_shapes
    from .results import history_to_json
    from .verify import write_inputs

    # everything is validated before any solving starts
    options = GenerationOptions(iterations=args.iterations, alpha=_pair_of_floats(args.alpha, "--alpha"),
                                lam=_pair_of_floats(args.lam, "--lambda"))
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    names, examples = load_examples(args.examples, template)
    X0 = load_weights(args.weights, names, template.names)
    problem = GenerationProblem(template, target, examples, X0, names, parse_pairs(args.exclusive))
    print(f"template {template.n_shapes} shapes, {template.n_vertices} vertices; {len(names)} training "
          f"expressions; {len(problem.exclusive)} exclusive pairs")
    gen = BlendshapeGenerator(problem, options)

    def progress(rec, total):
        flag = "" if rec.ipopt_success else f"  [IPOPT: {rec.ipopt_status}]"
        print(f"  iteration {rec.iteration}/{total}: alpha {rec.alpha:.3g} lambda {rec.lam:.3g} "
              f"E_fit {rec.e_fit:.4g} E_reg {rec.e_reg:.4g} weight objective {rec.weight_objective:.6g} "
              f"(IPOPT {rec.ipopt_iterations} it, {rec.basis_seconds + rec.weight_seconds:.2f} s){flag}", flush=True)

    result = gen.run(progress)
    with atomic_directory(args.out) as stage:
        write_shapes(stage, result.rig)
        atomic_write_json(stage / "weights.json", weights_to_json(result.weights, names, template.names))
        atomic_write_json(stage / "history.json", history_to_json(result, options, problem))
        atomic_write_json(stage / "residuals.json", {
            "threshold": options.missing_threshold,
            "relative_residual": dict(zip(names, map(float, result.residuals))),
            "missing": list(result.missing)})
        write_inputs(stage, args.examples, args.weights, problem.exclusive, options.schedule()[-1][1])
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
    from .verify import verify_run

    report = verify_run(args.run_dir, tolerance=args.tolerance)
    print(f"{report.run_dir}: {len(report.examples)} examples, lambda {report.lam:g}, tolerance {report.tolerance:g} "
          "(relative objective gap of the stored weights to the certified global optimum)")
    print(report.table())
    bad = [e.name for e in report.examples if not e.ok]
    if bad:
        print(f"NOT OPTIMAL: {len(bad)} of {len(report.examples)} stored answers ({', '.join(bad)})", file=sys.stderr)
        return 1
    print(f"all {len(report.examples)} stored answers are certified optimal")
    return 0


def cmd_demo(args) -> int:
    from .demo import run_demo

    run_demo(Path(args.out), quick=args.quick, log=print)
    return 0


def build_parser() -> argparse.ArgumentParser:
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
    p.add_argument("--exclusive", nargs="*", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="mutually exclusive shape pairs (complementarity x_a x_b = 0)")
    p.set_defaults(func=cmd_rig)

    p = sub.add_parser("verify", help="certify the stored weights of a `facebasis rig` output folder")
    p.add_argument("run_dir", help="output folder of `facebasis rig` (with inputs.json)")
    p.add_argument("--tolerance", type=float, default=1e-6,
                   help="largest relative objective gap accepted (default 1e-6); exit status 1 beyond it")
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
