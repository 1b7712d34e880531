"""Normal-only displacement: the last registration stage after a shape-model fit, which cannot slide.

After an identity (or expression) fit (:mod:`.shapemodel`), what the space cannot express -- a
person's own detail, modes the basis lacks -- is taken as a scalar offset ``d_i`` of each vertex
along the fitted model's unit normal ``m_i``:

    x_i = p_i + d_i m_i,
    E(d) = sum_i w_i (n_i . (p_i + d_i m_i - q_i))^2 + lambda sum_{(i,j) edges} (d_i - d_j)^2
           + eps sum_i d_i^2                                                          (eq. N1)

``q_i, n_i`` the nearest scan vertex's tangent plane (as :mod:`.nricp`'s point-to-plane term), ``w_i``
1 for kept pairs and 0 otherwise (holes, rims, far or back-facing pairs: those vertices follow their
neighbours through the graph Laplacian). Each vertex moves on its own normal line only, so the point
of the face a vertex stands for is the model's (its tangential place is not re-decided by the data,
which cannot tell it), unlike the free non-rigid stage whose points slide along the surface.

(N1) is a sparse linear least squares in ``d`` (n unknowns): ``(diag(w a^2) + lambda L + eps I) d =
-w a r`` with ``a_i = n_i . m_i``, ``r_i = n_i . (p_i - q_i)``; the pairs are found again at the
moved points and the system solved again (a few rounds; ``L`` is built once; ``eps = 1e-6`` keeps
a part without any data at zero offset).

Compared with a free non-rigid ICP after the fit (Amberg et al. 2007) this is the displacement-map
refinement of morphable-model pipelines (e.g. FLAME's or Booth et al.'s detail stage), here fitted
straight to the scan.

References
----------
Amberg B., Romdhani S., Vetter T. Optimal step nonrigid ICP algorithms for surface registration. CVPR 2007.
Li T. et al. Learning a model of facial shape and expression from 4D scans (FLAME). SIGGRAPH Asia 2017.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError


@dataclass(frozen=True)
class NormalStageOptions:
    """Options of :func:`normal_displacement`.

    Attributes
    ----------
    smoothness : ``lambda`` of (N1) (unit-free: the data term is per vertex, the Laplacian per edge)
    iterations : rounds of closest points and a solve
    max_distance : pairs farther than this many ``h`` from the scan are dropped
    normal_angle : degrees; pairs whose normals differ more are dropped
    max_offset : offsets are clipped to this many ``h`` (a hole's far side is not a target)
    """

    smoothness: float = 1.0
    iterations: int = 4
    max_distance: float = 3.0
    normal_angle: float = 60.0
    max_offset: float = 3.0

    def __post_init__(self):
        for k in ("smoothness", "max_distance", "max_offset"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"normal stage {k}: expected a positive number, found {v!r}")
        if not (isinstance(self.iterations, (int, np.integer)) and self.iterations >= 1):
            raise InputError(f"normal stage iterations: expected an integer >= 1, found {self.iterations!r}")
        if not 0 < self.normal_angle <= 180:
            raise InputError(f"normal stage normal_angle: expected degrees in (0, 180], found {self.normal_angle!r}")


@dataclass(frozen=True)
class NormalStageResult:
    """Result of :func:`normal_displacement`.

    Attributes
    ----------
    vertices : (n, 3) ``p + d m``
    offset : (n,) ``d`` (the surface's units)
    distance : (n,) distance of each vertex to the scan's triangles (exact closest points)
    no_surface : (n,) bool, vertices without a data term in the last round
    iterations : rounds run
    """

    vertices: np.ndarray
    offset: np.ndarray
    distance: np.ndarray
    no_surface: np.ndarray
    iterations: int


def normal_displacement(P: np.ndarray, normals: np.ndarray, laplacian: sp.spmatrix, surface, h: float,
                        options: NormalStageOptions = NormalStageOptions(),
                        use: np.ndarray | None = None) -> NormalStageResult:
    """Offsets along the normals (eq. N1 of the module docstring) of ``P`` towards a scan.

    Parameters
    ----------
    P : (n, 3) the fitted mesh (rest of this stage), in the surface's frame
    normals : (n, 3) its unit vertex normals ``m``
    laplacian : (n, n) graph Laplacian of the mesh (:attr:`.nricp.NonRigidICP.L`)
    surface : :class:`.nricp.ScanSurface`
    h : length unit (median edge length)
    use : vertices that may pair with the scan (default all); the others get no data term

    Returns
    -------
    NormalStageResult
    """
    n = len(P)
    use = np.arange(n) if use is None else np.asarray(use)
    cos_max = np.cos(np.radians(options.normal_angle))
    dmax, lim = options.max_distance * h, options.max_offset * h
    base = options.smoothness * sp.csr_matrix(laplacian) + sp.identity(n, format="csr") * 1e-6
    d = np.zeros(n)
    ok = np.zeros(n, bool)
    for _ in range(options.iterations):
        X = P + d[:, None] * normals
        U, N, du, rim = surface.nearest_planes(X[use], True, dmax)
        a = (N * normals[use]).sum(1)
        keep = (~rim) & (du <= dmax) & (a >= cos_max)
        ok[:] = False
        ok[use[keep]] = True
        i = use[keep]
        a, r = a[keep], ((P[i] - U[keep]) * N[keep]).sum(1)  # residual at d = 0 along the scan normal
        diag = np.zeros(n)
        rhs = np.zeros(n)
        diag[i] = a * a
        rhs[i] = -a * r
        M = (base + sp.diags(diag)).tocsc()
        d = np.clip(spla.spsolve(M, rhs), -lim, lim)
    X = P + d[:, None] * normals
    return NormalStageResult(X, d, surface.closest(X)[2], ~ok, options.iterations)
