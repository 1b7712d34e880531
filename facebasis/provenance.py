"""Provenance of an output folder: what made it, from what, so a figure or a rig can be traced back.

Every output folder a command writes holds ``provenance.json`` (:data:`PROVENANCE_FILE`):

* the package version and, when run from a git checkout, its commit (and whether the tree had
  uncommitted changes);
* Python's and the key libraries' versions (numpy, scipy, casadi, trimesh, matplotlib, opencv, av);
* the command line as typed (``argv``) and the working folder;
* every input file with its size and SHA-256 (a folder input: each file inside it, sorted), so a
  changed byte in any input changes the record.

The command line sets the run's context (:func:`run_context`) before any work;
:func:`facebasis.atomic.atomic_directory` writes the record into every folder it stages while that
context is active. Library calls outside a command write none.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Iterator

#: the file name of the record inside an output folder
PROVENANCE_FILE = "provenance.json"
#: libraries whose versions are recorded (import name -> distribution name)
LIBRARIES = {"numpy": "numpy", "scipy": "scipy", "casadi": "casadi", "trimesh": "trimesh",
             "matplotlib": "matplotlib", "cv2": "opencv-python-headless", "av": "av"}

_CONTEXT: dict | None = None


@contextlib.contextmanager
def run_context(argv, inputs) -> Iterator[None]:
    """Within the block, every staged output folder records ``argv`` and the ``inputs`` (paths)."""
    global _CONTEXT
    previous, _CONTEXT = _CONTEXT, {"argv": [str(a) for a in argv], "inputs": [str(p) for p in inputs]}
    try:
        yield
    finally:
        _CONTEXT = previous


def active() -> bool:
    """Whether a command's context is set (its output folders get a record)."""
    return _CONTEXT is not None


def sha256_file(path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


def input_records(paths) -> list[dict]:
    """``[{"path", "bytes", "sha256"}, ...]`` of the files named (a folder: every file in it, sorted;
    hidden files and staging folders are skipped; a path that is not there is recorded as missing)."""
    out = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            files = sorted(f for f in p.rglob("*") if f.is_file()
                           and not any(part.startswith(".") for part in f.relative_to(p).parts))
        else:
            files = [p]
        for f in files:
            try:
                out.append({"path": str(f), "bytes": f.stat().st_size, "sha256": sha256_file(f)})
            except OSError as exc:
                out.append({"path": str(f), "missing": exc.strerror or type(exc).__name__})
    return out


def _git(*args) -> str | None:
    root = Path(__file__).resolve().parents[1]
    if not (root / ".git").exists():
        return None
    try:
        res = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() if res.returncode == 0 else None


def library_versions() -> dict:
    from importlib import metadata

    found = {}
    for mod, dist in LIBRARIES.items():
        try:
            found[mod] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            found[mod] = None
    return found


def record(inputs=(), argv=None) -> dict:
    """The provenance record (a JSON-ready dict) for ``inputs`` and ``argv``."""
    from ._version import __version__

    commit = _git("rev-parse", "HEAD")
    dirty = _git("status", "--porcelain", "--untracked-files=no") if commit else None
    return {"format": "facebasis.provenance/1", "package": "facebasis", "version": __version__,
            "git_commit": commit, "git_dirty": bool(dirty) if commit else None,
            "python": platform.python_version(), "platform": platform.platform(), "libraries": library_versions(),
            "argv": list(argv if argv is not None else sys.argv), "cwd": os.getcwd(),
            "inputs": input_records(inputs)}


def write_into(folder) -> None:
    """Write the active context's record into ``folder`` (a staging folder); nothing without one."""
    if _CONTEXT is None:
        return
    import json

    text = json.dumps(record(_CONTEXT["inputs"], _CONTEXT["argv"]), indent=1) + "\n"
    (Path(folder) / PROVENANCE_FILE).write_text(text)


__all__ = ["PROVENANCE_FILE", "run_context", "record", "input_records", "write_into", "active"]
