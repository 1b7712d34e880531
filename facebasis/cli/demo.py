"""``facebasis demo``: the main job on the built-in face."""

from __future__ import annotations

from pathlib import Path

from .outputs import Outputs


def cmd_demo(args) -> int:
    from ..apps.demo import run_demo

    run_demo(Path(args.out), quick=args.quick, log=print)
    return 0


def register(sub) -> None:
    """Add this group's subcommands to the ``facebasis`` parser."""
    p = sub.add_parser("demo", help="run the main job on the built-in default face")
    p.add_argument("--out", default="facebasis-demo", help="output folder (default: ./facebasis-demo)")
    p.add_argument("--quick", action="store_true", help="fewer iterations (for smoke tests)")
    p.set_defaults(func=cmd_demo, outputs=Outputs(writes=(("out", "folder", "--out"),)))
