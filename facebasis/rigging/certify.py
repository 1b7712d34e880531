"""Certified global optima of the weight subproblem (Gao et al. 2015, eq. 5) by branch and bound.

Given the blendshapes, the examples of eq. 5 are independent. For one example the problem is

    min_x  f(x) = x^T (G + lambda I) x - 2 (c + lambda x~)^T x + t^T t + lambda ||x~||^2
    s.t.   0 <= x_i <= 1,    x_a x_b = 0  for every exclusive pair (a, b),

a convex box-constrained QP plus complementarity pairs: a mathematical program with complementarity
constraints (MPCC). The pair constraint violates the usual constraint qualifications, so a local
NLP solver (IPOPT) can stop at a non-optimal point. But every pair says "x_a = 0 or x_b = 0", so the
problem is the minimum over 2^p convex box-QPs, which branch and bound solves to a certified
global optimum:

* a node fixes some weights to zero (one per decided pair) and replaces every undecided pair by
  ``x_a + x_b <= 1``, the convex hull of ``{x_a x_b = 0} within [0, 1]^2``: a convex QP that
  *relaxes* every branch below the node, so its exact minimum is a lower bound;
* if the relaxed minimiser satisfies every pair, it solves the node: a candidate (incumbent);
* otherwise branch on the pair with the largest smaller weight (x_a = 0 | x_b = 0);
* a node whose bound is not below the incumbent (within ``gap_tol``) is pruned.

Nodes are explored best-bound first, so when the tree closes the smallest open bound is the
certificate: ``lower_bound <= f* <= objective`` with ``objective - lower_bound <= gap_tol``.

Each box-QP is solved by DAQP (Arnström, Bemporad & Axehill 2022, an exact dual active-set
method, MIT licence) and then refined on its active set with one dense linear solve, so bounds
hold exactly and the KKT residual is at rounding level; the residual is reported.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, SolverError

#: DAQP exit flags that mean "optimal" (1) or "optimal, soft constraints violated" (2).
_DAQP_OK = (1, 2)


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
    if flag not in _DAQP_OK:
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


@dataclass(frozen=True)
class CertifiedSolution:
    """A certified global optimum of one example's weight problem.

    Attributes
    ----------
    x : (k,) optimal weights (bounds and every pair hold exactly)
    objective : f(x) (eq. 5 for this example, constants included)
    lower_bound : the smallest bound among nodes open or pruned when the tree closed
    gap : objective - lower_bound (<= gap_tol * (1 + |objective|) when certified)
    nodes : box-QPs solved (tree nodes explored)
    pruned : nodes pruned by bound
    zeroed : indices fixed to zero on the optimal branch
    kkt_residual : KKT residual of the optimal branch's box-QP
    max_complementarity, max_bound_violation : at x (0.0 exactly when certified)
    seconds : wall time
    """

    x: np.ndarray
    objective: float
    lower_bound: float
    gap: float
    nodes: int
    pruned: int
    zeroed: tuple[int, ...]
    kkt_residual: float
    max_complementarity: float
    max_bound_violation: float
    seconds: float
    gap_tol: float

    @property
    def certified(self) -> bool:
        return self.gap <= self.gap_tol * (1.0 + abs(self.objective))


def _check_shared(G, lam, pairs):
    """Validate what all examples of one weight step share; returns (H = 2 (G + lam I), P, l_min(H))."""
    G = np.asarray(G, np.float64)
    if G.ndim != 2 or G.shape[0] != G.shape[1]:
        raise InputError(f"Gram matrix G: expected a square (k, k) matrix, found shape {G.shape}")
    k = G.shape[0]
    if not np.isfinite(G).all():
        raise InputError("weight problem: expected finite G, found NaN/inf")
    if not np.isfinite(lam) or lam < 0:
        raise InputError(f"lambda: expected a finite value >= 0, found {lam}")
    if not np.allclose(G, G.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(G).max())):
        raise InputError("Gram matrix G: expected a symmetric matrix, found an asymmetric one")
    H = 2.0 * (0.5 * (G + G.T) + lam * np.eye(k))
    ev = np.linalg.eigvalsh(H)
    if ev[0] < -1e-10 * max(1.0, abs(ev[-1])):
        raise InputError(f"Gram matrix G + lambda I: expected positive semidefinite, found smallest "
                         f"eigenvalue {ev[0] / 2:.3g} (a Gram matrix B^T B cannot be indefinite)")
    P = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(P) and (P.min() < 0 or P.max() >= k):
        raise InputError(f"exclusive pairs: expected shape indices in [0, {k}), found {P.tolist()}")
    if len(P) and np.any(P[:, 0] == P[:, 1]):
        raise InputError(f"exclusive pairs: a pair names one shape twice: {P[P[:, 0] == P[:, 1]].tolist()}")
    return H, P, float(ev[0])


def _check_example(k, c, prior):
    """Validate one example's data; returns (c, prior) as float arrays (k,)."""
    c = np.asarray(c, np.float64).reshape(-1)
    prior = np.zeros(k) if prior is None else np.asarray(prior, np.float64).reshape(-1)
    if c.shape != (k,) or prior.shape != (k,):
        raise InputError(f"weight problem: expected c and prior of length {k}, found {c.shape}, {prior.shape}")
    for name, a in (("c", c), ("prior", prior)):
        if not np.isfinite(a).all():
            raise InputError(f"weight problem: expected finite {name}, found NaN/inf")
    return c, prior


