"""The vectorised OBJ reader and writer against trimesh and against files written by hand."""

import io

import numpy as np
import pytest
import trimesh

from facebasis.defaults.face import default_template
from facebasis.errors import MeshError
from facebasis.geometry.meshio import read_mesh
from facebasis.geometry import numtext, obj
from facebasis.geometry.obj import _read_general, obj_bytes, read_obj

from conftest import bumpy_sheet, grid_sheet


def _trimesh(data: bytes):
    m = trimesh.load(io.BytesIO(data), file_type="obj", process=False, maintain_order=True, force="mesh")
    return np.asarray(m.vertices), np.asarray(m.faces)


def _trimesh_bytes(V, F) -> bytes:
    mesh = trimesh.Trimesh(vertices=V, faces=F, process=False)
    return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_color=False,
                                           include_texture=False, digits=10, header=None).encode()


def _meshes():
    t = default_template()
    yield "default face", t.neutral, t.faces
    yield "default face, shape", t.neutral + t.deltas[0], t.faces
    yield "sheet", *grid_sheet(7, 6)
    yield "bumpy sheet", *bumpy_sheet()
    rng = np.random.default_rng(3)
    V = rng.normal(size=(50, 3)) * 1e3
    yield "large coordinates", V, rng.integers(0, 50, size=(80, 3))


@pytest.mark.parametrize("name,V,F", list(_meshes()), ids=[m[0] for m in _meshes()])
def test_writer_bytes_and_reader_equal_trimesh(tmp_path, name, V, F):
    data = obj_bytes(V, F)
    assert data == _trimesh_bytes(V, F)
    path = tmp_path / "m.obj"
    path.write_bytes(data)
    V1, F1 = read_obj(path)
    V2, F2 = _trimesh(data)
    assert np.array_equal(V1, V2) and np.array_equal(F1, F2)
    assert np.array_equal(F1, F) and np.allclose(V1, V, atol=1e-10, rtol=0)


VERTS = b"".join(b"v %d.5 %d -0.25\n" % (i, (i * i) % 7) for i in range(9))
TEX = b"vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 1 0\n"

# files trimesh reads with every vertex kept: faces must match, quads split the same way
SAME_AS_TRIMESH = {
    "triangles": VERTS + b"f 1 2 3\nf 4 5 6\nf 7 8 9\n",
    "all quads": VERTS + b"f 1 2 3 4\nf 5 6 7 8\nf 9 1 2 3\n",
    "all pentagons": VERTS + b"f 1 2 3 4 5\nf 5 6 7 8 9\n",
    "mixed": VERTS + b"f 1 2 3\nf 4 5 6 7\nf 5 6 7 8 9\nf 9 1 2\n",
    "v/vt quads": VERTS + TEX + b"f 1/1 2/2 3/3 4/4\nf 5/1 6/2 7/3 8/4\nf 9/1 1/2 2/3 3/4\n",
    "v//vn": VERTS + TEX + b"f 1//1 2//1 3//2\nf 4//1 5//2 6//2\nf 7//1 8//1 9//1\n",
    "v/vt/vn mixed": VERTS + TEX + b"f 1/1/1 2/2/1 3/3/2 4/4/2\nf 5/1/1 6/2/1 7/3/1\nf 8/1/1 9/2/2 1/3/2\n",
    "comment lines, groups, smoothing": b"# made by hand\nmtllib x.mtl\no head\n" + VERTS + b"g skin\ns 1\n"
                                        b"f 1 2 3\nf 4 5 6\n# end\ns off\nf 7 8 9\n",
    "CRLF": (VERTS + b"f 1 2 3\nf 4 5 6 7\n").replace(b"\n", b"\r\n"),
}


@pytest.mark.parametrize("name", sorted(SAME_AS_TRIMESH))
def test_reader_equals_trimesh_where_trimesh_keeps_the_vertices(tmp_path, name):
    data = SAME_AS_TRIMESH[name]
    path = tmp_path / "m.obj"
    path.write_bytes(data)
    V1, F1 = read_obj(path)
    V2, F2 = _trimesh(data)
    assert len(V2) == 9 and np.array_equal(V1, V2) and np.array_equal(F1, F2)
    assert np.array_equal(read_mesh(path)[1], F1)
    V3, F3 = _read_general(data.replace(b"\r", b" "), name)  # the general path agrees with the fast one
    assert np.array_equal(V1, V3) and np.array_equal(F1, F3)


