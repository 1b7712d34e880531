"""Triangle-mesh arrays and their validation.

At the operator level a mesh is a pair ``V`` (n, 3) float64 and ``F`` (m, 3) int64, 0-based.
:func:`validate_mesh` checks both and raises :class:`~facebasis.errors.MeshError` with the mesh's
name (usually its file), what was expected and what was found.
"""

from __future__ import annotations

import numpy as np

from ..errors import MeshError, TopologyError

#: Default floor on the scale-free triangle quality ``q = 4 sqrt(3) area / sum(edge^2)``
#: (1 for an equilateral triangle, 0 for a degenerate one). Below it a triangle's frame is
#: treated as degenerate.
DEGENERATE_QUALITY = 1e-6


def _listing(indices: np.ndarray, limit: int = 10) -> str:
    idx = [int(i) for i in np.asarray(indices).ravel()[:limit]]
    more = len(np.asarray(indices).ravel()) - len(idx)
    return ", ".join(map(str, idx)) + (f" (+{more} more)" if more > 0 else "")


def triangle_quality(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Scale-free quality of every triangle.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    q : (m,) float array
        ``4 sqrt(3) |T| / (l1^2 + l2^2 + l3^2)``: 1 for an equilateral triangle, 0 for a
        zero-area one; unchanged by scaling or rigid motion of the mesh.
    """
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)  # twice the area
    sq = ((b - a) ** 2).sum(1) + ((c - b) ** 2).sum(1) + ((a - c) ** 2).sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = 2.0 * np.sqrt(3.0) * area2 / sq
    return np.where(sq > 0, q, 0.0)


def degenerate_triangles(V: np.ndarray, F: np.ndarray, quality: float = DEGENERATE_QUALITY) -> np.ndarray:
    """Indices of the triangles whose :func:`triangle_quality` is below ``quality``."""
    return np.flatnonzero(triangle_quality(V, F) < quality)


def validate_vertices(V, name: str = "mesh", n_vertices: int | None = None) -> np.ndarray:
    """Return ``V`` as a C-contiguous (n, 3) float64 array or raise :class:`MeshError`."""
    try:
        V = np.ascontiguousarray(V, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"{name}: vertex positions are not numeric ({exc})") from exc
    if V.ndim != 2 or V.shape[1] != 3:
        raise MeshError(f"{name}: expected vertex positions of shape (n, 3), found {V.shape}")
    if len(V) == 0:
        raise MeshError(f"{name}: expected at least 3 vertices, found an empty mesh")
    bad = [] if np.isfinite(V).all() else np.flatnonzero(~np.isfinite(V).all(axis=1))
    if len(bad):
        raise MeshError(
            f"{name}: expected finite coordinates, found NaN/inf at {len(bad)} vertices: {_listing(bad)}"
        )
    if n_vertices is not None and len(V) != n_vertices:
        raise TopologyError(f"{name}: expected {n_vertices} vertices, found {len(V)}")
    return V


def validate_faces(F, n_vertices: int, name: str = "mesh") -> np.ndarray:
    """Return ``F`` as a C-contiguous (m, 3) int64 array or raise :class:`MeshError`."""
    F = np.asarray(F)
    if F.ndim != 2 or F.shape[1] != 3:
        raise MeshError(f"{name}: expected triangles of shape (m, 3), found {F.shape}")
    if len(F) == 0:
        raise MeshError(f"{name}: expected at least one triangle, found none")
    if not np.issubdtype(F.dtype, np.integer):
        if not np.all(np.isfinite(F)) or not np.all(F == np.round(F)):
            raise MeshError(f"{name}: expected integer vertex indices in faces, found {F.dtype} values")
    F = np.ascontiguousarray(F, dtype=np.int64)
    bad = []
    if F.min() < 0 or F.max() >= n_vertices:  # one pass each; the per-face listing only on failure
        bad = np.flatnonzero((F < 0).any(1) | (F >= n_vertices).any(1))
    if len(bad):
        raise MeshError(
            f"{name}: expected vertex indices in [0, {n_vertices}), found out-of-range indices "
            f"in {len(bad)} faces: {_listing(bad)} (e.g. face {int(bad[0])} = {F[bad[0]].tolist()})"
        )
    rep = np.flatnonzero((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2]))
    if len(rep):
        raise MeshError(
            f"{name}: expected three distinct vertices per triangle, found {len(rep)} faces "
            f"repeating a vertex: {_listing(rep)}"
        )
    return F


def validate_mesh(
    V,
    F,
    name: str = "mesh",
    *,
    n_vertices: int | None = None,
    check_degenerate: bool = True,
    quality: float = DEGENERATE_QUALITY,
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a triangle mesh and return it as ``(V float64 (n,3), F int64 (m,3))``.

    Raises
    ------
    MeshError
        Non-numeric, NaN/inf or wrongly shaped coordinates; faces that are not (m, 3) integers,
        that index outside ``[0, n)`` or repeat a vertex; and, with ``check_degenerate``,
        zero-area or near-degenerate triangles (quality below ``quality``), listed by index.
        Degenerate triangles are rejected, not repaired: their frames (eq. 1 of Sumner &
        Popovic 2004) have no inverse, so no deformation gradient exists for them.
    TopologyError
        ``n_vertices`` is given and the vertex count differs.
    """
    V = validate_vertices(V, name, n_vertices)
    F = validate_faces(F, len(V), name)
    if check_degenerate:
        bad = degenerate_triangles(V, F, quality)
        if len(bad):
            raise MeshError(
                f"{name}: expected non-degenerate triangles (quality >= {quality:g}), found "
                f"{len(bad)} zero-area or near-degenerate triangles: {_listing(bad)}; they are "
                "rejected because their deformation gradient is undefined; remove or fix them"
            )
    return V, F


def same_topology(F_ref: np.ndarray, F: np.ndarray, name: str, ref_name: str) -> None:
    """Raise :class:`TopologyError` unless ``F`` equals ``F_ref`` exactly (same order)."""
    if F.shape != F_ref.shape:
        raise TopologyError(
            f"{name}: expected {len(F_ref)} triangles as in {ref_name}, found {len(F)}"
        )
    if np.array_equal(F, F_ref):  # one pass; the per-face listing only on failure
        return
    diff = np.flatnonzero((F != F_ref).any(axis=1))
    if len(diff):
        i = int(diff[0])
        raise TopologyError(
            f"{name}: expected the same faces as {ref_name}, found {len(diff)} differing faces: "
            f"{_listing(diff)} (face {i}: expected {F_ref[i].tolist()}, found {F[i].tolist()})"
        )


def connected_components(F: np.ndarray, n_vertices: int) -> np.ndarray:
    """Label of the connected component of every vertex, (n,) int (isolated vertices get their own)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components as cc

    i = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    j = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    A = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices))
    return cc(A, directed=False)[1]


def unique_edges(F) -> np.ndarray:
    """The unique undirected edges of triangles ``F`` (m, 3): (E, 2) int64, each row ``(low, high)``,
    rows in lexicographic order (what ``np.unique(np.sort(edges, axis=1), axis=0)`` gives, through one
    integer key per edge instead of a row-wise sort)."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros((0, 2), np.int64)
    e = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    lo, hi = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
    n = np.int64(hi.max()) + 1
    key = np.unique(lo * n + hi)
    return np.stack([key // n, key % n], axis=1)


def boundary_vertices(F) -> np.ndarray:
    """Sorted indices (b,) int64 of the vertices on a boundary edge (an edge of exactly one triangle of
    ``F`` (m, 3))."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros(0, np.int64)
    e = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    lo, hi = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
    n = np.int64(hi.max()) + 1
    key, count = np.unique(lo * n + hi, return_counts=True)
    once = key[count == 1]
    return np.unique(np.concatenate([once // n, once % n]))


def median_edge_length(V, F) -> float:
    """Median length of the triangle edges of ``V`` (n, 3), ``F`` (m, 3) (interior edges counted twice)."""
    e = V[F[:, [1, 2, 0]]] - V[F]
    return float(np.median(np.linalg.norm(e, axis=2)))