def complementarity_violation(X, pairs) -> float:
    """``max |x_a x_b|`` over the exclusive pairs (p, 2) and every row of ``X`` ((k,) or (m, k))."""
    P = np.asarray(pairs, np.int64).reshape(-1, 2)
    X = np.atleast_2d(np.asarray(X, np.float64))
    return float(np.max(np.abs(X[:, P[:, 0]] * X[:, P[:, 1]]))) if len(P) and X.size else 0.0


def bound_violation(X) -> float:
    """Largest violation of ``0 <= x <= 1`` over ``X`` ((k,) or (m, k))."""
    X = np.asarray(X, np.float64)
    return float(max(0.0, -X.min(), X.max() - 1.0)) if X.size else 0.0


def _violations(x, P):
    return complementarity_violation(x, P), bound_violation(x)


class _Workspace:
    """What every example of one weight step shares: ``H = 2 (G + lam I)``, the pairs and one DAQP
    workspace for the node relaxations. :meth:`set_example` loads an example's linear term.

    ``qp(zero)`` solves the box-QP with the weights ``zero`` fixed at 0 (one branch, exactly);
    ``relaxation(zero)`` adds, for every pair with neither weight fixed, ``x_a + x_b <= 1`` (the
    convex hull of ``{x_a x_b = 0, 0 <= x <= 1}`` in the pair's two weights) and the term
    ``mu x_a x_b`` with ``mu`` = 0.999 x smallest eigenvalue of H (over disjoint pairs). Both vanish
    or hold at every point that satisfies the pairs, and the QP stays convex, so its minimum is a
    valid lower bound; the term is the perspective strengthening that makes strongly convex (e.g.
    prior-dominated) instances prune early.
    """

    def __init__(self, H, P, ev_min):
        self.H, self.P, self.k = H, P, len(H)
        self.mu = 0.999 * max(0.0, ev_min) if len(P) else 0.0
        self.g, self.offset, self.count = np.zeros(self.k), 0.0, 0
        if len(P):
            import daqp

            k, mu = self.k, self.mu
            A = np.zeros((len(P), k))
            A[np.arange(len(P)), P[:, 0]] = 1.0
            A[np.arange(len(P)), P[:, 1]] = 1.0
            Hr = H.copy()
            if mu > 0:
                used = np.zeros(k, bool)
                for a, b in P:
                    if not (used[a] or used[b]):
                        used[a] = used[b] = True
                        Hr[a, b] += mu
                        Hr[b, a] += mu
            self._Hr = Hr
            self._upper = np.ones(k + len(P))
            lower = np.concatenate([np.zeros(k), np.full(len(P), -1e30)])
            self._model = daqp.Model()
            self._model.setup(np.ascontiguousarray(Hr), np.zeros(k), A, self._upper,
                              lower, np.zeros(k + len(P), dtype=np.int32))
            self._model.settings = {"primal_tol": 1e-12, "dual_tol": 1e-12}

    def set_example(self, g, offset):
        """Linear term ``g`` (k,) and constant of one example; resets the node count."""
        self.g, self.offset, self.count = np.ascontiguousarray(g, dtype=np.float64), float(offset), 0
        if len(self.P):
            self._model.update(f=self.g)

    def qp(self, zero: np.ndarray):
        free = ~zero
        self.count += 1
        sol = solve_box_qp(self.H[np.ix_(free, free)], self.g[free], 0.0, 1.0)
        x = np.zeros(self.k)
        x[free] = sol.x
        return x, sol.value + self.offset, sol.kkt_residual

    def relaxation(self, zero: np.ndarray, warm=None):
        """Bound of a node; returns (x, value, active-set flags for warm-starting its children).

        One DAQP workspace serves every node: the cost ``H + mu S`` is the same everywhere (S adds
        ``x_a x_b`` for disjoint pairs; it vanishes on every node's feasible set, decided pairs
        included, and keeps the QP convex since ``H - mu I`` is PSD), the rows ``x_a + x_b <= 1``
        are fixed, and a node only changes bounds (fixed weights become equalities 0 <= x <= 0)
        and starts from its parent's active set.
        """
        P, k = self.P, self.k
        if len(P) == 0 or (zero[P[:, 0]] | zero[P[:, 1]]).all():
            x, f, _ = self.qp(zero)
            return x, f, None
        self.count += 1
        upper = self._upper.copy()
        upper[:k][zero] = 0.0
        sense = np.zeros(k + len(P), dtype=np.int32) if warm is None else warm.copy()
        sense[:k][zero] = 5                        # equality (active, immutable)
        self._model.update(bupper=upper, sense=sense)
        x, _, flag, _ = self._model.solve()
        if flag not in _DAQP_OK:
            raise SolverError(f"certified weights: DAQP failed on a relaxation with exit flag {flag}", str(flag))
        x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
        x[zero] = 0.0
        val = float(0.5 * x @ self._Hr @ x + self.g @ x) + self.offset
        # active set of this node: weights at 0 (lower, flag 3) or 1 (upper, 1), hull rows at 1
        flags = np.zeros(k + len(P), dtype=np.int32)
        flags[:k][x <= 1e-12] = 3
        flags[:k][x >= 1.0 - 1e-12] = 1
        flags[k:][x[P[:, 0]] + x[P[:, 1]] >= 1.0 - 1e-12] = 1
        return x, val, flags


