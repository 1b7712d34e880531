"""Wavefront OBJ as artists and scanners write it, read and written in a few vectorised passes.

Reading keeps the file's own vertex order whatever else the file holds: groups and objects
(``g``/``o``), materials (``usemtl``/``mtllib``), smoothing groups, texture coordinates and normals
(``vt``/``vn``, and ``f v/vt/vn`` references), comments, blank lines, CRLF line ends, extra vertex
columns (``v x y z w`` or colours ``v x y z r g b``: the first three are the position), negative
(relative) indices, quads and n-gons. trimesh splits such a file by material and renumbers its
vertices (ICT-FaceKit's own ``generic_neutral_mesh.obj``: 26,719 vertices in the file, 257,701
after loading); this reader never does.

Polygons are split as trimesh splits them, so a mesh read here and one read through trimesh
have the same faces in the same order wherever trimesh keeps the vertices:

* a file whose faces are all triangles: as written;
* a file whose faces are all quads ``a b c d``: every ``(a, b, c)`` in file order, then every
  ``(c, d, a)``;
* any other file: polygon by polygon in file order, a quad as ``(a, b, c), (c, d, a)``, an n-gon as
  the fan ``(a, b, c), (a, c, d), ...``.

Writing produces the bytes trimesh's ``export_obj(digits=10)`` produces (``v`` lines with ten
decimals, ``f`` lines 1-based), without trimesh's per-line Python work.
No Python loop runs over lines, vertices or faces: the file is classified byte-wise with numpy and
its numbers are parsed and formatted by the exact kernels of :mod:`facebasis.geometry.numtext`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import MeshError
from .numtext import PAD, face_lines, fast_floats, fast_refs, vertex_lines

_NL, _SP, _TAB, _CR, _SLASH, _HASH = 10, 32, 9, 13, 47, 35
_V, _F, _OTHER = 1, 2, 0


def _tokens(buf: np.ndarray, line_of_byte: np.ndarray):
    """Start bytes of the whitespace-separated tokens of ``buf`` and the line each is on."""
    ws = (buf == _SP) | (buf == _TAB) | (buf == _NL)
    start = ~ws
    start[1:] &= ws[:-1]
    pos = np.flatnonzero(start)
    return pos, line_of_byte[pos]


def _parse_numbers(buf: np.ndarray, count: int, dtype, path: str, what: str, token_lines=None) -> np.ndarray:
    """Numbers of a whitespace-separated byte buffer that must hold exactly ``count`` of them;
    ``token_lines`` (count,): the file line (0-based) of each token, to name a bad one's line."""
    if count == 0:
        return np.zeros(0, dtype)
    import warnings

    text = buf.tobytes()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)  # numpy's signal of unparsed text
            vals = np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        vals = np.zeros(0, dtype)
    if len(vals) != count:  # name the first token that is not a number
        for i, token in enumerate(text.split()):
            try:
                (int if dtype is np.int64 else float)(token)
            except ValueError:
                where = f"line {int(token_lines[i]) + 1}: " if token_lines is not None and i < len(token_lines) else ""
                raise MeshError(f"{path}: {where}expected numbers in the {what} lines, found "
                                f"{token.decode(errors='replace')!r}") from None
        raise MeshError(f"{path}: expected {count} numbers in the {what} lines, found {len(vals)}")
    return vals


