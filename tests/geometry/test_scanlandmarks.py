"""Landmarks found on a scan (--landmarks auto): lifting 2D points onto a surface, detection on the
built-in face rendered from the front, the CLI's options."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import parser_refuses

from facebasis.cli import main
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.scanlandmarks import FrontView, lift


def plane(z, n=11):
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    V = np.stack([u.ravel(), v.ravel(), np.full(n * n, z)], 1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return V, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])  # counter-clockwise seen from +z


def test_lift_hits_the_nearest_front_facing_surface_exactly():
    V1, F1 = plane(0.0)
    V2, F2 = plane(0.5)
    V, F = np.concatenate([V1, V2]), np.concatenate([F1, F2 + len(V1)])
    view = FrontView.of(V, 200)
    P = view.pixels(V)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.9, 0.9, (20, 2))
    pts = view.pixels(np.c_[xy, np.zeros(20)])[:, :2]
    X, hit = lift(np.r_[pts, [[-50.0, -50.0]]], P, V, F)
    assert hit[:20].all() and not hit[20]
    assert np.allclose(X[:20], np.c_[xy, np.full(20, 0.5)], atol=1e-9)  # the front plane, not the one behind
    Xb, hitb = lift(pts, P, V, np.concatenate([F1, F2[:, ::-1] + len(V1)]))  # front plane turned away: not seen
    assert hitb.all() and np.allclose(Xb[:, 2], 0.0)


@pytest.fixture
def dlib_face():
    pytest.importorskip("dlib")
    pytest.importorskip("face_recognition_models")
    from facebasis.defaults.face import default_template

    return default_template()


def test_auto_landmarks_on_the_built_in_face_find_the_same_points_again(dlib_face):
    from facebasis.capture.detect import DlibDetector
    from facebasis.geometry.registration import Registration
    from test_shapemodel import as_scan

    T, F = dlib_face.neutral, dlib_face.faces
    reg = Registration(T, F, detector=DlibDetector())
    assert reg.auto.found.sum() >= 40          # brows, nose, eyes, mouth on the template's own render
    S, G, R, t = as_scan(T, F, seed=5)
    idx, pts = reg.auto.on_scan((S - t) @ R, G)  # the scan back in the template's frame: the same points
    h = np.median(np.linalg.norm(T[F[:, 0]] - T[F[:, 1]], axis=1))
    assert len(idx) >= 40 and np.median(np.linalg.norm(pts - T[idx], axis=1)) < h
    res = reg.register(S, G, "auto")
    found, used = res.landmarks_found
    assert found >= 40 and used >= 0.8 * found
    rep = res.report()
    assert rep["landmarks_found"] == found and rep["landmark_error"]["mean"] < h
    assert np.median(np.linalg.norm(res.vertices - (T @ R.T + t), axis=1)) < 0.05


def test_cli_landmarks_auto_reports_the_points(dlib_face, tmp_path, capsys):
    from test_shapemodel import as_scan

    T, F = dlib_face.neutral, dlib_face.faces
    write_mesh(tmp_path / "t.obj", T, F)
    S, G, _, _ = as_scan(T, F, seed=6)
    write_mesh(tmp_path / "scan.obj", S, G)
    rc = main(["register", str(tmp_path / "scan.obj"), "--template", str(tmp_path / "t.obj"), "--out",
               str(tmp_path / "o"), "--landmarks", "auto", "--detector", "dlib"])
    out = capsys.readouterr().out
    assert rc == 0 and "scan.obj: landmarks found on the scan and the template:" in out
    rep = json.loads((tmp_path / "o" / "scan.json").read_text())
    assert rep["landmarks_found"] >= 40 and rep["landmark_error"] is not None


@pytest.mark.parametrize("args, message", [
    (["--landmarks", "auto", "x.json"], "--landmarks: expected 'auto' or SCAN_LM.json TEMPLATE_LM.json, found auto x.json"),
    (["--landmarks", "a.json"], "--landmarks: expected 'auto' or SCAN_LM.json TEMPLATE_LM.json, found a.json"),
    (["--detector", "dlib"], "--detector dlib: expected together with --landmarks auto, found no --landmarks"),
])
def test_cli_bad_landmark_options(tmp_path, capsys, args, message):
    from facebasis.defaults.face import default_template

    rig = default_template()
    write_mesh(tmp_path / "t.obj", rig.neutral, rig.faces)
    rc = main(["register", str(tmp_path / "t.obj"), "--template", str(tmp_path / "t.obj"), "--out",
               str(tmp_path / "o")] + args)
    err = capsys.readouterr().err
    assert rc == 2 and err.strip() == f"error: {message}" and not (tmp_path / "o").exists()


@pytest.mark.parametrize("args", [["--detector", "dlib", "--detector", "dlib"], ["--detector", "opencv"],
                                  ["--landmarks", "auto", "--landmarks", "auto"], ["--expression-transfer", "affine"],
                                  ["--expression-transfer", "linear", "--expression-transfer", "linear"]])
def test_cli_detector_option_once_and_known(tmp_path, capsys, args):
    parser_refuses(main, ["register", "s.obj", "--template", "t.obj", "--out", str(tmp_path / "o")] + args, capsys,
                   args[0])


def test_register_files_auto_needs_a_detector_and_a_detector_needs_auto(tmp_path):
    from facebasis.defaults.face import default_template
    from facebasis.errors import InputError
    from facebasis.geometry.registerfiles import register_files

    rig = default_template()
    write_mesh(tmp_path / "t.obj", rig.neutral, rig.faces)
    from facebasis.cli.common import flags_of

    with pytest.raises(InputError, match=r"^landmarks auto: expected a 2D face detector \(detector\), found none") as ei:
        register_files(tmp_path / "t.obj", tmp_path / "t.obj", tmp_path / "o", landmarks="auto")
    assert str(ei.value.renamed(flags_of("register"))) == ("--landmarks auto: expected a 2D face detector (--detector), "
                                                          "found none")
    with pytest.raises(InputError, match="detector: expected together with landmarks 'auto', found no landmarks"):
        register_files(tmp_path / "t.obj", tmp_path / "t.obj", tmp_path / "o", detector=object())
    assert not (tmp_path / "o").exists()