def test_artist_files_keep_the_file_order(tmp_path):
    """What trimesh gets wrong: materials (it splits and renumbers the vertices), an indented face
    (it drops it), unreferenced vertices (dropped when texture references exist), relative indices,
    comments after data, extra vertex columns (colours)."""
    data = (b"mtllib a.mtl\nv 0 0 0 1 0 0\nv 1 0 0 1 0 0\n  v 1 1 0 0 1 0\nv 0 1 0 0 0 1\n"
            b"v 5 5 5 0 0 0   # never referenced\n" + TEX +
            b"usemtl skin\nf 1/1 2/2 3/3 # lower\nusemtl lips\n\t f -2/1 -4/2 -5/3\n")
    path = tmp_path / "artist.obj"
    path.write_bytes(data)
    V, F = read_obj(path)
    assert V.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 5]]
    assert F.tolist() == [[0, 1, 2], [3, 1, 0]]
    try:  # trimesh either fails on this file or does not keep its vertices
        kept = len(_trimesh(data)[0])
    except Exception:
        kept = None
    assert kept != 5


@pytest.mark.parametrize("body,message", [
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", r"line 4: expected 1-based vertex indices, found 0"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"line 4: expected an index of one of the 3 vertices defined, found 4"),
    (b"v 0 0 0\nv 1 0 0\nf 1 2 -3\nv 0 1 0\nf 1 2 3\n", r"line 3: expected an index of one of the 2 vertices defined, found -3"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"line 4: expected a face of at least 3 vertices, found 2"),
    (b"v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", r"line 2: expected a vertex 'v x y z', found 2 numbers"),
    (b"v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n", r"expected numbers in the vertex lines, found 'zero'"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", r"expected numbers in the face lines, found 'x'"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 /3\n", r"line 4: expected a vertex index in every face reference"),
])
def test_malformed_files_name_the_line(tmp_path, body, message):
    path = tmp_path / "bad.obj"
    path.write_bytes(body)
    with pytest.raises(MeshError, match=message) as err:
        read_obj(path)
    assert "bad.obj" in str(err.value)


def test_what_trimesh_rejects_is_rejected_with_the_same_messages(tmp_path):
    empty = tmp_path / "empty.obj"
    empty.write_bytes(b"")
    with pytest.raises(MeshError, match="empty.obj: expected a mesh, found an empty file"):
        read_mesh(empty)
    points = tmp_path / "points.obj"
    points.write_bytes(b"# only points\nv 0 0 0\nv 1 0 0\n")
    with pytest.raises(MeshError, match="points.obj: expected vertices and faces, found 2 vertices and 0 faces"):
        read_mesh(points)
    with pytest.raises(MeshError, match="nothing.obj: expected a mesh file, found no such file"):
        read_mesh(tmp_path / "nothing.obj")


def test_writer_rejects_negative_indices():
    with pytest.raises(MeshError, match="expected face indices >= 0, found -1"):
        obj_bytes(np.zeros((3, 3)), np.array([[0, 1, -1]]))


def test_face_lines_are_cached_per_topology_never_reused_for_another():
    V = np.random.default_rng(0).normal(size=(6, 3))
    F1 = np.array([[0, 1, 2], [3, 4, 5]])
    F2 = np.array([[0, 1, 2], [3, 5, 4]])  # same shape, other faces
    for F in (F1, F2, F1, F2):
        assert obj_bytes(V, F) == _trimesh_bytes(V, F)


# --- the loop-free kernels (facebasis.geometry.numtext) against Python's own parsing and formatting

def _v_text(numbers, per_line=3):
    """Lines ``v a b c`` of the number strings, between the blanks the kernels expect."""
    rows = [numbers[i:i + per_line] for i in range(0, len(numbers), per_line)]
    body = "".join("v " + " ".join(r) + "\n" for r in rows).encode()
    text = numtext.PAD + body + numtext.PAD
    return text, np.flatnonzero(np.frombuffer(text, np.uint8) == 10)


