"""Certified weight solver (branch and bound), IPOPT formulations and the weight-problem suite."""

import numpy as np
import pytest

from facebasis.geometry.boxqp import box_qp_kkt, solve_box_qp
from facebasis.rigging.certify import brute_force_weights, certified_weights
from facebasis.rigging.weightproblem import WeightProblem
from facebasis.errors import InputError, SolverError
from facebasis.rigging.formulations import FORMULATIONS, FormulationSolver
from problems.weights_suite import closed_form_instances, weight_suite


def _certified(G, c, const, pairs=(), prior=None, lam=0.0, **kw):
    """The certified solve of one example given by its arrays (its WeightProblem checks them)."""
    return certified_weights(WeightProblem(G, c, const, pairs, prior, lam), **kw)


def _brute(G, c, const, pairs=(), prior=None, lam=0.0):
    return brute_force_weights(WeightProblem(G, c, const, pairs, prior, lam))


def _objective(x, G, c, const, prior=None, lam=0.0):
    return float(WeightProblem(G, c, const, (), prior, lam).objective(x)[0])


def test_box_qp_is_exact_on_random_problems():
    rng = np.random.default_rng(5)
    for _ in range(5):
        A = rng.standard_normal((9, 9))
        H = A @ A.T + 0.1 * np.eye(9)
        g = 3 * rng.standard_normal(9)
        sol = solve_box_qp(H, g, 0.0, 1.0)
        assert sol.kkt_residual <= 1e-10
        assert box_qp_kkt(H, g, sol.x, 0.0, 1.0) == sol.kkt_residual
        assert sol.x.min() >= 0.0 and sol.x.max() <= 1.0
        # no point of a random sample of the box does better
        samples = rng.uniform(0, 1, (2000, 9))
        f = lambda z: 0.5 * np.einsum("...i,ij,...j->...", z, H, z) + z @ g  # noqa: E731
        assert f(sol.x) <= f(samples).min() + 1e-12


@pytest.mark.parametrize("inst", closed_form_instances(), ids=lambda i: i.name)
def test_closed_form_instances_are_solved_exactly(inst):
    cs = inst.certify()
    assert cs.certified
    assert cs.objective == pytest.approx(inst.known_objective, abs=1e-12)
    assert cs.max_complementarity == 0.0 and cs.max_bound_violation == 0.0
    assert inst.objective(cs.x) == pytest.approx(cs.objective, abs=1e-12)


def test_prior_pulling_both_weights_keeps_one():
    """Closed form: G = I, no data, prior 0.9 on both, lambda 1 -> one weight 0.45, the other 0."""
    cs = _certified(np.eye(2), np.zeros(2), 0.0, [(0, 1)], prior=[0.9, 0.9], lam=1.0)
    assert sorted(cs.x.tolist()) == pytest.approx([0.0, 0.45], abs=1e-12)
    assert min(cs.x) == 0.0


def _random_instance(rng, k, pairs, lam):
    B = rng.standard_normal((3 * k, k))
    t = B @ rng.uniform(0, 1.2, k) + 0.3 * rng.standard_normal(3 * k)
    return B.T @ B, B.T @ t, float(t @ t), rng.uniform(0, 1, k), lam


@pytest.mark.parametrize("seed", range(8))
def test_branch_and_bound_agrees_with_brute_force(seed):
    rng = np.random.default_rng(seed)
    k = 10
    # disjoint pairs plus an overlapping chain (0,1), (1,2)
    pairs = [(0, 1), (1, 2), (3, 4), (5, 6), (7, 8)]
    G, c, const, prior, lam = _random_instance(rng, k, pairs, lam=[0.0, 1.0, 10.0][seed % 3])
    cs = _certified(G, c, const, pairs, prior, lam)
    x, f, branches = _brute(G, c, const, pairs, prior, lam)
    assert branches == 2 ** len(pairs)
    assert cs.certified and cs.gap <= 1e-9 * (1 + abs(f))
    assert cs.objective == pytest.approx(f, rel=1e-10, abs=1e-10)
    assert _objective(cs.x, G, c, const, prior, lam) == pytest.approx(cs.objective, rel=1e-12)
    assert cs.max_complementarity == 0.0 and cs.max_bound_violation == 0.0
    assert cs.lower_bound <= cs.objective


