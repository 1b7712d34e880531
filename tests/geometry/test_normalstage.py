"""The normal-only displacement stage after a shape-model fit (geometry/normalstage.py).

Tiny data built here: flat sheets (conftest.grid_sheet) and the built-in default face with smooth
random identity modes (as tests/geometry/test_shapemodel.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import grid_sheet, parser_refuses

from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.detailprior import DetailPriorOptions
from facebasis.geometry.normalstage import NormalStageOptions, normal_displacement
from facebasis.geometry.nricp import NonRigidICP, ScanSurface
from facebasis.geometry.registration import Registration, RegistrationOptions
from facebasis.geometry.shapemodel import ShapeBasis


def _bump(V, centre, height=0.05, width=0.25):
    return height * np.exp(-((V[:, :2] - centre) ** 2).sum(1) / (2 * width ** 2))


def test_a_bump_is_recovered_along_the_normals_without_tangential_sliding():
    P, F = grid_sheet(31, 26, size=1.5)  # the fitted model: a flat sheet (normals +z or -z)
    S, G = grid_sheet(47, 39, size=1.5)  # the scan: another, finer topology with a bump the model lacks
    S = S.copy()
    S[:, 2] = _bump(S, [0.7, 0.55])
    nr = NonRigidICP(F, len(P))
    m = nr.vertex_normals(P)
    res = normal_displacement(P, m, nr.L, ScanSurface(S, G), 1.5 / 30)
    assert np.array_equal(res.vertices[:, :2], P[:, :2])  # moved along the normals only: no sliding
    want = _bump(P, [0.7, 0.55])
    rim = (P[:, 0] < 0.01) | (P[:, 0] > 1.49) | (P[:, 1] < 0.01) | (P[:, 1] > 1.19)
    assert np.array_equal(res.no_surface, rim)  # the scan's rim gives no data: those follow their neighbours
    # the smoothness term lowers and widens the bump a little (default lambda 1: ~7% of its height here)
    assert np.abs(res.vertices[~rim, 2] - want[~rim]).max() < 0.15 * want.max()
    assert np.allclose(res.offset * m[:, 2], res.vertices[:, 2])


def test_a_part_without_scan_keeps_its_place():
    P, F = grid_sheet(11, 9)
    Q, H = grid_sheet(11, 9, z=5.0)  # a second part far from the scan: no data, zero offset
    P2, F2 = np.concatenate([P, Q]), np.concatenate([F, H + len(P)])
    S, G = grid_sheet(21, 17)
    S = S.copy()
    S[:, 2] = 0.02
    nr = NonRigidICP(F2, len(P2))
    res = normal_displacement(P2, nr.vertex_normals(P2), nr.L, ScanSurface(S, G), 0.1)
    assert np.allclose(res.vertices[len(P):], Q, atol=1e-6) and res.no_surface[len(P):].all()
    assert np.allclose(res.vertices[: len(P), 2], 0.02, atol=1e-3)


def test_detail_outside_the_identity_space_is_taken_along_the_normals():
    from test_shapemodel import as_scan, bumped_person

    T, F, D, c, bump, person = bumped_person()
    S, G, R, t = as_scan(person, F, seed=1)
    basis = ShapeBasis(tuple(f"m{k}" for k in range(6)), D, "test")
    res = Registration(T, F, RegistrationOptions(after_model="normal", detail=DetailPriorOptions(modes=0)), identity=basis).register(S, G)
    truth = person @ R.T + t
    where = bump > 0.1
    model = res.similarity.apply(res.model.vertices)
    model_err = np.linalg.norm(model[where] - truth[where], axis=1)
    err = np.linalg.norm(res.vertices[where] - truth[where], axis=1)
    assert np.median(model_err) > 0.05
    assert np.median(err) < 0.3 * np.median(model_err) and np.median(err) < 0.03
    # each vertex left the fitted model along the model's normal only
    step = res.vertices - model
    mn = NonRigidICP(F, len(T)).vertex_normals(model)
    tangential = np.linalg.norm(step - (step * mn).sum(1, keepdims=True) * mn, axis=1)
    assert tangential.max() < 1e-9 * np.abs(model).max() + 1e-9


def test_bad_after_model_and_normal_stage_options_are_refused():
    with pytest.raises(InputError, match=r"after_model: expected one of nricp, normal, nricp\+normal, found 'slide'"):
        RegistrationOptions(after_model="slide")
    with pytest.raises(InputError, match="normal stage smoothness: expected a positive number, found -1"):
        NormalStageOptions(smoothness=-1.0)
    with pytest.raises(InputError, match="normal stage iterations: expected an integer >= 1, found 0"):
        NormalStageOptions(iterations=0)
    with pytest.raises(InputError, match="normal stage normal_angle"):
        NormalStageOptions(normal_angle=0.0)


def test_cli_after_model_bad_value_and_repeat(tmp_path, capsys):
    base = ["register", str(tmp_path / "scan.obj"), "--template", str(tmp_path / "t.obj"), "--out", str(tmp_path / "o")]
    parser_refuses(main, base + ["--after-model", "slide"], capsys, "--after-model", "invalid choice: 'slide'")
    parser_refuses(main, base + ["--after-model", "normal", "--after-model", "nricp"], capsys, "--after-model")


def test_the_normal_stage_is_the_default_after_a_model_fit(monkeypatch, tmp_path):
    """The library's and the command line's default stage after a fit is the normal stage (measured: a
    lower held-out ratio than the free non-rigid ICP on both ICT persons and both seeds of the rig bench)."""
    import facebasis.geometry.registerfiles as rf

    assert RegistrationOptions().after_model == "normal"
    seen = {}

    def fake_register_files(scans, template, out, lm, neutral, opts, **kw):
        seen["after_model"] = opts.after_model
        return {"scans": []}

    monkeypatch.setattr(rf, "register_files", fake_register_files)
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    for name in ("scan.obj", "t.obj"):
        (tmp_path / name).write_text(tri)
    base = ["register", str(tmp_path / "scan.obj"), "--template", str(tmp_path / "t.obj"), "--out", str(tmp_path / "o")]
    for extra, want in (([], "normal"), (["--after-model", "nricp"], "nricp")):
        seen.clear()
        assert main(base + extra) == 0
        assert seen["after_model"] == want
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("after", ["nricp", "normal"])
def test_a_template_of_several_parts_refines_its_skin_and_keeps_the_other_parts_at_the_fit(after):
    from test_shapemodel import as_scan, face, modes

    rig = face()
    T, F = rig.neutral, rig.faces
    Q, H = grid_sheet(5, 4, z=float(T[:, 2].min()) - 3.0, size=2.0)  # a second part behind the head: no scan
    T2, F2 = np.concatenate([T, Q]), np.concatenate([F, H + len(T)])
    D = modes(T)
    c = np.array([0.8, -1.2, 0.5, 1.5, -0.3, 0.9])
    person = T + np.tensordot(c, D, 1)
    S, G, R, t = as_scan(person, F, seed=5)
    D2 = np.concatenate([D, np.zeros((6, len(Q), 3))], 1)
    reg = Registration(T2, F2, RegistrationOptions(after_model=after), identity=ShapeBasis(tuple("abcdef"), D2, "t"))
    res = reg.register(S, G)
    assert np.allclose(res.vertices[len(T):], res.similarity.apply(res.model.vertices)[len(T):])
    assert res.no_surface[len(T):].all() and np.isfinite(res.distance).all()
    err = np.linalg.norm(res.vertices[: len(T)] - (person @ R.T + t), axis=1)
    assert np.median(err) < 0.01 and np.percentile(err, 95) < 0.03


def test_cli_after_model_normal_registers_through_the_identity_basis(tmp_path, capsys):
    import json

    from test_shapemodel import as_scan, face, modes

    from facebasis.geometry.meshio import write_mesh

    rig = face()
    D = modes(rig.neutral, 3)
    (tmp_path / "basis").mkdir()
    write_mesh(tmp_path / "t.obj", rig.neutral, rig.faces)
    for k in range(3):
        write_mesh(tmp_path / "basis" / f"id{k}.obj", rig.neutral + D[k], rig.faces)
    c = np.array([1.0, -0.5, 0.7])
    S, G, _, _ = as_scan(rig.neutral + np.tensordot(c, D, 1), rig.faces, seed=6)
    write_mesh(tmp_path / "p.obj", S, G)
    rc = main(["register", str(tmp_path / "p.obj"), "--template", str(tmp_path / "t.obj"), "--out", str(tmp_path / "o"),
               "--identity-basis", str(tmp_path / "basis"), "--after-model", "normal"])
    assert rc == 0, capsys.readouterr()
    rep = json.loads((tmp_path / "o" / "p.json").read_text())
    assert np.allclose([rep["identity"]["coefficients"][f"id{k}"] for k in range(3)], c, atol=0.05)
    assert rep["residual"]["median"] < 0.01


def test_cli_expression_transfer_given_once_is_accepted(tmp_path, capsys):
    # (an option with a default under the given-once rule refused any value given once)
    rc = main(["register", str(tmp_path / "missing.obj"), "--template", str(tmp_path / "t.obj"), "--out",
               str(tmp_path / "o"), "--expression-transfer", "linear"])
    err = capsys.readouterr().err
    assert rc == 2 and "given twice" not in err and "missing.obj" in err
