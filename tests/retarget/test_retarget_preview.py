"""Issue 23, rig side: left/right symmetry on a symmetric face, the preview video and weight plot,
and rig folders as they ship (``--exclude`` / ``--neutral`` on retarget and animate3d, the warning)."""

import json

import numpy as np
import pytest

from facebasis.capture.trackfile import Capture, write_capture
from facebasis.defaults.face import EXCLUSIVE_PAIRS, default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.geometry.meshio import write_mesh
from facebasis.cli.common import FLAGS
from facebasis.errors import renamed_text
from facebasis.geometry.rig import Rig, rig_folder_warning, write_rig_folder
from facebasis.geometry.raster import rasterize_mesh
from facebasis.retarget.rigdrive import RigRetargeter
from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture


def lr_pairs(names):
    names = list(names)
    return np.array([(i, names.index(n[:-2] + "_R")) for i, n in enumerate(names) if n.endswith("_L")])


def test_symmetric_face_with_symmetric_expressions_gives_equal_left_and_right():
    """The built-in face is mirror-symmetric (neutral, L/R shapes and the 68 landmarks, checked
    here); a frontal capture of symmetric expressions is then a mirror-symmetric problem whose
    optimum is unique (ridge > 0), so noise-free left and right weights are equal to rounding. With
    0.5 px noise the left and right landmarks get independent noise: x_L - x_R has about sqrt(2)
    times the error of one weight, so its median over frames stays below 2 sqrt(2) times the mean
    weight error, and below 0.1 (half the real-clip target of issue 23; measured 0.033, 0.059 with
    the defaults before it)."""
    from scipy.spatial import cKDTree

    rig, idx = default_template(), face_landmarks()
    d, j = cKDTree(rig.neutral).query(rig.neutral * [-1, 1, 1])
    assert d.max() < 1e-9 and set(j[idx].tolist()) == set(idx.tolist())           # symmetric face and landmarks
    P = lr_pairs(rig.names)
    mirror = np.abs(rig.deltas[P[:, 0]][:, j] * [-1, 1, 1] - rig.deltas[P[:, 1]]).max()
    assert mirror < 1e-9                                                           # mirrored L/R shapes
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L", "eyeBlink_L", "cheekPuff_L", "browInnerUp"),
                             150, seed=2)
    X[:, P[:, 1]] = X[:, P[:, 0]]                                                  # symmetric expressions
    exact = synthetic_capture(rig, idx, X, noise_px=0.0, seed=2, amplitude_deg=0.0)
    r = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS).run(exact.landmarks)
    assert np.abs(r.weights[:, P[:, 0]] - r.weights[:, P[:, 1]]).max() < 1e-9
    noisy = synthetic_capture(rig, idx, X, noise_px=0.5, seed=2, amplitude_deg=0.0)
    r = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS).run(noisy.landmarks)
    lr = np.median(np.abs(r.weights[:, P[:, 0]] - r.weights[:, P[:, 1]]).max(1))
    err = np.abs(r.weights - X)[:, P.ravel()].mean()
    assert lr < 0.1 and lr < 2 * np.sqrt(2) * err


# ----------------------------------------------------------------------------------------------
# the rasteriser

def test_rasterize_covers_the_right_pixels_and_keeps_the_nearest():
    # a 20 x 10 pixel rectangle (two triangles, counter-clockwise in a y-up frame = negative area in
    # the image's y-down frame) covers exactly 200 pixel centres
    P = np.array([[5.0, 5.0, 0.0], [25.0, 5.0, 0.0], [25.0, 15.0, 0.0], [5.0, 15.0, 0.0]])
    front = np.array([[0, 3, 2], [0, 2, 1]])
    img = rasterize_mesh(P, front, (30, 40))
    covered = (img != 255).any(2)
    assert covered.sum() == 200 and covered[5:15, 5:25].all()
    assert (rasterize_mesh(P, front[:, ::-1], (30, 40)) == 255).all()          # back-facing: culled
    # a nearer (z larger) triangle over a farther rectangle wins wherever both cover a pixel
    Q = np.concatenate([P, [[0.0, 0.0, 1.0], [30.0, 0.0, 1.0], [0.0, 30.0, 1.0]]])
    F = np.concatenate([front, [[4, 6, 5]]])
    near = rasterize_mesh(Q, F, (30, 40), color=(1.0, 0.0, 0.0))
    far_only = rasterize_mesh(Q, front, (30, 40), color=(1.0, 0.0, 0.0))
    tri_only = rasterize_mesh(Q, F[2:], (30, 40), color=(1.0, 0.0, 0.0))
    in_tri = (tri_only != 255).any(2)
    assert np.array_equal(near[in_tri], tri_only[in_tri])
    assert np.array_equal(near[~in_tri], far_only[~in_tri])
    # off-screen geometry draws nothing and does not fail
    assert (rasterize_mesh(P + [100.0, 0, 0], front, (30, 40)) == 255).all()


