"""Registration through a shape model first: identity basis, expressions through the rig, bad bases.

Tiny data built here: the built-in default face (about 4k vertices) as the template, smooth random
identity modes, its own expressions; scans are subdivided (another topology), shuffled and moved.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import parser_refuses

from facebasis.cli import main
from facebasis.errors import FacebasisError, InputError, TopologyError
from facebasis.geometry.detailprior import DetailPriorOptions
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.nricp import NonRigidICP
from facebasis.geometry.registerfiles import register_files
from facebasis.geometry.registration import Registration, RegistrationOptions
from facebasis.geometry.shapemodel import ShapeBasis
from problems.bench_registration import random_rotation


@lru_cache(maxsize=1)
def face():
    from facebasis.defaults.face import default_template

    return default_template()


def modes(V, k=6, seed=0):
    """``k`` smooth random displacement fields (k, n, 3) of about 0.5 cm."""
    rng = np.random.default_rng(seed)
    c = V[rng.choice(len(V), k)]
    w = np.exp(-((V[None] - c[:, None]) ** 2).sum(2) / (2 * 3.0 ** 2))
    return w[:, :, None] * rng.uniform(-0.5, 0.5, (k, 1, 3))


def as_scan(V, F, seed=0):
    """Another topology (midpoint subdivision), shuffled vertices, a rigid motion: (S, G, R, t)."""
    import trimesh

    S, G = trimesh.remesh.subdivide(V, F)
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(S))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    R, t = random_rotation(rng), rng.uniform(-5, 5, 3)
    return S[perm] @ R.T + t, inv[G], R, t


def test_person_in_a_known_identity_space_is_recovered_to_its_coefficients():
    rig = face()
    T, F = rig.neutral, rig.faces
    D = modes(T)
    c = np.array([0.8, -1.2, 0.5, 1.5, -0.3, 0.9])
    person = T + np.tensordot(c, D, 1)
    S, G, R, t = as_scan(person, F)
    res = Registration(T, F, identity=ShapeBasis(tuple(f"m{k}" for k in range(6)), D, "test")).register(S, G)
    assert res.model_kind == "identity"
    assert np.abs(res.model.coefficients - c).max() < 0.05, res.model.coefficients
    err = np.linalg.norm(res.vertices - (person @ R.T + t), axis=1)
    assert np.median(err) < 0.01 and np.percentile(err, 95) < 0.03
    rep = res.report()["identity"]
    assert set(rep["coefficients"]) == {f"m{k}" for k in range(6)} and rep["iterations"] >= 1


def bumped_person():
    """The built-in face's template (T, F), six modes D, coefficients c and a person in their span plus
    a 2.5 mm bump along the normals on the cheek, which no mode has: ``(T, F, D, c, bump, person)``."""
    rig = face()
    T, F = rig.neutral, rig.faces
    D = modes(T)
    c = np.array([0.8, -1.2, 0.5, 1.5, -0.3, 0.9])
    n = NonRigidICP(F, len(T)).vertex_normals(T + np.tensordot(c, D, 1))
    front = np.flatnonzero(T[:, 2] > np.median(T[:, 2]))
    centre = T[front[np.argmin(((T[front, :2] - [3.0, -1.0]) ** 2).sum(1))]]
    bump = 0.25 * np.exp(-((T - centre) ** 2).sum(1) / (2 * 1.0 ** 2))
    return T, F, D, c, bump, T + np.tensordot(c, D, 1) + bump[:, None] * n


def test_detail_outside_the_identity_space_survives_the_non_rigid_stage():
    T, F, D, c, bump, person = bumped_person()
    S, G, R, t = as_scan(person, F, seed=1)
    modes_only = RegistrationOptions(detail=DetailPriorOptions(modes=0))  # the stage after a modes-only fit
    res = Registration(T, F, modes_only, identity=ShapeBasis(tuple(f"m{k}" for k in range(6)), D, "test")).register(S, G)
    truth = person @ R.T + t
    where = bump > 0.1
    model_err = np.linalg.norm(res.similarity.apply(res.model.vertices)[where] - truth[where], axis=1)
    err = np.linalg.norm(res.vertices[where] - truth[where], axis=1)
    assert np.median(model_err) > 0.05          # the space cannot express the bump ...
    assert np.median(err) < 0.3 * np.median(model_err) and np.median(err) < 0.03  # ... the non-rigid stage keeps it


@pytest.mark.parametrize("transfer", ["linear", "deformation"])
def test_expression_built_from_the_rig_is_registered_to_its_weights(transfer):
    rig = face()
    T, F = rig.neutral, rig.faces
    reg = Registration(T, F, expressions=ShapeBasis(rig.names, rig.deltas, "test"))
    w = np.zeros(len(rig.names))
    w[rig.names.index("jawOpen")], w[rig.names.index("mouthSmile_L")] = 0.7, 0.4
    S0, G0, _, _ = as_scan(T, F, seed=2)
    neutral = reg.register(S0, G0).vertices
    S, G, R, t = as_scan(T + np.tensordot(w, rig.deltas, 1), F, seed=3)
    res = reg.register(S, G, start=neutral, expressions=reg.person_expressions(neutral, transfer))
    assert res.model_kind == "expressions"
    assert np.abs(res.model.coefficients - w).max() < 0.1, dict(zip(rig.names, res.model.coefficients.round(2)))
    err = np.linalg.norm(res.vertices - (T + np.tensordot(w, rig.deltas, 1)) @ R.T - t, axis=1)
    assert np.percentile(err, 95) < 0.1
    assert res.report()["expressions"]["coefficients"]["jawOpen"] == pytest.approx(0.7, abs=0.1)


def test_expressions_without_a_basis_or_a_start_are_refused():
    rig = face()
    reg = Registration(rig.neutral, rig.faces)
    with pytest.raises(InputError, match="no expression basis"):
        reg.person_expressions(rig.neutral)
    with pytest.raises(InputError, match="without a start mesh"):
        reg.register(rig.neutral, rig.faces, expressions=rig.deltas)
    reg = Registration(rig.neutral, rig.faces, expressions=ShapeBasis(rig.names, rig.deltas, "x"))
    with pytest.raises(InputError, match="transfer: expected 'deformation' or 'linear', found 'x'"):
        reg.person_expressions(rig.neutral, "x")
    with pytest.raises(InputError, match=r"identity basis b: expected displacements of shape \(K, \d+, 3\)"):
        Registration(rig.neutral, rig.faces, identity=ShapeBasis(("a",), np.zeros((1, 5, 3)), "b"))


@pytest.fixture
def files(tmp_path):
    rig = face()
    write_mesh(tmp_path / "t.obj", rig.neutral, rig.faces)
    write_mesh(tmp_path / "scan.obj", rig.neutral + 0.1, rig.faces)
    (tmp_path / "empty").mkdir()
    (tmp_path / "other").mkdir()
    (tmp_path / "good").mkdir()
    write_mesh(tmp_path / "good" / "identity000.obj", rig.neutral + modes(rig.neutral, 1)[0], rig.faces)
    write_mesh(tmp_path / "other" / "identity000.obj", rig.neutral[:-3], rig.faces[np.all(rig.faces < len(rig.neutral) - 3, 1)])
    return tmp_path


def test_a_basis_of_another_topology_is_refused_naming_the_file(files):
    n = len(face().neutral)
    with pytest.raises(TopologyError, match=rf"identity000.obj: expected {n} vertices as in .*t.obj, found {n - 3}"):
        register_files(files / "scan.obj", files / "t.obj", files / "out", identity_basis=files / "other")
    assert not (files / "out").exists()


def test_an_empty_basis_folder_is_refused(files):
    from facebasis.cli.common import flags_of

    with pytest.raises(InputError, match=r"^expression_basis .*empty: expected .obj or .ply meshes in the "
                                         r"template's topology, found none"):
        register_files(files / "scan.obj", files / "t.obj", files / "out", expression_basis=files / "empty")
    with pytest.raises(InputError, match=r"^identity_basis .*nothing: expected a folder of meshes .* found no such") \
            as ei:
        register_files(files / "scan.obj", files / "t.obj", files / "out", identity_basis=files / "nothing")
    assert str(ei.value.renamed(flags_of("register"))).startswith("--identity-basis ")  # the command line's flag
    assert not (files / "out").exists()


def test_an_unknown_expression_transfer_is_refused(files):
    with pytest.raises(InputError, match="^expression_transfer: expected 'deformation' or 'linear', found 'affine'"):
        register_files(files / "scan.obj", files / "t.obj", files / "out", expression_transfer="affine")
    assert not (files / "out").exists()


def test_a_scan_without_faces_is_refused_with_a_basis(files):
    (files / "cloud.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(FacebasisError, match="cloud.obj: expected vertices and faces, found 3 vertices and 0 faces"):
        register_files(files / "cloud.obj", files / "t.obj", files / "out", identity_basis=files / "good")
    assert not (files / "out").exists()


def test_cli_basis_options(files, capsys):
    rc = main(["register", str(files / "scan.obj"), "--template", str(files / "t.obj"), "--out", str(files / "out"),
               "--identity-basis", str(files / "empty")])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: --identity-basis") and "found none" in err and err.count("\n") == 1
    parser_refuses(main, ["register", str(files / "scan.obj"), "--template", str(files / "t.obj"), "--out",
                          str(files / "out"), "--expression-basis", str(files / "empty"), "--expression-basis",
                          str(files / "empty")], capsys, "--expression-basis")
    assert not (files / "out").exists()


def test_cli_auto_detects_identity_meshes_beside_the_template(files, capsys):
    rig = face()
    D = modes(rig.neutral, 3)
    ict = files / "facex"
    ict.mkdir()
    write_mesh(ict / "neutral.obj", rig.neutral, rig.faces)
    for k in range(3):
        write_mesh(ict / f"identity{k:03d}.obj", rig.neutral + D[k], rig.faces)
    write_mesh(ict / "jawOpen.obj", rig.neutral + rig.deltas[rig.names.index("jawOpen")], rig.faces)
    c = np.array([1.0, -0.5, 0.7])
    S, G, _, _ = as_scan(rig.neutral + np.tensordot(c, D, 1), rig.faces, seed=4)
    write_mesh(files / "person.obj", S, G)
    rc = main(["register", str(files / "person.obj"), "--template", str(ict / "neutral.obj"), "--out", str(files / "o")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "identity basis: 3 meshes found beside the template" in out
    assert "expression basis: 1 meshes found beside the template" in out
    import json

    rep = json.loads((files / "o" / "person.json").read_text())
    got = [rep["identity"]["coefficients"][f"identity{k:03d}"] for k in range(3)]
    assert np.allclose(got, c, atol=0.05)
    rc = main(["register", str(files / "person.obj"), "--template", str(ict / "neutral.obj"), "--out", str(files / "o2"),
               "--identity-basis", "none"])
    assert rc == 0 and "identity" not in json.loads((files / "o2" / "person.json").read_text())


def test_bounded_step_is_the_bounded_least_squares_minimiser(monkeypatch):
    """The model fit's bounded step (a box QP on the normal matrix: block principal pivoting, DAQP when it
    does not settle) is BVLS's minimiser on A, with free (infinite-bound) unknowns beside bounded ones and
    bounds active."""
    from scipy.optimize import lsq_linear

    from facebasis.geometry.shapemodel import _solve, box_qp, normal_equations

    rng = np.random.default_rng(4)
    Jp, Jc, r = rng.standard_normal((80, 6)), rng.standard_normal((80, 24)), 3.0 * rng.standard_normal(80)
    lam, c = rng.uniform(0.1, 1.0, 24), rng.uniform(-0.2, 0.2, 24)
    # the stacked least squares the normal equations stand for: residuals [Jp Jc] dx + r and lam (c + dc)
    A = np.block([[Jp, Jc], [np.zeros((24, 6)), np.diag(lam)]])
    b = np.concatenate([-r, -lam * c])
    lb = np.concatenate([np.full(6, -np.inf), np.full(24, -0.2)])
    ub = np.concatenate([np.full(6, np.inf), rng.uniform(0.0, 0.3, 24)])
    ref = lsq_linear(A, b, bounds=(lb, ub), method="bvls", tol=1e-14).x
    assert np.sum((ref <= lb + 1e-12) | (ref >= ub - 1e-12)) >= 3  # bounds matter
    Hn, gn = normal_equations(Jp, Jc, r, lam, c)
    np.testing.assert_allclose(Hn, A.T @ A, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gn, A.T @ b, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(_solve(Hn, gn, lb, ub), ref, rtol=0, atol=1e-9)
    # block pivoting from a guess of the active bounds (right, or every bound wrong), and DAQP alone
    H, g = A.T @ A, A.T @ b
    right = (ref <= lb + 1e-12, ref >= ub - 1e-12)
    wrong = (np.isfinite(lb) & ~right[0], np.zeros(30, bool))
    daqp_only = box_qp(H, g, lb, ub, pivots=0)
    import facebasis.geometry.shapemodel as sm

    monkeypatch.setattr(sm, "_daqp", None)  # pivoting alone settles (no fallback)
    for x in (box_qp(H, g, lb, ub), box_qp(H, g, lb, ub, right), box_qp(H, g, lb, ub, wrong), daqp_only):
        np.testing.assert_allclose(x, ref, rtol=0, atol=1e-9)


def test_bounds_with_a_lower_above_its_upper_are_refused_before_any_work():
    """A box whose lower bound exceeds its upper one has no point: one line naming the unknown, both in
    the QP and in the model fit (it used to return a point outside one of the bounds)."""
    from facebasis.geometry.shapemodel import box_qp, fit_shape_model

    with pytest.raises(InputError, match=r"^bounds: expected lower <= upper .*found lower 1 > upper 0 at unknown 0"):
        box_qp(np.eye(2), np.ones(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]))
    V = np.zeros((4, 3))
    with pytest.raises(InputError, match=r"^bounds: .*at unknown 1 \(1 such\)"):
        fit_shape_model(V, np.zeros((2, 4, 3)), None, None, 1.0, bounds=(np.array([0.0, 2.0]), np.array([1.0, 1.0])))


class _JumpingPlanes:
    """A scan that is two planes, ``z = 1`` for a mesh below ``z = 0.5`` (mean) and ``z = 0.3`` for one above: its
    closest points jump with the fit, so the closest-point loop cycles between the two for ever (period 2)."""

    def nearest_planes(self, P, plane=True, max_distance=np.inf):
        z = 1.0 if P[:, 2].mean() < 0.5 else 0.3
        U = P.copy()
        U[:, 2] = z
        return U, np.tile([0.0, 0.0, 1.0], (len(P), 1)), np.abs(P[:, 2] - z), np.zeros(len(P), bool)


def test_model_fit_stops_at_a_limit_cycle_and_returns_one_of_its_states():
    """The loop stops when a round returns to a state of up to CYCLE rounds before, long before its cap, and
    returns a state of the cycle (a plane), not a mix of the two."""
    from facebasis.geometry.shapemodel import CYCLE, ModelFitOptions, fit_shape_model

    x, y = np.meshgrid(np.linspace(0, 1, 8), np.linspace(0, 1, 8))
    base = np.column_stack([x.ravel(), y.ravel(), np.zeros(64)])
    bend = np.zeros((1, 64, 3))
    bend[0, :, 2] = base[:, 0] ** 2
    normals = lambda X: np.tile([0.0, 0.0, 1.0], (len(X), 1))  # noqa: E731
    fit = fit_shape_model(base, bend, _JumpingPlanes(), normals, 0.1, ModelFitOptions(scale=False, iterations=40))
    assert fit.iterations <= 2 + CYCLE < 40
    assert np.ptp(fit.vertices[:, 2]) < 1e-6 and min(abs(fit.vertices[0, 2] - 1.0), abs(fit.vertices[0, 2] - 0.3)) < 1e-6


class _FlatOrWavy:
    """A mesh below ``z = 0.5`` (mean) pairs with the plane ``z = 1``, one above with the wavy sheet
    ``z = 0.3 + 0.2 sin(3 pi y)``, which no pose and bend reach: the loop cycles between the flat mesh at 1
    (residual RMS about 0.72 against the sheet) and the sheet's best fit near 0.3 (about 0.7 against the plane)."""

    def nearest_planes(self, P, plane=True, max_distance=np.inf):
        U = P.copy()
        U[:, 2] = 1.0 if P[:, 2].mean() < 0.5 else 0.3 + 0.2 * np.sin(3 * np.pi * P[:, 1])
        return U, np.tile([0.0, 0.0, 1.0], (len(P), 1)), np.abs(P[:, 2] - U[:, 2]), np.zeros(len(P), bool)


@pytest.mark.parametrize("z0", [0.0, 0.6])
def test_model_fit_keeps_the_cycle_state_with_the_smaller_residual(z0):
    """Started on either side (so that the last state, or the one before it, is the worse one), the fit returns the
    cycle's state with the smaller residual: the fit of the wavy sheet near z = 0.3, not the plane at 1."""
    from facebasis.geometry.shapemodel import ModelFitOptions, fit_shape_model

    x, y = np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 1, 9))
    base = np.column_stack([x.ravel(), y.ravel(), np.full(81, z0)])
    bend = np.zeros((1, 81, 3))
    bend[0, :, 2] = base[:, 0] ** 2
    normals = lambda X: np.tile([0.0, 0.0, 1.0], (len(X), 1))  # noqa: E731
    fit = fit_shape_model(base, bend, _FlatOrWavy(), normals, 0.1, ModelFitOptions(scale=False, iterations=40))
    assert fit.iterations < 40
    assert abs(fit.vertices[:, 2].mean() - 0.3) < 0.1 and fit.rms < 0.71
