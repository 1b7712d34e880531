"""What a user opens is what they gave: OBJ outputs in the template's own layout, glTF in metres with
normals, UVs and materials, .gltf vs .glb, the head pose in retarget's animation, animate3d's
compact motion."""

import csv
import json

import numpy as np
import pytest

from conftest import facex_like_folder, facex_like_positions
from facebasis.defaults.face import default_template
from facebasis.errors import InputError
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.obj import obj_bytes, read_obj
from facebasis.geometry.objlayout import layout_normals, read_obj_layout
from facebasis.geometry.rig import load_rig_folder, write_rig_folder


def _main(argv):
    from facebasis.cli import main

    try:
        return main(argv)
    except SystemExit as exc:  # argparse's own errors
        return exc.code


@pytest.fixture(scope="module")
def facex(tmp_path_factory):
    """A FaceXModel-like folder and its transfer onto a target (the CLI, as a user runs it)."""
    root = tmp_path_factory.mktemp("facex")
    folder, V0, shapes = facex_like_folder(root / "FaceXModel")
    _, F = read_obj(folder / "generic_neutral_mesh.obj")
    target = V0 * np.array([1.06, 0.97, 1.02]) + np.array([0.0, 0.4, 0.1])
    write_mesh(root / "target.obj", target, F)  # a plain OBJ of the template's topology
    out = root / "transferred"
    assert _main(["transfer", "--template", str(folder), "--neutral", "generic_neutral_mesh.obj",
                  "--exclude", "identity*", "--target", str(root / "target.obj"), "--out", str(out)]) == 0
    return folder, out, target, shapes


def _polygon_normals(obj_text: str, V: np.ndarray, n_normals: int) -> np.ndarray:
    """Area-weighted normals per vn slot, written independently: every polygon fanned from its first
    corner, each fan triangle's area vector added to the slot its corners name."""
    N = np.zeros((n_normals, 3))
    for line in obj_text.splitlines():
        if not line.startswith("f "):
            continue
        refs = [tuple(int(x) - 1 for x in r.split("/")) for r in line.split()[1:]]
        for a, b, c in ((refs[0], refs[j], refs[j + 1]) for j in range(1, len(refs) - 1)):
            area = np.cross(V[b[0]] - V[a[0]], V[c[0]] - V[a[0]])
            for corner in (a, b, c):
                N[corner[2]] += area
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def test_transferred_obj_keeps_the_template_layout(facex):
    """Only the v (and recomputed vn) lines differ from the template: vt, usemtl, groups, smoothing,
    quads, the hexagon and the face order are the template's own lines."""
    folder, out, target, shapes = facex
    template_lines = (folder / "jawOpen.obj").read_text().splitlines()
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == \
        ["browInnerUp.obj", "face.mtl", "jawOpen.obj", "mouthSmile_L.obj", "neutral.obj", "provenance.json", "skin.png"]
    rig = load_rig_folder(out)
    for name in ("neutral", "jawOpen", "mouthSmile_L", "browInnerUp"):
        text = (out / f"{name}.obj").read_text()
        lines = text.splitlines()
        assert len(lines) == len(template_lines)
        differ = [(a, b) for a, b in zip(template_lines, lines) if a != b]
        assert differ and all(a.split()[0] == b.split()[0] and a.split()[0] in ("v", "vn") for a, b in differ)
        for key in ("vt", "usemtl", "g", "s", "mtllib", "#"):
            assert [x for x in lines if x.split()[0] == key] == [x for x in template_lines if x.split()[0] == key]
        faces = [x for x in lines if x.startswith("f ")]
        assert faces == [x for x in template_lines if x.startswith("f ")]
        assert sum(len(x.split()) == 5 for x in faces) > 50 and sum(len(x.split()) == 7 for x in faces) == 1
        V = np.array([[float(c) for c in x.split()[1:4]] for x in lines if x.startswith("v ")])
        expect = rig.neutral if name == "neutral" else rig.shape(name)
        np.testing.assert_allclose(V, expect, atol=1e-9)
        vn = np.array([[float(c) for c in x.split()[1:4]] for x in lines if x.startswith("vn ")])
        np.testing.assert_allclose(vn, _polygon_normals(text, V, len(vn)), atol=1e-9)
    np.testing.assert_allclose(rig.neutral, target, atol=1e-9)
    # the material library and its texture, copied byte for byte beside the shapes
    assert (out / "face.mtl").read_bytes() == (folder / "face.mtl").read_bytes()
    assert (out / "skin.png").read_bytes() == (folder / "skin.png").read_bytes()


