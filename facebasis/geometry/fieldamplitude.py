"""The detail field's amplitude over the skin: where the modes-only fit leaves residuals, then where the field is
(eqs. D5-D6).

The joint fit of :mod:`.detailprior` (eq. D1 / D3) gives the detail field the same pointwise deviation ``s``
everywhere: a stationary Gaussian process. A person's detail outside an identity space is rarely spread so
evenly (a nose, a chin, cheeks that the modes do not reach; the back of a head that they fit), and a field as
free on the parts the modes fit as on those they miss lets the modes share the detail where it is, and the
field undo their side effects where it is not. The modes move points *along* the skin as well as across it,
which no scan shows, so the registered neutral's correspondence slides. On the ICT rig benchmark's ``detail``
persons (a smooth field of Gaussian bumps on the face, up to 2.5 mm) the registered neutral's error is
mostly tangential (seed 3: 0.0196 of 0.0224 cm RMS over all vertices) and all of it from the modes (their
mesh ``T + c D``'s own tangential error 0.0195; the field's 0.0017; coefficients 0.12 off, RMS, against
0.045 for the persons within the space), and no global ``s`` does better than the evidence's (half or twice
it: 0.0202 / 0.0221 cm RMS on average over the ``detail`` persons of seeds 0-5, against 0.0205).

So the field's deviation follows the residual the modes-only fit leaves: its functions ``b_k`` (eq. D3) are
scaled by

    w(x) = max(sqrt(v(x) / mean_i v(x_i)), floor),
    v(x) = (sum_p k(x, x_p) r_p^2 + c rbar^2) / (sum_p k(x, x_p) + c)                          (eq. D5)

``r_p`` the modes-only fit's point-to-plane residuals at its pairs ``x_p`` (a seeded sample), ``rbar^2``
their mean square, ``k`` the field's own squared-exponential kernel of length ``l`` (a Nadaraya-Watson
estimate of the local residual variance, shrunk to the mean with a pseudo-count ``c`` = :data:`PSEUDO`
where few pairs are near: the sockets), the mean over the part's vertices. The field is then the
non-stationary process of covariance ``s^2 w(x) w(y) k(x, y)`` (a valid kernel for any ``w``), and the
evidence (:mod:`.detailevidence`, eq. E1) still chooses ``s`` and the noise level. Only where the evidence of the
uniform field finds detail above the noise (``s > sigma_n``; with a given amplitude: above the modes-only fit's
residual) is ``w`` used: on a scan within the space the residual is noise, and eq. D5 on noise alone (weights 0.8-1.3,
up to 2 with 1 % outliers: squared residuals are not robust) moved a 0.6 mm-noise in-space neutral by 20 % RMS
(review9); such a scan gets the uniform field, exactly.

**Re-estimated from the fitted field** (eq. D6, ``amplitude_map="field"``, the default). The modes-only fit's
residual is a blurred picture of the detail (the modes took part of it), so after the joint fit ``w`` is estimated
again by eq. D5 with the joint fit's own field at every vertex of the part in place of the residuals,

    r_i = f(x_i) = m_i . (x_i - b_i)                                                               (eq. D6)

``x`` the joint fit's mesh, ``b = pose(T + c D)`` its modes' mesh and ``m`` its unit normals (one step of an
EM-like re-estimation of the local variance), and the joint fit's last :data:`ROUNDS` rounds continue from its modes
and pose with the field from zero (the same ``s``, noise level and eq. D4 normals). Only where the evidence found
detail above the noise (``s > sigma_n``; the amplitude rule: above the modes-only fit's residual): a field at the
noise level says nothing about where the detail is (ICT persons within the space: ``s`` ~0.002 cm against
``sigma_n`` ~0.02; with detail 0.026-0.043 against 0.019-0.023), and the re-estimation there only moved the
registered neutral by less than 1e-4 cm RMS, enough to tip a later expression fit elsewhere (the tests' regional
expression with 12 regions: p95 0.092 -> 0.116 cm). The vertices no scan sees take the same covariance in their
extension (:mod:`.unseen`, eq. U1 with ``w``).

Registered neutral (ICT rig benchmark's neutral scans, ``problems/bench_registration_rig.py``'s persons and scan
generator, 100 modes; RMS over all 14062 vertices, cm; scratch script re-registering them; eq. D5 alone measured
with 3000 pairs, eq. D6 with 20 rounds of eq. D5 and 8 more, the default as below for seeds 1 and 3):

| person, seeds 0-5 | uniform | eq. D5 | eq. D5 + D6 |
|---|---|---|---|
| ``detail`` RMS | .0228 .0181 .0172 .0224 .0212 .0215 | .0201 .0173 .0150 .0204 .0180 .0181 | .0185 .0157 .0151 .0173 .0148 .0160 |
| ``detail`` tangential, mean | 0.0174 | 0.0150 | 0.0132 |
| ``in-space`` RMS | .0086 .0102 .0087 .0098 .0102 .0126 | .0085 .0106 .0088 .0100 .0104 .0126 | .0083 .0100 .0089 .0099 .0103 .0128 |

(The ``in-space`` column of eq. D6 is before the ``s > sigma_n`` condition; with it these persons take eq. D5 alone
at 1500 pairs: .0086 .0104 - .0101 .0106 .0127, tangential .0063 .0090 - .0085 .0090 .0109 against the uniform
field's .0063 .0088 .0070 .0082 .0085 .0108: up to 0.0004 cm more.)

The default splits the joint fit's 20 rounds as 12 with eq. D5's ``w`` and the last 8 after eq. D6 (:func:`split_rounds`;
the same CPU as the uniform field's rounds) and samples 1500 pairs: seed 3 ``detail`` 0.0169, seed 1 0.0155, seed 0
0.0184, seed 1 ``in-space`` 0.0100. Eq. D5 was the first rule tried; also tried there: ``c`` 10 (``detail`` mean
0.0184 against 0.0181 with ``c`` 1), half the length in eq. D5 (0.0183), the scans' noise variance taken out of
``v`` (0.0178, but it needs the noise level before the evidence gives it); eq. D6 with a whole second joint fit of
20 rounds from the modes-only fit: within 0.0006 cm (seed 3 0.0166) for ~2 s CPU more. On the tests' small face
(4497 vertices, a noise-free scan, bumps on the front) RMS uniform -> eq. D5 -> eq. D6: 0.0058 -> 0.0018 -> 0.0017 cm
with 300 functions, 0.0149 -> 0.0117 -> 0.0044 with 150, but 0.0294 -> 0.0332 -> 0.0347 with 60 (a basis too short
to carry the detail leaves it to the modes either way). Cost: two (n, 1500) kernel passes and one pairing round,
~0.5 s CPU per ICT neutral; the whole neutral 7.5-8.1 s CPU (detail persons, seeds 0-3 of the rig bench, load 5-7,
``reports/registration/round9_seed*``; the 9.1-9.3 s measured before at load 13 was the 20 + 8 rounds version).
"""

