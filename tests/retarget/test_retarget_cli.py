"""The animate2d / animate3d / retarget commands: outputs, and every input error before any work."""

import csv
import json

import numpy as np
import pytest
from conftest import parser_refuses

from facebasis.defaults.cartoon import default_cartoon
from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.rig import write_rig_folder
from facebasis.capture.trackfile import write_capture
from facebasis.retarget.files import write_pts
from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture


def _main():
    from facebasis.cli import main

    return main


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    rig = default_template()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L", "eyeBlink_L", "browInnerUp"), 24, seed=2)
    cap = synthetic_capture(rig, face_landmarks(), X, noise_px=0.2, seed=2)
    folder = tmp_path_factory.mktemp("cli") / "capture"
    write_capture(folder, capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size))
    return folder, X


def run(argv, capsys):
    code = _main()(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_retarget_default_face(capture, tmp_path, capsys):
    folder, X = capture
    out = tmp_path / "rt"
    code, stdout, _ = run(["retarget", str(folder), "--out", str(out), "--smooth", "0.01"], capsys)
    assert code == 0, stdout
    rows = list(csv.reader((out / "weights.csv").open()))
    assert rows[0] == ["frame", *default_template().names]
    assert len(rows) == 1 + len(X)
    W = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    assert np.all((W >= 0) & (W <= 1))
    assert np.abs(W[:, 0] - X[:, 0]).max() < 0.05           # jawOpen, the best-seen shape
    data = json.loads((out / "weights.json").read_text())
    assert data["names"][0] == "jawOpen" and len(data["weights"]) == len(X)
    pose = list(csv.reader((out / "pose.csv").open()))
    assert pose[0][:3] == ["frame", "time_s", "scale_px_per_unit"] and len(pose) == 1 + len(X)
    assert (out / "animation.glb").stat().st_size > 0


def test_retarget_rig_folder_with_exclusive_pairs(capture, tmp_path, capsys):
    folder, X = capture
    rig = default_template()
    rig_dir = tmp_path / "rig"
    write_rig_folder(rig_dir, rig)
    idx = tmp_path / "idx.json"
    idx.write_text(json.dumps(face_landmarks().tolist()))
    out = tmp_path / "rt"
    code, stdout, err = run(["retarget", str(folder), "--rig", str(rig_dir), "--landmarks", str(idx), "--out", str(out),
                             "--exclusive", "mouthLeft:mouthRight", "eyeBlink_L:eyeWide_L",
                             "--exclusive", "eyeBlink_R:eyeWide_R"], capsys)
    assert code == 0, err
    assert "3 exclusive pairs" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exclusive"] == ["mouthLeft:mouthRight", "eyeBlink_L:eyeWide_L", "eyeBlink_R:eyeWide_R"]


def test_retarget_ridge_auto_and_given(capture, tmp_path, capsys):
    folder, _ = capture
    out = tmp_path / "auto"
    code, stdout, err = run(["retarget", str(folder), "--out", str(out)], capsys)
    assert code == 0, err
    assert "ridge auto" in stdout and "landmark noise" in stdout
    assert "hint:" not in stdout                        # the built-in face's own capture: no shape difference
    s = json.loads((out / "summary.json").read_text())
    assert s["ridge_rule"] == "auto" and s["ridge"] >= 1e-3
    # 0.2 px per coordinate: rms 2D residual ~0.27 px (1.34 x noise, see test_retarget_rig)
    assert 0.1 < s["noise_px"] < 0.5
    out2 = tmp_path / "given"
    code, stdout, err = run(["retarget", str(folder), "--ridge", "0.01", "--out", str(out2)], capsys)
    assert code == 0, err
    s = json.loads((out2 / "summary.json").read_text())
    assert s["ridge_rule"] == "given" and s["ridge"] == 0.01 and "noise_px" not in s
    _fails(["retarget", str(folder), "--ridge", "lots", "--out", str(tmp_path / "x")],
           "--ridge: expected a finite number >= 0, found lots", capsys, tmp_path / "x")


def test_animate2d_default_cartoon(capture, tmp_path, capsys):
    folder, _ = capture
    out = tmp_path / "a2"
    code, stdout, err = run(["animate2d", str(folder), "--out", str(out)], capsys)
    assert code == 0, err
    for name in ("cartoon.mp4", "cartoon.gif", "cartoon_mesh.npz"):
        assert (out / name).stat().st_size > 0
    with np.load(out / "cartoon_mesh.npz") as d:
        assert d["vertices"].shape == (24, 68, 2) and d["faces"].shape[1] == 3
    from facebasis.retarget.media import read_video_frames

    frames = list(read_video_frames(out / "cartoon.mp4"))
    assert len(frames) == 24 and frames[0].shape == (512, 512, 3)


def test_animate2d_own_image(capture, tmp_path, capsys):
    import cv2

    folder, _ = capture
    face = default_cartoon(256)
    img = tmp_path / "toon.png"
    cv2.imwrite(str(img), np.ascontiguousarray(face.image[..., ::-1]))
    pts = tmp_path / "toon.pts"
    write_pts(pts, face.landmarks)
    out = tmp_path / "a2"
    code, _, err = run(["animate2d", str(folder), "--image", str(img), "--landmarks", str(pts), "--out", str(out)],
                       capsys)
    assert code == 0, err
    assert (out / "cartoon.mp4").is_file()


def test_animate3d(capture, tmp_path, capsys):
    folder, _ = capture
    rig = default_template()
    mesh = tmp_path / "face.obj"
    write_mesh(mesh, rig.neutral, rig.faces)
    idx = tmp_path / "idx.json"
    idx.write_text(json.dumps({"indices": face_landmarks().tolist()}))
    out = tmp_path / "a3"
    code, _, err = run(["animate3d", str(folder), "--mesh", str(mesh), "--landmarks", str(idx), "--out", str(out)],
                       capsys)
    assert code == 0, err
    with np.load(out / "frames.npz") as d:
        V = d["vertices"]
        assert V.shape == (24, rig.n_vertices, 3)
        np.testing.assert_allclose(V[0], rig.neutral, atol=1e-5)            # frame 0 is the rest pose
        np.testing.assert_allclose(V[:, :, 2], np.broadcast_to(rig.neutral[:, 2], V.shape[:2]), atol=1e-5)
        assert np.abs(V[5] - V[0]).max() > 0.01
    import pygltflib

    g = pygltflib.GLTF2().load(str(out / "animation.glb"))
    assert g.animations[0].channels[0].target.path == "weights"
    assert g.accessors[g.animations[0].samplers[0].input].count == 24


def test_head_option(capture, tmp_path, capsys):
    """--head still (default) takes the head's similarity out; --head follow / --follow-head keep it."""
    folder, _ = capture
    meshes = {}
    for name, extra in (("still", []), ("follow", ["--head", "follow"]), ("short", ["--follow-head"])):
        out = tmp_path / f"a2_{name}"
        code, _, err = run(["animate2d", str(folder), *extra, "--out", str(out)], capsys)
        assert code == 0, err
        with np.load(out / "cartoon_mesh.npz") as d:
            meshes[name] = d["vertices"]
        summary = json.loads((out / "summary.json").read_text())
        assert summary["head"] == ("still" if name == "still" else "follow")
    np.testing.assert_array_equal(meshes["follow"], meshes["short"])
    assert np.abs(meshes["follow"] - meshes["still"]).max() > 1.0           # the synthetic head moves
    # still: the stable points (nose, eye corners) move less (only by the synthetic head's turns out
    # of the image plane, which no similarity describes); follow: they also move with the head
    stable = np.r_[27:36, 36, 39, 42, 45]
    spread = lambda M: np.sqrt(np.mean((M[:, stable] - M[:1, stable]) ** 2))  # noqa: E731
    assert spread(meshes["still"]) < spread(meshes["follow"])
    rig = default_template()
    for name, extra in (("still", []), ("follow", ["--follow-head"])):
        out = tmp_path / f"a3_{name}"
        code, _, err = run(["animate3d", str(folder), *extra, "--out", str(out)], capsys)
        assert code == 0, err
        with np.load(out / "frames.npz") as d:
            meshes["3d" + name] = d["vertices"]
    assert np.abs(meshes["3dfollow"] - meshes["3dstill"]).max() > 0.01 * np.ptp(rig.neutral[:, 0])
    z = meshes["3dstill"][:, :, 2]
    np.testing.assert_allclose(z, np.broadcast_to(rig.neutral[:, 2], z.shape), atol=1e-5)


@pytest.mark.parametrize("value", ["sideways", "Still!", ""])
def test_bad_head_values(capture, tmp_path, capsys, value):
    folder, _ = capture
    out = tmp_path / "out"
    for cmd in ("animate2d", "animate3d"):
        _fails([cmd, str(folder), "--head", value, "--out", str(out)],
               f"--head: expected one of still, follow, found {value!r}", capsys, out)


def _animate2d_meshes(folder, tmp_path, capsys, key: str, values) -> dict:
    """animate2d with ``--key`` at each of ``values`` (the first the default, not given): each run succeeds and its
    summary records the value; the cartoon meshes (T, N, 2) by value."""
    meshes = {}
    for i, name in enumerate(values):
        out = tmp_path / f"{key}_{name}"
        extra = [f"--{key}", name] if i else []
        code, _, err = run(["animate2d", str(folder), *extra, "--out", str(out)], capsys)
        assert code == 0, err
        assert json.loads((out / "summary.json").read_text())[key] == name
        with np.load(out / "cartoon_mesh.npz") as d:
            meshes[name] = d["vertices"].astype(np.float64)
    return meshes


def test_amplitude_option(capture, tmp_path, capsys):
    """animate2d --amplitude feature (default) and uniform (the paper's one scale) move the eyes,
    brows and mouth differently (the built-in cartoon's proportions are not the capture's: its eyes
    are 0.9x as tall, relative to the face, and the brows follow the eyes' centres)."""
    meshes = _animate2d_meshes(capture[0], tmp_path, capsys, "amplitude", ("feature", "uniform"))
    diff = np.abs(meshes["feature"] - meshes["uniform"]).max(axis=(0, 2))
    assert diff[17:27].max() > 1.0 and diff[36:48].max() > 1.0 and diff[48:68].max() > 1.0


@pytest.mark.parametrize("value", ["loud", "Feature!", ""])
def test_bad_amplitude_values(capture, tmp_path, capsys, value):
    folder, _ = capture
    out = tmp_path / "out"
    _fails(["animate2d", str(folder), "--amplitude", value, "--out", str(out)],
           f"--amplitude: expected one of feature, uniform, found {value!r}", capsys, out)


# ---------------------------------------------------------------------------------------------
# every error: one line, before any work, no output folder

def _fails(argv, match, capsys, out):
    code, _, err = run(argv, capsys)
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert match in err, err
    assert not out.exists()
    assert not list(out.parent.glob(f".{out.name}*"))


def test_errors(capture, tmp_path, capsys):
    folder, _ = capture
    out = tmp_path / "out"
    rig = default_template()
    # landmark index file of the wrong length, and out of range
    short = tmp_path / "short.json"
    short.write_text(json.dumps(list(range(60))))
    far = tmp_path / "far.json"
    far.write_text(json.dumps([*range(67), rig.n_vertices + 5]))
    mesh = tmp_path / "face.obj"
    write_mesh(mesh, rig.neutral, rig.faces)
    _fails(["retarget", str(folder), "--landmarks", str(short), "--out", str(out)],
           "expected 68 indices (one per capture landmark), found 60", capsys, out)
    _fails(["animate3d", str(folder), "--mesh", str(mesh), "--landmarks", str(far), "--out", str(out)],
           f"expected vertex indices in [0, {rig.n_vertices})", capsys, out)
    # capture folder without track.npz
    empty = tmp_path / "empty"
    empty.mkdir()
    for cmd in ("retarget", "animate2d", "animate3d"):
        _fails([cmd, str(empty), "--out", str(out)], "track.npz", capsys, out)
    # cartoon landmark count != capture's
    face = default_cartoon(128)
    import cv2

    img = tmp_path / "toon.png"
    cv2.imwrite(str(img), np.ascontiguousarray(face.image[..., ::-1]))
    pts = tmp_path / "toon.json"
    pts.write_text(json.dumps(face.landmarks[:50].tolist()))
    _fails(["animate2d", str(folder), "--image", str(img), "--landmarks", str(pts), "--out", str(out)],
           "expected 68 points (the capture's count), found 50", capsys, out)
    # unreadable image
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    pts.write_text(json.dumps(face.landmarks.tolist()))
    _fails(["animate2d", str(folder), "--image", str(bad), "--landmarks", str(pts), "--out", str(out)],
           "OpenCV cannot read", capsys, out)
    # unknown shape names in --exclusive
    _fails(["retarget", str(folder), "--exclusive", "jawOpen:smileBig", "--out", str(out)],
           "unknown blendshape names ['smileBig']", capsys, out)
    _fails(["retarget", str(folder), "--exclusive", "jawOpen", "--out", str(out)],
           "expected SHAPE_A:SHAPE_B", capsys, out)
    # --image without --landmarks; rig folder without --landmarks
    _fails(["animate2d", str(folder), "--image", str(img), "--out", str(out)], "expected both", capsys, out)


def test_existing_output_survives_a_failed_run(capture, tmp_path, capsys):
    folder, _ = capture
    out = tmp_path / "keep"
    out.mkdir()
    (out / "old.txt").write_text("x")
    code, _, _ = run(["retarget", str(folder), "--exclusive", "a:b", "--out", str(out)], capsys)
    assert code == 2 and (out / "old.txt").read_text() == "x"


def test_rest_anchor_option(capture, tmp_path, capsys, monkeypatch):
    """--rest-anchor on|off reaches the solver (default: the library's), is recorded in the summary, and
    a bad or repeated value is one line before any work."""
    import inspect

    from facebasis.retarget import pipeline
    from facebasis.retarget.rigdrive import RigRetargeter

    folder, _ = capture
    seen = []
    original = RigRetargeter.__init__

    def spy(self, *a, **kw):
        seen.append(kw.get("rest_anchor"))
        original(self, *a, **kw)

    monkeypatch.setattr(RigRetargeter, "__init__", spy)
    for extra, want in (([], True), (["--rest-anchor", "off"], False), (["--rest-anchor", "on"], True)):
        out = tmp_path / f"rt{len(seen)}"
        code, stdout, _ = run(["retarget", str(folder), "--out", str(out), "--no-preview", *extra], capsys)
        assert code == 0, stdout
        assert seen[-1] is want
        summary = json.loads((out / "summary.json").read_text())
        assert summary["identity_rest_anchor"] is want
        # the landmark evidence on the take's start (None: not a 68-point capture) and the demand ratio
        assert summary["identity_rest_start"] in (True, False, None)
        ratio = summary["identity_demand_ratio"]
        assert ratio is None or ratio >= 0
        if not want:
            assert summary["identity_rest_start"] is None and ratio is None and not summary["identity_rest_anchored"]
    assert inspect.signature(pipeline.run_retarget).parameters["rest_anchor"].default is True
    assert inspect.signature(original).parameters["rest_anchor"].default is True
    for argv, msg in ((["--rest-anchor", "maybe"], "invalid choice: 'maybe'"),
                      (["--rest-anchor", "on", "--rest-anchor", "off"], "--rest-anchor")):
        parser_refuses(_main(), ["retarget", str(folder), "--out", str(tmp_path / "bad"), *argv], capsys, msg)
        assert not (tmp_path / "bad").exists()


def test_focal_and_noise_model_options(capture, tmp_path, capsys, monkeypatch):
    """--focal PX and --noise-model pixels|rig reach the solver (defaults: the library's; the principal
    point is the image centre), are recorded in the summary; bad or repeated values are one line with
    nothing written."""
    import inspect

    from facebasis.retarget.rigdrive import RigRetargeter

    folder, _ = capture
    seen = []
    original = RigRetargeter.__init__

    def spy(self, *a, **kw):
        seen.append((kw.get("focal"), kw.get("centre"), kw.get("noise_model")))
        original(self, *a, **kw)

    monkeypatch.setattr(RigRetargeter, "__init__", spy)
    for extra, want in (([], (None, None, "pixels")), (["--focal", "600", "--noise-model", "rig"], (600.0, (256.0, 256.0), "rig"))):
        out = tmp_path / f"rt{len(seen)}"
        code, stdout, _ = run(["retarget", str(folder), "--out", str(out), "--no-preview", *extra], capsys)
        assert code == 0, stdout
        assert seen[-1] == want
        summary = json.loads((out / "summary.json").read_text())
        assert summary["focal_px"] == want[0] and summary["noise_model"] == want[2]
        assert (summary["noise_pixel_scale"] is None) == (want[2] == "rig")
        assert summary["principal_point_px"] == (None if want[1] is None else list(want[1]))
    assert inspect.signature(original).parameters["noise_model"].default == "pixels"
    assert inspect.signature(original).parameters["focal"].default is None
    for argv, msg in ((["--focal", "0"], "--focal: expected a focal length in pixels > 0, found 0"),
                      (["--focal", "nan"], "--focal: expected"), (["--focal", "-5"], "--focal: expected")):
        code, stdout, err = run(["retarget", str(folder), "--out", str(tmp_path / "bad"), *argv], capsys)
        assert code == 2 and msg in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "bad").exists()
    for argv, msg in ((["--focal", "wide"], "invalid float value: 'wide'"),
                      (["--noise-model", "metres"], "invalid choice: 'metres'"),
                      (["--focal", "500", "--focal", "600"], "--focal"),
                      (["--noise-model", "rig", "--noise-model", "pixels"], "--noise-model")):
        parser_refuses(_main(), ["retarget", str(folder), "--out", str(tmp_path / "bad"), *argv], capsys, msg)
        assert not (tmp_path / "bad").exists()


