"""The exact contact solver of one shape: separating planes, the separation QP, the exact check.

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
``x^T L x`` with ``L = E^T E`` the factored normal matrix (plus virtual-edge rows, if any); with
``stiffness`` beta, ``x^T (L + beta I) x`` (large beta: the smallest displacement, for generated shapes
whose fit to examples is measured by vertex positions; see :mod:`facebasis.contact.exact`).
1. Find the new pairs of the plain solution exactly (:func:`facebasis.contact.proximity.new_pairs`,
   the package's exact predicates).
2. Every new pair (T_i, T_j) is disjoint in ``B0``; its closest-point direction ``n`` there separates
   the two triangles with margin equal to their distance. Require, for the 3 x 3 corners a of T_i and
   b of T_j, ``n . (X_a - X_b) >= delta`` with ``delta = min(margin, dist_B0 / 2)``: then a plane
   separates them and they cannot intersect. ``X = B0`` satisfies every such row, so the problem
   is always feasible.
3. Minimise ``x^T L x`` over the region R (vertices within ``reach`` of a constrained vertex in
   ``B0``, anchors excluded, the rest fixed) subject to the rows, by ADMM with OSQP's splitting on the
   sparse problem over R (:func:`facebasis.contact.qp.admm`, the default), or (``solver="daqp"``): the dual is a small dense
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
6. Rounds are bounded (``max_iterations``). Next to pairs the target neutral keeps crossed (allowed),
   a correction slides the crossing onto neighbouring triangles and the rounds discover those new
   pairs a few at a time (ICT seed 1, jawOpen: 92 rounds with the transfer energy, 99 with the stiff
   one). A shape left with pairs is solved again with the transfer energy for ``fallback_iterations``
   rounds; pairs still left then are removed by the last resort :meth:`ContactSolver._retreat` (the
   shape pulled back towards ``B0`` around them, which always ends: ``B0`` has no new pair). So the
   exact check ends clean for every shape; the report says which pass ended it.

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
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import InputError, SolverError
from ..geometry.mesh import median_edge_length
from ..geometry.rig import Rig
from ..geometry.transfer import DeformationTransfer
from .proximity import candidate_pairs, intersecting, new_pairs, triangle_distance
from .qp import Cholesky, admm, normal_matrix, separation_rows
from .retreat import retreat

#: default margin kept between constrained triangles, in median edge lengths of the target neutral
MARGIN_EDGES = 0.05
#: default radius of the region allowed to move around a contact, in median edge lengths
REACH_EDGES = 2.0
#: planes are re-derived from the solution (see ContactSolver._polish) when the correction exceeds this
#: fraction of the plain motion in the region that moves
POLISH_RATIO = 0.1
#: vertices moving less than this (median edge lengths) count as still in the plain solution's check
STILL_EDGES = 0.1
#: rounds of the transfer-energy fallback, in multiples of ``max_iterations``
FALLBACK_ROUNDS = 1



@dataclass(frozen=True)
class ContactShape:
    """Per-shape report. ``new_pairs_left`` is the exact count after the last solve (0 = guarantee
    met); ``min_distance`` the smallest distance between constrained triangles in the result (nan
    without constraints); ``iterations`` solve-and-check rounds; ``solver_iterations`` DAQP
    active-set iterations summed over rounds; ``moved`` vertices in the region allowed to move;
    ``fallback`` solved with the transfer energy alone after the stiff energy left pairs;
    ``retreated`` vertices pulled back towards the target neutral by the last resort
    (:meth:`ContactSolver._retreat`) because the rounds still left pairs (0 = not needed), and
    ``retreat_loss`` the part of the shape's delta it removed (norm over vertices, relative)."""

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
    fallback: bool = False
    retreated: int = 0
    retreat_loss: float = 0.0


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
        """One line per shape: new pairs of the plain shape, left after the last solve (exact count),
        constrained pairs, plane rows, rounds of solve + exact check, QP solver iterations (ADMM or
        DAQP) summed over rounds, vertices allowed to move, the smallest distance kept between
        constrained triangles and seconds."""
        head = (f"{'shape':18s} {'plain':>6s} {'left':>5s} {'pairs':>6s} {'rows':>5s} {'rounds':>6s} {'QP it':>7s} "
                f"{'moved':>6s} {'min dist':>9s} {'s':>6s}")
        lines = [head]
        for s in self.shapes:
            if s.excluded:
                lines.append(f"{s.name:18s} excluded: left uncorrected")
                continue
            lines.append(f"{s.name:18s} {s.plain_new_pairs:6d} {s.new_pairs_left:5d} {s.constrained_pairs:6d} "
                         f"{s.rows:5d} {s.iterations:6d} {s.solver_iterations:7d} {s.moved:6d} "
                         f"{s.min_distance:9.4f} {s.seconds:6.2f}" + ("  (transfer energy)" if s.fallback else "")
                         + (f"  (retreated {s.retreated} vertices towards the neutral, {100 * s.retreat_loss:.1f}% of "
                            "its delta)" if s.retreated else ""))
        return "\n".join(lines)

    def record(self) -> dict:
        """The exact check's verdict and every shape's report as JSON-ready data (NaN as None): what
        the commands write as ``contact.json`` beside the shapes."""
        def clean(v):
            return None if isinstance(v, float) and not np.isfinite(v) else v

        return {"ok": self.ok, "excluded": [s.name for s in self.shapes if s.excluded],
                "seconds": {k: clean(float(v)) for k, v in self.seconds.items()},
                "shapes": [{k: clean(v) for k, v in asdict(s).items()} for s in self.shapes]}


