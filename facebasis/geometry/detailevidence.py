"""The detail field's amplitude and the scan's noise level chosen per scan by the evidence of the joint fit.

The identity fit with the detail prior (:mod:`.detailprior`, eq. D1 / D3) is the MAP of a Gaussian model: the
point-to-plane residuals are independent noise ``N(0, sigma_n^2)``, the modes' coefficients ``c ~ N(0, 1)``,
the field's ``e_j ~ N(0, s^2 sigma_j^2)`` (``sigma_j``: :attr:`.detailprior.DetailPrior.scales`). Two numbers of
that model are not known beforehand: the field's pointwise deviation ``s`` (how much detail the person has
outside the identity space) and ``sigma_n``. Linearised at the modes-only fit (one closest-point round of the
joint fit: ``p`` pairs, the Jacobian ``J`` (p, q) in the pose (flat prior) and the ``K + J`` coefficients, data
``y = J_c theta_0 - r_0``), the model is linear-Gaussian and its marginal likelihood (evidence) is closed form,

    log p(y | s, beta) = 1/2 [p log beta + sum_j log P_j - log det A - beta |y - J m|^2 - m^T P m] + const,
    A = beta J^T J + P,   m = beta A^{-1} J^T y,   beta = 1 / sigma_n^2                          (eq. E1)

``P`` the diagonal prior precisions (0 for the pose, 1 for the modes, ``1 / (s sigma_j)^2`` for the field). It
needs only the (q, q) normal matrix ``J^T J``, ``J^T y`` and ``|y|^2`` (q ~ 400 on ICT: one Cholesky per
evaluation), and its gradient in ``log s`` and ``log beta`` is closed form too,

    d/d log s = sum_field (P_j (A^{-1})_jj + P_j m_j^2 - 1),
    d/d log beta = 1/2 (p - q + sum_j P_j (A^{-1})_jj - beta |y - J m|^2)                     (eq. E2)

(the stationary points are MacKay's re-estimation formulas, ``gamma`` well-determined parameters). ``s`` and
``sigma_n`` maximise (E1) (type-II maximum likelihood, the evidence framework: MacKay 1992, Tipping 2001; a
coarse grid in ``s`` at the modes-only fit's residual, then L-BFGS-B in both logs within bounds). The joint fit
then runs with that ``s`` and with eq. D2's coefficient prior at ``sigma_n`` (the noise the joint model leaves,
not the modes-only fit's residual, which holds the detail too).

Why: a fixed rule ``s = amplitude x`` the RMS normal offset of the modes-only fit cannot tell detail from that
fit's shrinkage. Measured on the ICT rig benchmark's neutral scans (``problems/bench_registration_rig.py``, 100
modes, 0.2 mm noise; registered neutral RMS over all 14062 vertices, cm; seeds 0-4, ``amplitude`` 2 -> the
evidence): persons with detail outside the space 0.0266 / 0.0218 / 0.0225 / 0.0342 / 0.0252 -> 0.0269 / 0.0218 /
0.0203 / 0.0283 / 0.0240 (``s`` 0.074 / 0.041 / 0.096 / 0.104 / 0.092 -> 0.044 / 0.026 / 0.030 / 0.040 / 0.038 cm);
persons within it 0.0115 / 0.0133 / 0.0138 / 0.0175 / 0.0150 -> 0.0086 / 0.0109 / 0.0091 / 0.0108 / 0.0110 (``s``
~0.018 -> ~0.002: the evidence finds no detail). ``sigma_n`` came out 0.019-0.023 cm on every scan, the scans' 0.2
mm noise. Cost: one pairing round and 30-60 evaluations, 0.2-0.4 s CPU, and no normal-stage pass for the offsets.

References
----------
MacKay D. J. C. Bayesian interpolation. Neural Computation 4(3), 1992.
Tipping M. E. Sparse Bayesian learning and the relevance vector machine. JMLR 1, 2001.
Bishop C. M. Pattern recognition and machine learning, section 3.5 (the evidence approximation). Springer 2006.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve, solve_triangular
from scipy.optimize import minimize

from .shapemodel import ModelFitOptions, _pairs

#: ``s`` and ``sigma_n`` are searched within these multiples of the template's median edge length ``h``. The lower
#: bound keeps the joint fit's normal matrix well conditioned (its prior rows ``1 / (s sigma_j)`` against data rows of
#: order one; :func:`.shapemodel._solve`'s ridge is relative to the trace): at ``s`` = 5e-9 the tests' default-face
#: person's joint fit stopped after one round at the modes-only fit's coefficients (0.16 off; 0.02 at ``s`` >= 5e-6).
#: ICT persons within the space land at ~7e-3 ``h``
BOUNDS = (1e-3, 10.0)
#: the coarse grid of ``s`` (log-spaced within :data:`BOUNDS`) before the joint search
GRID = 15


@dataclass(frozen=True)
class EvidenceChoice:
    """The field's deviation and the noise level that maximise eq. E1.

    Attributes
    ----------
    sd : ``s``, the field's pointwise standard deviation (template units)
    noise : ``sigma_n``, the residuals' standard deviation (template units; the one given when it is held fixed)
    log_evidence : eq. E1 at the maximum (without the constant)
    pairs : ``p``, the pairs of the linearisation
    evaluations : evaluations of eq. E1
    """

    sd: float
    noise: float
    log_evidence: float
    pairs: int
    evaluations: int


def normal_equations(base: np.ndarray, basis, coefficients: np.ndarray, pose, surface, normals_of, h: float,
                     options: ModelFitOptions):
    """The joint model linearised as one round of :func:`.shapemodel.fit_shape_model` does it (the same pairs,
    the same pose Jacobian), at ``pose(base + basis.combine(coefficients))``.

    Parameters
    ----------
    base : (n, 3) the part's template vertices; basis : a structured basis of ``Q`` columns
        (:class:`.detailprior.ModesAndField`); coefficients : (Q,) the linearisation point; pose : its similarity
    surface, normals_of, h, options : as :func:`.shapemodel.fit_shape_model` (``samples``, ``seed``,
        ``max_distance``, ``normal_angle``, ``scale``)

    Returns
    -------
    H : (q, q) ``J^T J`` with ``q = npose + Q`` (the pose's columns first); g : (q,) ``J^T y``; yy : ``|y|^2``;
    p : pairs; npose : 7 with a scale, else 6
    """
    use = np.arange(len(base))
    if len(use) > options.samples:                 # the fit's own seeded sample
        use = np.sort(use[np.random.default_rng(options.seed).choice(len(use), options.samples, replace=False)])
    X = pose.apply(base + basis.combine(coefficients))
    idx, Q, N = _pairs(X, normals_of(X), surface, options.max_distance * h, np.cos(np.radians(options.normal_angle)),
                       use, 0.5 * h)
    x = X[idx]
    y0 = x - x.mean(0)
    npose = 7 if options.scale else 6
    Jp = np.concatenate([np.cross(y0, N), N, (y0 * N).sum(1, keepdims=True)], 1)[:, :npose]
    Jc = basis.normal_jacobian(idx, pose.scale * (N @ pose.rotation))
    J = np.concatenate([Jp, Jc], 1)
    y = Jc @ coefficients - ((x - Q) * N).sum(1)  # residual r = J theta - y, theta = (pose step, coefficients)
    return J.T @ J, J.T @ y, float(y @ y), len(idx), npose


def log_evidence(H: np.ndarray, g: np.ndarray, yy: float, p: int, beta: float, P: np.ndarray,
                 field: np.ndarray | None = None):
    """Eq. E1 and, with ``field`` (a boolean (q,) mask of the columns whose precision scales as ``s^-2``), its
    gradient in ``(log s, log beta)`` (eq. E2).

    Parameters
    ----------
    H : (q, q), g : (q,), yy, p : :func:`normal_equations`' ``J^T J``, ``J^T y``, ``|y|^2``, pairs
    beta : the noise precision ``1 / sigma_n^2``
    P : (q,) prior precisions (0: a flat prior)

    Returns
    -------
    float, or ``(float, (2,) gradient)`` with ``field``
    """
    A = beta * H + np.diag(P)
    L = cho_factor(A, lower=True)
    m = beta * cho_solve(L, g)
    fit = yy - 2.0 * g @ m + m @ H @ m                      # |y - J m|^2
    pos = P > 0
    val = 0.5 * (p * np.log(beta) + np.log(P[pos]).sum() - 2.0 * np.log(np.diag(L[0])).sum() - beta * fit
                 - m @ (P * m))
    if field is None:
        return float(val)
    Ainv = (solve_triangular(L[0], np.eye(len(A)), lower=True) ** 2).sum(0)   # diag(A^-1) from L^-1
    d_s = float(np.sum(P[field] * (Ainv[field] + m[field] ** 2) - 1.0))
    d_b = 0.5 * float(p - len(A) + np.sum(P * Ainv) - beta * fit)
    return float(val), np.array([d_s, d_b])


def choose_by_evidence(H: np.ndarray, g: np.ndarray, yy: float, p: int, npose: int, scales: np.ndarray, h: float,
                       noise: float, fit_noise: bool = True) -> EvidenceChoice:
    """``s`` (and ``sigma_n`` if ``fit_noise``) maximising eq. E1: the grid of :data:`GRID` values of ``s`` at
    ``noise``, then L-BFGS-B in ``(log s, log sigma_n)`` (``log s`` alone with ``fit_noise`` False) within
    :data:`BOUNDS` x ``h``.

    Parameters
    ----------
    H, g, yy, p, npose : :func:`normal_equations`' output; the columns after the pose are the ``K`` modes (prior
        precision 1) and the ``len(scales)`` field functions (precision ``1 / (s scales_j)^2``)
    scales : (J,) :attr:`.detailprior.DetailPrior.scales`
    h : length unit (the bounds are multiples of it)
    noise : ``sigma_n`` of the grid (the modes-only fit's residual), and the fixed one with ``fit_noise`` False
    """
    q, J = len(H), len(scales)
    field = np.zeros(q, bool)
    field[q - J:] = True
    fixed = np.where(np.arange(q) < npose, 0.0, 1.0)
    lo, hi = np.log(BOUNDS[0] * h), np.log(BOUNDS[1] * h)
    calls = [0]

    def neg(z, grad=True):
        calls[0] += 1
        s, sn = np.exp(z[0]), (np.exp(z[1]) if fit_noise else noise)
        P = fixed.copy()
        P[field] = 1.0 / (s * scales) ** 2
        try:
            out = log_evidence(H, g, yy, p, sn ** -2, P, field if grad else None)
        except (LinAlgError, ValueError):
            return (np.inf, np.zeros(len(z))) if grad else np.inf
        if not grad:
            return -out
        val, (d_s, d_b) = out
        return -val, -np.array([d_s, -2.0 * d_b][:len(z)])  # d/d log sigma_n = -2 d/d log beta

    noise = float(np.clip(noise, np.exp(lo), np.exp(hi)))
    grid = np.linspace(lo, hi, GRID)
    z0 = np.array([grid[int(np.argmin([neg([z, np.log(noise)], False) for z in grid]))]]
                  + ([np.log(noise)] if fit_noise else []))
    # relative to the start: eq. E1 is ~1e4 on a scan, and L-BFGS-B's relative tolerance then stops on the plateau
    # where the field is off (a person within the space: d/d log s ~0.1 at the lower bound, the maximum 7x higher)
    f0 = neg(z0, False)
    res = minimize(lambda z: (lambda v, d: (v - f0, d))(*neg(z)), z0, jac=True, method="L-BFGS-B",
                   bounds=[(lo, hi)] * len(z0), options=dict(ftol=1e-12, gtol=1e-7, maxiter=200))
    z = res.x if np.isfinite(res.fun) and res.fun <= 0 else z0
    return EvidenceChoice(float(np.exp(z[0])), float(np.exp(z[1])) if fit_noise else noise,
                          -float(neg(z, False)), int(p), calls[0])


__all__ = ["BOUNDS", "EvidenceChoice", "GRID", "choose_by_evidence", "log_evidence", "normal_equations"]
