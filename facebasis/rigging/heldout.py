"""The one held-out error of example-based generation, and the folds of cross-validation.

A rig is scored on expressions it was not made from by refitting their weights (eq. 5 of Gao et
al. 2015 with bounds and complementarity, no prior: the certified optimum of
:func:`~facebasis.rigging.certify.certify_problem`, no IPOPT model built) and measuring the
vertex residual ``||B_0 + B x - T|| / ||T - B_0||``. The cross-validation of ``alpha="auto"``
(:mod:`facebasis.rigging.crossval`), the studies and the benchmarks all use :func:`heldout_error`.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .certify import certify_problem
from .weightproblem import WeightProblem


def refit_heldout(rig, expressions, pairs=()) -> np.ndarray:
    """Weights (h, k) of expressions (h, n, 3) refitted to ``rig``: the certified optimum of eq. 5
    with bounds and complementarity, no prior (:func:`~facebasis.rigging.certify.certify_problem`;
    no IPOPT model is built)."""
    return certify_problem(WeightProblem.from_rig(rig, expressions, pairs)).X


def heldout_error_parts(rig, expressions, pairs=()) -> tuple[float, float]:
    """(``||B_0 + B x - T||^2``, ``||T - B_0||^2``) summed over expressions (h, n, 3), with weights
    refitted by :func:`refit_heldout`: the terms of :func:`heldout_error`, to pool over folds."""
    E = np.asarray(expressions, np.float64)
    X = refit_heldout(rig, E, pairs)
    return float(np.sum((rig.evaluate(X) - E) ** 2)), float(np.sum((E - rig.neutral) ** 2))


def heldout_error(rig, expressions, pairs=()) -> float:
    """How well ``rig`` reproduces expressions (h, n, 3) with refitted weights (:func:`refit_heldout`):
    ``||B_0 + B x - T|| / ||T - B_0||`` over all of them. The one held-out error of the package (the
    cross-validation curve, the studies, the benchmarks); it compares rigs fairly, since a shape's
    amplitude and its weight trade off (method.md A)."""
    E = np.asarray(expressions, np.float64)
    X = refit_heldout(rig, E, pairs)
    return float(np.linalg.norm(rig.evaluate(X) - E) / np.linalg.norm(E - rig.neutral))


def check_folds(m: int, folds: int) -> None:
    """The one check that ``m`` training expressions allow ``folds``-fold cross-validation (made by
    :func:`cross_validate_alpha`, and by an application before any solving starts).

    Raises
    ------
    InputError
        ``m < folds`` (fields ``alpha``, ``cv_folds``: "alpha auto: expected at least 4 training
        expressions for 4-fold cross-validation (cv_folds), found 3")
    """
    if m < folds:
        raise InputError(what="{alpha} auto", expected=f"at least {folds} training expressions for {folds}-fold "
                                                         "cross-validation ({cv_folds})", found=m,
                         params={"alpha": "alpha", "cv_folds": "cv_folds"})


def fold_labels(m: int, folds: int) -> np.ndarray:
    """Interleaved folds: training expression j in fold ``j mod folds``."""
    return np.arange(m) % folds


__all__ = ["refit_heldout", "heldout_error_parts", "heldout_error", "check_folds", "fold_labels"]
