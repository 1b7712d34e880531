"""The weight problem of example-based generation (Gao et al. 2015, eq. 5) and its solutions.

With the blendshapes fixed, the weight step finds weights ``x_j`` (k,) for every training
expression j = 1..m with target deltas ``t_j = T_j - B_0`` (3n,) and blendshape deltas ``B``
(3n, k)::

    min_X  sum_j ||B x_j - t_j||^2 + lambda ||x_j - x~_j||^2                         (eq. 5)
    s.t.   0 <= x_ij <= 1,   x_aj x_bj = 0  for every exclusive pair (a, b).

Only Gram quantities enter, ``||B x - t||^2 = x^T G x - 2 c^T x + t^T t`` with ``G = B^T B``
(k, k), ``c_j = B^T t_j`` and ``const_j = t_j^T t_j``, so one example's objective is

    f_j(x) = x^T G x - 2 c_j^T x + const_j + lambda ||x - x~_j||^2,

and the examples are independent given G. :class:`WeightProblem` holds these data (validated once,
when it is made) and is the one place where the objective, the complementarity and bound
residuals and the checks of the exclusive pairs are written; :class:`WeightSolution` keeps its
problem and computes its residuals from it, whichever solver produced it (the certified branch and
bound of :mod:`facebasis.rigging.certify`, the CasADi/IPOPT model of
:mod:`facebasis.rigging.weights`). Those are the two solves of the weight step, both
``problem -> WeightSolution``: :func:`facebasis.rigging.certify.certify_problem` and
:meth:`facebasis.rigging.weights.WeightSolver.solve_problem`.

Array conventions: ``G`` (k, k); ``c`` (m, k), row j = ``B^T t_j``; ``const`` (m,); ``prior``
(m, k), the rough weights ``x~`` (zeros if not given); ``pairs`` (P, 2) shape indices; weights
``X`` (m, k), row j = ``x_j``.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import InputError

#: ``WeightSolution.ipopt_status`` of a weight step that did not run IPOPT
IPOPT_NOT_RUN = "not run"


def check_pairs(pairs, k: int, what: str = "exclusive pairs") -> np.ndarray:
    """Exclusive pairs as a (P, 2) int64 array of shape indices in ``[0, k)``, two different per pair.

    Raises
    ------
    InputError
        not a list of pairs, non-integer or out-of-range indices, a pair naming one shape twice
    """
    P = np.asarray(pairs)
    if P.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if P.ndim != 2 or P.shape[1] != 2:
        raise InputError(f"{what}: expected (P, 2) shape index pairs, found an array of shape {P.shape}")
    whole = np.issubdtype(P.dtype, np.integer) or (
        np.issubdtype(P.dtype, np.floating) and np.all(np.isfinite(P)) and np.all(P == np.round(P)))
    if not whole:
        raise InputError(f"{what}: expected integer shape indices, found {P.tolist()}")
    P = P.astype(np.int64)
    if P.min() < 0 or P.max() >= k:
        raise InputError(f"{what}: expected shape indices in [0, {k}), found {P.tolist()}")
    same = P[:, 0] == P[:, 1]
    if same.any():
        raise InputError(f"{what}: a pair names one shape twice: {P[same].tolist()} (expected two different shapes)")
    return P


def pair_products(X, P) -> np.ndarray:
    """Largest ``|x_a x_b|`` over the pairs ``P`` (P, 2) for every row of ``X`` (m, k): (m,)."""
    X = np.atleast_2d(np.asarray(X, np.float64))
    if len(P) == 0 or X.shape[1] == 0:
        return np.zeros(len(X))
    return np.abs(X[:, P[:, 0]] * X[:, P[:, 1]]).max(axis=1)


def bound_excess(X) -> np.ndarray:
    """Largest violation of ``0 <= x <= 1`` for every row of ``X`` (m, k): (m,), 0 inside the box."""
    X = np.atleast_2d(np.asarray(X, np.float64))
    if X.shape[1] == 0:
        return np.zeros(len(X))
    return np.maximum(0.0, np.maximum(-X.min(axis=1), X.max(axis=1) - 1.0))


def complementarity_violation(X, pairs) -> float:
    """``max |x_a x_b|`` over the exclusive pairs (P, 2) and every row of ``X`` ((k,) or (m, k))."""
    r = pair_products(X, np.asarray(pairs, np.int64).reshape(-1, 2))
    return float(r.max()) if r.size else 0.0


def bound_violation(X) -> float:
    """Largest violation of ``0 <= x <= 1`` over ``X`` ((k,) or (m, k))."""
    r = bound_excess(X)
    return float(r.max()) if r.size else 0.0


def gram_data(rig, expressions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Gram quantities of eq. 5 for expressions (m, n, 3) against a rig's blendshapes:
    ``G = B^T B`` (k, k), ``c`` (m, k) with row j ``B^T t_j`` and ``const = t_j^T t_j`` (m,), with
    ``t_j = T_j - B_0`` flattened; BLAS on one thread (its spinning threads cost more than they
    gain for these sizes on a shared machine)."""
    from threadpoolctl import threadpool_limits

    E = np.asarray(expressions, np.float64)
    if E.ndim != 3 or E.shape[1:] != rig.neutral.shape:
        raise InputError(f"expressions: expected shape (m, {rig.n_vertices}, 3), found {E.shape}")
    T = (E - rig.neutral).reshape(len(E), -1)
    B = rig.deltas.reshape(rig.n_shapes, -1)
    with threadpool_limits(1):
        G, C = B @ B.T, B @ T.T
    return G, C.T, np.einsum("ij,ij->i", T, T)


