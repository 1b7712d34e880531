"""Fast exact new-pair search and triangle-triangle distances, for the exact contact solve.

Broad phase
-----------
Every triangle lies in the ball around its centroid whose radius is the largest centroid-to-corner
distance (enlarged by a relative 1e-9 for rounding), so two triangles can only intersect (closed
sets) if their balls meet. Ball pairs are found with a k-d tree (scipy ``cKDTree``): small balls
by one ``query_pairs`` at twice the largest small radius, the few large ones (above the 95th
percentile) against every centroid. The search can be restricted to pairs with at least one
triangle in a given set (the triangles that moved), which is what keeps the contact loop fast.

Narrow phase
------------
The package's exact predicates, :func:`facebasis.contact.penetration.triangle_pairs_intersect`;
a pair is *new* unless it also intersects (same test) in every reference's place, i.e. in the target
neutral or in the template shape: the definition of
:func:`~facebasis.contact.penetration.penetration_report`, evaluated on candidate pairs only.

Distances
---------
:func:`triangle_distance` gives the distance between disjoint triangles and the unit direction
between their closest points (Ericson, Real-Time Collision Detection, 2005, sec. 5.1.5 and 5.1.9):
the smallest of the six point-triangle and nine segment-segment distances. For disjoint convex
sets the plane through the closest points, normal to that direction, separates them with margin
equal to the distance.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .penetration import triangle_pairs_intersect


def _balls(V, F):
    tri = V[F]
    c = tri.mean(1)
    r = np.sqrt(((tri - c[:, None]) ** 2).sum(-1)).max(1)
    scale = float(np.abs(V).max()) if len(V) else 1.0
    return c, r * (1.0 + 1e-9) + 1e-12 * scale


def _levels(r: np.ndarray) -> list:
    """Triangles grouped by ball radius in factors of two (at most 8 groups): (indices, max radius)."""
    lev = np.floor(np.log2(r / r.min())).astype(np.int64)
    lev = np.minimum(lev, 7)
    return [(np.flatnonzero(lev == k), float(r[lev == k].max())) for k in np.unique(lev)]


def candidate_pairs(V: np.ndarray, F: np.ndarray, faces=None, pad: float = 0.0) -> np.ndarray:
    """Vertex-disjoint triangle pairs (i < j) whose bounding balls and boxes meet, (p, 2) int64; with ``faces``
    (indices or (m,) bool) only pairs holding at least one of those triangles; with ``pad`` > 0 the
    balls are enlarged by pad / 2 (every pair closer than ``pad`` is listed). Conservative: every
    intersecting pair is listed. Balls are grouped by radius (factors of two), one k-d tree per
    group, so that small triangles are never searched at a large triangle's radius."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    m = len(F)
    if m < 2:
        return np.zeros((0, 2), np.int64)
    c, r = _balls(V, F)
    r = r + 0.5 * float(pad)
    P = []
    if faces is None:
        levels = [(idx, R, cKDTree(c[idx])) for idx, R in _levels(r)]
        for a, (ia, ra, ta) in enumerate(levels):
            P.append(ia[ta.query_pairs(2.0 * ra, output_type="ndarray")].reshape(-1, 2))
            for ib, rb, tb in levels[a + 1:]:
                sdm = ta.sparse_distance_matrix(tb, ra + rb, output_type="ndarray")
                P.append(np.stack([ia[sdm["i"]], ib[sdm["j"]]], 1))
    else:
        faces = np.asarray(faces)
        sel = faces.astype(bool) if faces.dtype == bool else np.isin(np.arange(m), faces)
        if not sel.any():
            return np.zeros((0, 2), np.int64)
        # only triangles whose balls can reach the selected ones' box are searched (exact: ball distance)
        lo_s = (c[sel] - r[sel, None]).min(0) - r.max()
        hi_s = (c[sel] + r[sel, None]).max(0) + r.max()
        keep = ((c >= lo_s) & (c <= hi_s)).all(1)
        levels = [(idx[keep[idx]], R) for idx, R in _levels(r)]
        levels = [(idx, R, cKDTree(c[idx])) for idx, R in levels if len(idx)]
        for ia, ra, _ in levels:
            qa = ia[sel[ia]]
            if len(qa) == 0:
                continue
            tq = cKDTree(c[qa])
            for ib, rb, tb in levels:
                sdm = tq.sparse_distance_matrix(tb, ra + rb, output_type="ndarray")
                P.append(np.stack([qa[sdm["i"]], ib[sdm["j"]]], 1))
    P = np.concatenate(P) if P else np.zeros((0, 2), np.int64)
    P = P[((c[P[:, 0]] - c[P[:, 1]]) ** 2).sum(1) <= (r[P[:, 0]] + r[P[:, 1]]) ** 2]
    P = np.sort(P, axis=1)
    P = P[P[:, 0] != P[:, 1]]
    if faces is not None:  # a pair of two selected triangles was found twice
        code = np.unique(P[:, 0] * m + P[:, 1])
        P = np.stack([code // m, code % m], 1)
    else:
        P = P[np.lexsort((P[:, 1], P[:, 0]))]
    tri = V[F]
    lo, hi = tri.min(1) - 0.5 * pad, tri.max(1) + 0.5 * pad
    P = P[((lo[P[:, 0]] <= hi[P[:, 1]]) & (lo[P[:, 1]] <= hi[P[:, 0]])).all(1)]  # boxes meet too
    shared = (F[P[:, 0]][:, :, None] == F[P[:, 1]][:, None, :]).any(axis=(1, 2))
    return P[~shared]


def intersecting(V, F, pairs) -> np.ndarray:
    """(p,) bool: the exact closed intersection test of triangle pairs (p, 2) placed at V."""
    P = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(P) == 0:
        return np.zeros(0, bool)
    return triangle_pairs_intersect(V[F[P[:, 0]]], V[F[P[:, 1]]])


def new_pairs(V, F, references=(), faces=None) -> np.ndarray:
    """Intersecting vertex-disjoint pairs of (V, F) that intersect in none of ``references`` (meshes
    (n, 3) in the same topology), (q, 2) sorted. With ``faces``, only pairs holding one of them (the
    caller guarantees that the other pairs are unchanged)."""
    P = candidate_pairs(V, F, faces)
    P = P[intersecting(V, F, P)]
    for R in references:
        if len(P):
            P = P[~intersecting(np.asarray(R, np.float64), F, P)]
    return P


# --- distances ------------------------------------------------------------------------------------

def _dot(a, b):
    return (a * b).sum(-1)


def closest_point_triangle(p, a, b, c) -> np.ndarray:
    """Closest point of triangles abc to points p, all (q, 3) (Ericson 2005, sec. 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp = p - b
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    cp = p - c
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v = np.where(den != 0, vb / den, 0.0)
        w = np.where(den != 0, vc / den, 0.0)
        out = a + v[:, None] * ab + w[:, None] * ac  # interior
        # edge regions (later assignments win; the order follows Ericson's early returns reversed)
        m = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        out = np.where(m[:, None], b + np.nan_to_num(t)[:, None] * (c - b), out)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = d2 / (d2 - d6)
        out = np.where(m[:, None], a + np.nan_to_num(t)[:, None] * ac, out)
        out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = d1 / (d1 - d3)
        out = np.where(m[:, None], a + np.nan_to_num(t)[:, None] * ab, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)
    return out


def closest_points_segments(p1, q1, p2, q2):
    """Closest points of segments p1q1 and p2q2, all (q, 3) (Ericson 2005, sec. 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    c, b = _dot(d1, r), _dot(d1, d2)
    tiny = 1e-30
    with np.errstate(divide="ignore", invalid="ignore"):
        den = a * e - b * b
        s = np.where(den > tiny, np.clip((b * f - c * e) / den, 0, 1), 0.0)
        t = np.where(e > tiny, (b * s + f) / e, 0.0)
        lo, hi = t < 0, t > 1
        s = np.where(lo, np.where(a > tiny, np.clip(-c / a, 0, 1), 0.0), s)
        s = np.where(hi, np.where(a > tiny, np.clip((b - c) / a, 0, 1), 0.0), s)
        t = np.clip(t, 0, 1)
    return p1 + s[:, None] * d1, p2 + t[:, None] * d2


def triangle_distance(T1: np.ndarray, T2: np.ndarray):
    """Distance between triangles T1, T2 (p, 3, 3) that do not intersect, and the unit direction
    from T2's closest point to T1's, (p,), (p, 3). Intersecting pairs get distance 0 (direction
    arbitrary but unit)."""
    T1 = np.asarray(T1, np.float64)
    T2 = np.asarray(T2, np.float64)
    best = np.full(len(T1), np.inf)
    vec = np.zeros((len(T1), 3))
    cands = []
    for k in range(3):
        cands.append((T1[:, k], closest_point_triangle(T1[:, k], T2[:, 0], T2[:, 1], T2[:, 2])))
        cands.append((closest_point_triangle(T2[:, k], T1[:, 0], T1[:, 1], T1[:, 2]), T2[:, k]))
    for i in range(3):
        for j in range(3):
            cands.append(closest_points_segments(T1[:, i], T1[:, (i + 1) % 3], T2[:, j], T2[:, (j + 1) % 3]))
    for x, y in cands:
        d = np.sqrt(((x - y) ** 2).sum(1))
        m = d < best
        best[m] = d[m]
        vec[m] = (x - y)[m]
    norm = np.linalg.norm(vec, axis=1)
    zero = norm <= 0
    vec[zero] = np.cross(T1[zero, 1] - T1[zero, 0], T1[zero, 2] - T1[zero, 0]) if zero.any() else vec[zero]
    norm = np.linalg.norm(vec, axis=1)
    vec = vec / np.where(norm > 0, norm, 1.0)[:, None]
    vec[norm <= 0] = (1.0, 0.0, 0.0)
    return best, vec


__all__ = ["candidate_pairs", "intersecting", "new_pairs", "closest_point_triangle", "closest_points_segments",
           "triangle_distance"]