def read_obj(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read the vertices and triangulated faces of an OBJ file, vertex order kept.

    Parameters
    ----------
    path : an OBJ file

    Returns
    -------
    V : (n, 3) float64, the ``v`` lines in file order
    F : (m, 3) int64, 0-based, polygons split as described in the module docstring

    Raises
    ------
    MeshError
        Unreadable numbers, a vertex line with fewer than three coordinates, a face with fewer than
        three vertices, an index of 0 or one that names no vertex defined so far (OBJ indices are
        1-based; negative ones count back from the last vertex defined before the face); the
        message names the file and the line.
    """
    name = str(path)
    try:
        _sniff_text(path, name)
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise MeshError(f"{name}: expected a readable OBJ file, found {exc.strerror or exc}") from None
    _refuse_zero_byte(raw, name)  # memchr: OBJ is text; a zero byte (a binary file, a sparse file's hole, a
    # file cut by a crash) would otherwise be parsed at length into "found 0 vertices"
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise MeshError(f"{name}: expected an ASCII/UTF-8 OBJ file, found UTF-16 text (byte-order mark)")
    if raw.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte-order mark (Windows editors) is not data
        raw = raw[3:]
    if b"\r" in raw:  # CRLF line ends as LF (the fast path then still applies); a lone CR as a blank,
        raw = raw.replace(b"\r\n", b"\n")  # or as the line end of a file with no LF at all (classic Mac)
        raw = raw.replace(b"\r", b" " if b"\n" in raw else b"\n")
    fast = _read_plain(raw, name)
    if fast is not None:
        return fast
    if b"#" in raw or b"\n " in raw or b"\n\t" in raw or raw[:1] in (b" ", b"\t"):
        import re  # comments and indentation cut out (every line kept, so line numbers hold): the fast path
        raw = re.sub(rb"(?m)^[ \t]+", b"", re.sub(rb"#[^\n]*", b"", raw))  # again, not 60 bytes per byte
        fast = _read_plain(raw, name)
        if fast is not None:
            return fast
    return _read_general(raw, name)


#: bytes read from the start of an OBJ file to tell text from binary data before reading it all
SNIFF_BYTES = 1 << 16


def _refuse_zero_byte(data: bytes, name: str) -> None:
    zero = data.find(b"\0")
    if zero >= 0:
        line = data.count(b"\n", 0, zero) + 1
        raise MeshError(f"{name}: expected OBJ text, found a zero byte at byte {zero:,} (line {line}): binary "
                        "data or a damaged file")


def _sniff_text(path, name: str) -> None:
    """Refuse, before reading it, an OBJ file that cannot be text: one with a hole (a sparse file:
    its unwritten ranges read as zero bytes; found with ``SEEK_HOLE``, no data read) or a zero byte
    in its first :data:`SNIFF_BYTES` bytes (a binary file), without reading the file's data."""
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        head = fh.read(SNIFF_BYTES)
        if head.startswith((b"\xff\xfe", b"\xfe\xff")):
            raise MeshError(f"{name}: expected an ASCII/UTF-8 OBJ file, found UTF-16 text (byte-order mark)")
        _refuse_zero_byte(head, name)
        hole = size
        if hasattr(os, "SEEK_HOLE"):
            try:
                hole = os.lseek(fh.fileno(), 0, os.SEEK_HOLE)
            except OSError:  # a file system without hole reporting: the full check after reading
                hole = size
        if hole < size:
            raise MeshError(f"{name}: expected OBJ text, found a sparse file of {size:,} bytes with a hole (bytes "
                            f"never written, read as zeros) from byte {hole:,}")


def _count_tokens(buf: np.ndarray, n_lines: int) -> np.ndarray:
    """Tokens on each of the ``n_lines`` newline-terminated lines of ``buf``."""
    ws = (buf == _SP) | (buf == _TAB) | (buf == _NL)
    start = ~ws
    start[1:] &= ws[:-1]
    if n_lines == 0:
        return np.zeros(0, np.int64)
    line_starts = np.r_[0, np.flatnonzero(buf == _NL)[:-1] + 1]  # every line ends in a newline
    return np.add.reduceat(start.view(np.uint8), line_starts, dtype=np.int64)


def _read_plain(raw: bytes, name: str):
    """The common case: keywords at the start of their lines, no comment after data on a ``v`` or
    ``f`` line. Returns None for any other file (:func:`_read_general` reads it).

    The lines of each kind are cut out of the file in runs; numbers written with a fixed count of
    decimals and references separated by single spaces are parsed by :func:`~.numtext.fast_floats` and
    :func:`~.numtext.fast_refs`, anything else by ``np.fromstring``, which gives the same values."""
    if not raw.endswith(b"\n"):
        raw += b"\n"
    data = np.frombuffer(raw, np.uint8)
    nl = np.flatnonzero(data == _NL)
    starts = np.empty_like(nl)
    starts[0], starts[1:] = 0, nl[:-1] + 1
    c0 = data[starts]
    c1 = data[np.minimum(starts + 1, len(data) - 1)]
    if np.any((c0 == _SP) | (c0 == _TAB)):  # an indented line: leave it to the general reader
        return None
    sep = (c1 == _SP) | (c1 == _TAB)
    if np.any(((c0 == ord("v")) | (c0 == ord("f"))) & (c1 == _NL)):
        return None  # a bare 'v' or 'f' line: the general reader names it
    kind = np.where((c0 == ord("v")) & sep, _V, np.where((c0 == ord("f")) & sep, _F, _OTHER)).astype(np.int8)
    vtext, v_nl = _lines_of(raw, data, kind, starts, nl, _V)
    ftext, f_nl = _lines_of(raw, data, kind, starts, nl, _F)
    if b"#" in vtext or b"#" in ftext:
        return None
    fast_v = fast_floats(vtext, v_nl)
    fast_f = next((hit[1] for hit in _FACE_CACHE if hit[0] == ftext), None)
    if fast_f is None:
        fast_f = fast_refs(ftext, f_nl)
        if fast_f is not None:
            for a in fast_f:  # shared by later reads: nobody may write into them
                a.flags.writeable = False
            _FACE_CACHE[:] = [(ftext, fast_f)] + _FACE_CACHE[:3]
    if fast_v is not None:
        per_v, nums = fast_v
    else:
        vbuf = _blank_keywords(vtext, v_nl)
        per_v, nums = _count_tokens(vbuf, len(v_nl)), None
    if fast_f is not None:
        k, refs = fast_f
    else:
        fbuf = _blank_keywords(ftext, f_nl)
        if b"/" in ftext:
            import re

            fbuf = np.frombuffer(re.sub(rb"/[^\s]*", b"", fbuf.tobytes()), np.uint8)
        k, refs = _count_tokens(fbuf, len(f_nl)), None
    if (len(v_nl) and per_v.min() < 3) or (len(f_nl) and k.min() < 3):
        return None  # the general reader names the line
    try:
        if nums is None:
            nums = _parse_numbers(vbuf, int(per_v.sum()), np.float64, name, "vertex")
        if refs is None:
            refs = _parse_numbers(fbuf, int(k.sum()), np.int64, name, "face")
    except MeshError:
        return None  # the general reader names the line of the bad number
    if len(refs) and refs.min() <= 0:
        return None  # relative indices or a 0: the general reader resolves or names them
    if (per_v == 3).all():
        V = nums.reshape(-1, 3)
    else:
        V = nums[np.r_[0, np.cumsum(per_v)[:-1]][:, None] + np.arange(3)]
    idx = refs - 1
    if len(idx) and idx.max() >= len(V):
        return None
    return np.ascontiguousarray(V, dtype=np.float64), _triangulate(idx, k)


#: (bytes of the f lines, (references per line, indices)) of the last few files read: a rig's shapes
#: share their f lines, which are then parsed once
_FACE_CACHE: list = []


def _lines_of(raw: bytes, data: np.ndarray, kind: np.ndarray, starts: np.ndarray, nl: np.ndarray, k: int):
    """The lines of kind ``k`` in file order between two :data:`PAD`, and where each ends (its
    newline) in these bytes."""
    lines = np.flatnonzero(kind == k)
    if len(lines) == 0:
        return PAD + PAD, np.zeros(0, np.int64)
    cut = np.flatnonzero(np.diff(lines) != 1)
    if len(cut) < 64:  # a few runs of consecutive lines (groups, materials): slices of the file
        first = starts[np.r_[lines[0], lines[cut + 1]]].tolist()
        last = (nl[np.r_[lines[cut], lines[-1]]] + 1).tolist()
        mv = memoryview(raw)
        body = b"".join([mv[a:b] for a, b in zip(first, last)])
    else:  # lines of this kind interleaved with others
        body = data[np.repeat(kind == k, nl - starts + 1)].tobytes()
    return PAD + body + PAD, np.cumsum(nl[lines] - starts[lines] + 1) + (len(PAD) - 1)


def _blank_keywords(text: bytes, line_nl: np.ndarray) -> np.ndarray:
    """``text`` as a writable byte array with each line's one-letter keyword blanked."""
    buf = np.frombuffer(text, np.uint8).copy()
    buf[np.r_[len(PAD), line_nl[:-1] + 1]] = _SP
    return buf


def _read_general(raw: bytes, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Any OBJ: comments anywhere, indented keywords, relative indices; names a bad line."""
    data = np.frombuffer(raw, np.uint8)
    if data.size and data[-1] != _NL:
        data = np.concatenate([data, np.array([_NL], np.uint8)])
    data = data.copy()
    nl = np.flatnonzero(data == _NL)
    starts = np.r_[0, nl[:-1] + 1]
    # comments end a line's content: blank everything from '#' to the line end
    line_of_byte = np.cumsum(data == _NL) - (data == _NL)
    hashes = np.flatnonzero(data == _HASH)
    if len(hashes):
        first_hash = np.full(len(starts), np.iinfo(np.int64).max)
        np.minimum.at(first_hash, line_of_byte[hashes], hashes)
        in_comment = (np.arange(len(data)) >= first_hash[line_of_byte]) & (data != _NL)
        data[in_comment] = _SP
    # leading white space is allowed before the keyword: find each line's first non-blank byte
    blank = (data == _SP) | (data == _TAB)
    nonblank = np.flatnonzero(~blank)
    first = nonblank[np.searchsorted(nonblank, starts)] if len(nonblank) else starts
    first = np.minimum(first, nl)
    c0 = data[first]
    c1 = data[np.minimum(first + 1, len(data) - 1)]
    sep = (c1 == _SP) | (c1 == _TAB) | (c1 == _NL)
    kind = np.where((c0 == ord("v")) & sep, _V, np.where((c0 == ord("f")) & sep, _F, _OTHER))
    # the keyword itself is not data
    data[first[kind != _OTHER]] = _SP
    byte_kind = kind[line_of_byte]

    # --- vertices: every v line, first three numbers
    vmask = byte_kind == _V
    vbuf = data[vmask]
    vlines = line_of_byte[vmask]
    vpos, vtok_line = _tokens(vbuf, vlines)
    v_line_ids = np.flatnonzero(kind == _V)
    per_line = np.bincount(np.searchsorted(v_line_ids, vtok_line), minlength=len(v_line_ids))
    if len(v_line_ids) and per_line.min() < 3:
        bad = v_line_ids[np.argmin(per_line)]
        raise MeshError(f"{name}: line {bad + 1}: expected a vertex 'v x y z', found {int(per_line.min())} numbers")
    nums = _parse_numbers(vbuf, len(vpos), np.float64, name, "vertex", vtok_line)
    first_tok = np.r_[0, np.cumsum(per_line)[:-1]]
    V = nums[first_tok[:, None] + np.arange(3)] if len(v_line_ids) else np.zeros((0, 3))

    # --- faces: vertex index of every reference (the part before the first '/')
    fmask = byte_kind == _F
    fbuf = data[fmask].copy()
    flines = line_of_byte[fmask]
    fpos, ftok_line = _tokens(fbuf, flines)
    if len(fpos):
        tok_of_byte = np.cumsum(np.isin(np.arange(len(fbuf)), fpos)) - 1
        slash = fbuf == _SLASH
        after = np.cumsum(slash)
        before_tok = np.r_[0, after][fpos]  # slashes before each token's start
        in_suffix = (after - before_tok[np.maximum(tok_of_byte, 0)]) > 0
        ws = (fbuf == _SP) | (fbuf == _TAB) | (fbuf == _NL)
        fbuf[in_suffix & ~ws] = _SP
        empty_ref = fbuf[fpos] == _SP  # a reference that starts with '/': no vertex index
        if empty_ref.any():
            line = int(ftok_line[np.argmax(empty_ref)])
            raise MeshError(f"{name}: line {line + 1}: expected a vertex index in every face reference, found none")
    refs = _parse_numbers(fbuf, len(fpos), np.int64, name, "face", ftok_line)
    f_line_ids = np.flatnonzero(kind == _F)
    k = np.bincount(np.searchsorted(f_line_ids, ftok_line), minlength=len(f_line_ids))
    if len(f_line_ids) and k.min() < 3:
        bad = f_line_ids[np.argmin(k)]
        raise MeshError(f"{name}: line {bad + 1}: expected a face of at least 3 vertices, found {int(k.min())}")
    # 1-based, negative = relative to the vertices defined so far (OBJ specification)
    if (refs == 0).any():
        line = int(ftok_line[np.argmax(refs == 0)])
        raise MeshError(f"{name}: line {line + 1}: expected 1-based vertex indices, found 0")
    v_before = np.searchsorted(v_line_ids, ftok_line)  # v lines above each reference's line
    idx = np.where(refs > 0, refs - 1, v_before + refs)
    bad = (idx < 0) | (idx >= np.where(refs > 0, len(V), v_before))
    if bad.any():
        j = int(np.argmax(bad))
        r = int(refs[j])
        shown = (str(r) if abs(r) < np.iinfo(np.int64).max  # np.fromstring saturates: say what was meant
                 else "an index beyond 2^63" if r > 0 else "an index below -2^63")
        raise MeshError(f"{name}: line {int(ftok_line[j]) + 1}: expected an index of one of the "
                        f"{int(v_before[j]) if refs[j] < 0 else len(V)} vertices defined, found {shown}")
    F = _triangulate(idx, k)
    return np.ascontiguousarray(V, dtype=np.float64), F


def _triangulate(idx: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Split polygons with ``k`` (p,) corners, corners ``idx`` concatenated, as trimesh does."""
    if len(k) == 0:
        return np.zeros((0, 3), np.int64)
    if (k == 3).all():
        return idx.reshape(-1, 3).astype(np.int64)
    if (k == 4).all():
        Q = idx.reshape(-1, 4)
        return np.concatenate([Q[:, [0, 1, 2]], Q[:, [2, 3, 0]]]).astype(np.int64)
    offset = np.r_[0, np.cumsum(k)[:-1]]
    n_tri = k - 2
    poly = np.repeat(np.arange(len(k)), n_tri)
    corner = np.arange(n_tri.sum()) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri) + 1  # 1..k-2
    base = offset[poly]
    F = np.stack([idx[base], idx[base + corner], idx[base + corner + 1]], 1)
    second_of_quad = (k[poly] == 4) & (corner == 2)  # (a, c, d) -> (c, d, a)
    F[second_of_quad] = F[second_of_quad][:, [1, 2, 0]]
    return F.astype(np.int64)


def obj_bytes(V: np.ndarray, F: np.ndarray) -> bytes:
    """``V`` (n, 3) and ``F`` (m, 3) as OBJ bytes: the bytes of trimesh's ``export_obj`` with
    ``digits=10`` and no normals, colours, texture or header."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if len(F) and F.min() < 0:
        raise MeshError(f"OBJ output: expected face indices >= 0, found {int(F.min())}")
    verts = vertex_lines(V)
    if verts is None:  # a coordinate of 2048 or more, NaN or inf: Python's own formatting
        verts = (("v %.10f %.10f %.10f\n" * len(V)) % tuple(V.ravel().tolist())).encode()
    return verts + _face_block(F)


#: (face array bytes, ``f`` lines) of the last few topologies written (a rig's shapes share one)
_FACE_BLOCKS: list = []


def _face_block(F: np.ndarray) -> bytes:
    """``b"f a b c\\n" ... b"\\n"`` of ``F`` (m, 3), formatted once per distinct face array."""
    key = (F.shape, np.ascontiguousarray(F).tobytes())
    block = next((b for k, b in _FACE_BLOCKS if k == key), None)
    if block is None:
        block = face_lines(F)
        if block is None:
            block = (("f %d %d %d\n" * len(F)) % tuple((F + 1).ravel().tolist())).encode()
        block += b"\n"
        _FACE_BLOCKS[:] = [(key, block)] + _FACE_BLOCKS[:3]
    return block


__all__ = ["read_obj", "obj_bytes"]
