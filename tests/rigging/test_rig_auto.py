"""§4: --alpha auto (k-fold cross-validation of alpha), unobserved shapes, the options' error branches."""

import dataclasses
import json

import numpy as np
import pytest

from conftest import write_rig_inputs
from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.transfer import deformation_transfer
from facebasis.rigging.crossval import cross_validate_alpha
from facebasis.rigging.heldout import heldout_error
from facebasis.rigging.generation import BlendshapeGenerator, generate_blendshapes
from facebasis.rigging.problem import GenerationOptions
from facebasis.rigging.synthetic import default_face_problem, make_person_problem
from facebasis.defaults.face import EXCLUSIVE_PAIRS

GRID = (0.001, 1000.0)


def _transfer_is_truth_problem(noise):
    """Training expressions of the deformation transfer itself plus vertex noise: transfer
    (the largest alpha) is exactly right, a small alpha fits the noise."""
    pp = default_face_problem(seed=0, n_train=9)
    p = pp.problem
    dt = deformation_transfer(p.template, p.target_neutral)
    truth = make_person_problem(p.template, dt, EXCLUSIVE_PAIRS, 9, 6, 0.3, seed=0)
    rng = np.random.default_rng(0)
    scale = noise * np.abs(dt.deltas).max()
    noisy = dataclasses.replace(truth.problem, examples=truth.problem.examples + rng.normal(0, scale, truth.problem.examples.shape))
    return noisy, truth


def test_auto_alpha_picks_transfer_when_transfer_is_the_truth():
    problem, truth = _transfer_is_truth_problem(0.05)
    opts = GenerationOptions(iterations=3, alpha="auto", cv_folds=3, cv_grid=GRID, unobserved="fit")
    res = generate_blendshapes(problem, opts)
    cv = res.crossval
    assert cv.grid == GRID and cv.best_alpha == 1000.0 and cv.errors[1] < cv.errors[0]
    assert res.options.alpha == (5000.0, 1000.0) and res.history[-1].alpha == pytest.approx(1000.0)
    assert len(cv.fold_errors) == 3 and len(cv.folds) == 9


@pytest.mark.parametrize("candidates", ["path", "coarse"])
def test_auto_alpha_picks_the_small_alpha_when_the_person_differs_from_transfer(candidates):
    pp = default_face_problem(seed=0, n_train=9)
    opts = GenerationOptions(iterations=3, alpha="auto", cv_folds=3, cv_grid=GRID, cv_candidates=candidates)
    cv = cross_validate_alpha(BlendshapeGenerator(pp.problem, opts))
    assert cv.best_alpha == 0.001 and cv.errors[0] < cv.errors[1]
    if candidates == "coarse":  # the path's candidates are scored by fold deletion (tested below)
        return
    # the curve is what it claims: the held-out error of the chosen schedule's rig on fold 0
    gen = BlendshapeGenerator(pp.problem, dataclasses.replace(opts, alpha=(1000.0 * 5, 1000.0), ipopt="never"))
    train, held = np.flatnonzero(np.array(cv.folds) != 0), np.flatnonzero(np.array(cv.folds) == 0)
    rig = gen.subset(train).run().rig
    assert heldout_error(rig, pp.problem.examples[held], pp.problem.pair_indices) == pytest.approx(
        cv.fold_errors[0][1], rel=1e-9)


def test_heldout_error_equals_an_ipopt_refit_of_the_vertex_residual():
    """The one held-out error (certified refit, no IPOPT model) equals the error of weights refitted
    by the IPOPT model of eq. 5 (polished) and the vertex residual written out; its pooled parts give it too."""
    from facebasis.rigging.heldout import heldout_error_parts
    from facebasis.rigging.weightproblem import WeightProblem
    from facebasis.rigging.weights import WeightSolver

    pp = default_face_problem(seed=1, n_train=6)
    rig = deformation_transfer(pp.problem.template, pp.problem.target_neutral)
    pairs = pp.problem.pair_indices
    problem = WeightProblem.from_rig(rig, pp.heldout, pairs)
    W = WeightSolver(rig.n_shapes, problem.m, problem.pairs).solve_problem(problem).X  # IPOPT, polished
    explicit = np.linalg.norm(rig.evaluate(W) - pp.heldout) / np.linalg.norm(pp.heldout - rig.neutral)
    assert heldout_error(rig, pp.heldout, pairs) == pytest.approx(explicit, rel=1e-7)
    num, den = heldout_error_parts(rig, pp.heldout, pairs)
    assert np.sqrt(num / den) == pytest.approx(heldout_error(rig, pp.heldout, pairs), rel=1e-12)


