"""Reading a user's JSON file with one set of error messages (shared by every method).

:func:`read_json` is the only place that opens a JSON input: a missing file, a folder, unreadable
bytes and invalid JSON each become one :class:`~facebasis.errors.InputError` that names the file,
what was expected and what was found. Checking the parsed value stays with the caller, who knows
its shape.
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

import numpy as np

from .errors import InputError


#: deepest nesting of arrays/objects accepted (facebasis files use 3 or 4 levels); deeper text is
#: refused before parsing, where Python's parser would end in a RecursionError
MAX_DEPTH = 64

#: longest run of digits accepted in a number (Python refuses to convert longer integers:
#: ``sys.get_int_max_str_digits()``, 4300 by default); checked before parsing
MAX_DIGITS = min(4300, sys.get_int_max_str_digits() or 4300) if hasattr(sys, "get_int_max_str_digits") else 4300

_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)


def check_json_text(text: str, label: str, expected: str) -> None:
    """Refuse JSON text that Python's parser cannot take in one piece, before parsing it: nesting
    deeper than :data:`MAX_DEPTH` or a number with more than :data:`MAX_DIGITS` digits.

    Strings are blanked first (a bracket or digit inside a string does not count); the depth is a
    cumulative sum over the bracket characters and the digit runs are measured with numpy
    (no Python loop over characters).

    Raises
    ------
    InputError
        ``"<label>: expected <expected>, found arrays/objects nested N levels deep ..."``.
    """
    bare = _STRING.sub('""', text)
    b = np.frombuffer(bare.encode("utf-8", "surrogatepass"), np.uint8)
    digit = np.concatenate(([False], (b >= ord("0")) & (b <= ord("9")), [False]))
    edges = np.flatnonzero(digit[1:] != digit[:-1])  # starts and ends of the runs of digits, paired
    if len(edges):
        runs = edges[1::2] - edges[::2]
        k = int(np.argmax(runs))
        if runs[k] > MAX_DIGITS:
            line = int(np.count_nonzero(b[:edges[2 * k]] == ord("\n"))) + 1
            raise InputError(f"{label}: expected {expected}, found a number of {int(runs[k])} digits on line {line} "
                             f"(at most {MAX_DIGITS} are read)")
    step = np.zeros(len(b), np.int8)
    step[(b == ord("[")) | (b == ord("{"))] = 1
    step[(b == ord("]")) | (b == ord("}"))] = -1
    nz = np.flatnonzero(step)
    if len(nz):
        deepest = int(np.cumsum(step[nz], dtype=np.int64).max())
        if deepest > MAX_DEPTH:
            raise InputError(f"{label}: expected {expected}, found arrays/objects nested {deepest} levels deep "
                             f"(at most {MAX_DEPTH} are read)")


def _first_hole(path: Path) -> int | None:
    """Offset of the first hole of a sparse file (``SEEK_HOLE``; no data read), or None."""
    if not hasattr(os, "SEEK_HOLE"):
        return None
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        try:
            hole = os.lseek(fh.fileno(), 0, os.SEEK_HOLE)
        except OSError:
            return None
    return hole if hole < size else None


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
        are not UTF-8 text, text that is not JSON, nesting deeper than :data:`MAX_DEPTH` or a number
        longer than :data:`MAX_DIGITS` digits (both checked before parsing).
    """
    path = Path(path)
    label = f"{what} {path}" if what else str(path)
    if path.is_dir():
        raise InputError(f"{label}: expected {expected}, found a folder")
    if not path.is_file():
        raise InputError(f"{label}: expected {expected}, found no such file")
    try:
        hole = _first_hole(path)
        if hole is not None:  # a sparse file: its unwritten bytes read as zeros, never JSON; refused unread
            raise InputError(f"{label}: expected {expected}, found a sparse file of {path.stat().st_size:,} bytes "
                             f"with a hole (bytes never written) from byte {hole:,}")
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

    check_json_text(text, label, expected)
    try:
        return json.loads(text.removeprefix("\ufeff"), object_pairs_hook=unique)
    except json.JSONDecodeError as exc:
        raise InputError(f"{label}: expected {expected}, found invalid JSON ({exc})") from None
    except (ValueError, RecursionError) as exc:  # what the checks above did not foresee: still one line
        raise InputError(f"{label}: expected {expected}, found JSON Python cannot read ({type(exc).__name__}: "
                         f"{str(exc)[:200]})") from None
