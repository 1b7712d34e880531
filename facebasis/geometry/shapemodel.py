"""Linear shape models in the template's topology as registration priors: identity and expression bases.

A *shape basis* is a set of meshes in the template's topology (same vertex count and triangles),
each read as a displacement of the template: ``D_k = mesh_k - template``. Two uses:

* **identity** (ICT-FaceKit's ``FaceXModel/identity*.obj``, or any folder of such meshes): a neutral
  scan is first fitted as ``s R (T + sum_k c_k D_k) + t``, coefficients ``c`` with a Gaussian prior
  (each basis mesh taken as one standard deviation of its mode, as ICT's are: ``c ~ N(0, I)``);
* **expressions** (the template's blendshapes, transferred to the person): an expression scan is
  first fitted as ``R (B_0 + sum_k w_k E_k) + t`` with ``B_0`` the person's registered neutral and
  weights bounded to ``[0, 1]``.

Either fit alternates closest points on the scan with one Gauss-Newton step of the point-to-plane
energy in the pose and the coefficients together (Chen & Medioni 1992 for the point-to-plane term;
the pose linearised as in :func:`.rigid.refine_point_to_plane`),

    E(c, pose) = (1/p) sum_i (n_i . (x_i(c, pose) - q_i))^2 + mu h^2 sum_k (c_k / sigma_k)^2,

``q_i, n_i`` the closest scan point and its normal, ``h`` the template's median edge length (so
``mu`` is unit-free). A step is a bounded linear least squares (bounds on the coefficients only) solved
exactly on its normal equations (:func:`normal_equations`, :func:`box_qp`), i.e. the exact minimiser of the
linearised energy inside the bounds. The non-rigid stage (:mod:`.nricp`) then starts from the fitted mesh and
takes only what the space cannot express: correspondence follows the model's convention instead of sliding.

**When the loop stops.** When a round moves no vertex by ``tolerance h`` (at the final prior), or when it
returns to a state of up to :data:`CYCLE` rounds before (within ``tolerance h`` and 1 % of the round's step, so an
oscillation that still shrinks goes on): the closest points are discrete, so near the
minimum a vertex pair that enters and leaves the kept set (or a bound that becomes active and inactive)
can make the iteration cycle for ever between two to four states; the state of the cycle with the smallest
residual RMS is returned. Measured on the ICT mouth scans (``problems.bench_mouth_basin``, seed 1 in-space
jawOpen): the whole-expression fits cycled with period 4 and 2 from their 22nd round to the cap of 40, the
regional fit (:mod:`.expressionregions`) with period 2 from its 5th round to its cap of 20, moving vertices
by 0.016-0.027 h per round and the residual by < 0.1 %: half of the expression scan's CPU time.

References
----------
Blanz V., Vetter T. A morphable model for the synthesis of 3D faces. SIGGRAPH 1999 (fitting a
linear face space with a prior on the coefficients).
Li T. et al. Learning a model of facial shape and expression from 4D scans (FLAME). SIGGRAPH Asia
2017 (registration through the model first, then free-form refinement).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, named_params, parameter_error
from .rigid import Similarity, _rotation_from_vector
from .scanpairs import ScanToModel


#: the longest limit cycle :func:`fit_shape_model` detects, in rounds (module docstring)
CYCLE = 4


@dataclass(frozen=True)
class ShapeBasis:
    """Displacements of the template, one per basis mesh.

    Attributes
    ----------
    names : (K,) the meshes' file stems
    deltas : (K, n, 3) ``mesh_k - template``
    source : where they were read (folder), for messages and reports
    """

    names: tuple
    deltas: np.ndarray
    source: str = ""

    def subset(self, k: int) -> "ShapeBasis":
        """The first ``k`` modes."""
        return ShapeBasis(self.names[:k], self.deltas[:k], self.source)


def basis_files(folder: str | os.PathLike, pattern: str = "*", what: str = "folder") -> list[Path]:
    """The mesh files of a basis folder matching ``pattern``, sorted by name (``what`` names the folder
    in errors, a ``{name}`` placeholder for a library parameter, see :mod:`facebasis.errors`).

    Raises
    ------
    InputError
        No such folder, or no .obj/.ply file in it.
    """
    from .meshio import MESH_SUFFIXES

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(what=f"{what} {folder}", expected="a folder of meshes in the template's topology",
                         found='a file' if folder.exists() else 'no such folder', params=named_params(what))
    files = sorted(p for p in folder.glob(pattern) if p.suffix.lower() in MESH_SUFFIXES and p.is_file())
    if not files:
        raise InputError(what=f"{what} {folder}", expected=".obj or .ply meshes in the template's topology",
                         found="none", params=named_params(what))
    return files


def read_shape_basis(files, V_ref: np.ndarray, F_ref: np.ndarray, ref_name: str, source: str = "") -> ShapeBasis:
    """Read basis meshes (each of the template's topology) as displacements ``(K, n, 3)`` of ``V_ref``.

    Raises
    ------
    TopologyError
        A mesh with another vertex count or other triangles (names the file, expected and found).
    """
    from .meshio import read_mesh_like

    files = list(files)
    D = np.empty((len(files), len(V_ref), 3))
    for k, p in enumerate(files):  # a loop over files, not vertices
        D[k] = read_mesh_like(p, len(V_ref), F_ref, ref_name) - V_ref
    return ShapeBasis(tuple(Path(p).stem for p in files), D, source)


def template_bases(template: str | os.PathLike, V_ref: np.ndarray) -> tuple[list[Path], list[Path]]:
    """Bases found beside a template in ICT-FaceKit's FaceXModel layout.

    When the template's folder holds ``identity*.obj``: those are the identity basis, and the other
    meshes of the folder with the template's vertex count (not the template itself) its expressions.
    Returns ``(identity files, expression files)``, both empty otherwise.
    """
    t = Path(template).resolve()
    ident = sorted(p for p in t.parent.glob("identity*") if p.suffix.lower() == ".obj" and p.is_file())
    if not ident:
        return [], []
    expr = []
    for p in sorted(t.parent.iterdir()):
        if (p.suffix.lower() == ".obj" and p.is_file() and p.resolve() != t and p not in ident
                and _obj_vertex_count(p) == len(V_ref)):
            expr.append(p)
    return ident, expr


def _obj_vertex_count(path: Path) -> int:
    """Number of ``v`` lines of an OBJ file (a cheap check before reading it)."""
    data = b"\n" + path.read_bytes()
    return data.count(b"\nv ") + data.count(b"\nv\t")


@dataclass(frozen=True)
class ModelFitOptions:
    """Options of :func:`fit_shape_model`.

    Attributes
    ----------
    iterations : closest-point / Gauss-Newton rounds at most
    prior : ``mu`` of the module's energy (unit-free: times ``h^2``)
    max_distance : pairs farther than this many ``h`` are dropped (and farther than 3 x the median
        and h / 2)
    normal_angle : degrees; pairs whose normals differ more are dropped
    scale : also fit a uniform scale (another person; not for one person's expressions)
    tolerance : stop when the largest vertex step is below this many ``h``
    samples : at most this many model vertices (a seeded sample) pair with the scan
    seed : seed of that sample
    prior_start : if set, ``mu`` starts here and falls geometrically to ``prior`` over the first half
        of the iterations (graduated: a strong prior first finds the basin, e.g. an opened jaw rather
        than lips closed over the scan's mouth hole, where no data says otherwise)
    scan_pairs : also pair this many scan vertices (a seeded sample) with their nearest model vertex
        (eq. S1 of :mod:`.scanpairs`; 0: model-to-scan pairs only). A model part over a scan's hole has no
        model-to-scan pair; the scan's points it should cover do
    """

    iterations: int = 40
    prior: float = 1e-4
    max_distance: float = 10.0
    normal_angle: float = 60.0
    scale: bool = True
    tolerance: float = 1e-3
    samples: int = 5000
    seed: int = 0
    prior_start: float | None = None
    scan_pairs: int = 0

    def __post_init__(self):
        v = self.scan_pairs
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise parameter_error("expression_scan_pairs", "an integer >= 0 (0: model-to-scan pairs only)", repr(v),
                                  label="scan_pairs")


@dataclass(frozen=True)
class ModelFit:
    """Result of :func:`fit_shape_model`.

    Attributes
    ----------
    vertices : (n, 3) the fitted mesh ``pose(base + c D)`` in the surface's frame
    coefficients : (K,) ``c``
    pose : the similarity applied to the model (surface's frame)
    rms : final RMS point-to-plane residual of the kept pairs
    pairs : how many pairs were kept in the last round
    iterations : rounds run
    detail_sd : the pointwise deviation ``s`` of the detail field fitted beside the modes (eq. D1 of
        :mod:`.detailprior`; 0: none)
    detail_noise : the residuals' deviation ``sigma_n`` chosen with ``s`` by the evidence (eq. E1 of
        :mod:`.detailevidence`; 0: ``s`` was not chosen so)
    detail_weights : (n_part,) the field's deviation over the fitted part relative to ``s`` (``w`` of eq. D5 of
        :mod:`.fieldamplitude`); None: ``s`` everywhere
    """

    vertices: np.ndarray
    coefficients: np.ndarray
    pose: Similarity
    rms: float
    pairs: int
    iterations: int
    detail_sd: float = 0.0
    detail_noise: float = 0.0
    detail_weights: np.ndarray | None = None


def _pairs(X, normals, surface, dmax, cos_max, use, floor):
    """Kept model-to-scan pairs: indices, targets, scan normals (the tangent plane of the nearest scan
    vertex, as the non-rigid stage's point-to-plane term; one bounded tree query)."""
    U, N, dist, rim = surface.nearest_planes(X[use], True, dmax)
    ok = (~rim) & (dist <= dmax) & ((normals[use] * N).sum(1) >= cos_max)
    if ok.sum() > 10:
        ok &= dist <= max(3.0 * float(np.median(dist[ok])), floor)
    return use[ok], U[ok], N[ok]


def normal_equations(Jp: np.ndarray, Jc: np.ndarray, r: np.ndarray, lam: np.ndarray, c: np.ndarray):
    """The Gauss-Newton step's normal equations ``H dx = g`` of ``min ||[Jp Jc] dx + r||^2 + ||lam (c + dc)||^2``:
    ``H = [Jp Jc]^T [Jp Jc] + diag(0, lam^2)``, ``g = -[Jp Jc]^T r - (0, lam^2 c)``, built by blocks (the pose's
    ``Jp`` (p, P), the coefficients' ``Jc`` (p, K)) instead of as ``A^T A`` of the stacked least squares
    ``A = [[Jp, Jc], [0, diag(lam)]]``: the same matrix without the K prior rows in the product (a third of
    the regional stage's, :mod:`.expressionregions`) nor the stacked copy."""
    P = Jp.shape[1]
    H = np.empty((P + Jc.shape[1],) * 2)
    H[:P, :P] = Jp.T @ Jp
    H[:P, P:] = Jp.T @ Jc
    H[P:, :P] = H[:P, P:].T
    H[P:, P:] = Jc.T @ Jc
    H[np.arange(P, len(H)), np.arange(P, len(H))] += lam ** 2
    g = -np.concatenate([Jp.T @ r, Jc.T @ r + lam ** 2 * c])
    return H, g


def _solve(H: np.ndarray, g: np.ndarray, lb: np.ndarray, ub: np.ndarray, start=None) -> np.ndarray:
    """``argmin 1/2 x^T H x - g^T x`` within ``lb <= x <= ub`` for the normal equations of
    :func:`normal_equations` (the bounded least squares ``min ||A x - b||`` with ``H = A^T A``, ``g = A^T b``):
    unbounded, its Cholesky solve; bounded, the box QP (:func:`box_qp`; ``start``: its guess of the active
    bounds). The same minimiser as a bounded least squares on ``A`` (BVLS, used before), which solved a dense
    (q, q) least squares per active-set change: with the regional expression stage's several hundred unknowns
    (:mod:`.expressionregions`) that was most of an expression scan's time."""
    from scipy.linalg import cho_factor, cho_solve

    H = H + 1e-12 * np.trace(H) * np.eye(len(H))
    if np.all(np.isinf(lb)) and np.all(np.isinf(ub)):
        return cho_solve(cho_factor(H), g)
    return box_qp(H, g, lb, ub, start)


def check_box(lb: np.ndarray, ub: np.ndarray) -> None:
    """Refuse bounds with a lower above its upper (or NaN) in one line, before any work."""
    lb, ub = np.asarray(lb, float), np.asarray(ub, float)
    bad = np.flatnonzero(~(lb <= ub))
    if bad.size:
        raise parameter_error("bounds", "lower <= upper for every unknown",
                              f"lower {lb[bad[0]]:g} > upper {ub[bad[0]]:g} at unknown {bad[0]} ({bad.size} such)")


def box_qp(H: np.ndarray, g: np.ndarray, lb: np.ndarray, ub: np.ndarray, start=None, pivots: int = 25) -> np.ndarray:
    """``argmin 1/2 x^T H x - g^T x`` within ``lb <= x <= ub`` (H (q, q) positive definite; infinite bounds
    allowed), exactly.

    Block principal pivoting (Judice & Pires 1994, for bounds: Portugal, Judice & Vicente 1994): guess
    which bounds hold, solve the free unknowns with the others on their bounds (one LAPACK Cholesky of
    the free block), move every free unknown outside its bounds onto them and release every bound whose
    multiplier has the wrong sign; stop when none does (the KKT conditions hold, so this is the unique
    minimiser). A guess from the previous Gauss-Newton step (``start``) settles in one or two solves. Full
    exchanges may cycle: after ``pivots`` solves, or a singular block, DAQP (Arnström, Bemporad & Axehill
    2022, an exact dual active-set method; the package's box QP solver, :mod:`.boxqp`)
    solves it instead.

    Parameters
    ----------
    H : (q, q); g : (q,); lb, ub : (q,) bounds (infinite: free)
    start : ``(at_lower, at_upper)`` boolean (q,) guesses, or None (the bounds the unbounded minimiser violates)
    pivots : block pivots before DAQP takes over

    Raises
    ------
    SolverError
        DAQP reports no optimum (its exit flag is the status)
    """
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    check_box(lb, ub)
    tol = 1e-11 * max(1.0, float(np.abs(g).max()))
    try:
        if start is None:
            x = cho_solve(cho_factor(H), g)
            lo, hi = x < lb, x > ub
        else:
            lo, hi = start[0] & np.isfinite(lb), start[1] & ~start[0] & np.isfinite(ub)
        for _ in range(pivots):
            free = ~(lo | hi)
            x = np.where(lo, lb, np.where(hi, ub, 0.0))
            if free.any():
                fixed = np.flatnonzero(~free)
                f = np.flatnonzero(free)
                x[f] = cho_solve(cho_factor(H[np.ix_(f, f)]), g[f] - H[np.ix_(f, fixed)] @ x[fixed])
            grad = H @ x - g  # the bounds' multipliers: >= 0 at a lower bound, <= 0 at an upper one
            out_lo, out_hi = free & (x < lb), free & (x > ub)
            wrong_lo, wrong_hi = lo & (grad < -tol), hi & (grad > tol)
            if not (out_lo.any() or out_hi.any() or wrong_lo.any() or wrong_hi.any()):
                return x
            lo, hi = (lo & ~wrong_lo) | out_lo, (hi & ~wrong_hi) | out_hi
    except LinAlgError:
        pass
    return _daqp(H, g, lb, ub)


def _daqp(H, g, lb, ub) -> np.ndarray:
    """:func:`box_qp` by the package's DAQP box-QP solver (:func:`facebasis.geometry.boxqp.solve_box_qp`,
    which minimises ``1/2 x^T H x + g^T x``: hence ``-g``)."""
    from .boxqp import solve_box_qp

    return solve_box_qp(H, -np.asarray(g, np.float64), lb, ub).x


class DenseBasis:
    """A shape basis held as its displacements ``(K, n, 3)`` (the default of :func:`fit_shape_model`; a
    structured basis, e.g. :class:`.expressionregions.RegionalBasis`, offers the same three members)."""

    def __init__(self, deltas: np.ndarray):
        self.deltas = deltas
        self.shape = deltas.shape
        self._flat = deltas.reshape(len(deltas), -1)

    def combine(self, c: np.ndarray) -> np.ndarray:
        """``sum_k c_k D_k`` (n, 3)."""
        return (c @ self._flat).reshape(self.shape[1:])

    def normal_jacobian(self, idx: np.ndarray, RN: np.ndarray) -> np.ndarray:
        """``(p, K)``: ``D_k,idx_i . RN_i`` (the Jacobian of the point-to-plane residuals in ``c``)."""
        return np.einsum("kpj,pj->pk", self.deltas[:, idx, :], RN)


def fit_shape_model(base: np.ndarray, deltas: np.ndarray, surface, normals_of, h: float,
                    options: ModelFitOptions = ModelFitOptions(), sigma=None, bounds=None,
                    use: np.ndarray | None = None, c0=None, pose0: Similarity | None = None) -> ModelFit:
    """Fit ``pose(base + sum_k c_k deltas_k)`` to a scan surface (module docstring's energy).

    Parameters
    ----------
    base : (n, 3) the model's mean (template or the person's neutral), roughly aligned to ``surface``
    deltas : (K, n, 3) the basis, or a structured one with ``shape``, ``combine`` and ``normal_jacobian``
        (:class:`DenseBasis`'s members)
    surface : :class:`.nricp.ScanSurface` in ``base``'s frame
    normals_of : callable ``X (n, 3) -> (n, 3)`` unit vertex normals of the model's topology
    h : length unit (the template's median edge length)
    sigma : (K,) prior standard deviation of each coefficient (default 1)
    bounds : ``(lo, hi)`` arrays (K,) or scalars, or None (unbounded)
    use : vertices that may pair with the scan (default all; at most ``options.samples`` of them, a
        seeded sample, are used)
    c0 : (K,) start coefficients (default 0, or clipped into the bounds)
    pose0 : start pose (default the identity): with ``c0``, a fit continued from an earlier one

    Returns
    -------
    ModelFit
    """
    basis = deltas if hasattr(deltas, "normal_jacobian") else DenseBasis(np.asarray(deltas))
    K, n = basis.shape[0], base.shape[0]
    sigma = np.ones(K) if sigma is None else np.broadcast_to(np.asarray(sigma, float), (K,))
    lo, hi = (np.full(K, -np.inf), np.full(K, np.inf)) if bounds is None else (
        np.broadcast_to(np.asarray(bounds[0], float), (K,)), np.broadcast_to(np.asarray(bounds[1], float), (K,)))
    check_box(lo, hi)
    c = np.clip(np.zeros(K) if c0 is None else np.asarray(c0, float), lo, hi)
    use = np.arange(n) if use is None else np.asarray(use)
    back = ScanToModel(surface, use, options, h) if options.scan_pairs else None
    if len(use) > options.samples:  # a seeded sample of the vertices: the fit has few unknowns
        use = np.sort(use[np.random.default_rng(options.seed).choice(len(use), options.samples, replace=False)])
    npose = 7 if options.scale else 6
    pose = Similarity() if pose0 is None else pose0
    cos_max = np.cos(np.radians(options.normal_angle))
    rms, kept, it = np.inf, 0, 0
    X = pose.apply(base + basis.combine(c))
    seen = []  # the last CYCLE rounds' states at the final prior: (X, c, pose, rms of X's pairs)
    for it in range(1, options.iterations + 1):
        nX = normals_of(X)
        idx, Q, N = _pairs(X, nX, surface, options.max_distance * h, cos_max, use, 0.5 * h)
        if back is not None:  # eq. S1: the scan's points pull the nearest model vertices too
            idx, Q, N = (np.concatenate(a) for a in zip((idx, Q, N), back.pairs(X, nX)))
        kept = len(idx)
        if kept < npose + 3:
            break
        x = X[idx]
        r0 = ((x - Q) * N).sum(1)
        rms = float(np.sqrt(np.mean(r0 ** 2)))
        cen = x.mean(0)
        y = x - cen
        Jp = np.concatenate([np.cross(y, N), N, (y * N).sum(1, keepdims=True)], 1)[:, :npose]
        # d x_i / d c_k = s R D_k,i: the normal's component, (p, K)
        RN = pose.scale * (N @ pose.rotation)
        Jc = basis.normal_jacobian(idx, RN)
        w = 1.0 / np.sqrt(kept)
        t = 1.0 if options.prior_start is None else min(1.0, (it - 1) / max(1.0, options.iterations / 2 - 1))
        final = t >= 1.0  # the graduated prior has reached its final value
        mu = options.prior if final else options.prior_start * (options.prior / options.prior_start) ** t
        lam = np.sqrt(mu) * h / sigma
        seen = (seen + [(X, c, pose, rms, kept)])[-CYCLE:] if final else []
        H, g = normal_equations(w * Jp, w * Jc, w * r0, lam, c)
        lb = np.concatenate([np.full(npose, -np.inf), lo - c])
        ub = np.concatenate([np.full(npose, np.inf), hi - c])
        # the bounds that held after the last step: the bounded step's first guess
        start = (np.concatenate([np.zeros(npose, bool), c <= lo]), np.concatenate([np.zeros(npose, bool), c >= hi]))
        dx = _solve(H, g, lb, ub, start if it > 1 else None)
        R = _rotation_from_vector(dx[:3])
        s = 1.0 + dx[6] if options.scale else 1.0
        pose = pose.then(Similarity(s, R, cen - s * R @ cen + dx[3:6]))
        c = np.clip(c + dx[npose:], lo, hi)
        X_new = pose.apply(base + basis.combine(c))
        step = float(np.abs(X_new - X).max())
        X = X_new
        if step < options.tolerance * h and final:
            break
        # a limit cycle (module docstring): back where it was k rounds ago, exactly (within 1 % of this round's step:
        # a shrinking oscillation is not a cycle); its state with the smallest residual
        back_to = [k for k in range(2, len(seen) + 1)
                   if np.abs(X - seen[-k][0]).max() < min(options.tolerance * h, 0.01 * step)]
        if back_to:
            X, c, pose, rms, kept = min(seen[-back_to[0]:], key=lambda state: state[3])
            break
    return ModelFit(X, c, pose, rms, kept, it)
