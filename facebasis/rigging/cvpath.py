"""The path procedures of ``alpha="auto"`` (:mod:`facebasis.rigging.crossval`): one warm-started
regularisation path on all training expressions, every scored candidate scored by deleting each
fold from its last basis step (``"deletion"``, ``"coarse"``)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .cvcurve import PATIENCE, SCHEDULE_RATIO, TOP_ITERATIONS, CrossValidation
from .heldout import heldout_error_parts


def cross_validate_deletion(generator, grid, labels, chain, progress, t0, c0) -> CrossValidation:
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



#: ``"coarse"``: while the path runs, every ``COARSE_STEP``-th candidate of the grid from the largest
#: (the smallest always) is scored, about 10x apart in alpha on the default grid
COARSE_STEP = 2

#: ``"coarse"``: the largest coarse candidates (on the default grid 100 and 3, transfer in effect)
#: are scored only if the best is the largest candidate scored, upwards
LAZY_COARSE = 2


class _Path:
    """The warm-started path of ``"coarse"``: candidates visited from a previous one (or from the
    rough weights), each candidate's last alternation made only when something continues from it,
    fold scores kept per candidate and fold (NaN until scored)."""

    def __init__(self, gen, grid, labels, chain, lam_last, progress, pool, quick=()):
        from threadpoolctl import threadpool_limits

        self.gen, self.grid, self.labels, self.progress, self.pool = gen, grid, labels, progress, pool
        self._limits = threadpool_limits
        self.top = len(grid) - 1
        self.top_schedule = gen.options.schedule()
        self.chain, self.lam_last, self.quick = chain, lam_last, set(quick)
        folds = int(labels.max()) + 1
        self.train = [np.flatnonzero(labels != f) for f in range(folds)]
        self.R_train = [np.ascontiguousarray(gen.R[:, :, t]) for t in self.train]
        self.T_held = [gen.problem.examples[labels == f] for f in range(folds)]
        X = gen.problem.initial_weights.copy()
        if gen.free is not None:
            X[:, ~gen.free] = 0.0
        self.start = X
        self.states, self.ends, self.nums = {}, {}, {}   # c -> (X_in, records, route), (X_end, records), (folds,)
        self.den = np.full(folds, np.nan)
        self.rows = None

    def schedule(self, c):
        if c == self.top:
            return self.top_schedule
        return [(self.grid[c], self.lam_last)] * (1 if c in self.quick else self.chain)

    def visit(self, c, after=None) -> None:
        """Go to candidate c from the end of candidate ``after`` (None: from the rough weights), up to
        the weights entering c's last alternation (the weights its score deletes folds at)."""
        X, recs = (self.start, []) if after is None else self.end(after)
        route = () if after is None else self.states[after][2]
        sched = self.schedule(c)
        if len(sched) > 1:
            h, X, _ = self.gen._iterate(X, sched[:-1], self.pool, None)
            recs = recs + h
        self.states[c] = (X, recs, route + (c,))

    def end(self, c):
        """(weights, records) after candidate c's last alternation, made once when first needed."""
        if c not in self.ends:
            X, recs, _ = self.states[c]
            h, X, _ = self.gen._iterate(X, self.schedule(c)[-1:], self.pool, None)
            self.ends[c] = (X, recs + h)
        return self.ends[c]

    def score(self, c, folds) -> None:
        """Fold f deleted from candidate c's last basis step (eq. 4 on the other folds at the path's
        weights), reconstructed and scored on fold f (:func:`heldout_error_parts`), for ``folds``."""
        from ..geometry.rig import Rig
        from .basis import basis_rows

        gen, p, a = self.gen, self.gen.problem, self.grid[c]
        X_in = self.states[c][0]
        nums = self.nums.setdefault(c, np.full(len(self.den), np.nan))
        for f in folds:
            if not np.isnan(nums[f]):
                continue
            with self._limits(1):
                self.rows, _, _ = basis_rows(X_in[self.train[f]].T, self.R_train[f], gen.A_tilde, gen.w, a,
                                             executor=self.pool, out=self.rows)
            rig = Rig(p.target_neutral, p.template.faces, p.template.names, gen.deltas_of(gen.reconstruct(self.rows)))
            nums[f], self.den[f] = heldout_error_parts(rig, self.T_held[f], gen.pairs)
            if self.progress is not None:
                self.progress(f, a, float(np.sqrt(nums[f] / self.den[f])))

    def error(self, c, folds=None) -> float:
        """Pooled held-out error of c over ``folds`` (default: every fold scored for c)."""
        nums = self.nums[c]
        idx = np.flatnonzero(~np.isnan(nums)) if folds is None else np.asarray(folds)
        return float(np.sqrt(nums[idx].sum() / self.den[idx].sum()))

    def complete(self, c) -> bool:
        return c in self.nums and not np.isnan(self.nums[c]).any()


