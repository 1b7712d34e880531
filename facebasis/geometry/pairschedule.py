"""When the expression fit's scan-to-model pairs join it, and which fit is kept (eqs. S1, S2).

The scan-to-model pairs (eq. S1 of :mod:`.scanpairs`) keep an opened mouth from being fitted as lips closed
over its hole, but used from the fit's first round they open other basins on scans the one-sided fit got
right (``problems.bench_mouth_basin``, seed 0 detail jawOpen 0.7: a lower lip rolled in, mouthRollLower 1.5,
whole-fit p95 0.176 -> 0.686 cm; seed 4 in-space mouthClose: lips half closed, mouthClose 0.46 for 0.82).
Schedules of :func:`whole_expression_fit`:

``"joint"``
    the pairs from the first round (the fit of :func:`.shapemodel.fit_shape_model` with ``scan_pairs``; the
    previous default)
``"after"``
    the model-to-scan fit first (its graduated prior finds the basin of the large motions), then the same fit
    with the scan pairs continued from its weights, and the continued fit kept if it leaves less of the scan
    unexplained (eq. S2 below the first's, :data:`MARGIN`): a fit already right stays right (within the noise of
    S2), one with lips closed over a hole moves on.
    On the two scans above the continued fit lands right (whole-fit p95 0.183 and 0.122 cm). Costs one
    whole fit more (about 1 s CPU on a 100k-vertex scan).

The choice uses no ground truth: the scan-to-model residual of eq. S1's pairs on a seeded sample of the scan,

    S2 = sqrt( (1/p) sum_j min(|m_j . (x_i(j) - q_j)|, 2 h)^2 )                         (eq. S2)

over the pairs eq. S1 keeps (normals within the fit's ``normal_angle``, within ``max_distance`` h). The
model-to-scan residual cannot choose: it drops the pairs over a hole, so lips closed over it cost nothing
there; every scan point has a counterpart on a right model. Measured on the two scans above: S2 0.115 h
(right) vs 0.171 (rolled lip); 0.081 (right) vs 0.130-0.137 (half closed).

Measured (``problems.bench_mouth_basin``, reports/registration/mouth_basin: 9 mouth scans x ICT persons of seeds
0-4, in the identity space and with detail outside it): 0 of 90 scans over median 0.05 / p95 0.2 cm (pairs from
the first round: 2; no pairs: 9), worst p95 0.127 cm; CPU per scan median 6.6 s, max 10.0 s (load 13-27; the
joint schedule 5.0 / 8.3 s at load 7-32). Eq. S2 kept the continued fit on 87 of 90; on 15 (opened jaws) the
kept fit's face p95 before the regional stage was 0.01-0.05 cm above the other's, where the two S2 differed by
under 10 %: the regional stage then brought both within the targets.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import parameter_error
from .scanpairs import ScanToModel
from .shapemodel import ModelFit, ModelFitOptions, fit_shape_model

SCHEDULES = ("after", "joint")  #: values of :func:`whole_expression_fit`'s ``schedule``
CAP = 2.0  #: eq. S2's residuals are capped at this many ``h``
#: the continued fit is kept if its eq. S2 is below this fraction of the one-sided fit's. A margin of 0.9 (between
#: two right fits S2 differs by noise, and the continued fit minimised it on a correlated sample) kept the one-sided
#: fit in a wrong basin on 3 of 90 mouth scans whose S2 differed by only 4-10 % (reports/registration/
#: mouth_basin_final at fa5e20b: seed 4 in-space mouthClose whole-fit p95 0.594 against 0.121 cm), so none is used
MARGIN = 1.0


def check_schedule(schedule) -> str:
    """``schedule`` if it is one of :data:`SCHEDULES`, else a one-line error naming the option."""
    if not isinstance(schedule, str) or schedule not in SCHEDULES:
        raise parameter_error("expression_pairs_schedule", f"one of {', '.join(SCHEDULES)}", repr(schedule))
    return schedule


def scan_unexplained(X: np.ndarray, normals: np.ndarray, pairs: ScanToModel, h: float) -> float:
    """Eq. S2 in units of ``h``: the capped RMS point-to-plane residual of the scan sample's kept pairs with
    the model at ``X`` (n, 3), unit vertex normals ``normals`` (n, 3); inf without any pair."""
    i, Q, N = pairs.pairs(X, normals)
    if not len(i):
        return float("inf")
    r = np.minimum(np.abs(((X[i] - Q) * N).sum(1)), CAP * h)
    return float(np.sqrt(np.mean(r ** 2)) / h)


def whole_expression_fit(base: np.ndarray, expressions, surface, normals_of, h: float, options: ModelFitOptions,
                         bounds, use=None, schedule: str = "after") -> tuple[ModelFit, dict]:
    """The whole-expression fit of an expression scan with the scan pairs joining by ``schedule`` (module
    docstring).

    Parameters
    ----------
    base, expressions, surface, normals_of, h, bounds, use : as :func:`.shapemodel.fit_shape_model`
    options : its options; ``scan_pairs`` 0: the model-to-scan fit alone (any schedule)
    schedule : ``"after"`` or ``"joint"``

    Returns
    -------
    (fit, info): ``info`` has ``schedule``, and with ``"after"`` and scan pairs ``s2`` (eq. S2 of the
    model-to-scan fit and of the continued fit, in ``h``), ``kept`` (``"continued"`` or ``"one-sided"``) and
    ``fits`` (both fits)
    """
    check_schedule(schedule)
    if schedule == "joint" or not options.scan_pairs:
        return fit_shape_model(base, expressions, surface, normals_of, h, options, bounds=bounds, use=use), {
            "schedule": schedule if options.scan_pairs else "one-sided"}
    first = fit_shape_model(base, expressions, surface, normals_of, h, dataclasses.replace(options, scan_pairs=0),
                            bounds=bounds, use=use)
    then = fit_shape_model(base, expressions, surface, normals_of, h, options, bounds=bounds, use=use,
                           c0=first.coefficients)
    # another seeded sample of the scan than the fit's pairs (seed + 2; the same points when the scan has no more
    # vertices than scan_pairs: then the whole scan is both samples)
    pairs = ScanToModel(surface, np.arange(len(base)) if use is None else use, dataclasses.replace(options, seed=options.seed + 1), h)
    s2 = [scan_unexplained(f.vertices, normals_of(f.vertices), pairs, h) for f in (first, then)]
    keep = 1 if s2[1] < MARGIN * s2[0] else 0
    return (first, then)[keep], {"schedule": schedule, "s2": s2, "kept": ("one-sided", "continued")[keep],
                                 "fits": (first, then)}
