"""An OBJ's own layout, kept for the meshes written in its topology: ``vt``/``vn`` lines,
``mtllib``/``usemtl``, groups, smoothing groups, comments, quads and n-gons and the face order.

A transferred, generated or registered shape is written as its template was, with only the ``v``
positions replaced (:meth:`ObjLayout.obj_bytes`): every other line keeps its bytes, in place.
Where the template has ``vn`` lines they are recomputed for the new positions as area-weighted
normals *per the template's normal indexing*: every triangle of the triangulated polygons (split
as :func:`facebasis.geometry.obj.read_obj` splits them) adds its area vector
``(b - a) x (c - a)`` to the normal each of its corners names (``f v/vt/vn``), which is then
normalised; a template that splits normals at a crease (two ``vn`` for one ``v``) keeps its crease,
and a ``vn`` no face names, or one whose faces have zero area, keeps the template's value.

A *plain* OBJ (only ``v`` lines of three numbers and triangle ``f`` lines of vertex indices, besides
comments and blank lines) has no layout (:func:`read_obj_layout` returns None): its shapes are
written by :func:`facebasis.geometry.obj.obj_bytes` exactly as before.

The material library (``mtllib``) and the texture maps it names (``map_Kd``, ``map_Bump``, ...) are
*copied* beside the written meshes (:meth:`ObjLayout.side_files`) rather than referenced by a path
back to the template: the ``mtllib`` line stays byte-identical (relative to the OBJ, as the
specification reads it) and the output folder opens on its own when moved or shared. Absolute
paths and paths leaving the template's folder (``..``) are left as references.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MeshError
from .numtext import vertex_lines
from .obj import _triangulate
from .objscan import (_face_corners, _keywords, _line_text, _line_tokens, _numbers, _resolve, _runs,
                      _tokens_per_line, _v_tails)

_NL, _SP, _TAB, _HASH = 10, 32, 9, 35

#: the MTL statements whose last token is a file (textures)
_MAP_KEYS = ("map_ka", "map_kd", "map_ks", "map_ke", "map_ns", "map_d", "map_bump", "bump", "disp", "decal",
             "refl", "norm", "map_pr", "map_pm", "map_ps")


@dataclass(frozen=True)
class Material:
    """One ``newmtl`` of an MTL file: diffuse colour ``Kd`` (3,), opacity ``d`` and the diffuse
    texture ``map_Kd`` (a path as written, resolved against the MTL's folder, or None)."""

    name: str
    kd: tuple = (0.8, 0.8, 0.8)
    d: float = 1.0
    map_kd: str | None = None
    map_kd_path: Path | None = None


@dataclass(frozen=True, eq=False)
class ObjLayout:
    """What an OBJ holds besides its positions (see the module docstring).

    Attributes
    ----------
    path : the OBJ read
    raw : its bytes (line ends as LF; ``crlf``/``bom`` say how to write them back)
    v_runs, vn_runs : (r, 2) byte ranges ``[start, end)`` of consecutive ``v`` / ``vn`` lines
    v_counts, vn_counts : (r,) lines in each run
    v_tails : bytes after the third number of every ``v`` line (colours, ``w``) with their newline,
        concatenated, and their lengths (n,); None when every ``v`` line has three numbers
    n_vertices : n, ``v`` lines
    faces : (m, 3) int64 vertex indices of the triangulated polygons (as ``read_obj``)
    uv : (t, 2) float64 ``vt`` values (u, v); None without ``vt``
    face_uv : (m, 3) int64 ``vt`` index of each triangle corner (-1: none); None without ``vt``
    normals : (q, 3) float64 the template's ``vn`` values; None without ``vn``
    face_normal : (m, 3) int64 ``vn`` index of each triangle corner (-1: none); None without ``vn``
    face_material : (m,) int64 index into ``materials`` (-1: before any ``usemtl``)
    material_names : names of ``usemtl``, in order of first use
    materials : :class:`Material` per name of ``material_names`` (from the MTL files; a name no
        MTL defines gets the defaults)
    mtllibs : MTL paths as written in ``mtllib`` lines
    """

    path: Path
    raw: bytes
    v_runs: np.ndarray
    v_counts: np.ndarray
    vn_runs: np.ndarray
    vn_counts: np.ndarray
    v_tails: tuple | None
    n_vertices: int
    faces: np.ndarray
    uv: np.ndarray | None
    face_uv: np.ndarray | None
    normals: np.ndarray | None
    face_normal: np.ndarray | None
    face_material: np.ndarray
    material_names: tuple
    materials: tuple
    mtllibs: tuple
    crlf: bool = False
    bom: bool = False
    _files: list = field(default_factory=list, repr=False)

    def matches(self, n_vertices: int, faces: np.ndarray) -> bool:
        """Whether this layout is the topology of a mesh of ``n_vertices`` and ``faces`` (m, 3)."""
        F = np.asarray(faces)
        return (n_vertices == self.n_vertices and F.shape == self.faces.shape
                and bool(np.array_equal(F, self.faces)))

    # ------------------------------------------------------------------ normals
    def corner_normals(self, V: np.ndarray) -> np.ndarray:
        """Area-weighted normals (q, 3) of positions ``V`` (n, 3) per the template's ``vn`` indexing
        (module docstring); (n, 3) per vertex when the template has no ``vn``."""
        return layout_normals(V, self.faces, self.face_normal,
                              self.normals if self.normals is not None else None)

    # ------------------------------------------------------------------ writing
    def obj_bytes(self, V: np.ndarray) -> bytes:
        """The template's bytes with its ``v`` lines holding ``V`` (n, 3) (``%.10f``, as
        :func:`~facebasis.geometry.obj.obj_bytes` writes them) and its ``vn`` lines the recomputed
        normals; every other byte as the template has it."""
        V = np.asarray(V, np.float64)
        if V.shape != (self.n_vertices, 3):
            raise MeshError(f"OBJ output in the layout of {self.path}: expected ({self.n_vertices}, 3) positions, "
                            f"found {V.shape}")
        vtext = _lines(V, b"v ")
        if self.v_tails is not None:
            tails, tail_len = self.v_tails
            vtext = _retail(vtext, tails, tail_len)
        pieces = [(s, e, t) for (s, e), t in zip(self.v_runs.tolist(), _split_lines(vtext, self.v_counts))]
        if len(self.vn_runs):
            N = self.corner_normals(V)
            pieces += [(s, e, t) for (s, e), t in zip(self.vn_runs.tolist(), _split_lines(_lines(N, b"vn "),
                                                                                          self.vn_counts))]
        pieces.sort(key=lambda p: p[0])
        out, at = [], 0
        mv = memoryview(self.raw)
        for s, e, text in pieces:
            out.append(mv[at:s])
            out.append(text)
            at = e
        out.append(mv[at:])
        data = b"".join(out)
        if self.crlf:
            data = data.replace(b"\n", b"\r\n")
        return (b"\xef\xbb\xbf" if self.bom else b"") + data

    def side_files(self) -> list[tuple[str, Path]]:
        """(path relative to the OBJ's folder, source file) of the MTL files and the textures they
        name that exist and lie inside the template's folder: the files to copy beside an output."""
        return [f for f in self._files if f[1] is not None]

    def missing_files(self) -> list[str]:
        """MTL files and textures named but not found (or not copyable: absolute, outside)."""
        return [f[0] for f in self._files if f[1] is None]


def layout_normals(V, faces, face_normal=None, fallback=None, dtype=np.float64) -> np.ndarray:
    """Area-weighted normals of positions ``V`` (n, 3), or of a batch (k, n, 3), with triangles
    ``faces`` (m, 3).

    ``face_normal`` (m, 3) names the normal slot of every triangle corner (-1: none), giving
    (q, 3) normals, q = ``len(fallback)`` (slots no triangle names, or of zero area, keep
    ``fallback``); without it one normal per vertex (n, 3) (zero-area ones are (0, 0, 1)).
    A batch gives (k, q, 3). One sparse (q, m) corner-incidence product sums the triangles' area
    vectors ``(b - a) x (c - a)`` into their slots for all k at once; ``dtype`` float32 halves the
    memory traffic where the result is stored as float32 anyway (glTF)."""
    V = np.asarray(V, np.float64)
    batch = V.ndim == 3
    P = V if batch else V[None]
    F = np.asarray(faces, np.int64)
    k, m = len(P), len(F)
    if face_normal is None:
        slots, q = F.ravel(), P.shape[1]
        base = np.broadcast_to([0.0, 0.0, 1.0], (q, 3))
    else:
        slots, q = np.asarray(face_normal, np.int64).ravel(), len(fallback)
        base = np.asarray(fallback, np.float64)
    A = _incidence(slots, q, m).astype(dtype)
    Pt = np.ascontiguousarray(P.transpose(1, 0, 2), dtype=dtype)  # (n, k, 3): a corner's k shapes at once
    a = Pt[F[:, 0]]
    e1 = Pt[F[:, 1]] - a
    e2 = Pt[F[:, 2]] - a
    fn = np.empty((m, k, 3), dtype)  # (b - a) x (c - a), twice the area
    fn[..., 0] = e1[..., 1] * e2[..., 2] - e1[..., 2] * e2[..., 1]
    fn[..., 1] = e1[..., 2] * e2[..., 0] - e1[..., 0] * e2[..., 2]
    fn[..., 2] = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    N = (A @ fn.reshape(m, 3 * k)).reshape(q, k, 3).astype(np.float64)
    length = np.sqrt(np.einsum("qkc,qkc->qk", N, N))
    good = length > 0
    N /= np.where(good, length, 1.0)[..., None]
    bad = ~good
    if bad.any():
        N[bad] = np.broadcast_to(base[:, None, :], N.shape)[bad]
    out = N.transpose(1, 0, 2)
    return out if batch else out[0]


#: the last few incidence matrices built (a rig's shapes share one topology)
_INCIDENCE: list = []


def _incidence(slots: np.ndarray, q: int, m: int):
    """(q, m) sparse matrix: 1 where a corner of triangle j names slot i (corners without one: none);
    built once per topology."""
    import scipy.sparse as sp

    key = (q, m, slots.tobytes())
    hit = next((A for k, A in _INCIDENCE if k == key), None)
    if hit is None:
        tri = np.repeat(np.arange(m), 3)
        keep = slots >= 0
        hit = sp.csr_matrix((np.ones(int(keep.sum())), (slots[keep], tri[keep])), shape=(q, m))
        _INCIDENCE[:] = [(key, hit)] + _INCIDENCE[:3]
    return hit


def _lines(X: np.ndarray, key: bytes) -> bytes:
    """``key`` + ``"%.10f %.10f %.10f\\n"`` per row of ``X`` (n, 3)."""
    text = vertex_lines(X)
    if text is None:
        text = (("v %.10f %.10f %.10f\n" * len(X)) % tuple(np.asarray(X, np.float64).ravel().tolist())).encode()
    if key == b"v ":
        return text
    buf = np.frombuffer(text, np.uint8)
    starts = np.r_[0, np.flatnonzero(buf == _NL)[:-1] + 1]  # each line's 'v': the rest of the key after it
    return np.insert(buf, np.repeat(starts + 1, len(key) - 2), np.frombuffer(key[1:-1], np.uint8).tolist()
                     * len(starts)).tobytes()


def _split_lines(text: bytes, counts: np.ndarray) -> list[bytes]:
    """``text`` cut into consecutive pieces of ``counts`` lines each."""
    if len(counts) == 1:
        return [text]
    nl = np.flatnonzero(np.frombuffer(text, np.uint8) == _NL)
    ends = (nl[np.cumsum(counts) - 1] + 1).tolist()
    return [text[a:b] for a, b in zip([0] + ends[:-1], ends)]


def _retail(text: bytes, tails: bytes, tail_len: np.ndarray) -> bytes:
    """Each line of ``text`` with its newline replaced by its tail (which ends in a newline)."""
    buf = np.frombuffer(text, np.uint8)
    nl = np.flatnonzero(buf == _NL)
    head_len = np.diff(np.r_[-1, nl])  # bytes of each line with its newline
    body_len = head_len - 1
    tb = np.frombuffer(tails, np.uint8)
    out = np.empty(int(body_len.sum() + tail_len.sum()), np.uint8)
    line_start = np.r_[0, np.cumsum(body_len + tail_len)[:-1]]
    src_start = np.r_[0, nl[:-1] + 1]
    out[np.repeat(line_start - src_start, body_len) + np.flatnonzero(buf != _NL)] = buf[buf != _NL]
    tail_src = np.r_[0, np.cumsum(tail_len)[:-1]]
    out[np.repeat(line_start + body_len - tail_src, tail_len) + np.arange(len(tb))] = tb
    return out.tobytes()


# ---------------------------------------------------------------------- reading
def read_obj_layout(path: str | os.PathLike) -> ObjLayout | None:
    """The layout of an OBJ file, or None for a plain one (module docstring).

    Raises :class:`MeshError` naming the file and line for face references it cannot resolve
    (a ``vt``/``vn`` index naming no such line); the vertex indices are checked by ``read_obj``.
    """
    path = Path(path)
    if path.suffix.lower() != ".obj":
        return None
    name = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"{name}: expected a readable OBJ file, found {exc.strerror or exc}") from None
    bom = raw.startswith(b"\xef\xbb\xbf")
    if bom:
        raw = raw[3:]
    crlf = b"\r\n" in raw
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n")
        if b"\r" in raw:  # lone CRs: the positions are read right, the bytes cannot be written back alike
            return None
    if not raw.endswith(b"\n"):
        raw += b"\n"
    data = np.frombuffer(raw, np.uint8)
    nl = np.flatnonzero(data == _NL)
    starts = np.r_[0, nl[:-1] + 1]
    # each line's keyword: its first token (lines may be indented)
    blank = (data == _SP) | (data == _TAB)
    nonblank = np.flatnonzero(~blank)
    first = np.minimum(nonblank[np.searchsorted(nonblank, starts)], nl) if len(nonblank) else starts
    key = _keywords(data, first, nl)
    is_v, is_f = key == b"v", key == b"f"
    is_vt, is_vn = key == b"vt", key == b"vn"
    other = ~(is_v | is_f | is_vt | is_vn | (key == b"") | (key == b"#") | np.char.startswith(key, b"#"))
    if not (other.any() or is_vt.any() or is_vn.any()) and b"/" not in raw:
        # only v, f, comments: plain if every v line has 3 numbers and every f line 3 indices (each line's
        # token count, keyword included, from one pass over the bytes)
        ws = blank | (data == _NL)
        tok = ~ws
        tok[1:] &= ws[:-1]
        per_line = np.add.reduceat(tok.view(np.uint8), starts, dtype=np.int64)
        if (per_line[is_v | is_f] == 4).all():
            return None
    # the numbers of the v lines: three, or more (kept as a tail)
    v_tok = _line_tokens(raw, starts[is_v], nl[is_v], first[is_v])
    f_text, f_lines = _line_text(raw, starts[is_f], nl[is_f], first[is_f])
    has_slash = b"/" in f_text
    k = _tokens_per_line(f_text, f_lines)
    plain = not other.any() and not is_vt.any() and not is_vn.any() and not has_slash and (k == 3).all() \
        and (v_tok == 3).all()
    if plain:
        return None
    line_no = np.arange(len(starts))
    corners = _face_corners(f_text, len(k), name)
    v_before = np.searchsorted(line_no[is_v], line_no[is_f])  # per f line: v lines above it
    vt_before = np.searchsorted(line_no[is_vt], line_no[is_f])
    vn_before = np.searchsorted(line_no[is_vn], line_no[is_f])
    per = np.repeat(np.arange(len(k)), k)
    fline = line_no[is_f][per]
    vidx = _resolve(corners[:, 0], v_before[per], int(is_v.sum()), fline, name, "vertex", required=True)
    tidx = _resolve(corners[:, 1], vt_before[per], int(is_vt.sum()), fline, name, "texture coordinate")
    nidx = _resolve(corners[:, 2], vn_before[per], int(is_vn.sum()), fline, name, "normal")
    F = _triangulate(vidx, k)
    poly = _triangulate(np.repeat(np.arange(len(k)), k), k)[:, 0]
    uv = face_uv = normals = face_normal = None
    if is_vt.any():
        uv = _numbers(raw, starts[is_vt], nl[is_vt], first[is_vt], 2, name, "vt")
        face_uv = _triangulate(tidx, k)
    if is_vn.any():
        normals = _numbers(raw, starts[is_vn], nl[is_vn], first[is_vn], 3, name, "vn")
        face_normal = _triangulate(nidx, k)
    # materials: the last usemtl above each f line
    use = np.flatnonzero(key == b"usemtl")
    mat_text = [raw[first[i]:nl[i]].split(None, 1) for i in use]
    mat_names = [t[1].strip().decode(errors="replace") if len(t) > 1 else "" for t in mat_text]
    order = list(dict.fromkeys(mat_names))
    mat_of_line = np.array([order.index(m) for m in mat_names] or [0], np.int64)
    above = np.searchsorted(use, line_no[is_f]) - 1
    face_material = np.where(above >= 0, mat_of_line[np.maximum(above, 0)], -1)[poly] if len(use) else \
        np.full(len(F), -1, np.int64)
    libs = [raw[first[i]:nl[i]].split(None, 1)[1].strip().decode(errors="replace")
            for i in np.flatnonzero(key == b"mtllib") if len(raw[first[i]:nl[i]].split(None, 1)) > 1]
    defined, files = _read_mtls(path.parent, libs)
    materials = tuple(defined.get(m, Material(m)) for m in order)
    tails = None
    if not (v_tok == 3).all():
        tails = _v_tails(raw, starts[is_v], nl[is_v], first[is_v])
    v_runs, v_counts = _runs(is_v, starts, nl)
    vn_runs, vn_counts = _runs(is_vn, starts, nl)
    return ObjLayout(path, raw, v_runs, v_counts, vn_runs, vn_counts, tails, int(is_v.sum()), F, uv, face_uv,
                     normals, face_normal, face_material.astype(np.int64), tuple(order), materials, tuple(libs),
                     crlf, bom, files)


