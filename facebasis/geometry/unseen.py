"""Where no scan sees: the registered neutral's detail extended from the seen vertices (eq. U1).

A scan never shows a template's mouth and eye sockets (ICT's 2814 of 14062 vertices) and leaves holes
(ears, the lips' and eyelids' rims). After the identity fit with the detail prior (:mod:`.detailprior`)
and the normal stage (:mod:`.normalstage`) those vertices hold the modes plus whatever the field's
functions and the normal stage's Laplacian carry there. The normal stage (and the field's
Laplace-Beltrami eigenfunctions, the ``spectral`` basis, the default when this was measured) extend the
detail *along the surface*, where a socket is a long tube from its rim although its inside lies within a
centimetre or two of the seen face in space, and the first 150 eigenfunctions barely resolve such thin
parts (the ``kernel`` basis, now the default, is 3D, but the normal stage still acts along the surface).
Measured on the ICT rig benchmark's ``detail`` persons (a smooth field along the normals, outside
any identity basis; ``problems/bench_registration_rig.py``), the right eye socket of seed 0 lay 0.143 cm
off (median), the modes alone there 0.089, the person's field itself ~0.08 cm RMS.

So the detail the fit and the normal stage found on the seen vertices -- the normal offset ``f_i =
m_i . (x_i - b_i)`` of the registered mesh ``x`` from the fit's modes-only mesh ``b = pose(T + c D)``,
``m`` its unit normals -- is extended to the unseen vertices ``u`` by the conditional mean of a Gaussian
process with the detail prior's squared-exponential covariance of length ``l`` (eq. D1), in 3D
(Euclidean) distance,

    f_u = k(u, A) (k(A, A) + (sigma_n / s)^2 I)^-1 f_A,   k(x, y) = exp(-|x - y|^2 / (2 l^2))      (eq. U1)

``A`` the seen vertices within ``3 l`` of an unseen one (at most ``samples``, a seeded sample), ``s``
the detail prior's pointwise deviation and ``sigma_n`` the joint fit's point-to-plane residual (RMS),
and the unseen vertices are set to ``b_u + f_u m_u``: the modes' socket plus the seen detail's smooth
extension, which falls back to the modes alone farther than a few ``l`` from any seen vertex (Rasmussen &
Williams 2006, eq. 2.23). ICT ``detail`` persons, registered neutral's RMS error over all vertices:
seed 0 0.0551 -> 0.0456 cm (right eye socket 0.143 -> 0.059 median), seed 1 0.0417 -> 0.0376; in-space
persons 0.0141 -> 0.0143, 0.0167 -> 0.0164; the rig bench's held-out ratio for the ``detail`` persons 1.48
-> 1.30 and 1.69 -> 1.59 (``reports/registration/unseen_detail``). Only the neutral registered through the
identity fit with the detail prior and the normal stage is affected (expression scans start from it).

References
----------
Rasmussen C. E., Williams C. K. I. Gaussian Processes for Machine Learning. MIT Press 2006.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

#: seen vertices within this many lengths ``l`` of an unseen one condition eq. U1
REACH = 3.0
#: the nugget is at least this (a noise-free scan: the kernel matrix of vertices much closer than ``l`` is
#: numerically singular)
NUGGET_FLOOR = 1e-3


def se_kernel(A: np.ndarray, B: np.ndarray, length: float) -> np.ndarray:
    """``k(a, b) = exp(-|a - b|^2 / (2 l^2))`` (len(A), len(B)): the detail field's squared-exponential covariance in
    3D, shared by its basis (eq. D3 of :mod:`.detailprior`), its amplitude map (eq. D5 of :mod:`.fieldamplitude`) and
    the extension here (eq. U1)."""
    return np.exp(-cdist(A, B, "sqeuclidean") / (2.0 * length ** 2))


def extend_normal_offset(X: np.ndarray, base: np.ndarray, normals: np.ndarray, seen: np.ndarray,
                         unseen: np.ndarray, length: float, noise_ratio: float, samples: int = 2000,
                         seed: int = 0, weights: np.ndarray | None = None) -> np.ndarray:
    """The mesh ``X`` with its unseen vertices replaced by ``base`` plus the seen normal offset's
    extension along ``normals`` (eq. U1 of the module docstring).

    Parameters
    ----------
    X : (n, 3) the registered mesh, base : (n, 3) the model's mesh it offsets (same frame)
    normals : (n, 3) unit vertex normals of ``base``
    seen, unseen : (n,) bool, the vertices whose offset is known (found scan surface) and those to set
    length : ``l`` (``X``'s units)
    noise_ratio : ``(sigma_n / s)^2``, the nugget relative to the prior's variance (at least ``NUGGET_FLOOR``)
    samples : at most this many seen vertices condition the extension (a seeded sample)
    weights : (n,) the prior's deviation relative to ``s`` over the vertices (``w`` of eq. D5 of
        :mod:`.fieldamplitude`: the covariance ``w(x) w(y) k(x, y)``); None: 1 everywhere

    Returns
    -------
    (n, 3) a copy of ``X`` (``X`` itself if no vertex is unseen or none is seen near one)
    """
    u, a = np.flatnonzero(unseen), np.flatnonzero(seen)
    if not len(u) or not len(a):
        return X
    a = a[cKDTree(base[u]).query(base[a], distance_upper_bound=REACH * length)[0] <= REACH * length]
    if not len(a):
        return X
    if len(a) > samples:
        a = np.sort(np.random.default_rng(seed).choice(a, samples, replace=False))
    f = ((X[a] - base[a]) * normals[a]).sum(1)
    w = np.ones(len(X)) if weights is None else np.asarray(weights, float)
    K = se_kernel(base[a], base[a], length) * np.outer(w[a], w[a])
    K[np.diag_indices_from(K)] += max(noise_ratio, NUGGET_FLOOR)
    alpha = cho_solve(cho_factor(K), f)
    fu = w[u] * (se_kernel(base[u], base[a], length) @ (w[a] * alpha))
    Y = X.copy()
    Y[u] = base[u] + fu[:, None] * normals[u]
    return Y


def extend_unseen(reg, fit, res, surface, identity_fit: bool):
    """The stage result ``res`` (:class:`.normalstage.NormalStageResult` or the non-rigid one) of a neutral
    registered through the identity fit ``fit`` with the detail prior, its skin vertices without scan
    surface set by :func:`extend_normal_offset` (``fit.detail_sd`` is ``s``; ``reg._detail_prior.length``
    ``l``). Unchanged unless ``identity_fit`` (the scan was fitted in the identity space, not as an
    expression), ``reg.options.detail.unseen``, the fit carried the detail field
    (``detail_sd > 0``) and the last stage was the normal one (the free non-rigid stage's points slide
    along the skin: its offsets are not along the normals)."""
    import dataclasses

    opts = reg.options.detail
    if (not identity_fit or fit is None or not opts.unseen or not getattr(fit, "detail_sd", 0.0) > 0
            or reg.options.after_model != "normal"):
        return res
    noise_ratio = (fit.rms / fit.detail_sd) ** 2
    if not np.isfinite(noise_ratio):  # the fit kept no pairs: nothing seen to extend
        return res
    from .shapemodel import DenseBasis

    base = fit.pose.apply(reg.V + DenseBasis(reg.identity.deltas).combine(fit.coefficients))
    unseen = res.no_surface.copy()
    if reg.skin is not None:  # the other parts (eyeballs, teeth) stay where the fit put them
        unseen[:] = False
        unseen[reg.skin] = res.no_surface[reg.skin]
    w = getattr(fit, "detail_weights", None)
    if w is not None and reg.skin is not None:  # over the skin: the other parts' weights do not enter
        full = np.ones(len(base))
        full[reg.skin] = w
        w = full
    X = extend_normal_offset(res.vertices, base, reg.nricp.vertex_normals(base), ~res.no_surface, unseen,
                             reg._detail_prior.length * fit.pose.scale, noise_ratio,
                             opts.unseen_samples, weights=w)
    if X is res.vertices:
        return res
    dist = res.distance.copy()
    dist[unseen] = surface.closest(X[unseen])[2]
    return dataclasses.replace(res, vertices=X, distance=dist)


__all__ = ["NUGGET_FLOOR", "REACH", "extend_normal_offset", "extend_unseen", "se_kernel"]