def test_a_bad_noise_model_is_said_before_the_capture_is_read(tmp_path):
    """run_retarget checks noise_model before any work: a capture folder that does not exist is not
    what the error names; the CLI passes None (the library's default) when --noise-model is not given."""
    from facebasis.retarget.pipeline import run_retarget

    with pytest.raises(InputError, match=r"^noise_model: expected one of pixels, rig, found 'metres'$"):
        run_retarget(tmp_path / "no_such_capture", tmp_path / "out", noise_model="metres")
    assert not (tmp_path / "out").exists()


def test_the_principal_point_is_not_named_as_focal():
    """The CLI never takes a principal point (it is the image centre): a bad one comes from the capture
    folder's size, which its own error names, so ``centre`` maps to no flag (it was ``--focal``)."""
    from facebasis.cli.common import FLAGS

    assert "centre" not in FLAGS and FLAGS["focal"] == "--focal" and FLAGS["noise_model"] == "--noise-model"


def _check_retarget_option(folder, tmp_path, capsys, monkeypatch, key: str, cases, bad: str, library_message: str):
    """A ``retarget`` choice option (``--key`` with dashes, :class:`RigRetargeter`'s keyword ``key``): each of ``cases``
    (extra argv, the value expected; the second and third given together are a repeat) reaches the solver and the
    summary; a bad value and a repeat are refused while parsing, and the library refuses the bad value with ``library_message``, nothing written. Returns the cases'
    (value, summary, stdout)."""
    from facebasis.retarget.pipeline import run_retarget
    from facebasis.retarget.rigdrive import RigRetargeter

    flag = "--" + key.replace("_", "-")
    seen, runs = [], []
    original = RigRetargeter.__init__

    def spy(self, *a, **kw):
        seen.append(kw.get(key))
        original(self, *a, **kw)

    monkeypatch.setattr(RigRetargeter, "__init__", spy)
    for extra, want in cases:
        out = tmp_path / f"{key}{len(seen)}"
        code, stdout, _ = run(["retarget", str(folder), "--out", str(out), "--no-preview", *extra], capsys)
        assert code == 0, stdout
        assert seen[-1] == want
        summary = json.loads((out / "summary.json").read_text())
        assert summary[key] == want
        runs.append((want, summary, stdout))
    for argv, msg in (([flag, bad], f"invalid choice: '{bad}'"), (cases[1][0] + cases[2][0], flag)):
        parser_refuses(_main(), ["retarget", str(folder), "--out", str(tmp_path / "bad"), *argv], capsys, msg)
        assert not (tmp_path / "bad").exists()
    with pytest.raises(InputError, match=library_message):
        run_retarget(tmp_path / "no_such_capture", tmp_path / "out", **{key: bad})
    assert not (tmp_path / "out").exists()
    return runs


