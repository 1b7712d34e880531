"""Outputs that never destroy what a user owns: one rule for every command, and atomic writes.

The rule (:func:`check_output`, called by every command before any work, through
:mod:`facebasis.cli.outputs`):

* an output is never an input, never holds an input, and never lies inside an input folder
  (unless that folder is itself a facebasis output, e.g. ``RUN_DIR/report``);
* an output is never the current folder or one above it, never a symbolic link, never a path
  through a file;
* an existing output *folder* is replaced only if it is empty or a previous facebasis output (its
  :data:`OUTPUT_MARKER` file); an existing output *file* only if facebasis wrote it (its format's
  signature: a glTF ``asset.generator``, a JSON ``format``/``generator`` key, a PNG/PDF software
  tag, a results table's header, ...: :func:`written_by_facebasis`).

Atomic writes: every output is made in a *run folder* beside it, ``.NAME.facebasis-XXXX``, which
belongs to its run by a lock held for the run's lifetime (``flock``; released by the kernel when the
process dies however it dies, across PID namespaces and containers that share the folder) and by a
unique token written inside it. The new output is built in ``RUN/new``; the swap moves an existing
output to ``RUN/old``, renames ``RUN/new`` into place, then removes the run folder. A run folder
whose lock is free belongs to a dead run and is recovered by the next run writing the same output
(:func:`recover`): if the kill fell between the two renames, the old output is *restored* from
``RUN/old``; a half-built ``RUN/new`` is deleted; an old output is never deleted unless the new one
is in place.

Outputs get the permissions an ordinary ``open``/``mkdir`` would give under the process's umask.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
import secrets
import shutil
import tempfile
import time
from pathlib import Path
from typing import Iterable, Iterator

from .interrupt import deferred_interrupts

#: the file every output folder carries, so that a later run with the same ``--out`` may replace it
OUTPUT_MARKER = ".facebasis-output"
#: run folders beside an output: ``.NAME.facebasis-XXXX``
RUN_INFIX = ".facebasis-"
_LOCK, _TOKEN, _NEW, _OLD = "lock", "token", "new", "old"
#: a run folder without a lock file (its run died between mkdir and lock) is stale after this long
_LOCKLESS_GRACE_SECONDS = 60.0


def _read_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: the process's umask, read once at import (reading it means setting it, which is not thread-safe)
_UMASK = _read_umask()

#: staging folders of the runs in this process (files written inside them need no run folder)
_ACTIVE_STAGES: set[Path] = set()


def _open_up(path: Path, directory: bool) -> None:
    """Give a private temporary file or folder the mode ``open``/``mkdir`` would have given it."""
    os.chmod(path, (0o777 if directory else 0o666) & ~_UMASK)


def _input_error(text: str):
    from .errors import InputError

    return InputError(text)


# ----------------------------------------------------------------------------------------------
# what facebasis wrote

#: byte patterns that mark a file as written by facebasis, by suffix (searched in its first 64 KiB;
#: for GLB in its JSON chunk)
_SIGNATURES: dict[str, tuple[bytes, ...]] = {
    ".json": (b'"format": "facebasis', b'"generator": "facebasis', b'"format":"facebasis', b'"generator":"facebasis'),
    ".gltf": (b'"generator": "facebasis', b'"generator":"facebasis'),
    ".glb": (b'"generator":"facebasis', b'"generator": "facebasis'),
    ".png": (b"tEXtSoftware\x00facebasis",),
    ".pdf": (b"(facebasis",),
    ".svg": (b"facebasis",),
}

#: first lines of the CSV tables facebasis writes (registered by their writers)
CSV_HEADERS: set[bytes] = set()


def written_by_facebasis(path: str | os.PathLike) -> bool:
    """Whether the existing file ``path`` carries the signature facebasis writes into its format
    (so a later run may replace it). Reads at most 64 KiB (a GLB's JSON chunk: at most 16 MiB)."""
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
            if suffix == ".glb" and head[:4] == b"glTF" and len(head) >= 20:
                n = int.from_bytes(head[12:16], "little")
                if n <= 16 * 2 ** 20:
                    fh.seek(20)
                    head = fh.read(n)
    except OSError:
        return False
    if suffix == ".csv":
        first = head.split(b"\n", 1)[0].rstrip(b"\r")
        return first in CSV_HEADERS
    if suffix == ".bin":  # a .gltf's buffer: ours if the .gltf beside it is ours and names it
        gltf = path.with_suffix(".gltf")
        try:
            text = gltf.read_bytes() if gltf.is_file() and gltf.stat().st_size <= 16 * 2 ** 20 else b""
        except OSError:
            return False
        return written_by_facebasis(gltf) and f'"uri":"{path.name}"'.encode() in text.replace(b" ", b"")
    return any(sig in head for sig in _SIGNATURES.get(suffix, ()))


# ----------------------------------------------------------------------------------------------
# the rule

def _is_within(path: Path, folder: Path) -> bool:
    return path != folder and folder in path.parents


def _resolved(p) -> Path:
    return Path(os.path.abspath(os.fspath(p))).resolve()


def _describe_entries(folder: Path) -> str:
    entries = sorted(p.name for p in folder.iterdir())
    return ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")


def check_output(out, inputs: Iterable = (), *, kind: str = "folder", what: str = "--out",
                 allow: Iterable = ()) -> Path:
    """Refuse an output whose writing would change what the user owns; returns its absolute path.

    Parameters
    ----------
    out : path
        The output folder (``kind="folder"``) or file (``kind="file"``).
    inputs : iterable of paths
        Everything the command reads (``None`` entries are skipped).
    kind : {"folder", "file"}
    what : str
        How the error names the output (the option the user typed).
    allow : iterable of paths
        Inputs the output may replace (``rig --resume RUN --out RUN`` updates a run in place).

    Raises
    ------
    InputError
        Naming the output, what was expected and what was found.
    """
    if kind not in ("folder", "file"):
        raise ValueError(f"kind: expected 'folder' or 'file', found {kind!r}")
    noun = "output folder" if kind == "folder" else "output file"
    if not str(out).strip():
        raise _input_error(f"{what}: expected an {noun} path, found an empty string"
                           + (" (it would replace the current folder)" if kind == "folder" else ""))
    given = Path(os.path.abspath(os.fspath(out)))
    if os.path.islink(given):
        target = os.readlink(given)
        raise _input_error(f"{what} {out}: expected a new path or a previous facebasis {noun[7:]}, found a symbolic "
                           f"link (to {target}); name the real path instead")
    blocker = next((p for p in given.parents if os.path.lexists(p) and not p.is_dir()), None)
    if blocker is not None:
        found = (f"the symbolic link {blocker} (to {os.readlink(blocker)}), which leads to no folder (it is broken or "
                 "loops)," if os.path.islink(blocker) else f"the file {blocker}")
        raise _input_error(f"{what} {out}: expected a folder path, found {found} in it")
    resolved = given.resolve()
    cwd = Path.cwd().resolve()
    if resolved == cwd or resolved in cwd.parents:
        raise _input_error(f"{what} {out}: expected a new {noun[7:]} or a previous output, found "
                           f"{'the current folder' if resolved == cwd else 'a folder above the current one'} "
                           "(replacing it would delete everything in it)")
    allowed = {_resolved(a) for a in allow if a is not None}
    for p in inputs:
        if p is None or not str(p).strip():
            continue
        q = _resolved(p)
        if q in allowed:
            continue
        same = resolved == q or (resolved.exists() and q.exists() and _samefile(resolved, q))
        if same:
            raise _input_error(f"{what} {out}: expected an output apart from the inputs, found the input {p} itself "
                               "(writing it would destroy the input)")
        if _is_within(q, resolved):
            raise _input_error(f"{what} {out}: expected an output apart from the inputs, found a folder holding the "
                               f"input {p} (replacing it would delete the input)")
        if q.is_dir() and _is_within(resolved, q) and not _is_output(q):
            raise _input_error(f"{what} {out}: expected an output outside the input folders, found a path inside the "
                               f"input folder {p} (a command never writes into a folder of the user's files)")
    if kind == "folder":
        if resolved.exists() and not resolved.is_dir():
            raise _input_error(f"{what} {out}: expected a folder or a new path, found a file")
        if resolved.is_dir() and not (resolved / OUTPUT_MARKER).is_file() and any(resolved.iterdir()):
            raise _input_error(f"{what} {out}: expected a new or empty folder or a previous facebasis output (with its "
                               f"{OUTPUT_MARKER} file), found a folder holding {_describe_entries(resolved)}; choose "
                               "another output folder or remove this one (it would be replaced, its files deleted)")
    else:
        if resolved.is_dir():
            raise _input_error(f"{what} {out}: expected a file name, found a folder")
        if not resolved.parent.is_dir():
            raise _input_error(f"{what} {out}: expected an existing folder to write into, found no folder "
                               f"{resolved.parent}")
        if resolved.exists() and not written_by_facebasis(resolved):
            raise _input_error(f"{what} {out}: expected a new file or one facebasis wrote, found an existing file "
                               "without facebasis's signature; choose another name or remove it (it would be "
                               "overwritten)")
    return resolved


def _is_output(folder: Path) -> bool:
    """Whether ``folder`` is, or lies inside, a facebasis output folder (``demo/rig`` of a demo)."""
    return any((f / OUTPUT_MARKER).is_file() for f in (folder, *folder.parents))


def _samefile(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


# ----------------------------------------------------------------------------------------------
# run folders: a lock held for the run's life, a token, recovery after a crash

class _Run:
    """A run folder ``.NAME.facebasis-XXXX`` beside ``out``, locked for this process's run."""

    def __init__(self, out: Path):
        self.out = out
        self.dir = Path(tempfile.mkdtemp(prefix=f".{out.name}{RUN_INFIX}", dir=out.parent))
        self.token = secrets.token_hex(16)
        self._fd = os.open(self.dir / _LOCK, os.O_RDWR | os.O_CREAT, 0o600)
        fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        (self.dir / _TOKEN).write_text(f"{self.token}\n")
        _open_up(self.dir, directory=True)

    def check_owned(self) -> None:
        """Raise if the run folder was taken away (deleted or replaced by another process)."""
        try:
            ok = (self.dir / _TOKEN).read_text().strip() == self.token
        except OSError:
            ok = False
        if not ok:
            raise _input_error(f"output {self.out}: expected this run's staging folder {self.dir}, found it removed "
                               "or replaced by another process; nothing was written")

    def close(self) -> None:
        """Remove the run folder and release the lock (the lock last: until then no one recovers it)."""
        shutil.rmtree(self.dir, ignore_errors=True)
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)


def _lock_is_free(run_dir: Path) -> bool | None:
    """True if nobody holds the run folder's lock (its run is dead), False if a live run holds it,
    None if it has no lock file."""
    try:
        fd = os.open(run_dir / _LOCK, os.O_RDWR)
    except FileNotFoundError:
        return None
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return False
        raise
    finally:
        os.close(fd)
    return True


def recover(out: str | os.PathLike) -> list[str]:
    """Finish or undo what dead runs left beside ``out``; returns what was done (for messages).

    A run folder whose lock is free: if it holds ``old`` and ``out`` is missing, the kill fell
    between the two renames of a swap, and the old output is put back; if it holds ``old`` and
    ``out`` exists, the swap had completed and ``old`` is the replaced output; otherwise it holds
    at most a half-built output. The run folder is then removed. Run folders of live runs (lock
    held) are left alone.
    """
    out = Path(os.path.abspath(os.fspath(out)))
    done = []
    pattern = re.compile(re.escape(f".{out.name}{RUN_INFIX}") + r"[A-Za-z0-9_]+$")
    try:
        siblings = [p for p in out.parent.iterdir() if pattern.match(p.name) and p.is_dir() and not p.is_symlink()]
    except (FileNotFoundError, NotADirectoryError):
        return done
    for run in siblings:
        free = _lock_is_free(run)
        if free is False:
            continue
        if free is None and time.time() - run.stat().st_mtime < _LOCKLESS_GRACE_SECONDS:
            continue  # a run between its mkdir and its lock, or one that died there a moment ago
        old = run / _OLD
        with deferred_interrupts():
            if os.path.lexists(old) and not os.path.lexists(out):
                os.replace(old, out)
                done.append(f"restored the previous {out.name} that an interrupted run had moved aside")
            shutil.rmtree(run, ignore_errors=True)
    return done


def _swap_in(new: Path, out: Path, run: _Run) -> None:
    """Replace ``out`` by ``new`` (inside the run folder). A failure half-way leaves the old output
    in ``RUN/old``, which the caller's cleanup (:func:`_restore_if_moved`) or :func:`recover` puts back."""
    run.check_owned()
    if os.path.lexists(out):
        os.replace(out, run.dir / _OLD)
    os.replace(new, out)


@contextlib.contextmanager
def atomic_directory(out_dir: str | os.PathLike, inputs: Iterable = (), allow: Iterable = ()) -> Iterator[Path]:
    """Yield a fresh staging folder that replaces ``out_dir`` only if the block succeeds.

    :func:`check_output` runs first (with ``inputs``). The staging folder lives in a locked run
    folder beside ``out_dir`` (same file system, so the final rename is atomic). If the block raises
    (an interrupt included), the run folder is deleted and an existing ``out_dir`` is left
    untouched. If it succeeds, an existing ``out_dir`` is moved into the run folder, the new folder
    renamed into place, and the run folder removed, with interrupts held back for those steps; a
    SIGKILL at any point is undone or finished by :func:`recover` in the next run.
    """
    check_output(out_dir, inputs, kind="folder", what="output folder", allow=allow)
    out = Path(os.path.abspath(os.fspath(out_dir)))
    out.parent.mkdir(parents=True, exist_ok=True)
    recover(out)
    run = stage = None
    try:
        with deferred_interrupts():
            run = _Run(out)
            stage = run.dir / _NEW
            stage.mkdir()
            _open_up(stage, directory=True)
            (stage / OUTPUT_MARKER).write_text("written by facebasis; a later run with this output folder replaces it\n")
            _set_active(stage, True)
        from .provenance import write_into

        write_into(stage)  # provenance.json: version, commit, libraries, command line, inputs' SHA-256 (commands only)
        yield stage
        with deferred_interrupts():
            _set_active(stage, False)
            _swap_in(stage, out, run)
            run.close()
    except BaseException:
        if run is not None:
            with deferred_interrupts():
                _set_active(stage, False)
                _restore_if_moved(run, out)
                run.close()
        raise


def _set_active(stage: Path, active: bool) -> None:
    # no lock: set.add/discard are atomic under the GIL, and a lock taken where an interrupt can land
    # between its acquire and the block that releases it would deadlock the next write
    (_ACTIVE_STAGES.add if active else _ACTIVE_STAGES.discard)(stage)


def _restore_if_moved(run: _Run, out: Path) -> None:
    old = run.dir / _OLD
    if os.path.lexists(old) and not os.path.lexists(out):
        os.replace(old, out)


def _inside_active_stage(path: Path) -> bool:
    return any(s == path.parent or s in path.parents for s in tuple(_ACTIVE_STAGES))


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the new one, never half.

    Inside a staging folder of :func:`atomic_directory` (which is atomic as a whole) the file is
    written directly. Elsewhere it is written in a locked run folder beside ``path`` and renamed
    into place; a run folder left by a killed process is removed by the next write of ``path``.
    The caller has checked the path with :func:`check_output` (the commands do, before any work, and
    refuse a missing folder there; a library caller may name a new folder, which is created).
    """
    path = Path(os.path.abspath(os.fspath(path)))
    if path.is_dir():
        raise _input_error(f"output file {path}: expected a file name, found a folder")
    if _inside_active_stage(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        return
    path.parent.mkdir(parents=True, exist_ok=True)  # a library call may name a new folder (the commands may not)
    recover(path)
    run = None
    try:
        with deferred_interrupts():
            run = _Run(path)
        new = run.dir / _NEW
        with open(new, "wb") as fh:
            fh.write(data)
        _open_up(new, directory=False)
        with deferred_interrupts():
            run.check_owned()
            os.replace(new, path)
            run.close()
    except BaseException:
        if run is not None:
            with deferred_interrupts():
                run.close()
        raise


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=False) + "\n").encode())


def register_csv_header(header: str) -> None:
    """Declare the first line of a CSV table facebasis writes (so a later run may replace it)."""
    CSV_HEADERS.add(header.encode())


__all__ = ["OUTPUT_MARKER", "check_output", "written_by_facebasis", "recover",
           "atomic_directory", "atomic_write_bytes", "atomic_write_json", "register_csv_header"]
