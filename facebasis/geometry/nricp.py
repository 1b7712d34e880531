"""Non-rigid ICP of a template mesh onto a scan surface, with a stiffness schedule.

The loop is Amberg, Romdhani and Vetter's optimal-step non-rigid ICP (2007, Algorithm 1): for a
decreasing sequence of stiffness weights ``alpha_1 > alpha_2 > ...``, alternate closest-point
correspondences with the exact minimiser of a quadratic energy for fixed correspondences, until
the vertices stop moving. The energy has their three terms (eq. 1)

    E(X) = E_d(X) + alpha E_s(X) + beta E_l(X)

with the data term (eq. 5, in the matrix form of eq. 8-9) ``sum_i w_i ||x_i - u_i||^2``, the
landmark term (eq. 10) ``sum_l ||x_l - l||^2`` and ``w_i = 0`` for a vertex whose closest scan
point is too far, lies on a rim of a hole, or whose normal disagrees with the scan's (sec. 3.2).

The stiffness term differs from eq. 3-7. Amberg et al. give each vertex an affine 3x4 transform and
penalise the difference of neighbouring transforms, ``||(M (x) G) X||^2`` (eq. 7): 4n unknowns, and
a 56k x 56k factorisation for the 14k-vertex ICT face, once per stiffness level.
We keep one unknown position per vertex and make the stiffness term rotation-aware instead, as in
as-rigid-as-possible modelling (Sorkine & Alexa 2007) and Sumner-style embedded deformation with the
mesh as its own graph: ``E_s = sum_(i,j) ||(x_i - x_j) - R_ij (p_i - p_j)||^2`` with ``p`` the rest
(start) mesh and ``R_ij = (R_i + R_j) / 2`` the mean of the vertices' best local rotations (found
per vertex by one batched 3x3 SVD). Like eq. 7 it leaves local rotations free, so a jaw opening
or a turned head costs nothing, but the normal matrix of eq. 11-12,
``A^T A = alpha^2 L + W^2 + beta^2 S_l^T S_l``, is n x n (L the graph Laplacian ``M^T M`` of
eq. 6's node-arc incidence matrix ``M``) and shared by x, y and z: a quarter of the unknowns. The
weights ``W`` are fixed per stiffness level, so each level factors once and every inner
iteration is a back-substitution.

With ``local_scale`` the local rotations also carry the best uniform scale per vertex (as similar
as possible): faces of two people differ in local size, so registering a template onto another
person uses it; a person's expressions from their own registered neutral do not.

Data targets: the first levels pull a vertex to its nearest scan vertex; from ``plane_from_level``
on, to its foot on that scan vertex's tangent plane (point-to-plane, Chen & Medioni 1992, with the
target fixed per iteration so the matrix is unchanged). A converged vertex then lies on the scan
without being snapped to a scan vertex: its position along the surface is set by the stiffness
term. One vertex-tree query per iteration, bounded by the level's distance threshold (a vertex with
no scan vertex that close gets no data term and the search stops early). The reported distances
are exact point-to-triangle distances on the triangles around the nearest scan vertex (vectorised,
Ericson 2004, sec. 5.1.5).

What the data cannot fix: on a smooth surface a vertex's place along the surface is the stiffness
term's choice. Registering a generic template onto another person therefore cannot recover a
correspondence defined otherwise (e.g. by a statistical model's own registration); on the ICT
benchmark this leaves ~0.12 cm median error along the surface even for the exact mesh, see
``reports/registration/README.md``.

References
----------
Amberg B., Romdhani S., Vetter T. Optimal step nonrigid ICP algorithms for surface registration.
CVPR 2007. Equation numbers "eq. N" are this paper's.
Sorkine O., Alexa M. As-rigid-as-possible surface modeling. SGP 2007 (eq. 3-9: local rotations,
the global Laplacian system).
Ericson C. Real-Time Collision Detection. 2004, sec. 5.1.5 (closest point on a triangle).
Chen Y., Medioni G. Object modelling by registration of multiple range images. IVC 10(3), 1992
(point-to-plane distances).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .cholesky import SparseCholesky
from .mesh import boundary_vertices, unique_edges


def closest_point_on_triangles(P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Closest point on triangle ``(A, B, C)`` to ``P``, row by row (Ericson 2004, sec. 5.1.5).

    Parameters
    ----------
    P, A, B, C : (..., 3)

    Returns
    -------
    Q : (..., 3)
    """
    ab, ac = B - A, C - A
    ap, bp, cp = P - A, P - B, P - C
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        v_ab = d1 / (d1 - d3)
        w_ac = d2 / (d2 - d6)
        w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    conds = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (vc <= 0) & (d1 >= 0) & (d3 <= 0),
             (d6 >= 0) & (d5 <= d6), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
             (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)]
    # barycentric weights of B and C in each Voronoi region, in Ericson's order
    v = np.select(conds, [0.0, 1.0, v_ab, 0.0, 0.0, 1.0 - w_bc], v_in)
    w = np.select(conds, [0.0, 0.0, 0.0, 1.0, w_ac, w_bc], w_in)
    v, w = np.nan_to_num(v), np.nan_to_num(w)
    return A + ab * v[..., None] + ac * w[..., None]


