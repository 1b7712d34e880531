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
    from .meshio import write_mesh
    from .rig import load_rig_folder, load_target_neutral, write_shapes
    from .transfer import DeformationTransfer

    template = load_rig_folder(args.template, args.neutral, args.exclude)
    target = load_target_neutral(args.target, template)
    t0 = time.perf_counter()
    result = DeformationTransfer(template, target).transfer()
    seconds = time.perf_counter() - t0
    with atomic_directory(args.out) as stage:
        write_shapes(stage, result, neutral_name=None)
        write_mesh(stage / "neutral.obj", result.neutral, result.faces)
    print(f"transferred {result.n_shapes} shapes onto {args.target} in {seconds:.3f} s -> {args.out}")
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