# ----------------------------------------------------------------------------------------------
# retarget: preview, --exclude, the warning

def video_frames(path):
    import av

    with av.open(str(path)) as c:
        return [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """A rig folder as it ships: the built-in face plus two identity modes, and a 12-frame capture
    whose source video (160 x 120) is recorded in the capture folder."""
    from facebasis.retarget.media import write_mp4

    root = tmp_path_factory.mktemp("shipped")
    rig, idx = default_template(), face_landmarks()
    write_rig_folder(root / "rig", rig)
    rng = np.random.default_rng(0)
    for i in range(2):
        write_mesh(root / "rig" / f"identity{i:03d}.obj", rig.neutral + 0.05 * rng.standard_normal(rig.neutral.shape),
                   rig.faces)
    (root / "idx.json").write_text(json.dumps(np.asarray(idx).tolist()))
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L"), 12, seed=1)
    cap = synthetic_capture(rig, idx, X, noise_px=0.3, seed=1, size=(160, 120), scale=6.0)
    write_mp4(root / "source.mp4", (np.full((120, 160, 3), 40 * (f % 5), np.uint8) for f in range(12)), 30.0)
    c = capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size)
    write_capture(root / "capture", Capture(c.landmarks, c.vertices, c.faces, c.fps, c.size, c.lost,
                                            video=root / "source.mp4"))
    return root


def test_retarget_exclude_warning_and_preview(shipped, capsys):
    from facebasis.cli import main

    root = shipped
    common = ["retarget", str(root / "capture"), "--rig", str(root / "rig"), "--landmarks", str(root / "idx.json")]
    # as it ships: the identity modes are solved as expressions, with a one-line warning naming them
    assert main(common + ["--out", str(root / "all"), "--no-preview"]) == 0
    out = capsys.readouterr().out
    warn = [line for line in out.splitlines() if line.startswith("warning:")]
    assert len(warn) == 1 and "identity000, identity001 (2 of 17 shapes)" in warn[0] and "--exclude 'identity*'" in warn[0]
    assert json.loads((root / "all" / "summary.json").read_text())["shapes"] == 17
    assert not (root / "all" / "preview.mp4").exists() and not (root / "all" / "weights.png").exists()
    # --exclude leaves them out (no warning); repeated, each glob leaves out its file
    assert main(common + ["--exclude", "identity*", "--out", str(root / "one")]) == 0
    assert "warning" not in capsys.readouterr().out
    assert main(common + ["--exclude", "identity000*", "--exclude", "identity001.obj", "--out", str(root / "two"),
                          "--no-preview"]) == 0
    capsys.readouterr()
    for name in ("one", "two"):
        names = json.loads((root / name / "weights.json").read_text())["names"]
        assert sorted(names) == sorted(default_template().names)
    # the preview: every frame, the 160x120 source beside a 120x120 rig panel
    s = json.loads((root / "one" / "summary.json").read_text())
    frames = video_frames(root / "one" / "preview.mp4")
    assert len(frames) == 12 and frames[0].shape == (120, 280, 3)
    assert s["preview_frames"] == 12 and s["preview_size"] == [280, 120]
    assert (root / "one" / "weights.png").stat().st_size > 1000
    assert (frames[3][:, 160:] < 250).any(2).mean() > 0.1                       # the rig is drawn
    # bad values: a glob that matches nothing, --exclude with the built-in face
    assert main(common + ["--exclude", "identiy*", "--out", str(root / "bad")]) == 2
    assert "found none for 'identiy*'" in capsys.readouterr().err
    assert main(["retarget", str(root / "capture"), "--exclude", "identity*", "--out", str(root / "bad")]) == 2
    assert "--exclude: expected a rig folder (--rig RIG_DIR)" in capsys.readouterr().err
    assert not (root / "bad").exists()


