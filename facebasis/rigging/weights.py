"""The weight step of example-based generation (Gao et al. 2015, eq. 5), in CasADi, solved by IPOPT.

For training expressions j = 1..m with target deltas ``t_j = T_j - B_0`` (3n,) and blendshape
deltas ``B`` (3n, k), find weights ``x_j`` (k,) minimising

    sum_j || B x_j - t_j ||^2 + lambda sum_j || x_j - x~_j ||^2          (eq. 5)
    s.t.  0 <= x_ij <= 1,   x_aj * x_bj = 0  for every exclusive pair (a, b).

Only Gram quantities enter: ``||B x - t||^2 = x^T G x - 2 c^T x + t^T t`` with ``G = B^T B``
(k, k) and ``c_j = B^T t_j`` (method.md: a model built on per-vertex residuals is orders of
magnitude slower). The CasADi problem is built once, symbolic in ``G``, ``C``, ``X~`` and
``lambda`` (its parameters), and reused for every alternation.

The complementarity constraint violates the usual constraint qualifications, so IPOPT can stop a
little off the constraint set, or at a non-optimal point. Each IPOPT answer is therefore
*polished* by the certified solver of :mod:`facebasis.rigging.certify`: per example, branch and bound over
the pairs, seeded with IPOPT's branch, every box-QP solved exactly. The polished point satisfies
the bounds and every complementarity constraint exactly, is a certified global optimum of each
example's problem and is never worse than IPOPT's; IPOPT's status, its raw answer and the
certificate (nodes, gap, KKT residual) are all reported.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .certify import CertifiedWeightSolver, bound_violation, complementarity_violation  # noqa: F401 (re-exported)
from ..errors import InputError, SolverError
from ..interrupt import interruptible

#: IPOPT return statuses that count as a successful solve.
IPOPT_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@dataclass(frozen=True)
class WeightSolution:
    """Result of one weight step.

    Attributes
    ----------
    weights : (m, k) solved weights (after polishing, if enabled)
    objective : float, eq. 5 objective at ``weights`` (including the constant ``sum t^T t``)
    ipopt_status : IPOPT's own return status string
    ipopt_iterations : IPOPT iteration count
    ipopt_success : whether the status is one of :data:`IPOPT_OK`
    ipopt_weights : (m, k) IPOPT's raw answer
    ipopt_objective : eq. 5 objective at the raw answer
    max_complementarity : max |x_a x_b| over pairs and examples, at ``weights``
    max_bound_violation : max violation of 0 <= x <= 1 at ``weights``
    ipopt_max_complementarity, ipopt_max_bound_violation : the same at IPOPT's raw answer
    kkt_residual : max KKT residual of the optimal branches' box-QPs (0 if not polished)
    polished : whether ``weights`` come from the certified polish
    seconds : wall time of IPOPT + polish
    certificate_nodes : box-QPs solved by branch and bound over all examples
    certificate_gap : largest ``objective - lower bound`` over the examples (NaN if not polished)
    """

    weights: np.ndarray
    objective: float
    ipopt_status: str
    ipopt_iterations: int
    ipopt_success: bool
    ipopt_weights: np.ndarray
    ipopt_objective: float
    max_complementarity: float
    max_bound_violation: float
    ipopt_max_complementarity: float
    ipopt_max_bound_violation: float
    kkt_residual: float
    polished: bool
    seconds: float
    certificate_nodes: int = 0
    certificate_gap: float = float("nan")


def gram_data(rig, expressions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Gram quantities of eq. 5 for expressions (m, n, 3) against a rig's blendshapes:
    ``G = B^T B`` (k, k), ``C = B^T t_j`` (k, m) and ``const = t_j^T t_j`` (m,), with
    ``t_j = T_j - B_0`` flattened; BLAS on one thread (its spinning threads cost more than they
    gain for these sizes on a shared machine)."""
    from threadpoolctl import threadpool_limits

    T = (np.asarray(expressions, np.float64) - rig.neutral).reshape(len(expressions), -1)
    B = rig.deltas.reshape(rig.n_shapes, -1)
    with threadpool_limits(1):
        G, C = B @ B.T, B @ T.T
    return G, C, np.einsum("ij,ij->i", T, T)


def eq5_objective(X, G, C, const, X_prior, lam) -> float:
    """Eq. 5 objective for weights X (m, k), G (k, k), C (k, m), const (m,) = t_j^T t_j."""
    X = np.asarray(X, float)
    data = np.einsum("jk,kl,jl->", X, G, X) - 2.0 * np.einsum("kj,jk->", C, X) + float(np.sum(const))
    return float(data + lam * np.sum((X - X_prior) ** 2))




