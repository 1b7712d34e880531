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
   sparse problem over R (:func:`facebasis.contact.qp.admm`), warm-started from the last round.
   (A dense DAQP backend over the Schur complement of the constrained vertices was removed in issue
   25: no caller reached it, it needs an |R| x |C| Green's function block and a dense |C| x |C|
   inverse, and the polish step below was ADMM-only, so the two did not return the same answer.)
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
- Stellato B., Banjac G., Goulart P., Bemporad A., Boyd S. OSQP: an operator splitting solver for
    quadratic programs. Mathematical Programming Computation 12, 2020 (the ADMM splitting).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import InputError
from ..geometry.mesh import median_edge_length
from ..geometry.rig import Rig
from ..geometry.transfer import DeformationTransfer
from .proximity import candidate_pairs, intersecting, new_pairs, triangle_distance
from .qp import admm, normal_matrix, separation_rows
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
    without constraints); ``iterations`` solve-and-check rounds; ``solver_iterations`` ADMM
    iterations summed over rounds; ``moved`` vertices in the region allowed to move;
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
        constrained pairs, plane rows, rounds of solve + exact check, QP solver iterations (ADMM)
        summed over rounds, vertices allowed to move, the smallest distance kept between
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


@dataclass
class _Rounds:
    """The state of one shape's solve-and-check rounds (:meth:`ContactSolver._correct`), updated by
    one method per step of the module docstring.

    P : (n, 3) the plain solution ``B0 + d*``; S : (n, 3) the template shape
    pairs : (q, 2) constrained triangle pairs; normals (q, 3), delta (q,) their planes and gaps (step 2)
    active : row ids ``p * 9 + 3 ka + kb`` of the rows in the QP (step 2)
    C : constrained vertices; R : the region allowed to move (step 3)
    x : (|R|, 3) the correction over R (None before the first solve); dual : the rows' ADMM multipliers
    X : (n, 3) current positions ``P + x``; left : new pairs at X; found : those not yet constrained (step 4)
    rounds, qp_iterations : solve-and-check rounds and ADMM iterations so far
    """

    P: np.ndarray
    S: np.ndarray
    X: np.ndarray
    found: np.ndarray
    left: np.ndarray
    pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    delta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    active: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    C: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    R: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    x: np.ndarray | None = None
    dual: np.ndarray | None = None
    rounds: int = 0
    qp_iterations: int = 0


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
                 max_iterations: int = 40, polish: int = 3, stiffness: float = 0.0,
                 fallback_iterations: int | None = None):
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
        """One pass of the module's method over one shape with the energy ``L``, at most ``rounds``
        solve-and-check rounds: (corrected delta (n, 3), :class:`ContactShape`, new pairs left (q, 2)).
        Each numbered step of the module docstring is one method: step 1 :meth:`_plain_new_pairs`,
        2 :meth:`_add_planes`, 3 :meth:`_grow_region` and :meth:`_solve_separation`, 4
        :meth:`_check`, 5 :meth:`_polish`; step 6 (rounds bounded, fallback, retreat) is this loop
        and :meth:`correct`."""
        t0 = time.perf_counter()
        P = self.B0 + d_plain
        S = self.dt.template.neutral + template_delta
        found = self._plain_new_pairs(P, S, d_plain)                                   # step 1
        if len(found) == 0:
            return d_plain, ContactShape(name, plain_new_pairs=0, seconds=time.perf_counter() - t0), found
        st = _Rounds(P=P, S=S, X=P, found=found, left=found)
        for st.rounds in range(1, rounds + 1):                                         # step 6: bounded
            self._add_planes(st)                                                       # step 2
            if not self._grow_region(st):                                              # step 3: region
                break
            self._solve_separation(st, L, name)                                        # step 3: the QP
            if self._check(st):                                                        # step 4
                break
        if (self.polish and len(st.left) == 0 and st.x is not None and len(st.pairs)
                and np.linalg.norm(st.x) > POLISH_RATIO * np.linalg.norm(d_plain[st.R])):
            X, x, extra = self._polish(L, P, S, st.X, st.x, st.pairs, st.normals, st.delta, st.active, st.R)  # step 5
            st.X, st.x = X, x
            st.rounds += extra[0]
            st.qp_iterations += extra[1]
        d = d_plain.copy()
        if st.x is not None:
            d[st.R] += st.x
        dist, _ = triangle_distance(st.X[self.F[st.pairs[:, 0]]], st.X[self.F[st.pairs[:, 1]]])
        report = ContactShape(name=name, excluded=False, plain_new_pairs=len(found), new_pairs_left=len(st.left),
                              constrained_pairs=len(st.pairs), rows=len(st.active), iterations=st.rounds,
                              solver_iterations=st.qp_iterations, moved=len(st.R),
                              min_distance=float(dist.min()) if len(dist) else float("nan"),
                              seconds=time.perf_counter() - t0)
        return d, report, st.left

    def _add_planes(self, st: "_Rounds") -> None:
        """Step 2: the pairs found last round get their separating plane from the target neutral
        (closest-point direction, gap ``min(margin, dist_B0 / 2)``); rows violated by more than half
        their gap at the current positions join the active rows (rows are added lazily)."""
        B0, F = self.B0, self.F
        if len(st.found):
            dist, nrm = triangle_distance(B0[F[st.found[:, 0]]], B0[F[st.found[:, 1]]])
            st.pairs = np.concatenate([st.pairs, st.found])
            st.normals = np.concatenate([st.normals, nrm])
            st.delta = np.concatenate([st.delta, np.minimum(self.margin, 0.5 * dist)])
        vals = self._row_values(st.X, st.pairs, st.normals, st.delta)  # (q, 9)
        st.active = np.union1d(st.active, np.flatnonzero(vals.ravel() < -0.5 * np.repeat(st.delta, 9)))

    def _grow_region(self, st: "_Rounds") -> bool:
        """Step 3, the region: the constrained vertices C (corners of constrained pairs, anchors
        excluded) and R, every vertex within ``reach`` of C in the target neutral (anchors excluded),
        which only grows; the last correction is carried over to a larger R. False when no vertex
        can move (every constrained corner is an anchor)."""
        C = np.unique(self.F[st.pairs].ravel())
        C = C[~self.is_anchor[C]]
        if len(C) == 0:
            return False
        if not np.array_equal(C, st.C):
            st.C = C
            hits = self.tree.query_ball_point(self.B0[C], self.reach)
            R = np.union1d(st.R, np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits] + [C])))
            R = R[~self.is_anchor[R]]
            if len(R) != len(st.R):           # R only grows: a new length is a new region
                if st.x is not None:          # carry the correction over to the larger region
                    x = np.zeros((len(R), 3))
                    x[np.searchsorted(R, st.R)] = st.x
                    st.x = x
                st.R = R
        return True

    def _solve_separation(self, st: "_Rounds", L, name: str) -> None:
        """Step 3, the QP: ``min x^T L_RR x`` over R's corrections (3 |R| unknowns, sparse) subject to
        the active rows, by ADMM (OSQP's splitting), warm-started from the last correction and duals."""
        c = len(st.active)
        x0 = np.zeros((len(st.R), 3)) if st.x is None or len(st.x) != len(st.R) else st.x
        y0 = None if st.dual is None else np.concatenate([st.dual, np.zeros(c - len(st.dual))])
        st.x, st.dual, n_it = self._admm_rows(L, st.P, st.pairs, st.normals, st.delta, st.active, st.R, x0, y0)
        st.qp_iterations += n_it

    def _check(self, st: "_Rounds") -> bool:
        """Step 4: the exact check of every pair touching R at ``X = P + x`` (the others are the plain
        solution's, all constrained); the new pairs not yet constrained are found for the next
        round. True when no new pair is left (the exact guarantee is met)."""
        F = self.F
        st.X = st.P.copy()
        st.X[st.R] += st.x
        touch = (self.vf.T @ np.isin(np.arange(self.n), st.R).astype(np.float64)) > 0
        st.left = new_pairs(st.X, F, (self.B0, st.S), faces=touch)
        code = st.pairs[:, 0] * len(F) + st.pairs[:, 1]
        st.found = st.left[~np.isin(st.left[:, 0] * len(F) + st.left[:, 1], code)]
        return len(st.left) == 0

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