def test_plain_template_writes_the_same_bytes_as_before(tmp_path):
    """A plain v/f template has no layout: its shapes are exactly obj_bytes (today's output)."""
    rig = default_template()
    write_rig_folder(tmp_path / "tpl", rig)
    assert read_obj_layout(tmp_path / "tpl" / "neutral.obj") is None
    loaded = load_rig_folder(tmp_path / "tpl")
    assert loaded.layout is None
    write_rig_folder(tmp_path / "out", loaded)
    assert (tmp_path / "out" / "neutral.obj").read_bytes() == obj_bytes(loaded.neutral, loaded.faces)
    for name in (rig.names[0], rig.names[-1]):
        assert (tmp_path / "out" / f"{name}.obj").read_bytes() == obj_bytes(loaded.shape(name), loaded.faces)
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if p.suffix != ".obj" and not p.name.startswith(".")) == []


def test_layout_keeps_vertex_colours_crlf_and_names_missing_files(tmp_path):
    text = ("mtllib gone.mtl\r\nv 0 0 0 1 0 0\r\nv 1 0 0 0 1 0\r\nv 1 1 0 0 0 1\r\nv 0 1 0.5 1 1 1\r\n"
            "usemtl red\r\nf 1 2 3 4\r\n")
    (tmp_path / "q.obj").write_bytes(text.encode())
    layout = read_obj_layout(tmp_path / "q.obj")
    assert layout is not None and layout.missing_files() == ["gone.mtl"] and layout.material_names == ("red",)
    V, F = read_obj(tmp_path / "q.obj")
    out = layout.obj_bytes(V + 1.0).decode()
    assert out.count("\r\n") == text.count("\r\n")
    lines = out.split("\r\n")
    assert lines[1] == "v 1.0000000000 1.0000000000 1.0000000000 1 0 0"
    assert lines[4] == "v 1.0000000000 2.0000000000 1.5000000000 1 1 1"
    assert [x for x in lines if not x.startswith("v ")] == [x for x in text.split("\r\n") if not x.startswith("v ")]
    with pytest.raises(Exception, match=r"expected \(4, 3\) positions"):
        layout.obj_bytes(V[:3])