from __future__ import annotations

import copy

import numpy as np
from .shapemodel import DenseBasis, ModelFit, ModelFitOptions, _pairs
from .unseen import se_kernel

#: the pseudo-count ``c`` of eq. D5: the local variance falls back to the mean where the kernel weights of the
#: pairs sum to less than about this (a vertex with no pair within a few lengths: a socket's inside)
PSEUDO = 1.0
#: ``w`` is at least this (a part the modes fit to the noise keeps a tenth of the field's deviation)
FLOOR = 0.1
#: at most this many of the modes-only fit's pairs (a seeded sample) enter eq. D5
SAMPLES = 1500
#: the field's amplitude maps (:class:`.detailprior.DetailPriorOptions`.amplitude_map)
AMPLITUDE_MAPS = ("field", "residual", "uniform")
#: rounds of the joint fit after ``w`` is re-estimated from its field (eq. D6), continued from its modes: the last of
#: its ``fit_iterations`` (at most half of them; :func:`split_rounds`)
ROUNDS = 8


def residual_weights(X: np.ndarray, idx: np.ndarray, r: np.ndarray, length: float, pseudo: float = PSEUDO,
                     floor: float = FLOOR, samples: int = SAMPLES, seed: int = 0, chunk: int = 2048) -> np.ndarray:
    """``w`` (n,) of eq. D5.

    Parameters
    ----------
    X : (n, 3) the part's vertices (the modes-only fit's mesh)
    idx : (p,) the vertices of the fit's pairs, r : (p,) their point-to-plane residuals
    length : the kernel's length ``l`` (``X``'s units)
    pseudo, floor : ``c`` and the floor of eq. D5
    samples : at most this many pairs (a seeded sample), seed : its seed
    chunk : vertices per block of the kernel (memory; a loop over blocks, not vertices)

    Returns
    -------
    (n,) ones when no residual is left (no pairs, or all zero)
    """
    r2 = np.asarray(r, float) ** 2
    if not len(r2) or not r2.mean() > 0:
        return np.ones(len(X))
    if len(r2) > samples:
        keep = np.sort(np.random.default_rng(seed).choice(len(r2), samples, replace=False))
        idx, r2 = np.asarray(idx)[keep], r2[keep]
    P, mean = X[idx], float(r2.mean())
    num, den = np.empty(len(X)), np.empty(len(X))
    for i in range(0, len(X), chunk):
        K = se_kernel(X[i:i + chunk], P, length)
        num[i:i + chunk], den[i:i + chunk] = K @ r2, K.sum(1)
    v = (num + pseudo * mean) / (den + pseudo)
    return np.maximum(np.sqrt(v / v.mean()), floor)


