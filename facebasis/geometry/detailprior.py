"""The identity fit with a prior on the detail outside the identity space (a smooth field along the normals).

A person's neutral is rarely exactly in a template's identity space (ICT-FaceKit's 100 modes, or
fewer): a fit of the modes alone (:func:`.shapemodel.fit_shape_model`) then uses the modes to
explain that detail too, and since the modes also move vertices *along* the surface, the fitted
correspondence slides. No later stage can undo it (a scan shows where the surface is, not where a
point lies on it). Measured on the ICT rig benchmark's ``detail`` person (a smooth field along the
normals, up to 2.5 mm; seed 0, 100 modes), 0.051 cm median of the 0.054 cm left after the normal
stage is along the surface, and the normal stage recovers the normal part almost completely
(oracle: 0.001 cm); ``problems/bench_registration_rig.py``, ``reports/registration/detail/``.

So the neutral is fitted jointly in the identity modes ``D_k`` and a smooth normal field ``f``,

    x = pose(T + sum_k c_k D_k + f m),   f = sum_j e_j phi_j,
    c_k ~ N(0, 1),   e_j ~ N(0, sigma_j^2),   sigma_j = s sqrt(2 pi) l exp(-l^2 lambda_j / 4)   (eq. D1)

``phi_j, lambda_j`` the first eigenpairs of the template's cotangent Laplace-Beltrami operator
(generalised, with the lumped mass: ``K phi = lambda M phi``, ``phi^T M phi = 1``), ``m`` the
template's vertex normals: (D1) is the spectral form of a Gaussian process on the surface with a
squared-exponential covariance of length ``l`` and pointwise standard deviation ``s`` (Solin &
Sarkka 2020, eq. 7-8; the manifold-harmonics basis of Vallet & Levy 2008). The MAP of (D1) under
the point-to-plane data term is the same alternating Gauss-Newton fit, with ``K + J`` columns and
the prior of each one (:func:`.shapemodel.fit_shape_model` with ``sigma``): a shape that a smooth
normal field explains more cheaply than the modes is left to the field instead of sliding the
vertices. ``s`` is set from the scan (empirical Bayes): ``amplitude`` times the RMS of the normal
offsets a modes-only fit leaves (:mod:`.normalstage` on it). A scan within the space leaves offsets
of the order of its noise, so the prior is weak and the fit is the modes-only one (ICT in-space
person: 0.0163 -> 0.0165 cm median); with detail, 0.054 -> 0.040 cm (seed 0).

**The coefficients' prior at the noise level** (eq. D2). The fit's energy weighs the prior by a fixed
``mu`` (:class:`.shapemodel.ModelFitOptions`, 1e-4: strong enough to find the basin from the
template). As a Gaussian MAP, a point-to-plane residual of independent noise ``sigma_n`` over ``p``
pairs and ``c ~ N(0, I)`` call for

    mu h^2 = sigma_n^2 / p                                                          (eq. D2)

with ``sigma_n`` the residual's RMS: about 1.5e-6 on a 0.2 mm-noise ICT scan (~2900 pairs, h 0.30
cm), so the fixed prior is ~60x too strong there. It shrinks the coefficients, which the surface
alone cannot restore where the modes move points *along* it (the back of the head, the neck): on the
ICT rig benchmark's in-space person (seed 1, 100 modes) the registered neutral lay 0.085 cm (median)
off on the head and neck, 0.084 of it along the surface, coefficients 0.24 off (RMS); the held-out
error of the rig built from the registered scans was 1.8x the exact examples' (its excess was the
neutral's). So the fit continues from the first one with ``mu`` of eq. D2 (never stronger than the
fixed one, :func:`noise_prior`): head and neck 0.019 cm, coefficients 0.07. A scan with detail outside
the space leaves a larger residual, hence a stronger prior (ICT detail persons 3.5e-6 .. 7e-6). A
weak prior from the template on, instead of continuing, lost the basin on those persons (face 0.16
cm median with ``mu`` 1e-6 throughout). Only the joint fit takes it: eq. D2 holds when the model
explains all but noise, and without the field a modes-only fit with a weak prior hands the detail to
the modes (tests' default-face person with a field: p95 0.12 -> 0.20 cm).

References
----------
Blanz V., Vetter T. A morphable model for the synthesis of 3D faces. SIGGRAPH 1999.
Vallet B., Levy B. Spectral geometry processing with manifold harmonics. Eurographics 2008.
Solin A., Sarkka S. Hilbert space methods for reduced-rank Gaussian process regression.
Statistics and Computing 30, 2020.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError, parameter_error
from .laplacian import cotangent_laplacian, lumped_mass
from .shapemodel import ModelFit, ModelFitOptions, fit_shape_model


#: the noise-level prior (eq. D2) is never weaker than this fraction of the fixed one (a noise-free scan
#: leaves no residual: the modes the surface cannot see would be unconstrained)
NOISE_PRIOR_FLOOR = 1e-3


def noise_prior(fit: ModelFit, h: float, ceiling: float) -> float:
    """``mu`` of :mod:`.shapemodel`'s energy at which the coefficients' prior weighs as their Gaussian
    ``N(0, sigma^2)`` against the residuals ``fit`` leaves, taken as independent Gaussian noise of
    their RMS (eq. D2): ``mu h^2 = rms^2 / pairs``, within ``[NOISE_PRIOR_FLOOR ceiling, ceiling]``.

    Parameters
    ----------
    fit : a fit of the modes (its ``rms`` point-to-plane residual over ``pairs`` kept pairs)
    h : the fit's length unit (median edge length)
    ceiling : the fixed ``mu`` the fit ran with (the noise-level prior is never stronger)
    """
    mu = fit.rms ** 2 / (max(fit.pairs, 1) * h ** 2)
    return float(np.clip(mu, NOISE_PRIOR_FLOOR * ceiling, ceiling))


@dataclass(frozen=True)
class DetailPriorOptions:
    """Options of :class:`DetailPrior` (eq. D1 of the module docstring).

    Attributes
    ----------
    modes : how many Laplace-Beltrami eigenfunctions carry the field (0: no detail prior, the
        modes-only fit)
    length : the field's correlation length ``l``, as a fraction of the fitted part's bounding-box
        diagonal (0.04: 1.9 cm on ICT's head, the scale of a cheek or a brow)
    amplitude : ``s`` is this times the RMS of the normal offsets that a modes-only fit leaves
    noise_prior : the joint fit continues from the modes-only fit (the fixed prior
        ``ModelFitOptions.prior``, which finds the basin from the template) with the priors at the noise
        level of that fit's residual (eq. D2, :func:`noise_prior`). False: the fixed prior, the joint fit
        from the template (the previous pipeline). No effect with ``modes == 0`` (no field to take what
        the modes cannot express, which a weak prior would hand to the modes)
    unseen : after the normal stage, the vertices without scan surface (the sockets, holes) get the fit's
        modes plus the seen detail's extension in 3D (:mod:`.unseen`, eq. U1). False: what the field's
        eigenfunctions and the normal stage put there (the previous pipeline). Acts only when the stage
        after the fits is the normal one alone (``after_model="normal"``, the default): after the free
        non-rigid ICP the offsets are not along the normals
    unseen_samples : at most this many seen vertices condition that extension (a seeded sample)
    """

    modes: int = 150
    length: float = 0.04
    amplitude: float = 2.0
    noise_prior: bool = True
    unseen: bool = True
    unseen_samples: int = 2000

    def __post_init__(self):
        if isinstance(self.modes, bool) or not (isinstance(self.modes, (int, np.integer)) and self.modes >= 0):
            raise parameter_error("detail_modes", "an integer >= 0", repr(self.modes), label="detail.modes")
        for k in ("length", "amplitude"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                raise InputError(f"detail.{k}: expected a positive number, found {v!r}")
        for k in ("noise_prior", "unseen"):
            if not isinstance(getattr(self, k), (bool, np.bool_)):
                raise InputError(f"detail.{k}: expected True or False, found {getattr(self, k)!r}")
        u = self.unseen_samples
        if isinstance(u, bool) or not (isinstance(u, (int, np.integer)) and u >= 1):
            raise InputError(f"detail.unseen_samples: expected an integer >= 1, found {u!r}")


class DetailPrior:
    """The Laplace-Beltrami eigenbasis of a template's part, built once per template (eq. D1).

    Parameters
    ----------
    V : (n, 3) the part's vertices (the template's skin), F : (m, 3) its triangles
    options : :class:`DetailPriorOptions` (``modes >= 1``)

    Attributes
    ----------
    eigenvalues : (J,) ``lambda_j`` (1 / length^2), ascending
    fields : (J, n, 3) ``phi_j m``: each eigenfunction along the template's unit normals
    length : ``l`` in the template's units
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, options: DetailPriorOptions = DetailPriorOptions()):
        from .nricp import NonRigidICP

        self.options = options
        n = len(V)
        self.length = options.length * float(np.linalg.norm(V.max(0) - V.min(0)))
        K = cotangent_laplacian(V, F, clip_negative=True)
        mass = lumped_mass(V, F)
        mass = np.maximum(mass, 1e-9 * mass.max())
        k = int(min(options.modes, n - 2))
        # shift-invert about a small negative shift: the k smallest eigenpairs; a fixed start vector
        # (ARPACK's default is random) keeps the result deterministic
        lam, phi = spla.eigsh(sp.csc_matrix(K), k, M=sp.diags(mass).tocsc(), sigma=-1e-2 / self.length ** 2,
                              which="LM", v0=np.ones(n))
        order = np.argsort(lam)
        self.eigenvalues = np.maximum(lam[order], 0.0)
        m = NonRigidICP(F, n).vertex_normals(V)
        self.fields = phi[:, order].T[:, :, None] * m[None]

    def sigma(self, s: float) -> np.ndarray:
        """(J,) prior standard deviations ``sigma_j`` of eq. D1 for a pointwise deviation ``s``."""
        ell = self.length
        return s * np.sqrt(2.0 * np.pi) * ell * np.exp(-ell ** 2 * self.eigenvalues / 4.0)


