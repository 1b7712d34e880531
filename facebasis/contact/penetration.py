"""Exact counting of self-intersecting triangle pairs (surface penetration, Li et al. 2023).

A *penetration* is a pair of triangles that share no vertex and intersect (closed sets: touching
counts). Pairs that share a vertex or an edge are neighbours on the surface and are not counted.

Method
------
* Broad phase: a uniform grid of cells (twice the median triangle box); triangles sharing a cell
  and whose axis-aligned boxes overlap are candidates; all vectorised.
* Narrow phase: for non-coplanar triangles, T1 and T2 intersect iff an edge of one crosses the other
  (the intersection segment starts and ends on triangle edges). A segment xy crosses triangle pqr
  iff ``orient(p,q,r,x)`` and ``orient(p,q,r,y)`` do not have the same strict sign and
  ``orient(x,y,p,q)``, ``orient(x,y,q,r)``, ``orient(x,y,r,p)`` do not have opposite strict signs.
  Coplanar pairs are tested in 2D (edge crossings and containment).
* Exact predicates: each ``orient3d`` is evaluated in floating point with Shewchuk's static error
  bound (1997); the few determinants within the bound are re-evaluated exactly in rational
  arithmetic (``fractions.Fraction`` of the float coordinates), so the count does not depend on
  rounding.

Cross-checked in the tests against a brute-force count and against libigl's CGAL-based
``remesh_self_intersections(detect_only=True)``.

References
----------
- Li Hanchao, Shen Chengze, Liu Xinguo. Facial blendshape generation with virtual-edge constraints
    (带虚拟边约束的面部表情基生成算法). Chinese Journal of Computers, 2023(11).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ..errors import InputError, parameter_error
from ..geometry.mesh import validate_mesh

_EPS = 2.0 ** -53
_O3D_BOUND = (7.0 + 56.0 * _EPS) * _EPS  # Shewchuk's o3derrboundA


def _orient3d_exact(a, b, c, d) -> int:
    ax, ay, az = (Fraction(float(a[i])) - Fraction(float(d[i])) for i in range(3))
    bx, by, bz = (Fraction(float(b[i])) - Fraction(float(d[i])) for i in range(3))
    cx, cy, cz = (Fraction(float(c[i])) - Fraction(float(d[i])) for i in range(3))
    det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
    return (det > 0) - (det < 0)


def orient3d(a, b, c, d) -> np.ndarray:
    """Exact sign of ``det[a - d, b - d, c - d]`` for arrays of points (..., 3): +1, 0 or -1.

    Positive when d lies below the plane through a, b, c seen counter-clockwise (Shewchuk's
    convention). Floating-point with a static error bound, exact rational fallback where uncertain.
    """
    a, b, c, d = (np.asarray(x, np.float64) for x in (a, b, c, d))
    shape = np.broadcast_shapes(a.shape, b.shape, c.shape, d.shape)[:-1]
    a, b, c, d = (np.broadcast_to(x, shape + (3,)).reshape(-1, 3) for x in (a, b, c, d))
    ad, bd, cd = a - d, b - d, c - d
    m1 = bd[..., 1] * cd[..., 2] - bd[..., 2] * cd[..., 1]
    m2 = bd[..., 0] * cd[..., 2] - bd[..., 2] * cd[..., 0]
    m3 = bd[..., 0] * cd[..., 1] - bd[..., 1] * cd[..., 0]
    det = ad[..., 0] * m1 - ad[..., 1] * m2 + ad[..., 2] * m3
    perm = (np.abs(ad[..., 0]) * (np.abs(bd[..., 1] * cd[..., 2]) + np.abs(bd[..., 2] * cd[..., 1]))
            + np.abs(ad[..., 1]) * (np.abs(bd[..., 0] * cd[..., 2]) + np.abs(bd[..., 2] * cd[..., 0]))
            + np.abs(ad[..., 2]) * (np.abs(bd[..., 0] * cd[..., 1]) + np.abs(bd[..., 1] * cd[..., 0])))
    sign = np.sign(det).astype(np.int8)
    for i in np.flatnonzero(np.abs(det) <= _O3D_BOUND * perm):  # uncertain: exact rational arithmetic
        sign[i] = _orient3d_exact(a[i], b[i], c[i], d[i])
    return sign.reshape(shape) if shape else sign[0]


def _orient2d_exact(a, b, c) -> int:
    ax, ay = Fraction(float(a[0])) - Fraction(float(c[0])), Fraction(float(a[1])) - Fraction(float(c[1]))
    bx, by = Fraction(float(b[0])) - Fraction(float(c[0])), Fraction(float(b[1])) - Fraction(float(c[1]))
    det = ax * by - ay * bx
    return (det > 0) - (det < 0)


def _project(points, normal_from):
    n = np.cross(normal_from[1] - normal_from[0], normal_from[2] - normal_from[0])
    keep = [i for i in range(3) if i != int(np.argmax(np.abs(n)))]
    return [np.asarray(p, np.float64)[..., keep] for p in points]


def _seg_cross_2d(a, b, c, d) -> bool:
    """Closed segments ab and cd intersect (2D, exact)."""
    o = _orient2d_exact
    d1, d2, d3, d4 = o(a, b, c), o(a, b, d), o(c, d, a), o(c, d, b)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return True

    def on(p, q, r):  # r on segment pq, given collinear
        return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])
    return (d1 == 0 and on(a, b, c)) or (d2 == 0 and on(a, b, d)) or (d3 == 0 and on(c, d, a)) or \
        (d4 == 0 and on(c, d, b))


def _inside_2d(p, T) -> bool:
    s = [_orient2d_exact(T[i], T[(i + 1) % 3], p) for i in range(3)]
    return all(x >= 0 for x in s) or all(x <= 0 for x in s)


def _coplanar_intersect(t1, t2) -> bool:
    """Closed intersection of coplanar triangles t1, t2 (3, 3): 2D test on the dominant plane."""
    P, Q = _project([t1, t2], t1)
    if any(_seg_cross_2d(P[i], P[(i + 1) % 3], Q[j], Q[(j + 1) % 3]) for i in range(3) for j in range(3)):
        return True
    return _inside_2d(P[0], Q) or _inside_2d(Q[0], P)


def _coplanar_segment_triangle(x, y, T) -> bool:
    """Closed segment xy lying in the plane of triangle T (3, 3): 2D test."""
    x2, y2, Q = _project([x, y, T], T)
    return any(_seg_cross_2d(x2, y2, Q[j], Q[(j + 1) % 3]) for j in range(3)) or _inside_2d(x2, Q)


def _segments_cross_triangles(x, y, p, q, r) -> np.ndarray:
    """Closed segment xy vs closed triangle pqr, vectorised over pairs (..., 3) (non-coplanar)."""
    sx = orient3d(p, q, r, x)
    sy = orient3d(p, q, r, y)
    straddle = (sx * sy) <= 0
    s1 = orient3d(x, y, p, q)
    s2 = orient3d(x, y, q, r)
    s3 = orient3d(x, y, r, p)
    same = ~(((s1 > 0) | (s2 > 0) | (s3 > 0)) & ((s1 < 0) | (s2 < 0) | (s3 < 0)))
    out = straddle & same
    for i in np.flatnonzero((sx == 0) & (sy == 0)):  # segment in the triangle's plane: exact 2D test
        out[i] = _coplanar_segment_triangle(x[i], y[i], np.stack([p[i], q[i], r[i]]))
    return out


def triangle_pairs_intersect(T1: np.ndarray, T2: np.ndarray) -> np.ndarray:
    """Exact closed intersection test for triangle pairs T1, T2 (p, 3, 3); (p,) bool."""
    T1 = np.asarray(T1, np.float64)
    T2 = np.asarray(T2, np.float64)
    a, b, c = T1[:, 0], T1[:, 1], T1[:, 2]
    p, q, r = T2[:, 0], T2[:, 1], T2[:, 2]
    o1 = np.stack([orient3d(p, q, r, v) for v in (a, b, c)], 1)  # T1's corners vs T2's plane
    o2 = np.stack([orient3d(a, b, c, v) for v in (p, q, r)], 1)
    separated = (o1 > 0).all(1) | (o1 < 0).all(1) | (o2 > 0).all(1) | (o2 < 0).all(1)
    coplanar = (o1 == 0).all(1)
    hit = np.zeros(len(T1), bool)
    todo = ~separated & ~coplanar
    if todo.any():
        i = np.flatnonzero(todo)
        A, B, C, P, Q, R = a[i], b[i], c[i], p[i], q[i], r[i]
        h = np.zeros(len(i), bool)
        for x, y in ((A, B), (B, C), (C, A)):
            h |= _segments_cross_triangles(x, y, P, Q, R)
        for x, y in ((P, Q), (Q, R), (R, P)):
            h |= _segments_cross_triangles(x, y, A, B, C)
        hit[i] = h
    for j in np.flatnonzero(~separated & coplanar):  # rare: exact 2D test one by one
        hit[j] = _coplanar_intersect(T1[j], T2[j])
    return hit


def _pairs_within_groups(keys: np.ndarray, items: np.ndarray) -> np.ndarray:
    """All pairs of ``items`` that share a key (keys, items (q,)); (p, 2), may repeat."""
    order = np.argsort(keys, kind="stable")
    k, it = keys[order], items[order]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    sizes = np.diff(np.r_[starts, len(k)])
    group_end = np.repeat(starts + sizes, sizes)          # one past the last element of each group
    pos = np.arange(len(k))
    n_after = group_end - pos - 1                          # partners after each element in its group
    first = np.repeat(pos, n_after)
    offs = np.arange(n_after.sum()) - np.repeat(np.cumsum(n_after) - n_after, n_after)
    second = first + 1 + offs
    return np.stack([it[first], it[second]], 1)


def candidate_triangle_pairs(V: np.ndarray, F: np.ndarray, face_mask=None) -> np.ndarray:
    """Vertex-disjoint triangle pairs (i < j) whose bounding boxes overlap, (p, 2) int64.

    Broad phase on a uniform grid (cell = twice the median box size): every triangle is listed in
    the cells its box touches, pairs sharing a cell are kept if their boxes overlap.
    """
    faces = np.flatnonzero(np.ones(len(F), bool) if face_mask is None else np.asarray(face_mask, bool))
    if len(faces) < 2:
        return np.zeros((0, 2), np.int64)
    tri = V[F[faces]]
    lo, hi = tri.min(1), tri.max(1)
    h = 2.0 * float(np.median((hi - lo).max(1))) or 1.0
    origin = lo.min(0)
    c0 = np.floor((lo - origin) / h).astype(np.int64)
    c1 = np.floor((hi - origin) / h).astype(np.int64)
    span = c1 - c0 + 1
    count = span.prod(1)
    tri_id = np.repeat(np.arange(len(faces)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)  # cell index within the box
    sy, sz = np.repeat(span[:, 1], count), np.repeat(span[:, 2], count)
    cell = np.repeat(c0, count, axis=0) + np.stack([local // (sy * sz), (local // sz) % sy, local % sz], 1)
    dims = cell.max(0) + 1
    keys = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    P = _pairs_within_groups(keys, tri_id)
    P = np.sort(P, axis=1)
    code = np.sort(P[:, 0] * len(faces) + P[:, 1])
    code = code[np.r_[True, code[1:] != code[:-1]]]
    P = np.stack([code // len(faces), code % len(faces)], 1)
    overlap = ((lo[P[:, 0]] <= hi[P[:, 1]]) & (lo[P[:, 1]] <= hi[P[:, 0]])).all(1)
    P = P[overlap]
    G = F[faces]
    shared = (G[P[:, 0]][:, :, None] == G[P[:, 1]][:, None, :]).any(axis=(1, 2))
    return faces[P[~shared]]


def intersecting_pairs(V: np.ndarray, F: np.ndarray, face_mask=None, name: str = "mesh") -> np.ndarray:
    """All vertex-disjoint intersecting triangle pairs (i < j), (p, 2), sorted.

    Parameters
    ----------
    V : (n, 3), F : (m, 3)
    face_mask : optional (m,) bool, triangles to consider (e.g. a region)
    """
    V, F = validate_mesh(V, F, name, check_degenerate=False)
    if face_mask is not None and np.asarray(face_mask).shape != (len(F),):
        raise InputError(f"{name}: expected a face mask of shape ({len(F)},), found {np.asarray(face_mask).shape}")
    P = candidate_triangle_pairs(V, F, face_mask)
    if len(P) == 0:
        return P
    hit = np.zeros(len(P), bool)
    for s in range(0, len(P), 200_000):  # bounded memory
        sl = slice(s, s + 200_000)
        hit[sl] = triangle_pairs_intersect(V[F[P[sl, 0]]], V[F[P[sl, 1]]])
    return P[hit]


def region_faces(F: np.ndarray, vertex_mask) -> np.ndarray:
    """Triangles whose three vertices all lie in ``vertex_mask`` (n,) bool."""
    vm = np.asarray(vertex_mask, bool)
    return vm[F].all(1)


def parse_region(text: str, n_vertices: int) -> np.ndarray:
    """``START:END`` (vertex index range, END exclusive) -> (n,) bool mask."""
    try:
        a, b = (int(t) for t in text.split(":"))
    except ValueError as exc:
        raise parameter_error("region", "START:END vertex indices", repr(text)) from exc
    if not (0 <= a < b <= n_vertices):
        raise parameter_error("region", f"0 <= START < END <= {n_vertices}", f"{a}:{b}")
    m = np.zeros(n_vertices, bool)
    m[a:b] = True
    return m


@dataclass(frozen=True)
class PenetrationReport:
    """Intersecting pairs of a mesh, and those new relative to references (same triangle indices).

    pairs : (p, 2) all intersecting vertex-disjoint pairs; new : (q, 2) those in no reference;
    zones : count of new pairs per named vertex zone (a pair belongs to the first zone holding a
    vertex of either triangle; the rest are ``elsewhere``);
    zone_index : (q,) the zone of each new pair, an index into ``zone_names`` (``elsewhere`` last);
    local : (q,) True where the two triangles are within ``local_within`` of each other along the
        rest surface (a fold of the surface onto itself), False for a crossing of two layers that
        are apart along the surface; None when no rest surface was given.
    """

    pairs: np.ndarray
    new: np.ndarray
    zones: dict
    zone_names: tuple = ()
    zone_index: np.ndarray | None = None
    local: np.ndarray | None = None

    def count(self, zone: str | None = None, local: bool | None = None) -> int:
        """New pairs in ``zone`` (any zone if None), local folds only (True), layer crossings only
        (False) or both (None)."""
        keep = np.ones(len(self.new), bool)
        if zone is not None:
            if zone not in self.zone_names:
                raise InputError(f"zone: expected one of {list(self.zone_names)}, found {zone!r}")
            keep &= self.zone_index == self.zone_names.index(zone)
        if local is not None:
            if self.local is None:
                raise InputError("local: this report was made without a rest surface (rest=, local_within=)")
            keep &= self.local if local else ~self.local
        return int(keep.sum())


def pair_set(V, F, face_mask=None, name: str = "reference") -> set:
    """The intersecting pairs of a mesh as a set of (i, j) tuples, for :func:`penetration_report`'s
    ``reference_pairs`` when one reference serves many meshes."""
    return set(map(tuple, intersecting_pairs(V, F, face_mask, name=name).tolist()))


#: default radius of a local fold, in median edge lengths of the rest surface (``local_within``)
LOCAL_FOLD_EDGES = 2.0


def triangle_surface_distance(V, F, pairs, limit: float) -> np.ndarray:
    """Graph geodesic distance along the surface (V, F) between two triangles, (p,).

    The smallest of the nine vertex-to-vertex distances of each pair (p, 2) of triangle indices, by
    the bounded Dijkstra of :func:`facebasis.contact.geodesics.geodesic_pair_distances` (mesh edges and
    unfolded segments across adjacent triangles); ``inf`` beyond ``limit``.
    """
    from .geodesics import geodesic_pair_distances

    P = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(P) == 0:
        return np.zeros(0)
    A, B = F[P[:, 0]], F[P[:, 1]]
    vp = np.stack([np.repeat(A, 3, axis=1), np.tile(B, (1, 3))], axis=-1).reshape(-1, 2)  # (9p, 2)
    return geodesic_pair_distances(V, F, vp, limit=limit).reshape(-1, 9).min(1)


def penetration_report(V, F, references=(), face_mask=None, zones=None, reference_pairs=(), rest=None,
                       local_within: float | None = None) -> PenetrationReport:
    """Count intersecting pairs of (V, F) and the pairs new relative to every reference.

    references : meshes (n, 3) in the same topology (e.g. the target neutral and the template shape
        the result came from); a pair present in any of them is not new
    reference_pairs : the same given as sets from :func:`pair_set` (computed once, reused)
    zones : optional {name: (n,) bool vertex mask}, for locating the new pairs
    rest, local_within : optional rest mesh (n, 3) (e.g. the target neutral) and a distance: new
        pairs whose triangles are within ``local_within`` along the rest surface
        (:func:`triangle_surface_distance`) are *local folds*, the others *layer crossings*. Virtual
        edges (Li et al. 2023) join points far apart along the surface, so they address the second kind.
    """
    if (rest is None) != (local_within is None):
        raise InputError("penetration_report: expected rest and local_within together, found only "
                         + ("rest" if rest is not None else "local_within"))
    if local_within is not None and not (np.isfinite(local_within) and local_within > 0):
        raise InputError(f"local_within: expected a positive distance, found {local_within}")
    if rest is not None:
        rest = np.asarray(rest, np.float64)
        if rest.shape != np.shape(V):
            raise InputError(f"rest: expected vertices of shape {np.shape(V)}, found {rest.shape}")
    P = intersecting_pairs(V, F, face_mask)
    seen = set().union(*reference_pairs)
    for R in references:
        seen |= pair_set(R, F, face_mask)
    new = np.array([p for p in P.tolist() if tuple(p) not in seen], dtype=np.int64).reshape(-1, 2)
    counts, names = {}, ()
    zone_index = None
    if zones is not None:
        names = tuple(zones) + ("elsewhere",)
        zone_index = np.full(len(new), len(names) - 1, dtype=np.int64)
        for z in reversed(range(len(zones))):  # a pair belongs to the first zone that holds it
            m = np.asarray(zones[names[z]], bool)
            zone_index[m[F[new[:, 0]]].any(1) | m[F[new[:, 1]]].any(1)] = z
        counts = dict(zip(names, np.bincount(zone_index, minlength=len(names)).tolist()))
    local = None
    if rest is not None:
        local = triangle_surface_distance(rest, F, new, float(local_within)) < local_within
    return PenetrationReport(P, new, counts, names, zone_index, local)


__all__ = ["orient3d", "triangle_pairs_intersect", "candidate_triangle_pairs", "intersecting_pairs",
           "region_faces", "parse_region", "PenetrationReport", "penetration_report", "pair_set",
           "triangle_surface_distance", "LOCAL_FOLD_EDGES"]