def test_many_shapes_warning():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2]])
    many = Rig(V, F, tuple(f"shape{i}" for i in range(101)), np.zeros((101, 3, 3)), source="big")
    w = rig_folder_warning(many)   # the library's parameter; the command line's flag by renaming
    assert w.startswith("warning: rig folder big: 101 shapes (more than 100)") and w.endswith(" with exclude GLOB")
    assert renamed_text(w, FLAGS).endswith(" with --exclude GLOB") and "--" not in w
    assert rig_folder_warning(Rig(V, F, ("a", "b"), np.zeros((2, 3, 3)), source="small")) is None
    ids = Rig(V, F, ("jawOpen", "id_00", "id_01", "ID7"), np.zeros((4, 3, 3)), source="ids")
    w = rig_folder_warning(ids)
    assert "id_00, id_01, ID7 (3 of 4 shapes)" in w and "exclude 'id_*'" in w and "--" not in w
    w = renamed_text(w, FLAGS)
    assert "id_00, id_01, ID7 (3 of 4 shapes)" in w and "--exclude 'id_*'" in w and "--exclude 'id*'" in w
    assert rig_folder_warning(ids, option="--skip").endswith("leave them out with --skip 'id*' --skip 'id_*'")


def test_animate3d_rig_folder_neutral_exclude_and_preview(shipped, capsys):
    from facebasis.cli import main

    root = shipped
    assert main(["animate3d", str(root / "capture"), "--mesh", str(root / "rig"), "--landmarks",
                 str(root / "idx.json"), "--exclude", "identity*", "--out", str(root / "a3")]) == 0
    out = capsys.readouterr().out
    assert "warning" not in out and "preview: 12 frames 280x120" in out
    frames = video_frames(root / "a3" / "preview.mp4")
    assert len(frames) == 12 and frames[0].shape == (120, 280, 3)
    assert main(["animate3d", str(root / "capture"), "--mesh", str(root / "rig"), "--landmarks",
                 str(root / "idx.json"), "--no-preview", "--out", str(root / "a3b")]) == 0
    assert capsys.readouterr().out.count("warning: rig folder") == 1
    assert not (root / "a3b" / "preview.mp4").exists()
    # --exclude / --neutral need a rig folder
    assert main(["animate3d", str(root / "capture"), "--mesh", str(root / "rig" / "neutral.obj"), "--landmarks",
                 str(root / "idx.json"), "--exclude", "identity*", "--out", str(root / "bad")]) == 2
    assert "--exclude identity*: expected a rig folder as --mesh, found the mesh file" in capsys.readouterr().err
    assert main(["animate3d", str(root / "capture"), "--neutral", "head.obj", "--out", str(root / "bad")]) == 2
    assert "--neutral head.obj: expected a rig folder as --mesh, found the built-in face" in capsys.readouterr().err


# ----------------------------------------------------------------------------------------------
# the noise model and the prior: options and their bad values

def test_contour_weights_and_bad_noise_model_options():
    from facebasis.errors import InputError
    from facebasis.retarget.pose import contour_weights

    p = np.stack([np.arange(5.0), np.zeros(5)], 1)                   # a straight contour along x
    W = contour_weights(p, [0, 1, 2, 3], 0.04)
    np.testing.assert_allclose(W[1] @ [1.0, 0.0], [0.2, 0.0])        # along it: sqrt(0.04)
    np.testing.assert_allclose(W[1] @ [0.0, 1.0], [0.0, 1.0])        # across it: in full
    np.testing.assert_allclose(W[4], np.eye(2))                      # not on the contour
    assert contour_weights(p, [0, 1, 2], 1.0) is None and contour_weights(p, [], 0.05) is None
    rig, idx = default_template(), face_landmarks()
    assert list(RigRetargeter(rig, idx).contour) == list(range(17))  # the iBUG jaw line by default
    for kw, msg in (({"sparsity": -1.0}, "sparsity: expected a finite number >= 0, found -1.0"),
                    ({"contour_slide": float("nan")}, "contour_slide: expected a finite number >= 0, found nan"),
                    ({"contour": [3, 68]}, r"contour: expected landmark indices in \[0, 68\), found \[3, 68\]"),
                    ({"contour": "jaw"}, "contour: expected 'auto' or landmark indices, found 'jaw'")):
        with pytest.raises(InputError, match=msg):
            RigRetargeter(rig, idx, **kw)
    fit = RigRetargeter(rig, idx).solve_frame(synthetic_capture(rig, idx, np.zeros((1, rig.n_shapes))).landmarks[0])
    x, s, R, t, rms, nodes = fit                                     # FrameFit unpacks as the former tuple
    assert fit.state[1] == s and rms < 1e-6 and np.abs(x).max() < 1e-6
