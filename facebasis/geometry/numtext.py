"""Decimal text to and from numpy arrays without a Python loop over numbers: the kernels of the OBJ
reader and writer (:mod:`facebasis.geometry.obj`).

Parsing reads the 8 bytes at a position of the text as one little-endian uint64 and handles its
8 characters at once ("SWAR"): one mask finds the bytes that are not digits, three
multiply-shift-mask steps give the integer the digits write. Formatting splits exact integers
into table strings of 4 bytes, padded with NUL bytes that are then dropped. Both are exact, not
approximations: the parsed floats are the correctly rounded values ``np.fromstring``/``float``
give, the written text is the text ``"%.10f" %`` and ``"%d" %`` write. Anything outside the
covered cases returns None and the caller takes the general (slower) route.
"""

from __future__ import annotations

import numpy as np

_SP, _TAB, _NL, _SLASH = 32, 9, 10, 47
#: blanks around the lines given to :func:`fast_floats` and :func:`fast_refs`, so that the 24-byte
#: windows read around a number never leave the text
PAD = b" " * 16
_U64 = np.dtype("<u8")
_TEN = 10.0 ** np.arange(17)


def _u64(*values):
    return tuple(np.uint64(v) for v in values)


_ZEROS, _HIGH, _LOW7, _PAST9, _BYTE = _u64(0x3030303030303030, 0x8080808080808080, 0x7F7F7F7F7F7F7F7F,
                                          0x7676767676767676, 0xFF)


def _words(text: bytes, pos: np.ndarray, n_words: int) -> np.ndarray:
    """The ``8 n_words`` bytes from each of ``pos`` as (n_words, len(pos)) uint64, xor ``'0'``: a
    digit becomes its value; the first byte is the lowest."""
    win = np.ndarray((len(text) - 8 * n_words + 1,), f"V{8 * n_words}", text, strides=(1,))[pos]
    t = np.ascontiguousarray(win.view(_U64).reshape(len(pos), n_words).T)
    t ^= _ZEROS
    return t


def _not_digits(t: np.ndarray) -> np.ndarray:
    """The high bit of each byte of ``t`` (from :func:`_words`) that is not a digit."""
    r = t & _LOW7
    r += _PAST9
    r |= t
    r &= _HIGH
    return r


def _byte_index(bits: np.ndarray) -> np.ndarray:
    """Index of the byte of the highest bit set in each of ``bits`` (from :func:`_not_digits`; -129
    for none). float64 keeps the exponent of the highest bit: the bits below it are 8 apart."""
    e = bits.astype(np.float64).view(_U64)
    e >>= np.uint64(52)
    e = e.view(np.int64)
    e -= 1030
    e >>= 3
    return e


def _byte(t: np.ndarray, index: np.ndarray) -> np.ndarray:
    return (t >> (np.uint64(8) * index.astype(np.uint64))) & _BYTE


def _digits8(t: np.ndarray) -> np.ndarray:
    """The integers written by the 8 digit values (0..9, the first one the most significant, in the
    lowest byte) of each uint64."""
    t = t.copy()
    for mul, shift, mask in ((10, 8, 0x00FF00FF00FF00FF), (100, 16, 0x0000FFFF0000FFFF), (10000, 32, 0xFFFFFFFF)):
        low = t >> np.uint64(shift)
        t *= np.uint64(mul)
        t += low
        t &= np.uint64(mask)
    return t


def per_line(pos: np.ndarray, line_nl: np.ndarray) -> np.ndarray:
    """How many of the sorted positions ``pos`` fall on each line (lines end at ``line_nl``)."""
    n = len(line_nl)
    if len(pos) == 3 * n and n and (pos[2::3] < line_nl).all() and (pos[3::3] > line_nl[:-1]).all():
        return np.full(n, 3)
    return np.diff(np.searchsorted(pos, line_nl), prepend=0)