def _as_float(a, name):
    a = np.asarray(a, np.float64)
    if not np.isfinite(a).all():
        raise InputError(f"weight problem: expected finite Gram matrices and prior weights, found NaN/inf in {name}")
    return a


class ExampleResiduals:
    """Mixin of a one-example answer ``x`` (k,) of ``problem`` (a one-example :class:`WeightProblem`):
    its residuals are computed from the problem, never stored."""

    @property
    def max_complementarity(self) -> float:
        """``max |x_a x_b|`` over the problem's exclusive pairs at x."""
        return float(self.problem.complementarity(self.x)[0])

    @property
    def max_bound_violation(self) -> float:
        """Largest violation of ``0 <= x <= 1`` at x."""
        return float(self.problem.bounds(self.x)[0])


@dataclass(frozen=True, eq=False)
class WeightProblem:
    """Eq. 5 for m examples that share the blendshapes (module docstring).

    Parameters
    ----------
    G : (k, k) Gram matrix ``B^T B`` (symmetric positive semidefinite)
    c : (m, k) linear terms, row j = ``B^T t_j``; a (k,) vector is one example
    const : (m,) constants ``t_j^T t_j`` (they only shift the objective); a number for one example
    pairs : (P, 2) exclusive shape index pairs (:func:`check_pairs`)
    prior : (m, k) rough weights ``x~`` or None (zeros)
    lam : prior weight lambda >= 0

    Everything is checked when the problem is made (shapes, finiteness, symmetry and
    semidefiniteness of G, lambda, the pairs); :class:`InputError` says what was expected and found.
    """

    G: np.ndarray
    c: np.ndarray
    const: np.ndarray
    pairs: np.ndarray = ()
    prior: np.ndarray | None = None
    lam: float = 0.0

    def __post_init__(self):
        G = _as_float(self.G, "G")
        if G.ndim != 2 or G.shape[0] != G.shape[1]:
            raise InputError(f"Gram matrix G: expected a square (k, k) matrix, found shape {G.shape}")
        lam = float(self.lam)
        if not np.isfinite(lam):
            raise InputError(f"lambda: expected a finite number, found {lam}")
        if lam < 0:
            raise InputError(f"lambda: expected >= 0, found {lam}")
        if not np.allclose(G, G.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(G).max(initial=0.0))):
            raise InputError(f"Gram matrix G: expected a symmetric matrix, found an asymmetric one (largest "
                             f"|G - G^T| {np.abs(G - G.T).max():.3g})")
        k = G.shape[0]
        object.__setattr__(self, "G", G)
        object.__setattr__(self, "lam", lam)
        object.__setattr__(self, "pairs", check_pairs(self.pairs, k))
        self._set_examples(self.c, self.const, self.prior)
        ev = self.eigenvalues
        if ev.size and ev[0] < -1e-10 * max(1.0, abs(ev[-1])):
            raise InputError(f"Gram matrix G + lambda I: expected positive semidefinite, found smallest "
                             f"eigenvalue {ev[0] / 2:.3g} (a Gram matrix B^T B cannot be indefinite)")

    def _set_examples(self, c, const, prior):
        k, shape = self.k, np.shape(c)
        c = _as_float(c, "c")
        one = c.ndim == 1
        c = c.reshape(1, -1) if one else c
        if c.ndim != 2 or c.shape[1] != k:
            raise InputError(f"linear terms c: expected shape (m, {k}) (or ({k},) for one example), found {shape}")
        m = len(c)
        const = _as_float(const, "const")
        const = const.reshape(1) if const.ndim == 0 else const
        if const.shape != (m,):
            raise InputError(f"constants const: expected shape ({m},), found {const.shape}")
        if prior is None:
            prior = np.zeros((m, k))
        else:
            prior = _as_float(prior, "prior")
            prior = prior.reshape(1, -1) if m == 1 and prior.ndim == 1 else prior
            if prior.shape != (m, k):
                raise InputError(f"prior: expected shape ({m}, {k}) or None, found {prior.shape}")
        object.__setattr__(self, "c", c)
        object.__setattr__(self, "const", const)
        object.__setattr__(self, "prior", prior)

    def __repr__(self) -> str:
        return f"WeightProblem(k={self.k}, m={self.m}, pairs={self.pairs.tolist()}, lam={self.lam:g})"

    # --- sizes and the QP form ---------------------------------------------------------------------

    @property
    def k(self) -> int:
        """Number of shapes."""
        return self.G.shape[0]

    @property
    def m(self) -> int:
        """Number of examples."""
        return len(self.c)

    @cached_property
    def hessian(self) -> np.ndarray:
        """``H = 2 (G + lambda I)`` (k, k), G symmetrised: ``f_j(x) = 1/2 x^T H x + g_j^T x + const``."""
        return 2.0 * (0.5 * (self.G + self.G.T) + self.lam * np.eye(self.k))

    @cached_property
    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of :attr:`hessian`, ascending (k,)."""
        return np.linalg.eigvalsh(self.hessian)

    def linear_term(self, j: int) -> np.ndarray:
        """``g_j = -2 (c_j + lambda x~_j)`` (k,), the linear term of example j's QP form."""
        return -2.0 * (self.c[j] + self.lam * self.prior[j])

    def offset(self, j: int) -> float:
        """``const_j + lambda ||x~_j||^2``, the constant of example j's QP form."""
        return float(self.const[j]) + self.lam * float(self.prior[j] @ self.prior[j])

    # --- the objective and the residuals ----------------------------------------------------------

    def _weights(self, X) -> np.ndarray:
        X = np.asarray(X, np.float64)
        X = X.reshape(1, -1) if X.ndim == 1 and self.m == 1 else X
        if X.shape != (self.m, self.k):
            raise InputError(f"weights: expected shape ({self.m}, {self.k}), found {X.shape}")
        return X

    def objective(self, X) -> np.ndarray:
        """``f_j(x_j)`` of eq. 5 for weights X (m, k) (or (k,) when m = 1): (m,), constants included."""
        X = self._weights(X)
        D = X - self.prior
        return (np.einsum("jk,jk->j", X @ self.G, X) - 2.0 * np.einsum("jk,jk->j", self.c, X) + self.const
                + self.lam * np.einsum("jk,jk->j", D, D))

    def total_objective(self, X) -> float:
        """Eq. 5 summed over the examples (the weight step's objective)."""
        return float(self.objective(X).sum())

    def complementarity(self, X) -> np.ndarray:
        """Largest ``|x_a x_b|`` over the pairs for every example of X (m, k): (m,)."""
        return pair_products(self._weights(X), self.pairs)

    def bounds(self, X) -> np.ndarray:
        """Largest violation of ``0 <= x <= 1`` for every example of X (m, k): (m,)."""
        return bound_excess(self._weights(X))

    # --- making problems --------------------------------------------------------------------------

    @classmethod
    def from_rig(cls, rig, expressions, pairs=(), prior=None, lam: float = 0.0) -> WeightProblem:
        """Eq. 5 for expressions (m, n, 3) against ``rig``'s blendshapes (:func:`gram_data`)."""
        G, c, const = gram_data(rig, expressions)
        return cls(G, c, const, pairs, prior, lam)

    def with_examples(self, c, const, prior=None) -> WeightProblem:
        """The same G, pairs and lambda (not checked again) with other examples (checked)."""
        new = object.__new__(type(self))
        for name in ("G", "pairs", "lam", "c", "const", "prior"):
            object.__setattr__(new, name, getattr(self, name))
        new.__dict__.update({k: v for k, v in self.__dict__.items() if k in ("hessian", "eigenvalues")})
        new._set_examples(c, const, prior)
        return new

    def example(self, j: int) -> WeightProblem:
        """Example j alone (m = 1), sharing G and the checks."""
        return self.with_examples(self.c[j:j + 1], self.const[j:j + 1], self.prior[j:j + 1])

    def restrict(self, free) -> tuple[WeightProblem, np.ndarray]:
        """The problem over the shapes ``free`` (k,) bool, the others held at 0.

        Returns (sub-problem, indices of the free shapes). The pairs keep those whose both shapes
        are free (the others hold trivially) and the held weights' prior terms
        ``lambda ||0 - x~_held||^2`` join the constants, so the sub-problem's objective at
        ``x[free]`` equals this problem's at ``x``.
        """
        free = np.asarray(free, bool)
        if free.shape != (self.k,):
            raise InputError(f"free shapes: expected a ({self.k},) bool array, found shape {free.shape}")
        idx = np.flatnonzero(free)
        pos = np.full(self.k, -1)
        pos[idx] = np.arange(len(idx))
        P = self.pairs
        P = pos[P[(pos[P] >= 0).all(axis=1)]] if len(P) else P
        held = self.prior[:, ~free]
        const = self.const + self.lam * np.array([float(h @ h) for h in held])
        return WeightProblem(self.G[np.ix_(idx, idx)], self.c[:, idx], const, P, self.prior[:, idx], self.lam), idx


