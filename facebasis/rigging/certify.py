"""Certified global optima of the weight subproblem (Gao et al. 2015, eq. 5) by branch and bound.

Given the blendshapes, the examples of eq. 5 are independent (:class:`~facebasis.rigging.weightproblem.WeightProblem`).
For one example the problem is

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
Each branch's box-QP is solved exactly by :func:`facebasis.geometry.boxqp.solve_box_qp`.

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
from ..geometry.boxqp import DAQP_OK, solve_box_qp
from .weightproblem import ExampleResiduals, WeightProblem, WeightSolution


@dataclass(frozen=True, eq=False)
class CertifiedSolution(ExampleResiduals):
    """A certified global optimum of one example's weight problem.

    Attributes
    ----------
    problem : the one-example :class:`WeightProblem` solved (its residuals give the properties below)
    x : (k,) optimal weights (bounds and every pair hold exactly)
    objective : f(x) (eq. 5 for this example, constants included), as the tree computed it
    lower_bound : the smallest bound among nodes open or pruned when the tree closed
    gap : objective - lower_bound (<= gap_tol * (1 + |objective|) when certified)
    nodes : box-QPs solved (tree nodes explored)
    pruned : nodes pruned by bound
    zeroed : indices fixed to zero on the optimal branch
    kkt_residual : KKT residual of the optimal branch's box-QP
    seconds : wall time
    gap_tol : the relative tolerance of the certificate
    """

    problem: WeightProblem
    x: np.ndarray
    objective: float
    lower_bound: float
    gap: float
    nodes: int
    pruned: int
    zeroed: tuple[int, ...]
    kkt_residual: float
    seconds: float
    gap_tol: float

    @property
    def certified(self) -> bool:
        return self.gap <= self.gap_tol * (1.0 + abs(self.objective))



def _one_example(problem: WeightProblem, what: str) -> WeightProblem:
    if not isinstance(problem, WeightProblem):
        raise InputError(f"{what}: expected a one-example WeightProblem, found {type(problem).__name__}")
    if problem.m != 1:
        raise InputError(f"{what}: expected a problem of one example, found {problem.m}")
    return problem


class _Workspace:
    """What every example of one weight problem shares: ``H = 2 (G + lam I)``, the pairs and one DAQP
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
        if flag not in DAQP_OK:
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


def certified_weights(problem: WeightProblem, *, start=None, gap_tol: float = 1e-9,
                      max_nodes: int = 100_000) -> CertifiedSolution:
    """Global optimum of one example's eq. 5 weight problem by branch and bound over the pairs.

    Nodes fix weights to zero; the bound at a node is the exact minimum of its convex-hull
    relaxation (box + ``x_a + x_b <= 1`` for undecided pairs). A relaxed minimiser that satisfies
    every pair gives a leaf, whose branch (the smaller weight of each pair zeroed) is re-solved
    exactly as a box-QP. Best-bound-first; the incumbent is seeded by ``start`` and by rounding
    the root relaxation. (A weight step of many examples: :func:`certify_problem`.)

    Parameters
    ----------
    problem : a one-example :class:`WeightProblem` (G (k, k), c (1, k), const, pairs, prior, lambda)
    start : (k,) optional starting point (e.g. IPOPT's answer): its branch (the smaller weight of
        each pair zeroed) is solved first and seeds the incumbent
    gap_tol : relative optimality tolerance of the certificate
    max_nodes : a tree larger than this raises :class:`SolverError` (never a silent, uncertified answer)

    Raises
    ------
    InputError
        not a one-example problem (the problem's own checks cover shapes, NaN, indefinite G, bad pairs)
    SolverError
        the tree exceeded ``max_nodes`` or DAQP failed
    """
    problem = _one_example(problem, "certified_weights")
    return CertifiedWeightSolver(problem, gap_tol=gap_tol, max_nodes=max_nodes).solve_example(0, start=start)


class CertifiedWeightSolver:
    """The branch and bound of :func:`certified_weights` for the examples of one
    :class:`WeightProblem` (they share G, lambda and the pairs): ``H``, its eigenvalues and the DAQP
    workspace are set up once, then :meth:`solve_example` / :meth:`solve_all` solve examples.

    Two correlated shapes that may not be on together (pair (0, 1)); the optimum keeps shape 1:

    >>> import numpy as np
    >>> from facebasis.rigging.weightproblem import WeightProblem
    >>> G, c = np.array([[1.0, 0.5], [0.5, 4.0]]), np.array([1.0, 2.1])   # B^T B (k, k), B^T (t - b0) (k,)
    >>> sol = CertifiedWeightSolver(WeightProblem(G, c, 0.0, [(0, 1)])).solve_example(0)
    >>> np.round(sol.x, 3).tolist(), round(sol.objective, 4), sol.certified
    ([0.0, 0.525], -1.1025, True)
    """

    def __init__(self, problem: WeightProblem, *, gap_tol: float = 1e-9, max_nodes: int = 100_000):
        if not isinstance(problem, WeightProblem):
            raise InputError(f"certified solver: expected a WeightProblem, found {type(problem).__name__}")
        self.problem = problem
        self.lam, self.gap_tol, self.max_nodes = problem.lam, gap_tol, max_nodes
        ev = problem.eigenvalues
        self._ws = _Workspace(problem.hessian, problem.pairs, float(ev[0]) if ev.size else 0.0)

    def solve_example(self, j: int, *, start=None) -> CertifiedSolution:
        """Example j of the solver's problem; ``start`` (k,) as in :func:`certified_weights`."""
        return self._solve(self.problem.example(j), start)

    def solve_all(self, start=None) -> list[CertifiedSolution]:
        """Every example of the solver's problem; ``start`` (m, k) or None."""
        return [self.solve_example(j, start=None if start is None else start[j]) for j in range(self.problem.m)]

    def _solve(self, problem: WeightProblem, start) -> CertifiedSolution:
        gap_tol, max_nodes = self.gap_tol, self.max_nodes
        t0 = time.perf_counter()
        inst, P, k = self._ws, self._ws.P, self._ws.k
        inst.set_example(problem.linear_term(0), problem.offset(0))
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
        return CertifiedSolution(
            problem=problem, x=best_x, objective=float(best_f), lower_bound=float(lower),
            gap=float(max(0.0, best_f - lower)), nodes=inst.count, pruned=pruned,
            zeroed=tuple(int(i) for i in np.flatnonzero(best_zero)), kkt_residual=best_kkt,
            seconds=time.perf_counter() - t0, gap_tol=gap_tol,
        )


