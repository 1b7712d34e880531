"""IPOPT formulations of the complementarity constraints of eq. 5 (Gao et al. 2015), for comparison.

One example's weight problem (see :mod:`facebasis.rigging.certify`)

    min_x  x^T (G + lambda I) x - 2 (c + lambda x~)^T x + const,   0 <= x <= 1,   x_a x_b = 0

is handed to IPOPT in CasADi in one of these forms (each built once, parametric in G, c, x~,
lambda and its own parameter, and reused for every instance of the same size and pairs):

``equality``
    ``x_a x_b = 0`` as an equality constraint (the paper's literal form; no constraint
    qualification holds at any feasible point, so IPOPT's multipliers are unbounded).
``inequality``
    ``x_a x_b <= 0``: equivalent given the bounds, one-sided for IPOPT's barrier.
``scholtes``
    ``x_a x_b <= eps`` with eps = 1e-1, 1e-2, ..., 1e-8, each solve warm-started from the last
    (Scholtes 2001); the relaxed problems satisfy MFCQ.
``penalty``
    ``f + rho sum x_a x_b`` (only bounds as constraints), rho = 1, 10, ... until the pairs hold to
    1e-9 or rho = 1e8 (an exact penalty for MPCCs, Ralph & Wright 2004).

Beside them, the heuristic production facial solvers use (:func:`cancel_pairs`):

``cancel-pairs``
    Solve without the pairs (an exact box QP), then for every pair with both weights positive set
    the smaller one to zero (held at 0 from then on) and solve again, until no pair is violated
    (NVIDIA Audio2Face-3D's blendshape solver cancels pairs this way, with one re-solve). Always
    feasible, never better than the optimum, and provably suboptimal when the smaller weight of a
    pair is the one that should stay (see the test on two shapes).

The certified optimum from :func:`facebasis.rigging.certify.certified_weights` is the yardstick;
objectives and residuals of every answer come from its
:class:`~facebasis.rigging.weightproblem.WeightProblem`.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .weightproblem import ExampleResiduals, WeightProblem, check_pairs
from .weights import IPOPT_OK

FORMULATIONS = ("equality", "inequality", "scholtes", "penalty")
#: methods that are not IPOPT formulations (compared with them by :func:`compare_formulations`)
HEURISTICS = ("cancel-pairs",)
SCHOLTES_EPS = tuple(10.0 ** -e for e in range(1, 9))
PENALTY_RHO = tuple(10.0 ** e for e in range(0, 9))


@dataclass(frozen=True, eq=False)
class FormulationResult(ExampleResiduals):
    """One IPOPT formulation on one example's problem: raw answer x (k,), IPOPT statuses of every
    solve, total IPOPT iterations and wall time; the eq. 5 objective and the violations at x come
    from ``problem`` (one example)."""

    formulation: str
    problem: WeightProblem
    x: np.ndarray
    statuses: tuple[str, ...]
    iterations: int
    seconds: float

    @property
    def success(self) -> bool:
        return all(s in IPOPT_OK for s in self.statuses)

    @property
    def objective(self) -> float:
        return float(self.problem.objective(self.x)[0])



class FormulationSolver:
    """CasADi/IPOPT model of one example's weight problem in a given formulation, built once."""

    def __init__(self, k: int, pairs, formulation: str = "equality", ipopt_options: dict | None = None):
        import casadi as ca

        if formulation not in FORMULATIONS:
            raise InputError(f"formulation: expected one of {FORMULATIONS}, found {formulation!r}")
        self.k, self.formulation = int(k), formulation
        self.pairs = check_pairs(pairs, self.k)
        P = self.pairs
        x = ca.MX.sym("x", k)
        G = ca.MX.sym("G", k, k)
        c = ca.MX.sym("c", k)
        xp = ca.MX.sym("xp", k)
        lam = ca.MX.sym("lam")
        par = ca.MX.sym("par")  # eps (scholtes) or rho (penalty); unused otherwise
        # eq. 5 for one example, without its constant: x^T G x - 2 c^T x + lambda ||x - x~||^2
        f = ca.dot(x, ca.mtimes(G, x)) - 2 * ca.dot(c, x) + lam * ca.sumsqr(x - xp)
        prod = x[P[:, 0].tolist()] * x[P[:, 1].tolist()] if len(P) else ca.MX.zeros(0)
        nlp = {"x": x, "p": ca.vertcat(ca.vec(G), c, xp, lam, par)}
        if formulation == "penalty":
            nlp["f"] = f + par * ca.sum1(prod) if len(P) else f
        else:
            nlp["f"] = f
            if len(P):
                nlp["g"] = prod
        opts = {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10, "max_iter": 3000}}
        opts["ipopt"].update(ipopt_options or {})
        self._solver = ca.nlpsol(f"weights_{formulation}", "ipopt", nlp, opts)

    def solve(self, G, c, const, prior, lam: float, x0=None) -> FormulationResult:
        """One example: G (k, k), c (k,), const, prior (k,), lam (see :meth:`solve_problem`)."""
        return self.solve_problem(WeightProblem(G, c, const, self.pairs, prior, lam), x0)

    def solve_problem(self, problem: WeightProblem, x0=None) -> FormulationResult:
        """IPOPT on a one-example problem with this solver's k and pairs, from x0 (k,) (default: the
        prior clipped to [0, 1])."""
        t0 = time.perf_counter()
        k, P = self.k, self.pairs
        if (problem.m, problem.k) != (1, k) or not np.array_equal(problem.pairs, P):
            raise InputError(f"formulation {self.formulation}: expected one example, {k} shapes and the pairs "
                             f"{P.tolist()}, found {problem.m}, {problem.k} and {problem.pairs.tolist()}")
        prior = problem.prior[0]
        x = np.clip(prior if x0 is None else np.asarray(x0, float), 0.0, 1.0)
        base = np.concatenate([problem.G.ravel(order="F"), problem.c[0], prior, [problem.lam]])
        statuses, iters = [], 0

        def run(par, ubg):
            nonlocal x, iters
            args = {"x0": x, "p": np.append(base, par), "lbx": 0.0, "ubx": 1.0}
            if len(P) and self.formulation != "penalty":
                args.update(lbg=-np.inf if self.formulation != "equality" else 0.0, ubg=ubg)
            sol = self._solver(**args)
            st = self._solver.stats()
            statuses.append(str(st.get("return_status", "unknown")))
            iters += int(st.get("iter_count", 0))
            x = np.asarray(sol["x"]).reshape(k)

        if self.formulation in ("equality", "inequality") or not len(P):
            run(0.0, 0.0)
        elif self.formulation == "scholtes":
            for eps in SCHOLTES_EPS:
                run(eps, eps)
        else:
            for rho in PENALTY_RHO:
                run(rho, 0.0)
                if problem.complementarity(x)[0] <= 1e-9:
                    break
        return FormulationResult(self.formulation, problem, x, tuple(statuses), iters, time.perf_counter() - t0)


