"""An independent referee for the certified weight step: a global MIQP solver on the same problems.

``python -m problems.bench weights --independent gurobi`` solves every weight-suite instance (eq. 5
of Gao et al. 2015 for one example, :class:`facebasis.rigging.weightproblem.WeightProblem`)

    min 1/2 x^T H x + g^T x + const,   0 <= x <= 1,   SOS1 {x_a, x_b} for every exclusive pair

with Gurobi's branch and bound (SOS1 constraints: at most one of each pair nonzero, which is
``x_a x_b = 0``), and reports agreement with the certified solver's optimum and both times. The
referee is optional: never a run-time or CI dependency. ``gurobipy`` from PyPI carries a
size-limited licence that runs offline, enough for problems of this size (53 variables).
"""

from __future__ import annotations

import time

import numpy as np

#: referees this module knows
REFEREES = ("gurobi",)


def gurobi_weights(problem, mip_gap: float = 1e-10, threads: int = 1) -> tuple[np.ndarray, float, float, str]:
    """Global optimum of a one-example ``problem`` by Gurobi: (x (k,), objective by the problem's own
    formula, wall seconds, Gurobi's status name)."""
    import gurobipy as gp
    from gurobipy import GRB

    H, g = problem.hessian, problem.linear_term(0)
    t0 = time.perf_counter()
    with gp.Env(empty=True) as env:
        env.setParam("OutputFlag", 0)
        env.start()
        with gp.Model(env=env) as m:
            m.Params.MIPGap, m.Params.MIPGapAbs, m.Params.Threads = mip_gap, 1e-12, threads
            m.Params.OptimalityTol = m.Params.FeasibilityTol = 1e-9
            x = m.addMVar(problem.k, lb=0.0, ub=1.0, name="x")
            m.setObjective(0.5 * (x @ H @ x) + g @ x, GRB.MINIMIZE)
            for a, b in problem.pairs.tolist():
                m.addSOS(GRB.SOS_TYPE1, [x[a].item(), x[b].item()])
            m.optimize()
            status = {GRB.OPTIMAL: "optimal", GRB.SUBOPTIMAL: "suboptimal", GRB.TIME_LIMIT: "time limit"}.get(
                m.Status, f"status {m.Status}")
            xs = np.clip(np.asarray(x.X, float), 0.0, 1.0)
    # Gurobi's SOS1 branching may leave a partner at ~1e-10: the pairs are then held exactly, as the
    # certified solver holds them, by zeroing the smaller weight of each pair
    P = problem.pairs
    if len(P):
        small = np.where(xs[P[:, 0]] <= xs[P[:, 1]], P[:, 0], P[:, 1])
        xs[small[xs[small] < 1e-7]] = 0.0
    return xs, float(problem.objective(xs)[0]), time.perf_counter() - t0, status


def referee(instances, name: str = "gurobi", rel_tol: float = 1e-6) -> list[dict]:
    """Per instance: certified and referee objectives, their relative difference over max(1, |f*|),
    agreement within ``rel_tol``, both times."""
    from facebasis.errors import InputError

    if name not in REFEREES:
        raise InputError(f"--independent: expected one of {', '.join(REFEREES)}, found {name!r}")
    try:
        import gurobipy  # noqa: F401
    except ImportError:
        raise InputError("--independent gurobi: expected gurobipy installed (pip install gurobipy; its size-limited "
                         "licence runs offline), found none") from None
    rows = []
    for inst in instances:
        cs = inst.certify()
        x, f, seconds, status = gurobi_weights(inst.problem)
        diff = (f - cs.objective) / max(1.0, abs(cs.objective))
        rows.append({"instance": inst.name, "kind": inst.kind, "certified": cs.objective, "referee": f,
                     "relative_difference": diff, "agree": abs(diff) <= rel_tol, "status": status,
                     "certified_ms": 1e3 * cs.seconds, "referee_ms": 1e3 * seconds,
                     "max_complementarity": float(inst.problem.complementarity(x)[0])})
    return rows