def certify_problem(problem: WeightProblem, start=None, free=None, *, gap_tol: float = 1e-9,
                    max_nodes: int = 100_000) -> WeightSolution:
    """The certified solve of a weight step: the global optimum of every example of ``problem``
    (they are independent given G), a :class:`WeightSolution` (the other solve of the same problem
    is IPOPT's, :meth:`facebasis.rigging.weights.WeightSolver.solve_problem`).

    One :class:`CertifiedWeightSolver` serves all examples; ``start`` (m, k) optionally seeds each.
    ``free`` (k,) bool: only these weights may be nonzero (the others are held at 0 and their pairs
    hold trivially; :meth:`WeightProblem.restrict`). Returns a :class:`WeightSolution` of
    ``problem`` with the largest KKT residual, the total node count and the largest gap.
    """
    t0 = time.perf_counter()
    m, k = problem.m, problem.k
    X = np.zeros((m, k))
    sub, idx = problem, np.arange(k)
    if free is not None and not np.all(free):
        sub, idx = problem.restrict(free)
    kkt, nodes, gap = 0.0, 0, 0.0
    if len(idx):
        solver = CertifiedWeightSolver(sub, gap_tol=gap_tol, max_nodes=max_nodes)
        for j in range(m):  # examples are independent given the blendshapes
            cs = solver.solve_example(j, start=None if start is None else start[j, idx])
            X[j, idx] = cs.x
            kkt, nodes, gap = max(kkt, cs.kkt_residual), nodes + cs.nodes, max(gap, cs.gap)
    return WeightSolution(problem, X, kkt_residual=kkt, polished=True, seconds=time.perf_counter() - t0,
                          certificate_nodes=nodes, certificate_gap=gap)


def brute_force_weights(problem: WeightProblem):
    """Global optimum of a one-example :class:`WeightProblem` by enumerating all ``2^p`` branches
    (one box-QP each). For checking only. Returns (x, objective, branches solved)."""
    problem = _one_example(problem, "brute force")
    P = problem.pairs
    if len(P) > 16:
        raise InputError(f"brute force: expected at most 16 pairs, found {len(P)}")
    ev = problem.eigenvalues
    inst = _Workspace(problem.hessian, P, float(ev[0]) if ev.size else 0.0)
    inst.set_example(problem.linear_term(0), problem.offset(0))
    best = (None, np.inf)
    for choice in itertools.product((0, 1), repeat=len(P)):
        zero = np.zeros(problem.k, bool)
        zero[P[np.arange(len(P)), list(choice)]] = True
        x, f, _ = inst.qp(zero)
        if f < best[1]:
            best = (x, f)
    return best[0], float(best[1]), inst.count


@dataclass(frozen=True, eq=False)
class WeightInstance:
    """A named one-example :class:`WeightProblem` of the weight-problem suite (``problems/weights_suite.py``),
    with its optimum ``known_objective`` if known in closed form; the maths are the problem's."""

    name: str
    kind: str
    problem: WeightProblem
    known_objective: float | None = None

    @classmethod
    def make(cls, name, kind, G, c, const, prior, lam, pairs, known_objective=None) -> WeightInstance:
        """From one example's data: G (k, k), c (k,), const, prior (k,), lam, pairs (P, 2)."""
        return cls(name, kind, WeightProblem(G, c, const, pairs, prior, lam), known_objective)

    k = property(lambda self: self.problem.k, doc="number of shapes")
    pairs = property(lambda self: self.problem.pairs, doc="(P, 2) exclusive pairs")

    def objective(self, x) -> float:
        """Eq. 5 at x (k,)."""
        return float(self.problem.objective(x)[0])

    def certify(self, start=None, **kw):
        """Certified optimum (:func:`certified_weights`)."""
        return certified_weights(self.problem, start=start, **kw)



__all__ = ["CertifiedSolution", "CertifiedWeightSolver", "certified_weights", "certify_problem", "brute_force_weights",
           "WeightInstance"]
