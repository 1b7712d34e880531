"""The eq. 5 weight problem type (WeightProblem) and its solutions (WeightSolution)."""

import dataclasses

import numpy as np
import pytest

from facebasis.errors import InputError
from facebasis.rigging.certify import CertifiedWeightSolver, brute_force_weights, certified_weights, certify_problem
from facebasis.rigging.weightproblem import (WeightProblem, WeightSolution, bound_violation, check_pairs,
                                             complementarity_violation)

PAIRS = [(0, 1), (1, 2), (3, 4), (5, 6)]  # a chain (0,1), (1,2) and two disjoint pairs


def random_problem(rng, k=8, m=3, lam=2.0, pairs=PAIRS):
    """Eq. 5 from explicit blendshapes B (3n, k) and targets T (m, 3n); returns (problem, B, T)."""
    B = rng.standard_normal((5 * k, k))
    T = rng.uniform(0, 1.2, (m, k)) @ B.T + 0.3 * rng.standard_normal((m, 5 * k))
    prior = rng.uniform(0, 1, (m, k))
    return WeightProblem(B.T @ B, T @ B, np.einsum("ij,ij->i", T, T), pairs, prior, lam), B, T


# --- construction checks ---------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs,message", [
    (dict(G=np.ones((2, 3))), r"Gram matrix G: expected a square \(k, k\) matrix, found shape \(2, 3\)"),
    (dict(c=np.zeros((2, 4))), r"linear terms c: expected shape \(m, 3\) \(or \(3,\) for one example\), found \(2, 4\)"),
    (dict(const=np.zeros(3)), r"constants const: expected shape \(2,\), found \(3,\)"),
    (dict(prior=np.zeros((2, 2))), r"prior: expected shape \(2, 3\) or None, found \(2, 2\)"),
    (dict(prior=np.full((2, 3), np.nan)), "expected finite Gram matrices and prior weights, found NaN/inf in prior"),
    (dict(c=np.array([[0.0, np.inf, 0.0], [0.0, 0.0, 0.0]])), "found NaN/inf in c"),
    (dict(G=np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),
     r"expected a symmetric matrix, found an asymmetric one \(largest \|G - G\^T\| 0.5\)"),
    (dict(G=-np.eye(3), lam=0.0), "expected positive semidefinite, found smallest eigenvalue -1"),
    (dict(lam=-0.5), "lambda: expected >= 0, found -0.5"),
    (dict(lam=np.nan), "lambda: expected a finite number, found nan"),
    (dict(pairs=[(0, 3)]), r"exclusive pairs: expected shape indices in \[0, 3\), found \[\[0, 3\]\]"),
    (dict(pairs=[(-1, 2)]), r"exclusive pairs: expected shape indices in \[0, 3\), found \[\[-1, 2\]\]"),
    (dict(pairs=[(0, 1), (2, 2)]), r"exclusive pairs: a pair names one shape twice: \[\[2, 2\]\]"),
    (dict(pairs=[(0, 1, 2)]), r"exclusive pairs: expected \(P, 2\) shape index pairs, found an array of shape \(1, 3\)"),
    (dict(pairs=[(0.0, 1.5)]), r"exclusive pairs: expected integer shape indices, found \[\[0.0, 1.5\]\]"),
])
def test_bad_problems_are_rejected_when_made(kwargs, message):
    args = dict(G=np.eye(3), c=np.zeros((2, 3)), const=np.zeros(2), pairs=[(0, 1)], prior=None, lam=1.0)
    args.update(kwargs)
    with pytest.raises(InputError, match=message):
        WeightProblem(**args)


def test_pairs_given_as_whole_floats_or_empty_are_accepted():
    assert check_pairs(np.array([[0.0, 2.0]]), 3).tolist() == [[0, 2]]
    assert check_pairs([], 3).shape == (0, 2)
    assert WeightProblem(np.eye(2), np.zeros(2), 0.0).pairs.shape == (0, 2)