def test_normals_follow_the_template_normal_indexing():
    """Two vn for one crease vertex: each side keeps its own normal (a crease survives); one vn per
    vertex gives the smooth normal."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    F = np.array([[0, 1, 2], [0, 3, 1]])  # two faces at a right angle sharing the edge 0-1
    crease = layout_normals(V, F, np.array([[0, 0, 0], [1, 1, 1]]), np.zeros((2, 3)))
    np.testing.assert_allclose(crease, [[0, 0, 1], [0, 1, 0]], atol=1e-12)
    smooth = layout_normals(V, F)
    np.testing.assert_allclose(smooth[0], np.array([0, 1, 1]) / np.sqrt(2), atol=1e-12)
    batch = layout_normals(np.stack([V, V * 2]), F)
    np.testing.assert_allclose(batch[1], smooth, atol=1e-12)


def test_layout_errors_name_the_file_and_line(tmp_path):
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n")
    with pytest.raises(Exception, match=r"bad.obj: line 5: expected a texture coordinate index of one of the 1"):
        read_obj_layout(tmp_path / "bad.obj")
    (tmp_path / "tok.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/x 3/1\n")
    with pytest.raises(Exception, match=r"tok.obj: expected numbers in the face lines, found 'x'"):
        read_obj_layout(tmp_path / "tok.obj")
    (tmp_path / "vt.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5\nf 1/1 2/1 3/1\n")
    with pytest.raises(Exception, match=r"vt.obj: line 4: expected 'vt' with 2 numbers, found 1"):
        read_obj_layout(tmp_path / "vt.obj")


# ------------------------------------------------------------------------------------- glTF
def _gltf(path):
    pygltflib = pytest.importorskip("pygltflib")
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob() if str(path).endswith(".glb") else (path.parent / g.buffers[0].uri).read_bytes()

    def acc(i):
        a = g.accessors[i]
        v = g.bufferViews[a.bufferView]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a.type]
        dtype = np.float32 if a.componentType == 5126 else np.uint32
        d = np.frombuffer(blob, dtype, a.count * width, v.byteOffset + (a.byteOffset or 0))
        return d.reshape(a.count, width) if width > 1 else d

    return g, acc


@pytest.mark.parametrize("unit,factor", [("cm", 0.01), ("m", 1.0), ("mm", 0.001)])
def test_export_units(facex, tmp_path, unit, factor):
    _, out, _, _ = facex
    argv = ["export", str(out), "--out", str(tmp_path / "r.glb")] + (["--unit", unit] if unit != "cm" else [])
    assert _main(argv) == 0
    g, acc = _gltf(tmp_path / "r.glb")
    rig = load_rig_folder(out)
    assert g.asset.extras == {"sourceUnit": unit, "metresPerSourceUnit": factor}
    prim = g.meshes[0].primitives[0]
    P = acc(prim.attributes.POSITION)
    # the glTF vertices split at the UV seam: every position is one of the rig's, scaled
    layout = rig.layout
    assert len(P) > rig.n_vertices
    heights = np.ptp(P, axis=0)
    np.testing.assert_allclose(heights, np.ptp(rig.neutral, axis=0) * factor, rtol=1e-6)
    if unit == "cm":
        assert 0.1 <= heights[1] <= 0.5  # a head 20 cm tall is 0.2 m in glTF
    # morph targets: names, deltas scaled the same way, unit normals
    assert g.meshes[0].extras["targetNames"] == list(rig.names)
    N = acc(prim.attributes.NORMAL)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-6)
    jaw = rig.index(["jawOpen"])[0]
    dP = acc(prim.targets[jaw]["POSITION"])
    assert np.abs(dP).max() == pytest.approx(np.abs(rig.deltas[jaw]).max() * factor, rel=1e-6)
    dN = acc(prim.targets[jaw]["NORMAL"])
    assert np.abs(dN).max() > 1e-3 and np.linalg.norm(N + dN, axis=1).max() == pytest.approx(1.0, abs=1e-5)
    assert layout is not None


def test_export_uvs_materials_and_texture(facex, tmp_path):
    folder, out, _, _ = facex
    assert _main(["export", str(out), "--out", str(tmp_path / "r.glb")]) == 0
    g, acc = _gltf(tmp_path / "r.glb")
    rig = load_rig_folder(out)
    layout = rig.layout
    assert [m.name for m in g.materials] == ["lips", "skin"]
    assert len(g.meshes[0].primitives) == 2
    skin = g.materials[1].pbrMetallicRoughness
    assert skin.baseColorTexture.index == 0 and g.images[0].mimeType == "image/png"
    view = g.bufferViews[g.images[0].bufferView]
    assert g.binary_blob()[view.byteOffset:view.byteOffset + view.byteLength] == (folder / "skin.png").read_bytes()
    np.testing.assert_allclose(g.materials[0].pbrMetallicRoughness.baseColorFactor, [0.7, 0.3, 0.3, 1.0])
    # TEXCOORD_0 is (u, 1 - v) of the OBJ's vt at every corner, positions those of the corner's v
    prim = g.meshes[0].primitives[0]
    P, UV = acc(prim.attributes.POSITION), acc(prim.attributes.TEXCOORD_0)
    tri = np.concatenate([acc(p.indices).reshape(-1, 3) for p in g.meshes[0].primitives])
    faces_by_material = np.concatenate([np.flatnonzero(layout.face_material == i) for i in range(2)])
    corners_v = rig.faces[faces_by_material].ravel()
    corners_vt = layout.face_uv[faces_by_material].ravel()
    np.testing.assert_allclose(P[tri.ravel()], rig.neutral[corners_v] * 0.01, atol=1e-7)
    np.testing.assert_allclose(UV[tri.ravel(), 0], layout.uv[corners_vt, 0], atol=1e-7)
    np.testing.assert_allclose(UV[tri.ravel(), 1], 1.0 - layout.uv[corners_vt, 1], atol=1e-7)


def test_gltf_and_glb_hold_the_same_data(facex, tmp_path):
    _, out, _, _ = facex
    assert _main(["export", str(out), "--out", str(tmp_path / "r.glb")]) == 0
    assert _main(["export", str(out), "--out", str(tmp_path / "r.gltf")]) == 0
    raw = (tmp_path / "r.gltf").read_bytes()
    assert raw[:4] != b"glTF" and json.loads(raw)["buffers"][0]["uri"] == "r.bin"
    assert (tmp_path / "r.bin").is_file() and (tmp_path / "skin.png").is_file()
    gb, acc_b = _gltf(tmp_path / "r.glb")
    gj, acc_j = _gltf(tmp_path / "r.gltf")
    assert gj.images[0].uri == "skin.png" and gb.images[0].uri is None
    for a, b in ((gb.meshes[0].primitives[0].attributes.POSITION, gj.meshes[0].primitives[0].attributes.POSITION),
                 (gb.meshes[0].primitives[0].targets[1]["NORMAL"], gj.meshes[0].primitives[0].targets[1]["NORMAL"])):
        assert np.array_equal(acc_b(a), acc_j(b))
    assert (tmp_path / "r.glb").read_bytes()[:4] == b"glTF"


@pytest.mark.parametrize("out,unit,match", [
    ("missing/dir/r.glb", "cm", "expected an existing folder"),
    ("r.fbx", "cm", "expected a file ending in .glb (binary glTF) or .gltf"),
    ("r", "cm", "found 'no suffix'"),
    ("r.glb", "inch", "--unit: expected one of m, cm, mm"),
    ("r.glb", "", "--unit: expected one of m, cm, mm"),
])
def test_export_bad_out_and_unit(facex, tmp_path, capsys, out, unit, match):
    _, rig_dir, _, _ = facex
    code = _main(["export", str(rig_dir), "--out", str(tmp_path / out), "--unit", unit])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1 and match in err, err
    assert not (tmp_path / "missing").exists() and list(tmp_path.iterdir()) == []


def test_export_neutral_and_exclude_like_transfer(facex, tmp_path, capsys):
    folder, _, _, _ = facex
    base = ["export", "--template", str(folder), "--neutral", "generic_neutral_mesh.obj"]
    assert _main(base + ["--out", str(tmp_path / "all.glb")]) == 0
    err = capsys.readouterr().err
    assert "look like identity modes, not expressions: identity000, identity001 (2 of 5 shapes)" in err \
        and "--exclude 'identity*'" in err, err
    g, _ = _gltf(tmp_path / "all.glb")
    assert len(g.meshes[0].extras["targetNames"]) == 5
    # repeated --exclude
    assert _main(base + ["--exclude", "identity000", "--exclude", "identity001", "--out", str(tmp_path / "x.glb")]) == 0
    assert "identity" not in capsys.readouterr().err
    g, _ = _gltf(tmp_path / "x.glb")
    assert g.meshes[0].extras["targetNames"] == ["browInnerUp", "jawOpen", "mouthSmile_L"]
    assert _main(base + ["--exclude", "nothing*", "--out", str(tmp_path / "y.glb")]) == 2
    assert "expected every --exclude pattern to match" in capsys.readouterr().err
    assert _main(["export", str(folder), "--template", str(folder), "--out", str(tmp_path / "z.glb")]) == 2
    assert _main(["export", "--out", str(tmp_path / "z.glb")]) == 2
    assert not (tmp_path / "y.glb").exists() and not (tmp_path / "z.glb").exists()


def test_exported_files_pass_the_khronos_validator(facex, tmp_path):
    from conftest import gltf_validate as _validate

    _, out, _, _ = facex
    for name in ("r.glb", "r.gltf"):
        assert _main(["export", str(out), "--out", str(tmp_path / name)]) == 0
        issues = _validate(tmp_path / name)
        assert issues["numErrors"] == 0, issues["messages"][:5]


# ------------------------------------------------------------------------- retarget's pose
@pytest.fixture(scope="module")
def retargeted(tmp_path_factory):
    from facebasis.capture.trackfile import write_capture
    from facebasis.defaults.face_landmarks import face_landmarks
    from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture

    rig = default_template()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L"), 20, seed=4)
    cap = synthetic_capture(rig, face_landmarks(), X, noise_px=0.2, seed=4, amplitude_deg=15.0)
    root = tmp_path_factory.mktemp("rt")
    write_capture(root / "capture", capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size))
    assert _main(["retarget", str(root / "capture"), "--out", str(root / "out"), "--identity", "rig"]) == 0
    assert _main(["retarget", str(root / "capture"), "--out", str(root / "nopose"), "--identity", "rig",
                  "--no-pose"]) == 0
    return root, cap


def test_animation_pose_channels_match_pose_csv(retargeted):
    from scipy.spatial.transform import Rotation

    root, cap = retargeted
    rows = list(csv.DictReader((root / "out" / "pose.csv").open()))
    T = len(rows)
    rv = np.array([[float(r[f"rot_{a}_rad"]) for a in "xyz"] for r in rows])
    t = np.array([[float(r["tx_px"]), float(r["ty_px"])] for r in rows])
    s = np.array([float(r["scale_px_per_unit"]) for r in rows])
    g, acc = _gltf(root / "out" / "animation.glb")
    (anim,) = g.animations
    paths = {c.target.path: anim.samplers[c.sampler] for c in anim.channels}
    assert set(paths) == {"weights", "rotation", "translation"}
    times = acc(paths["rotation"].input)
    np.testing.assert_allclose(times, [float(r["time_s"]) for r in rows], atol=1e-6)
    q = acc(paths["rotation"].output).astype(np.float64)
    assert q.shape == (T, 4)
    expect = Rotation.from_rotvec(rv).as_quat()
    sign = np.sign(np.sum(q * expect, axis=1))
    np.testing.assert_allclose(q, expect * sign[:, None], atol=2e-5)  # pose.csv keeps 6 decimals
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) > 0)  # consecutive keys on the same side
    tr = acc(paths["translation"].output)
    assert tr.shape == (T, 3)
    np.testing.assert_allclose(tr[:, 0], 0.01 * (t[:, 0] - t[0, 0]) / s, atol=1e-6)
    np.testing.assert_allclose(tr[:, 1], -0.01 * (t[:, 1] - t[0, 1]) / s, atol=1e-6)
    assert np.all(tr[:, 2] == 0) and np.abs(tr).max() > 1e-3  # the synthetic head moves
    # the animated rotation is the synthetic camera's, within a degree
    off = (Rotation.from_quat(q) * Rotation.from_matrix(cap.rotation).inv()).magnitude()
    assert np.degrees(off).max() < 1.0 and np.degrees(np.ptp(Rotation.from_matrix(cap.rotation).magnitude())) > 1.0
    g2, _ = _gltf(root / "nopose" / "animation.glb")
    assert [c.target.path for c in g2.animations[0].channels] == ["weights"]


def test_retarget_bad_unit_before_any_work(retargeted, tmp_path, capsys):
    root, _ = retargeted
    assert _main(["retarget", str(root / "capture"), "--out", str(tmp_path / "o"), "--unit", "ft"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "--unit" in err and "expected one of m, cm, mm" in err
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------------- compact motion
def test_compact_vertex_animation_meets_its_bound():
    from facebasis.retarget.animation import compact_vertex_animation

    rng = np.random.default_rng(0)
    rest = facex_like_positions(20, 16)
    modes = rng.normal(size=(4, len(rest), 3))
    T = 150
    coef = np.cumsum(rng.normal(size=(T, 4)), axis=0) * 0.05
    frames = rest + np.tensordot(coef, modes, axes=(1, 0)) + 1e-4 * rng.normal(size=(T, len(rest), 3))
    tol = 2e-3
    m = compact_vertex_animation(rest, frames, tol)
    assert m.rank <= 6 and m.max_error <= tol  # four real modes and noise far below the bound
    assert m.weights.min() >= 0 and m.weights.max() <= 1 and np.all(m.weights[:, 0] == 1)
    approx = rest + np.tensordot(m.weights, m.targets, axes=(1, 0))
    err = np.linalg.norm(approx - frames, axis=2).max()
    assert err == pytest.approx(m.max_error, rel=1e-6)
    # a bound no basis of the allowed size meets: the best reached is reported, honestly
    m2 = compact_vertex_animation(rest, frames, 1e-9, max_basis=3)
    assert m2.rank == 3 and m2.max_error > 1e-9
    # more frames than the exact route takes: the randomized range finder
    long = np.concatenate([frames] * 3)
    m3 = compact_vertex_animation(rest, long, tol)
    assert m3.rank <= 6 and m3.max_error <= tol
    with pytest.raises(InputError, match="expected frames"):
        compact_vertex_animation(rest, frames[:, :5], tol)


def test_animate3d_writes_a_small_basis(tmp_path):
    from facebasis.capture.trackfile import write_capture
    from facebasis.defaults.face_landmarks import face_landmarks
    from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture

    rig = default_template()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L", "browInnerUp"), 60, seed=1)
    cap = synthetic_capture(rig, face_landmarks(), X, noise_px=0.3, seed=1)
    write_capture(tmp_path / "cap", capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size))
    assert _main(["animate3d", str(tmp_path / "cap"), "--out", str(tmp_path / "a3")]) == 0
    summary = json.loads((tmp_path / "a3" / "summary.json").read_text())
    g, acc = _gltf(tmp_path / "a3" / "animation.glb")
    k = len(g.meshes[0].extras["targetNames"])
    assert k == summary["morph_targets"] == summary["animation_basis"] + 1 and k < 60
    assert summary["animation_max_vertex_error"] <= summary["animation_error_bound"] == pytest.approx(0.1)
    # the written animation reproduces frames.npz within the bound (float32 storage aside)
    with np.load(tmp_path / "a3" / "frames.npz") as d:
        frames = d["vertices"].astype(np.float64)
    prim = g.meshes[0].primitives[0]
    P = acc(prim.attributes.POSITION).astype(np.float64) / 0.01
    D = np.stack([acc(t["POSITION"]) for t in prim.targets]).astype(np.float64) / 0.01
    sampler = g.animations[0].samplers[0]
    W = acc(sampler.output).reshape(-1, k).astype(np.float64)
    approx = P + np.tensordot(W, D, axes=(1, 0))
    assert np.linalg.norm(approx - frames, axis=2).max() <= summary["animation_error_bound"] + 1e-4


def test_registered_scan_keeps_the_template_layout(tmp_path):
    """register: the registered mesh is the template's file with its v/vn lines replaced."""
    folder, V0, shapes = facex_like_folder(tmp_path / "tpl", identities=0)
    _, F = read_obj(folder / "generic_neutral_mesh.obj")
    write_mesh(tmp_path / "scan.obj", shapes["jawOpen"], F)  # a plain triangle scan
    out = tmp_path / "reg"
    assert _main(["register", str(tmp_path / "scan.obj"), "--template", str(folder / "generic_neutral_mesh.obj"),
                  "--out", str(out)]) == 0
    lines = (out / "scan.obj").read_text().splitlines()
    template = (folder / "generic_neutral_mesh.obj").read_text().splitlines()
    assert [x for x in lines if x.split()[0] not in ("v", "vn")] == \
        [x for x in template if x.split()[0] not in ("v", "vn")]
    assert (out / "face.mtl").is_file() and (out / "skin.png").read_bytes() == (folder / "skin.png").read_bytes()


