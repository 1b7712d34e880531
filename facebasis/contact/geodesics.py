"""Graph geodesics on triangle meshes, bounded and local (used by virtual-edge detection and by the
penetration counter's split into local folds and layer crossings).

Shortest paths (scipy's Dijkstra) on the mesh edges extended by the straight segments across each
pair of adjacent triangles (:func:`edge_graph`): graph distances never underestimate surface
geodesics and overestimate them by a few per cent. Searches are bounded and grouped by grid cells
so each one only touches the vertices it can reach; large batches run on the machine's cores.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def edge_graph(V, F) -> sp.csr_matrix:
    """Symmetric sparse (n, n) graph for shortest paths: mesh edges with their lengths, plus for
    every interior edge ab between triangles abc and bad the segment cd, with its length in the
    unfolding of the two triangles, when that segment crosses ab (the straight path across the
    pair of triangles). The extra segments remove most of the zig-zag error of edge paths on
    skinny triangles; every graph path still has a surface path of the same length, so graph
    distances never underestimate geodesics."""
    n = len(V)
    half = np.concatenate([F[:, [0, 1, 2]], F[:, [1, 2, 0]], F[:, [2, 0, 1]]])  # (a, b, opposite c)
    key = np.minimum(half[:, 0], half[:, 1]) * n + np.maximum(half[:, 0], half[:, 1])
    order = np.argsort(key, kind="stable")
    ks = key[order]
    E = np.stack([ks // n, ks % n], 1)
    first = np.r_[True, ks[1:] != ks[:-1]]
    U = E[first]
    w = np.linalg.norm(V[U[:, 0]] - V[U[:, 1]], axis=1)
    rows, cols, vals = [U[:, 0]], [U[:, 1]], [w]
    # interior edges: exactly two half-edges with the same key
    pair = np.flatnonzero(~first)
    pair = pair[(pair + 1 >= len(ks)) | (np.r_[ks[1:], -1][pair] != ks[pair])]  # drop non-manifold runs
    h1, h2 = half[order[pair - 1]], half[order[pair]]
    a, b, c, d = V[h1[:, 0]], V[h1[:, 1]], V[h1[:, 2]], V[h2[:, 2]]
    ab = b - a
    L = np.linalg.norm(ab, axis=1)
    ok = L > 0
    u = ab / np.maximum(L, 1e-300)[:, None]

    def planar(p):  # coordinates (along ab, distance from ab) of p in its triangle's plane
        q = p - a
        x = (q * u).sum(1)
        y = np.linalg.norm(q - x[:, None] * u, axis=1)
        return x, y

    xc, yc = planar(c)
    xd, yd = planar(d)
    yd = -yd  # unfold d to the other side of ab
    t = yc / np.maximum(yc - yd, 1e-300)
    x_cross = xc + t * (xd - xc)  # where segment cd meets the line ab
    ok &= (yc > 0) & (yd < 0) & (x_cross >= 0) & (x_cross <= L)
    length = np.hypot(xc - xd, yc - yd)
    rows.append(h1[ok, 2])
    cols.append(h2[ok, 2])
    vals.append(length[ok])
    return _min_duplicates(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), n)


def _min_duplicates(r, c, v, n) -> sp.csr_matrix:
    """Symmetric graph keeping the shortest length among repeated (r, c) entries."""
    a, b = np.minimum(r, c), np.maximum(r, c)
    key = a * n + b
    order = np.lexsort((v, key))
    key, v = key[order], v[order]
    first = np.r_[True, key[1:] != key[:-1]]
    key, v = key[first], v[first]
    a, b = key // n, key % n
    return sp.coo_matrix((np.r_[v, v], (np.r_[a, b], np.r_[b, a])), shape=(n, n)).tocsr()


def geodesic_pair_distances(V, F, pairs, limit: float, memory_bytes: int = 64 * 2 ** 20) -> np.ndarray:
    """Graph geodesic distance (:func:`edge_graph`) of every pair (p, 2), ``inf`` beyond ``limit``.

    Bounded Dijkstra (scipy) from each distinct first vertex. With a finite ``limit`` the sources
    are grouped by grid cells of size ``2 limit`` and each group searches only the subgraph of
    vertices within ``limit`` (Euclidean) of the cell's box: every path no longer than ``limit``
    stays there, so the distances are the same as on the whole graph, at a fraction of the cost.
    """
    pairs = np.asarray(pairs, np.int64)
    out = np.full(len(pairs), np.inf)
    if len(pairs) == 0:
        return out
    G = edge_graph(V, F)
    order = np.argsort(pairs[:, 0], kind="stable")
    P = pairs[order]
    src = np.unique(P[:, 0])
    if not np.isfinite(limit):  # whole-graph searches, as many sources as the memory budget allows
        chunk = max(1, int(memory_bytes // (8 * len(V))))
        groups = [src[i:i + chunk] for i in range(0, len(src), chunk)]
    else:
        cell = np.floor((V[src] - V.min(0)) / (2.0 * limit)).astype(np.int64)
        key = (cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]) * (cell[:, 2].max() + 1) + cell[:, 2]
        ko = np.argsort(key, kind="stable")
        cuts = np.flatnonzero(np.diff(key[ko])) + 1
        groups = [np.sort(g) for g in np.split(src[ko], cuts)]
    jobs = [(g, _group_rows(P, g)) for g in groups]
    results = None
    if np.isfinite(limit) and len(jobs) > 8:
        results = _parallel_groups(V, G, P, jobs, limit)
    if results is None:
        results = [_group_distances(V, G, P, g, rows, sel, limit) for g, (rows, sel) in jobs]
    for (g, (rows, sel)), vals in zip(jobs, results):
        out[order[sel]] = vals
    return out


def _group_rows(P, s):
    """Rows of P (sorted by source) whose source is in the sorted group s: (row in s, index in P)."""
    starts = np.searchsorted(P[:, 0], s, side="left")
    counts = np.searchsorted(P[:, 0], s, side="right") - starts
    rows = np.repeat(np.arange(len(s)), counts)
    sel = np.repeat(starts, counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
    return rows, sel


def _group_distances(V, G, P, s, rows, sel, limit):
    from scipy.sparse.csgraph import dijkstra

    if not np.isfinite(limit):
        D = dijkstra(G, directed=False, indices=s, limit=limit)
        return D[rows, P[sel, 1]]
    lo, hi = V[s].min(0) - limit, V[s].max(0) + limit
    sub = np.flatnonzero(((V >= lo) & (V <= hi)).all(1))
    local = -np.ones(len(V), np.int64)
    local[sub] = np.arange(len(sub))
    D = dijkstra(G[sub][:, sub], directed=False, indices=local[s], limit=limit)
    tgt = local[P[sel, 1]]
    inside = tgt >= 0
    vals = np.full(len(sel), np.inf)
    vals[inside] = D[rows[inside], tgt[inside]]
    return vals


_SHARED: dict = {}


def _worker(args):
    lo_hi, limit = args
    V, G, P, jobs = _SHARED["V"], _SHARED["G"], _SHARED["P"], _SHARED["jobs"]
    return [_group_distances(V, G, P, g, rows, sel, limit) for g, (rows, sel) in jobs[lo_hi[0]:lo_hi[1]]]


def _parallel_groups(V, G, P, jobs, limit):
    """The groups' searches on the machine's cores (forked worker processes: scipy's Dijkstra
    holds the GIL). None where fork is unavailable or there is one core."""
    import multiprocessing as mp
    import os

    from ..workers import worker_init

    try:
        cores = len(os.sched_getaffinity(0))
        ctx = mp.get_context("fork")
    except (AttributeError, ValueError):  # pragma: no cover - not Linux
        return None
    if cores < 2 or mp.current_process().daemon:  # e.g. inside a Dask worker: no child processes
        return None
    _SHARED.update(V=V, G=G, P=P, jobs=jobs)
    try:
        bounds = np.linspace(0, len(jobs), cores + 1).astype(int)
        with ctx.Pool(cores, initializer=worker_init, initargs=(os.getpid(),)) as pool:  # see facebasis.workers
            parts = pool.map(_worker, [((bounds[i], bounds[i + 1]), limit) for i in range(cores)])
    finally:
        _SHARED.clear()
    return [r for part in parts for r in part]


__all__ = ["edge_graph", "geodesic_pair_distances"]