def test_weights_of_the_wrong_shape_and_bad_free_masks_are_rejected():
    p, _, _ = random_problem(np.random.default_rng(0))
    with pytest.raises(InputError, match=r"weights: expected shape \(3, 8\), found \(8,\)"):
        p.objective(np.zeros(8))
    with pytest.raises(InputError, match=r"weights: expected shape \(3, 8\), found \(2, 8\)"):
        p.complementarity(np.zeros((2, 8)))
    with pytest.raises(InputError, match=r"free shapes: expected a \(8,\) bool array, found shape \(7,\)"):
        p.restrict(np.ones(7, bool))


def test_derived_problems_share_the_checked_data():
    p, _, _ = random_problem(np.random.default_rng(1))
    one = p.example(1)
    assert one.m == 1 and one.hessian is p.hessian and one.G is p.G
    assert one.objective(p.c[1] * 0) == pytest.approx(p.objective(np.zeros((3, 8)))[1], rel=1e-15)
    with pytest.raises(InputError, match=r"linear terms c: expected shape \(m, 8\)"):
        p.with_examples(np.zeros(5), 0.0)


# --- the objective and the residuals ---------------------------------------------------------------

@pytest.mark.parametrize("seed", range(4))
def test_objective_equals_a_dense_evaluation_of_eq5(seed):
    rng = np.random.default_rng(seed)
    lam = [0.0, 0.5, 3.0, 100.0][seed]
    p, B, T = random_problem(rng, lam=lam)
    X = rng.uniform(-0.2, 1.2, (3, 8))  # also outside the box: the objective does not care
    direct = np.sum((X @ B.T - T) ** 2, axis=1) + lam * np.sum((X - p.prior) ** 2, axis=1)
    np.testing.assert_allclose(p.objective(X), direct, rtol=1e-10)
    assert p.total_objective(X) == pytest.approx(direct.sum(), rel=1e-10)
    # one example's problem is the same objective
    assert p.example(2).objective(X[2])[0] == pytest.approx(direct[2], rel=1e-10)


def test_objective_of_a_rig_problem_equals_the_vertex_residuals():
    from facebasis.defaults.face import default_template

    rig = default_template()
    rng = np.random.default_rng(7)
    T = rig.evaluate(rng.uniform(0, 1, (4, rig.n_shapes))) + 0.01 * rng.standard_normal((4, rig.n_vertices, 3))
    prior = rng.uniform(0, 1, (4, rig.n_shapes))
    p = WeightProblem.from_rig(rig, T, [(0, 1)], prior, 5.0)
    X = rng.uniform(0, 1, (4, rig.n_shapes))
    direct = ((rig.evaluate(X) - T) ** 2).sum(axis=(1, 2)) + 5.0 * ((X - prior) ** 2).sum(axis=1)
    np.testing.assert_allclose(p.objective(X), direct, rtol=1e-9)
    with pytest.raises(InputError, match=rf"expressions: expected shape \(m, {rig.n_vertices}, 3\), found \(4, 5, 3\)"):
        WeightProblem.from_rig(rig, np.zeros((4, 5, 3)))


def test_residuals_per_example_and_overall():
    p, _, _ = random_problem(np.random.default_rng(2))
    X = np.zeros((3, 8))
    X[0, [0, 1]] = 0.5, 0.4          # pair (0, 1) breached: 0.2
    X[1, [1, 2]] = 0.9, 0.3          # pair (1, 2) breached: 0.27
    X[1, 7] = 1.25                   # above the box by 0.25
    X[2, 5] = -0.1                   # below it by 0.1
    np.testing.assert_allclose(p.complementarity(X), [0.2, 0.27, 0.0])
    np.testing.assert_allclose(p.bounds(X), [0.0, 0.25, 0.1])
    assert complementarity_violation(X, p.pairs) == pytest.approx(0.27)
    assert bound_violation(X) == pytest.approx(0.25)


