"""Regional expression weights: a person's expression whose strength varies over the face.

The expression fit of :mod:`.shapemodel` explains an expression scan as ``R (B_0 + sum_k w_k E_k) + t``:
one weight per whole expression. A person's own expression is rarely the template's scaled as a
whole: a jaw that opens further on one side, a smile stronger at the mouth corners than at the
cheeks. What no combination of whole expressions expresses, the later stages must take from the
scan, and the part of it that runs along the skin (most of a jaw's or a smile's motion) they cannot
see (``reports/registration/README.md``). With ``R`` soft regions ``phi_r`` (a partition of unity,
``sum_r phi_r = 1`` at every vertex), each active expression gets one weight per region,

    x_i = R (B_0,i + sum_k sum_r (w_k + b_kr) phi_r(i) E_k,i) + t                      (eq. X1)

and the deviations ``b_kr`` from the whole fit's weights ``w_k`` are fitted by the same alternating
closest-point / bounded Gauss-Newton loop (:func:`.shapemodel.fit_shape_model`, the displacements
``phi_r E_k`` as its basis, the whole fit as its base), with the prior ``mu h^2 sum (b_kr / sigma)^2``
pulling every region back to the whole weight where the scan says nothing, and bounds keeping each
region's weight ``w_k + b_kr`` inside the whole weights' range. Equal deviations in every region are
a change of the whole weight, so the whole fit is the special case ``b = 0``.

The regions follow the rig, not a hand-drawn map: their centres are a farthest-point sample of the
vertices the expressions move (the union of the expressions' supports: motion above ``support``
times the largest), each region a Gaussian of the distance to its centre normalised over the centres
(``width`` times the spacing of the centres), so they are smooth and overlap: a strength that varies
smoothly over the face is a smooth combination of them, without seams. This is the region-based linear
face model of Tena et al. 2011 with soft regions, fitted to a scan.

References
----------
Tena J. R., De la Torre F., Matthews I. Interactive region-based linear 3D face models. SIGGRAPH 2011.
Blanz V., Vetter T. A morphable model for the synthesis of 3D faces. SIGGRAPH 1999 (segments of a
face model, blended at their borders).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import parameter_error
from .pairschedule import whole_expression_fit
from .shapemodel import ModelFit, ModelFitOptions, fit_shape_model


@dataclass(frozen=True)
class RegionOptions:
    """Options of :func:`fit_regional_expressions`.

    Attributes
    ----------
    count : number of soft regions (default 48); 0: whole expressions only, no regional stage. ICT persons
        of ``problems.bench_registration_rig`` (reports/registration/regions*): every scan's p95 <= 0.18 cm
        with 12 (0.235-0.237 with whole expressions), held-out ratio unchanged, about 1 s CPU more per scan.
        24 (reports/registration/regions24_seed*): a person's expression strength varies at a finer scale
        than 12 regions resolve (the ICT persons' jawOpen: the worst 5 % of its face vertices 0.24 cm off
        *along* the skin at the chin and lips after the regional fit, which no later stage sees; from the
        person's exact neutral still p95 0.146 cm), so the p95 of jawOpen was 0.13-0.18 cm depending on
        the neutral (seed 0: 0.134 with the fixed identity prior, 0.176 with the noise-level one):
        with 24, 0.094 cm. Cost (reports/registration/regions_factored_seed*, the basis held as its factors
        and the exact bounded step of :func:`.shapemodel.box_qp`): expression scans 3.5-4.2 s CPU median with
        24, 4.6-6.5 with 48 (jawOpen 7.9-11.1 s with DAQP as the bounded step, 6.4-7.3 s with the
        pivoting step; the Gauss-Newton normal matrix grows as (K R)^2); 48 lowered the worst p95 only
        where 24 left it (seed 0 detail jawOpen 0.183 -> 0.157, seed 1 ex03 0.167 -> 0.133, seed 1 detail
        ex03 0.187 -> 0.164), held-out ratios unchanged; with the pivoting step 48 costs 4.2-5.0 s CPU
        median, max 7.3 per expression scan (reports/registration/regions48_pivot_seed*, load 14-22), within
        10 s, and it buys p95 margin on the scans near the limit: the default since then
    width : the Gaussian width of a region in units of the centres' median spacing
    support : the regions are placed over the vertices whose largest expression motion is above this
        fraction of the largest motion of any vertex
    active : only expressions whose whole weight is above this get regional weights
    sigma : prior standard deviation of a region's deviation from the whole weight
    fit : the closest-point / Gauss-Newton loop's options (prior ``mu``, iterations, ...)
    """

    count: int = 48
    width: float = 0.6
    support: float = 0.05
    active: float = 0.02
    sigma: float = 2.0
    fit: ModelFitOptions = dataclasses.field(default_factory=lambda: ModelFitOptions(scale=False, prior=1e-3,
                                                                                     iterations=20))

    def __post_init__(self):
        if isinstance(self.count, bool) or not isinstance(self.count, (int, np.integer)) or self.count < 0:
            raise parameter_error("expression_regions", "an integer >= 0 (0: whole expressions only)",
                                  repr(self.count))
        if self.count == 1:
            raise parameter_error("expression_regions", "0 (whole expressions only) or at least 2 regions",
                                  "1 (one region is the whole expression)")
        for k in ("width", "sigma"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float, np.number)) and np.isfinite(v) and v > 0):
                raise parameter_error(f"region_{k}", "a positive number", repr(v), label=f"expression_regions.{k}")
        for k in ("support", "active"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float, np.number)) and 0 <= v < 1):
                raise parameter_error(f"region_{k}", "a number in [0, 1)", repr(v), label=f"expression_regions.{k}")


def soft_regions(V: np.ndarray, deltas: np.ndarray, count: int, width: float = 0.6, support: float = 0.05,
                 use: np.ndarray | None = None) -> np.ndarray:
    """A smooth partition of unity ``(R, n)`` over the vertices the expressions move.

    Parameters
    ----------
    V : (n, 3) the mesh (the person's neutral)
    deltas : (K, n, 3) its expressions
    count : R, the number of regions (at most the number of supporting vertices)
    width : Gaussian width in units of the median distance from a centre to its nearest other centre
    support : vertices moving more than this fraction of the largest motion carry the centres
    use : the vertices that may carry a centre (default all; a template's skin part)

    Returns
    -------
    (R, n) weights ``phi_r(i) >= 0`` with ``sum_r phi_r(i) = 1`` at every vertex
    """
    use = np.arange(len(V)) if use is None else np.asarray(use)
    motion = np.linalg.norm(deltas[:, use], axis=2).max(0)
    cand = use[motion > support * motion.max()] if motion.max() > 0 else use
    cand = cand if len(cand) >= count else use
    if len(np.unique(V[cand], axis=0)) < count:  # farthest-point sampling would repeat a centre (0/0 below)
        raise parameter_error("expression_regions", f"at most {len(np.unique(V[cand], axis=0))} regions (the "
                              "distinct vertices that may carry a centre)", str(count))
    P = V[cand]
    # farthest-point sample, from the vertex nearest the supports' centroid (deterministic)
    first = int(np.argmin(((P - P.mean(0)) ** 2).sum(1)))
    centres = [first]
    dist = np.linalg.norm(P - P[first], axis=1)
    for _ in range(count - 1):  # a loop over regions (a few), not vertices
        nxt = int(np.argmax(dist))
        centres.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(P - P[nxt], axis=1))
    C = P[centres]
    cc = np.linalg.norm(C[:, None] - C[None], axis=2) + np.diag(np.full(count, np.inf))
    s = width * float(np.median(cc.min(1)))
    d2 = ((V[None] - C[:, None]) ** 2).sum(2)  # (R, n)
    # normalised Gaussians, shifted by each vertex's nearest centre (no underflow far from every centre)
    g = np.exp(-(d2 - d2.min(0)) / (2.0 * s * s))
    return g / g.sum(0)


def expression_fit(base: np.ndarray, expressions: np.ndarray, surface, normals_of, h: float, options, use=None,
                   basis=None) -> tuple[ModelFit, str, tuple]:
    """The expression stage of a registration: the whole-expression fit (:func:`.pairschedule.whole_expression_fit`,
    weights in ``[0, options.expression_max]``; the scan pairs joining by ``options.expression_pairs_schedule``), then, with ``options.expression_regions.count`` regions,
    :func:`fit_regional_expressions` over :func:`soft_regions` of ``base`` (the person's neutral).

    Parameters
    ----------
    base : (n, 3) the person's neutral; expressions : (K, n, 3) in its frame
    surface, normals_of, h, use : as :func:`.shapemodel.fit_shape_model`
    options : :class:`.registration.RegistrationOptions` (``expression_fit``, ``expression_max``,
        ``expression_regions``)
    basis : the template's expression basis (:class:`.shapemodel.ShapeBasis`) for the weights' names

    Returns
    -------
    (fit, ``"expressions"``, the K weights' names)
    """
    top, reg = options.expression_max, options.expression_regions
    fit = whole_expression_fit(base, expressions, surface, normals_of, h, options.expression_fit, (0.0, top), use,
                               options.expression_pairs_schedule)[0]
    if reg.count:
        regions = soft_regions(base, expressions, reg.count, reg.width, reg.support, use)
        fit = fit_regional_expressions(fit, expressions, regions, surface, normals_of, h, reg, top, use)[0]
    K = len(expressions)
    names = tuple(basis.names) if basis is not None and len(basis.names) == K else tuple(f"e{k}" for k in range(K))
    return fit, "expressions", names


def fit_regional_expressions(whole: ModelFit, expressions: np.ndarray, regions: np.ndarray, surface, normals_of,
                             h: float, options: RegionOptions, upper: float, use=None) -> tuple[ModelFit, np.ndarray]:
    """Regional weights (eq. X1) on top of a whole-expression fit.

    Parameters
    ----------
    whole : the whole-expression fit (:func:`.shapemodel.fit_shape_model`; its ``vertices`` in the
        surface's frame, ``coefficients`` (K,) the weights ``w``, ``pose`` rigid)
    expressions : (K, n, 3) the expressions in the model's frame (before ``whole.pose``)
    regions : (R, n) :func:`soft_regions`
    surface, normals_of, h, use : as :func:`.shapemodel.fit_shape_model`
    options : :class:`RegionOptions`
    upper : upper bound of a weight (lower bound 0)

    Returns
    -------
    (ModelFit, (K, R) regional weights ``w_k + b_kr``); the fit's ``vertices`` and ``pose`` are the
    final ones (pose: the whole fit's followed by this stage's), its ``coefficients`` the whole weights
    """
    w = whole.coefficients
    R = len(regions)
    act = np.flatnonzero(w > options.active)
    W = np.repeat(w[:, None], R, 1)
    if not len(act):
        return whole, W
    rot = whole.pose.scale * whole.pose.rotation
    # basis phi_r E_k of the active expressions, in the surface's frame, never built: (len(act) * R) columns
    D = RegionalBasis(expressions[act] @ rot.T, np.asarray(regions, float))
    lo = np.repeat(-w[act], R)
    hi = np.repeat(upper - w[act], R)
    fit = fit_shape_model(whole.vertices, D, surface, normals_of, h, options.fit, sigma=options.sigma,
                          bounds=(lo, hi), use=use)
    W[act] += fit.coefficients.reshape(len(act), R)
    out = ModelFit(fit.vertices, w, whole.pose.then(fit.pose), fit.rms, fit.pairs, whole.iterations + fit.iterations)
    return out, W


class RegionalBasis:
    """The regional basis of eq. X1, ``D_(k,r),i = phi_r(i) E_k,i`` for K expressions and R regions, held
    as its two factors instead of its ``K R`` meshes (:func:`.shapemodel.fit_shape_model` takes it for an
    array ``(K R, n, 3)``, column ``k R + r``).

    The dense basis was ``K R n`` 3-vectors (ICT, 22 active expressions x 48 regions x 14062 vertices:
    350 MB, built per scan) and every round gathered its sampled rows; here a combination is one
    ``(K, R) @ (R, n)`` product and the Jacobian's rows ``a_ik phi_r(i)`` (``a_ik = E_k,i . n_i``) an
    outer product per sampled vertex: ``O(K (R + 3) n)`` and ``O(p K R)``, the latter the size of the
    Jacobian itself.

    Parameters
    ----------
    expressions : (K, n, 3) ``E_k`` (in the frame of the fit's base mesh)
    regions : (R, n) ``phi_r`` (:func:`soft_regions`)
    """

    def __init__(self, expressions: np.ndarray, regions: np.ndarray):
        self.expressions, self.regions = expressions, regions
        K, n = expressions.shape[:2]
        self.shape = (K * len(regions), n, 3)

    def combine(self, c: np.ndarray) -> np.ndarray:
        """``sum_kr c_kr phi_r E_k`` (n, 3) for c (K R,)."""
        Wv = c.reshape(len(self.expressions), len(self.regions)) @ self.regions  # (K, n) per-vertex weights
        return np.einsum("kn,knj->nj", Wv, self.expressions)

    def normal_jacobian(self, idx: np.ndarray, RN: np.ndarray) -> np.ndarray:
        """``(p, K R)``: ``phi_r(idx_i) E_k,idx_i . RN_i``."""
        a = np.einsum("kpj,pj->pk", self.expressions[:, idx, :], RN)
        return (a[:, :, None] * self.regions[:, idx].T[:, None, :]).reshape(len(idx), -1)