class WeightSolver:
    """CasADi/IPOPT model of eq. 5 for m examples and k shapes, built once, solved many times.

    Parameters
    ----------
    n_shapes : k
    n_examples : m
    pairs : sequence of (a, b) shape indices that are mutually exclusive
    ipopt_options : extra IPOPT options (``tol``, ``max_iter``, ...)
    polish : replace every answer by the certified global optimum of each example (branch and bound)
    """

    def __init__(self, n_shapes: int, n_examples: int, pairs=(), ipopt_options: dict | None = None,
                 polish: bool = True):
        import casadi as ca

        self.k, self.m = int(n_shapes), int(n_examples)
        P = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if len(P) and (P.min() < 0 or P.max() >= self.k):
            raise InputError(f"exclusive pairs: expected shape indices in [0, {self.k}), found {P.tolist()}")
        if len(P) and np.any(P[:, 0] == P[:, 1]):
            raise InputError(f"exclusive pairs: a pair names one shape twice: {P[P[:, 0] == P[:, 1]].tolist()}")
        self.pairs = P
        self.polish = polish
        k, m = self.k, self.m
        # matrix-level MX graph: its size does not grow with k^2 m, so building is fast
        x = ca.MX.sym("x", k * m)            # x_j = x[j*k : (j+1)*k]
        G = ca.MX.sym("G", k, k)
        C = ca.MX.sym("C", k, m)
        Xp = ca.MX.sym("Xp", k, m)
        lam = ca.MX.sym("lam")
        Xm = ca.reshape(x, k, m)
        # eq. 5: sum_j ||B x_j - t_j||^2 - t_j^T t_j = sum_j x_j^T G x_j - 2 c_j^T x_j,
        #        plus the prior lambda sum_j ||x_j - x~_j||^2
        f = ca.sum1(ca.sum2(Xm * ca.mtimes(G, Xm))) - 2 * ca.sum1(ca.sum2(C * Xm)) + lam * ca.sumsqr(Xm - Xp)
        p = ca.vertcat(ca.vec(G), ca.vec(C), ca.vec(Xp), lam)
        nlp = {"x": x, "p": p, "f": f}
        if len(P):
            # eq. 5 complementarity: x_aj * x_bj = 0 for every exclusive pair (a, b) and example j
            nlp["g"] = ca.vec(Xm[P[:, 0].tolist(), :] * Xm[P[:, 1].tolist(), :])
        self.n_constraints = len(P) * m
        opts = {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10,
                                               "max_iter": 3000, "acceptable_tol": 1e-7,
                                               # warm starts stay near the bounds: on the ICT
                                               # problem 37 instead of 54 iterations per solve
                                               "mu_strategy": "adaptive", "mu_init": 1e-4,
                                               "bound_push": 1e-5, "bound_frac": 1e-5}}
        opts["ipopt"].update(ipopt_options or {})
        self._nlp = nlp
        self._solver = ca.nlpsol("weights", "ipopt", nlp, opts)

    def solve(self, G, C, const, X_prior, lam: float, X0=None, free=None) -> WeightSolution:
        """Solve eq. 5.

        Parameters
        ----------
        G : (k, k) Gram matrix ``B^T B``
        C : (k, m) ``B^T t_j`` for every example
        const : (m,) ``t_j^T t_j``
        X_prior : (m, k) rough weights ``x~``
        lam : prior weight lambda >= 0
        X0 : (m, k) starting point (default: ``X_prior`` clipped to [0, 1])
        free : optional (k,) bool, the weights that may be nonzero (the others are fixed at 0)

        Raises
        ------
        SolverError
            IPOPT fails and no polish is requested; the message carries IPOPT's status.
        """
        import time

        t0 = time.perf_counter()
        k, m = self.k, self.m
        G = np.asarray(G, float)
        C = np.asarray(C, float)
        X_prior = np.asarray(X_prior, float)
        if G.shape != (k, k) or C.shape != (k, m) or X_prior.shape != (m, k):
            raise InputError(f"weight step: expected G {(k, k)}, C {(k, m)}, prior {(m, k)}, found "
                             f"{G.shape}, {C.shape}, {X_prior.shape}")
        if not (np.isfinite(G).all() and np.isfinite(C).all() and np.isfinite(X_prior).all()):
            raise InputError("weight step: expected finite Gram matrices and prior weights, found NaN/inf")
        if lam < 0:
            raise InputError(f"lambda: expected >= 0, found {lam}")
        x0 = np.clip(X_prior if X0 is None else X0, 0.0, 1.0)
        ub = 1.0
        if free is not None:
            ub = np.broadcast_to(np.where(np.asarray(free, bool), 1.0, 0.0), (m, k))
            x0 = np.minimum(x0, ub)
            ub = ub.ravel()
        p = np.concatenate([G.ravel(order="F"), C.ravel(order="F"), X_prior.T.ravel(order="F"), [lam]])
        args = {"x0": x0.ravel(), "p": p, "lbx": 0.0, "ubx": ub}
        if self.n_constraints:
            args.update(lbg=0.0, ubg=0.0)
        with interruptible():  # IPOPT would turn Ctrl-C into a failure status and carry on
            sol = self._solver(**args)
        stats = self._solver.stats()
        status = str(stats.get("return_status", "unknown"))
        iters = int(stats.get("iter_count", -1))
        X_ipopt = np.asarray(sol["x"]).reshape(m, k)
        ok = status in IPOPT_OK
        const = np.asarray(const, float)
        obj_ipopt = eq5_objective(X_ipopt, G, C, const, X_prior, lam)
        X, kkt, nodes, gap = X_ipopt, 0.0, 0, float("nan")
        if self.polish:
            X, kkt, nodes, gap = certified_examples(G, C, const, X_prior, lam, self.pairs, start=X_ipopt, free=free)
        elif not ok:
            raise SolverError(f"weight step: IPOPT failed with status {status} after {iters} iterations", status)
        return WeightSolution(
            weights=X, objective=eq5_objective(X, G, C, const, X_prior, lam), ipopt_status=status,
            ipopt_iterations=iters, ipopt_success=ok, ipopt_weights=X_ipopt, ipopt_objective=obj_ipopt,
            max_complementarity=complementarity_violation(X, self.pairs), max_bound_violation=bound_violation(X),
            ipopt_max_complementarity=complementarity_violation(X_ipopt, self.pairs),
            ipopt_max_bound_violation=bound_violation(X_ipopt), kkt_residual=kkt, polished=self.polish,
            certificate_nodes=nodes, certificate_gap=gap,
            seconds=time.perf_counter() - t0,
        )

    def _polish(self, G, C, const, X_prior, lam, X_ipopt):
        """Certified global optimum of every example, starting from IPOPT's branch
        (:func:`certified_examples`). Returns weights, max KKT residual, total nodes, max gap."""
        return certified_examples(G, C, const, X_prior, lam, self.pairs, start=X_ipopt)