def cross_validate_coarse(generator, grid, labels, chain, progress, t0, c0) -> CrossValidation:
    """``cv_candidates="coarse"`` (the default; :mod:`facebasis.rigging.crossval`): the path and the
    deletion scores of ``"deletion"``, fewer folds where candidates are far apart.

    1. The path runs through every candidate from the largest, as in ``"deletion"``, with one
       alternation (not ``chain``) at each candidate between the largest and the first one scored
       (the lazy ones below; on the default grid 10, 3 and 1, transfer in effect). Every
       :data:`COARSE_STEP`-th one (the smallest always) is scored on the first half of the folds,
       the :data:`LAZY_COARSE` largest of those (plain transfer in effect) only if the best is the
       largest scored one (upwards); the path stops after :data:`PATIENCE` scored candidates in a
       row above the best.
    2. The best and its two neighbours on the grid (the path's, the one below visited now if the
       path stopped at the best) are scored on every fold.
    3. The choice is the lowest of these on every fold (only fully scored candidates compete); the
       rig returned is the path's at the chosen alpha. The curve reported (``errors``) pools the
       first half of the folds, which every scored candidate has.

    Against ``"deletion"`` (every other candidate and the best's better neighbour on every fold) it
    scores 14-18 fold deletions instead of 24 on the default grid. A path that skips candidates
    (about 10x steps) cost half as much again but returned worse rigs: on ICT at m = 80 the
    alternations through the intermediate alphas matter (held-out 0.0235 against 0.0213, seed 0).
    """
    from concurrent.futures import ThreadPoolExecutor

    from ..workers import available_cores

    opts = generator.options
    folds = int(labels.max()) + 1
    half = tuple(range((folds + 1) // 2))
    top_its = min(TOP_ITERATIONS or opts.iterations, int(opts.iterations))
    base = dataclasses.replace(opts, alpha=(SCHEDULE_RATIO * grid[-1], grid[-1]), ipopt="never", iterations=top_its)
    workers = opts.threads or available_cores()
    pool = ThreadPoolExecutor(workers) if workers > 1 else None
    top = len(grid) - 1
    coarse = list(range(top, -1, -COARSE_STEP))
    coarse += [] if coarse[-1] == 0 else [0]
    lazy = coarse[:min(LAZY_COARSE, len(coarse) - 1)]
    # above the first candidate scored, the rigs are transfer in effect: one alternation each
    quick = range(coarse[len(lazy)] + 1, top) if len(lazy) else ()
    path = _Path(generator.with_options(base), grid, labels, chain, float(opts.lam[1]), progress, pool, quick)
    try:
        best = _coarse_pass(path, coarse, half)
        path.score(best, range(folds))
        for n in _neighbours(path, best):
            path.score(n, range(folds))
    finally:
        if pool is not None:
            pool.shutdown()
    chosen = min((c for c in path.nums if path.complete(c)), key=path.error)
    scored = sorted(path.nums)
    X_in, recs, route = path.states[chosen]
    done = tuple(dataclasses.replace(r, iteration=i + 1) for i, r in enumerate(recs))
    errors = tuple(path.error(c, half) for c in scored)  # the curve on the folds every candidate has
    a = grid[chosen]
    fold_errors = tuple(tuple(float(np.sqrt(path.nums[c][f] / path.den[f])) for c in scored) for f in range(folds))
    return CrossValidation(grid=tuple(grid[c] for c in scored), errors=errors, fold_errors=fold_errors,
                           best_alpha=a, schedule=(SCHEDULE_RATIO * a, a), folds=tuple(map(int, labels)),
                           chain_iterations=chain, seconds=time.perf_counter() - t0,
                           cpu_seconds=time.process_time() - c0, candidates="coarse",
                           curves={"coarse": errors}, path=tuple(sorted(grid[c] for c in route)),
                           final_state={"X": X_in, "history": done}, top_iterations=top_its,
                           coarse_folds=len(half), chosen_error=path.error(chosen),
                           quick_alphas=tuple(grid[c] for c in quick))


def _coarse_pass(path: _Path, coarse, half) -> int:
    """Step 1 of :func:`cross_validate_coarse`: the path through every candidate from the largest,
    the ``coarse`` ones scored on ``half`` (the two largest only if the curve still falls towards
    them); returns the best of them."""
    lazy = coarse[:min(LAZY_COARSE, len(coarse) - 1)]
    best, worse, prev = None, 0, None
    for c in range(path.top, -1, -1):
        path.visit(c, after=prev)
        prev = c
        if c not in coarse or c in lazy:
            continue
        path.score(c, half)
        if best is None or path.error(c, half) < path.error(best, half):
            best, worse = c, 0
        else:
            worse += 1
            if worse >= PATIENCE:
                break
    for c in reversed(lazy):  # upwards, while the best is the largest candidate scored
        if best != max(path.nums):
            break
        path.score(c, half)
        if path.error(c, half) < path.error(best, half):
            best = c
    return best


def _neighbours(path: _Path, best: int) -> list[int]:
    """Step 2: the neighbours of ``best`` on the grid (the one below it is visited now if the path
    stopped at ``best``): chosen on half the folds, the side would be a guess where the curve is flat."""
    out = [n for n in (best + 1, best - 1) if 0 <= n <= path.top]
    for n in out:
        if n not in path.states:
            path.visit(n, after=best)
    return out


__all__ = ["cross_validate_deletion", "cross_validate_coarse", "COARSE_STEP", "LAZY_COARSE"]