def test_start_point_never_makes_it_worse():
    rng = np.random.default_rng(3)
    G, c, const, prior, lam = _random_instance(rng, 8, [(0, 1), (2, 3)], 1.0)
    ref = _certified(G, c, const, [(0, 1), (2, 3)], prior, lam)
    for _ in range(5):
        cs = _certified(G, c, const, [(0, 1), (2, 3)], prior, lam, start=rng.uniform(0, 1, 8))
        assert cs.objective == pytest.approx(ref.objective, rel=1e-12)


@pytest.fixture(scope="module")
def default_suite():
    return weight_suite("default")


def test_suite_has_every_kind(default_suite):
    kinds = {i.kind for i in default_suite}
    assert len(default_suite) >= 50
    assert kinds == {"natural", "prior-both", "data-both", "near-tie", "on-bounds", "collinear", "closed-form"}
    cond = max(np.linalg.cond(i.problem.G) for i in default_suite if i.kind == "collinear")
    assert cond > 1e6  # genuinely ill-conditioned


def test_certified_is_never_worse_than_any_ipopt_formulation(default_suite):
    solvers = {}
    worse = []
    for inst in default_suite:
        cs = inst.certify()
        assert cs.certified, inst.name
        assert cs.max_complementarity == 0.0 and cs.max_bound_violation == 0.0
        for form in FORMULATIONS:
            key = (form, inst.k, inst.pairs.tobytes())
            if key not in solvers:
                solvers[key] = FormulationSolver(inst.k, inst.pairs, form)
            r = solvers[key].solve_problem(inst.problem)
            # an IPOPT answer can only be lower by being infeasible; project it onto its own branch
            # (smaller weight of each pair zeroed, clipped to the box) and compare the feasible point
            x = np.clip(r.x, 0.0, 1.0)
            if len(inst.pairs):
                P = inst.pairs
                x[np.where(x[P[:, 0]] >= x[P[:, 1]], P[:, 1], P[:, 0])] = 0.0
            if inst.objective(x) < cs.objective - 1e-9 * (1 + abs(cs.objective)):
                worse.append((inst.name, form, inst.objective(x), cs.objective))
    assert not worse


def test_polished_weight_step_is_the_certified_optimum(default_suite):
    from facebasis.rigging.weights import WeightSolver

    insts = [i for i in default_suite if i.kind == "natural"][:6]
    p = insts[0].problem
    c = np.stack([i.problem.c[0] for i in insts])
    const = np.array([i.problem.const[0] for i in insts])
    prior = np.stack([i.problem.prior[0] for i in insts])
    sol = WeightSolver(p.k, len(insts), p.pairs).solve_problem(WeightProblem(p.G, c, const, p.pairs, prior, p.lam))
    for j, inst in enumerate(insts):
        assert inst.objective(sol.weights[j]) == pytest.approx(inst.certify().objective, rel=1e-10)
    assert sol.certificate_gap <= 1e-9 * (1 + abs(sol.objective))
    assert sol.objective <= sol.ipopt_objective + 1e-9 * abs(sol.ipopt_objective)


# --- bad input -----------------------------------------------------------------------------------

def test_negative_definite_gram_is_rejected():
    with pytest.raises(InputError, match="expected positive semidefinite, found smallest eigenvalue -1"):
        _certified(-np.eye(3), np.zeros(3), 0.0, [(0, 1)])


def test_nan_data_is_rejected():
    with pytest.raises(InputError, match="expected finite Gram matrices and prior weights, found NaN/inf in c"):
        _certified(np.eye(3), [0.0, np.nan, 0.0], 0.0, [(0, 1)])
    with pytest.raises(InputError, match="expected finite Gram matrices and prior weights, found NaN/inf in G"):
        _certified(np.full((2, 2), np.nan), np.zeros(2), 0.0, [])


