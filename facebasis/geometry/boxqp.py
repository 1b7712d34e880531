"""Exact convex box-constrained QPs: ``min 1/2 x^T H x + g^T x`` on ``lo <= x <= hi``.

Every branch of the weight problem of Gao et al. 2015 (eq. 5, :mod:`facebasis.rigging.weightproblem`)
with some weights fixed at zero is such a QP, and branch and bound (:mod:`facebasis.rigging.certify`)
needs its exact minimum. Each QP is solved by DAQP (Arnström, Bemporad & Axehill 2022, an exact dual
active-set method, MIT licence) and then refined on its active set with one dense linear solve, so
the bounds hold exactly and the KKT residual is at rounding level; the residual is reported.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
- Arnström D., Bemporad A., Axehill D. A dual active-set solver for embedded quadratic programming
    using recursive LDL^T updates. IEEE Transactions on Automatic Control 67(8): 4362-4369, 2022.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SolverError

#: DAQP exit flags that mean "optimal" (1) or "optimal, soft constraints violated" (2).
DAQP_OK = (1, 2)


@dataclass(frozen=True)
class BoxQPSolution:
    """Minimiser of ``1/2 x^T H x + g^T x`` on ``lo <= x <= hi``.

    x : (n,) minimiser; value : ``1/2 x^T H x + g^T x``; kkt_residual : max over i of
    ``|clip(x - grad, lo, hi) - x|`` (0 exactly at an optimum); iterations : DAQP's; refined : the
    active-set refinement was accepted.
    """

    x: np.ndarray
    value: float
    kkt_residual: float
    iterations: int
    refined: bool


def box_qp_kkt(H, g, x, lo, hi) -> float:
    """Max KKT residual of ``min 1/2 x^T H x + g^T x, lo <= x <= hi`` at x (projected gradient)."""
    if len(x) == 0:
        return 0.0
    grad = H @ x + g
    return float(np.max(np.abs(np.clip(x - grad, lo, hi) - x)))


def solve_box_qp(H, g, lo=0.0, hi=1.0, *, active_tol: float = 1e-9) -> BoxQPSolution:
    """Exact minimiser of a convex box-constrained QP (H (n, n) symmetric positive semidefinite).

    DAQP finds the optimal active set; the free variables are then re-solved from
    ``H_FF x_F = -(g_F + H_FA x_A)`` with the active ones exactly on their bounds, and the refined
    point is kept if it is feasible and its multipliers have the right signs.

    Parameters
    ----------
    H : (n, n) Hessian; g : (n,) linear term; lo, hi : bounds, numbers or (n,)

    Raises
    ------
    SolverError
        DAQP fails (its exit flag is the status)
    """
    import daqp

    H = np.ascontiguousarray(H, dtype=np.float64)
    g = np.ascontiguousarray(g, dtype=np.float64)
    n = len(g)
    lo = np.broadcast_to(np.asarray(lo, np.float64), (n,)).copy()
    hi = np.broadcast_to(np.asarray(hi, np.float64), (n,)).copy()
    if n == 0:
        return BoxQPSolution(np.zeros(0), 0.0, 0.0, 0, True)
    x, _, flag, info = daqp.solve(H, g, np.zeros((0, n)), hi, lo, np.zeros(n, dtype=np.int32),
                                  primal_tol=1e-12, dual_tol=1e-12, eps_prox=-1.0)
    if flag not in DAQP_OK:
        raise SolverError(f"box QP: DAQP failed with exit flag {flag} ({n} variables)", str(flag))
    x = np.clip(np.asarray(x, np.float64), lo, hi)
    # refinement on the active set found by DAQP
    at_lo = x <= lo + active_tol
    at_hi = ~at_lo & (x >= hi - active_tol)
    free = ~(at_lo | at_hi)
    xr = np.where(at_lo, lo, np.where(at_hi, hi, x))
    refined = False
    if free.any():
        A = ~free
        rhs = -(g[free] + H[np.ix_(free, A)] @ xr[A])
        try:
            xf = np.linalg.solve(H[np.ix_(free, free)], rhs)
        except np.linalg.LinAlgError:
            xf = None
        if xf is not None and np.all(xf >= lo[free]) and np.all(xf <= hi[free]):
            cand = xr.copy()
            cand[free] = xf
            if box_qp_kkt(H, g, cand, lo, hi) <= box_qp_kkt(H, g, x, lo, hi):
                xr, refined = cand, True
    else:
        refined = box_qp_kkt(H, g, xr, lo, hi) <= box_qp_kkt(H, g, x, lo, hi)
    if not refined:
        xr = x
    value = float(0.5 * xr @ H @ xr + g @ xr)
    return BoxQPSolution(xr, value, box_qp_kkt(H, g, xr, lo, hi), int(info.get("iterations", -1)), refined)


__all__ = ["BoxQPSolution", "box_qp_kkt", "solve_box_qp", "DAQP_OK"]