def offset_rms(offset: np.ndarray, no_surface: np.ndarray) -> float:
    """RMS of the normal offsets (n,) of the vertices that found scan surface (0 if none did)."""
    d = offset[~no_surface]
    return float(np.sqrt(np.mean(d ** 2))) if len(d) else 0.0


def fit_with_detail(plain: ModelFit, prior: DetailPrior, base: np.ndarray, deltas: np.ndarray, surface,
                    normals_of, h: float, s: float, options: ModelFitOptions = ModelFitOptions(),
                    start: ModelFit | None = None) -> ModelFit:
    """The joint fit of eq. D1 on one part, after a modes-only fit ``plain`` of the same part.

    Parameters
    ----------
    plain : the modes-only fit (:func:`.shapemodel.fit_shape_model`), returned unchanged if ``s <= 0``
    prior : :class:`DetailPrior` of this part
    base : (n, 3) the part's template vertices, deltas : (K, n, 3) the identity modes on the part
    surface : :class:`.nricp.ScanSurface` in ``base``'s frame
    normals_of : unit vertex normals ``(n, 3) -> (n, 3)`` of the part's topology
    h : length unit (median edge length)
    s : the field's pointwise standard deviation (template units)

    Returns
    -------
    ModelFit
        vertices ``pose(T + c D + f m)`` (detail included), the K identity coefficients, iterations
        of both fits
    """
    if not s > 0:
        return plain
    K = len(deltas)
    sigma = np.concatenate([np.ones(K), prior.sigma(s)])
    c0 = pose0 = None
    if start is not None:  # continued from a fit of the modes (its coefficients, the field at zero)
        c0, pose0 = np.concatenate([start.coefficients, np.zeros(len(prior.fields))]), start.pose
    fit = fit_shape_model(base, np.concatenate([deltas, prior.fields]), surface, normals_of, h, options, sigma=sigma,
                          c0=c0, pose0=pose0)
    return ModelFit(fit.vertices, fit.coefficients[:K], fit.pose, fit.rms, fit.pairs,
                    plain.iterations + fit.iterations, float(s))


