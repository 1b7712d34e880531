"""Atomic outputs: a failed or interrupted run leaves no half-written file or folder behind.

An output folder replaces an existing one only if that folder is empty or was written by this
package (its :data:`OUTPUT_MARKER` file): ``--out`` naming a folder of the user's own files is
refused, never emptied.

Outputs get the permissions an ordinary ``open``/``mkdir`` would give under the process's umask
(temporary files are created private, then opened up before they are renamed into place). Staging
folders carry the writing process's id; one left behind by a process that no longer runs (killed
with SIGKILL, power loss) is removed the next time the same output is written.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from .interrupt import deferred_interrupts

#: the file every output folder carries, so that a later run with the same ``--out`` may replace it
OUTPUT_MARKER = ".facebasis-output"


def _read_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: the process's umask, read once at import (reading it means setting it, which is not thread-safe)
_UMASK = _read_umask()


def _open_up(path: Path, directory: bool) -> None:
    """Give a private temporary file or folder the mode ``open``/``mkdir`` would have given it."""
    os.chmod(path, (0o777 if directory else 0o666) & ~_UMASK)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - someone else's process
        return True
    return True


def _remove_stale(out: Path) -> None:
    """Staging or swapped-out siblings of ``out`` left by processes that no longer run."""
    for kind in ("partial", "old"):
        for p in out.parent.glob(f".{out.name}.{kind}-*"):
            try:
                pid = int(p.name[len(f".{out.name}.{kind}-"):].split("-")[0])
            except ValueError:
                continue
            if pid != os.getpid() and not _alive(pid):
                shutil.rmtree(p, ignore_errors=True)


def check_output_folder(out_dir, inputs=(), what: str = "--out", allow=()) -> Path:
    """Refuse an output folder whose replacement would delete what is not an output: an empty path
    (the current folder), the current folder or one above it, or an input (or a folder holding one).
    Called by every command before any work, and by :func:`atomic_directory` before the swap.

    ``inputs``: paths the command reads (None entries are skipped); ``allow``: inputs the output
    may replace (``rig --resume RUN --out RUN`` updates the run in place)."""
    from .errors import InputError

    if not str(out_dir).strip():
        raise InputError(f"{what}: expected an output folder path, found an empty string (it would "
                         "replace the current folder)")
    out = Path(out_dir).absolute().resolve()
    cwd = Path.cwd().resolve()
    if out == cwd or out in cwd.parents:
        raise InputError(f"{what} {out_dir}: expected a new folder or a previous output, found "
                         f"{'the current folder' if out == cwd else 'a folder above the current one'} "
                         "(replacing it would delete everything in it)")
    allowed = {Path(a).absolute().resolve() for a in allow if a is not None}
    for p in inputs:
        if p is None:
            continue
        q = Path(p).absolute().resolve()
        if q in allowed:
            continue
        if out == q or out in q.parents:
            raise InputError(f"{what} {out_dir}: expected a folder apart from the inputs, found "
                             f"{'the input' if out == q else 'a folder holding the input'} {p} (replacing it "
                             "would delete it)")
    return out


@contextlib.contextmanager
def atomic_directory(out_dir: str | os.PathLike) -> Iterator[Path]:
    """Yield a fresh staging folder that replaces ``out_dir`` only if the block succeeds.

    The staging folder is a sibling of ``out_dir`` (same file system, so the final rename is
    atomic). If the block raises (an interrupt included), the staging folder is deleted and an
    existing ``out_dir`` is left untouched. If it succeeds, an existing ``out_dir`` is moved aside,
    the new folder renamed into place, and the old one removed, with SIGINT held back for those
    steps: whenever an interrupt lands, either the old or the new folder is left, and nothing else.
    """
    check_output_folder(out_dir, what="output folder")
    out = Path(out_dir).absolute()
    from .errors import InputError

    if out.exists() and not out.is_dir():
        raise InputError(f"output folder {out}: expected a folder or a new path, found a file")
    blocker = next((p for p in out.parents if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise InputError(f"output folder {out}: expected a folder path, found the file {blocker} in it")
    _check_replaceable(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale(out)
    stage = None
    try:
        with deferred_interrupts():
            stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-{os.getpid()}-", dir=out.parent))
            _open_up(stage, directory=True)
            (stage / OUTPUT_MARKER).write_text("written by facebasis; a later run with this output folder replaces it\n")
        yield stage
        with deferred_interrupts():
            _swap_in(stage, out)
    except BaseException:
        if stage is not None:
            with deferred_interrupts():
                shutil.rmtree(stage, ignore_errors=True)
        raise


def _check_replaceable(out: Path) -> None:
    """An existing folder is replaced only if it is empty or a previous output (its marker)."""
    if not out.is_dir() or (out / OUTPUT_MARKER).is_file():
        return
    entries = sorted(p.name for p in out.iterdir())
    if entries:
        from .errors import InputError

        shown = ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")
        raise InputError(f"output folder {out}: expected a new or empty folder or a previous facebasis output "
                         f"(with its {OUTPUT_MARKER} file), found a folder holding {shown}; choose another "
                         "output folder or remove this one (it would be replaced, its files deleted)")


def _swap_in(stage: Path, out: Path) -> None:
    """Replace ``out`` by ``stage``; on a failure half-way the old ``out`` is put back."""
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
        os.replace(out, old / "x")
    try:
        os.replace(stage, out)
    except BaseException:
        if old is not None:
            os.replace(old / "x", out)
            old.rmdir()
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary sibling and an atomic rename."""
    path = Path(path)
    if path.is_dir():
        from .errors import InputError

        raise InputError(f"output file {path}: expected a file name, found a folder")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        with deferred_interrupts():
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
            fh = os.fdopen(fd, "wb")
        with fh:
            fh.write(data)
        _open_up(Path(tmp), directory=False)
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            with deferred_interrupts(), contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=False) + "\n").encode())
