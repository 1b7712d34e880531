"""The one output rule, applied to every command before any work.

Each command declares, with its parser, what it writes and what it reads (:class:`Outputs`);
:func:`check_command_outputs` runs :func:`facebasis.atomic.check_output` on every output against
every input before the command's handler is called, so no command can destroy its own inputs or
a user's files, and a bad ``--out`` is refused before minutes of work. ``tests/cli/test_outputs``
checks that every command declares itself and points every command at each of its own inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable


@dataclass(frozen=True)
class Outputs:
    """What one command writes and reads.

    Attributes
    ----------
    writes : tuple of (attribute, kind, option)
        Output paths: the ``args`` attribute, ``"folder"`` or ``"file"``, and the option's name for
        messages. An attribute that is None is skipped unless ``default`` gives its path.
    reads : tuple of str
        ``args`` attributes holding input paths (a path, a list of paths, or None).
    derived : callable, optional
        ``args -> list of paths`` the inputs name in turn (a capture's source video, a resumed
        run's recorded inputs), checked as inputs too.
    default : callable, optional
        ``(args, attribute) -> path or None``: an output's path when its option was not given.
    allow : tuple of str
        ``args`` attributes naming inputs the output may replace (``rig --resume RUN --out RUN``).
    also : callable, optional
        ``args -> [(path, kind, option), ...]``: files an output brings beside it (a ``.gltf``'s ``.bin``).
    """

    writes: tuple = ()
    reads: tuple = ()
    derived: Callable | None = None
    default: Callable | None = None
    allow: tuple = ()
    also: Callable | None = None


#: a command that writes nothing (verify, penetration)
READS_ONLY = Outputs()


def _paths(value) -> list:
    if value is None:
        return []
    if isinstance(value, (list, tuple)):
        return [v for item in value for v in _paths(item)]
    return [value]


def output_paths(args, spec: Outputs) -> list[tuple[str, str, str]]:
    """(path, kind, option) of every output of a parsed command line."""
    out = []
    for attr, kind, option in spec.writes:
        path = getattr(args, attr, None)
        if path is None and spec.default is not None:
            path = spec.default(args, attr)
        if path is None:
            continue
        out.append((path, kind, option))
    if spec.also is not None:
        out += spec.also(args)
    return out


def input_paths(args, spec: Outputs) -> list:
    """Every input path of a parsed command line (declared and derived)."""
    found = [p for attr in spec.reads for p in _paths(getattr(args, attr, None))]
    if spec.derived is not None:
        found += [p for p in spec.derived(args) if p is not None]
    return found


def check_command_outputs(args) -> None:
    """Refuse, before any work, every output of ``args`` that would change what the user owns."""
    from ..atomic import check_output
    from ..errors import InputError

    spec = getattr(args, "outputs", None)
    if spec is None:
        raise RuntimeError(f"command {getattr(args, 'command', '?')} declares no Outputs")  # a programming error
    outputs = output_paths(args, spec)
    if not outputs:
        return
    inputs = input_paths(args, spec)
    allow = [p for attr in spec.allow for p in _paths(getattr(args, attr, None))]
    seen = {}
    for path, kind, option in outputs:
        resolved = check_output(path, inputs, kind=kind, what=option, allow=allow)
        if resolved in seen:
            raise InputError(f"{option} {path}: expected an output apart from {seen[resolved]}, found the same path")
        seen[resolved] = option


# ----------------------------------------------------------------------------------------------
# inputs named by inputs

def capture_video(capture_dir) -> list:
    """The source video a capture folder records (its frames are read by the reproduction commands)."""
    import numpy as np

    track = Path(capture_dir) / "track.npz"
    if not track.is_file():
        return []  # the command's own reader says what is missing
    try:
        with np.load(track, allow_pickle=False) as data:
            return [Path(str(data["video"]))] if "video" in data.files else []
    except Exception:  # noqa: BLE001 - an unreadable track is the reader's error to report
        return []


__all__ = ["Outputs", "READS_ONLY", "check_command_outputs", "output_paths", "input_paths", "capture_video"]
