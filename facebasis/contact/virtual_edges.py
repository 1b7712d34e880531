"""Virtual edges across thin multi-layer regions (Li, Shen, Liu 2023; see References).

Where the face is thin and layered (lips against each other and the mouth socket, upper against
lower eyelid) two vertices can be close in space but far apart along the surface. Deformation
transfer only constrains real edges, so such layers can be pushed through each other. A *virtual
edge* joins two such vertices and is kept, softly, transformed like a real edge.

Detection
---------
Candidate pairs (u, v): Euclidean distance ``d < cap`` and geodesic distance ``g >= ratio * d``.
Geodesics are shortest paths (Dijkstra, scipy) on the mesh edges extended by the straight segments
across each pair of adjacent triangles (:func:`facebasis.contact.geodesics.edge_graph`), bounded by ``ratio * cap`` so that each
search stays local; a pair not reached within the bound has ``g > ratio * cap > ratio * d``. Graph
paths never underestimate surface geodesics and overestimate them by a few per cent, which only
matters for pairs whose ratio is within that margin of the threshold; the tests compare the chosen
edges with exact geodesics (potpourri3d's edge-flip geodesics) on a sample.

Thinning: candidates are taken shortest first; a vertex keeps at most ``per_vertex`` edges, and once
an edge is chosen the vertices within ``spacing`` of either end (other than the ends) are excluded
from further choices, so the edges spread over the layer instead of piling up (default spacing 0:
measured on ICT, sparser edges let more triangles between them cross).

Energy
------
For a virtual edge (u, v) with template rest vector ``s = S0_v - S0_u``, template shape vector
``s_i = Si_v - Si_u`` and target rest vector ``t = B0_v - B0_u``, the transformation is the mean
deformation gradient ``Q`` of the triangles around u and v, as for a real edge of that
neighbourhood; optionally corrected by a rank-one term so that it maps ``s`` to ``s_i`` as a real
edge's own gradient maps the edge (:func:`virtual_edge_targets`):

    t_i = Q t + c (s_i - Q s),  c = clip(s.t / |s|^2, 0, 1)   (mode "proportional", default)
    t_i = Q t                                                 (mode "gradient")

and the energy ``w sum_uv ||(x_v - x_u) - t_i||^2`` is added to the edge-based least squares of
deformation transfer (same factor-once solve, one extra sparse term ``w X^T X``). With the gradient
targets a gap keeps its length up to the local rotation and stretch, so layers do not cross; with
the proportional ones a thinner target layer closes by proportionally less than the template's and
transfer onto the template's own neutral still returns the template exactly.

References
----------
- Li Hanchao, Shen Chengze, Liu Xinguo. Facial blendshape generation with virtual-edge constraints
    (带虚拟边约束的面部表情基生成算法). Chinese Journal of Computers, 2023(11).
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. ACM Transactions on Graphics
    23(3) (SIGGRAPH 2004): 399-405.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from ..jsonio import read_json
from ..geometry.mesh import median_edge_length, validate_mesh
from .geodesics import geodesic_pair_distances

#: Default geodesic/Euclidean ratio floor: catches lids (ratio < 2.7 on ICT) as well as lips.
DEFAULT_RATIO = 2.0
#: Default Euclidean cap, in median edge lengths (about 1 cm on the ICT face and the built-in face).
DEFAULT_CAP_EDGES = 3.3
#: Default weight of the virtual-edge energy relative to the real edges' (each real edge term has 1).
#: Measured on ICT onto a 3x identity (problems/bench.py virtual), proportional targets: 1 beats 3 and 10.
DEFAULT_VIRTUAL_WEIGHT = 1.0
#: Default exclusion radius around chosen ends, in median edge lengths. 0 = no exclusion: on ICT an
#: exclusion of 1.5 edge lengths keeps 618 instead of 5835 edges and halves the reduction of new
#: intersecting pairs (24% instead of 44% at weight 3 with gradient targets).
DEFAULT_SPACING_EDGES = 0.0
#: Default number of virtual edges kept per vertex (the paper: the 3-5 shortest).
DEFAULT_PER_VERTEX = 4


@dataclass(frozen=True)
class VirtualEdges:
    """Chosen virtual edges of a mesh.

    edges : (e, 2) vertex pairs (u < v); euclidean, geodesic : (e,) lengths (geodesic ``inf`` when
    beyond the search bound ``ratio * cap``); n_vertices; the parameters; candidates : pairs that
    passed cap and ratio before thinning; seconds : detection time.
    """

    edges: np.ndarray
    euclidean: np.ndarray
    geodesic: np.ndarray
    n_vertices: int
    cap: float
    ratio: float
    per_vertex: int
    spacing: float
    candidates: int = 0
    seconds: float = 0.0
    source: str = field(default="", compare=False)

    # The interface deformation transfer (:class:`facebasis.geometry.transfer.DeformationTransfer`)
    # uses for an extra edge term: ``n_vertices``, ``len``, ``source``, ``operator()``, the
    # ``default_weight`` and ``modes``, and ``targets(...)``; geometry never imports this module.
    default_weight = DEFAULT_VIRTUAL_WEIGHT
    modes = ("proportional", "gradient")

    def __len__(self) -> int:
        return len(self.edges)

    def targets(self, template_neutral, template_deltas, target_neutral, F, mode: str = "proportional",
                neutral_frames=None, frame_deltas=None) -> np.ndarray:
        """Target vectors (k, e, 3) of the edges for template shapes ``template_deltas`` (k, n, 3);
        see :func:`virtual_edge_targets`."""
        return virtual_edge_targets(self, template_neutral, template_deltas, target_neutral, F, mode,
                                    neutral_frames, frame_deltas)

    def operator(self) -> sp.csr_matrix:
        """Sparse (e, n): row r gives ``x_v - x_u`` of edge r."""
        e = len(self.edges)
        rows = np.r_[np.arange(e), np.arange(e)]
        cols = np.r_[self.edges[:, 1], self.edges[:, 0]]
        vals = np.r_[np.ones(e), -np.ones(e)]
        return sp.csr_matrix((vals, (rows, cols)), shape=(e, self.n_vertices))

    def to_json(self) -> dict:
        return {"format": "facebasis.virtual_edges/1", "n_vertices": int(self.n_vertices), "cap": self.cap,
                "ratio": self.ratio, "per_vertex": int(self.per_vertex), "spacing": self.spacing,
                "candidates": int(self.candidates), "seconds": self.seconds,
                "edges": self.edges.tolist(), "euclidean": self.euclidean.tolist(),
                "geodesic": [None if not np.isfinite(g) else float(g) for g in self.geodesic]}

    def write(self, path) -> None:
        from ..atomic import atomic_write_json

        atomic_write_json(Path(path), self.to_json())

    @staticmethod
    def read(path, n_vertices: int | None = None) -> VirtualEdges:
        """Read an EDGES.json; checks the vertex count against ``n_vertices`` if given."""
        path = Path(path)
        d = read_json(path, "a virtual-edges JSON file")
        try:
            raw = np.asarray(d["edges"])
            if raw.size and (raw.ndim != 2 or raw.shape[1] != 2 or raw.dtype.kind not in "iu"):
                raise ValueError(f"edges as integer pairs [[u, v], ...], found {raw.dtype} values of shape {raw.shape}")
            E = raw.astype(np.int64).reshape(-1, 2)
            n = int(d["n_vertices"])
            for key in ("euclidean", "geodesic"):
                if key in d and len(d[key]) != len(E):
                    raise ValueError(f"'{key}' with one value per edge ({len(E)}), found {len(d[key])}")
            ve = VirtualEdges(E, np.asarray(d.get("euclidean", [np.nan] * len(E)), float),
                              np.asarray([np.inf if g is None else g for g in d.get("geodesic", [None] * len(E))], float),
                              n, float(d.get("cap", np.nan)), float(d.get("ratio", np.nan)),
                              int(d.get("per_vertex", 0)), float(d.get("spacing", np.nan)),
                              int(d.get("candidates", 0)), float(d.get("seconds", 0.0)), source=str(path))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{path}: expected a virtual-edges JSON with 'n_vertices' and 'edges' [[u, v], ...], "
                             f"found an unreadable file ({exc})") from exc
        if n_vertices is not None and n != n_vertices:
            raise InputError(f"{path}: expected edges for a mesh of {n_vertices} vertices, found {n}")
        if len(E) and (E.min() < 0 or E.max() >= n):
            raise InputError(f"{path}: expected vertex indices in [0, {n}), found {int(E.min())}..{int(E.max())}")
        if len(E) and np.any(E[:, 0] == E[:, 1]):
            raise InputError(f"{path}: expected edges between two different vertices, found {E[E[:, 0] == E[:, 1]][0].tolist()}")
        key = np.sort(E, axis=1)
        uniq, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
        if len(uniq) < len(E):  # an edge listed twice would count twice in the energy
            raise InputError(f"{path}: expected each edge once, found {int((counts > 1).sum())} listed more than once "
                             f"(e.g. {uniq[np.argmax(counts > 1)].tolist()})")
        return ve


def thin_candidates(V, pairs, lengths, per_vertex: int, spacing: float) -> np.ndarray:
    """Greedy thinning (shortest first): indices of the kept pairs (see module docstring)."""
    from scipy.spatial import cKDTree

    order = np.argsort(lengths, kind="stable")
    count = np.zeros(len(V), np.int64)
    blocked = np.zeros(len(V), bool)
    tree = cKDTree(V) if spacing > 0 else None
    keep = []
    for idx in order:  # a loop over candidate pairs (thousands), never over triangles
        u, v = pairs[idx]
        if blocked[u] or blocked[v] or count[u] >= per_vertex or count[v] >= per_vertex:
            continue
        keep.append(idx)
        count[u] += 1
        count[v] += 1
        if tree is not None:
            for w in (u, v):
                near = tree.query_ball_point(V[w], spacing)
                blocked[near] = True
            blocked[u] = blocked[v] = False  # the ends themselves may take more edges
    return np.asarray(keep, dtype=np.int64)


def detect_virtual_edges(V, F, cap: float | None = None, ratio: float = DEFAULT_RATIO, per_vertex: int = DEFAULT_PER_VERTEX,
                         spacing: float | None = None, vertex_mask=None, name: str = "mesh") -> VirtualEdges:
    """Detect virtual edges on a mesh (Li et al. 2023).

    Parameters
    ----------
    V : (n, 3), F : (m, 3)
    cap : Euclidean distance cap (mesh units; default ``3.3`` median edge lengths, ~1 cm on ICT)
    ratio : geodesic/Euclidean floor (default 2.0: catches lids, whose ratio is below 2.7 on ICT)
    per_vertex : at most this many edges per vertex (the paper keeps 3-5)
    spacing : exclusion radius around the ends of a chosen edge (default 1.5 median edge lengths)
    vertex_mask : optional (n,) bool, vertices allowed as ends (e.g. to drop nostrils and ears)
    """
    t0 = time.perf_counter()
    from scipy.spatial import cKDTree

    V, F = validate_mesh(V, F, name)
    h = median_edge_length(V, F)
    cap = DEFAULT_CAP_EDGES * h if cap is None else float(cap)
    spacing = DEFAULT_SPACING_EDGES * h if spacing is None else float(spacing)
    if not (cap > 0 and np.isfinite(cap)):
        raise InputError(f"cap: expected a positive distance, found {cap}")
    if not (ratio > 1 and np.isfinite(ratio)):
        raise InputError(f"ratio: expected a geodesic/Euclidean floor > 1, found {ratio}")
    if int(per_vertex) < 1:
        raise InputError(f"per_vertex: expected >= 1, found {per_vertex}")
    if spacing < 0:
        raise InputError(f"spacing: expected >= 0, found {spacing}")
    pairs = cKDTree(V).query_pairs(cap, output_type="ndarray")
    if vertex_mask is not None:
        m = np.asarray(vertex_mask, bool)
        if m.shape != (len(V),):
            raise InputError(f"vertex_mask: expected shape ({len(V)},), found {m.shape}")
        pairs = pairs[m[pairs[:, 0]] & m[pairs[:, 1]]]
    d = np.linalg.norm(V[pairs[:, 0]] - V[pairs[:, 1]], axis=1)
    g = geodesic_pair_distances(V, F, pairs, limit=ratio * cap)
    ok = g >= ratio * d
    pairs, d, g = pairs[ok], d[ok], g[ok]
    keep = thin_candidates(V, pairs, d, int(per_vertex), spacing)
    E = np.sort(pairs[keep], axis=1)
    return VirtualEdges(E, d[keep], g[keep], len(V), cap, float(ratio), int(per_vertex), spacing, int(len(pairs)),
                        time.perf_counter() - t0, source=name)


def vertex_gradients(neutral, shapes, F, neutral_frames=None, frame_deltas=None) -> np.ndarray:
    """Per-vertex mean deformation gradient minus identity, ``Q - I`` (k, n, 3, 3), of shapes (k, n, 3)
    relative to ``neutral`` (Sumner-Popovic frames, averaged over each vertex's triangles).

    ``neutral_frames`` (3, 3, m) and ``frame_deltas`` (k, 3, 3, m), the frames of ``neutral`` and of
    the shapes minus them (:func:`~facebasis.geometry.gradients.frames_cm`), may be passed when the caller
    has them already; ``shapes`` is then not read.
    """
    from ..geometry.gradients import frames_cm

    A0 = frames_cm(neutral, F) if neutral_frames is None else neutral_frames  # (3, 3, m) component-major
    A0inv = np.linalg.inv(np.moveaxis(A0, -1, 0))    # (m, 3, 3)
    dA = frames_cm(shapes, F) - A0 if frame_deltas is None else frame_deltas  # (k, 3, 3, m)
    D = np.einsum("kabt,tbc->ktac", dA, A0inv)       # (Q - I) per triangle, (k, m, 3, 3)
    n, m = len(neutral), len(F)
    inc = sp.csr_matrix((np.ones(3 * m), (F.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m))
    deg = np.asarray(inc.sum(1)).ravel()
    inc = sp.diags(1.0 / np.maximum(deg, 1)) @ inc
    k = len(dA)
    flat = np.moveaxis(D, 1, -1).reshape(k * 9, m)   # (k*9, m)
    return np.moveaxis((inc @ flat.T).T.reshape(k, 3, 3, n), -1, 1)


VIRTUAL_MODES = VirtualEdges.modes


def virtual_edge_targets(edges: VirtualEdges, template_neutral, template_deltas, target_neutral, F,
                         mode: str = "proportional", template_frames=None, frame_deltas=None) -> np.ndarray:
    """Target deltas of every virtual edge for every shape, (k, e, 3): ``t_i - t``.

    ``mode="proportional"`` (default): ``t_i = Q t + c (s_i - Q s)`` with ``Q`` the mean gradient
    around u and v and ``c = clip(s.t / |s|^2, 0, 1)``: the part of the template's motion of the
    edge that the local gradient does not explain is transferred as it is, or scaled down in
    proportion when the target's gap (along s) is thinner than the template's, so a layer pressed
    onto another in the template stops short of it in the target instead of crossing. Never
    scaled up (pairs that touch at rest, |s| ~ 0, would amplify the template's motion). With
    t = s (the template's own neutral) c = 1 and the targets are the template's edge vectors.

    ``mode="gradient"``: ``t_i = Q t``, the vector transformed by the local gradient only, as a
    real edge of that neighbourhood would be. It resists every change of the gap that the
    gradients around u and v do not make, the template's own too (a jaw opening is held back).

    Measured on ICT onto a 3x identity (``python -m problems.bench virtual``), weight 1: gradient
    targets remove 45% of the new intersecting pairs but move the face away from the lips and lids
    by 0.50 of its motion (relative); proportional targets remove 14% and move it by 0.14. Counting
    only layer crossings (triangles >= 2 median edges apart along the target neutral,
    :func:`~facebasis.contact.penetration.penetration_report` with ``rest``), they remove 83% and 31%.

    ``template_frames``, ``frame_deltas``: the template's frames and its shapes' frame deltas, if the
    caller has them (see :func:`vertex_gradients`).
    """
    if mode not in VIRTUAL_MODES:
        raise InputError(f"virtual edge mode: expected one of {VIRTUAL_MODES}, found {mode!r}")
    E = edges.edges
    k = len(template_deltas)
    if len(E) == 0:
        return np.zeros((k, 0, 3))
    S0 = np.asarray(template_neutral, float)
    D = vertex_gradients(S0, S0 + template_deltas if frame_deltas is None else None, F, template_frames,
                         frame_deltas)                        # (k, n, 3, 3)
    Dm = 0.5 * (D[:, E[:, 0]] + D[:, E[:, 1]])             # (k, e, 3, 3)
    t = target_neutral[E[:, 1]] - target_neutral[E[:, 0]]  # (e, 3)
    Dt = np.einsum("keab,eb->kea", Dm, t)                  # (Q - I) t
    if mode == "gradient":
        return Dt
    s = S0[E[:, 1]] - S0[E[:, 0]]                          # (e, 3)
    ds = template_deltas[:, E[:, 1]] - template_deltas[:, E[:, 0]]  # s_i - s, (k, e, 3)
    Ds = np.einsum("keab,eb->kea", Dm, s)                  # (Q - I) s
    coef = np.clip((s * t).sum(1) / np.maximum((s * s).sum(1), 1e-300), 0.0, 1.0)
    return Dt + (ds - Ds) * coef[None, :, None]


__all__ = ["VirtualEdges", "detect_virtual_edges", "thin_candidates", "virtual_edge_targets", "vertex_gradients",
           "DEFAULT_RATIO", "DEFAULT_CAP_EDGES", "DEFAULT_PER_VERTEX", "DEFAULT_SPACING_EDGES",
           "DEFAULT_VIRTUAL_WEIGHT", "VIRTUAL_MODES"]
