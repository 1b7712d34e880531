"""Reading a user's JSON file with one set of error messages (shared by every method).

:func:`read_json` is the only place that opens a JSON input: a missing file, a folder, unreadable
bytes and invalid JSON each become one :class:`~facebasis.errors.InputError` that names the file,
what was expected and what was found. Checking the parsed value stays with the caller, who knows
its shape.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .errors import InputError


def read_json(path: str | os.PathLike, expected: str, what: str | None = None):
    """Parse the JSON file ``path``.

    Parameters
    ----------
    path : the file.
    expected : what the file should hold, in words ("a JSON list of vertex indices"); used in
        every message.
    what : optional label put before the path ("landmark index file"), e.g. the option's name.

    Returns
    -------
    The parsed value (dict, list, number, ...).

    Raises
    ------
    InputError
        ``"<what> <path>: expected <expected>, found ..."`` for a missing file, a folder, bytes that
        are not UTF-8 text or text that is not JSON.
    """
    path = Path(path)
    label = f"{what} {path}" if what else str(path)
    if path.is_dir():
        raise InputError(f"{label}: expected {expected}, found a folder")
    if not path.is_file():
        raise InputError(f"{label}: expected {expected}, found no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{label}: expected {expected}, found unreadable bytes ({exc})") from None
    def unique(pairs):  # JSON allows a key twice and json.loads keeps the last: a value dropped silently
        seen = set()
        for k, _ in pairs:
            if k in seen:
                raise InputError(f"{label}: expected {expected} with each key once, found {k!r} twice in one object")
            seen.add(k)
        return dict(pairs)

    try:
        return json.loads(text.removeprefix("\ufeff"), object_pairs_hook=unique)
    except json.JSONDecodeError as exc:
        raise InputError(f"{label}: expected {expected}, found invalid JSON ({exc})") from None
