"""Exact contact for deformation transfer: no new intersecting triangle pair, smallest energy change.

Problem
-------
For every transferred shape, the delta ``d`` minimising the deformation-transfer energy
(:class:`facebasis.geometry.transfer.DeformationTransfer`) subject to: no vertex-disjoint triangle
pair intersects unless it intersects in the target neutral ``B0`` or in the template shape ``S_i``
(both layer crossings and local folds), and, so that only what must move moves, vertices farther
than ``reach`` from a contact keep the plain solution ``d*``.

Method (separating planes, iterated with the exact counter)
-----------------------------------------------------------
The energy is ``||E d - t||^2`` per coordinate, so with ``x = d - d*`` its increase is exactly
``x^T L x`` with ``L = E^T E`` the factored normal matrix (plus virtual-edge rows, if any).
1. Find the new pairs of the plain solution exactly (:func:`facebasis.contact.proximity.new_pairs`,
   the package's exact predicates).
2. Every new pair (T_i, T_j) is disjoint in ``B0``; its closest-point direction ``n`` there separates
   the two triangles with margin equal to their distance. Require, for the 3 x 3 corners a of T_i and
   b of T_j, ``n . (X_a - X_b) >= delta`` with ``delta = min(margin, dist_B0 / 2)``: then a plane
   separates them and they cannot intersect. ``X = B0`` satisfies every such row, so the problem
   is always feasible.
3. Minimise ``x^T L x`` over the region R (vertices within ``reach`` of a constrained vertex in
   ``B0``, anchors excluded, the rest fixed) subject to the rows: the dual is a small dense
   bound-constrained QP, ``min 1/2 l^T G l - g^T l, l >= 0`` with ``G = A L_RR^-1 A^T``, built from
   the Green's function columns ``L_RR^-1 e_c`` of the constrained vertices (one sparse Cholesky
   of ``L_RR``) and solved exactly by DAQP's active-set method; ``x = L_RR^-1 A^T l``.
4. Check the result exactly on every pair touching R (the others are those of the plain solution);
   add new pairs and violated rows (rows are added lazily: at first only those the plain solution
   violates), repeat until there are none. The final check is complete: pairs away from R are the
   plain solution's, whose new pairs are all constrained.

5. Optionally (``polish``, shapes corrected by more than ``POLISH_RATIO`` of their motion): the planes
   of pairs apart by their margin are re-derived from the solution's closest points (any separating
   plane keeps a pair apart; the target neutral's over-constrain under large rotations such as
   blinks), the QP solved again and the result kept only if the exact check still finds no new pair.

Shapes are corrected in parallel (forked processes, ``workers``). :func:`contact_correct` applies
the same correction to shapes made otherwise (``facebasis rig --contact``: generated shapes).

The plain solution's check is exhaustive without a full search: a pair of triangles that moved at
most ``tau`` (per vertex) can only become intersecting if it is within ``2 tau`` in ``B0``; such
near pairs of ``B0`` are listed once and always re-tested, every other pair holding a triangle that
moved more is searched.

References
----------
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. SIGGRAPH 2004.
- Ericson C. Real-Time Collision Detection. Morgan Kaufmann 2005 (closest points).
- Arnstrom D., Bemporad A., Axehill D. A dual active-set solver for embedded quadratic programming
    using recursive LDL^T updates. IEEE TAC 67(8), 2022 (DAQP).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import InputError
from ..geometry.gradients import edge_operator
from ..geometry.mesh import median_edge_length, validate_vertices
from ..geometry.rig import Rig
from ..geometry.transfer import DeformationTransfer
from .proximity import candidate_pairs, intersecting, new_pairs, triangle_distance

#: largest mesh (vertices) accepted by default: ICT's 14k vertices take ~46 s CPU for 52 shapes (mouthClose excluded)
MAX_VERTICES = 60_000
#: default margin kept between constrained triangles, in median edge lengths of the target neutral
MARGIN_EDGES = 0.05
#: default radius of the region allowed to move around a contact, in median edge lengths
REACH_EDGES = 2.0
#: planes are re-derived from the solution (see ContactSolver._polish) when the correction exceeds this
#: fraction of the plain motion in the region that moves
POLISH_RATIO = 0.1
#: vertices moving less than this (median edge lengths) count as still in the plain solution's check
STILL_EDGES = 0.1


@dataclass(frozen=True)
class ContactShape:
    """Per-shape report. ``new_pairs_left`` is the exact count after the last solve (0 = guarantee
    met); ``min_distance`` the smallest distance between constrained triangles in the result (nan
    without constraints); ``iterations`` solve-and-check rounds; ``solver_iterations`` DAQP
    active-set iterations summed over rounds; ``moved`` vertices in the region allowed to move."""

    name: str
    excluded: bool = False
    plain_new_pairs: int = 0
    new_pairs_left: int = 0
    constrained_pairs: int = 0
    rows: int = 0
    iterations: int = 0
    solver_iterations: int = 0
    moved: int = 0
    min_distance: float = float("nan")
    seconds: float = 0.0


@dataclass(frozen=True)
class ContactResult:
    """The contact-corrected rig, the plain transfer, per-shape reports and where the time went."""

    rig: Rig
    plain: Rig
    shapes: tuple
    seconds: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when no transferred (not excluded) shape has a new intersecting pair left."""
        return all(s.new_pairs_left == 0 for s in self.shapes if not s.excluded)

    def table(self) -> str:
        head = (f"{'shape':18s} {'plain':>6s} {'left':>5s} {'pairs':>6s} {'rows':>5s} {'iter':>4s} {'qp it':>6s} "
                f"{'moved':>6s} {'min dist':>9s} {'s':>6s}")
        lines = [head]
        for s in self.shapes:
            if s.excluded:
                lines.append(f"{s.name:18s} excluded: plain transfer")
                continue
            lines.append(f"{s.name:18s} {s.plain_new_pairs:6d} {s.new_pairs_left:5d} {s.constrained_pairs:6d} "
                         f"{s.rows:5d} {s.iterations:4d} {s.solver_iterations:6d} {s.moved:6d} "
                         f"{s.min_distance:9.4f} {s.seconds:6.2f}")
        return "\n".join(lines)


