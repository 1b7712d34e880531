"""Scan-to-model pairs for the model fits of :mod:`.shapemodel`: what a one-sided closest-point term misses.

The fits of :func:`.shapemodel.fit_shape_model` pair each model vertex with its nearest scan vertex and
drop the pairs that land on the scan's rim (a hole's border: the true counterpart is in the hole) or
far away. A model part that lies over a hole of the scan is then free: nothing in the energy says that
the scanner would have seen it there. On an opened mouth (the scan has a hole between the lips) that
left a basin where the lips close over the hole, ``jawOpen + mouthClose + mouthShrugLower`` (the lips'
model-to-scan pairs all land on the hole's rim and are dropped, while the scan's lips, a centimetre
lower, pair with nothing). The reverse pairs see it: every scan point has a counterpart on the model,
so scan vertices pull their nearest model vertices,

    E = (1/(k + p)) [ sum_k (n_k . (x_k - y_k))^2 + sum_j (m_j . (x_i(j) - q_j))^2 ],
    i(j) = argmin_i |x_i - q_j|                                                            (eq. S1)

with ``q_j, m_j`` a scan vertex and its normal, ``x_i`` the model's vertices that may pair, and the first
sum the fit's k model-to-scan pairs: the p pairs join them in the same least squares (same Jacobian rows,
the model vertex ``i(j)``) under one normalisation, so switching them on lowers the model-to-scan pairs'
share; the point-to-plane residual is measured along the scan's normal (Chen & Medioni 1992). It is a
bidirectional (Chamfer-type) closest-point term on a sample of the scan, not Rusinkiewicz's (2019)
symmetric objective (one set of pairs, residuals along the sum of both normals).

Pairs are kept when the two normals agree (the fit's ``normal_angle``), the distance is within
``max_distance`` edge lengths, and the scan point is the model vertex's own counterpart,

    |n_i . (q_j - x_i)|  <=  |n_i . (p_i - x_i)| + SLACK h,
    or  |p_i - x_i| > SLACK h with p_i on a rim,          i = i(j)                           (eq. S3)

with ``n_i`` the model's unit normal and ``p_i`` the scan vertex nearest ``x_i``: a scan point farther off
the vertex's tangent plane than the scan surface the vertex already lies on is a layer the model lacks (a
fringe of hair, a cap's brim, a collar) and would pull the model towards it; offsets are taken along the
normal, so the points of a scan denser than the model, lying along the skin between its vertices, all
pair (straight-line distances dropped 35 % of the right pairs of a midpoint-subdivided scan at the
exact fit); a vertex over a hole (its nearest scan vertex on the hole's rim, farther than the slack) is
exactly what the pairs are for. Not trimmed at a few times the
median as the model-to-scan pairs are: the pairs a few millimetres off are the ones that carry the signal.
Measured on the tiny rig of ``tests/geometry/test_scanpairs.py`` with the forehead copied 0.5-1 cm in front
of it: without eq. S3 browInnerUp 1.1-1.5 and face p95 0.03-0.06, or (through eq. S2's choice) an opened
mouth left half closed; with it the scan's own face decides (p95 <= 0.001).

Measured (``problems.bench_mouth_basin``, reports/registration/mouth_basin: 9 mouth scans x ICT persons of seeds
0-4, with and without out-of-space detail): 9 of 90 scans over median 0.05 / p95 0.2 cm with the model-to-scan
pairs alone, 2 with 5000 scan pairs (1000 left seed 3's jawOpen 0.5 in the basin; 2000-10000 gave the same). Those
2 were within the targets before: the term opens other basins there (a lower lip rolled in, mouthRollLower 1.5, on
seed 0 detail jawOpen 0.7: p95 0.062 -> 0.323; lips half open on seed 4 in-space mouthClose: 0.042 -> 0.488). The
registration's expression fit therefore adds the pairs after a one-sided fit, continued from it, and keeps the fit
that leaves less of the scan unexplained (:mod:`.pairschedule`, eq. S2).

References
----------
Chen Y., Medioni G. Object modelling by registration of multiple range images. Image and Vision
Computing 1992.
Rusinkiewicz S. A symmetric objective function for ICP. SIGGRAPH 2019.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: eq. S3's slack, in the model's edge lengths: a scan point's distance to its model vertex may exceed that
#: vertex's own distance to the scan by this much (the vertices' spacing, noise; 1 let a layer 1.7 edge lengths
#: in front through on the tiny rig)
SLACK = 0.5


class ScanToModel:
    """A seeded sample of scan vertices, paired each round with the nearest model vertex (eq. S1).

    Parameters
    ----------
    surface : :class:`.nricp.ScanSurface` in the model's frame
    use : (u,) the model vertices that may pair (all of them, not a sample: the nearest one is wanted)
    options : :class:`.shapemodel.ModelFitOptions` (``scan_pairs``, ``seed``, ``max_distance``,
        ``normal_angle``)
    h : the length unit of ``max_distance``
    """

    def __init__(self, surface, use: np.ndarray, options, h: float):
        pool = surface.used
        rng = np.random.default_rng(options.seed + 1)
        pick = pool if len(pool) <= options.scan_pairs else np.sort(
            rng.choice(pool, options.scan_pairs, replace=False))
        self.Q, self.N = surface.V[pick], surface.vertex_normals[pick]
        self.use = np.asarray(use)
        self.dmax = options.max_distance * h
        self.cos_max = np.cos(np.radians(options.normal_angle))
        self.surface, self.slack = surface, SLACK * h

    def pairs(self, X: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(model vertex indices, scan points, scan normals)`` of the kept pairs, for the model at ``X``
        (n, 3) with unit vertex normals ``normals`` (n, 3)."""
        dist, j = cKDTree(X[self.use]).query(self.Q, distance_upper_bound=self.dmax)
        far = ~np.isfinite(dist)
        i = self.use[np.where(far, 0, j)]
        ok = ~far & ((normals[i] * self.N).sum(1) >= self.cos_max)
        i, Q, N = i[ok], self.Q[ok], self.N[ok]
        # eq. S3: a scan point pulls its model vertex only if it lies no farther off the vertex's tangent plane
        # than the scan the vertex already lies on (offsets along the model's normal: a scan denser than the
        # model has points along the skin between its vertices), or the vertex lies over a hole (its nearest
        # scan vertex a rim vertex farther than the slack); else the point is on a layer the model lacks
        own, k = self.surface.tree.query(X[i])
        p = self.surface.used[k]
        n = normals[i]
        off_q = np.abs(((Q - X[i]) * n).sum(1))
        off_own = np.abs(((self.surface.V[p] - X[i]) * n).sum(1))
        over_hole = self.surface.rim_vertex[p] & (own > self.slack)
        mutual = (off_q <= off_own + self.slack) | over_hole
        return i[mutual], Q[mutual], N[mutual]