def test_unobserved_shape_keeps_its_transfer_and_zero_weights():
    pp = default_face_problem(seed=0, n_train=10)  # mouthSmile_L: no training expression uses it
    p = pp.problem
    i = p.template.names.index("mouthSmile_L")
    assert pp.true_weights[:, i].max() == 0
    gen = BlendshapeGenerator(p, GenerationOptions(iterations=3))
    assert gen.unobserved == ("mouthSmile_L",)
    res = gen.run()
    dt = deformation_transfer(p.template, p.target_neutral)
    assert np.abs(res.weights[:, i]).max() == 0.0
    assert np.linalg.norm(res.rig.deltas[i] - dt.deltas[i]) <= 1e-6 * np.linalg.norm(dt.deltas[i])
    fit = generate_blendshapes(p, GenerationOptions(iterations=3, unobserved="fit"))
    assert fit.unobserved == () and fit.weights[:, i].max() > 0


def test_rig_cli_alpha_auto_writes_the_curve(tmp_path, capsys):
    root = write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=6))
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "examples"), "--weights", str(root / "weights.json"),
                 "--out", str(root / "auto"), "--iterations", "2", "--alpha", "auto", "--cv-folds", "2",
                 "--cv-grid", "0.01", "--cv-grid", "1,100"])
    assert code == 0
    out = capsys.readouterr().out
    assert "--alpha auto: 3 candidates x 2 folds" in out
    cv = json.loads((root / "auto" / "crossval.json").read_text())
    assert cv["grid"] == [0.01, 1.0, 100.0] and len(cv["errors"]) == 3 and cv["best_alpha"] in cv["grid"]
    hist = json.loads((root / "auto" / "history.json").read_text())
    assert hist["options"]["alpha_requested"] == "auto"
    assert hist["options"]["alpha"] == [5 * cv["best_alpha"], cv["best_alpha"]]
    assert main(["verify", str(root / "auto")]) == 0


@pytest.mark.parametrize("kw,message", [
    ({"alpha": "bogus"}, r"alpha: expected two numbers \(first, last\) or 'auto', found 'bogus'"),
    ({"ipopt": "sometimes"}, r"ipopt: expected one of every, final, never, found 'sometimes'"),
    ({"unobserved": "drop"}, r"unobserved: expected one of transfer, fit, found 'drop'"),
    ({"support": 1.5}, r"support: expected a rough weight in \[0, 1\], found 1.5"),
    ({"cv_folds": 1}, r"cv_folds: expected >= 2, found 1"),
    ({"cv_chain_iterations": 0}, r"cv_chain_iterations: expected >= 1, found 0"),
    ({"cv_grid": (0.1, -1.0)}, r"cv_grid: expected final alphas > 0, found \(0.1, -1.0\)"),
    ({"polish": False}, r"polish: expected True unless ipopt='every' \(IPOPT's raw answers\), found polish=False "
                        r"with ipopt='final'"),
])
def test_option_errors(kw, message):
    with pytest.raises(InputError, match=message):
        GenerationOptions(**kw)


def test_auto_alpha_needs_as_many_examples_as_folds():
    pp = default_face_problem(seed=0, n_train=3)
    gen = BlendshapeGenerator(pp.problem, GenerationOptions(alpha="auto"))
    # the library names its own parameters (the command line writes them as its flags)
    with pytest.raises(InputError, match=r"^alpha auto: expected at least 4 training expressions for 4-fold "
                                         r"cross-validation \(cv_folds\), found 3$"):
        gen.run()
    with pytest.raises(InputError, match=r"alpha: 'auto' has no schedule before cross-validation"):
        GenerationOptions(alpha="auto").schedule()