#: a pair counts as satisfied in a relaxed solution if its smaller weight is at most this
_PAIR_TOL = 1e-10


def certified_weights(G, c, const, pairs, prior=None, lam: float = 0.0, *, start=None,
                      gap_tol: float = 1e-9, max_nodes: int = 100_000) -> CertifiedSolution:
    """Global optimum of one example's eq. 5 weight problem by branch and bound over the pairs.

    Nodes fix weights to zero; the bound at a node is the exact minimum of its convex-hull
    relaxation (box + ``x_a + x_b <= 1`` for undecided pairs). A relaxed minimiser that satisfies
    every pair gives a leaf, whose branch (the smaller weight of each pair zeroed) is re-solved
    exactly as a box-QP. Best-bound-first; the incumbent is seeded by ``start`` and by rounding
    the root relaxation.

    Parameters
    ----------
    G : (k, k) Gram matrix ``B^T B``
    c : (k,) ``B^T t`` of the example
    const : ``t^T t`` (only shifts the objective)
    pairs : (p, 2) exclusive shape index pairs
    prior : (k,) rough weights ``x~`` (default zeros); lam : prior weight lambda >= 0
    start : (k,) optional starting point (e.g. IPOPT's answer): its branch (the smaller weight of
        each pair zeroed) is solved first and seeds the incumbent
    gap_tol : relative optimality tolerance of the certificate
    max_nodes : a tree larger than this raises :class:`SolverError` (never a silent, uncertified answer)

    Raises
    ------
    InputError
        malformed instance (shapes, NaN, indefinite G, bad pairs)
    SolverError
        the tree exceeded ``max_nodes`` or DAQP failed
    """
    return CertifiedWeightSolver(G, pairs, lam, gap_tol=gap_tol, max_nodes=max_nodes).solve(c, const, prior,
                                                                                             start=start)


