"""Paper figures and report folders: units on every axis and colour bar, every series in a legend,
legends off the data, fonts >= 8 pt (facebasis.report.figures.lint_figure on every figure written),
the rig report's tables and index."""

import re
from pathlib import Path

import numpy as np
import pytest

from facebasis.report import figures


@pytest.fixture
def linted(monkeypatch):
    """Every figure saved during the test is checked; yields {file stem: [problems]} and
    {file stem: [axes titles]}."""
    problems, titles = {}, {}

    def hook(fig, path):
        problems[path.stem] = figures.lint_figure(fig)
        titles[path.stem] = [ax.get_title() for ax in fig.axes]

    monkeypatch.setattr(figures, "SAVE_HOOKS", [hook])
    return problems, titles


@pytest.fixture(scope="module")
def rig_run(tmp_path_factory):
    from facebasis.rigging.problem import GenerationOptions
    from facebasis.rigging.generation import generate_blendshapes
    from facebasis.rigging.runs import write_problem_inputs, write_rig_run
    from facebasis.rigging.synthetic import default_face_problem

    root = tmp_path_factory.mktemp("run")
    p = default_face_problem(seed=0, n_train=4).problem
    options = GenerationOptions(iterations=2, threads=1)
    res = generate_blendshapes(p, options)
    run = root / "run"
    run.mkdir()
    examples_dir, weights_file = write_problem_inputs(root / "inputs", p)
    write_rig_run(run, res, options, p, examples_dir, weights_file, relative_to=run)
    return run


def test_lint_catches_missing_units_legends_and_small_fonts():
    plt = figures._pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="a")
    ax.plot([0, 1], [1, 0], label="b")
    ax.legend(["a"], loc="center")  # b missing; the legend sits on the crossing of the lines
    ax.set_xlabel("time")           # no unit
    ax.set_title("small", fontsize=6)
    found = " | ".join(figures.lint_figure(fig))
    plt.close(fig)
    assert "x label 'time' has no (unit)" in found and "y axis has ticks but no label" in found
    assert "series 'b' is in no legend" in found and "legend covers" in found and "'small' is 6.0 pt" in found
    fig, ax = plt.subplots()
    ax.semilogy([1, 2], [1e-3, 1e2])  # mathtext tick labels (10^-2) are numbers too
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("energy")
    found = figures.lint_figure(fig)
    plt.close(fig)
    assert found == ["axes 0 (?): y label 'energy' has no (unit)"]


def test_rig_report_figures_tables_and_index(rig_run, tmp_path, linted):
    from facebasis.report.run_report import report_run

    problems, _ = linted
    out = tmp_path / "report"
    paths = report_run(rig_run, out, formats=("pdf",))  # PDF only: the PNG path is the same code, and slow
    assert {"convergence", "weights", "residuals", "shapes"} <= set(problems)
    assert all(not v for v in problems.values()), problems
    names = {p.name for p in paths}
    for stem in ("convergence", "weights", "residuals", "shapes"):
        assert f"{stem}.pdf" in names
    for table in ("history", "residuals_table", "weights_table"):
        assert (out / f"{table}.csv").is_file() and (out / f"{table}.md").is_file()
    history = (out / "history.csv").read_text().splitlines()
    assert history[0].startswith("iteration,alpha,lambda (cm²),E_fit (cm²)") and len(history) == 3
    weights = (out / "weights_table.csv").read_text().splitlines()
    assert len(weights) == 5 and weights[0].startswith("example,")
    index = (out / "index.md").read_text()
    assert index.startswith(f"# Rig run report: {rig_run.name}\n") and "## Key numbers" in index and "E_fit" in index
    assert "folder `../../" in index  # the run, relative to the report
    assert "max bound violation -0" not in index
    assert str(tmp_path) not in index and "/" + tmp_path.parts[1] not in index  # no absolute path
    linked = re.findall(r"\]\(([^)]+)\)", index)
    assert set(linked) == {p.name for p in out.iterdir() if p.name != "index.md"}
    assert all((out / f).is_file() for f in linked)
    assert "shapes.pdf" in linked and "convergence.pdf" in linked


def test_rig_report_renders_elsewhere_stay_out_of_the_index(rig_run, tmp_path, monkeypatch):
    from facebasis.report import run_report

    def fake_shapes(rig, path, formats=("png",)):  # the renders themselves are tested above
        path.parent.mkdir(parents=True, exist_ok=True)
        path.with_suffix(".png").write_bytes(b"png")
        return [path.with_suffix(".png")]

    monkeypatch.setattr(run_report, "shapes_figure", fake_shapes)
    run_report.report_run(rig_run, tmp_path / "report", formats=("png",), renders_dir=tmp_path / "renders")
    assert (tmp_path / "renders" / "shapes.png").is_file()
    index = (tmp_path / "report" / "index.md").read_text()
    assert "shapes" not in index.split("## Figures")[1] and "convergence.png" in index