def _normal_matrix(dt: DeformationTransfer) -> sp.csr_matrix:
    """``L = E^T E (+ w X^T X)``: the normal matrix the transfer factors (before removing anchors)."""
    F, n = dt.template.faces, dt.template.n_vertices
    E = edge_operator(F, n)
    L = E.T @ E
    if dt.poisson.extra_rows is not None:
        X = dt.poisson.extra_rows
        L = L + dt.poisson.extra_weight * (X.T @ X)
    return sp.csr_matrix(L)


class _Cholesky:
    def __init__(self, M: sp.spmatrix):
        from cholespy import CholeskySolverD, MatrixType

        coo = sp.coo_matrix(M)
        self.n = M.shape[0]
        self._s = CholeskySolverD(self.n, coo.row.astype(np.int32), coo.col.astype(np.int32),
                                  coo.data.astype(np.float64), MatrixType.COO)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        b = np.ascontiguousarray(rhs, np.float64)
        x = np.zeros_like(b)
        self._s.solve(b, x)
        return x


def _admm(L: sp.spmatrix, A: sp.csr_matrix, g: np.ndarray, delta: np.ndarray, x: np.ndarray, y: np.ndarray,
          max_iterations: int = 2000, rho_scale: float = 0.5, alpha: float = 1.6):
    """``min 1/2 x^T (I_3 (x) L) x  s.t.  A x >= g`` by ADMM with OSQP's splitting (Stellato et al. 2020):
    stops once every row is met to half its margin ``delta`` and the iterates settle. Returns x, the
    row multipliers and the iterations."""
    n3 = A.shape[1]
    Lb = sp.block_diag([L, L, L], format="csr")
    rho = rho_scale * float(L.diagonal().mean())
    sigma = 1e-6 * rho
    chol = _Cholesky((Lb + sigma * sp.eye(n3) + rho * (A.T @ A)).tocsr())
    At = A.T.tocsr()
    z = np.maximum(g, A @ x)
    k = 0
    for k in range(1, max_iterations + 1):
        x_new = chol.solve((sigma * x + At @ (rho * z - y))[:, None])[:, 0]
        Ax = A @ x_new
        Ax_r = alpha * Ax + (1.0 - alpha) * z  # over-relaxation
        z = np.maximum(g, Ax_r + y / rho)
        y = y + rho * (Ax_r - z)
        step = float(np.abs(x_new - x).max())
        x = x_new
        if np.all(Ax >= g - 0.5 * delta) and step <= 1e-3 * float(delta.max()):
            break
    return x, y, k