def fast_floats(text: bytes, line_nl: np.ndarray):
    """The numbers of lines ``keyword x y z ...`` (one-letter keyword at each line start, lines
    ending at ``line_nl``, :data:`PAD` around them) if every number is written ``[-]digits.digits``
    with at most 7 characters before the point, the decimals (at most 15) of the first number and
    at most 15 or 16 digits (the integer they write <= 2**53), and nothing else is on the lines;
    else None.

    Returns (numbers on each line, values (count,) float64), the values ``np.fromstring`` gives:
    the digits without the point form an integer m <= 2**53, exact in float64, and
    m / 10**decimals is one correctly rounded division of exact numbers, i.e. the correctly
    rounded decimal."""
    buf = np.frombuffer(text, np.uint8)
    dots = np.flatnonzero(buf == ord("."))
    n = len(dots)
    if n == 0:
        return None
    D = int(np.argmax(buf[dots[0] + 1:dots[0] + 17] - np.uint8(48) > 9))  # decimals of the first number
    post = buf[dots + (D + 1)]
    if not ((post == _SP) | (post == _TAB) | (post == _NL)).all():
        return None
    t0, t1, t2 = _words(text, dots - 8, 3)  # 8 bytes before the point; the point and 15 bytes after
    h = _byte_index(_not_digits(t0))  # the byte before the integer digits, which end at byte 7
    if h.min() < 0:
        return None  # 8 digits or more before the point
    neg = _byte(t0, h) == ord("-") ^ 48
    at = h - neg  # the blank before the number
    if at.min() < 0:
        return None
    pre = _byte(t0, at)
    nint = 7 - h
    blanks = np.count_nonzero(buf == _SP) + np.count_nonzero(buf == _TAB) + len(line_nl)
    if ((D == 0 and nint.min() == 0) or not ((pre == _SP ^ 48) | (pre == _TAB ^ 48)).all()
            or len(buf) - blanks != len(line_nl) + int(nint.sum() + neg.sum()) + n * (D + 1)):
        return None  # "." alone; or a byte that is neither blank, nor a keyword, nor in a number
    whole = _digits8(t0 & ~((np.uint64(2) << (np.uint64(8) * h.astype(np.uint64) + np.uint64(7))) - np.uint64(1)))
    first = ((t1 >> np.uint64(8)) | (t2 << np.uint64(56))) & np.uint64((1 << 8 * min(8, D)) - 1)
    second = (t2 >> np.uint64(8)) & np.uint64((1 << 8 * max(0, D - 8)) - 1)
    if (_not_digits(first) | _not_digits(second)).any() or whole.max() > 2**53 // 10**D:
        return None
    m = whole * np.uint64(10**D) + (_digits8(first) * np.uint64(10**8) + _digits8(second)) // np.uint64(10 ** (16 - D))
    if m.max() > 2**53:
        return None
    vals = m.astype(np.float64) / _TEN[D]
    return per_line(dots, line_nl), np.where(neg, -vals, vals)


def fast_refs(text: bytes, line_nl: np.ndarray):
    """The vertex indices of ``f`` lines (as for :func:`fast_floats`) if the references are
    separated by single spaces and each is 1 to 7 digits, alone or before a ``/``; else None.
    Returns (references on each line, indices as written (count,) int64)."""
    buf = np.frombuffer(text, np.uint8)
    body = buf[len(PAD):-len(PAD)]
    if np.count_nonzero(body < 32) != len(line_nl):  # tabs, other control characters
        return None
    at = np.flatnonzero(body == _SP) + (len(PAD) + 1)  # where each reference starts
    t = _words(text, at, 1)[0]
    bad = _not_digits(t)
    L = _byte_index(bad & (np.uint64(0) - bad))  # leading digits: the first byte that is not one
    if len(at) and L.min() < 1:
        return None
    stop = _byte(t, L)
    if not ((stop == _SP ^ 48) | (stop == _NL ^ 48) | (stop == _SLASH ^ 48)).all():
        return None
    return per_line(at, line_nl), _digits8(t << (np.uint64(64) - np.uint64(8) * L.astype(np.uint64))).astype(np.int64)


def _words4(strings) -> np.ndarray:
    """Strings of at most 4 ASCII characters as little-endian uint32, padded with NUL bytes."""
    return np.frombuffer(b"".join(s.encode().ljust(4, b"\0") for s in strings), "<u4").copy()


