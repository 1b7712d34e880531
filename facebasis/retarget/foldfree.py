"""A fold-free 2D mesh deformation: the warp gives way where the driven motion would fold it.

The cartoon's warp mesh moves its vertices to the positions eq. 12 asks for (``target``). When the
capture's landmarks cross (a lower lip pushed through the upper one by tracking noise, an eyelid
through the other, a jaw point through its neighbour), some triangles of that target turn over
and the piecewise-affine warp tears and folds the image. This module finds, per frame, positions
``x`` that are as close to the target as possible while every triangle's Jacobian stays in the
set of orientation-preserving maps of bounded compression

    K = { J in R^{2x2} : det J > 0, sigma_min(J) >= sigma_lo }

(Jacobians against the rest mesh; bounded-distortion mapping, Lipman 2012, and the local/global
iteration of as-rigid-as-possible deformation, Sorkine & Alexa 2007 / Liu et al. 2008):

    min_x  sum_t A_t || J_t(x) - P_K(J_t(x)) ||_F^2 + lambda sum_i mu_i || x_i - target_i ||^2   (1)

* local step: every Jacobian is projected onto K in closed form. A 2x2 matrix is the sum of a
  conformal part z1 and an anti-conformal part z2 (complex numbers); its signed singular values
  are |z1| + |z2| and |z1| - |z2| (negative when the triangle is flipped). The Frobenius-nearest
  member of K keeps both phases and clamps the signed singular values (the smallest to at least
  ``sigma_lo``): vectorised over all triangles, no SVD call.
* global step: the quadratic (1) with the projections fixed; its matrix ``G^T A G + lambda M``
  (G the per-triangle gradient operator, A the rest areas, M the lumped vertex areas divided by
  the squared mean edge length) does not depend on the frame and is factorised once (sparse LU,
  SciPy's SuperLU); every iteration is two triangular solves.

Frames whose target has no triangle outside K are returned unchanged (the warp is the paper's
exactly); the iteration starts from the target and stops as soon as every triangle is inside K up
to a factor 1/2 of ``sigma_lo``. The result is then checked exactly: every triangle's area
relative to the rest (``det J``) must be at least ``margin``. If the iteration did not get there,
a fallback that always does: the positions are blended towards the rest mesh,
``x(alpha) = rest + alpha (x - rest)``; ``det J_t(x(alpha))`` is a quadratic in alpha
(``1 + alpha tr(J - I) + alpha^2 det(J - I)``), so the largest alpha in [0, 1] for which every
triangle keeps ``det J >= margin`` all the way from the rest is found in closed form, not by
bisection. The rest mesh (alpha = 0) has ``det J = 1`` everywhere, so a fold-free frame always
exists.

Degenerate rest triangles (zero area, no orientation to keep) are left out of (1) and of the check.

Written here rather than taken from a library: the projection is a few vectorised lines, the
factorisation is SciPy's SuperLU; libigl (only a test dependency here) offers SLIM and ARAP, which
minimise a distortion energy from a given injective start rather than fitting a per-frame target
with a fold-free guarantee, and would add a compiled runtime dependency to every install.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: the smallest stretch a triangle may take along any direction (a lip or eyelid gap may shrink to
#: 15% of its rest height, no further); the warp starts to give way there
SIGMA_LO = 0.15
#: weight of the data term in (1): small, so the projection (no fold) wins where they conflict
DATA_WEIGHT = 0.02
#: smallest area ratio (det J) a written frame may have
MARGIN = 1e-3


def project_jacobians(J: np.ndarray, sigma_lo: float, sigma_hi: float = np.inf) -> np.ndarray:
    """Frobenius-nearest members of ``{det > 0, sigma_lo <= sigma_min, sigma_max <= sigma_hi}``.

    Parameters
    ----------
    J : (m, 2, 2) Jacobians
    sigma_lo, sigma_hi : bounds of the singular values (0 < sigma_lo <= sigma_hi)

    Returns
    -------
    (m, 2, 2) projections; Jacobians already inside are returned as they are (to rounding).
    """
    z1 = 0.5 * ((J[:, 0, 0] + J[:, 1, 1]) + 1j * (J[:, 1, 0] - J[:, 0, 1]))   # conformal part
    z2 = 0.5 * ((J[:, 0, 0] - J[:, 1, 1]) + 1j * (J[:, 1, 0] + J[:, 0, 1]))   # anti-conformal part
    r1, r2 = np.abs(z1), np.abs(z2)
    s1 = np.clip(r1 + r2, sigma_lo, sigma_hi)            # largest singular value
    s2 = np.clip(r1 - r2, sigma_lo, s1)                  # signed smallest: negative = flipped
    e1 = np.where(r1 > 0, z1 / np.where(r1 > 0, r1, 1.0), 1.0)
    e2 = np.where(r2 > 0, z2 / np.where(r2 > 0, r2, 1.0), 1.0)
    w1, w2 = 0.5 * (s1 + s2) * e1, 0.5 * (s1 - s2) * e2
    P = np.empty_like(J)
    P[:, 0, 0] = w1.real + w2.real
    P[:, 0, 1] = -w1.imag + w2.imag
    P[:, 1, 0] = w1.imag + w2.imag
    P[:, 1, 1] = w1.real - w2.real
    return P


def smallest_singular_signed(J: np.ndarray) -> np.ndarray:
    """Signed smallest singular value (m,) of 2x2 Jacobians (m, 2, 2): negative when flipped."""
    z1 = 0.5 * ((J[:, 0, 0] + J[:, 1, 1]) + 1j * (J[:, 1, 0] - J[:, 0, 1]))
    z2 = 0.5 * ((J[:, 0, 0] - J[:, 1, 1]) + 1j * (J[:, 1, 0] + J[:, 0, 1]))
    return np.abs(z1) - np.abs(z2)


@dataclass(frozen=True)
class FoldFreeStats:
    """What :meth:`FoldFreeMap.solve` did to one frame.

    Attributes
    ----------
    folded_before : triangles with ``det J <= 0`` in the target
    projected : True if the target had a triangle outside K (the iteration ran)
    iterations : local/global iterations run
    alpha : 1.0, or the blend towards the rest the fallback needed
    min_det : smallest ``det J`` of the returned positions (>= margin)
    """

    folded_before: int
    projected: bool
    iterations: int
    alpha: float
    min_det: float


class FoldFreeMap:
    """Built once per rest mesh: the gradient operator and the factorised matrix of (1).

    Parameters
    ----------
    rest : (n, 2) rest positions; faces : (m, 3) triangles
    fixed : indices of vertices that never move (e.g. a static outer ring), or None
    sigma_lo : smallest singular value allowed (see :data:`SIGMA_LO`)
    weight : lambda of (1) (see :data:`DATA_WEIGHT`)
    iterations : most local/global iterations per frame
    margin : smallest ``det J`` of a returned frame
    """

    def __init__(self, rest, faces, fixed=None, sigma_lo: float = SIGMA_LO, weight: float = DATA_WEIGHT,
                 iterations: int = 100, margin: float = MARGIN, reweight_every: int = 5):
        import scipy.sparse as sp

        if not (np.isfinite(sigma_lo) and 0 < sigma_lo < 1):
            raise InputError(f"fold-free warp: expected 0 < sigma_lo < 1, found {sigma_lo}")
        if not (np.isfinite(weight) and weight > 0):
            raise InputError(f"fold-free warp: expected a data weight > 0, found {weight}")
        if not (0 < margin < sigma_lo ** 2):
            raise InputError(f"fold-free warp: expected 0 < margin < sigma_lo^2, found {margin}")
        self.rest = np.asarray(rest, np.float64)
        self.faces = np.asarray(faces, np.int64)
        self.sigma_lo, self.weight, self.iterations, self.margin = float(sigma_lo), float(weight), int(iterations), \
            float(margin)
        self.reweight_every = max(int(reweight_every), 1)
        self.fallback_iterations = 30
        n, F = len(self.rest), self.faces
        P0, P1, P2 = self.rest[F[:, 0]], self.rest[F[:, 1]], self.rest[F[:, 2]]
        D = np.stack([P1 - P0, P2 - P0], axis=2)                          # (m, 2, 2), edge columns
        det = D[:, 0, 0] * D[:, 1, 1] - D[:, 0, 1] * D[:, 1, 0]
        size = float(np.ptp(self.rest, axis=0).max()) if n else 1.0
        self.valid = np.abs(det) > 1e-9 * size ** 2                         # degenerate rest triangles: out
        Fv, Dv, detv = F[self.valid], D[self.valid], det[self.valid]
        inv = np.empty_like(Dv)                                             # D^{-1}
        inv[:, 0, 0], inv[:, 0, 1] = Dv[:, 1, 1] / detv, -Dv[:, 0, 1] / detv
        inv[:, 1, 0], inv[:, 1, 1] = -Dv[:, 1, 0] / detv, Dv[:, 0, 0] / detv
        self._inv = inv
        self._fv = Fv
        self.area = 0.5 * np.abs(detv)                                      # (mv,)
        mv = len(Fv)
        # gradient operator G (2 mv, n): row 2t+k gives J_t[c, k] from coordinate c of the vertices
        rows = np.repeat(np.arange(2 * mv), 3)
        coef = np.stack([-(inv[:, 0, :] + inv[:, 1, :]), inv[:, 0, :], inv[:, 1, :]], axis=2)  # (mv, 2, 3)
        cols = np.repeat(Fv[:, None, :], 2, axis=1)
        G = sp.csr_matrix((coef.reshape(-1), (rows, cols.reshape(-1))), shape=(2 * mv, n))
        E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        E = np.unique(E, axis=0)
        h = float(np.mean(np.linalg.norm(self.rest[E[:, 0]] - self.rest[E[:, 1]], axis=1))) if len(E) else 1.0
        mu = np.bincount(Fv.ravel(), weights=np.repeat(self.area / 3.0, 3), minlength=n) / h ** 2
        mu = np.where(mu > 0, mu, 1.0 / 3.0)                                # vertices in no valid triangle
        self._mu = mu
        self._G = G
        free = np.ones(n, bool)
        if fixed is not None:
            free[np.asarray(fixed, np.int64)] = False
        self.free = np.flatnonzero(free)
        self.fixed = np.flatnonzero(~free)
        self._factor = self._factorise(np.ones(mv))                         # factor once
        self._strong = None                                                 # the fallback's, on first use

    def _factorise(self, boost, weight=None):
        """(G^T W, A_free,fixed, LU of A_free,free, lambda) of (1) with triangle weights ``area * boost``."""
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        weight = self.weight if weight is None else weight
        GtW = (self._G.T @ sp.diags(np.repeat(self.area * boost, 2))).tocsr()
        A = (GtW @ self._G + weight * sp.diags(self._mu)).tocsc()
        A_free = A[self.free]
        lu = splu(A_free[:, self.free].tocsc()) if len(self.free) else None
        return GtW, A_free[:, self.fixed].tocsc(), lu, weight

    # ------------------------------------------------------------------------------------------
    def jacobians(self, X) -> np.ndarray:
        """(mv, 2, 2) Jacobians of the valid triangles (rest -> X)."""
        X = np.asarray(X, np.float64)
        F = self._fv
        E = np.stack([X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]], axis=2)
        return E @ self._inv

    def area_ratios(self, X) -> np.ndarray:
        """``det J`` (mv,) of the valid triangles: the signed area of each triangle in ``X`` over its
        signed area at rest; <= 0 means flipped against the rest."""
        return np.linalg.det(self.jacobians(X))

    def folded(self, X) -> np.ndarray:
        """Indices (into ``faces``) of the triangles flipped or collapsed against the rest in X (n, 2)."""
        return np.flatnonzero(self.valid)[self.area_ratios(X) <= 0]

    def _global(self, P, target, factor) -> np.ndarray:
        """Global step of (1): the minimiser for fixed projections P (mv, 2, 2)."""
        GtW, A_fx, lu, weight = factor
        X = target.copy()                                   # fixed vertices stay where the target has them
        if lu is None:
            return X
        for c in range(2):
            rhs = GtW @ P[:, c, :].reshape(-1) + weight * self._mu * target[:, c]
            rhs = rhs[self.free] - A_fx @ target[self.fixed, c]
            X[self.free, c] = lu.solve(rhs)
        return X

    def safe_step(self, X0, X1, floor=None) -> float:
        """Largest beta in [0, 1] with ``det J >= floor`` for every triangle of ``X0 + b (X1 - X0)``
        for all b in [0, beta] (closed form: ``det(J0 + b B)`` is a quadratic in b per triangle).

        ``floor`` (scalar or (mv,)) defaults to ``margin``; ``X0`` must satisfy it."""
        J0 = self.jacobians(X0)
        B = self.jacobians(X1) - J0
        a0 = np.linalg.det(J0)
        floor = self.margin if floor is None else floor
        # det(J0 + b B) = det J0 + b tr(adj(J0) B) + b^2 det B
        lin = J0[:, 0, 0] * B[:, 1, 1] + J0[:, 1, 1] * B[:, 0, 0] - J0[:, 0, 1] * B[:, 1, 0] - J0[:, 1, 0] * B[:, 0, 1]
        c = B[:, 0, 0] * B[:, 1, 1] - B[:, 0, 1] * B[:, 1, 0]
        k = a0 - floor                              # >= 0: c b^2 + lin b + k >= 0 must hold on [0, beta]
        with np.errstate(divide="ignore", invalid="ignore"):
            disc = lin * lin - 4 * c * k
            sq = np.sqrt(np.maximum(disc, 0.0))
            r1 = np.where(c != 0, (-lin - sq) / (2 * c), np.where(lin != 0, -k / lin, np.inf))
            r2 = np.where(c != 0, (-lin + sq) / (2 * c), np.inf)
        roots = np.stack([r1, r2], 1)
        roots = np.where((disc[:, None] >= 0) | (c[:, None] == 0), roots, np.inf)
        roots = np.where(roots > 0, roots, np.inf)
        return float(min(1.0, roots.min())) if len(roots) else 1.0

    def safe_alpha(self, X) -> float:
        """Largest alpha in [0, 1] with ``det J >= margin`` for every triangle of
        ``rest + a (X - rest)`` for all a in [0, alpha] (the rest has ``det J = 1``)."""
        return self.safe_step(self.rest, X)

    def _feasible_descent(self, Y, target, iterations):
        """Local/global steps from a fold-free Y that never leave the fold-free set: each step is cut
        to the largest fraction keeping every ``det J`` above ``min(sigma_lo^2 / 4, its current value)``
        (exact, :meth:`safe_step`); the data term weighs 1 here, so the regions away from the fold
        return to the target within a few steps."""
        if self._strong is None:
            self._strong = self._factorise(np.ones(len(self.area)), weight=1.0)
        for _ in range(iterations):
            J = self.jacobians(Y)
            floor = np.minimum(0.25 * self.sigma_lo ** 2, np.linalg.det(J))
            Z = self._global(project_jacobians(J, self.sigma_lo), target, self._strong)
            beta = self.safe_step(Y, Z, floor)
            if beta <= 0:
                break
            Y = Y + (beta if beta == 1.0 else 0.9 * beta) * (Z - Y)
        return Y

    def solve(self, target):
        """Fold-free positions (n, 2) for target positions (n, 2) (fixed vertices are reset to the
        rest); returns ``(X, FoldFreeStats)``. Every valid triangle of X has ``det J >= margin``."""
        target = np.array(target, np.float64)
        target[self.fixed] = self.rest[self.fixed]
        J = self.jacobians(target)
        s2 = smallest_singular_signed(J)
        folded = int(np.count_nonzero(np.linalg.det(J) <= 0))
        X, it = target, 0
        if len(s2) and s2.min() < self.sigma_lo * (1 - 1e-9):
            factor, boost = self._factor, None
            while it < self.iterations:
                X = self._global(project_jacobians(J, self.sigma_lo), target, factor)
                J = self.jacobians(X)
                it += 1
                s2 = smallest_singular_signed(J)
                if s2.min() >= 0.5 * self.sigma_lo:
                    break
                if it % self.reweight_every == 0:
                    # triangles the iteration has not brought into K weigh more (x4): the fold is
                    # resolved at the cost of their neighbours' fit, never the other way round
                    boost = np.ones(len(s2)) if boost is None else boost
                    boost[s2 < 0.5 * self.sigma_lo] *= 4.0
                    np.minimum(boost, 1e4, out=boost)             # bounded: the system stays well conditioned
                    factor = self._factorise(boost)
        dets = np.linalg.det(J)
        alpha = 1.0
        if len(dets) and dets.min() < self.margin:                # exact check, then the sure fallback
            alpha = self.safe_alpha(X)
            for _ in range(60):                                    # rounding: step back until it holds
                Y = self.rest + alpha * (X - self.rest)
                dets = self.area_ratios(Y)
                if dets.min() >= self.margin or alpha == 0.0:
                    break
                alpha = alpha * 0.999 if alpha > 1e-6 else 0.0
            Z = self._feasible_descent(Y, target, self.fallback_iterations)
            dz = self.area_ratios(Z)
            if dz.min() >= self.margin:                           # exact check again (rounding)
                X, dets = Z, dz
            else:
                X = Y
        return X, FoldFreeStats(folded, it > 0, it, alpha, float(dets.min()) if len(dets) else 1.0)


__all__ = ["FoldFreeMap", "FoldFreeStats", "project_jacobians", "smallest_singular_signed", "SIGMA_LO",
           "DATA_WEIGHT", "MARGIN"]
