"""The directions of the identity fit's detail field: the person's normals, not the template's (eq. D4).

The joint fit of :mod:`.detailprior` (eq. D1) displaces the template's vertices by the identity modes and a
smooth scalar field ``f`` along unit directions ``m``. With ``m`` the *template's* normals, a person whose
surface is tilted against the template's (ICT's identities: 6-10 degrees at the median vertex, 20-28 at the
95th percentile) gets a field with a part along its own surface: to move the surface by a detail ``d`` along
the person's normal ``n`` the field must take ``d / (m . n)``, and ``d tan(angle(m, n))`` of it slides the
points along the skin, where no scan term sees it. On the ICT rig benchmark's ``detail`` persons (a smooth
field along the person's normals, up to 2.5 mm) that slide predicted from the true fields is 0.013-0.023 cm
RMS over all vertices (seeds 0-3), against a registered neutral's tangential error of 0.0246 cm (seed 3, of
0.0270 in all); the rig built from its scans had most of its held-out excess from it (ratio 1.40; with the
neutral's tangential error taken out of every scan 1.12, its normal error 1.36). So the field runs along the
normals of the person's modes mesh,

    m = normals(T + sum_k c_k D_k)                                                       (eq. D4)

the modes-only fit's ``c`` until the joint fit has converged (at most half its rounds), then a few rounds more
along the joint fit's own (one update: the normals of a continued fit barely move after it; a second joint
fit from the modes-only fit along the updated normals cost 2.2 s CPU more for 0.0224 -> 0.0221 cm on seed 3);
the added rounds cost 0.2-0.5 s CPU per ICT neutral (review: 7.4 -> 7.9 s). With the fixed prior
(``noise_prior`` off) the whole joint fit runs along the modes-only fit's normals.

The assumption: a person's own detail lies along the normals of their best in-space approximation (how the
bench builds it, and how a surface's offset from its nearest in-space shape is naturally measured). Detail
laid along the *template's* normals instead is fitted worse with eq. D4 (review on ICT seed 3: face median /
p95 0.0158 / 0.0417 with template normals against 0.0202 / 0.0570 with D4); ``field_normals="template"``
keeps that model. Registered neutral of seed 3 ``detail``, RMS over all vertices, template normals ->
eq. D4: 0.0270 -> 0.0224 cm (face median / p95 0.017 / 0.050 -> 0.013 / 0.030); seed 1 0.0187 -> 0.0181
(scratch scripts re-registering the bench's neutral scans).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .shapemodel import DenseBasis, ModelFit, ModelFitOptions, fit_shape_model


def person_normals(base: np.ndarray, deltas: np.ndarray, coefficients: np.ndarray, normals_of) -> np.ndarray:
    """(n, 3) unit normals of the modes' mesh ``T + sum_k c_k D_k`` (unposed; eq. D4).

    Parameters
    ----------
    base : (n, 3) the template's vertices ``T``, deltas : (K, n, 3) the modes ``D_k``
    coefficients : (K,) ``c``
    normals_of : unit vertex normals ``(n, 3) -> (n, 3)`` of the topology
    """
    return normals_of(base + DenseBasis(deltas).combine(np.asarray(coefficients)[:len(deltas)]))


def fit_along_person_normals(base: np.ndarray, deltas: np.ndarray, basis_along, normals: np.ndarray, surface,
                             normals_of, h: float, options: ModelFitOptions, sigma: np.ndarray, c0: np.ndarray,
                             pose0) -> ModelFit:
    """The joint fit (:func:`.shapemodel.fit_shape_model` on the modes and the field) continued from ``c0``,
    ``pose0``: half of ``options.iterations`` with the field along ``normals`` (the modes-only fit's, eq. D4),
    the rest along the normals of the modes mesh those rounds reached.

    Parameters
    ----------
    base : (n, 3) the template part, deltas : (K, n, 3) the identity modes on it
    basis_along : ``m (n, 3) -> basis``: the structured basis of the modes and the field along ``m``
        (:class:`.detailprior.ModesAndField`)
    normals : (n, 3) the field's directions for the first half
    surface, normals_of, h, options, sigma, c0, pose0 : as :func:`.shapemodel.fit_shape_model`'s

    Returns
    -------
    ModelFit
        over all ``K + J`` coefficients; ``iterations`` of both halves
    """
    half = max(1, options.iterations // 2)
    fit = fit_shape_model(base, basis_along(normals), surface, normals_of, h,
                          dataclasses.replace(options, iterations=half), sigma=sigma, c0=c0, pose0=pose0)
    if options.iterations - half < 1:
        return fit
    m = person_normals(base, deltas, fit.coefficients, normals_of)
    rest = fit_shape_model(base, basis_along(m), surface, normals_of, h,
                           dataclasses.replace(options, iterations=options.iterations - half), sigma=sigma,
                           c0=fit.coefficients, pose0=fit.pose)
    return dataclasses.replace(rest, iterations=fit.iterations + rest.iterations)


__all__ = ["fit_along_person_normals", "person_normals"]
