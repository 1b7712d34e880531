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

The problem's data, objective and residuals are :class:`~facebasis.rigging.weightproblem.WeightProblem`'s,
the answer a :class:`~facebasis.rigging.weightproblem.WeightSolution` of it: this module only adds
the CasADi/IPOPT model, the IPOPT solve of a weight step (:meth:`WeightSolver.solve_problem`); the
certified solve of the same problem is :func:`facebasis.rigging.certify.certify_problem`. The
model is the one place where eq. 5 is written symbolically.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import time

import numpy as np

from .certify import certify_problem
from .weightproblem import WeightProblem, WeightSolution, check_pairs
from ..errors import InputError, SolverError
from ..interrupt import interruptible

#: IPOPT return statuses that count as a successful solve.
IPOPT_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


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
        P = check_pairs(pairs, self.k)
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

    def solve_problem(self, problem: WeightProblem, X0=None, free=None) -> WeightSolution:
        """The IPOPT solve of a weight step: eq. 5 for ``problem`` (its k, m and pairs must be the model's).

        Parameters
        ----------
        problem : :class:`WeightProblem` of m examples and k shapes
        X0 : (m, k) starting point (default: the problem's prior clipped to [0, 1])
        free : optional (k,) bool, the weights that may be nonzero (the others are fixed at 0)

        Returns
        -------
        :class:`WeightSolution` of ``problem``: with ``polish``, the certified optimum of every
        example seeded by IPOPT's answer (which the solution keeps as ``ipopt_X``).

        Raises
        ------
        InputError
            a problem of other sizes or pairs than the model's
        SolverError
            IPOPT fails and no polish is requested; the message carries IPOPT's status.
        """
        t0 = time.perf_counter()
        k, m = self.k, self.m
        if (problem.k, problem.m) != (k, m) or not np.array_equal(problem.pairs, self.pairs):
            raise InputError(f"weight step: expected a problem of {m} examples, {k} shapes and the pairs "
                             f"{self.pairs.tolist()}, found {problem.m}, {problem.k} and {problem.pairs.tolist()}")
        x0 = np.clip(problem.prior if X0 is None else X0, 0.0, 1.0)
        ub = 1.0
        if free is not None:
            ub = np.broadcast_to(np.where(np.asarray(free, bool), 1.0, 0.0), (m, k))
            x0 = np.minimum(x0, ub)
            ub = ub.ravel()
        p = np.concatenate([problem.G.ravel(order="F"), problem.c.T.ravel(order="F"),
                            problem.prior.T.ravel(order="F"), [problem.lam]])
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
        info = {"kkt_residual": 0.0, "certificate_nodes": 0, "certificate_gap": float("nan")}
        X = X_ipopt
        if self.polish:
            cert = certify_problem(problem, start=X_ipopt, free=free)
            X = cert.X
            info = {"kkt_residual": cert.kkt_residual, "certificate_nodes": cert.certificate_nodes,
                    "certificate_gap": cert.certificate_gap}
        elif not ok:
            raise SolverError(f"weight step: IPOPT failed with status {status} after {iters} iterations", status)
        return WeightSolution(problem, X, polished=self.polish, seconds=time.perf_counter() - t0,
                              ipopt_status=status, ipopt_iterations=iters, ipopt_success=ok, ipopt_X=X_ipopt,
                              **info)


__all__ = ["WeightSolver", "IPOPT_OK"]