class CertifiedWeightSolver:
    """:func:`certified_weights` for many examples that share G, lambda and the pairs (the examples
    of one weight step): the checks, ``H``, its eigenvalues and the DAQP workspace are set up once.

    >>> solver = CertifiedWeightSolver(G, pairs, lam)            # doctest: +SKIP
    >>> [solver.solve(C[:, j], const[j], prior[j]) for j in range(m)]   # doctest: +SKIP
    """

    def __init__(self, G, pairs, lam: float = 0.0, *, gap_tol: float = 1e-9, max_nodes: int = 100_000):
        H, P, ev_min = _check_shared(G, lam, pairs)
        self.lam, self.gap_tol, self.max_nodes = float(lam), gap_tol, max_nodes
        self._ws = _Workspace(H, P, ev_min)

    def solve(self, c, const, prior=None, *, start=None) -> CertifiedSolution:
        """One example (see :func:`certified_weights` for the parameters)."""
        gap_tol, max_nodes = self.gap_tol, self.max_nodes
        t0 = time.perf_counter()
        inst, P, k, lam = self._ws, self._ws.P, self._ws.k, self.lam
        c, prior = _check_example(k, c, prior)
        inst.set_example(-2.0 * (c + lam * prior), float(const) + lam * float(prior @ prior))
        best_x, best_f, best_zero, best_kkt = None, np.inf, None, 0.0

        def round_and_consider(x, zero):
            """Exact box-QP on the branch that zeroes the smaller weight of every pair of x."""
            nonlocal best_x, best_f, best_zero, best_kkt
            z = zero.copy()
            if len(P):
                z[np.where(x[P[:, 0]] >= x[P[:, 1]], P[:, 1], P[:, 0])] = True
            xb, fb, kkt = inst.qp(z)
            if fb < best_f:
                best_x, best_f, best_zero, best_kkt = xb, fb, z, kkt

        def threshold():  # a node must beat the incumbent by more than the tolerance to be kept
            return best_f - gap_tol * (1.0 + abs(best_f)) if np.isfinite(best_f) else np.inf

        if start is not None:
            round_and_consider(np.clip(np.asarray(start, np.float64).reshape(-1), 0.0, 1.0), np.zeros(k, bool))
        tick = itertools.count()
        root = np.zeros(k, bool)
        x, f, flags = inst.relaxation(root)
        round_and_consider(x, root)
        heap = [(f, next(tick), root, x, flags)]
        closed_bound = np.inf  # smallest bound among pruned nodes
        pruned = 0
        while heap:
            f, _, zero, x, flags = heapq.heappop(heap)
            if f >= threshold():
                # best-first: every node still open is bounded below by f, so the tree closes here
                closed_bound = min(closed_bound, f)
                pruned += 1 + len(heap)
                break
            smaller = np.minimum(x[P[:, 0]], x[P[:, 1]]) if len(P) else np.zeros(0)
            if not len(P) or smaller.max() <= _PAIR_TOL:
                # the relaxation's minimiser satisfies every pair: it solves this node's subtree
                round_and_consider(x, zero)
                continue
            if inst.count > max_nodes:
                raise SolverError(f"certified weights: branch and bound exceeded {max_nodes} nodes "
                                  f"(gap {best_f - f:.3g})", "max_nodes")
            a, b = P[int(np.argmax(smaller))]
            for i in (a, b):  # branch: x_a = 0 | x_b = 0
                child = zero.copy()
                child[i] = True
                xc, fc, fl = inst.relaxation(child, flags)
                if fc < threshold():
                    heapq.heappush(heap, (fc, next(tick), child, xc, fl))
                else:
                    pruned += 1
                    closed_bound = min(closed_bound, fc)
        lower = min(best_f, closed_bound)
        comp, bnd = _violations(best_x, P)
        return CertifiedSolution(
            x=best_x, objective=float(best_f), lower_bound=float(lower), gap=float(max(0.0, best_f - lower)),
            nodes=inst.count, pruned=pruned, zeroed=tuple(int(i) for i in np.flatnonzero(best_zero)),
            kkt_residual=best_kkt, max_complementarity=comp, max_bound_violation=bnd,
            seconds=time.perf_counter() - t0, gap_tol=gap_tol,
        )


