"""Automatic regularisation of example-based generation: k-fold cross-validation of alpha.

``GenerationOptions(alpha="auto")`` (``facebasis rig --alpha auto``) chooses the alpha schedule of
eq. 4 (Gao et al. 2015) from the training expressions themselves:

* the training expressions are split into ``cv_folds`` interleaved folds (example j in fold
  ``j mod K``);
* for every fold, a rig is generated from the other folds for every candidate final alpha ``a``
  of ``cv_grid``, in one of two ways (``cv_candidates``), and the final run on all training
  expressions is made *the same way* for the chosen alpha, so that the curve scores the
  procedure whose result is returned:

  - ``"deletion"`` (default): one warm-started path (as ``"path"`` below, but the largest
    candidate's schedule cut to :data:`TOP_ITERATIONS` alternations) on *all* training
    expressions; candidate ``a`` is scored by deleting each fold from the basis step of its last
    alternation, i.e. eq. 4 solved again on the other folds at the weights the path gave them, then
    reconstructed and scored on the held-out fold like the others. Per triangle this is the
    fold-deletion identity of ridge regression, ``Y_-f = Y - M^-1 X_f (I - H_ff)^-1 e_f``
    (:func:`~facebasis.rigging.basis.fold_deletion_rows` computes it in closed form from the full
    fit); with k = 53 shapes and 15-60 expressions per fold the closed form costs more than solving
    the smaller systems again (ICT, 28,068 triangles, one thread, CPU s for 4 folds: 1.36 vs 0.78 at
    m = 20, 8.1 vs 2.2 at m = 80), so the scores solve them explicitly. Exact for the basis step;
    the weights of the other folds are the path's on all expressions (fitted with fold f's rows in
    the previous basis steps), the one approximation against ``"path"``. The path is scored on
    every other candidate going down, stops once :data:`PATIENCE` scored candidates in a row are
    above the best, and the best's neighbour on the side of its better coarse neighbour is then
    scored too; the rig returned is the
    path's at the chosen alpha (no separate final run: only its last alternation is made again,
    with IPOPT as ``ipopt`` says). Cost: the path (``iterations + chain x (candidates - 1)``
    alternations on all expressions) plus, per scored candidate, ``folds`` basis steps and
    reconstructions on 3/4 of the expressions, against ``folds`` whole paths and the final run
    for ``"path"``;
  - ``"path"``: one warm-started regularisation path per fold, as the paper's own
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

from ..errors import InputError, parameter_error
from .certify import certify_problem
from .problem import CV_CANDIDATES
from .weightproblem import WeightProblem

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
            out += [(a, lam_last)] * self.chain_iterations
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
                **({"path": list(self.path)} if self.path else {}),
                "cpu_seconds": self.cpu_seconds}


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
        raise parameter_error("cv_candidates", f"one of {', '.join(CANDIDATE_MODES)}", repr(candidates))
    m = len(generator.problem.examples)
    check_folds(m, folds)
    if any(a <= 0 for a in grid):
        raise parameter_error("cv_grid", "final alphas > 0", grid)
    labels = fold_labels(m, folds)
    if candidates == "deletion":
        return _cross_validate_deletion(generator, grid, labels, chain, progress, t0, c0)
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


def _cross_validate_deletion(generator, grid, labels, chain, progress, t0, c0) -> CrossValidation:
    """``cv_candidates="deletion"`` (module docstring): one path on all training expressions, each
    candidate scored by fold deletion of its last basis step; stops after :data:`PATIENCE`
    candidates in a row above the best."""
    from concurrent.futures import ThreadPoolExecutor

    from threadpoolctl import threadpool_limits

    from ..geometry.rig import Rig
    from ..workers import available_cores
    from .basis import basis_rows

    opts = generator.options
    p = generator.problem
    folds = int(labels.max()) + 1
    lam_last = float(opts.lam[1])
    top_its = min(TOP_ITERATIONS or opts.iterations, int(opts.iterations))
    base = dataclasses.replace(opts, alpha=(SCHEDULE_RATIO * grid[-1], grid[-1]), ipopt="never", iterations=top_its)
    gen = generator.with_options(base)  # the same free shapes (unobserved and support unchanged)
    held = [np.flatnonzero(labels == f) for f in range(folds)]
    train = [np.flatnonzero(labels != f) for f in range(folds)]
    R_train = [np.ascontiguousarray(generator.R[:, :, t]) for t in train]  # the training rows of every fold, once
    T_held = [p.examples[h] for h in held]
    X = p.initial_weights.copy()
    if gen.free is not None:
        X[:, ~gen.free] = 0.0
    workers = opts.threads or available_cores()
    pool = ThreadPoolExecutor(workers) if workers > 1 else None
    den = np.zeros(folds)
    history = []
    states, scores, rows_buf = {}, {}, [None]

    def score(c):  # fold f deleted from candidate c's last basis step: eq. 4 on the other folds
        a, X_in = grid[c], states[c][0]
        nums = np.zeros(folds)
        for f in range(folds):
            with threadpool_limits(1):
                rows_buf[0], _, _ = basis_rows(X_in[train[f]].T, R_train[f], gen.A_tilde, gen.w, a, executor=pool,
                                               out=rows_buf[0])
            rig = Rig(p.target_neutral, p.template.faces, p.template.names, gen.deltas_of(gen.reconstruct(rows_buf[0])))
            nums[f], den[f] = heldout_error_parts(rig, T_held[f], generator.pairs)
            if progress is not None:
                progress(f, a, float(np.sqrt(nums[f] / den[f])))
        scores[c] = nums
        return float(np.sqrt(nums.sum() / den.sum()))

    top = len(grid) - 1
    try:
        best_err, worse = np.inf, 0
        for c in range(top, -1, -1):  # down the path
            sched = base.schedule() if c == top else [(grid[c], lam_last)] * chain
            if len(sched) > 1:
                h, X, _ = gen._iterate(X, sched[:-1], pool, None)
                history += h
            states[c] = (X, len(history))  # the weights of the candidate's last basis step, alternations before it
            h, X, _ = gen._iterate(X, sched[-1:], pool, None)
            history += h
            if (top - c) % 2 and c > 0:  # coarse pass: every other candidate (and the smallest)
                continue
            err = score(c)
            if err < best_err:
                best_err, worse = err, 0
            else:
                worse += 1
                if worse >= PATIENCE:
                    break
        b = min(scores, key=lambda c: scores[c].sum())
        # refined around the coarse minimum, on the side of its better coarse neighbour (one scoring)
        sides = [c for c in (b - 1, b + 1) if c in states and c not in scores]
        if len(sides) == 2:
            err = {c: scores[c + (c - b)].sum() if c + (c - b) in scores else np.inf for c in sides}
            sides = [min(sides, key=lambda c: err[c])]
        for c in sides:
            score(c)
    finally:
        if pool is not None:
            pool.shutdown()
    scored = sorted(scores)  # ascending alpha
    num = np.array([scores[c] for c in scored])  # (scored, folds)
    g = tuple(grid[c] for c in scored)
    errors = np.sqrt(num.sum(1) / den.sum())
    b = scored[int(np.argmin(errors))]
    a = grid[b]
    X_in, n_before = states[b]
    done = tuple(dataclasses.replace(r, iteration=i + 1) for i, r in enumerate(history[:n_before]))
    return CrossValidation(grid=g, errors=tuple(map(float, errors)),
                           fold_errors=tuple(tuple(map(float, np.sqrt(num[:, f] / den[f]))) for f in range(folds)),
                           best_alpha=a, schedule=(SCHEDULE_RATIO * a, a), folds=tuple(map(int, labels)),
                           chain_iterations=chain, seconds=time.perf_counter() - t0,
                           cpu_seconds=time.process_time() - c0, candidates="deletion",
                           curves={"deletion": tuple(map(float, errors))},
                           path=tuple(grid[c] for c in sorted(states)),
                           final_state={"X": X_in, "history": done}, top_iterations=top_its)


__all__ = ["CrossValidation", "cross_validate_alpha", "heldout_error", "heldout_error_parts", "refit_heldout",
           "fold_labels",
           "check_folds", "DEFAULT_GRID", "SCHEDULE_RATIO", "CANDIDATE_MODES"]