class ContactSolver:
    """Set up once per template and target neutral; :meth:`correct` one plain-transferred shape.

    Parameters
    ----------
    dt : the :class:`DeformationTransfer` whose plain solutions are corrected
    margin : distance kept between constrained triangles (default ``MARGIN_EDGES`` median edges),
        at most half their distance in the target neutral
    reach : radius of the region allowed to move around contacts (default ``REACH_EDGES`` median edges)
    max_iterations : solve-and-check rounds per shape
    fallback_iterations : rounds of the transfer-energy fallback (default ``FALLBACK_ROUNDS``
        ``* max_iterations``); each round constrains at least one more pair or row, so more rounds
        end with fewer shapes needing the last resort
    polish : rounds re-deriving the separating planes from the solution (kept only if the exact check
        still passes) for shapes corrected by more than ``POLISH_RATIO`` of their motion; 0 = off
    stiffness : ``beta`` of the energy ``x^T (L + beta I) x``: 0 = the transfer's own energy; large = the
        smallest displacement, the transfer energy only smoothing it (generated shapes: ``RIG_STIFFNESS``)
    """

    def __init__(self, dt: DeformationTransfer, margin: float | None = None, reach: float | None = None,
                 max_iterations: int = 40, solver: str = "admm", polish: int = 3, stiffness: float = 0.0,
                 fallback_iterations: int | None = None):
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
        self.fallback_iterations = (FALLBACK_ROUNDS * self.max_iterations if fallback_iterations is None
                                    else int(fallback_iterations))
        self.tau = STILL_EDGES * h
        self.L = normal_matrix(dt, stiffness)
        self.stiffness = float(stiffness)
        self._L0 = None  # the transfer energy alone, for the fallback (built when first needed)
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
        """The corrected delta (n, 3) of one shape and its :class:`ContactShape` report.

        With ``stiffness`` > 0, a shape that keeps new pairs after ``max_iterations`` rounds is solved
        again with the transfer energy alone (``stiffness`` 0, up to ``fallback_iterations`` rounds),
        whose smooth corrections disturb fewer neighbouring pairs; that answer is kept if it leaves
        fewer new pairs (``fallback`` in the report). Pairs still left then are removed by the last
        resort :meth:`_retreat` (``retreated`` in the report), so the exact check always ends clean.
        """
        d, rep, left = self._correct(name, d_plain, template_delta, self.L, self.max_iterations)
        if len(left) and self.stiffness > 0:
            if self._L0 is None:
                self._L0 = normal_matrix(self.dt)
            d0, rep0, left0 = self._correct(name, d_plain, template_delta, self._L0, self.fallback_iterations)
            if len(left0) < len(left):
                d, left = d0, left0
                rep = replace(rep0, fallback=True, seconds=rep.seconds + rep0.seconds)
        if len(left):
            t0 = time.perf_counter()
            solved = d
            d, retreated = self._retreat(d, self.dt.template.neutral + template_delta, left)
            loss = float(np.linalg.norm(solved - d) / max(np.linalg.norm(solved), 1e-300))
            rep = replace(rep, new_pairs_left=0, retreated=retreated, retreat_loss=loss, min_distance=float("nan"),
                          seconds=rep.seconds + time.perf_counter() - t0)  # distances of the solve no longer hold
        return d, rep

    def _retreat(self, d, S, left):
        """The last resort (:func:`facebasis.contact.retreat.retreat`): (delta, vertices moved)."""
        return retreat(d, self.B0, self.F, S, left, self.reach, self.vf)

    def _correct(self, name, d_plain, template_delta, L, rounds):
        import daqp

        t0 = time.perf_counter()
        F, B0 = self.F, self.B0
        P = B0 + d_plain
        S = self.dt.template.neutral + template_delta
        found = self._plain_new_pairs(P, S, d_plain)
        plain_new = len(found)
        if plain_new == 0:
            return d_plain, ContactShape(name, plain_new_pairs=0, seconds=time.perf_counter() - t0), found
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
        for it in range(1, rounds + 1):
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
                        chol = Cholesky(L[R][:, R])
                    else:
                        chol = True
                if self.solver == "daqp":
                    pos = np.searchsorted(R, C)
                    E = np.zeros((len(R), len(C)))
                    E[pos, np.arange(len(C))] = 1.0
                    Z = chol.solve(E)  # Green's function columns of the constrained vertices, (|R|, |C|)
                    Zc = Z[pos]
            c = len(active)
            if self.solver == "daqp":
                A, g = separation_rows(F, pairs, normals, delta, active, P, C)  # rows over C's corrections
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
                    raise SolverError(f"contact ({name}): expected the separation QP solved, found DAQP exit flag {flag}")
                x = np.stack([Z @ (K @ y[k * len(C):(k + 1) * len(C)]) for k in range(3)], 1)
            else:
                # the same QP over R's corrections (3 |R| unknowns, sparse), by ADMM (OSQP's splitting)
                x0 = np.zeros((len(R), 3)) if x is None or len(x) != len(R) else x
                y0 = None if dual is None else np.concatenate([dual, np.zeros(c - len(dual))])
                x, dual, n_it = self._admm_rows(L, P, pairs, normals, delta, active, R, x0, y0)
                qp_iters += n_it
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
            X, x, extra = self._polish(L, P, S, X, x, pairs, normals, delta, active, R)
            it += extra[0]
            qp_iters += extra[1]
        d = d_plain.copy()
        if x is not None:
            d[R] += x
        dist, _ = triangle_distance(X[F[pairs[:, 0]]], X[F[pairs[:, 1]]])
        return d, ContactShape(name, False, plain_new, len(left), len(pairs), len(active), it, qp_iters, len(R),
                               float(dist.min()) if len(dist) else float("nan"), time.perf_counter() - t0), left

    def _admm_rows(self, L, P, pairs, normals, delta, active, R, x, dual):
        """The separation QP over R's corrections for the given rows, by ADMM: x (|R|, 3), duals, iterations."""
        A, g = separation_rows(self.F, pairs, normals, delta, active, P, R)
        c = len(active)
        AR = sp.hstack(A).tocsr()
        xs = x.T.ravel().copy()
        ys = np.zeros(c) if dual is None or len(dual) != c else dual
        xs, dual, n_it = admm(L[R][:, R], AR, g, delta[active // 9], xs, ys)
        return xs.reshape(3, len(R)).T, dual, n_it

    def _polish(self, L, P, S, X, x, pairs, normals, delta, active, R):
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
            x2, dual2, n_it = self._admm_rows(L, P, pairs, normals2, delta, active2, R, x, None)
            rounds += 1
            qp += n_it
            X2 = P.copy()
            X2[R] += x2
            if len(new_pairs(X2, F, (self.B0, S), faces=touch)):
                break
            improved = (x2 * (L[R][:, R] @ x2)).sum() < (x * (L[R][:, R] @ x)).sum()
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


__all__ = ["ContactShape", "ContactResult", "ContactSolver", "MARGIN_EDGES", "REACH_EDGES", "POLISH_RATIO",
           "STILL_EDGES", "FALLBACK_ROUNDS"]