def test_a_solution_takes_its_residuals_from_its_problem():
    p, _, _ = random_problem(np.random.default_rng(3))
    sol = certify_problem(p)
    assert sol.problem is p and sol.weights is sol.X
    assert sol.max_complementarity == 0.0 and sol.max_bound_violation == 0.0
    assert sol.objective == pytest.approx(p.total_objective(sol.X), rel=1e-15)
    # breach a pair: the solution reports that product, from the problem's pairs
    X = sol.X.copy()
    X[2, 3], X[2, 4] = 0.7, 0.4
    breached = dataclasses.replace(sol, X=X)
    assert breached.max_complementarity == pytest.approx(0.28)
    np.testing.assert_allclose(breached.objectives, p.objective(X))
    # the same weights against a problem without that pair: no breach
    q = WeightProblem(p.G, p.c, p.const, [(0, 1)], p.prior, p.lam)
    assert WeightSolution(q, X).max_complementarity == 0.0
    # IPOPT's fields: NaN when IPOPT did not run, from the problem when it did
    assert np.isnan(sol.ipopt_objective) and np.isnan(sol.ipopt_max_complementarity)
    assert np.isnan(sol.ipopt_weights).all()
    withipopt = dataclasses.replace(sol, ipopt_X=X)
    assert withipopt.ipopt_max_complementarity == pytest.approx(0.28)
    assert withipopt.ipopt_objective == pytest.approx(p.total_objective(X), rel=1e-15)


def test_a_certified_solution_takes_its_residuals_from_its_problem():
    p, _, _ = random_problem(np.random.default_rng(4), m=1)
    cs = certified_weights(p)
    assert cs.certified and cs.problem.m == 1
    assert cs.max_complementarity == 0.0 and cs.max_bound_violation == 0.0
    x = cs.x.copy()
    x[:3] = 1.5, 0.5, 0.0              # pair (0, 1): 0.75, (1, 2): 0
    x[5], x[6] = 0.5, 0.5              # pair (5, 6): 0.25
    bad = dataclasses.replace(cs, x=x)
    assert bad.max_complementarity == pytest.approx(0.75)
    assert bad.max_bound_violation == pytest.approx(0.5)


# --- solving -------------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(6))
def test_certified_solution_is_never_worse_than_brute_force(seed):
    rng = np.random.default_rng(10 + seed)
    p, _, _ = random_problem(rng, k=8, m=3, lam=[0.0, 1.0, 10.0][seed % 3])
    sol = certify_problem(p)
    assert sol.max_complementarity == 0.0 and sol.max_bound_violation == 0.0
    for j in range(p.m):
        x, f, branches = brute_force_weights(p.example(j))
        assert branches == 2 ** len(PAIRS)
        assert sol.objectives[j] <= f + 1e-9 * (1 + abs(f))
        assert sol.objectives[j] == pytest.approx(f, rel=1e-9, abs=1e-9)
        assert p.objective(np.tile(x, (p.m, 1)))[j] == pytest.approx(f, rel=1e-10, abs=1e-10)


def test_held_weights_stay_at_zero_and_the_restricted_objective_is_the_full_one():
    rng = np.random.default_rng(21)
    p, _, _ = random_problem(rng, k=8, m=3, lam=4.0)
    free = np.ones(8, bool)
    free[[1, 6]] = False
    sub, idx = p.restrict(free)
    assert idx.tolist() == [0, 2, 3, 4, 5, 7]
    assert sub.pairs.tolist() == [[2, 3]]            # only (3, 4) keeps both shapes: new indices 2, 3
    X = np.zeros((3, 8))
    X[:, idx] = rng.uniform(0, 1, (3, 6))
    np.testing.assert_allclose(sub.objective(X[:, idx]), p.objective(X), rtol=1e-12)
    sol = certify_problem(p, free=free)
    assert np.all(sol.X[:, ~free] == 0.0) and sol.max_complementarity == 0.0
    for j in range(p.m):
        _, f, _ = brute_force_weights(sub.example(j))
        assert sol.objectives[j] == pytest.approx(f, rel=1e-9, abs=1e-9)
    # the other solve of the weight step (IPOPT, polished) gives the same weights
    from facebasis.rigging.weights import WeightSolver

    same = WeightSolver(p.k, p.m, p.pairs).solve_problem(p, free=free)
    np.testing.assert_allclose(same.X, sol.X, atol=1e-12)


