"""The cross-validation curve of ``alpha="auto"`` (:class:`CrossValidation`) and the settings of
its procedures (:mod:`facebasis.rigging.crossval` describes them)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .problem import CV_CANDIDATES

#: default candidate final alphas (the paper's 0.1 among them; >= 100 is plain transfer in effect)
DEFAULT_GRID = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0)

#: ratio first/last alpha of a candidate schedule (the paper's 0.5 -> 0.1)
SCHEDULE_RATIO = 5.0

#: how the candidates are generated and scored (module docstring)
CANDIDATE_MODES = CV_CANDIDATES

#: ``"deletion"``: the path stops once this many consecutive candidates score above the best so far
PATIENCE = 2

#: ``"deletion"``: at most this many alternations of the largest candidate's schedule (its rig is
#: transfer in effect, and its weights settle in a few): on ICT persons (m = 20 seeds 0, 1; m = 80
#: seed 2) 3 instead of 10 chose the same alpha with the same held-out error to 4 digits, 20% less CPU
TOP_ITERATIONS = 3


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
    #: ``"deletion"``: the path's state at the chosen alpha (weights entering its last alternation,
    #: the records of the alternations before it), so the final run is that one alternation
    final_state: object = dataclasses.field(default=None, compare=False, repr=False)
    #: ``"deletion"``: the candidates the path went through (ascending; :attr:`grid` those scored)
    path: tuple[float, ...] = ()
    #: alternations of the largest candidate's schedule (None: the options' ``iterations``)
    top_iterations: int | None = None
    #: ``"coarse"``: the first folds, those every scored candidate was scored on (:attr:`errors` pools
    #: them); the finalists were scored on every fold (NaN in :attr:`fold_errors` where not scored)
    coarse_folds: int | None = None
    #: ``"coarse"``: the pooled error of the chosen alpha over every fold (what it was chosen by)
    chosen_error: float | None = None
    #: ``"coarse"``: candidates the path passes with one alternation instead of ``chain_iterations``
    quick_alphas: tuple[float, ...] = ()

    @property
    def best_error(self) -> float:
        """The pooled held-out error of the chosen alpha (on every fold)."""
        return float(self.errors[self.grid.index(self.best_alpha)]) if self.chosen_error is None else self.chosen_error

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
        # "path" and "deletion": the same warm-started path
        path = self.path or self.grid
        top = path[-1]
        out = dataclasses.replace(options, alpha=(SCHEDULE_RATIO * top, top),
                                  iterations=self.top_iterations or options.iterations).schedule()
        lam_last = float(options.lam[1])
        for a in path[-2::-1]:
            if a < self.best_alpha:
                break
            out += [(a, lam_last)] * (1 if a in self.quick_alphas else self.chain_iterations)
        return out

    def to_json(self) -> dict:
        how = {"cold": "each candidate a from the rough weights with the schedule 5a -> a",
               "path": "candidates along one warm-started path from the largest (schedule 5a -> a), then "
                       f"{self.chain_iterations} alternations at each next smaller alpha; the final run follows "
                       "that path down to the chosen alpha",
               "deletion": "one warm-started path on all training expressions from the largest candidate "
                           f"(schedule 5a -> a, {self.top_iterations} alternations), then "
                           f"{self.chain_iterations} alternations at each next smaller alpha; each candidate "
                           "scored by deleting each fold from its last basis step (exact refit of eq. 4 at the "
                           "path's weights), every other candidate on the way down and the best's neighbour "
                           "towards its better coarse neighbour; the path stops once "
                           f"{PATIENCE} scored candidates in a row are above the best; the returned rig is the "
                           "path's at the chosen alpha",
               "coarse": "one warm-started path on all training expressions from the largest candidate "
                         f"(schedule 5a -> a, {self.top_iterations} alternations), then {self.chain_iterations} "
                         "alternations at each next smaller alpha; every other candidate scored by deleting each "
                         "fold from its last basis step (exact refit of eq. 4 at the path's weights) on the first "
                         f"{self.coarse_folds} folds while the path runs (the largest only if the curve still falls "
                         f"towards it; the path stops once {PATIENCE} scored candidates in a row are above the "
                         "best), then the best and its two neighbours on every fold, the lowest chosen; the "
                         "returned rig is the path's at the chosen alpha",
               }
        what = how.get(self.candidates, self.candidates)
        if len(self.curves) > 1:
            what = f"both procedures tried, the curve with the lower minimum kept: {what}"
        return {"method": f"k-fold cross-validation of the final alpha ({what}), "
                          "held-out error with refitted weights (bounds + complementarity, no prior)",
                "grid": list(self.grid), "errors": list(self.errors),
                "fold_errors": [[None if e != e else e for e in r] for r in self.fold_errors],
                "best_alpha": self.best_alpha,
                "schedule": list(self.schedule), "folds": list(self.folds),
                "candidates": self.candidates, "curves": {k: list(v) for k, v in self.curves.items()},
                "chain_iterations": self.chain_iterations, "seconds": self.seconds,
                **({"path": list(self.path)} if self.path else {}),
                **({"coarse_folds": self.coarse_folds, "chosen_error": self.chosen_error,
                    "quick_alphas": list(self.quick_alphas)} if self.coarse_folds is not None else {}),
                "cpu_seconds": self.cpu_seconds}


__all__ = ["CrossValidation", "DEFAULT_GRID", "SCHEDULE_RATIO", "CANDIDATE_MODES", "PATIENCE", "TOP_ITERATIONS"]