def _rows(seeds=(0, 1)):
    rows = []
    base = {"problem": "default", "method": "example-based", "alpha0": None, "lam0": None, "noise": None,
            "noise_seed": None, "train_error": None, "shape_error": 0.2, "rig_change": None, "seconds": 1.0}
    for s in seeds:
        for a in (0.01, 0.1, 1.0):
            rows.append({**base, "study": "alpha", "seed": s, "alpha0": a, "heldout_error": 0.05 + a / 100 + s / 1000,
                         "train_error": 0.02 + a / 50})
            for v in (1.0, 100.0):
                rows.append({**base, "study": "grid", "seed": s, "alpha0": a, "lam0": v, "heldout_error": 0.04 + a / 50})
        for v in (0.1, 10.0, 1000.0):
            rows.append({**base, "study": "lambda", "seed": s, "lam0": v, "heldout_error": 0.06, "train_error": 0.03})
        for nz in (0.0, 0.5):
            for ns in (0, 1):
                rows.append({**base, "study": "noise", "seed": s, "noise": nz, "noise_seed": ns,
                             "heldout_error": 0.05, "rig_change": nz / 50 + ns / 1000})
        for m, e in (("deformation transfer", 0.07), ("example-based", 0.03 + s / 100)):
            rows.append({**base, "study": "methods", "seed": s, "method": m, "heldout_error": e})
    return rows


def test_sweep_figures_and_methods_with_seeds(tmp_path, linted):
    from facebasis.report.run_report import sweep_report

    problems, titles = linted
    paths = sweep_report(_rows(), tmp_path, formats=("png",))
    assert {p.name for p in paths} >= {"alpha_sweep.png", "lambda_sweep.png", "alpha_lambda_heatmap.png",
                                       "noise_robustness.png", "methods.png", "methods.md", "methods.csv"}
    assert all(not v for v in problems.values()), problems
    md = (tmp_path / "methods.md").read_text()
    assert "held-out error (std over seeds)" in md and "| example-based | 0.035 | 0.005 |" in md
    # one seed: the figure says n = 1
    problems.clear()
    sweep_report([r for r in _rows((0,)) if r["study"] == "methods"], tmp_path / "one", formats=("png",))
    assert not problems["methods"]
    text = (tmp_path / "one" / "methods.csv").read_text()
    assert text.splitlines()[1].endswith(",1")


def test_formulation_figure_is_clean(tmp_path, linted):
    from facebasis.report.run_report import formulation_report
    from facebasis.rigging.formulations import compare_formulations
    from problems.weights_suite import closed_form_instances

    problems, _ = linted
    formulation_report(compare_formulations(closed_form_instances()), tmp_path, formats=("png",))
    assert problems["formulations"] == []


def test_penetration_closeups_count_per_zone_with_equal_panels(tmp_path, linted):
    from facebasis.report.run_report import penetration_figure

    from conftest import grid_sheet

    _, titles = linted
    V, F = grid_sheet(8, 6)
    V = np.asarray(V, float)
    F = np.asarray(F)
    c = V[F].mean(1)
    left, right = np.flatnonzero(c[:, 0] < 0.5), np.flatnonzero(c[:, 0] >= 0.5)
    data = {"faces": F, "names": ["e"], "e/plain": V, "e/ve": V,
            "e/plain_hits": np.r_[left[:3], right[:2]], "e/ve_hits": left[:1],
            "crops": {"a": ("front", ((-0.1, 0.5), (-0.1, 1.1))), "b": ("front", ((0.5, 1.1), (0.2, 0.5)))},
            "zone_faces": {"a": left, "b": right}}
    penetration_figure(data, tmp_path)
    shown = titles["penetration_closeups"]
    assert shown == ["3 crossing", "1 crossing", "2 crossing", "0 crossing"]


def test_reports_script_names_the_folder_it_wrote(tmp_path, monkeypatch):
    from problems.reports import _shown

    monkeypatch.chdir(tmp_path)
    assert _shown(tmp_path / "x") == "x"
    assert _shown(Path("/elsewhere/out")) == "/elsewhere/out"


def test_penetration_closeups_gain_a_contact_column(tmp_path, linted):
    """Three columns per zone (plain / virtual edges / exact contact); the contact panels count their
    remaining pairs (here none) and show a note for an excluded shape."""
    from facebasis.report.penetration import penetration_figure

    from conftest import grid_sheet

    problems, titles = linted
    V, F = grid_sheet(8, 6)
    V = np.asarray(V, float)
    c = np.asarray(V)[np.asarray(F)].mean(1)
    left, right = np.flatnonzero(c[:, 0] < 0.5), np.flatnonzero(c[:, 0] >= 0.5)
    data = {"faces": np.asarray(F), "names": ["e", "x"], "kinds": ("plain", "ve", "contact"),
            "crops": {"a": ("front", ((-0.1, 0.5), (-0.1, 1.1))), "b": ("front", ((0.5, 1.1), (0.2, 0.5)))},
            "zone_faces": {"a": left, "b": right}}
    for name, contact_hits in (("e", left[:0]), ("x", right[:2])):
        for kind, hits in (("plain", np.r_[left[:3], right[:2]]), ("ve", left[:1]), ("contact", contact_hits)):
            data[f"{name}/{kind}"] = V
            data[f"{name}/{kind}_hits"] = hits
    data["x/contact_note"] = "excluded"
    penetration_figure(data, tmp_path)
    assert titles["penetration_closeups"] == ["3 crossing", "1 crossing", "0 crossing", "2 crossing", "0 crossing",
                                              "0 crossing", "3 crossing", "1 crossing", "0 crossing\n(excluded)",
                                              "2 crossing", "0 crossing", "2 crossing\n(excluded)"]
    assert problems["penetration_closeups"] == []