def cancel_pairs(problem: WeightProblem, tol: float = 0.0) -> FormulationResult:
    """The cancel-pairs heuristic on one example's problem (module docstring).

    Each round solves the box QP ``min 1/2 x^T H x + g^T x``, ``0 <= x <= hi`` exactly
    (:func:`facebasis.geometry.boxqp.solve_box_qp`, H and g from eq. 5 via ``problem``), then sets
    ``hi = 0`` for the smaller weight of every pair whose product exceeds ``tol``; it ends when none
    does (at most one round per pair, since a cancelled weight stays at 0).

    Parameters
    ----------
    problem : WeightProblem with one example (m = 1)
    tol : float, a pair counts as violated when ``x_a x_b > tol``

    Returns
    -------
    FormulationResult
        ``formulation="cancel-pairs"``, ``iterations`` = box QPs solved, one ``statuses`` entry per
        round ("box QP optimal").
    """
    from ..geometry.boxqp import solve_box_qp

    if problem.m != 1:
        raise InputError(f"cancel-pairs: expected one example, found {problem.m}")
    t0 = time.perf_counter()
    P, H, g = problem.pairs, problem.hessian, problem.linear_term(0)
    hi = np.ones(problem.k)
    statuses = []
    while True:
        x = solve_box_qp(H, g, 0.0, hi).x
        statuses.append("box QP optimal")
        if not len(P):
            break
        bad = P[x[P[:, 0]] * x[P[:, 1]] > tol]
        if not len(bad):
            break
        hi[np.where(x[bad[:, 0]] <= x[bad[:, 1]], bad[:, 0], bad[:, 1])] = 0.0  # cancel the smaller weight
    return FormulationResult("cancel-pairs", problem, x, tuple(statuses), len(statuses), time.perf_counter() - t0)


