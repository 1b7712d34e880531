"""The vectorised OBJ reader and writer against trimesh and against files written by hand."""

import io

import numpy as np
import pytest
import trimesh

from facebasis.defaults.face import default_template
from facebasis.errors import MeshError
from facebasis.geometry.meshio import read_mesh
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