def test_template_without_normals_uv_only_as_ict_ships(tmp_path):
    """ICT-FaceKit's files have ``f v/vt`` quads and no ``vn``: outputs have no vn lines either, and the
    glTF still gets area-weighted normals, UVs and validates."""
    folder, V0, shapes = facex_like_folder(tmp_path / "fx", identities=0, normals=False)
    assert _main(["export", "--template", str(folder), "--neutral", "generic_neutral_mesh.obj",
                  "--out", str(tmp_path / "r.glb")]) == 0
    g, acc = _gltf(tmp_path / "r.glb")
    prim = g.meshes[0].primitives[0]
    N = acc(prim.attributes.NORMAL)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-6)
    rig = load_rig_folder(folder, "generic_neutral_mesh.obj")
    expect = layout_normals(rig.neutral, rig.faces)  # per vertex, copied to both sides of the UV seam
    P = acc(prim.attributes.POSITION)
    v_of = np.argmin(np.linalg.norm(P[:, None] - rig.neutral[None] * 0.01, axis=2), axis=1)
    np.testing.assert_allclose(N, expect[v_of], atol=1e-5)
    assert prim.attributes.TEXCOORD_0 is not None
    layout = rig.layout
    assert layout.normals is None and layout.face_normal is None
    out = layout.obj_bytes(rig.shape("jawOpen")).decode().splitlines()
    src = (folder / "jawOpen.obj").read_text().splitlines()
    assert not any(x.startswith("vn") for x in out)
    assert [x for x in out if not x.startswith("v ")] == [x for x in src if not x.startswith("v ")]
    from conftest import gltf_validate as _validate

    assert _validate(tmp_path / "r.glb")["numErrors"] == 0


