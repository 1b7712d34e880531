"""Vertex positions from target edges: the factor-once least-squares reconstruction.

Given target edge vectors ``e*`` for every triangle edge, find per-vertex values ``d`` minimising

    sum_t sum_e  c_t || (E d)_{t,e} - e*_{t,e} ||^2        (Gao et al. 2015, sec. 2.2, last step of eq. 4)

with ``d`` fixed at anchor vertices. Edges only determine ``d`` up to one translation per connected
component, so anchors are required (``method.md``: every component must be anchored, or whole parts
drift). The normal matrix ``L = E^T C E`` restricted to the free vertices is factored once; every
later call solves all right-hand sides (shapes x 3 coordinates) in one back-substitution.

References
----------
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. ACM Transactions on Graphics
    23(3) (SIGGRAPH 2004): 399-405.
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, MeshError
from .cholesky import SparseCholesky
from .gradients import edge_operator, frame_edge_operator
from .mesh import connected_components

#: A template vertex whose largest displacement over all shapes is at most this fraction of the
#: neutral's bounding-box diagonal is "still" and anchors the reconstruction.
STILL_TOLERANCE = 1e-7


def choose_anchors(F: np.ndarray, n_vertices: int, motion: np.ndarray | None = None,
                   tolerance: float | None = None, scale: float = 1.0) -> np.ndarray:
    """Anchor vertices that fix the translation of every connected component.

    Parameters
    ----------
    F : (m, 3) triangles
    n_vertices : n
    motion : (n,) largest displacement of each vertex over the template's shapes, or None
    tolerance : absolute motion at or below which a vertex is still; default
        ``STILL_TOLERANCE * scale``
    scale : the neutral's bounding-box diagonal (sets the default tolerance)

    Returns
    -------
    anchors : sorted (a,) int64. With ``motion``: every still vertex, plus, for each component
        without one, its least-moving vertex. Without ``motion``: the lowest-index vertex of each
        component.
    """
    labels = connected_components(F, n_vertices)
    n_comp = labels.max() + 1
    if motion is None:
        first = np.full(n_comp, n_vertices)
        np.minimum.at(first, labels, np.arange(n_vertices))
        return np.sort(first)
    motion = np.asarray(motion, dtype=np.float64)
    tol = STILL_TOLERANCE * scale if tolerance is None else tolerance
    still = motion <= tol
    anchored = np.zeros(n_comp, bool)
    anchored[labels[still]] = True
    extra = []
    for c in np.flatnonzero(~anchored):  # loop over components (few), not triangles
        members = np.flatnonzero(labels == c)
        extra.append(members[np.argmin(motion[members])])
    return np.unique(np.concatenate([np.flatnonzero(still), np.asarray(extra, dtype=np.int64)]))


class EdgePoisson:
    """Factor-once least-squares reconstruction of vertex values from triangle edges.

    Minimises ``sum_t c_t ||(E d)_t - e*_t||^2 + w ||X d - x*||^2`` over the vertex values ``d``
    with ``d`` prescribed at the anchors: ``E`` (3m, n) is the triangle edge operator, ``X`` (r, n)
    an optional extra operator (e.g. virtual edges) with targets ``x*``.

    Parameters
    ----------
    F : (m, 3) triangles
    n_vertices : n
    anchors : (a,) vertex indices whose values are prescribed at solve time; must hit every
        connected component
    triangle_weights : (m,) optional non-negative weights ``c_t`` (default 1)
    extra_operator : optional sparse (r, n) operator ``X`` of additional "edges" (e.g. virtual
        edges); its targets are the ``extra_targets`` of :meth:`solve` / :meth:`solve_frame_rows`
    extra_weight : weight ``w`` of the extra operator in the energy; the operator is ignored
        unless ``w > 0`` and ``r > 0``

    Attributes
    ----------
    anchors : (a,) sorted unique anchor indices (the order of ``anchor_values``)
    free : (f,) the other vertices
    extra_operator : csr (r, n) or None (None when ignored)
    extra_weight : float

    Notes
    -----
    Building costs one sparse Cholesky factorisation (CHOLMOD, through cholespy) of the
    free-vertex block of ``L = E^T C E + w X^T X``, which is symmetric positive definite once every
    component is anchored; a solve is then a pair of triangular solves for all right-hand
    sides at once (SuperLU's LU solve is the fallback where cholespy is missing).

    Two entry points, for two layouts of the same problem: :meth:`solve` (triangle edge targets,
    batch axes first) and :meth:`solve_frame_rows` (frame edge columns, one problem per column of
    C-contiguous arrays, nothing copied: the generation hot path).
    """

    def __init__(self, F, n_vertices: int, anchors, triangle_weights=None, extra_operator=None,
                 extra_weight: float = 0.0):
        F = np.asarray(F, dtype=np.int64)
        self.n_vertices = int(n_vertices)
        self.n_faces = len(F)
        anchors = np.unique(np.asarray(anchors, dtype=np.int64))
        if len(anchors) == 0:
            raise InputError("anchors: expected at least one anchor vertex per component, found none")
        if anchors[0] < 0 or anchors[-1] >= n_vertices:
            raise InputError(f"anchors: expected indices in [0, {n_vertices}), found {anchors[[0, -1]].tolist()}")
        labels = connected_components(F, n_vertices)
        missing = np.setdiff1d(np.unique(labels), labels[anchors])
        if len(missing):
            raise InputError(
                f"anchors: expected an anchor in every connected component, found {len(missing)} "
                f"components without one (e.g. the one holding vertex {int(np.flatnonzero(labels == missing[0])[0])})"
            )
        self.anchors = anchors
        free = np.ones(n_vertices, bool)
        free[anchors] = False
        self.free = np.flatnonzero(free)
        E = edge_operator(F, n_vertices)
        if triangle_weights is not None:
            c = np.repeat(np.asarray(triangle_weights, dtype=np.float64), 3)
            E_w = sp.diags(c) @ E
        else:
            E_w = E
        self._Et = E_w.T.tocsr()  # E^T C, applied to edge targets
        self._Ew = E_w
        self._frame_op = None  # (n, 2m) operator of frame edge columns, built on first use
        L = (E.T @ E_w).tocsr()
        self.extra_operator = None
        self.extra_weight = float(extra_weight)
        if extra_operator is not None and extra_operator.shape[0] > 0 and extra_weight > 0:
            if extra_operator.shape[1] != n_vertices:
                raise InputError(f"extra_operator: expected shape (r, {n_vertices}), found {extra_operator.shape}")
            X = sp.csr_matrix(extra_operator)
            self.extra_operator = X
            self._Xt = (self.extra_weight * X.T).tocsr()  # w X^T, applied to extra targets
            L = L + self.extra_weight * (X.T @ X)
        L = L.tocsc()
        self._L_fa = L[self.free][:, anchors].tocsc()
        L_ff = L[self.free][:, self.free].tocsc()
        try:
            self._chol = SparseCholesky(L_ff)
        except (RuntimeError, ValueError) as exc:  # not positive definite: a part without anchor
            raise MeshError(f"reconstruction: the edge system is singular ({exc}); check for isolated vertices") from exc

    @property
    def extra_rows(self):
        """Alias of :attr:`extra_operator` (read-only), kept for :mod:`facebasis.contact.exact`."""
        return self.extra_operator

    @property
    def n_extra(self) -> int:
        """r, the number of extra rows (0 without an extra operator)."""
        return 0 if self.extra_operator is None else self.extra_operator.shape[0]

    def solve(self, edge_targets: np.ndarray, anchor_values: np.ndarray | None = None,
              extra_targets: np.ndarray | None = None) -> np.ndarray:
        """Solve for vertex values.

        Parameters
        ----------
        edge_targets : (..., m, 3, d) target vectors of the three edges of every triangle
            (order of :data:`facebasis.geometry.gradients.EDGE_CORNERS`); the leading axes ``...``
            are a batch of independent problems sharing the factorisation
        anchor_values : (..., a, d) values at :attr:`anchors` (broadcast over the batch; default 0)
        extra_targets : (..., r, d) targets of the extra operator's rows; required when there is an
            extra operator, ignored otherwise

        Returns
        -------
        values : (..., n, d) float64
        """
        T = np.asarray(edge_targets, dtype=np.float64)
        if T.ndim < 3 or T.shape[-3:-1] != (self.n_faces, 3):
            raise InputError(f"edge_targets: expected shape (..., {self.n_faces}, 3, d), found {T.shape}")
        batch, d = T.shape[:-3], T.shape[-1]
        k = int(np.prod(batch)) if batch else 1
        # columns (c = k d) are (batch, coordinate) pairs; rows are the 3m triangle edges
        cols = np.moveaxis(T.reshape(k, 3 * self.n_faces, d), 2, 1).reshape(k * d, 3 * self.n_faces)
        a_vals = None
        if anchor_values is not None:
            A = np.broadcast_to(np.asarray(anchor_values, dtype=np.float64), batch + (len(self.anchors), d))
            a_vals = np.moveaxis(A.reshape(k, len(self.anchors), d), 2, 1).reshape(k * d, len(self.anchors)).T
        x_vals = None
        if extra_targets is not None and self.extra_operator is not None:
            X = np.asarray(extra_targets, dtype=np.float64)
            if X.shape[-2:] != (self.n_extra, d):
                raise InputError(f"extra_targets: expected shape (..., {self.n_extra}, {d}), found {X.shape}")
            x_vals = np.moveaxis(X.reshape(k, -1, d), 2, 1).reshape(k * d, -1).T
        out = self._solve_rhs(np.asarray(self._Et @ cols.T), a_vals, x_vals)  # (n, k d)
        return np.moveaxis(out.T.reshape(k, d, self.n_vertices), 1, 2).reshape(batch + (self.n_vertices, d))

    def solve_frame_rows(self, frame_rows: np.ndarray, anchor_values: np.ndarray | None = None,
                         extra_targets: np.ndarray | None = None) -> np.ndarray:
        """Fast path: solve c problems given as columns of frame edge targets.

        Parameters
        ----------
        frame_rows : (2m, c) frame edge columns of every problem: row ``t`` is the first edge
            ``v2 - v1`` of triangle t, row ``m + t`` its second edge ``v3 - v1`` (the layout of
            :func:`~facebasis.geometry.gradients.frame_edge_operator`); one column per problem
            (e.g. one coordinate of one shape)
        anchor_values : (a, c) values at :attr:`anchors` (default 0)
        extra_targets : (r, c) targets of the extra operator's rows; required when there is an
            extra operator, ignored otherwise

        Returns
        -------
        values : (n, c) float64

        Notes
        -----
        The triangle's third edge is implied by the first two. With C-contiguous float64 inputs
        nothing is copied: the right-hand sides are one sparse-times-dense product
        ``(E^T C S) frame_rows``.
        """
        if frame_rows.ndim != 2 or frame_rows.shape[0] != 2 * self.n_faces:
            raise InputError(f"frame_rows: expected shape ({2 * self.n_faces}, c), found {frame_rows.shape}")
        rhs = self._frame_operator() @ frame_rows
        if self.extra_operator is None:
            extra_targets = None
        return self._solve_rhs(rhs, anchor_values, extra_targets)

    def _frame_operator(self):
        """``E^T C S`` (n, 2m) with S = :func:`~facebasis.geometry.gradients.frame_edge_operator`: frame edge
        columns ``[a_1..a_m, b_1..b_m]`` straight to right-hand sides; built once."""
        if self._frame_op is None:
            self._frame_op = (self._Ew.T @ frame_edge_operator(self.n_faces)).tocsr()
        return self._frame_op

    def _solve_rhs(self, rhs: np.ndarray, anchor_values, extra_targets) -> np.ndarray:
        """Right-hand sides ``E^T C e*`` (n, c), anchor values (a, c) or None, extra targets (r, c)
        or None -> vertex values (n, c)."""
        c = rhs.shape[1]
        if self.extra_operator is not None:
            if extra_targets is not None:
                extra_targets = np.asarray(extra_targets, dtype=np.float64)
            if extra_targets is None:
                raise InputError("extra_targets: expected targets for the extra (virtual edge) rows, found none")
            if extra_targets.shape != (self.n_extra, c):
                raise InputError(f"extra_targets: expected shape ({self.n_extra}, {c}), found {extra_targets.shape}")
            rhs = rhs + self._Xt @ extra_targets
        out = np.empty((self.n_vertices, c))
        if anchor_values is None:
            out[self.anchors] = 0.0
            b = rhs[self.free]
        else:
            anchor_values = np.asarray(anchor_values, dtype=np.float64)
            if anchor_values.shape != (len(self.anchors), c):
                raise InputError(f"anchor_values: expected shape ({len(self.anchors)}, {c}), "
                                 f"found {anchor_values.shape}")
            out[self.anchors] = anchor_values
            b = rhs[self.free]
            b -= self._L_fa @ np.ascontiguousarray(anchor_values)
        out[self.free] = self._chol.solve(b)
        return out
