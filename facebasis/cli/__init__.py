"""The ``facebasis`` command line: a thin layer over the library.

Every user error is a :class:`~facebasis.errors.FacebasisError`: it is printed as ``error: ...``
on stderr and the command exits with status 2. An operating-system error (disk full, read-only
location, no permission, a symbolic-link loop) is one such line too, naming the path, the errno and
what to do. Outputs are written atomically. Ctrl-C, SIGTERM and SIGHUP stop any command at once,
even inside IPOPT, print one line and exit with 128 + the signal's number (130, 143, 129), leaving
either the old output or none (:mod:`facebasis.interrupt`).

One module per group of commands; each only parses, calls the library and prints:
:mod:`.demo`, :mod:`.rigging` (transfer, rig, export, verify), :mod:`.contact` (virtual-edges,
penetration), :mod:`.capture` (capture), :mod:`.retarget` (animate2d, animate3d, retarget), :mod:`.report` (report, sweep).
"""

from __future__ import annotations

import argparse
import errno
import os
import signal
import sys
from pathlib import Path

from ..errors import FacebasisError
from ..interrupt import install_stop_handlers, signal_number
from . import capture, contact, demo, registration, report, retarget, rigging

#: command groups, in the order their commands are listed by ``facebasis --help``
GROUPS = (demo, rigging, contact, capture, retarget, report, registration)


DESCRIPTION = ("facebasis: personalised facial blendshape rigs (deformation transfer, example-based "
               "generation with certified weights), kept free of layer penetration (virtual edges, an exact "
               "counter), driven from video (markerless capture, reproduction on cartoons, meshes and rigs). "
               "Errors exit with status 2; an interrupt (Ctrl-C, SIGTERM, SIGHUP) exits with 128 + the "
               "signal's number (130, 143, 129), leaving the old output or none.")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``error: facebasis rig: argument --iterations: ...``."""

    def error(self, message):
        print(f"error: {self.prog}: {message} (see '{self.prog} --help')", file=sys.stderr)
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog="facebasis", description=DESCRIPTION)
    parser.add_argument("-V", "--version", action="version", version=f"facebasis {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for group in GROUPS:
        group.register(sub)
    for action in sub._choices_actions:  # each command's --help opens with its one-line summary
        command = sub.choices[action.dest]
        if command.description is None:
            command.description = action.help[:1].upper() + action.help[1:] + "."
    from .examples import apply_examples

    apply_examples(parser)  # every --help page ends with examples (facebasis.cli.examples.EXAMPLES)
    return parser


#: advice added to an operating-system error, by errno
_OS_ADVICE = {
    errno.ENOSPC: "the disk is full: free space or write elsewhere",
    errno.EDQUOT: "the disk quota is used up: free space or write elsewhere",
    errno.EROFS: "the location is read-only: write elsewhere",
    errno.EACCES: "no permission: check the folder's owner and mode, or write elsewhere",
    errno.EPERM: "operation not permitted: check the folder's owner and mode, or write elsewhere",
    errno.ELOOP: "a symbolic link points (through others) back to itself",
    errno.ENOTDIR: "a part of the path is a file or a symbolic link that leads nowhere",
}


def os_error_line(exc: OSError, command: str, out=None) -> str:
    """One line for an operating-system error: the path (the output it was being written for, when
    it lies in that output's staging area), what failed and the errno name, e.g.
    ``facebasis rig: writing output run (staging .run.facebasis-ab12/new/jawOpen.obj): No space left on
    device [ENOSPC]; the disk is full: free space or write elsewhere``."""
    name = errno.errorcode.get(exc.errno or 0, "")
    what = exc.strerror or str(exc) or type(exc).__name__
    path = exc.filename
    if path is not None:
        path = str(path) + (f" -> {exc.filename2}" if exc.filename2 is not None else "")
        where = path
        if out:
            o = Path(str(out)).absolute()
            try:
                rel = Path(str(exc.filename)).absolute().relative_to(o.parent)
            except ValueError:
                rel = None
            if rel is not None and rel.parts and rel.parts[0].startswith(f".{o.name}."):
                where = f"writing output {out} (staging {rel.as_posix()})"
            elif rel is not None and rel.parts == (o.name,):
                where = f"writing output {out}"
            elif rel is not None and rel.parts and rel.parts[0] == o.name:
                where = f"writing output {out} ({path})"
    elif out and exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS):  # only writes fail so
        where = f"writing output {out}"
    elif out:
        where = f"while reading the inputs or writing output {out}"
    else:
        where = "while reading the inputs or writing the output"
    advice = _OS_ADVICE.get(exc.errno)
    link = _symlink_note(out)
    if link:
        advice = link
    return f"facebasis {command}: {where}: {what}" + (f" [{name}]" if name else "") + (f"; {advice}" if advice else "")


def _symlink_note(out) -> str:
    """'--out X is a symbolic link to Y, which does not exist' (or loops); '' otherwise."""
    if not out:
        return ""
    p = Path(str(out))
    for q in (p, *p.parents):
        try:
            if not q.is_symlink():
                continue
            target = q.readlink()
            q.stat()
        except (OSError, RuntimeError) as exc:
            if getattr(exc, "errno", None) == errno.ELOOP or isinstance(exc, RuntimeError):
                return f"{q} is a symbolic link to {target}, which leads back to itself (a loop)"
            if isinstance(exc, FileNotFoundError):
                return f"{q} is a symbolic link to {target}, which does not exist"
            return ""
    return ""


class _StdoutGuard:
    """``sys.stdout`` for a command: once the reader of a pipe has gone (``facebasis rig ... | head``),
    further output is dropped and the command goes on to write its files, instead of dying in the
    middle with a ``BrokenPipeError``."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._drop()

    def _drop(self):
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:  # the descriptor itself goes to /dev/null: the final flush at exit succeeds too
            os.dup2(devnull, self._stream.fileno())
        except (OSError, ValueError):
            pass
        finally:
            os.close(devnull)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv=None) -> int:
    """Run one command. Exit status: 0 done, 2 an error (one ``error:`` line on stderr), 128 + the
    signal's number when stopped by SIGINT (130), SIGTERM (143) or SIGHUP (129), with one
    ``interrupted:`` line. A closed stdout (``| head``) does not stop the command."""
    replaced = install_stop_handlers()
    guarded = sys.stdout is sys.__stdout__ and sys.stdout is not None
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if guarded:
            sys.stdout = _StdoutGuard(sys.stdout)
        return _run(args, getattr(args, "out", None), argv)
    finally:
        if guarded:
            sys.stdout = sys.__stdout__
        for sig, handler in replaced.items():  # main() called from Python: the caller's handlers back
            signal.signal(sig, handler)