def test_generated_rig_keeps_the_template_layout(facex, tmp_path):
    """rig: the generated shapes and rig.glb carry the template's layout (UVs, materials, quads)."""
    folder, _, target, shapes = facex
    _, F = read_obj(folder / "generic_neutral_mesh.obj")
    (tmp_path / "ex").mkdir()
    V0 = read_obj(folder / "generic_neutral_mesh.obj")[0]
    write_mesh(tmp_path / "ex" / "ex0.obj", target + 1.1 * (shapes["jawOpen"] - V0), F)
    write_mesh(tmp_path / "ex" / "ex1.obj", target + 0.9 * (shapes["mouthSmile_L"] - V0), F)
    (tmp_path / "w.json").write_text(json.dumps({"ex0": {"jawOpen": 0.9}, "ex1": {"mouthSmile_L": 0.7}}))
    out = tmp_path / "run"
    assert _main(["rig", "--template", str(folder), "--neutral", "generic_neutral_mesh.obj", "--exclude", "identity*",
                  "--target", str(facex[1].parent / "target.obj"),
                  "--examples", str(tmp_path / "ex"), "--weights", str(tmp_path / "w.json"), "--iterations", "2",
                  "--out", str(out)]) == 0
    template = (folder / "jawOpen.obj").read_text().splitlines()
    lines = (out / "jawOpen.obj").read_text().splitlines()
    assert [x for x in lines if x.split()[0] not in ("v", "vn")] == \
        [x for x in template if x.split()[0] not in ("v", "vn")]
    assert (out / "skin.png").is_file()
    g, _ = _gltf(out / "rig.glb")
    assert g.meshes[0].primitives[0].attributes.TEXCOORD_0 is not None and len(g.materials) == 2