def test_point_noise_option(capture, tmp_path, capsys, monkeypatch):
    """--point-noise per-point|shared reaches the solver (default: the library's, per-point), the
    landmarks' weights are in the summary (none with shared); bad or repeated values are one line with
    nothing written."""
    folder, _ = capture
    cases = (([], "per-point"), (["--point-noise", "shared"], "shared"), (["--point-noise", "per-point"], "per-point"))
    for want, summary, stdout in _check_retarget_option(
            folder, tmp_path, capsys, monkeypatch, "point_noise", cases, "pointwise",
            r"^point_noise: expected one of per-point, shared, found 'pointwise'$"):
        w = summary.get("landmark_weights")
        assert (w is None) == (want == "shared")
        if w is not None:
            assert len(w) == summary_landmarks(folder) and min(w) > 0 and max(w) == 1.0
            assert "landmark noise per point:" in stdout


def summary_landmarks(folder) -> int:
    from facebasis.capture.trackfile import read_capture

    return read_capture(folder).n_landmarks


def test_gaze_option(capture, tmp_path, capsys, monkeypatch):
    """--gaze conjugate|free reaches the solver (default: the library's, conjugate) and the summary, with the
    tied pairs (none on the built-in face: it has no eye-look shapes); bad or repeated values are one line
    with nothing written."""
    from facebasis.retarget.rigdrive import RigRetargeter

    folder, _ = capture
    seen = []
    original = RigRetargeter.__init__

    def spy(self, *a, **kw):
        seen.append(kw.get("gaze"))
        original(self, *a, **kw)

    monkeypatch.setattr(RigRetargeter, "__init__", spy)
    for extra, want in (([], "conjugate"), (["--gaze", "free"], "free"), (["--gaze", "conjugate"], "conjugate")):
        out = tmp_path / f"gz{len(seen)}"
        code, stdout, _ = run(["retarget", str(folder), "--out", str(out), "--no-preview", *extra], capsys)
        assert code == 0, stdout
        assert seen[-1] == want
        summary = json.loads((out / "summary.json").read_text())
        assert summary["gaze"] == want and summary["gaze_pairs"] == []
    for argv, msg in ((["--gaze", "left"], "invalid choice: 'left'"),
                      (["--gaze", "free", "--gaze", "conjugate"], "--gaze")):
        parser_refuses(_main(), ["retarget", str(folder), "--out", str(tmp_path / "bad"), *argv], capsys, msg)
        assert not (tmp_path / "bad").exists()
    with pytest.raises(InputError, match=r"^gaze: expected one of conjugate, free, found 'left'$"):
        from facebasis.retarget.pipeline import run_retarget

        run_retarget(tmp_path / "no_such_capture", tmp_path / "out", gaze="left")
    assert not (tmp_path / "out").exists()