def _digit_chars(count: int, width: int) -> np.ndarray:
    """(count, width) uint8: the digits of 0 .. count - 1, zero-padded to ``width``."""
    return (np.arange(count)[:, None] // 10 ** np.arange(width - 1, -1, -1) % 10 + 48).astype(np.uint8)


def _table(chars: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(chars, dtype=np.uint8).view("<u4").ravel()


_D4, _D3 = _digit_chars(10000, 4), _digit_chars(1000, 3)
_DIG4 = _table(_D4)  # "0000" .. "9999"
#: "\0\0\0" "7", "\0" "123", ...: NUL for leading zeros
_INT4 = _table(np.where((np.arange(10000)[:, None] < 10 ** np.arange(3, -1, -1)) & (np.arange(4) < 3), 0, _D4))
_DOT3 = _table(np.concatenate([np.full((1000, 1), ord(".")), _D3], 1))  # ".000" .. ".999"
_DIG3 = _table(np.concatenate([_D3, np.zeros((1000, 1), np.uint8)], 1))  # "000\0" .. "999\0"


def _join(words: np.ndarray) -> bytes:
    flat = words.view(np.uint8).ravel()
    return np.compress(flat != 0, flat).tobytes()


def vertex_lines(V: np.ndarray) -> bytes | None:
    """``b"v %.10f %.10f %.10f\\n"`` for each row of ``V`` (n, 3) if all |x| < 2048; else None.

    |x| = M 2**(e-53) with the integer M < 2**53 (``np.frexp``), so 2 x 10**10 = M 5**10 / 2**(42-e),
    where M 5**10 < 2**77 is held in two words; the quotient is rounded half to even, as ``%``
    rounds, and its digits come from tables."""
    n = len(V)
    x = np.ascontiguousarray(V, dtype=np.float64).ravel()
    a = np.abs(x)
    if n == 0 or x.shape != (3 * n,) or not (a < 2048).all():  # NaN and inf fail too
        return None
    mant, e = np.frexp(a)
    M = (mant * 2.0**53).astype(np.int64).view(np.uint64)
    u = np.minimum(11 - e, 63).astype(np.uint64)  # e <= 11
    B = (M & np.uint64(0xFFFFFFFF)) * np.uint64(5**10)
    H = (M >> np.uint64(32)) * np.uint64(5**10) + (B >> np.uint64(32))  # M 5**10 = H 2**32 + B mod 2**32
    G = (H << np.uint64(1)) | ((B >> np.uint64(31)) & np.uint64(1))  # M 5**10 / 2**31, truncated
    one = np.uint64(1)
    N2 = G >> u  # 2 x 10**10, truncated
    sticky = ((G & ((one << u) - one)) | (B & np.uint64(0x7FFFFFFF))) != 0
    N = N2 >> one
    N += (N2 & one).astype(bool) & (sticky | (N & one).astype(bool))
    N = N.astype(np.float64)  # < 2**45: the quotients below are exact in float64
    whole = np.floor(N / 1e10)
    frac = N - whole * 1e10
    hi = np.floor(frac / 1e7)
    rest = frac - hi * 1e7
    mid = np.floor(rest / 1e3)
    words = np.empty((n, 16), "<u4")  # per line 3 numbers of 5 words, then "\n"
    f = words[:, :15].reshape(n, 3, 5)
    f[:, :, 0] = _words4(["v ", " ", " "]) + np.signbit(x).reshape(n, 3) * np.uint32(ord("-") << 24)
    for j, (table, part) in enumerate(((_INT4, whole), (_DOT3, hi), (_DIG4, mid), (_DIG3, rest - mid * 1e3))):
        f[:, :, j + 1] = table[part.astype(np.intp)].reshape(n, 3)
    words[:, 15] = ord("\n")
    return _join(words)


def face_lines(F: np.ndarray) -> bytes | None:
    """``b"f %d %d %d\\n"`` of ``F + 1`` for ``F`` (m, 3) int64 with 0 <= F < 10**8 - 1; else None."""
    m = len(F)
    if m == 0 or F.shape != (m, 3) or F.min() < 0 or F.max() >= 10**8 - 1:
        return None
    hi, lo = np.divmod(F + 1, 10000)
    words = np.empty((m, 10), "<u4")  # per line 3 indices of 3 words, then "\n"
    f = words[:, :9].reshape(m, 3, 3)
    f[:, :, 0] = _words4(["f ", " ", " "])
    f[:, :, 1] = np.where(hi > 0, _INT4[hi], 0)
    f[:, :, 2] = np.where(hi > 0, _DIG4[lo], _INT4[lo])
    words[:, 9] = ord("\n")
    return _join(words)