@pytest.mark.parametrize("extra,message", [
    (["--alpha", "auto"], r"--alpha auto: expected at least 4 training expressions for 4-fold cross-validation "
                          r"\(--cv-folds\), found 3"),
    (["--cv-grid", "0.1", "x"], r"--cv-grid: expected final alphas > 0, found 'x'"),
    (["--cv-grid", "-1"], r"--cv-grid: expected final alphas > 0, found '-1'"),
])
def test_rig_cli_errors_before_solving(tmp_path, capsys, extra, message):
    root = write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=3))
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "examples"), "--weights", str(root / "weights.json"),
                 "--out", str(root / "o"), *extra])
    assert code == 2
    err = capsys.readouterr().err
    assert __import__("re").search(message, err), err
    assert not (root / "o").exists()


def test_rig_cli_without_inputs_names_them(tmp_path, capsys):
    assert main(["rig", "--out", str(tmp_path / "o"), "--target", "t.obj"]) == 2
    assert "rig: expected --template, --examples, --weights (or --resume RUN_DIR), found none" in capsys.readouterr().err


def test_final_schedule_follows_the_scored_candidate():
    from facebasis.rigging.cvcurve import CrossValidation

    opts = GenerationOptions(iterations=3, lam=(100.0, 10.0))
    kw = dict(grid=(0.01, 0.1, 1.0, 10.0), errors=(0.3, 0.1, 0.2, 0.4), fold_errors=((0.3, 0.1, 0.2, 0.4),),
              best_alpha=0.1, schedule=(0.5, 0.1), folds=(0, 0), chain_iterations=2, seconds=0.0, cpu_seconds=0.0)
    path = CrossValidation(candidates="path", **kw).final_schedule(opts)
    top = GenerationOptions(iterations=3, alpha=(50.0, 10.0)).schedule()
    assert path == top + [(1.0, 10.0)] * 2 + [(0.1, 10.0)] * 2
    cold = CrossValidation(candidates="cold", **kw).final_schedule(opts)
    assert cold == GenerationOptions(iterations=3, alpha=(0.5, 0.1)).schedule()


def test_auto_alpha_returns_the_rig_its_curve_scored():
    """"path": the curve's error of the chosen alpha on a fold is that of the path on the other
    folds, and the returned rig is the same path on all training expressions (not a fresh run)."""
    pp = default_face_problem(seed=0, n_train=8)
    grid = (0.01, 0.1, 10.0)
    opts = GenerationOptions(iterations=2, alpha="auto", cv_folds=2, cv_grid=grid, ipopt="never", cv_candidates="path")
    res = generate_blendshapes(pp.problem, opts)
    cv = res.crossval
    assert cv.candidates == "path" and res.options.alpha == (5 * cv.best_alpha, cv.best_alpha)
    sched = cv.final_schedule(opts)
    assert np.allclose([(h.alpha, h.lam) for h in res.history], sched, rtol=1e-15, atol=0)
    fixed = dataclasses.replace(opts, alpha=(1.0, 1.0))
    ref = BlendshapeGenerator(pp.problem, fixed).run(schedule=sched)
    assert np.abs(ref.rig.deltas - res.rig.deltas).max() <= 1e-12 * np.abs(ref.rig.deltas).max()
    # fold 1's error of the chosen alpha: the path down to it on fold 0's expressions
    gen = BlendshapeGenerator(pp.problem, fixed)
    train, held = np.flatnonzero(np.array(cv.folds) != 1), np.flatnonzero(np.array(cv.folds) == 1)
    rig = gen.subset(train).run(schedule=sched).rig
    c = grid.index(cv.best_alpha)
    assert heldout_error(rig, pp.problem.examples[held], pp.problem.pair_indices) == pytest.approx(
        cv.fold_errors[1][c], rel=1e-9)


