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

**The field's basis** (eq. D3). The spectral form (D1) keeps the first ``J`` eigenfunctions only; 150 of them
hold 82% of the prior's variance on ICT's head (``sigma_150 / sigma_1`` = 0.43: the spectrum is cut where it
is still large), and what the basis cannot carry goes to the modes again. Projected onto the first 150 / 300
eigenfunctions, the ICT rig benchmark's detail fields leave 0.014-0.019 / 0.006-0.010 cm RMS on the seen
vertices (seeds 0-2); 300 eigenpairs cost 10 s CPU (ARPACK shift-invert). The default basis is instead the
Nystrom form of the same squared-exponential covariance in 3D (Williams & Seeger 2001): inducing points ``z``
one per cell of ``INDUCING_CELL l`` (vertex clustering of the template), ``K_zz = U Lambda U^T`` and

    f = sum_k e_k b_k,   b_k(x) = k(x, z) u_k / sqrt(lambda_k),   e_k ~ N(0, s^2),   k(x, y) = exp(-|x - y|^2 / (2 l^2))
                                                                                                   (eq. D3)

over the ``J`` largest ``lambda_k``: 300 functions hold 96.5% of the pointwise variance (median vertex) and
leave 0.004-0.006 cm of the benchmark's fields, for 1.5 s CPU (one dense eigendecomposition of ~1700
inducing points on ICT). 3D distance, not geodesic: the covariance the unseen vertices' extension uses
(:mod:`.unseen`, eq. U1); where two surfaces nearly touch they share detail (spectral 150 -> kernel 300 on ICT:
``reports/registration/README.md``, sixth round). The functions are scaled by ``w(x)`` (:mod:`.fieldamplitude`).

