"""The outputs imported the way an artist imports them: Blender headless (its own glTF importer).

Skips when no ``blender`` is on the PATH (CI installs Debian's package; see .ci/run). One Blender
process imports every file (tests/blender_inspect.py) and reports shape keys, dimensions, UV maps,
materials and animation fcurves.
"""

import csv
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import facex_like_folder, ict_available
from facebasis.defaults.face import default_template
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.obj import read_obj

pytestmark = pytest.mark.skipif(shutil.which("blender") is None, reason="blender not installed (apt-get install blender)")


def _main(argv):
    from facebasis.cli import main

    return main(argv)


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    from facebasis.capture.trackfile import write_capture
    from facebasis.defaults.face_landmarks import face_landmarks
    from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture

    root = tmp_path_factory.mktemp("blender")
    folder, V0, _ = facex_like_folder(root / "FaceXModel")
    _, F = read_obj(folder / "generic_neutral_mesh.obj")
    write_mesh(root / "target.obj", V0 * 1.04, F)
    assert _main(["transfer", "--template", str(folder), "--neutral", "generic_neutral_mesh.obj", "--exclude",
                  "identity*", "--target", str(root / "target.obj"), "--out", str(root / "tr")]) == 0
    assert _main(["export", str(root / "tr"), "--out", str(root / "rig.glb")]) == 0
    assert _main(["export", str(root / "tr"), "--out", str(root / "rig.gltf")]) == 0
    rig = default_template()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L"), 16, seed=5)
    cap = synthetic_capture(rig, face_landmarks(), X, noise_px=0.2, seed=5, amplitude_deg=15.0)
    write_capture(root / "cap", capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size))
    assert _main(["retarget", str(root / "cap"), "--out", str(root / "rt"), "--identity", "rig"]) == 0
    assert _main(["animate3d", str(root / "cap"), "--out", str(root / "a3")]) == 0
    files = {"glb": root / "rig.glb", "gltf": root / "rig.gltf", "retarget": root / "rt" / "animation.glb",
             "animate3d": root / "a3" / "animation.glb"}
    if ict_available():
        from problems.ict import ict_rig
        from facebasis.geometry.rig import write_rig_folder

        write_rig_folder(root / "ict", ict_rig())
        assert _main(["export", str(root / "ict"), "--out", str(root / "ict.glb")]) == 0
        files["ict"] = root / "ict.glb"
    script = Path(__file__).with_name("blender_inspect.py")
    out = root / "report.json"
    proc = subprocess.run(["blender", "-b", "--factory-startup", "--python", str(script), "--", str(out),
                           *map(str, files.values())], capture_output=True, text=True, timeout=300)
    assert out.is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    reports = json.loads(out.read_text())
    if "__skip__" in reports:
        pytest.skip(reports["__skip__"])
    return {key: reports[str(path)] for key, path in files.items()}, root


def _mesh(report):
    assert "error" not in report, report
    meshes = [o for o in report["objects"] if o["type"] == "MESH"]
    assert len(meshes) == 1
    return meshes[0]


@pytest.mark.parametrize("kind", ["glb", "gltf"])
def test_export_in_blender(imported, kind):
    reports, _ = imported
    m = _mesh(reports[kind])
    assert m["shape_keys"] == ["Basis", "browInnerUp", "jawOpen", "mouthSmile_L"]  # one per expression
    width, depth, height = m["world_extent"]  # Blender is z-up: glTF's y is its z
    assert 0.1 <= height <= 0.5 and height == pytest.approx(0.2 * 1.04, rel=1e-3)  # 20.8 cm
    assert m["uv_layers"] == ["UVMap"]
    assert [x["name"] for x in m["materials"]] == ["lips", "skin"]
    assert m["materials"][1]["images"] and not m["materials"][0]["images"]


def test_ict_export_in_blender(imported):
    reports, _ = imported
    if "ict" not in reports:
        pytest.skip("ICT data absent")
    m = _mesh(reports["ict"])
    assert len(m["shape_keys"]) == 1 + 53
    assert 0.1 <= m["world_extent"][2] <= 0.5
    assert m["materials"]


def test_retarget_animation_in_blender(imported):
    reports, root = imported
    m = _mesh(reports["retarget"])
    rig = default_template()
    assert m["shape_keys"] == ["Basis", *rig.names]
    assert 0.1 <= m["world_extent"][2] <= 0.5
    paths = {(f["data_path"], f["index"]) for f in m["fcurves"]}
    assert {("rotation_quaternion", i) for i in range(4)} <= paths and {("location", i) for i in range(3)} <= paths
    keyed = {f["data_path"] for f in m["shape_key_fcurves"]}
    assert keyed == {f'key_blocks["{n}"].value' for n in rig.names}
    # the head moves: location keys follow pose.csv (glTF x -> Blender x, glTF y -> Blender z)
    rows = list(csv.DictReader((root / "rt" / "pose.csv").open()))
    t = np.array([[float(r["tx_px"]), float(r["ty_px"])] for r in rows])
    s = np.array([float(r["scale_px_per_unit"]) for r in rows])
    loc = {f["index"]: np.array(f["keys"]) for f in m["fcurves"] if f["data_path"] == "location"}
    assert len(loc[0]) == len(rows)
    np.testing.assert_allclose(loc[0][:, 1], 0.01 * (t[:, 0] - t[0, 0]) / s, atol=1e-5)
    np.testing.assert_allclose(loc[2][:, 1], -0.01 * (t[:, 1] - t[0, 1]) / s, atol=1e-5)
    rot = [np.array(f["keys"])[:, 1] for f in m["fcurves"] if f["data_path"] == "rotation_quaternion"]
    assert max(np.ptp(r) for r in rot) > 0.01
    # the shape keys play weights.csv
    wrows = list(csv.DictReader((root / "rt" / "weights.csv").open()))
    for f in m["shape_key_fcurves"]:
        name = f["data_path"].split('"')[1]
        np.testing.assert_allclose(np.array(f["keys"])[:, 1], [float(r[name]) for r in wrows], atol=2e-6)
    assert max(np.ptp(np.array(f["keys"])[:, 1]) for f in m["shape_key_fcurves"]) > 0.05


def test_animate3d_in_blender(imported):
    reports, root = imported
    m = _mesh(reports["animate3d"])
    summary = json.loads((root / "a3" / "summary.json").read_text())
    assert len(m["shape_keys"]) == 1 + summary["morph_targets"] and summary["morph_targets"] < 16
    assert len(m["shape_key_fcurves"]) == summary["morph_targets"]
    assert 0.1 <= m["world_extent"][2] <= 0.5