def test_animate3d_unit_and_mesh_layout(tmp_path, capsys):
    """animate3d --mesh of an OBJ with UVs keeps them in animation.glb; --unit scales to metres;
    a bad --unit is said before any work."""
    from facebasis.capture.trackfile import write_capture
    from facebasis.retarget.synthetic import capture_from_landmarks

    folder, V0, _ = facex_like_folder(tmp_path / "fx", identities=0)
    rng = np.random.default_rng(2)
    idx = rng.choice(len(V0), 12, replace=False)
    lm0 = V0[idx, :2] * [10, -10] + 300
    lm = lm0 + np.cumsum(rng.normal(0, 0.4, (10, 12, 2)), axis=0)
    lm[0] = lm0
    write_capture(tmp_path / "cap", capture_from_landmarks(lm, fps=25.0, size=(600, 600)))
    (tmp_path / "idx.json").write_text(json.dumps(idx.tolist()))
    base = ["animate3d", str(tmp_path / "cap"), "--mesh", str(folder / "generic_neutral_mesh.obj"),
            "--landmarks", str(tmp_path / "idx.json")]
    assert _main(base + ["--out", str(tmp_path / "a"), "--unit", "mm"]) == 0
    g, acc = _gltf(tmp_path / "a" / "animation.glb")
    assert g.asset.extras["sourceUnit"] == "mm" and g.meshes[0].primitives[0].attributes.TEXCOORD_0 is not None
    P = acc(g.meshes[0].primitives[0].attributes.POSITION)
    np.testing.assert_allclose(np.ptp(P, axis=0), np.ptp(V0, axis=0) * 0.001, rtol=1e-6)
    capsys.readouterr()
    assert _main(base + ["--out", str(tmp_path / "b"), "--unit", "km"]) == 2
    assert "--unit: expected one of m, cm, mm" in capsys.readouterr().err and not (tmp_path / "b").exists()


