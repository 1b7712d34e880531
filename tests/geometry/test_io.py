"""Mesh files, rig folders and their validation errors."""

import numpy as np
import pytest
from conftest import grid_sheet

from facebasis.errors import MeshError, RigError, TopologyError
from facebasis.geometry.mesh import validate_mesh
from facebasis.geometry.meshio import read_mesh, write_mesh
from facebasis.geometry.rig import Rig, load_rig_folder, write_rig_folder


def write_obj(path, V, F, extra=""):
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in V] + ([extra] if extra else [])
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in F]
    path.write_text("\n".join(lines) + "\n")


def small_rig_folder(tmp_path, n_shapes=2):
    V, F = grid_sheet(5, 4)
    write_obj(tmp_path / "neutral.obj", V, F)
    for k in range(n_shapes):
        D = np.zeros_like(V)
        D[7, 2] = 0.1 * (k + 1)
        write_obj(tmp_path / f"shape{k}.obj", V + D, F)
    return V, F


def test_obj_round_trip_keeps_order(tmp_path):
    V, F = grid_sheet(5, 4)
    perm = np.random.default_rng(0).permutation(len(V))
    Vp = V[perm]
    inv = np.argsort(perm)
    Fp = inv[F]
    write_mesh(tmp_path / "m.obj", Vp, Fp)
    V2, F2 = read_mesh(tmp_path / "m.obj")
    assert np.allclose(V2, Vp, atol=1e-9) and np.array_equal(F2, Fp)
    write_mesh(tmp_path / "m.ply", Vp, Fp)
    V3, F3 = read_mesh(tmp_path / "m.ply")
    # binary PLY stores float32 coordinates (trimesh's writer); OBJ keeps 10 significant digits
    assert np.allclose(V3, Vp, rtol=1e-6, atol=1e-7) and np.array_equal(F3, Fp)