**The joint fit's data.** The modes-only fit pairs a seeded sample of 5000 vertices (~2800 kept pairs on an
ICT scan), enough for 100 modes but thin for 400 unknowns; the joint fit pairs every vertex of the part
(``fit_samples``; ~8000 pairs) and, its data term being a mean over them, takes eq. D2 with its own pair count
(the modes-only fit's kept share of its candidates). Same persons, kernel 300: every vertex 0.0319 -> 0.0273
(seed 0), 0.0323 -> 0.0254 (seed 1), 0.0423 -> 0.0349 (seed 3), in-space 0.0148 -> 0.0107, 0.0168 -> 0.0130;
with eq. D2 for the pair count (the default) 0.0266, 0.0212, 0.0342, in-space 0.0114, 0.0133. In-space seed 3 is
worse, 0.0143 -> 0.0175 (the kernel basis alone too): at ``s`` from the modes-only fit's offsets, which for a person in
the space are that fit's shrinkage more than detail, the richer field takes some of the modes' part. Twenty rounds
settle it (40: within 0.0002 cm). Held as :class:`ModesAndField`, the joint fit costs 2.5 s CPU (4.7 s dense).

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
Williams C. K. I., Seeger M. Using the Nystrom method to speed up kernel machines. NIPS 2001.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError, parameter_error
from .laplacian import cotangent_laplacian, lumped_mass
from .fieldamplitude import AMPLITUDE_MAPS, refit_on_field, split_rounds, weighted_prior
from .fieldnormals import fit_along_person_normals, person_normals
from .shapemodel import DenseBasis, ModelFit, ModelFitOptions, fit_shape_model
from .unseen import se_kernel


#: the noise-level prior (eq. D2) is never weaker than this fraction of the fixed one (a noise-free scan
#: leaves no residual: the modes the surface cannot see would be unconstrained)
NOISE_PRIOR_FLOOR = 1e-3
#: the kernel basis' inducing points: one per cell of this many lengths ``l`` (eq. D3)
INDUCING_CELL = 0.6
#: at most this many inducing points (a length short against the part's size gets a longer cell: the
#: kernel matrix between them is dense, 128 MB at 4000)
MAX_INDUCING = 4000
#: the field's bases (:class:`DetailPriorOptions`.basis)
BASES = ("kernel", "spectral")
#: the field's directions (:class:`DetailPriorOptions`.field_normals; eq. D4)
FIELD_NORMALS = ("person", "template")
#: ``amplitude`` ``"auto"`` with the fixed coefficient prior (``noise_prior`` False, the previous pipeline) is the previous
#: rule with this amplitude: the evidence's noise level sets eq. D2's prior, which the fixed prior does not take (it is
#: stronger than the noise on purpose, to find the basin from the template), and the evidence's ``s`` beside the fixed
#: prior was worse (the tests' default-face person with a field: median 0.0329 vs 0.0203 cm)
AUTO_FIXED_PRIOR = 2.0


def noise_prior(fit: ModelFit, h: float, ceiling: float, pairs: float | None = None) -> float:
    """``mu`` of :mod:`.shapemodel`'s energy at which the coefficients' prior weighs as their Gaussian
    ``N(0, sigma^2)`` against the residuals ``fit`` leaves, taken as independent Gaussian noise of
    their RMS (eq. D2): ``mu h^2 = rms^2 / pairs``, within ``[NOISE_PRIOR_FLOOR ceiling, ceiling]``.

    Parameters
    ----------
    fit : a fit of the modes (its ``rms`` point-to-plane residual over ``pairs`` kept pairs)
    h : the fit's length unit (median edge length)
    ceiling : the fixed ``mu`` the fit ran with (the noise-level prior is never stronger)
    pairs : the pairs of the fit the prior is for (default ``fit.pairs``): the energy's data term is a mean
        over them, so the same noise weighs ``1 / pairs`` per pair
    """
    p = fit.pairs if pairs is None else pairs
    mu = fit.rms ** 2 / (max(p, 1) * h ** 2)
    return float(np.clip(mu, NOISE_PRIOR_FLOOR * ceiling, ceiling))


@dataclass(frozen=True)
class DetailPriorOptions:
    """Options of :class:`DetailPrior` (eq. D1 of the module docstring).

    Attributes
    ----------
    modes : how many basis functions carry the field (0: no detail prior, the modes-only fit)
    basis : ``"kernel"``: the Nystrom basis of the squared-exponential covariance in 3D (eq. D3, the
        default); ``"spectral"``: the first Laplace-Beltrami eigenfunctions (eq. D1, the previous pipeline)
    length : the field's correlation length ``l``, as a fraction of the fitted part's bounding-box
        diagonal (0.04: 1.9 cm on ICT's head, the scale of a cheek or a brow)
    amplitude : ``"auto"`` (the default): ``s``, and the noise level of eq. D2's prior, maximise the evidence of
        the joint model linearised at the modes-only fit (:mod:`.detailevidence`, eq. E1); with ``noise_prior``
        False, :data:`AUTO_FIXED_PRIOR`. A number: ``s`` is this times the RMS of the normal offsets that a
        modes-only fit leaves (2: the previous default), eq. D2 at that fit's residual
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
    fit_samples : at most this many of the part's vertices (a seeded sample) pair with the scan in the joint fit
        that continues from the modes-only fit (``noise_prior``; the modes-only fit, and the joint fit from the
        template with the fixed prior, keep ``ModelFitOptions.samples``, 5000): the field's functions need more data
        than the modes (default: every vertex of ICT's 14062; with 5000, ~2800 kept pairs for 400 unknowns)
    field_normals : the directions the field displaces along (``m`` of eq. D1): ``"person"`` (the default), the
        normals of the person's modes mesh ``T + sum_k c_k D_k`` (eq. D4: the modes-only fit's until the joint fit
        has converged once, then a few more rounds along its own; with the fixed prior the modes-only fit's
        throughout); ``"template"``: the template's (the previous pipeline)
    amplitude_map : ``"field"`` (default): the field's deviation ``s w(x)``, ``w`` from the modes-only fit's residuals, then
        from the joint fit's field (:mod:`.fieldamplitude`, eqs. D5-D6); ``"residual"``: eq. D5; ``"uniform"``: ``s``
    fit_iterations : rounds of the joint fit at most when it continues from the modes-only fit (``noise_prior``;
        it settles in fewer: 20 and 40 gave the same ICT neutrals within 0.0002 cm RMS); from the template, and
        the modes-only fit, ``ModelFitOptions.iterations``
    """

    modes: int = 300
    length: float = 0.04
    amplitude: float | str = "auto"
    noise_prior: bool = True
    unseen: bool = True
    unseen_samples: int = 2000
    basis: str = "kernel"
    fit_samples: int = 100_000
    fit_iterations: int = 20
    field_normals: str = "person"
    amplitude_map: str = "field"

    def __post_init__(self):
        if isinstance(self.modes, bool) or not (isinstance(self.modes, (int, np.integer)) and self.modes >= 0):
            raise parameter_error("detail_modes", "an integer >= 0", repr(self.modes), label="detail.modes")
        v = self.length
        if not (isinstance(v, (int, float, np.floating)) and not isinstance(v, bool) and np.isfinite(v) and v > 0):
            raise InputError(f"detail.length: expected a positive number, found {v!r}")
        a = self.amplitude
        if not (isinstance(a, str) and a == "auto") and not (isinstance(a, (int, float, np.integer, np.floating))
                                                             and not isinstance(a, bool) and np.isfinite(a) and a > 0):
            raise parameter_error("detail_amplitude", "'auto' or a positive number", repr(a), label="detail.amplitude")
        for k in ("noise_prior", "unseen"):
            if not isinstance(getattr(self, k), (bool, np.bool_)):
                raise InputError(f"detail.{k}: expected True or False, found {getattr(self, k)!r}")
        for k in ("unseen_samples", "fit_samples", "fit_iterations"):
            u = getattr(self, k)
            if isinstance(u, bool) or not (isinstance(u, (int, np.integer)) and u >= 1):
                raise InputError(f"detail.{k}: expected an integer >= 1, found {u!r}")
        for k, ok in (("field_normals", FIELD_NORMALS), ("amplitude_map", AMPLITUDE_MAPS), ("basis", BASES)):
            if getattr(self, k) not in ok:
                raise parameter_error(f"detail_{k}", f"one of {', '.join(ok)}", repr(getattr(self, k)), label=f"detail.{k}")


class DetailPrior:
    """The detail field's basis on a template's part, built once per template: the Nystrom basis of eq. D3
    (``options.basis == "kernel"``) or the Laplace-Beltrami eigenbasis of eq. D1 (``"spectral"``).

    Parameters
    ----------
    V : (n, 3) the part's vertices (the template's skin), F : (m, 3) its triangles
    options : :class:`DetailPriorOptions` (``modes >= 1``)

    Attributes
    ----------
    eigenvalues : (J,) spectral: ``lambda_j`` (1 / length^2), ascending; kernel: the inducing points' kernel
        matrix's ``lambda_k``, descending
    phi : (J, n) the basis functions (``phi_j`` spectral, ``b_k`` kernel), normals : (n, 3) the template's unit
        normals; ``fields`` (J, n, 3) ``phi m``: each function along them (formed on demand)
    scales : (J,) each function's prior standard deviation for ``s = 1`` (:meth:`sigma`)
    length : ``l`` in the template's units
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, options: DetailPriorOptions = DetailPriorOptions()):
        from .nricp import NonRigidICP

        self.options = options
        self.length = options.length * float(np.linalg.norm(V.max(0) - V.min(0)))
        build = _kernel_basis if options.basis == "kernel" else _spectral_basis
        phi, self.eigenvalues, self.scales = build(V, F, self.length, int(options.modes))
        self.phi, self.normals = phi, NonRigidICP(F, len(V)).vertex_normals(V)

    @property
    def fields(self) -> np.ndarray:
        """(J, n, 3) each basis function along the template's unit normals."""
        return self.phi[:, :, None] * self.normals[None]

    def sigma(self, s: float) -> np.ndarray:
        """(J,) prior standard deviations ``sigma_j`` of eq. D1 / D3 for a pointwise deviation ``s``."""
        return s * self.scales


def _spectral_basis(V: np.ndarray, F: np.ndarray, ell: float, modes: int):
    """The first ``modes`` eigenfunctions ``(J, n)`` of ``K phi = lambda M phi``, their ``lambda`` and the
    scales ``sqrt(2 pi) l exp(-l^2 lambda / 4)`` of eq. D1."""
    n = len(V)
    K = cotangent_laplacian(V, F, clip_negative=True)
    mass = lumped_mass(V, F)
    mass = np.maximum(mass, 1e-9 * mass.max())
    k = int(min(modes, n - 2))
    # shift-invert about a small negative shift: the k smallest eigenpairs; a fixed start vector
    # (ARPACK's default is random) keeps the result deterministic
    lam, phi = spla.eigsh(sp.csc_matrix(K), k, M=sp.diags(mass).tocsc(), sigma=-1e-2 / ell ** 2, which="LM",
                          v0=np.ones(n))
    order = np.argsort(lam)
    lam = np.maximum(lam[order], 0.0)
    return phi[:, order].T, lam, np.sqrt(2.0 * np.pi) * ell * np.exp(-ell ** 2 * lam / 4.0)


def _kernel_basis(V: np.ndarray, F: np.ndarray, ell: float, modes: int, chunk: int = 2048):
    """The Nystrom basis ``(J, n)`` of eq. D3 (its ``J <= modes`` functions of the largest ``lambda_k``, the
    ones above 1e-10 of the largest), those ``lambda_k`` and unit scales. Inducing points: the first vertex
    of each occupied cell of ``INDUCING_CELL l`` (deterministic); ``k(x, z)`` in blocks of ``chunk`` vertices."""
    from scipy.linalg import eigh

    cell = INDUCING_CELL * ell
    while True:                          # at most MAX_INDUCING points: a longer cell for a short length
        key = np.floor((V - V.min(0)) / cell).astype(np.int64)
        Z = V[np.sort(np.unique(key, axis=0, return_index=True)[1])]
        if len(Z) <= MAX_INDUCING:
            break
        cell *= np.sqrt(len(Z) / MAX_INDUCING)
    m = len(Z)
    J = int(min(modes, m))
    lam, U = eigh(se_kernel(Z, Z, ell), subset_by_index=[m - J, m - 1])
    lam, U = lam[::-1], U[:, ::-1]
    keep = lam > 1e-10 * lam[0]
    W = U[:, keep] / np.sqrt(lam[keep])
    B = np.concatenate([se_kernel(V[i:i + chunk], Z, ell) @ W
                        for i in range(0, len(V), chunk)])  # a loop over blocks of vertices (memory), not vertices
    return B.T, lam[keep], np.ones(int(keep.sum()))


class ModesAndField:
    """The identity modes ``D (K, n, 3)`` and the field's functions ``phi (J, n)`` along the normals ``m (n, 3)`` as
    one structured basis of ``K + J`` columns (:class:`.shapemodel.DenseBasis`'s members), never the dense
    ``(K + J, n, 3)`` array: the point-to-plane Jacobian of the field is ``phi_j(i) (m_i . RN_i)``, one product per
    pair and function instead of three, and no (K + J, p, 3) gather per round (with 300 functions and all of ICT's
    vertices as candidates, 100 MB)."""

    def __init__(self, deltas: np.ndarray, phi: np.ndarray, normals: np.ndarray):
        self.modes, self.phi, self.normals = DenseBasis(np.asarray(deltas)), phi, normals
        self.shape = (len(deltas) + len(phi),) + np.shape(deltas)[1:]

    def combine(self, c: np.ndarray) -> np.ndarray:
        """``sum_k c_k D_k + (sum_j c_{K+j} phi_j) m`` (n, 3)."""
        K = self.modes.shape[0]
        return self.modes.combine(c[:K]) + (c[K:] @ self.phi)[:, None] * self.normals

    def normal_jacobian(self, idx: np.ndarray, RN: np.ndarray) -> np.ndarray:
        """``(p, K + J)``: the modes' ``D_k,idx_i . RN_i`` and the field's ``phi_j(idx_i) (m_idx_i . RN_i)``."""
        mn = (self.normals[idx] * RN).sum(1)
        return np.concatenate([self.modes.normal_jacobian(idx, RN), self.phi[:, idx].T * mn[:, None]], 1)


def offset_rms(offset: np.ndarray, no_surface: np.ndarray) -> float:
    """RMS of the normal offsets (n,) of the vertices that found scan surface (0 if none did)."""
    d = offset[~no_surface]
    return float(np.sqrt(np.mean(d ** 2))) if len(d) else 0.0


def fit_with_detail(plain: ModelFit, prior: DetailPrior, base: np.ndarray, deltas: np.ndarray, surface,
                    normals_of, h: float, s: float, options: ModelFitOptions = ModelFitOptions(),
                    start: ModelFit | None = None, field_normals: np.ndarray | None = None) -> ModelFit:
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
    start : a fit of the modes the joint fit continues from (its coefficients, the field at zero)
    field_normals : (n, 3) unit normals the field ``f`` displaces along (``m`` of eq. D1); default the
        template's (``prior.normals``). :func:`identity_fit_with_detail` passes the modes-only fit's (eq. D4 of
        :mod:`.fieldnormals`); continued from ``start``, the joint fit's own after half its rounds

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
        c0, pose0 = np.concatenate([start.coefficients, np.zeros(len(prior.phi))]), start.pose
    if field_normals is None or start is None:  # the template's normals, or one pass from the template
        m = prior.normals if field_normals is None else field_normals
        fit = fit_shape_model(base, ModesAndField(deltas, prior.phi, m), surface, normals_of, h, options, sigma=sigma,
                              c0=c0, pose0=pose0)
    else:  # eq. D4 (.fieldnormals): along the modes-only fit's normals, then the joint fit's after half the rounds
        fit = fit_along_person_normals(base, deltas, lambda m: ModesAndField(deltas, prior.phi, m), field_normals,
                                       surface, normals_of, h, options, sigma, c0, pose0)
    return ModelFit(fit.vertices, fit.coefficients[:K], fit.pose, fit.rms, fit.pairs,
                    plain.iterations + fit.iterations, float(s))


def identity_fit_with_detail(reg, plain: ModelFit, P: np.ndarray, surface, h: float) -> ModelFit:
    """The identity fit of a :class:`.registration.Registration` with the detail prior
    (``reg.options.detail``): the normal offsets the modes-only fit ``plain`` leaves (:mod:`.normalstage`)
    set ``s``, then :func:`fit_with_detail` on the template's skin (a template of several parts: the
    other parts follow the joint fit's pose and coefficients). ``plain`` unchanged with ``modes == 0``.
    The field's basis is built at the first call and kept on ``reg``.
    """
    from .normalstage import normal_displacement

    opts = reg.options.detail
    if opts.modes == 0:
        return plain
    fo = reg.options.identity_fit                 # the fixed prior: the joint fit from the template as it was
    part = slice(None) if reg.skin is None else reg.skin
    auto = isinstance(opts.amplitude, str) and opts.noise_prior     # "auto" with the fixed prior: AUTO_FIXED_PRIOR
    if opts.noise_prior:  # eq. D2: the coefficients' prior weighed against the residual the fit leaves; continued.
        # The joint fit pairs about as large a share of its candidate vertices as the modes-only fit did
        n = len(P) if reg.skin is None else len(reg.skin)       # the part's vertices, without copying them
        pairs = plain.pairs * min(opts.fit_samples, n) / min(fo.samples, n)
        fo = dataclasses.replace(fo, samples=opts.fit_samples, prior_start=None, iterations=opts.fit_iterations,
                                 prior=fo.prior if auto else noise_prior(plain, h, fo.prior, pairs))
    icp = reg.nricp if reg.skin is None else reg._skin_icp
    if getattr(reg, "_detail_prior", None) is None:
        reg._detail_prior = DetailPrior(reg.V[part], icp.F, opts)
    D, choice, prior, w = reg.identity.deltas, None, reg._detail_prior, None
    m = person_normals(P[part], D[:, part], plain.coefficients, icp.vertex_normals) if (
        opts.field_normals == "person") else None                                       # eq. D4
    weigh = lambda: weighted_prior(prior, plain, plain.vertices[part], surface, icp.vertex_normals, h, fo)  # noqa: E731
    if auto:  # eq. E1: s and the noise level from the evidence of the joint model at the modes-only fit
        choice, fo_e = _evidence_choice(plain, prior, P[part], D[:, part], surface, icp.vertex_normals, h, fo, m)
        if opts.amplitude_map != "uniform" and choice.sd > choice.noise and np.isfinite(choice.log_evidence):
            prior, w = weigh()  # eq. D5 where the evidence finds detail above the noise, and its evidence again
            choice, fo_e = _evidence_choice(plain, prior, P[part], D[:, part], surface, icp.vertex_normals, h, fo, m)
        if np.isfinite(choice.log_evidence):
            s, fo = choice.sd, fo_e
        else:  # the evidence could not be evaluated (a singular normal matrix): the amplitude rule and eq. D2,
            choice = None  # reported as chosen by the amplitude (detail_report), never as an evidence choice
            fo = dataclasses.replace(fo, prior=noise_prior(plain, h, fo.prior, pairs))
    if choice is None:
        out = normal_displacement(plain.vertices, reg.nricp.vertex_normals(plain.vertices), reg.nricp.L, surface, h,
                                  reg.options.normal_stage, use=reg.skin)
        amplitude = AUTO_FIXED_PRIOR if isinstance(opts.amplitude, str) else opts.amplitude
        s = amplitude * offset_rms(out.offset, out.no_surface)
        prior, w = weigh() if opts.amplitude_map != "uniform" and s > plain.rms and w is None else (prior, w)
    d6 = opts.amplitude_map == "field" and w is not None and s > (choice.noise if choice is not None else plain.rms)
    args, (first, again) = (P[part], D[:, part], surface, icp.vertex_normals, h, s), split_rounds(fo.iterations, d6)
    fit = fit_with_detail(plain, prior, *args, dataclasses.replace(fo, iterations=first),
                          start=plain if opts.noise_prior else None, field_normals=m)
    if again and fit is not plain:  # eq. D6: w from the fitted field, its last rounds
        fit, w = refit_on_field(fit, reg._detail_prior, fit_with_detail, args, dataclasses.replace(fo, iterations=again), m)
    if fit is not plain:
        fit = dataclasses.replace(fit, detail_noise=choice.noise if choice is not None else 0.0, detail_weights=w)
    if reg.skin is None or fit is plain:
        return fit
    X = fit.pose.apply(P + DenseBasis(D).combine(fit.coefficients))
    X[reg.skin] = fit.vertices
    return dataclasses.replace(fit, vertices=X)


def _evidence_choice(plain: ModelFit, prior: DetailPrior, base: np.ndarray, deltas: np.ndarray, surface, normals_of,
                     h: float, fo: ModelFitOptions, field_normals: np.ndarray | None = None):
    """``(EvidenceChoice, the joint fit's options)``: ``s``, ``sigma_n`` maximising eq. E1 (:mod:`.detailevidence`) at
    ``plain`` (field 0), paired as the joint fit's ``fo``; its ``mu``: eq. D2 at ``sigma_n`` (:func:`noise_prior`'s bounds)."""
    from .detailevidence import choose_by_evidence, normal_equations

    basis = ModesAndField(deltas, prior.phi, prior.normals if field_normals is None else field_normals)
    c = np.concatenate([plain.coefficients, np.zeros(len(prior.phi))])
    H, g, yy, p, npose = normal_equations(base, basis, c, plain.pose, surface, normals_of, h, fo)
    choice = choose_by_evidence(H, g, yy, p, npose, prior.scales, h, plain.rms)
    mu = choice.noise ** 2 / (max(p, 1) * h ** 2)
    return choice, dataclasses.replace(fo, prior=float(np.clip(mu, NOISE_PRIOR_FLOOR * fo.prior, fo.prior)))


def detail_report(fit: ModelFit) -> dict:
    """The detail field's part of a registration's report: ``{"detail_field": {...}}`` with its deviation ``s`` and,
    when the evidence chose it (:mod:`.detailevidence`), the noise level chosen with it; ``{}`` without a field."""
    if not fit.detail_sd > 0:
        return {}
    return {"detail_field": {"sd_template_units": float(fit.detail_sd),
                             "chosen_by": "evidence" if fit.detail_noise > 0 else "amplitude",
                             "noise_template_units": float(fit.detail_noise) if fit.detail_noise > 0 else None}}


__all__ = ["AUTO_FIXED_PRIOR", "BASES", "FIELD_NORMALS", "DetailPrior", "DetailPriorOptions", "INDUCING_CELL", "ModesAndField",
           "NOISE_PRIOR_FLOOR", "detail_report", "fit_with_detail", "identity_fit_with_detail", "noise_prior", "offset_rms"]
