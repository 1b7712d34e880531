"""Byte-level scanning of OBJ lines for :mod:`.objlayout`: keywords, the numbers and face references
of chosen lines, ``v``-line tails and runs of consecutive lines, vectorised over lines (no Python
loop over lines or tokens); OBJ references resolved to 0-based indices with a line-numbered error.
"""

from __future__ import annotations

import numpy as np

from ..errors import MeshError
from .obj import _parse_numbers

_NL, _SP, _TAB, _SLASH = 10, 32, 9, 47


def _keywords(data, first, nl) -> np.ndarray:
    """Each line's first token (up to 8 bytes) as a bytes array."""
    win = np.zeros((len(first), 8), np.uint8)
    for j in range(8):
        at = first + j
        ok = at < nl
        win[ok, j] = data[at[ok]]
    stop = (win == _SP) | (win == _TAB)
    stop = np.cumsum(stop, axis=1) > 0
    win[stop] = 0
    return win.view("S8").ravel()


def _line_text(raw: bytes, starts, nl, first):
    """The given lines without their keyword, joined (each ends in a newline), and the line count."""
    if len(starts) == 0:
        return b"", 0
    data = np.frombuffer(raw, np.uint8)
    keep = np.zeros(len(data) + 1, np.int8)
    keep[first + 1] += 1  # from just after each keyword's first byte (one per line: no repeats) ...
    keep[nl + 1] -= 1     # ... to the newline, included
    mask = np.cumsum(keep, dtype=np.int8)[:-1] > 0
    buf = data[mask].copy()
    # the keyword's second byte ('t' of 'vt'; the keywords read here are v, f, vt, vn) is blanked
    line_start = np.r_[0, np.flatnonzero(buf == _NL)[:-1] + 1]
    c = buf[line_start]
    buf[line_start[(c != _SP) & (c != _TAB) & (c != _NL)]] = _SP
    text = buf.tobytes()
    if b"#" in text:
        import re

        text = re.sub(rb"#[^\n]*", b"", text)
    return text, len(starts)


def _tokens_per_line(text: bytes, n_lines: int) -> np.ndarray:
    if n_lines == 0:
        return np.zeros(0, np.int64)
    buf = np.frombuffer(text, np.uint8)
    ws = (buf == _SP) | (buf == _TAB) | (buf == _NL)
    start = ~ws
    start[1:] &= ws[:-1]
    line_start = np.r_[0, np.flatnonzero(buf == _NL)[:-1] + 1]  # every line ends in a newline
    return np.add.reduceat(start.view(np.uint8), line_start, dtype=np.int64)


def _line_tokens(raw: bytes, starts, nl, first) -> np.ndarray:
    text, n = _line_text(raw, starts, nl, first)
    return _tokens_per_line(text, n)


def _numbers(raw: bytes, starts, nl, first, width: int, name: str, what: str) -> np.ndarray:
    """The first ``width`` numbers of each of the given lines (a line with fewer is an error)."""
    text, n = _line_text(raw, starts, nl, first)
    per = _tokens_per_line(text, n)
    if len(per) and per.min() < width:
        line = int(starts[np.argmin(per)])
        raise MeshError(f"{name}: line {int(np.count_nonzero(np.frombuffer(raw, np.uint8)[:line] == _NL)) + 1}: "
                        f"expected '{what}' with {width} numbers, found {int(per.min())}")
    vals = _parse_numbers(np.frombuffer(text, np.uint8), int(per.sum()), np.float64, name, what)
    first_tok = np.r_[0, np.cumsum(per)[:-1]]
    return vals[first_tok[:, None] + np.arange(width)]


def _v_tails(raw: bytes, starts, nl, first):
    """The bytes after the third number of each ``v`` line, newline included, and their lengths."""
    data = np.frombuffer(raw, np.uint8)
    n = len(starts)
    ends = nl.copy()
    # the end of the third number: the fourth token start (or the newline); per line via tokens
    ws = (data == _SP) | (data == _TAB) | (data == _NL)
    tok_start = np.flatnonzero(~ws & np.r_[True, ws[:-1]])
    tok_end = np.flatnonzero(ws & np.r_[False, ~ws[:-1]])  # a blank just after a token
    # token 0 is 'v', tokens 1..3 the position: the end of token 3 of each line
    i = np.searchsorted(tok_start, first)
    cut = tok_end[np.searchsorted(tok_end, tok_start[i + 3])]
    tail_len = (ends + 1 - cut).astype(np.int64)
    keep = np.zeros(len(data) + 1, np.int8)
    keep[cut] += 1
    keep[ends + 1] -= 1
    tails = data[np.cumsum(keep, dtype=np.int8)[:-1] > 0].tobytes()
    assert len(tails) == int(tail_len.sum()) and n == len(tail_len)
    return tails, tail_len


def _face_corners(text: bytes, n_lines: int, name: str) -> np.ndarray:
    """(c, 3) int64 ``v``, ``vt``, ``vn`` references as written of every face corner (0: absent)."""
    if n_lines == 0:
        return np.zeros((0, 3), np.int64)
    text = text.replace(b"//", b"/0/")
    buf = np.frombuffer(text, np.uint8)
    ws = (buf == _SP) | (buf == _TAB) | (buf == _NL)
    start = np.flatnonzero(~ws & np.r_[True, ws[:-1]])
    slashes = np.flatnonzero(buf == _SLASH)
    per_tok = np.diff(np.searchsorted(slashes, np.r_[start, len(buf)]))
    if len(per_tok) and per_tok.max() > 2:
        raise MeshError(f"{name}: expected face references v, v/vt, v//vn or v/vt/vn, found one with "
                        f"{int(per_tok.max())} slashes")
    spaced = text.replace(b"/", b" ")
    cnt = per_tok + 1
    if len(start) + len(slashes) != len(spaced.split()):
        raise MeshError(f"{name}: expected an index on both sides of every '/' of the face references")
    nums = _parse_numbers(np.frombuffer(spaced, np.uint8), int(cnt.sum()), np.int64, name, "face")
    out = np.zeros((len(start), 3), np.int64)
    tok = np.repeat(np.arange(len(start)), cnt)
    within = np.arange(len(nums)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    out[tok, within] = nums
    return out


def _resolve(ref, before, total: int, line, name: str, what: str, required: bool = False) -> np.ndarray:
    """1-based / negative (relative) OBJ references -> 0-based indices; 0 (absent) -> -1."""
    idx = np.where(ref > 0, ref - 1, np.where(ref < 0, before + ref, -1))
    absent = ref == 0
    bad = ~absent & ((idx < 0) | (idx >= np.where(ref > 0, total, before)))
    if required and absent.any():
        bad |= absent
    if bad.any():
        j = int(np.argmax(bad))
        raise MeshError(f"{name}: line {int(line[j]) + 1}: expected a {what} index of one of the {total} "
                        f"defined, found {int(ref[j])}")
    return idx.astype(np.int64)


def _runs(mask: np.ndarray, starts, nl):
    """Byte ranges (r, 2) of the runs of consecutive lines in ``mask`` and their line counts (r,)."""
    lines = np.flatnonzero(mask)
    if len(lines) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    cut = np.flatnonzero(np.diff(lines) != 1)
    a = np.r_[lines[0], lines[cut + 1]]
    b = np.r_[lines[cut], lines[-1]]
    return np.stack([starts[a], nl[b] + 1], 1).astype(np.int64), (b - a + 1).astype(np.int64)