def test_obj_with_uvs_and_quads_keeps_vertex_order(tmp_path):
    text = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0.5
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
f 1/1 2/2 3/3 4/4
f 2/5 5/1 6/2 3/3
"""
    (tmp_path / "q.obj").write_text(text)
    V, F = read_mesh(tmp_path / "q.obj")
    assert V.shape == (6, 3) and V[5].tolist() == [2, 1, 0.5]
    # quads a b c d split into (a, b, c) and (c, d, a); trimesh lists the first halves of all
    # quads, then the second halves: the same every time
    assert F.tolist() == [[0, 1, 2], [1, 4, 5], [2, 3, 0], [5, 2, 1]]
    V2, F2 = read_mesh(tmp_path / "q.obj")
    assert np.array_equal(F2, F) and np.array_equal(V2, V)


def test_read_errors(tmp_path):
    with pytest.raises(MeshError, match=r"missing\.obj: expected a mesh file, found no such file"):
        read_mesh(tmp_path / "missing.obj")
    (tmp_path / "empty.obj").write_text("")
    with pytest.raises(MeshError, match=r"empty\.obj: expected a mesh, found an empty file"):
        read_mesh(tmp_path / "empty.obj")
    (tmp_path / "junk.ply").write_bytes(b"ply\nformat nonsense\n\x00\x01garbage")
    with pytest.raises(MeshError, match=r"junk\.ply: unreadable mesh file"):
        read_mesh(tmp_path / "junk.ply")
    (tmp_path / "m.stl").write_text("solid x")
    with pytest.raises(MeshError, match=r"expected a mesh file ending in \.obj or \.ply, found '\.stl'"):
        read_mesh(tmp_path / "m.stl")
    (tmp_path / "nofaces.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(MeshError, match=r"nofaces\.obj: expected vertices and faces, found"):
        read_mesh(tmp_path / "nofaces.obj")
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match=r"nan\.obj: expected finite coordinates, found NaN/inf at 1 vertices: 1"):
        read_mesh(tmp_path / "nan.obj")
    (tmp_path / "deg.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n")
    with pytest.raises(MeshError, match=r"deg\.obj: expected non-degenerate triangles .* found 1 zero-area or near-degenerate triangles: 0"):
        read_mesh(tmp_path / "deg.obj", check_degenerate=True)


def test_validate_mesh_errors():
    V, F = grid_sheet(4, 4)
    with pytest.raises(MeshError, match=r"m: expected vertex positions of shape \(n, 3\), found \(16, 2\)"):
        validate_mesh(V[:, :2], F, "m")
    with pytest.raises(MeshError, match=r"m: expected vertex indices in \[0, 16\), found out-of-range indices in 1 faces: 0"):
        validate_mesh(V, np.vstack([[0, 1, 16], F[1:]]), "m")
    with pytest.raises(MeshError, match=r"m: expected triangles of shape \(m, 3\), found \(18, 4\)"):
        validate_mesh(V, np.hstack([F, F[:, :1]]), "m")
    with pytest.raises(MeshError, match="m: expected three distinct vertices per triangle, found 1 faces"):
        validate_mesh(V, np.vstack([[0, 0, 1], F[1:]]), "m")
    with pytest.raises(MeshError, match="m: expected at least one triangle, found none"):
        validate_mesh(V, np.zeros((0, 3), int), "m")
    with pytest.raises(MeshError, match="m: expected integer vertex indices"):
        validate_mesh(V, F + 0.5, "m")


def test_rig_folder_loads_and_excludes(tmp_path):
    V, F = small_rig_folder(tmp_path)
    write_obj(tmp_path / "identity000.obj", V * 1.1, F)
    rig = load_rig_folder(tmp_path, exclude=["identity*"])
    assert rig.names == ("shape0", "shape1") and rig.deltas[1, 7, 2] == pytest.approx(0.2)
    rig2 = load_rig_folder(tmp_path)
    assert "identity000" in rig2.names
    (tmp_path / "._shape0.obj").write_bytes(b"\x00\x05\x16\x07 macOS resource fork")  # hidden: not a shape
    assert load_rig_folder(tmp_path, exclude=["identity*"]).names == ("shape0", "shape1")
    with pytest.raises(RigError, match=r"expected every exclude pattern to match a mesh file, found none for "
                                       r"'identiy\*' \(mesh files there: \['identity000.obj', 'neutral.obj'"):
        load_rig_folder(tmp_path, exclude=["identity*", "identiy*"])


def test_rig_folder_custom_neutral_and_write(tmp_path):
    V, F = small_rig_folder(tmp_path)
    (tmp_path / "neutral.obj").rename(tmp_path / "generic_neutral_mesh.obj")
    with pytest.raises(RigError, match="expected the neutral 'neutral.obj', found no such file"):
        load_rig_folder(tmp_path)
    rig = load_rig_folder(tmp_path, neutral="generic_neutral_mesh.obj")
    write_rig_folder(tmp_path / "out", rig)
    again = load_rig_folder(tmp_path / "out")
    assert again.names == rig.names and np.allclose(again.deltas, rig.deltas, atol=1e-9)


def test_rig_folder_errors(tmp_path):
    with pytest.raises(RigError, match="expected a folder of meshes, found no such folder"):
        load_rig_folder(tmp_path / "nope")
    V, F = small_rig_folder(tmp_path, n_shapes=0)
    with pytest.raises(RigError, match="expected blendshape meshes beside 'neutral.obj', found none"):
        load_rig_folder(tmp_path)
    V2, F2 = grid_sheet(5, 5)
    write_obj(tmp_path / "bigger.obj", V2, F2)
    with pytest.raises(TopologyError, match=r"bigger\.obj: expected 20 vertices as in .*neutral\.obj, found 25"):
        load_rig_folder(tmp_path)
    (tmp_path / "bigger.obj").unlink()
    write_obj(tmp_path / "fewer.obj", V, F[:-1])
    with pytest.raises(TopologyError, match=r"fewer\.obj: expected 24 triangles as in .*, found 23"):
        load_rig_folder(tmp_path)
    (tmp_path / "fewer.obj").unlink()
    Fs = F.copy()
    Fs[3] = Fs[3][[1, 2, 0]]
    write_obj(tmp_path / "rotated.obj", V, Fs)
    with pytest.raises(TopologyError, match=r"rotated\.obj: expected the same faces as .*found 1 differing faces: 3"):
        load_rig_folder(tmp_path)
    (tmp_path / "rotated.obj").unlink()
    (tmp_path / "broken.obj").write_text("")
    with pytest.raises(MeshError, match=r"broken\.obj: expected a mesh, found an empty file"):
        load_rig_folder(tmp_path)


def test_rig_object_errors():
    V, F = grid_sheet(4, 4)
    with pytest.raises(TopologyError, match=r"expected deltas of shape \(k, 16, 3\), found \(2, 15, 3\)"):
        Rig(V, F, ("a", "b"), np.zeros((2, 15, 3)))
    with pytest.raises(RigError, match="expected 2 shape names, found 1"):
        Rig(V, F, ("a",), np.zeros((2, 16, 3)))
    with pytest.raises(RigError, match=r"expected unique shape names, found duplicates \['a'\]"):
        Rig(V, F, ("a", "a"), np.zeros((2, 16, 3)))
    D = np.zeros((1, 16, 3))
    D[0, 2, 2] = np.inf
    with pytest.raises(RigError, match="shape 'a' has NaN/inf deltas"):
        Rig(V, F, ("a",), D)
    rig = Rig(V, F, ("a", "b"), np.zeros((2, 16, 3)))
    with pytest.raises(RigError, match=r"weights: expected 2 per expression, found 3"):
        rig.evaluate(np.zeros(3))


def test_a_folder_named_like_a_mesh_is_called_a_folder(tmp_path):
    (tmp_path / "scan.obj").mkdir()
    with pytest.raises(MeshError, match=r"scan.obj: expected a mesh file, found a folder"):
        read_mesh(tmp_path / "scan.obj")