class ContactSolver:
    """Set up once per template and target neutral; :meth:`correct` one plain-transferred shape.

    Parameters
    ----------
    dt : the :class:`DeformationTransfer` whose plain solutions are corrected
    margin : distance kept between constrained triangles (default ``MARGIN_EDGES`` median edges),
        at most half their distance in the target neutral
    reach : radius of the region allowed to move around contacts (default ``REACH_EDGES`` median edges)
    max_iterations : solve-and-check rounds per shape
    polish : rounds re-deriving the separating planes from the solution (kept only if the exact check
        still passes) for shapes corrected by more than ``POLISH_RATIO`` of their motion; 0 = off
    """

    def __init__(self, dt: DeformationTransfer, margin: float | None = None, reach: float | None = None,
                 max_iterations: int = 40, solver: str = "admm", polish: int = 3):
        if solver not in ("admm", "daqp"):
            raise InputError(f"contact solver: expected 'admm' or 'daqp', found {solver!r}")
        self.solver = solver
        self.polish = int(polish)
        self.dt = dt
        self.F = dt.template.faces
        self.B0 = dt.target_neutral
        self.n = dt.template.n_vertices
        h = median_edge_length(self.B0, self.F)
        self.margin = MARGIN_EDGES * h if margin is None else float(margin)
        self.reach = REACH_EDGES * h if reach is None else float(reach)
        for label, v in (("margin", self.margin), ("reach", self.reach)):
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"contact {label}: expected a positive distance, found {v}")
        self.max_iterations = int(max_iterations)
        self.tau = STILL_EDGES * h
        self.L = _normal_matrix(dt)
        self.is_anchor = np.zeros(self.n, bool)
        self.is_anchor[dt.anchors] = True
        self.tree = cKDTree(self.B0)
        m = len(self.F)
        self.vf = sp.csr_matrix((np.ones(3 * m), (self.F.ravel(), np.repeat(np.arange(m), 3))), shape=(self.n, m))
        near = candidate_pairs(self.B0, self.F, pad=2.0 * self.tau)
        if len(near):
            dist, _ = triangle_distance(self.B0[self.F[near[:, 0]]], self.B0[self.F[near[:, 1]]])
            near = near[(dist <= 2.0 * self.tau) & ~intersecting(self.B0, self.F, near)]
        self.near = near  # disjoint pairs of B0 closer than 2 tau: re-tested for every shape

    # --- new pairs ------------------------------------------------------------------------------
    def _plain_new_pairs(self, X, S, d) -> np.ndarray:
        moved = np.sqrt((d ** 2).sum(1)) > self.tau
        sel = moved[self.F].any(1)
        P = new_pairs(X, self.F, (self.B0, S), faces=sel)
        near = self.near[~sel[self.near].any(1)]
        if len(near):
            near = near[intersecting(X, self.F, near) & ~intersecting(S, self.F, near)]
            P = np.concatenate([P, near])
        return P

    # --- one shape --------------------------------------------------------------------------------
    def correct(self, name: str, d_plain: np.ndarray, template_delta: np.ndarray):
        """The corrected delta (n, 3) of one shape and its :class:`ContactShape` report."""
        import daqp

        t0 = time.perf_counter()
        F, B0 = self.F, self.B0
        P = B0 + d_plain
        S = self.dt.template.neutral + template_delta
        found = self._plain_new_pairs(P, S, d_plain)
        plain_new = len(found)
        if plain_new == 0:
            return d_plain, ContactShape(name, plain_new_pairs=0, seconds=time.perf_counter() - t0)
        pairs = np.zeros((0, 2), np.int64)
        normals = np.zeros((0, 3))
        delta = np.zeros(0)
        active = np.zeros(0, np.int64)  # row ids p * 9 + 3 * ka + kb
        R = np.zeros(0, np.int64)
        C = np.zeros(0, np.int64)
        X = P
        x = None
        qp_iters = 0
        it = 0
        left = found
        chol = Z = K = dual = None
        for it in range(1, self.max_iterations + 1):
            if len(found):
                dist, nrm = triangle_distance(B0[F[found[:, 0]]], B0[F[found[:, 1]]])
                pairs = np.concatenate([pairs, found])
                normals = np.concatenate([normals, nrm])
                delta = np.concatenate([delta, np.minimum(self.margin, 0.5 * dist)])
            vals = self._row_values(X, pairs, normals, delta)  # (q, 9)
            add = np.flatnonzero(vals.ravel() < -0.5 * np.repeat(delta, 9))
            active = np.union1d(active, add)
            C_new = np.unique(F[pairs].ravel())
            C_new = C_new[~self.is_anchor[C_new]]
            if len(C_new) == 0:
                break
            if not np.array_equal(C_new, C):
                C = C_new
                hits = self.tree.query_ball_point(B0[C], self.reach)
                R_new = np.union1d(R, np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits] + [C])))
                R_new = R_new[~self.is_anchor[R_new]]
                if len(R_new) != len(R) and x is not None:  # carry the correction over to the larger region
                    x_new = np.zeros((len(R_new), 3))
                    x_new[np.searchsorted(R_new, R)] = x
                    x = x_new
                if chol is None or len(R_new) != len(R):
                    R = R_new
                    if self.solver == "daqp":
                        chol = _Cholesky(self.L[R][:, R])
                    else:
                        chol = True
                if self.solver == "daqp":
                    pos = np.searchsorted(R, C)
                    E = np.zeros((len(R), len(C)))
                    E[pos, np.arange(len(C))] = 1.0
                    Z = chol.solve(E)  # Green's function columns of the constrained vertices, (|R|, |C|)
                    Zc = Z[pos]
            # rows -> sparse coefficient matrices per coordinate over C
            p, ka, kb = active // 9, (active % 9) // 3, active % 3
            va, vb = F[pairs[p, 0], ka], F[pairs[p, 1], kb]
            nr = normals[p]
            g = delta[p] - (nr * (P[va] - P[vb])).sum(1)
            ca = np.searchsorted(C, va)
            cb = np.searchsorted(C, vb)
            ok_a = (ca < len(C)) & (C[np.minimum(ca, len(C) - 1)] == va)
            ok_b = (cb < len(C)) & (C[np.minimum(cb, len(C) - 1)] == vb)
            c = len(active)
            rows = np.arange(c)
            A = []
            for k in range(3):
                A.append(sp.csr_matrix((np.concatenate([nr[ok_a, k], -nr[ok_b, k]]),
                                        (np.concatenate([rows[ok_a], rows[ok_b]]),
                                         np.concatenate([ca[ok_a], cb[ok_b]]))), shape=(c, len(C))))
            if self.solver == "daqp":
                # primal QP over the constrained vertices' corrections y_k = x_C[:, k]: the energy of the
                # best extension to R is 1/2 sum_k y_k^T K y_k with K = (L_RR^-1)_CC^-1 (Schur complement)
                if K is None or K.shape[0] != len(C):
                    K = np.linalg.inv(0.5 * (Zc + Zc.T))
                    K = 0.5 * (K + K.T)
                    H = np.kron(np.eye(3), K)
                Ad = np.hstack([A[k].toarray() for k in range(3)])
                y, _, flag, info = daqp.solve(H, np.zeros(3 * len(C)), Ad, np.full(c, 1e30), g)
                qp_iters += int(info.get("iterations", 0))
                if flag < 1:
                    raise RuntimeError(f"contact ({name}): the separation QP failed (DAQP exit flag {flag})")
                x = np.stack([Z @ (K @ y[k * len(C):(k + 1) * len(C)]) for k in range(3)], 1)
            else:
                # the same QP over R's corrections (3 |R| unknowns, sparse), by ADMM (OSQP's splitting)
                pr = np.searchsorted(R, C)
                AR = sp.hstack([sp.csr_matrix((A[k].data, pr[A[k].indices], A[k].indptr), shape=(c, len(R)))
                                for k in range(3)]).tocsr()
                xs = np.zeros(3 * len(R)) if x is None or len(x) != len(R) else x.T.ravel().copy()
                ys = np.zeros(c) if dual is None else np.concatenate([dual, np.zeros(c - len(dual))])
                xs, dual, n_it = _admm(self.L[R][:, R], AR, g, delta[p], xs, ys)
                qp_iters += n_it
                x = xs.reshape(3, len(R)).T
            X = P.copy()
            X[R] += x
            touch = (self.vf.T @ np.isin(np.arange(self.n), R).astype(np.float64)) > 0
            left = new_pairs(X, F, (B0, S), faces=touch)
            code = pairs[:, 0] * len(F) + pairs[:, 1]
            found = left[~np.isin(left[:, 0] * len(F) + left[:, 1], code)]
            if len(left) == 0:  # the exact guarantee is met
                break
        if (self.polish and self.solver == "admm" and len(left) == 0 and x is not None and len(pairs)
                and np.linalg.norm(x) > POLISH_RATIO * np.linalg.norm(d_plain[R])):
            X, x, extra = self._polish(name, P, S, X, x, dual, pairs, normals, delta, active, C, R)
            it += extra[0]
            qp_iters += extra[1]
        d = d_plain.copy()
        if x is not None:
            d[R] += x
        dist, _ = triangle_distance(X[F[pairs[:, 0]]], X[F[pairs[:, 1]]])
        return d, ContactShape(name, False, plain_new, len(left), len(pairs), len(active), it, qp_iters, len(R),
                               float(dist.min()) if len(dist) else float("nan"), time.perf_counter() - t0)

    def _admm_rows(self, P, pairs, normals, delta, active, C, R, x, dual):
        """The separation QP over R's corrections for the given rows, by ADMM: x (|R|, 3), duals, iterations."""
        F = self.F
        p, ka, kb = active // 9, (active % 9) // 3, active % 3
        va, vb = F[pairs[p, 0], ka], F[pairs[p, 1], kb]
        nr = normals[p]
        g = delta[p] - (nr * (P[va] - P[vb])).sum(1)
        pa, pb = np.searchsorted(R, va), np.searchsorted(R, vb)
        ok_a = (pa < len(R)) & (R[np.minimum(pa, len(R) - 1)] == va)
        ok_b = (pb < len(R)) & (R[np.minimum(pb, len(R) - 1)] == vb)
        c = len(active)
        rows = np.arange(c)
        AR = sp.hstack([sp.csr_matrix((np.concatenate([nr[ok_a, k], -nr[ok_b, k]]),
                                       (np.concatenate([rows[ok_a], rows[ok_b]]),
                                        np.concatenate([pa[ok_a], pb[ok_b]]))), shape=(c, len(R)))
                        for k in range(3)]).tocsr()
        xs = x.T.ravel().copy()
        ys = np.zeros(c) if dual is None or len(dual) != c else dual
        xs, dual, n_it = _admm(self.L[R][:, R], AR, g, delta[p], xs, ys)
        return xs.reshape(3, len(R)).T, dual, n_it

    def _polish(self, name, P, S, X, x, dual, pairs, normals, delta, active, C, R):
        """Separating planes re-derived from the last solution: the planes of the target neutral
        over-constrain under large rotations (blinks), while any plane that separates a pair keeps it
        apart. For every constrained pair apart by at least its margin in X, the plane through X's
        closest points replaces the old one; the QP is solved again and kept only if the exact check
        still finds no new pair (otherwise X is kept). Returns X, x, (rounds, ADMM iterations)."""
        F = self.F
        rounds = qp = 0
        touch = (self.vf.T @ np.isin(np.arange(self.n), R).astype(np.float64)) > 0
        for _ in range(self.polish):
            dist, nrm = triangle_distance(X[F[pairs[:, 0]]], X[F[pairs[:, 1]]])
            ok = dist >= delta
            if not ok.any():
                break
            normals2 = np.where(ok[:, None], nrm, normals)
            vals = self._row_values(P, pairs, normals2, delta)
            active2 = np.union1d(np.flatnonzero(vals.ravel() < -0.5 * np.repeat(delta, 9)), active)
            x2, dual2, n_it = self._admm_rows(P, pairs, normals2, delta, active2, C, R, x, None)
            rounds += 1
            qp += n_it
            X2 = P.copy()
            X2[R] += x2
            if len(new_pairs(X2, F, (self.B0, S), faces=touch)):
                break
            improved = (x2 * (self.L[R][:, R] @ x2)).sum() < (x * (self.L[R][:, R] @ x)).sum()
            X, x, normals, active = X2, x2, normals2, active2
            if not improved:
                break
        return X, x, (rounds, qp)

    def _row_values(self, X, pairs, normals, delta) -> np.ndarray:
        """``n . (X_a - X_b) - delta`` for the 3 x 3 corners of every constrained pair, (q, 9)."""
        if len(pairs) == 0:
            return np.zeros((0, 9))
        A = (X[self.F[pairs[:, 0]]] * normals[:, None]).sum(-1)  # (q, 3)
        B = (X[self.F[pairs[:, 1]]] * normals[:, None]).sum(-1)
        return (A[:, :, None] - B[:, None, :]).reshape(-1, 9) - delta[:, None]