def _unit(v: np.ndarray) -> np.ndarray:
    ln = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, ln, out=np.zeros_like(v), where=ln > 0)


def vertex_face_incidence(F: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """Sparse (n, m) matrix with a 1 where vertex i is a corner of triangle t."""
    m = len(F)
    return sp.csr_matrix((np.ones(3 * m), (F.ravel(), np.repeat(np.arange(m), 3))), shape=(n_vertices, m))


def boundary_mask(F: np.ndarray, n_vertices: int) -> np.ndarray:
    """Mask (n,) of the vertices on a boundary edge (an edge of exactly one triangle)."""
    mask = np.zeros(n_vertices, bool)
    mask[boundary_vertices(F)] = True
    return mask


class ScanSurface:
    """A scan prepared for closest-point queries: vertex tree, triangles around each vertex, rims.

    Parameters
    ----------
    V : (N, 3) scan vertices, F : (M, 3) scan triangles
    max_valence : at most this many triangles around a vertex are searched (default: the 99th
        percentile of the valences; extra ones are rare and the nearest vertex's others still count)
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, max_valence: int | None = None):
        self.F = F
        self._used = np.unique(F)
        # triangles around each vertex, padded with the vertex's first triangle: (N, max_valence)
        corner_v = F.ravel()
        order = np.argsort(corner_v, kind="stable")
        sv, st = corner_v[order], order // 3
        start = np.searchsorted(sv, np.arange(len(V)))
        pos = np.arange(len(sv)) - start[sv]
        if max_valence is None:
            max_valence = int(np.clip(np.percentile(np.bincount(sv), 99), 3, 16))
        table = np.full((len(V), max_valence), -1, np.int64)
        keep = pos < max_valence
        table[sv[keep], pos[keep]] = st[keep]
        first = table[:, :1]
        self.ring = np.where(table >= 0, table, first)
        rim = boundary_mask(F, len(V))
        self.rim_face = rim[F].any(axis=1)
        # rim vertices: a corner of a triangle that touches a rim
        self._inc = vertex_face_incidence(F, len(V))
        self.rim_vertex = (self._inc @ self.rim_face.astype(np.float64)) > 0
        self._place(np.asarray(V, dtype=np.float64))

    def _place(self, V: np.ndarray) -> None:
        """The geometry-dependent parts: vertex tree, triangle edges, face and vertex normals."""
        F, inc = self.F, self._inc
        self.V = V
        self.tree = cKDTree(V[self._used])
        self._A = V[F[:, 0]]
        self._AB = V[F[:, 1]] - self._A
        self._AC = V[F[:, 2]] - self._A
        fn = np.cross(self._AB, self._AC)
        self.normals = _unit(fn)
        # vertex normals: area-weighted face normals, averaged once more over the triangles around
        # each vertex (damps scanner noise)
        vn = _unit(inc @ fn)
        self.vertex_normals = _unit(inc @ _unit(vn[F].sum(1)) + 1e-12 * vn)

    @property
    def used(self) -> np.ndarray:
        """(u,) the scan vertices that are a corner of some triangle (the tree's points, in order)."""
        return self._used

    def moved(self, V: np.ndarray) -> "ScanSurface":
        """The same scan topology at new vertex positions ``V`` (N, 3), e.g. mapped by a similarity;
        the topology tables are shared, the tree and normals rebuilt."""
        out = object.__new__(ScanSurface)
        out.__dict__.update(self.__dict__)
        out._place(np.asarray(V, dtype=np.float64))
        return out

    def nearest_planes(self, P: np.ndarray, plane: bool = True, max_distance: float = np.inf
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Point-to-plane targets: ``P`` projected onto the tangent plane of its nearest scan vertex.

        The target leaves a point free to slide along the surface (its place along the surface is
        set by the stiffness term, not by where the scan's vertices happen to be); its distance to
        the exact closest surface point is of the order of (half an edge)^2 x curvature.

        Returns
        -------
        U : (q, 3) targets, normal : (q, 3) scan vertex normals, dist : (q,) distance to the nearest
        scan vertex (inf beyond ``max_distance``), rim : (q,) bool, that vertex is on or next to a
        boundary of the scan, or none is within ``max_distance`` (with ``plane=False`` the targets are the nearest scan vertices themselves)
        """
        dist, j = self.tree.query(P, distance_upper_bound=max_distance)
        far = ~np.isfinite(dist)  # nothing within max_distance (the search stops early: cheaper)
        j = self._used[np.where(far, 0, j)]
        n = self.vertex_normals[j]
        U = P - ((P - self.V[j]) * n).sum(1, keepdims=True) * n if plane else self.V[j]
        U[far] = P[far]
        return U, n, dist, self.rim_vertex[j] | far

    def closest(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Closest scan points to ``P`` (q, 3) on the triangles around the nearest scan vertex.

        Returns
        -------
        Q : (q, 3) closest points, normal : (q, 3) unit normal of ``Q``'s triangle, dist : (q,)
        distances, rim : (q,) bool, ``Q``'s triangle touches a boundary of the scan
        """
        _, j = self.tree.query(P)
        faces = self.ring[self._used[j]]  # (q, k)
        A = self._A[faces]  # (q, k, 3)
        Q = closest_point_on_triangles(P[:, None, :], A, A + self._AB[faces], A + self._AC[faces])
        D = Q - P[:, None, :]
        best = np.argmin(np.einsum("qki,qki->qk", D, D), axis=1)
        rows = np.arange(len(P))
        Q, f = Q[rows, best], faces[rows, best]
        return Q, self.normals[f], np.linalg.norm(Q - P, axis=1), self.rim_face[f]


@dataclass(frozen=True)
class NricpOptions:
    """Stiffness schedule and correspondence rules of :class:`NonRigidICP`.

    Attributes
    ----------
    stiffness : decreasing stiffness weights ``alpha`` (eq. 1; one per level, Algorithm 1)
    landmark_weight : ``beta`` per level (eq. 1, 10), decreasing; its last value repeats. Twice the
        stiffness: a landmark must be able to carry its region against the stiffness term at every
        level (an opened jaw), yet not dominate the scan at the end (landmarks are noisy)
    max_iterations : inner iterations per level at most
    tolerance : a level ends when 95% of the vertices moved less than ``tolerance`` x the median
        edge length in an iteration
    max_distance : a vertex whose closest scan point is farther than this many median edge lengths
        gets no data term (per level; its last value repeats)
    normal_angle : degrees; a larger angle between the vertex normal and the scan normal rejects
    local_scale : let the stiffness term's local rotations also scale (as similar as possible), so a
        uniform local stretch costs nothing
    plane_from_level : point-to-plane targets (the tangent plane of the nearest scan vertex) from this
        level on; before it, the nearest scan vertex itself
    """

    stiffness: tuple = (50.0, 20.0, 8.0, 3.0, 1.2, 0.5, 0.2, 0.08)
    landmark_weight: tuple = (100.0, 40.0, 16.0, 6.0, 2.4, 1.0, 0.4, 0.16)
    max_iterations: int = 8
    tolerance: float = 1e-2
    max_distance: tuple = (10.0, 8.0, 6.0, 4.0, 3.0)
    normal_angle: float = 60.0
    plane_from_level: int = 2
    local_scale: bool = False

    def __post_init__(self):
        from ..errors import InputError

        s = np.asarray(self.stiffness, float)
        if s.ndim != 1 or len(s) == 0 or np.any(s <= 0) or np.any(np.diff(s) > 0):
            raise InputError(f"stiffness: expected a non-empty decreasing sequence of positive weights, found {self.stiffness}")
        if not 0 < self.normal_angle <= 180:
            raise InputError(f"normal_angle: expected degrees in (0, 180], found {self.normal_angle}")
        if self.max_iterations < 1:
            raise InputError(f"max_iterations: expected at least 1, found {self.max_iterations}")


@dataclass(frozen=True)
class NricpResult:
    """Output of :meth:`NonRigidICP.fit`.

    Attributes
    ----------
    vertices : (n, 3) registered vertices
    distance : (n,) distance of each vertex to its closest scan point
    no_surface : (n,) bool, vertices without a data term at the end (too far, rim, normal)
    iterations : inner iterations over all levels
    """

    vertices: np.ndarray
    distance: np.ndarray
    no_surface: np.ndarray
    iterations: int


def _level_value(seq, i):
    return float(seq[min(i, len(seq) - 1)]) if len(seq) else 0.0


class NonRigidICP:
    """Topology-dependent parts of the non-rigid ICP, built once per template topology.

    Parameters
    ----------
    F : (m, 3) template triangles
    n_vertices : n
    """

    def __init__(self, F: np.ndarray, n_vertices: int):
        self.F, self.n = F, n_vertices
        e = unique_edges(F)
        self.edges = e
        k = len(e)
        rows = np.repeat(np.arange(k), 2)
        # node-arc incidence matrix M (eq. 6): row r has -1 at edge r's first vertex, +1 at its second
        self.M = sp.csr_matrix((np.tile([-1.0, 1.0], k), (rows, e.ravel())), shape=(k, n_vertices))
        self.L = (self.M.T @ self.M).tocsr()  # graph Laplacian, the stiffness part of A^T A (eq. 11-12)
        # edge r -> both its vertices, for summing per-edge 3x3 products into per-vertex ones
        self.edge_to_vertex = abs(self.M).T.tocsr()
        self.incidence = vertex_face_incidence(F, n_vertices)

    def vertex_normals(self, X: np.ndarray) -> np.ndarray:
        """Area-weighted unit vertex normals (n, 3) of the template posed at ``X``."""
        fn = np.cross(X[self.F[:, 1]] - X[self.F[:, 0]], X[self.F[:, 2]] - X[self.F[:, 0]])
        vn = self.incidence @ fn
        ln = np.linalg.norm(vn, axis=1, keepdims=True)
        return np.divide(vn, ln, out=np.zeros_like(vn), where=ln > 0)

    def local_rotations(self, P: np.ndarray, X: np.ndarray, scale: bool = False) -> np.ndarray:
        """Best rotation (n, 3, 3) per vertex from rest edges to current edges (Sorkine & Alexa eq. 5-6).

        With ``scale``, the best rotation times the best uniform scale per vertex (a local similarity,
        "as similar as possible"): ``s_i = sum(singular values of S_i) / sum_j |p_j - p_i|^2``.
        """
        i, j = self.edges[:, 0], self.edges[:, 1]
        ep, ex = P[j] - P[i], X[j] - X[i]
        S = (self.edge_to_vertex @ (ep[:, :, None] * ex[:, None, :]).reshape(-1, 9)).reshape(-1, 3, 3)
        U, sig, Vt = np.linalg.svd(S)
        R = np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)
        flip = np.linalg.det(R) < 0
        if flip.any():
            Vt[flip, 2, :] *= -1
            sig[flip, 2] *= -1
            R[flip] = np.swapaxes(Vt[flip], 1, 2) @ np.swapaxes(U[flip], 1, 2)
        if scale:
            rest = self.edge_to_vertex @ (ep * ep).sum(1)
            s = np.clip(sig.sum(1) / np.maximum(rest, 1e-300), 0.5, 2.0)
            R = R * s[:, None, None]
        return R

    def fit(self, P: np.ndarray, surface: ScanSurface, options: NricpOptions = NricpOptions(),
            landmarks: np.ndarray | None = None, landmark_points: np.ndarray | None = None,
            X0: np.ndarray | None = None, h: float | None = None, callback=None) -> NricpResult:
        """Deform the rest mesh ``P`` onto ``surface``.

        Parameters
        ----------
        P : (n, 3) rest (start) mesh, already aligned to the scan
        surface : the scan
        landmarks : (k,) template vertex indices, with ``landmark_points`` (k, 3) on the scan
        X0 : (n, 3) start positions (default ``P``)
        h : the length unit of ``options.max_distance`` and ``tolerance`` (default: P's median edge)
        callback : called as ``callback(level, iteration, X, data_mask)`` after every iteration

        Returns
        -------
        NricpResult
        """
        X = np.array(P if X0 is None else X0, dtype=np.float64)
        if h is None:
            h = float(np.median(np.linalg.norm(P[self.edges[:, 1]] - P[self.edges[:, 0]], axis=1)))
        cos_max = np.cos(np.radians(options.normal_angle))
        has_lm = landmarks is not None and len(landmarks) > 0
        iterations = 0

        def correspondences(X, level):
            dmax = _level_value(options.max_distance, level) * h
            U, ns, dist, rim = surface.nearest_planes(X, level >= options.plane_from_level, dmax)
            nv = self.vertex_normals(X)
            ok = ((dist <= dmax) & ~rim
                  & ((nv * ns).sum(1) >= cos_max))
            return U, dist, ok

        def factor(alpha, diag):
            return SparseCholesky(alpha ** 2 * self.L + sp.diags(diag + 1e-9))

        for level, alpha in enumerate(options.stiffness):
            beta = _level_value(options.landmark_weight, level) if has_lm else 0.0
            U, dist, w = correspondences(X, level)
            # the normal matrix of eq. 11-12 for this level: alpha^2 M^T M + W^2 + beta^2 S_l^T S_l
            diag = w.astype(np.float64)  # W^2 of the data term (eq. 8-9), w_i in {0, 1}
            if beta > 0:
                np.add.at(diag, landmarks, beta ** 2)  # landmark rows D_L (eq. 10)
            chol = factor(alpha, diag)
            for it in range(options.max_iterations):
                if it > 0:
                    U_new, dist, ok = correspondences(X, level)
                    # a vertex that lost its partner within the level keeps its place as target
                    U = np.where((ok & w)[:, None], U_new, X)
                R = self.local_rotations(P, X, options.local_scale)
                i, j = self.edges[:, 0], self.edges[:, 1]
                target_edges = 0.5 * np.einsum("kab,kb->ka", R[i] + R[j], P[j] - P[i])
                # A^T B of eq. 11-12: stiffness rows M^T (alpha^2 target edges), data rows W U, landmarks
                rhs = alpha ** 2 * (self.M.T @ target_edges) + w[:, None] * U
                if beta > 0:
                    np.add.at(rhs, landmarks, beta ** 2 * landmark_points)
                X_new = chol.solve(rhs)
                iterations += 1
                step = float(np.percentile(np.linalg.norm(X_new - X, axis=1), 95))
                X = X_new
                if callback is not None:
                    callback(level, it, X, w)
                if step < options.tolerance * h:
                    break
        _, dist, ok = correspondences(X, len(options.stiffness) - 1)
        dist = surface.closest(X)[2]  # exact distances to the scan's triangles, for the report
        return NricpResult(X, dist, ~ok, iterations)