def fit_residual_weights(fit: ModelFit, X: np.ndarray, surface, normals_of, h: float, options: ModelFitOptions,
                         length: float) -> np.ndarray:
    """``w`` (n,) of eq. D5 from the residuals of a modes-only fit at its mesh ``X`` (the part's vertices in
    ``surface``'s frame), paired as :func:`.shapemodel.fit_shape_model` pairs every vertex with ``options``;
    ``length`` in the template's units (times the fit's scale)."""
    idx, Q, N = _pairs(X, normals_of(X), surface, options.max_distance * h, np.cos(np.radians(options.normal_angle)),
                       np.arange(len(X)), 0.5 * h)
    return residual_weights(X, idx, ((X[idx] - Q) * N).sum(1), length * fit.pose.scale)


def weighted_prior(prior, fit: ModelFit, X: np.ndarray, surface, normals_of, h: float, options: ModelFitOptions):
    """``(a copy of the field's basis prior with its functions scaled by w, w)``: eq. D5 for the joint fit of
    :mod:`.detailprior` (``prior`` a :class:`.detailprior.DetailPrior`, unchanged; the other arguments as
    :func:`fit_residual_weights`')."""
    w = fit_residual_weights(fit, X, surface, normals_of, h, options, prior.length)
    return scaled_prior(prior, w), w


def scaled_prior(prior, w: np.ndarray):
    """A copy of the field's basis prior (a :class:`.detailprior.DetailPrior`, unchanged) with its functions scaled
    by ``w`` (n,): the covariance ``s^2 w(x) w(y) k(x, y)``."""
    out = copy.copy(prior)
    out.phi = prior.phi * w[None]
    return out


def split_rounds(iterations: int, field: bool = True) -> tuple[int, int]:
    """``(rounds with eq. D5's w, rounds after eq. D6)`` of a joint fit of ``iterations`` rounds: the last
    :data:`ROUNDS`, at most half of them (at least one each; one round in all: ``(1, 0)``); ``(iterations, 0)``
    without ``field`` (eq. D6 not taken: the evidence's ``s`` below its noise level, a person within the space)."""
    again = min(ROUNDS, iterations // 2) if field else 0
    return max(1, iterations - again), again


def refit_on_field(fit: ModelFit, prior, fit_with_detail, args: tuple, options: ModelFitOptions, field_normals):
    """The joint fit again with ``w`` of eq. D6 (from the field ``fit`` carries), continued from its modes and pose
    for ``options.iterations`` rounds (:func:`split_rounds`), the field from zero: ``(the new fit, w)``.

    Parameters
    ----------
    fit : the joint fit with eq. D5's ``w`` (:func:`.detailprior.fit_with_detail`'s result)
    prior : the field's basis (:class:`.detailprior.DetailPrior`, unscaled)
    fit_with_detail : :func:`.detailprior.fit_with_detail` (passed in: that module imports this one)
    args : its ``(base, deltas, surface, normals_of, h, s)``; options : the joint fit's options (its rounds: these)
    field_normals : (n, 3) the field's directions of the first fit (eq. D4; None: the template's)
    """
    base, deltas, surface, normals_of, h, s = args
    w = field_weights(fit, base, deltas, normals_of, prior.length)
    return fit_with_detail(fit, scaled_prior(prior, w), *args, options, start=fit, field_normals=field_normals), w  # iterations: both fits'


def field_weights(fit: ModelFit, base: np.ndarray, deltas: np.ndarray, normals_of, length: float) -> np.ndarray:
    """``w`` (n,) of eq. D6: eq. D5 with the joint fit's field ``f(x_i)`` at every vertex of the part for the
    residuals, read off its mesh as the normal offset from its modes' mesh ``pose(T + c D)``.

    Parameters
    ----------
    fit : the joint fit (its ``vertices`` include the field), base : (n, 3) the part's template vertices
    deltas : (K, n, 3) the modes on the part; normals_of : unit vertex normals ``(n, 3) -> (n, 3)``
    length : the field's length ``l`` (template units; times the fit's scale)
    """
    M = fit.pose.apply(base + DenseBasis(deltas).combine(fit.coefficients[:len(deltas)]))
    f = ((fit.vertices - M) * normals_of(M)).sum(1)
    return residual_weights(M, np.arange(len(M)), f, length * fit.pose.scale)


__all__ = ["AMPLITUDE_MAPS", "FLOOR", "PSEUDO", "SAMPLES", "ROUNDS", "field_weights", "fit_residual_weights", "refit_on_field",
           "residual_weights", "scaled_prior", "split_rounds", "weighted_prior"]
