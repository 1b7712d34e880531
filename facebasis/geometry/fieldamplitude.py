"""The detail field's amplitude over the skin: larger where the modes-only fit leaves residuals (eq. D5).

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
evidence (:mod:`.detailevidence`, eq. E1) still chooses ``s`` and the noise level. A scan within the space
leaves noise alone: ``w`` ~ 1, and the evidence's ``s`` is near its lower bound anyway.

The vertices no scan sees take the same covariance in their extension (:mod:`.unseen`, eq. U1 with ``w``).

Registered neutral (ICT rig benchmark's neutral scans, ``problems/bench_registration_rig.py``'s persons and scan
generator, 100 modes; RMS over all 14062 vertices, cm; scratch script re-registering them; the first rule tried, kept
against the variants below on all twelve persons): ``detail`` seeds 0-5 0.0228 / 0.0181 / 0.0172 / 0.0224 / 0.0212 / 0.0215 ->
0.0201 / 0.0173 / 0.0150 / 0.0204 / 0.0180 / 0.0181, their tangential part (mean) 0.0174 -> 0.0150; ``in-space``
0.0086 / 0.0102 / 0.0087 / 0.0098 / 0.0102 / 0.0126 -> 0.0085 / 0.0106 / 0.0088 / 0.0100 / 0.0104 / 0.0126. Also
tried there: ``c`` 10 (detail mean 0.0184 against 0.0181 with ``c`` 1), half the length in eq. D5 (0.0183), the
scans' noise variance taken out of ``v`` (0.0178, but it needs the noise level before the evidence gives it).
On the tests' small face (4497 vertices, a noise-free scan, bumps on the front) the map helps with 150 or 300
functions (RMS 0.0149 -> 0.0094, 0.0058 -> 0.0032 cm) and not with 60 (0.0294 -> 0.0363): a basis too short to
carry the detail leaves it to the modes either way. Cost: one pairing round and an (n, 3000) kernel product,
~0.7 s CPU per ICT neutral (load 12; the whole neutral 7-8.5 s CPU).
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.spatial.distance import cdist

from .shapemodel import ModelFit, ModelFitOptions, _pairs

#: the pseudo-count ``c`` of eq. D5: the local variance falls back to the mean where the kernel weights of the
#: pairs sum to less than about this (a vertex with no pair within a few lengths: a socket's inside)
PSEUDO = 1.0
#: ``w`` is at least this (a part the modes fit to the noise keeps a tenth of the field's deviation)
FLOOR = 0.1
#: at most this many of the modes-only fit's pairs (a seeded sample) enter eq. D5
SAMPLES = 3000
#: the field's amplitude maps (:class:`.detailprior.DetailPriorOptions`.amplitude_map)
AMPLITUDE_MAPS = ("residual", "uniform")


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
        K = np.exp(-cdist(X[i:i + chunk], P, "sqeuclidean") / (2.0 * length ** 2))
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
    out = copy.copy(prior)
    out.phi = prior.phi * w[None]
    return out, w


__all__ = ["AMPLITUDE_MAPS", "FLOOR", "PSEUDO", "SAMPLES", "fit_residual_weights", "residual_weights", "weighted_prior"]