__all__ = ["FORMULATIONS", "HEURISTICS", "FormulationResult", "FormulationSolver", "cancel_pairs"]


def compare_formulations(instances, formulations=FORMULATIONS + HEURISTICS, rel_tol: float = 1e-6,
                         progress=None) -> list[dict]:
    """Solve every instance (:class:`facebasis.rigging.weightproblem.WeightInstance`) with the certified solver,
    each IPOPT formulation and the cancel-pairs heuristic (:data:`HEURISTICS`); one row per (instance,
    method) as plain dicts (a results table).

    Columns: instance, kind, method, objective, certified_objective, relative_gap (method minus
    certified, over max(1, |certified|)), reached (|gap| <= rel_tol), max_complementarity,
    max_bound_violation, seconds, statuses, iterations, nodes (certified only).
    """
    solvers: dict = {}
    rows = []
    for n, inst in enumerate(instances):
        cs = inst.certify()
        base = {"instance": inst.name, "kind": inst.kind, "certified_objective": cs.objective}
        rows.append({**base, "method": "certified", "objective": cs.objective, "relative_gap": 0.0, "reached": True,
                     "max_complementarity": cs.max_complementarity, "max_bound_violation": cs.max_bound_violation,
                     "seconds": cs.seconds, "statuses": "", "iterations": 0, "nodes": cs.nodes})
        for form in formulations:
            if form == "cancel-pairs":
                r = cancel_pairs(inst.problem)
            else:
                key = (form, inst.k, inst.pairs.tobytes())
                if key not in solvers:
                    solvers[key] = FormulationSolver(inst.k, inst.pairs, form)
                r = solvers[key].solve_problem(inst.problem)
            gap = (r.objective - cs.objective) / max(1.0, abs(cs.objective))
            rows.append({**base, "method": form, "objective": r.objective, "relative_gap": gap,
                         "reached": abs(gap) <= rel_tol, "max_complementarity": r.max_complementarity,
                         "max_bound_violation": r.max_bound_violation, "seconds": r.seconds,
                         "statuses": ";".join(sorted(set(r.statuses))), "iterations": r.iterations, "nodes": 0})
        if progress is not None:
            progress(n + 1, len(instances))
    return rows


def summarise_comparison(rows) -> list[dict]:
    """Per method: instances, reached optimum (count), worst gap, worst violations, median and max
    time, IPOPT statuses seen."""
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        rs = [r for r in rows if r["method"] == method]
        statuses = sorted({s for r in rs for s in r["statuses"].split(";") if s})
        out.append({"method": method, "instances": len(rs), "reached": sum(r["reached"] for r in rs),
                    "worst_relative_gap": max(r["relative_gap"] for r in rs),
                    "most_negative_gap": min(r["relative_gap"] for r in rs),
                    "max_complementarity": max(r["max_complementarity"] for r in rs),
                    "max_bound_violation": max(r["max_bound_violation"] for r in rs),
                    "median_ms": 1e3 * float(np.median([r["seconds"] for r in rs])),
                    "max_ms": 1e3 * max(r["seconds"] for r in rs), "statuses": ", ".join(statuses)})
    return out


__all__ += ["compare_formulations", "summarise_comparison"]