@dataclass(frozen=True, eq=False)
class WeightSolution:
    """Weights of a :class:`WeightProblem` and how they were found; residuals come from the problem.

    Attributes
    ----------
    problem : the problem solved
    X : (m, k) weights (``weights`` is the same array)
    kkt_residual : largest KKT residual of the optimal branches' box-QPs (0 if not certified)
    polished : the weights are the certified optimum (branch and bound) of every example
    seconds : wall time of the solve
    certificate_nodes : box-QPs solved by branch and bound over all examples
    certificate_gap : largest ``objective - lower bound`` over the examples (NaN if not certified)
    ipopt_status, ipopt_iterations, ipopt_success : IPOPT's run (:data:`IPOPT_NOT_RUN`, 0 and True
        if IPOPT did not run)
    ipopt_X : (m, k) IPOPT's raw answer, or None if it did not run
    """

    problem: WeightProblem
    X: np.ndarray
    kkt_residual: float = 0.0
    polished: bool = True
    seconds: float = 0.0
    certificate_nodes: int = 0
    certificate_gap: float = float("nan")
    ipopt_status: str = IPOPT_NOT_RUN
    ipopt_iterations: int = 0
    ipopt_success: bool = True
    ipopt_X: np.ndarray | None = None

    @property
    def weights(self) -> np.ndarray:
        """(m, k) the solved weights."""
        return self.X

    @cached_property
    def objectives(self) -> np.ndarray:
        """(m,) eq. 5 objective of every example at ``X``."""
        return self.problem.objective(self.X)

    @property
    def objective(self) -> float:
        """Eq. 5 at ``X``, summed over the examples (constants included)."""
        return float(self.objectives.sum())

    @property
    def max_complementarity(self) -> float:
        """``max |x_a x_b|`` over the pairs and examples at ``X``."""
        return _largest(self.problem.complementarity(self.X))

    @property
    def max_bound_violation(self) -> float:
        """Largest violation of ``0 <= x <= 1`` at ``X``."""
        return _largest(self.problem.bounds(self.X))

    @property
    def ipopt_weights(self) -> np.ndarray:
        """(m, k) IPOPT's raw answer (NaN if IPOPT did not run)."""
        return np.full_like(self.X, np.nan) if self.ipopt_X is None else self.ipopt_X

    @property
    def ipopt_objective(self) -> float:
        """Eq. 5 at IPOPT's raw answer (NaN if it did not run)."""
        return float("nan") if self.ipopt_X is None else self.problem.total_objective(self.ipopt_X)

    @property
    def ipopt_max_complementarity(self) -> float:
        return float("nan") if self.ipopt_X is None else _largest(self.problem.complementarity(self.ipopt_X))

    @property
    def ipopt_max_bound_violation(self) -> float:
        return float("nan") if self.ipopt_X is None else _largest(self.problem.bounds(self.ipopt_X))


def _largest(r) -> float:
    return float(r.max()) if r.size else 0.0


__all__ = ["WeightProblem", "WeightSolution", "IPOPT_NOT_RUN", "check_pairs", "pair_products",
           "bound_excess", "complementarity_violation", "bound_violation", "gram_data"]