def test_solvers_of_one_problem_agree():
    from facebasis.rigging.weights import WeightSolver

    rng = np.random.default_rng(5)
    p, _, _ = random_problem(rng, k=7, m=2, lam=1.0, pairs=[(0, 1), (2, 3)])
    by_example = CertifiedWeightSolver(p).solve_all()
    ipopt = WeightSolver(p.k, p.m, p.pairs).solve_problem(p)
    assert ipopt.problem is p and ipopt.ipopt_X is not None
    for j, cs in enumerate(by_example):
        assert ipopt.objectives[j] == pytest.approx(cs.objective, rel=1e-10)
    with pytest.raises(InputError, match=r"weight step: expected a problem of 2 examples, 7 shapes and the pairs "
                                         r"\[\[0, 1\], \[2, 3\]\], found 2, 7 and \[\[0, 1\]\]"):
        WeightSolver(p.k, p.m, p.pairs).solve_problem(WeightProblem(p.G, p.c, p.const, [(0, 1)], p.prior, p.lam))


def test_cancel_pairs_is_provably_suboptimal_on_two_shapes():
    """Two correlated shapes, one exclusive pair: without the pair the optimum is x = G^-1 c =
    (0.787, 0.427); cancel-pairs zeroes the smaller x_1 and keeps x_0 = c_0 / G_00 = 1, objective
    -c_0^2 / G_00 = -1; the optimum keeps x_1 = c_1 / G_11 = 0.525 instead, objective -1.1025."""
    from facebasis.rigging.certify import certified_weights
    from facebasis.rigging.formulations import cancel_pairs

    G = np.array([[1.0, 0.5], [0.5, 4.0]])
    c = np.array([1.0, 2.1])
    problem = WeightProblem(G, c, 0.0, [(0, 1)])
    heur = cancel_pairs(problem)
    np.testing.assert_allclose(heur.x, [1.0, 0.0], atol=1e-12)
    assert heur.objective == pytest.approx(-1.0, abs=1e-12) and heur.iterations == 2
    opt = certified_weights(problem)
    np.testing.assert_allclose(opt.x, [0.0, 0.525], atol=1e-9)
    assert opt.objective == pytest.approx(-1.1025, abs=1e-9) and opt.objective < heur.objective - 0.1
    assert heur.max_complementarity == 0.0 and heur.max_bound_violation == 0.0
    free = cancel_pairs(WeightProblem(G, c, 0.0, []))  # no pairs: one exact box QP
    np.testing.assert_allclose(free.x, np.linalg.solve(G, c), atol=1e-12)
    with pytest.raises(InputError, match="cancel-pairs: expected one example, found 2"):
        cancel_pairs(WeightProblem(G, np.stack([c, c]), np.zeros(2), [(0, 1)]))


def test_an_independent_miqp_referee_agrees_on_the_closed_form_instances():
    """Optional (never a CI dependency): Gurobi's SOS1 branch and bound, where gurobipy is installed,
    reaches the certified optimum of every closed-form instance."""
    pytest.importorskip("gurobipy")
    from problems.independent import referee
    from problems.weights_suite import closed_form_instances

    rows = referee(closed_form_instances())
    assert all(r["agree"] and r["status"] == "optimal" for r in rows), rows
    with pytest.raises(InputError, match="--independent: expected one of gurobi, found 'cplex'"):
        referee(closed_form_instances(), "cplex")