def brute_force_weights(G, c, const, pairs, prior=None, lam: float = 0.0):
    """Global optimum by enumerating all ``2^p`` branches (one box-QP each). For checking only.

    Returns (x, objective, branches solved).
    """
    H, P, ev_min = _check_shared(G, lam, pairs)
    c, prior = _check_example(len(H), c, prior)
    if len(P) > 16:
        raise InputError(f"brute force: expected at most 16 pairs, found {len(P)}")
    inst = _Workspace(H, P, ev_min)
    inst.set_example(-2.0 * (c + lam * prior), float(const) + lam * float(prior @ prior))
    best = (None, np.inf)
    for choice in itertools.product((0, 1), repeat=len(P)):
        zero = np.zeros(len(c), bool)
        zero[P[np.arange(len(P)), list(choice)]] = True
        x, f, _ = inst.qp(zero)
        if f < best[1]:
            best = (x, f)
    return best[0], float(best[1]), inst.count


def weight_objective(x, G, c, const, prior=None, lam: float = 0.0) -> float:
    """One example's eq. 5 objective ``||B x - t||^2 + lambda ||x - x~||^2`` from Gram quantities."""
    x = np.asarray(x, np.float64)
    prior = np.zeros_like(x) if prior is None else np.asarray(prior, np.float64)
    return float(x @ G @ x - 2.0 * c @ x + const + lam * np.sum((x - prior) ** 2))


__all__ = ["BoxQPSolution", "CertifiedSolution", "CertifiedWeightSolver", "box_qp_kkt", "solve_box_qp",
           "certified_weights",
           "brute_force_weights", "weight_objective", "complementarity_violation", "bound_violation"]


@dataclass(frozen=True)
class WeightInstance:
    """One example's weight problem (eq. 5): ``x^T G x - 2 c^T x + const + lam ||x - prior||^2``
    on ``[0, 1]^k`` with ``x_a x_b = 0`` for ``pairs``; ``known_objective`` if known in closed form."""

    name: str
    kind: str
    G: np.ndarray
    c: np.ndarray
    const: float
    prior: np.ndarray
    lam: float
    pairs: np.ndarray
    known_objective: float | None = None

    @property
    def k(self) -> int:
        return len(self.c)

    def objective(self, x) -> float:
        return weight_objective(x, self.G, self.c, self.const, self.prior, self.lam)

    def complementarity(self, x) -> float:
        """``max |x_a x_b|`` over this problem's pairs."""
        return complementarity_violation(x, self.pairs)

    def bound_violation(self, x) -> float:
        """Largest violation of ``0 <= x <= 1``."""
        return bound_violation(x)

    def certify(self, start=None, **kw) -> CertifiedSolution:
        return certified_weights(self.G, self.c, self.const, self.pairs, self.prior, self.lam, start=start, **kw)


__all__ += ["WeightInstance"]