def test_transfer_warns_about_a_folder_as_it_ships(facex, tmp_path, capsys):
    """#23 item 5: `transfer` without --exclude 'identity*' wrote ICT's identity modes as expressions
    without a word; now one line names them and the option (and --exclude silences it)."""
    folder, _, _, _ = facex
    target = folder.parent / "target.obj"
    base = ["transfer", "--template", str(folder), "--neutral", "generic_neutral_mesh.obj", "--target", str(target)]
    assert _main(base + ["--out", str(tmp_path / "all")]) == 0
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if line.startswith("warning: rig folder")]
    assert len(warned) == 1 and "look like identity modes" in warned[0] and "--exclude 'identity*'" in warned[0]
    assert _main(base + ["--exclude", "identity*", "--out", str(tmp_path / "some")]) == 0
    assert "identity modes" not in capsys.readouterr().err


def test_a_gltf_export_never_overwrites_a_users_file_with_a_texture_copy(facex, tmp_path, capsys):
    """The .gltf's texture is copied beside it: a different file of that name there is the user's and
    is refused before anything is written; the same texture (a previous export) is left as it is."""
    _, out, _, _ = facex
    (tmp_path / "skin.png").write_bytes(b"the user's own picture")
    assert _main(["export", str(out), "--out", str(tmp_path / "r.gltf")]) == 2
    err = capsys.readouterr().err
    assert "expected to copy the texture skin.png beside it, found a different file" in err
    assert (tmp_path / "skin.png").read_bytes() == b"the user's own picture"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["skin.png"]
    (tmp_path / "skin.png").write_bytes((out / "skin.png").read_bytes())
    assert _main(["export", str(out), "--out", str(tmp_path / "r.gltf")]) == 0
    assert _main(["export", str(out), "--out", str(tmp_path / "r.gltf")]) == 0  # again: its own files