def test_cold_candidates_do_not_depend_on_the_others():
    """"cold": a candidate's fold errors are the same whatever else is on the grid (no warm start)."""
    pp = default_face_problem(seed=1, n_train=8)
    opts = GenerationOptions(iterations=2, cv_folds=2, cv_candidates="cold")
    gen = BlendshapeGenerator(pp.problem, opts)
    full = cross_validate_alpha(gen, grid=(0.01, 0.1, 10.0))
    alone = cross_validate_alpha(gen, grid=(0.1,))
    assert full.candidates == "cold"
    assert np.allclose([f[1] for f in full.fold_errors], [f[0] for f in alone.fold_errors], rtol=1e-12, atol=0)
    path = cross_validate_alpha(gen, grid=(0.01, 0.1, 10.0), candidates="path")
    assert path.fold_errors[0][2] == pytest.approx(full.fold_errors[0][2], rel=1e-12)  # the top: the same run
    assert path.fold_errors[0][1] != pytest.approx(full.fold_errors[0][1], rel=1e-9)   # below: warm-started
    both = cross_validate_alpha(gen, grid=(0.01, 0.1, 10.0), candidates="both")
    assert np.allclose(both.curves["cold"], full.errors, rtol=1e-12, atol=0)
    assert np.allclose(both.curves["path"], path.errors, rtol=1e-12, atol=0)
    chosen = min(("path", "cold"), key=lambda mo: min(both.curves[mo]))
    assert both.candidates == chosen and both.errors == pytest.approx(both.curves[chosen], rel=1e-15)
    assert both.best_alpha == (0.01, 0.1, 10.0)[int(np.argmin(both.curves[chosen]))]
    assert (full.rigs_generated, path.rigs_generated, both.rigs_generated) == (2 * 3, 2 * 3, 2 * 5)
    assert "both procedures tried" in both.to_json()["method"] and "warm-started path" in path.to_json()["method"]
    with pytest.raises(InputError, match=r"cv_candidates: expected one of coarse, deletion, path, cold, both, "
                                         r"found 'warm'"):
        GenerationOptions(cv_candidates="warm")


def test_one_iteration_auto_run_records_the_lambda_its_weights_were_solved_at(tmp_path, capsys):
    """With ``--alpha auto`` the final run follows the cross-validated path, whose last alternation
    is at the last lambda even with ``--iterations 1`` (where the options' own schedule ends at the
    first): ``inputs.json`` must record the lambda actually used, so that `verify` certifies the run
    and `--resume` continues from it."""
    root = write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=6))
    run = root / "auto1"
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "examples"), "--weights", str(root / "weights.json"),
                 "--out", str(run), "--iterations", "1", "--alpha", "auto", "--cv-folds", "2",
                 "--cv-grid", "0.01", "100"])
    assert code == 0
    hist = json.loads((run / "history.json").read_text())
    inputs = json.loads((run / "inputs.json").read_text())
    lams = [it["lam"] for it in hist["iterations"]]
    assert len(lams) > 1 and lams[0] != lams[-1]          # the path: more alternations, lambda moved
    assert inputs["final_lambda"] == lams[-1]
    capsys.readouterr()
    assert main(["verify", str(run)]) == 0
    assert "certified optimal" in capsys.readouterr().out


def test_fold_deletion_closed_form_equals_explicit_refits():
    """Eq. 4 without a fold in closed form (hat matrix, Sherman-Morrison-Woodbury) equals the basis
    step solved again on the other folds: the solutions and the held-out residuals, with m < k and m > k."""
    from facebasis.rigging.basis import basis_rows, fold_deletion_rows

    rng = np.random.default_rng(3)
    for k, m in ((7, 9), (12, 5)):
        t = 37
        X = rng.uniform(0, 1, (k, m))
        RT, AT, w = rng.normal(size=(t, 6, m)), rng.normal(size=(t, 6, k)), rng.uniform(0.5, 3, (t, k))
        labels = np.arange(m) % 3
        rows, resid = fold_deletion_rows(X, RT, AT, w, 0.3, labels, residuals=True, block=16)
        for f in range(3):
            keep = labels != f
            ref, _, _ = basis_rows(X[:, keep], np.ascontiguousarray(RT[:, :, keep]), AT, w, 0.3)
            Y = ref.transpose(1, 2, 0, 3).reshape(t, 6, k)          # [t, 2d + e, i]
            r = RT[:, :, ~keep] - Y @ X[:, ~keep]                   # the explicit refit's held-out residuals
            assert np.abs(rows[f] - ref).max() <= 1e-10 * np.abs(ref).max()
            assert np.abs(resid[f] - r).max() <= 1e-10 * np.abs(r).max()
    with pytest.raises(InputError, match=r"fold_deletion_rows: labels: expected \(5,\) folds >= 0, found \(9,\)"):
        fold_deletion_rows(X, RT, AT, w, 0.3, np.zeros(9))