def test_rest_depth_option(capture, tmp_path, capsys, monkeypatch):
    """--rest-depth tangent|none reaches the solver (default: the library's, tangent) and the summary; bad or
    repeated values are one line with nothing written."""
    folder, _ = capture
    _check_retarget_option(folder, tmp_path, capsys, monkeypatch, "rest_depth",
                           (([], "tangent"), (["--rest-depth", "none"], "none"), (["--rest-depth", "tangent"], "tangent")),
                           "deep", r"^rest_depth: expected one of tangent, none, found 'deep'$")


def test_jaw_option(capture, tmp_path, capsys):
    """animate2d --jaw lips (default) drives the face contour by the lower lip, --jaw capture by the capture's
    contour (tests/retarget/test_retarget_jawline.py: what each does to a turning head); the option reaches the
    warp and is recorded; given twice, or a bad value, it is one line and no output."""
    folder, _ = capture
    meshes = _animate2d_meshes(folder, tmp_path, capsys, "jaw", ("lips", "capture"))
    assert np.abs(meshes["lips"][:, :17] - meshes["capture"][:, :17]).max() > 1.0   # the contours differ
    out = tmp_path / "bad"
    _fails(["animate2d", str(folder), "--jaw", "chin", "--out", str(out)],
           "--jaw: expected one of lips, capture, found 'chin'", capsys, out)
    from facebasis.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["animate2d", str(folder), "--jaw", "lips", "--jaw", "capture", "--out", str(out)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "--jaw: expected once, found it given twice" in err and not out.exists()