def identity_fit_with_detail(reg, plain: ModelFit, P: np.ndarray, surface, h: float) -> ModelFit:
    """The identity fit of a :class:`.registration.Registration` with the detail prior
    (``reg.options.detail``): the normal offsets the modes-only fit ``plain`` leaves (:mod:`.normalstage`)
    set ``s``, then :func:`fit_with_detail` on the template's skin (a template of several parts: the
    other parts follow the joint fit's pose and coefficients). ``plain`` unchanged with ``modes == 0``.
    The eigenbasis is built at the first call and kept on ``reg``.
    """
    from .normalstage import normal_displacement

    opts = reg.options.detail
    if opts.modes == 0:
        return plain
    fo = reg.options.identity_fit
    if opts.noise_prior:  # eq. D2: the coefficients' prior weighed against the residual the fit leaves
        fo = dataclasses.replace(fo, prior=noise_prior(plain, h, fo.prior), prior_start=None)
    out = normal_displacement(plain.vertices, reg.nricp.vertex_normals(plain.vertices), reg.nricp.L, surface, h,
                              reg.options.normal_stage, use=reg.skin)
    part = slice(None) if reg.skin is None else reg.skin
    icp = reg.nricp if reg.skin is None else reg._skin_icp
    if getattr(reg, "_detail_prior", None) is None:
        reg._detail_prior = DetailPrior(reg.V[part], icp.F, opts)
    D = reg.identity.deltas
    fit = fit_with_detail(plain, reg._detail_prior, P[part], D[:, part], surface, icp.vertex_normals, h,
                          opts.amplitude * offset_rms(out.offset, out.no_surface), fo,
                          start=plain if opts.noise_prior else None)
    if reg.skin is None or fit is plain:
        return fit
    X = fit.pose.apply(P + (fit.coefficients @ D.reshape(len(D), -1)).reshape(P.shape))
    X[reg.skin] = fit.vertices
    return ModelFit(X, fit.coefficients, fit.pose, fit.rms, fit.pairs, fit.iterations, fit.detail_sd)


__all__ = ["DetailPrior", "DetailPriorOptions", "NOISE_PRIOR_FLOOR", "fit_with_detail", "identity_fit_with_detail",
           "noise_prior", "offset_rms"]
