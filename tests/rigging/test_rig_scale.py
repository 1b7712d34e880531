"""§3: the faster paths give the results of the previous ones (direct Cholesky basis step, the
certified weight step without IPOPT, IPOPT's role)."""

import numpy as np
import pytest

from facebasis.rigging.generation import BlendshapeGenerator
from facebasis.rigging.problem import GenerationOptions
from facebasis.rigging.basis import basis_energies, basis_step, use_direct
from facebasis.rigging.synthetic import default_face_problem
from facebasis.rigging.certify import certify_problem
from facebasis.rigging.weightproblem import WeightProblem
from facebasis.rigging.weights import WeightSolver


@pytest.mark.parametrize("k,m", [(9, 5), (9, 6), (9, 20)])
def test_direct_and_woodbury_basis_steps_agree(k, m):
    rng = np.random.default_rng(m)
    X = rng.uniform(0, 1, (k, m))
    R, At = rng.standard_normal((m, 6, 700)), rng.standard_normal((k, 6, 700))
    w = rng.uniform(1, 100, (700, k))
    Y = basis_step(X, R, At, w, 0.2)
    ref = np.empty_like(At)
    for t in range(700):
        ref[:, :, t] = np.linalg.solve(X @ X.T + 0.2 * np.diag(w[t]), X @ R[:, :, t] + 0.2 * w[t][:, None] * At[:, :, t])
    assert np.allclose(Y, ref, rtol=1e-10, atol=1e-12)
    assert use_direct(k, m) == (m >= 0.6 * k)


def test_certified_weight_step_equals_ipopt_then_polish():
    rng = np.random.default_rng(0)
    k, m = 8, 6
    B = rng.standard_normal((40, k))
    T = rng.standard_normal((40, m))
    prior = rng.uniform(0, 1, (m, k))
    pairs = [(0, 1), (2, 3)]
    problem = WeightProblem(B.T @ B, (B.T @ T).T, (T * T).sum(0), pairs, prior, 2.0)
    a = certify_problem(problem)
    b = WeightSolver(k, m, pairs).solve_problem(problem)
    assert np.allclose(a.weights, b.weights, atol=1e-9) and a.objective == pytest.approx(b.objective, rel=1e-12)
    assert a.ipopt_status == "not run" and a.ipopt_iterations == 0 and np.isnan(a.ipopt_objective)
    # held weights: exactly 0, the pairs of the others remapped
    free = np.array([True, False, True, True, True, True, False, True])
    X = certify_problem(problem, free=free).X
    assert (X[:, ~free] == 0).all() and (X[:, 2] * X[:, 3] == 0).all()
    c = WeightSolver(k, m, pairs).solve_problem(problem, free=free)
    assert np.allclose(c.weights, X, atol=1e-9)


def test_ipopt_modes_give_the_same_rig():
    pp = default_face_problem(seed=2, n_train=8)
    runs = {mode: BlendshapeGenerator(pp.problem, GenerationOptions(iterations=3, ipopt=mode)).run()
            for mode in ("every", "final", "never")}
    ref = runs["every"]
    for mode, res in runs.items():
        assert np.abs(res.weights - ref.weights).max() <= 1e-9
        assert np.abs(res.rig.deltas - ref.rig.deltas).max() <= 1e-9 * np.abs(ref.rig.deltas).max()
    assert [h.ipopt_status for h in runs["final"].history][:2] == ["not run", "not run"]
    assert runs["final"].history[-1].ipopt_iterations > 0 and all(h.ipopt_iterations for h in ref.history)
    assert all(h.ipopt_iterations == 0 for h in runs["never"].history)


@pytest.mark.parametrize("k,m,exact", [(9, 5, False), (9, 20, False), (9, 20, True)])
def test_basis_step_energies_equal_the_residual_form(k, m, exact):
    """E_fit and E_reg of the basis step (from the solved system) equal eq. 2 and 3 evaluated at its
    answer, also when the examples are fitted exactly (E_fit ~ 0: the residual form is used)."""
    rng = np.random.default_rng(k + m)
    X = rng.uniform(0, 1, (k, m))
    At = rng.standard_normal((k, 6, 300))
    w = rng.uniform(1, 100, (300, k))
    # exact: the training rows are the prior's combinations, so Y = A~ fits them with E_fit = 0
    R = np.einsum("km,kct->mct", X, At) if exact else rng.standard_normal((m, 6, 300))
    Y, e_fit, e_reg = basis_step(X, R, At, w, 0.2, energies=True)
    ref_fit, ref_reg = basis_energies(X, R, At, w, Y)
    assert e_fit == pytest.approx(ref_fit, rel=1e-9, abs=1e-20) and e_reg == pytest.approx(ref_reg, rel=1e-9, abs=1e-20)
    assert e_fit >= 0.0
    if exact:
        assert e_fit < 1e-20 and np.allclose(Y, At, atol=1e-12)
