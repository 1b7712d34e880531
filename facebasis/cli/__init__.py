"""The ``facebasis`` command line: a thin layer over the library.

Every user error is a :class:`~facebasis.errors.FacebasisError`: it is printed as ``error: ...``
on stderr and the command exits with status 2. Outputs are written atomically. Ctrl-C stops any
command at once, even inside IPOPT, prints one line and exits with status 130, leaving either the
old output or none.

One module per group of commands; each only parses, calls the library and prints:
:mod:`.demo`, :mod:`.rigging` (transfer, rig, export, verify), :mod:`.contact` (virtual-edges,
penetration), :mod:`.capture` (capture), :mod:`.retarget` (animate2d, animate3d, retarget), :mod:`.report` (report, sweep).
"""

from __future__ import annotations

import argparse
import sys

from ..errors import FacebasisError
from . import capture, contact, demo, registration, report, retarget, rigging

#: command groups, in the order their commands are listed by ``facebasis --help``
GROUPS = (demo, rigging, contact, capture, retarget, report, registration)


DESCRIPTION = ("facebasis: personalised facial blendshape rigs (deformation transfer, example-based "
               "generation with certified weights), kept free of layer penetration (virtual edges, an exact "
               "counter), driven from video (markerless capture, reproduction on cartoons, meshes and rigs). "
               "Errors exit with status 2.")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``error: facebasis rig: argument --iterations: ...``."""

    def error(self, message):
        print(f"error: {self.prog}: {message} (see '{self.prog} --help')", file=sys.stderr)
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog="facebasis", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"facebasis {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for group in GROUPS:
        group.register(sub)
    for action in sub._choices_actions:  # each command's --help opens with its one-line summary
        command = sub.choices[action.dest]
        if command.description is None:
            command.description = action.help[:1].upper() + action.help[1:] + "."
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        from .outputs import check_command_outputs

        check_command_outputs(args)  # the one output rule, before any work
        return int(args.func(args) or 0)
    except FacebasisError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"interrupted: facebasis {args.command} stopped; no output was written or replaced", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