def _run(args, out, argv=None) -> int:
    try:
        from .outputs import check_command_outputs

        check_command_outputs(args)  # the one output rule, before any work
        from ..provenance import run_context
        from .outputs import input_paths

        spec = args.outputs
        with run_context(["facebasis", *(sys.argv[1:] if argv is None else argv)], input_paths(args, spec)):
            return int(args.func(args) or 0)
    except FacebasisError as exc:  # library parameters named in its fields are written as the flags
        from .common import flags_of

        print(f"error: {exc.renamed(flags_of(getattr(args, 'command', None)))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # SIGINT, and SIGTERM / SIGHUP as Terminated
        signum = signal_number(exc)
        name = signal.Signals(signum).name
        print(f"interrupted: facebasis {args.command} stopped by {name}; no output was written or replaced",
              file=sys.stderr)
        return 128 + signum
    except OSError as exc:  # disk full, read-only, no permission, symlink loops: what failed, where
        print(f"error: {os_error_line(exc, args.command, out)}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        if not str(exc).startswith("Symlink loop"):  # pathlib's resolve() on a link loop (Python < 3.13)
            raise
        print(f"error: facebasis {args.command}: {str(exc).removeprefix('Symlink loop from ').strip(chr(39))}: a symbolic link "
              f"that leads back to itself [ELOOP]", file=sys.stderr)
        return 2
    except RecursionError:
        print(f"error: facebasis {args.command}: an input is nested too deeply to be read (Python's recursion "
              "limit was reached)", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"error: facebasis {args.command}: out of memory (an input too large for this machine)",
              file=sys.stderr)
        return 2
    except ValueError as exc:
        if "integer string conversion" not in str(exc):  # Python's limit on long integers in inputs
            raise
        print(f"error: facebasis {args.command}: an input holds an integer too long to read ({exc})",
              file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