def test_render_image_colours_each_triangle_and_keeps_the_largest_value_visible():
    """The numpy renders of the rig report: per-triangle colours from the values, the top of the
    colour map is a colour (not black), the crop fills the image."""
    from facebasis.report.render import heat_cmap, render_image

    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])  # counter-clockwise seen from +z (the front view's viewer)
    img = render_image(V, F, ((0, 1), (0, 1)), 40, values=np.array([0, 1, 1, 0.0]), vmin=0, vmax=1)
    assert img.shape == (40, 40, 3) and img.dtype == np.uint8
    low, high = img[10, 5].astype(int), img[35, 35].astype(int)  # above / below the diagonal: two triangles
    assert (low != high).any()
    top = np.asarray(heat_cmap()(1.0))[:3]
    assert top.max() > 0.4  # the largest displacement stays a colour: no black hole
    assert not (img == 255).all(axis=2).any()  # the crop is the mesh: no background shows


def test_face_crop_follows_the_moving_face_not_a_slightly_dragged_head():
    V = np.random.default_rng(0).uniform(-10, 10, (2000, 3))
    face = np.abs(V[:, :2]).max(1) < 3
    deltas = np.zeros((2, len(V), 3))
    deltas[0, face, 2] = 1.0
    deltas[1, :, 2] = 0.25                      # a shape that drags the whole head a little
    deltas[1, face, 2] = 1.0
    (x0, x1), (y0, y1) = figures.face_crop(V, deltas, rel=0.5)
    assert -3.6 < x0 < -2.5 and 2.5 < x1 < 3.6 and -3.6 < y0 < -2.5 and 2.5 < y1 < 3.6


def test_history_splits_the_weight_objective_into_fit_and_prior(rig_run):
    """history.json's weight_prior is eq. 5's prior part at the solved weights, lambda ||x - x~||^2
    (the convergence figure draws the fit, objective - prior, which does not scale with lambda)."""
    import json

    history = json.loads((rig_run / "history.json").read_text())
    weights = json.loads((rig_run / "weights.json").read_text())
    inputs = json.loads((rig_run / "inputs.json").read_text())
    rough_path = Path(inputs["weights"]) if Path(inputs["weights"]).is_absolute() else rig_run / inputs["weights"]
    rough = json.loads(rough_path.read_text())
    last = history["iterations"][-1]
    x = np.array([[weights[e].get(s, 0.0) for s in history["shapes"]] for e in history["examples"]])
    xt = np.array([[rough[e].get(s, 0.0) for s in history["shapes"]] for e in history["examples"]])
    assert last["weight_prior"] == pytest.approx(last["lam"] * float(((x - xt) ** 2).sum()), rel=1e-6)
    for h in history["iterations"]:
        assert 0.0 <= h["weight_prior"] <= h["weight_objective"]


def test_crossval_figure_says_which_folds_the_curve_pools(tmp_path, monkeypatch):
    """A coarse cross-validation (--cv-candidates coarse) scores the path on its first folds only:
    the curve's label says how many, and the chosen alpha's error over all folds is its own mark."""
    import json

    from facebasis.report import run_report

    seen = []
    monkeypatch.setattr(run_report, "save", lambda fig, path, formats: seen.append(fig) or [])
    cv = {"grid": [0.01, 0.1, 1.0], "errors": [0.3, 0.2, 0.25], "best_alpha": 0.1}
    (tmp_path / "crossval.json").write_text(json.dumps(cv))
    run_report.crossval_figure(tmp_path, tmp_path / "cv")
    (tmp_path / "crossval.json").write_text(json.dumps({**cv, "coarse_folds": 2, "chosen_error": 0.21}))
    run_report.crossval_figure(tmp_path, tmp_path / "cv")
    labels = [[t.get_text() for t in fig.legends[0].get_texts()] if fig.legends else
              [t.get_text() for t in fig.axes[0].get_legend().get_texts()] for fig in seen]
    assert "pooled over the folds" in labels[0] and not any("all folds" in s for s in labels[0])
    assert "pooled over the first 2 folds" in labels[1] and "chosen, all folds" in labels[1]
