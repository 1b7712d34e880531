"""Automatic regularisation of example-based generation: k-fold cross-validation of alpha.

``GenerationOptions(alpha="auto")`` (``facebasis rig --alpha auto``) chooses the alpha schedule of
eq. 4 (Gao et al. 2015) from the training expressions themselves:

* the training expressions are split into ``cv_folds`` interleaved folds (example j in fold
  ``j mod K``);
* for every fold, a rig is generated from the other folds for every candidate final alpha ``a``
  of ``cv_grid``, in one of two ways (``cv_candidates``), and the final run on all training
  expressions is made *the same way* for the chosen alpha, so that the curve scores the
  procedure whose result is returned:

  - ``"coarse"`` (default): the path and the scores of ``"deletion"`` below with fewer folds
    where candidates are far apart (:func:`~facebasis.rigging.cvpath.cross_validate_coarse`):
    while the path runs, every other candidate (about 10x apart on the default grid) is scored on
    the first half of the folds (the largest, transfer in effect, only if the curve still falls
    towards it) and the path stops once :data:`PATIENCE` scored candidates in a row are above the
    best; then the best and its two neighbours are scored on every fold and the lowest is chosen.
    The path passes the candidates above the first one scored (transfer in effect) with one
    alternation each. The rig returned is the path's at the chosen alpha. On ICT persons (m = 20,
    80; ``python -m problems.bench_cv``, ``reports/examples_study/cv_speed.csv``, a loaded machine)
    it cost 1.1-2.6x the default run's CPU time against 1.7-3.9x for ``"deletion"``, with
    deletion's alpha and held-out error in 5 of 6 cases (the sixth: 0.1 for 0.03, held-out error
    +1.6%);
  - ``"deletion"``: one warm-started path (as ``"path"`` below, but the largest
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

import numpy as np

from ..errors import parameter_error
from .cvcurve import CANDIDATE_MODES, DEFAULT_GRID, SCHEDULE_RATIO, CrossValidation
from .cvpath import cross_validate_coarse, cross_validate_deletion
from .heldout import check_folds, fold_labels, heldout_error_parts


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
    if candidates in ("coarse", "deletion"):
        run = cross_validate_coarse if candidates == "coarse" else cross_validate_deletion
        return run(generator, grid, labels, chain, progress, t0, c0)
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


__all__ = ["cross_validate_alpha"]