_SOLVER = None  # the solver a forked worker inherits


def _correct_job(job):
    return _SOLVER.correct(*job)


def _available_cores() -> int:
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _correct_all(solver: "ContactSolver", jobs: list, workers: int | None) -> list:
    """``solver.correct`` on every job, in order; in ``workers`` forked processes when more than one
    (largest plain motion first, so that the slow shapes start early)."""
    import multiprocessing as mp

    workers = _available_cores() if workers is None else int(workers)
    workers = max(1, min(workers, len(jobs)))
    if workers == 1 or "fork" not in mp.get_all_start_methods():
        return [solver.correct(*job) for job in jobs]
    global _SOLVER
    order = sorted(range(len(jobs)), key=lambda k: -float(np.abs(jobs[k][1]).sum()))
    _SOLVER = solver
    try:
        pool = mp.get_context("fork").Pool(workers)
        try:
            done = pool.map(_correct_job, [jobs[k] for k in order], chunksize=1)
            pool.close()
        finally:
            pool.terminate()
            pool.join()
    finally:
        _SOLVER = None
    out = [None] * len(jobs)
    for k, r in zip(order, done):
        out[k] = r
    return out


def contact_transfer(template: Rig, target_neutral, names=None, exclude=(), anchors=None, margin=None,
                     reach=None, allow_target_pairs: bool = False, max_vertices: int = MAX_VERTICES,
                     max_iterations: int = 40, transfer: DeformationTransfer | None = None,
                     workers: int | None = None) -> ContactResult:
    """Deformation transfer with exact contact: no triangle pair intersects in a transferred shape
    unless it intersects in the target neutral or in the template shape.

    Parameters
    ----------
    template : Rig; target_neutral : (n, 3) in its topology
    names : shapes to transfer (default all); exclude : shape names left as plain transfer (e.g.
        shapes meant to press layers together whose result should not be corrected)
    anchors : as :class:`DeformationTransfer`; transfer : an existing one to reuse (virtual edges...)
    margin, reach : see :class:`ContactSolver`
    allow_target_pairs : accept a target neutral that intersects itself where the template neutral does
        not (its pairs stay allowed); by default that is an error
    max_vertices : refuse larger meshes (time budget)
    workers : processes correcting shapes in parallel (default: the available cores; 1 = in this
        process; needs the ``fork`` start method, otherwise 1)

    Returns
    -------
    :class:`ContactResult`; ``result.ok`` is False if any shape has new pairs left (see its report).
    """
    t_all = time.perf_counter()
    if template.n_vertices > max_vertices:
        raise InputError(f"contact: expected a mesh of at most {max_vertices} vertices for the time budget (ICT's "
                         f"14062 take ~46 s CPU for 52 shapes without mouthClose, on all cores), found {template.n_vertices}; pass max_vertices= to "
                         "allow more, or transfer without contact")
    B0 = validate_vertices(target_neutral, "target neutral", template.n_vertices)
    names = list(template.names) if names is None else list(names)
    template.index(names)
    exclude = [exclude] if isinstance(exclude, str) else list(exclude)
    unknown = [e for e in exclude if e not in template.names]
    if unknown:
        raise InputError(f"contact exclude: expected shape names of the template ({', '.join(template.names[:4])}, "
                         f"...), found unknown {', '.join(repr(u) for u in unknown)}")
    seconds = {}
    t = time.perf_counter()
    bad = new_pairs(B0, template.faces, (template.neutral,))
    seconds["target check"] = time.perf_counter() - t
    if len(bad) and not allow_target_pairs:
        ex = ", ".join(f"({i}, {j})" for i, j in bad[:5].tolist())
        raise InputError(f"target neutral: expected no intersecting triangle pairs beyond the template neutral's, "
                         f"found {len(bad)} (triangles {ex}{', ...' if len(bad) > 5 else ''}); fix the mesh or pass "
                         "allow_target_pairs=True to keep them allowed")
    t = time.perf_counter()
    dt = DeformationTransfer(template, B0, anchors) if transfer is None else transfer
    plain = dt.transfer(names)
    seconds["plain transfer"] = time.perf_counter() - t
    t = time.perf_counter()
    solver = ContactSolver(dt, margin, reach, max_iterations)
    seconds["contact setup"] = time.perf_counter() - t
    t = time.perf_counter()
    deltas = plain.deltas.copy()
    reports = [ContactShape(name, excluded=True) if name in exclude else None for name in names]
    idx = template.index(names)
    todo = [k for k, name in enumerate(names) if name not in exclude]
    jobs = [(names[k], plain.deltas[k], template.deltas[idx[k]]) for k in todo]
    for k, (d, rep) in zip(todo, _correct_all(solver, jobs, workers)):
        deltas[k] = d
        reports[k] = rep
    seconds["shapes"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t_all
    seconds["workers"] = max(1, min(_available_cores() if workers is None else int(workers), len(todo)))
    rig = Rig(B0, template.faces, tuple(names), deltas, source="deformation transfer, exact contact")
    return ContactResult(rig, plain, tuple(reports), seconds)


def contact_correct(rig: Rig, template: Rig, transfer: DeformationTransfer | None = None, exclude=(),
                    margin=None, reach=None, max_iterations: int = 40, workers: int | None = None) -> ContactResult:
    """Exact contact for shapes made otherwise (e.g. example-based generation) on the target neutral
    ``rig.neutral``: each shape of ``rig`` (named as in ``template``) is moved, least in the
    deformation-transfer energy of ``transfer`` (default a plain one onto ``rig.neutral``), so that no
    triangle pair intersects unless it intersects in ``rig.neutral`` or in the template's shape of
    the same name. ``result.plain`` is ``rig`` itself."""
    B0 = validate_vertices(rig.neutral, "target neutral", template.n_vertices)
    names = list(rig.names)
    idx = template.index(names)
    exclude = [exclude] if isinstance(exclude, str) else list(exclude)
    unknown = [e for e in exclude if e not in names]
    if unknown:
        raise InputError(f"contact exclude: expected shape names of the rig, found unknown "
                         f"{', '.join(repr(u) for u in unknown)}")
    t_all = time.perf_counter()
    dt = DeformationTransfer(template, B0) if transfer is None else transfer
    if not np.allclose(dt.target_neutral, B0):
        raise InputError("contact: expected the transfer's target neutral to be the rig's neutral")
    seconds = {}
    t = time.perf_counter()
    solver = ContactSolver(dt, margin, reach, max_iterations)
    seconds["contact setup"] = time.perf_counter() - t
    t = time.perf_counter()
    deltas = np.array(rig.deltas, dtype=np.float64, copy=True)
    reports = [ContactShape(name, excluded=True) if name in exclude else None for name in names]
    todo = [k for k, name in enumerate(names) if name not in exclude]
    jobs = [(names[k], deltas[k].copy(), template.deltas[idx[k]]) for k in todo]
    for k, (d, rep) in zip(todo, _correct_all(solver, jobs, workers)):
        deltas[k] = d
        reports[k] = rep
    seconds["shapes"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t_all
    out = Rig(B0, template.faces, tuple(names), deltas, source=f"{rig.source}, exact contact" if getattr(rig, "source", None)
              else "exact contact")
    return ContactResult(out, rig, tuple(reports), seconds)


__all__ = ["ContactShape", "ContactResult", "ContactSolver", "contact_transfer", "contact_correct", "MAX_VERTICES", "MARGIN_EDGES",
           "REACH_EDGES"]