def test_pair_naming_one_shape_twice_is_rejected():
    with pytest.raises(InputError, match=r"a pair names one shape twice: \[\[1, 1\]\]"):
        _certified(np.eye(3), np.zeros(3), 0.0, [(0, 2), (1, 1)])


def test_other_malformed_instances():
    with pytest.raises(InputError, match=r"expected a square \(k, k\) matrix, found shape \(2, 3\)"):
        _certified(np.ones((2, 3)), np.zeros(2), 0.0, [])
    with pytest.raises(InputError, match="expected a symmetric matrix"):
        _certified(np.array([[1.0, 0.5], [0.0, 1.0]]), np.zeros(2), 0.0, [])
    with pytest.raises(InputError, match=r"expected shape indices in \[0, 2\), found \[\[0, 5\]\]"):
        _certified(np.eye(2), np.zeros(2), 0.0, [(0, 5)])
    with pytest.raises(InputError, match=r"linear terms c: expected shape \(m, 2\) \(or \(2,\) for one example\), "
                                         r"found \(3,\)"):
        _certified(np.eye(2), np.zeros(3), 0.0, [])
    with pytest.raises(InputError, match=r"prior: expected shape \(1, 2\) or None, found \(1, 3\)"):
        _certified(np.eye(2), np.zeros(2), 0.0, [], prior=np.zeros(3))
    with pytest.raises(InputError, match="lambda: expected >= 0, found -1"):
        _certified(np.eye(2), np.zeros(2), 0.0, [], lam=-1.0)
    with pytest.raises(InputError, match="lambda: expected a finite number, found inf"):
        _certified(np.eye(2), np.zeros(2), 0.0, [], lam=np.inf)
    with pytest.raises(InputError, match="formulation: expected one of"):
        FormulationSolver(2, [(0, 1)], "magic")


def test_tree_size_limit_raises_instead_of_answering_uncertified():
    rng = np.random.default_rng(0)
    k = 16
    pairs = [(2 * i, 2 * i + 1) for i in range(8)]
    G, c, const, _, _ = _random_instance(rng, k, pairs, 0.0)
    with pytest.raises(SolverError, match="exceeded 1 nodes"):
        _certified(G, c, const, pairs, np.full(k, 0.9), 100.0, max_nodes=1)


def test_one_definition_of_the_residuals_serves_single_examples_and_batches():
    from facebasis.rigging.certify import WeightInstance
    from facebasis.rigging.weightproblem import bound_violation, complementarity_violation

    P = np.array([[0, 1], [2, 3]])
    X = np.array([[0.5, 0.2, 0.0, 1.0], [0.0, 0.9, 1.2, 0.3]])
    assert complementarity_violation(X, P) == pytest.approx(0.36)          # 1.2 * 0.3
    assert complementarity_violation(X[0], P) == pytest.approx(0.1)        # 0.5 * 0.2
    assert complementarity_violation(X, np.zeros((0, 2), int)) == 0.0
    assert bound_violation(X) == pytest.approx(0.2) and bound_violation(X[0]) == 0.0
    inst = WeightInstance.make("t", "test", np.eye(4), np.ones(4), 4.0, np.zeros(4), 0.0, P)
    assert inst.problem.complementarity(X[1]) == pytest.approx([0.36])
    assert inst.problem.bounds(X[1]) == pytest.approx([0.2])
    assert inst.objective(np.ones(4)) == pytest.approx(4 - 8 + 4)
    # the batched problem gives the same numbers row by row
    from facebasis.rigging.weightproblem import WeightProblem

    batch = WeightProblem(np.eye(4), np.ones((2, 4)), [4.0, 4.0], P)
    assert batch.complementarity(X) == pytest.approx([0.1, 0.36]) and batch.bounds(X) == pytest.approx([0.0, 0.2])
