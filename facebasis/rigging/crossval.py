"""Automatic regularisation of example-based generation: k-fold cross-validation of alpha.

``GenerationOptions(alpha="auto")`` (``facebasis rig --alpha auto``) chooses the alpha schedule of
eq. 4 (Gao et al. 2015) from the training expressions themselves:

* the training expressions are split into ``cv_folds`` interleaved folds (example j in fold
  ``j mod K``);
* for every fold, a rig is generated from the other folds for every candidate final alpha ``a``
  of ``cv_grid``, in one of two ways (``cv_candidates``), and the final run on all training
  expressions is made *the same way* for the chosen alpha, so that the curve scores the
  procedure whose result is returned:

  - ``"path"`` (default): one warm-started regularisation path per fold, as the paper's own
    schedule is a continuation: the largest candidate with the full schedule ``(5 a, a)`` (the
    paper's ratio 0.5 -> 0.1), then each next smaller one with ``cv_chain_iterations``
    alternations at its own final alpha from the previous one's weights. The final run follows
    the path on all training expressions down to the chosen alpha (:meth:`CrossValidation.final_schedule`);
  - ``"cold"``: every candidate from the rough weights with its own full schedule ``(5 a, a)``,
    so no candidate depends on the others (about ``len(grid) * iterations / (iterations +
    chain * (len(grid) - 1))`` times the cost of ``"path"``); the final run is that schedule;
  - ``"both"``: the two curves (the largest candidate's rig is shared); the procedure whose curve
    has the lower minimum is chosen with its alpha (the procedure is a hyperparameter too);

  (the earlier form scored the path but returned the fresh schedule of the chosen alpha: on ICT
  person problems the path's small alphas had more alternations behind them than that final run,
  and its choice was not the best for the rig it returned; ``reports/examples_study/cv_fix.md``);
* each rig is scored on the held-out fold by refitting weights (bounds + complementarity, no
  prior; the certified optimum) and measuring ``||B_0 + B x - T|| / ||T - B_0||``;
* the curve is the error pooled over the folds per candidate; the smallest wins.

All folds share the template's precompute (transfer, prior, regulariser weights) through
:meth:`~facebasis.rigging.generation.BlendshapeGenerator.subset`; the weight steps of the
cross-validation use the certified solver only (IPOPT would give the same optimum, slower).

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .certify import certify_problem
from .weightproblem import WeightProblem

#: default candidate final alphas (the paper's 0.1 among them; >= 100 is plain transfer in effect)
DEFAULT_GRID = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0)

#: ratio first/last alpha of a candidate schedule (the paper's 0.5 -> 0.1)
SCHEDULE_RATIO = 5.0

#: how the candidates of a fold are generated (module docstring)
CANDIDATE_MODES = ("path", "cold", "both")


@dataclass(frozen=True)
class CrossValidation:
    """The cross-validation curve behind ``alpha="auto"``.

    grid : candidate final alphas (ascending); errors : pooled held-out relative error per
    candidate; fold_errors : (folds, candidates) per fold; best_alpha, schedule : the choice and
    its schedule (first, last); folds : fold of every training expression; candidates : ``"path"``
    or ``"cold"`` (module docstring), the procedure chosen; curves : the pooled curve of every
    procedure tried (``"both"`` tries the two); seconds : wall time; rigs_generated : rigs built
    (folds x candidates).
    """

    grid: tuple[float, ...]
    errors: tuple[float, ...]
    fold_errors: tuple[tuple[float, ...], ...]
    best_alpha: float
    schedule: tuple[float, float]
    folds: tuple[int, ...]
    chain_iterations: int
    seconds: float
    cpu_seconds: float
    candidates: str = "path"
    curves: dict = dataclasses.field(default_factory=dict)

    @property
    def rigs_generated(self) -> int:
        """Rigs built by the cross-validation: one per fold and candidate, and with ``"both"`` the
        cold candidates too (the largest candidate's rig is shared by both procedures)."""
        per_fold = 2 * len(self.grid) - 1 if len(self.curves) > 1 else len(self.grid)
        return len(self.fold_errors) * per_fold

    def final_schedule(self, options) -> list[tuple[float, float]]:
        """The (alpha, lambda) of every alternation of the final run on all training expressions:
        what the curve scored for :attr:`best_alpha` (``options`` give ``iterations`` and lambda).

        ``"cold"``: the schedule ``(5 a, a)``; ``"path"``: the schedule of the largest candidate,
        then ``chain_iterations`` alternations at every next smaller candidate down to ``a``, at the
        last lambda.
        """
        if self.candidates == "cold":
            return dataclasses.replace(options, alpha=self.schedule).schedule()
        top = self.grid[-1]
        out = dataclasses.replace(options, alpha=(SCHEDULE_RATIO * top, top)).schedule()
        lam_last = float(options.lam[1])
        for a in self.grid[-2::-1]:
            if a < self.best_alpha:
                break
            out += [(a, lam_last)] * self.chain_iterations
        return out

    def to_json(self) -> dict:
        how = {"cold": "each candidate a from the rough weights with the schedule 5a -> a",
               "path": "candidates along one warm-started path from the largest (schedule 5a -> a), then "
                       f"{self.chain_iterations} alternations at each next smaller alpha; the final run follows "
                       "that path down to the chosen alpha",
               }
        what = how.get(self.candidates, self.candidates)
        if len(self.curves) > 1:
            what = f"both procedures tried, the curve with the lower minimum kept: {what}"
        return {"method": f"k-fold cross-validation of the final alpha ({what}), "
                          "held-out error with refitted weights (bounds + complementarity, no prior)",
                "grid": list(self.grid), "errors": list(self.errors),
                "fold_errors": [list(r) for r in self.fold_errors], "best_alpha": self.best_alpha,
                "schedule": list(self.schedule), "folds": list(self.folds),
                "candidates": self.candidates, "curves": {k: list(v) for k, v in self.curves.items()},
                "chain_iterations": self.chain_iterations, "seconds": self.seconds,
                "cpu_seconds": self.cpu_seconds}


def heldout_error_parts(rig, expressions, pairs=()) -> tuple[float, float]:
    """(``||B_0 + B x - T||^2``, ``||T - B_0||^2``) summed over expressions (h, n, 3), with weights
    refitted by the certified solver (bounds + complementarity, no prior): the terms of
    :func:`~facebasis.rigging.generation.reproduction_error`."""
    problem = WeightProblem.from_rig(rig, expressions, pairs)
    return max(float(certify_problem(problem).objective), 0.0), float(problem.const.sum())


def heldout_error(rig, expressions, pairs=()) -> float:
    """Relative reproduction error of ``expressions`` by ``rig`` with refitted weights (certified)."""
    num, den = heldout_error_parts(rig, expressions, pairs)
    return float(np.sqrt(num / den))


def fold_labels(m: int, folds: int) -> np.ndarray:
    """Interleaved folds: training expression j in fold ``j mod folds``."""
    return np.arange(m) % folds


def cross_validate_alpha(generator, grid=None, folds: int | None = None, chain_iterations: int | None = None,
                         progress=None, candidates: str | None = None) -> CrossValidation:
    """Choose the final alpha by k-fold cross-validation (module docstring) on ``generator``'s problem.

    Parameters
    ----------
    generator : :class:`~facebasis.rigging.generation.BlendshapeGenerator` of all training expressions
    grid, folds, chain_iterations, candidates : default to the generator's options (``cv_grid`` or
        :data:`DEFAULT_GRID`, ``cv_folds``, ``cv_chain_iterations``, ``cv_candidates``)
    progress : optional callable(fold, alpha, error) after every rig

    Raises
    ------
    InputError
        fewer training expressions than folds (before any solving)
    """
    t0, c0 = time.perf_counter(), time.process_time()
    opts = generator.options
    grid = tuple(sorted(float(a) for a in (grid or opts.cv_grid or DEFAULT_GRID)))
    folds = int(folds or opts.cv_folds)
    chain = int(chain_iterations or opts.cv_chain_iterations)
    candidates = candidates or opts.cv_candidates
    if candidates not in CANDIDATE_MODES:
        raise InputError(f"cv_candidates: expected one of {', '.join(CANDIDATE_MODES)}, found {candidates!r}")
    m = len(generator.problem.examples)
    if m < folds:
        raise InputError(f"--alpha auto: expected at least {folds} training expressions for {folds}-fold "
                         f"cross-validation, found {m}")
    if any(a <= 0 for a in grid):
        raise InputError(f"cv_grid: expected final alphas > 0, found {grid}")
    labels = fold_labels(m, folds)
    lam_last = float(opts.lam[1])
    # the cross-validation's own runs: certified weights only, the candidate's schedule
    base = dataclasses.replace(opts, alpha=(SCHEDULE_RATIO * grid[-1], grid[-1]), ipopt="never")
    modes = ("path", "cold") if candidates == "both" else (candidates,)
    num = {mode: np.zeros((folds, len(grid))) for mode in modes}
    den = np.zeros(folds)
    pairs = generator.pairs
    for f in range(folds):
        train, held = np.flatnonzero(labels != f), np.flatnonzero(labels == f)
        sub = generator.subset(train).with_options(base)
        T_held = generator.problem.examples[held]

        def score(mode, c, res):
            num[mode][f, c], den[f] = heldout_error_parts(res.rig, T_held, pairs)
            if progress is not None:
                progress(f, grid[c], float(np.sqrt(num[mode][f, c] / den[f])))

        top = sub.run()  # the largest alpha with its full schedule: the same rig in both modes
        for mode in modes:
            score(mode, len(grid) - 1, top)
        X = top.weights
        for c in range(len(grid) - 2, -1, -1):  # then downwards
            a = grid[c]
            if "path" in modes:  # warm-started from the previous candidate
                res = sub.run(X0=X, schedule=[(a, lam_last)] * chain)
                X = res.weights
                score("path", c, res)
            if "cold" in modes:  # from the rough weights, its own schedule
                score("cold", c, sub.with_options(dataclasses.replace(base, alpha=(SCHEDULE_RATIO * a, a))).run())
    curves = {mode: np.sqrt(num[mode].sum(0) / den.sum()) for mode in modes}
    mode = min(modes, key=lambda mo: float(curves[mo].min()))  # "both": the procedure with the lower minimum
    errors = curves[mode]
    best = int(np.argmin(errors))
    a = grid[best]
    return CrossValidation(grid=grid, errors=tuple(map(float, errors)),
                           fold_errors=tuple(tuple(map(float, np.sqrt(num[mode][f] / den[f]))) for f in range(folds)),
                           best_alpha=a, schedule=(SCHEDULE_RATIO * a, a), folds=tuple(map(int, labels)),
                           chain_iterations=chain, seconds=time.perf_counter() - t0,
                           cpu_seconds=time.process_time() - c0, candidates=mode,
                           curves={mo: tuple(map(float, cu)) for mo, cu in curves.items()})


__all__ = ["CrossValidation", "cross_validate_alpha", "heldout_error", "heldout_error_parts", "fold_labels",
           "DEFAULT_GRID", "SCHEDULE_RATIO", "CANDIDATE_MODES"]
