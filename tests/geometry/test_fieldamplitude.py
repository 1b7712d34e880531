"""The detail field's deviation over the skin from the modes-only fit's residuals and then the fitted field
(geometry/fieldamplitude.py, eqs. D5-D6).

Tiny data built here: the built-in default face with smooth random identity modes and a field of bumps on its front
(tests/geometry/test_detailprior.py's person).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import check_detail_choice_flag
from test_detailprior import person_parts

from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.detailprior import DetailPriorOptions
from facebasis.geometry.fieldamplitude import FLOOR, residual_weights
from facebasis.geometry.nricp import NonRigidICP
from facebasis.geometry.registration import Registration, RegistrationOptions
from facebasis.geometry.shapemodel import ShapeBasis


def _grid(n=30):
    x, y = np.meshgrid(np.linspace(0, 10, n), np.linspace(0, 10, n))
    return np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)


def test_weights_follow_the_residuals_local_variance():
    X = _grid()
    idx = np.arange(0, len(X), 2)
    # the same residual everywhere: the stationary field (w = 1 exactly)
    assert np.allclose(residual_weights(X, idx, np.full(len(idx), 0.3), 1.0), 1.0)
    # no residual left, or no pairs: the stationary field
    assert np.array_equal(residual_weights(X, idx, np.zeros(len(idx)), 1.0), np.ones(len(X)))
    assert np.array_equal(residual_weights(X, idx[:0], np.zeros(0), 1.0), np.ones(len(X)))
    # residuals on the left half ten times those on the right: the field's deviation follows them
    r = np.where(X[idx, 0] < 5, 1.0, 0.1) * np.random.default_rng(0).choice([-1, 1], len(idx))
    w = residual_weights(X, idx, r, 1.0)
    left, right = X[:, 0] < 3, X[:, 0] > 7
    assert w[left].min() > 1.2 and w[right].max() < 0.5 and w.min() >= FLOOR
    assert np.mean(w[w > FLOOR] ** 2) == pytest.approx(np.mean(w ** 2))  # the floor does not act here
    assert np.mean(w ** 2) == pytest.approx(1.0)
    # far from every pair (a socket's inside): the mean deviation (the pseudo-count)
    Y = np.concatenate([X, [[5.0, 5.0, 50.0]]])
    assert residual_weights(Y, idx, r, 1.0)[-1] == pytest.approx(1.0, rel=0.05)
    # sampled: deterministic
    assert np.array_equal(residual_weights(X, idx, r, 1.0, samples=100), residual_weights(X, idx, r, 1.0, samples=100))


def test_the_last_rounds_of_the_joint_fit_follow_the_field():
    from facebasis.geometry.fieldamplitude import ROUNDS, split_rounds

    assert split_rounds(20) == (20 - ROUNDS, ROUNDS) and split_rounds(7) == (4, 3) and split_rounds(1) == (1, 0)
    assert all(sum(split_rounds(n)) == n and split_rounds(n)[1] <= n // 2 for n in range(2, 60))


def _register(person, T, F, D, how):
    from test_shapemodel import as_scan

    S, G, R, t = as_scan(person, F, seed=1)
    basis = ShapeBasis(tuple(f"m{j}" for j in range(len(D))), D, "test")
    res = Registration(T, F, RegistrationOptions(after_model="normal", detail=DetailPriorOptions(amplitude_map=how)),
                       identity=basis).register(S, G)
    err = np.linalg.norm(res.vertices - (person @ R.T + t), axis=1)
    return np.median(err), np.percentile(err, 95), np.sqrt(np.mean(err ** 2))


def test_a_field_where_the_modes_miss_slides_the_points_less():
    """The person's detail lies on the front only; with the same deviation everywhere the modes share it and the
    field undoes their side effects on the back, where the points slide."""
    T, F, D, c, _, f, _ = person_parts()
    normals = NonRigidICP(F, len(T)).vertex_normals
    person = T + np.tensordot(c, D, 1)
    person = person + f[:, None] * normals(person)
    out = {how: _register(person, T, F, D, how) for how in ("uniform", "residual", "field")}
    # measured (uniform -> residual, eq. D5 -> field, eqs. D5-D6, the default): median 0.0026 -> 0.0012 -> 0.0007 cm,
    # p95 0.0131 -> 0.0032 -> 0.0038, RMS 0.0058 -> 0.0018 -> 0.0017
    for how in ("residual", "field"):
        assert out[how][2] < 0.7 * out["uniform"][2]
        assert out[how][0] < 0.7 * out["uniform"][0] and out[how][1] < 0.8 * out["uniform"][1]
    assert out["field"][0] < out["residual"][0]


def test_a_person_within_the_space_is_fitted_as_before():
    """Where the evidence finds no detail above the scan's noise, neither eq. D5 nor D6 runs: the fit is the uniform
    field's (eq. D5 on pure noise had weights 0.8-1.3 and moved a noisy in-space neutral by 20 %, review9)."""
    T, F, D, c, _, _, _ = person_parts()
    person = T + np.tensordot(c, D, 1)
    out = {how: _register(person, T, F, D, how) for how in ("uniform", "field")}
    np.testing.assert_allclose(out["field"], out["uniform"], rtol=0, atol=1e-12)


@pytest.mark.parametrize("value", ["local", None, 1])
def test_bad_amplitude_map_is_refused(value):
    with pytest.raises(InputError, match=r"detail\.amplitude_map: expected one of field, residual, uniform, found "):
        DetailPriorOptions(amplitude_map=value)


def test_cli_detail_amplitude_map_bad_value_repeat_without_the_prior_and_reaching_the_registration(tmp_path, capsys,
                                                                                                   monkeypatch):
    check_detail_choice_flag(main, tmp_path, capsys, monkeypatch, "--detail-amplitude-map", "amplitude_map", "local",
                             ("field", "residual", "uniform"))