def assert_is_the_final_schedule_run(p, opts, res):
    """``res`` (an ``--alpha auto`` result) is a plain run of its cross-validation's final schedule:
    the history numbers and follows that schedule, and the rig and weights equal a fresh run of it.
    Returns the fresh run's generator (alpha fixed), for recomputing fold errors."""
    sched = res.crossval.final_schedule(opts)
    assert [h.iteration for h in res.history] == list(range(1, len(sched) + 1))
    assert np.allclose([(h.alpha, h.lam) for h in res.history], sched, rtol=1e-15, atol=0)
    gen = BlendshapeGenerator(p, dataclasses.replace(opts, alpha=(1.0, 1.0)))
    ref = gen.run(schedule=sched)
    assert np.abs(ref.rig.deltas - res.rig.deltas).max() <= 1e-12 * np.abs(ref.rig.deltas).max()
    assert np.array_equal(ref.weights, res.weights)
    return gen


def test_deletion_scores_fold_deletion_of_the_path_and_returns_the_path_rig():
    """"deletion": one path on all training expressions; a candidate's fold error is
    the held-out error of its last basis step solved without the fold, at the path's weights; the
    returned rig is the path's at the chosen alpha (as a full run of final_schedule gives it)."""
    from facebasis.geometry.rig import Rig
    from facebasis.rigging.basis import basis_rows

    pp = default_face_problem(seed=0, n_train=8)
    p = pp.problem
    grid = (0.01, 0.1, 10.0)
    opts = GenerationOptions(iterations=2, alpha="auto", cv_folds=2, cv_grid=grid, ipopt="never",
                             cv_candidates="deletion")
    shown = []
    res = generate_blendshapes(p, opts, progress=lambda rec, total: shown.append((rec.iteration, total)))
    cv = res.crossval
    assert shown == [(len(res.history), len(res.history))]  # the final alternation, numbered after the path's
    assert cv.candidates == "deletion" and cv.path == grid and res.options.alpha == (5 * cv.best_alpha, cv.best_alpha)
    gen = assert_is_the_final_schedule_run(p, opts, res)
    # the fold error of every scored candidate, recomputed explicitly
    for c, a in enumerate(cv.grid):
        full = list(cv.path)
        s = cv.final_schedule(dataclasses.replace(opts)) if a == cv.best_alpha else \
            dataclasses.replace(cv, best_alpha=a).final_schedule(opts)
        X_in = gen.run(schedule=s[:-1]).weights if len(s) > 1 else p.initial_weights
        assert full == list(grid)
        for f in range(2):
            train, held = np.flatnonzero(np.array(cv.folds) != f), np.flatnonzero(np.array(cv.folds) == f)
            rows, _, _ = basis_rows(X_in[train].T, np.ascontiguousarray(gen.R[:, :, train]), gen.A_tilde, gen.w, a)
            rig = Rig(p.target_neutral, p.template.faces, p.template.names, gen.deltas_of(gen.reconstruct(rows)))
            assert heldout_error(rig, p.examples[held], p.pair_indices) == pytest.approx(cv.fold_errors[f][c], rel=1e-9)
    assert "deleting each fold" in cv.to_json()["method"] and cv.to_json()["path"] == list(grid)


def test_deletion_stops_the_path_once_candidates_score_worse():
    """Transfer is the truth: the largest alpha wins and the path stops after PATIENCE coarse candidates
    above it (the smallest alphas are never run); the neighbour of the coarse minimum is refined."""
    from facebasis.rigging.cvcurve import PATIENCE

    problem, _ = _transfer_is_truth_problem(0.05)
    grid = (0.0001, 0.0003, 0.001, 0.003, 0.01, 0.03, 0.1, 1000.0)
    opts = GenerationOptions(iterations=3, alpha="auto", cv_folds=3, cv_grid=grid, unobserved="fit", ipopt="never",
                             cv_candidates="deletion")
    cv = cross_validate_alpha(BlendshapeGenerator(problem, opts))
    assert PATIENCE == 2 and cv.best_alpha == 1000.0
    # coarse: 1000, 0.03, 0.003 (two above the best: stop); refined: 0.1, the top's neighbour
    assert cv.path == (0.003, 0.01, 0.03, 0.1, 1000.0) and cv.grid == (0.003, 0.03, 0.1, 1000.0)
    assert min(cv.errors) == cv.errors[-1] and cv.rigs_generated == 3 * 4


