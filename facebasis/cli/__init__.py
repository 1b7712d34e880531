"""The ``facebasis`` command line: a thin layer over the library.

Every user error is a :class:`~facebasis.errors.FacebasisError`: it is printed as ``error: ...``
on stderr and the command exits with status 2. Outputs are written atomically.

One module per group of commands; each only parses, calls the library and prints:
:mod:`.demo`, :mod:`.rigging` (transfer, rig, export, verify), :mod:`.contact` (virtual-edges,
penetration), :mod:`.report` (report, sweep).
"""

from __future__ import annotations

import argparse
import sys

from ..errors import FacebasisError
from . import contact, demo, report, rigging

#: command groups, in the order their commands are listed by ``facebasis --help``
GROUPS = (demo, rigging, contact, report)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="facebasis", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for group in GROUPS:
        group.register(sub)
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