# ---------------------------------------------------------------------- materials
def _inside(base: Path, rel: str) -> Path | None:
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts:
        return None
    return base / p


def _read_mtls(folder: Path, libs) -> tuple[dict, list]:
    """Materials defined by the MTL files ``libs`` (relative to ``folder``) and the files to copy:
    [(relative path, source or None when missing / not copyable)]."""
    materials, files, seen = {}, [], set()

    def add(rel: str, src: Path | None):
        if rel not in seen:
            seen.add(rel)
            files.append((rel, src if src is not None and src.is_file() else None))

    for lib in libs:
        names = [lib] if (folder / lib).is_file() else lib.split()  # 'mtllib a.mtl b.mtl' or a name with blanks
        for rel in names:
            src = _inside(folder, rel)
            add(rel, src)
            if src is None or not src.is_file():
                continue
            cur = None
            for line in src.read_text(errors="replace").splitlines():
                parts = line.strip().split()
                if not parts or parts[0].startswith("#"):
                    continue
                head = parts[0].lower()
                if head == "newmtl":
                    cur = " ".join(parts[1:])
                    materials[cur] = Material(cur)
                elif cur is None:
                    continue
                elif head == "kd" and len(parts) >= 4:
                    try:
                        materials[cur] = _with(materials[cur], kd=tuple(float(x) for x in parts[1:4]))
                    except ValueError:
                        pass
                elif head in ("d", "tr") and len(parts) >= 2:
                    try:
                        a = float(parts[-1])
                        materials[cur] = _with(materials[cur], d=a if head == "d" else 1.0 - a)
                    except ValueError:
                        pass
                elif head in _MAP_KEYS and len(parts) >= 2:
                    tex = parts[-1]
                    tex_src = _inside(src.parent, tex)
                    tex_rel = str(Path(rel).parent / tex) if tex_src is not None else tex
                    add(tex_rel, tex_src)
                    if head == "map_kd":
                        materials[cur] = _with(materials[cur], map_kd=tex,
                                               map_kd_path=tex_src if tex_src is not None and tex_src.is_file()
                                               else None)
    return materials, files


def _with(m: Material, **kw) -> Material:
    import dataclasses

    return dataclasses.replace(m, **kw)


def copy_side_files(layout: ObjLayout | None, folder) -> list[str]:
    """Copy the layout's MTL files and textures into ``folder`` (atomically, one by one), at the
    paths the OBJ and MTL name them; returns the names that were missing in the template's folder."""
    if layout is None:
        return []
    from ..atomic import atomic_write_bytes

    folder = Path(folder)
    for rel, src in layout.side_files():
        dest = folder / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(dest, src.read_bytes())
    return layout.missing_files()


__all__ = ["ObjLayout", "Material", "read_obj_layout", "layout_normals", "copy_side_files"]