@pytest.mark.parametrize("decimals", [0, 1, 6, 10, 14])
def test_fixed_decimal_numbers_are_parsed_as_float_parses_them(decimals):
    rng = np.random.default_rng(decimals)
    x = np.concatenate([rng.normal(size=300) * 10.0 ** rng.integers(-8, 7, 300), [0.0, -0.0, 9999999.5, -1e-20]])
    strings = ["%#.*f" % (decimals, v) for v in x]  # "#": "5." with no decimals
    strings = [s for s in strings if len(s.split(".")[0]) <= 7 and len(s.replace("-", "")) <= 16]
    strings = strings[:len(strings) // 3 * 3]
    per, vals = numtext.fast_floats(*_v_text(strings))
    expected = np.array([float(s) for s in strings])
    assert (per == 3).all() and np.array_equal(vals, expected)
    assert np.array_equal(np.signbit(vals), np.signbit(expected))  # "-0.000" stays negative


def test_number_forms_the_kernel_leaves_to_fromstring():
    for ok in (["5.", "-0.", "7."], ["-.5", ".2", "0.7"]):
        vals = numtext.fast_floats(*_v_text(ok))[1]
        assert np.array_equal(vals, [float(s) for s in ok]) and np.array_equal(np.signbit(vals), [s[0] == "-" for s in ok])
    for odd in (["1.5", "2.25", "3.5"],  # decimals differ from the first number's
                ["1.5", "2.5", "1e3"], ["1.5", "2.5", "3"], ["1.5", "2.5", "+3.5"], ["1.5", "2.5", "nan"],
                ["1.5", "2.5", "12345678.5"], ["1.5", "2.5", "-1234567.5"],  # 8 characters before the point
                ["1.5", "2.5", "3.5", "4.5", "5.5", "."], ["1.5", "2.5", "-"], ["1.5", "2.5", "1.2.5"],
                ["9007199254.7409930"[:13], "1.000", "2.000"], ["1.5", "2.5", "3.5x"]):
        assert numtext.fast_floats(*_v_text(odd)) is None, odd
    big = "%.9f" % 9007199.254740993  # 16 digits: more than 2**53
    assert numtext.fast_floats(*_v_text([big, big, big])) is None


def test_references_with_slashes_and_polygons():
    text = numtext.PAD + b"f 1 22 333\nf 4/1 5/2/3 6//7 7/8\nf 1234567 2 3\n" + numtext.PAD
    per, refs = numtext.fast_refs(text, np.flatnonzero(np.frombuffer(text, np.uint8) == 10))
    assert per.tolist() == [3, 4, 3] and refs.tolist() == [1, 22, 333, 4, 5, 6, 7, 1234567, 2, 3]
    for odd in (b"f 1  2 3\n", b"f 1 2 3 \n", b"f 1\t2 3\n", b"f 1 2 /3\n", b"f 1 2 x\n", b"f 1 2 -3\n",
                b"f 1 2 12345678\n", b"f 1 2 3x\n"):
        text = numtext.PAD + odd + numtext.PAD
        assert numtext.fast_refs(text, np.flatnonzero(np.frombuffer(text, np.uint8) == 10)) is None, odd


def test_vertex_lines_are_percent_10f():
    rng = np.random.default_rng(5)
    V = np.concatenate([rng.normal(size=(400, 3)) * 10.0 ** rng.integers(-12, 3, (400, 1)),
                        rng.integers(-2**21, 2**21, (300, 3)) / 2048.0,  # exact ties in the 11th decimal
                        rng.uniform(-2047.99, 2047.99, (300, 3)),
                        [[0.0, -0.0, 2047.99999999995], [5e-11, -5e-11, 1.5e-10], [5e-324, -5e-324, 1e-10]]])
    assert numtext.vertex_lines(V) == (("v %.10f %.10f %.10f\n" * len(V)) % tuple(V.ravel())).encode()
    for out_of_range in ([[2048.0, 0, 0]], [[np.nan, 0, 0]], [[0, -np.inf, 0]]):
        assert numtext.vertex_lines(np.array(out_of_range)) is None


@pytest.mark.parametrize("V", [np.array([[3000.5, -1e9, 0.25], [np.nan, 1.0, np.inf], [0.0, 1.0, 2.0]]),
                               np.random.default_rng(1).normal(size=(3, 3))])
def test_writer_falls_back_to_python_formatting(V):
    F = np.array([[0, 1, 2]])
    assert obj_bytes(V, F) == (("v %.10f %.10f %.10f\n" * 3) % tuple(V.ravel())).encode() + b"f 1 2 3\n\n"


def test_face_lines_with_large_indices():
    F = np.array([[0, 9999, 10000], [123456, 99999998, 5], [99999997, 1, 2]])
    assert numtext.face_lines(F) == (("f %d %d %d\n" * 3) % tuple((F + 1).ravel())).encode()
    assert numtext.face_lines(np.array([[0, 1, 99999999]])) is None  # 9 digits: Python formats it
    assert obj_bytes(np.zeros((3, 3)), np.array([[0, 1, 99999999]])).endswith(b"f 1 2 100000000\n\n")


def _random_obj(rng, decimals, style):
    nv = int(rng.integers(4, 40))
    V = rng.normal(size=(nv, 3)) * 10.0 ** rng.integers(-3, min(4, 13 - decimals))
    lines = ["v " + " ".join("%.*f" % (decimals, x) for x in row) for row in V]
    for _ in range(int(rng.integers(1, 30))):
        k = int(rng.choice([3, 3, 4, 5]))
        refs = rng.integers(1, nv + 1, k)
        form = {"plain": "{}", "vt": "{}/1", "vtvn": "{}/2/1", "vn": "{}//1"}[style]
        lines.append("f " + " ".join(form.format(r) for r in refs))
    if rng.random() < 0.5:
        lines.insert(int(rng.integers(0, len(lines))), "usemtl skin")
    return ("\n".join(lines) + "\n").encode()


@pytest.mark.parametrize("seed", range(40))
def test_fast_and_general_readers_agree(tmp_path, seed):
    """Random files the fast kernels take (fixed decimals, slashes, n-gons, materials): the result
    equals the general reader's, which parses with np.fromstring, and the fast kernels were used."""
    rng = np.random.default_rng(seed)
    data = _random_obj(rng, int(rng.choice([1, 2, 6, 10, 13])), ["plain", "vt", "vtvn", "vn"][seed % 4])
    path = tmp_path / "r.obj"
    path.write_bytes(data)
    obj._FACE_CACHE.clear()
    V1, F1 = read_obj(path)
    V2, F2 = _read_general(data, "r.obj")
    assert np.array_equal(V1, V2) and np.array_equal(F1, F2)
    assert np.array_equal(np.signbit(V1), np.signbit(V2))
    text, v_nl = obj._lines_of(data, *_lines_and_kinds(data), obj._V)
    assert numtext.fast_floats(text, v_nl) is not None


def _lines_and_kinds(data):
    raw = np.frombuffer(data, np.uint8)
    nl = np.flatnonzero(raw == 10)
    starts = np.r_[0, nl[:-1] + 1]
    c0, c1 = raw[starts], raw[starts + 1]
    kind = np.where((c0 == ord("v")) & (c1 == 32), obj._V, np.where((c0 == ord("f")) & (c1 == 32), obj._F, 0))
    return raw, kind.astype(np.int8), starts, nl


def test_face_cache_is_keyed_by_the_face_lines(tmp_path):
    """Shapes of one rig share their f lines (parsed once); another topology is never served the
    cached faces, and neither is a file with the same f lines but too few vertices."""
    V, F = grid_sheet(5, 4)
    F2 = F[:, [0, 2, 1]]
    a, b, c = tmp_path / "a.obj", tmp_path / "b.obj", tmp_path / "c.obj"
    a.write_bytes(obj_bytes(V, F))
    b.write_bytes(obj_bytes(V + 1.0, F))
    c.write_bytes(obj_bytes(V, F2))
    for path, (V_ref, F_ref) in ((a, (V, F)), (b, (V + 1.0, F)), (c, (V, F2)), (a, (V, F))):
        V1, F1 = read_obj(path)
        assert np.array_equal(F1, F_ref) and np.allclose(V1, V_ref, atol=1e-10, rtol=0)
    lines = obj_bytes(V, F).split(b"\n")
    short = tmp_path / "short.obj"  # the last v line dropped, the f lines of a.obj kept
    short.write_bytes(b"\n".join(lines[:len(V) - 1] + lines[len(V):]))
    with pytest.raises(MeshError, match=f"expected an index of one of the {len(V) - 1} vertices defined, found {len(V)}"):
        read_obj(short)


def test_crlf_files_read_as_their_lf_twins_on_the_fast_path(tmp_path, monkeypatch):
    """CRLF line ends give the arrays of the same file with LF, through the fast kernels (not the
    slow fallback: the f-line cache fills), and a lone CR still separates like a blank."""
    tpl = default_template()
    lf = obj_bytes(tpl.neutral, tpl.faces)
    (tmp_path / "lf.obj").write_bytes(lf)
    (tmp_path / "crlf.obj").write_bytes(lf.replace(b"\n", b"\r\n"))
    V0, F0 = read_obj(tmp_path / "lf.obj")
    monkeypatch.setattr(obj, "_FACE_CACHE", [])
    V1, F1 = read_obj(tmp_path / "crlf.obj")
    np.testing.assert_array_equal(V1, V0)
    np.testing.assert_array_equal(F1, F0)
    assert len(obj._FACE_CACHE) == 1  # fast_refs took the f lines
    (tmp_path / "cr.obj").write_bytes(b"v 0 0 0\rv 1 0 0\n v 0 1 0\nf 1 2 3\n".replace(b"\rv 1", b"\nv\r1"))
    V2, F2 = read_obj(tmp_path / "cr.obj")
    np.testing.assert_array_equal(V2, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_cached_face_arrays_cannot_be_written(tmp_path, monkeypatch):
    tpl = default_template()
    (tmp_path / "a.obj").write_bytes(obj_bytes(tpl.neutral, tpl.faces))
    monkeypatch.setattr(obj, "_FACE_CACHE", [])
    _, F = read_obj(tmp_path / "a.obj")
    (_, (k, refs)), = obj._FACE_CACHE
    assert not k.flags.writeable and not refs.flags.writeable
    F[0] = 0  # the caller's array is its own copy
    _, F2 = read_obj(tmp_path / "a.obj")
    np.testing.assert_array_equal(F2, tpl.faces)


def test_byte_order_mark_and_cr_only_line_ends(tmp_path):
    """A UTF-8 byte-order mark (Windows editors) is not data: the first vertex stays; a file whose
    lines end in CR alone (classic Mac) reads as its LF twin; UTF-16 is named, not misread."""
    text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 9 9 9\nf 1 2 3\nf 1 3 5\n"
    (tmp_path / "lf.obj").write_bytes(text)
    (tmp_path / "bom.obj").write_bytes(b"\xef\xbb\xbf" + text)
    (tmp_path / "cr.obj").write_bytes(text.replace(b"\n", b"\r"))
    V0, F0 = read_obj(tmp_path / "lf.obj")
    for name in ("bom.obj", "cr.obj"):
        V, F = read_obj(tmp_path / name)
        np.testing.assert_array_equal(V, V0)
        np.testing.assert_array_equal(F, F0)
    (tmp_path / "u16.obj").write_bytes(text.decode().encode("utf-16"))
    with pytest.raises(MeshError, match=r"u16.obj: expected an ASCII/UTF-8 OBJ file, found UTF-16 text"):
        read_obj(tmp_path / "u16.obj")
    with pytest.raises(MeshError, match=r"expected a readable OBJ file, found"):
        read_obj(tmp_path)  # a folder


def test_a_bad_number_or_a_bare_keyword_line_is_named_by_its_line(tmp_path):
    """The fast reader leaves such files to the general one, which names the line."""
    (tmp_path / "num.obj").write_bytes(b"v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match=r"num.obj: line 2: expected numbers in the vertex lines, found 'x'"):
        read_obj(tmp_path / "num.obj")
    (tmp_path / "ref.obj").write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 q\n")
    with pytest.raises(MeshError, match=r"ref.obj: line 5: expected numbers in the face lines, found 'q'"):
        read_obj(tmp_path / "ref.obj")
    (tmp_path / "bare.obj").write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv\nf 1 2 3\n")
    with pytest.raises(MeshError, match=r"bare.obj: line 4: expected a vertex 'v x y z', found 0 numbers"):
        read_obj(tmp_path / "bare.obj")


def test_an_index_too_large_for_int64_is_said_so(tmp_path):
    (tmp_path / "huge.obj").write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n")
    with pytest.raises(MeshError, match=r"line 4: expected an index of one of the 3 vertices defined, found an "
                                        r"index beyond 2\^63"):
        read_obj(tmp_path / "huge.obj")