def certified_examples(G, C, const, X_prior, lam, pairs, start=None, free=None):
    """Certified global optimum of eq. 5 for every example (they are independent given G).

    :class:`~facebasis.rigging.certify.CertifiedWeightSolver` (branch and bound over the pairs,
    exact box-QPs), set up once for the shared G, lambda and pairs, optionally seeded per example
    with ``start`` (m, k). ``free`` (k,) bool: only these weights may be nonzero (the others are
    fixed at 0, their pairs hold trivially). Returns (weights (m, k), max KKT residual, total
    nodes, max gap); the objective's constants (prior of the fixed weights) do not change the optimum.
    """
    k, m = C.shape
    X = np.zeros((m, k))
    P = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    idx = np.arange(k) if free is None else np.flatnonzero(free)
    if len(idx) < k:
        pos = np.full(k, -1)
        pos[idx] = np.arange(len(idx))
        P = pos[P[(pos[P] >= 0).all(axis=1)]] if len(P) else P
        G, C = G[np.ix_(idx, idx)], C[idx]
        X_prior = X_prior[:, idx]
        start = None if start is None else start[:, idx]
    kkt, nodes, gap = 0.0, 0, 0.0
    if len(idx) == 0:
        return X, kkt, nodes, gap
    certifier = CertifiedWeightSolver(G, P, lam)  # shared by all examples of this step
    for j in range(m):  # examples are independent given the blendshapes
        cs = certifier.solve(C[:, j], const[j], X_prior[j], start=None if start is None else start[j])
        X[j, idx] = cs.x
        kkt, nodes, gap = max(kkt, cs.kkt_residual), nodes + cs.nodes, max(gap, cs.gap)
    return X, kkt, nodes, gap


#: ``WeightSolution.ipopt_status`` of a weight step that did not run IPOPT
IPOPT_NOT_RUN = "not run"


def solve_certified(G, C, const, X_prior, lam: float, pairs=(), free=None) -> WeightSolution:
    """Eq. 5 by the certified solver alone (no IPOPT): the global optimum of every example.

    The answer is what :meth:`WeightSolver.solve` returns after its polish (the certified optimum
    does not depend on IPOPT's seed), without the joint IPOPT solve; the IPOPT fields of the
    solution say so (status :data:`IPOPT_NOT_RUN`, 0 iterations, NaN objective and violations,
    ``ipopt_success`` True since nothing failed). ``free``: see :func:`certified_examples`.
    """
    import time

    t0 = time.perf_counter()
    G, C = np.asarray(G, float), np.asarray(C, float)
    X_prior, const = np.asarray(X_prior, float), np.asarray(const, float)
    k, m = C.shape
    if G.shape != (k, k) or X_prior.shape != (m, k) or const.shape != (m,):
        raise InputError(f"weight step: expected G {(k, k)}, prior {(m, k)}, const {(m,)}, found "
                         f"{G.shape}, {X_prior.shape}, {const.shape}")
    P = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    X, kkt, nodes, gap = certified_examples(G, C, const, X_prior, lam, P, free=free)
    nan = float("nan")
    return WeightSolution(
        weights=X, objective=eq5_objective(X, G, C, const, X_prior, lam), ipopt_status=IPOPT_NOT_RUN,
        ipopt_iterations=0, ipopt_success=True, ipopt_weights=np.full_like(X, nan), ipopt_objective=nan,
        max_complementarity=complementarity_violation(X, P), max_bound_violation=bound_violation(X),
        ipopt_max_complementarity=nan, ipopt_max_bound_violation=nan, kkt_residual=kkt, polished=True,
        certificate_nodes=nodes, certificate_gap=gap, seconds=time.perf_counter() - t0,
    )