def test_coarse_path_scores_fold_deletion_and_returns_the_path_rig():
    """"coarse" (the default): the path through every candidate, every other one scored; the best
    of those and its two neighbours are scored on every fold, the others on the first
    half; every fold error is the held-out error of the candidate's last basis step solved without
    the fold at the path's weights (recomputed explicitly here), and the rig returned is the path's
    at the chosen alpha (a full run of final_schedule gives it, weights and history included)."""
    from facebasis.geometry.rig import Rig
    from facebasis.rigging.basis import basis_rows

    pp = default_face_problem(seed=0, n_train=8)
    p = pp.problem
    grid = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 10.0)
    opts = GenerationOptions(iterations=3, alpha="auto", cv_folds=4, cv_grid=grid, ipopt="never")
    res = generate_blendshapes(p, opts)
    cv = res.crossval
    assert cv.candidates == "coarse" and cv.coarse_folds == 2 and res.options.alpha == (5 * cv.best_alpha, cv.best_alpha)
    gen = assert_is_the_final_schedule_run(p, opts, res)
    # the path went through every other candidate from the top; the route ends at the choice
    assert set(cv.path) <= set(grid) and cv.path[-1] == 10.0 and cv.path[0] == cv.best_alpha
    full = [c for c in range(len(cv.grid)) if all(f[c] == f[c] for f in cv.fold_errors)]
    assert len(full) in (2, 3) and cv.grid.index(cv.best_alpha) in full
    # the choice: the finalist with the lower error pooled over every fold
    den = [np.sum((p.examples[np.array(cv.folds) == f] - p.target_neutral) ** 2) for f in range(4)]
    pooled = {cv.grid[c]: np.sqrt(sum(cv.fold_errors[f][c] ** 2 * den[f] for f in range(4)) / sum(den)) for c in full}
    assert cv.best_alpha == min(pooled, key=pooled.get) and cv.best_error == pytest.approx(pooled[cv.best_alpha], rel=1e-12)
    half = {cv.grid[c]: np.sqrt(sum(cv.fold_errors[f][c] ** 2 * den[f] for f in range(2)) / sum(den[:2]))
            for c in range(len(cv.grid))}
    assert np.allclose(cv.errors, [half[a] for a in cv.grid], rtol=1e-12, atol=0)  # the curve: the first 2 folds
    for c, a in enumerate(cv.grid):
        route = [x for x in cv.path if x >= a] if a in cv.path else None
        if route is None:  # a candidate the route to the choice did not take: its own route
            continue
        s = dataclasses.replace(cv, best_alpha=a, path=tuple(route)).final_schedule(opts)
        X_in = gen.run(schedule=s[:-1]).weights if len(s) > 1 else p.initial_weights
        for f in range(4):
            if cv.fold_errors[f][c] != cv.fold_errors[f][c]:
                assert c not in full and f >= cv.coarse_folds
                continue
            train, held = np.flatnonzero(np.array(cv.folds) != f), np.flatnonzero(np.array(cv.folds) == f)
            rows, _, _ = basis_rows(X_in[train].T, np.ascontiguousarray(gen.R[:, :, train]), gen.A_tilde, gen.w, a)
            rig = Rig(p.target_neutral, p.template.faces, p.template.names, gen.deltas_of(gen.reconstruct(rows)))
            assert heldout_error(rig, p.examples[held], p.pair_indices) == pytest.approx(cv.fold_errors[f][c], rel=1e-9)
    js = cv.to_json()
    assert "every other candidate" in js["method"] and js["path"] == list(cv.path)
    assert all(e is None or e > 0 for row in js["fold_errors"] for e in row)
