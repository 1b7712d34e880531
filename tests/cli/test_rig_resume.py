"""§5: `facebasis rig --resume RUN_DIR`: add training expressions to a finished run, warm-started."""

import json
import shutil

import numpy as np
import pytest

from conftest import write_rig_inputs
from facebasis.cli import main
from facebasis.geometry.rig import load_rig_folder
from facebasis.rigging.synthetic import default_face_problem


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    root = write_rig_inputs(tmp_path_factory.mktemp("resume"), default_face_problem(seed=0, n_train=8))
    # the first 5 expressions make the run; the other 3 come later
    weights = json.loads((root / "weights.json").read_text())
    for name, part in (("first", range(5)), ("more", range(5, 8))):
        (root / name).mkdir()
        names = [f"ex{j:02d}" for j in part]
        for n in names:
            shutil.copy(root / "examples" / f"{n}.obj", root / name / f"{n}.obj")
        (root / f"{name}.json").write_text(json.dumps({n: weights[n] for n in names}))
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "first"), "--weights", str(root / "first.json"),
                 "--out", str(root / "run"), "--iterations", "3", "--exclusive", "mouthLeft:mouthRight"])
    assert code == 0
    return root


def test_resume_without_new_examples_returns_the_run(finished, capsys):
    root = finished
    assert main(["rig", "--resume", str(root / "run"), "--out", str(root / "same")]) == 0
    assert "nothing new" in capsys.readouterr().out
    a, b = load_rig_folder(root / "run"), load_rig_folder(root / "same")
    assert a.names == b.names and np.array_equal(a.deltas, b.deltas) and np.array_equal(a.neutral, b.neutral)
    assert json.loads((root / "run" / "weights.json").read_text()) == json.loads((root / "same" / "weights.json").read_text())


def test_resume_with_more_examples_warm_starts_and_verifies(finished, capsys):
    root = finished
    code = main(["rig", "--resume", str(root / "run"), "--examples", str(root / "more"),
                 "--weights", str(root / "more.json"), "--out", str(root / "more_run"), "--iterations", "2"])
    assert code == 0
    out = capsys.readouterr().out
    assert "5 training expressions + 3 new" in out and "iteration 2/2" in out
    w = json.loads((root / "more_run" / "weights.json").read_text())
    assert sorted(w) == [f"ex{j:02d}" for j in range(8)]
    inputs = json.loads((root / "more_run" / "inputs.json").read_text())
    assert len(inputs["examples"]) == 2 and inputs["exclusive"] == [["mouthLeft", "mouthRight"]]
    hist = json.loads((root / "more_run" / "history.json").read_text())
    run_hist = json.loads((root / "run" / "history.json").read_text())
    assert [h["alpha"] for h in hist["iterations"]] == pytest.approx([run_hist["iterations"][-1]["alpha"]] * 2)
    assert main(["verify", str(root / "more_run")]) == 0


@pytest.mark.parametrize("extra,message", [
    (["--alpha", "0.3,0.1"], r"--resume: expected the run's own schedule and pairs, found --alpha"),
    (["--exclusive", "jawLeft:jawRight"], r"--resume: expected the run's own schedule and pairs, found --exclusive"),
    (["--cv-folds", "3", "--cv-candidates", "cold"],
     r"--resume: expected the run's own schedule and pairs, found --cv-folds, --cv-candidates"),
    (["--examples", "MORE"], r"--resume: expected --examples and --weights together \(or neither\), found only --examples"),
])
def test_resume_errors_before_solving(finished, capsys, extra, message):
    root = finished
    assert main(["rig", "--resume", str(root / "run"), "--out", str(root / "bad"), *extra]) == 2
    assert __import__("re").search(message, capsys.readouterr().err)
    assert not (root / "bad").exists()


def test_resume_errors_on_inputs(finished, tmp_path, capsys):
    root = finished
    assert main(["rig", "--resume", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2
    assert "--resume: expected a finished `facebasis rig` output folder, found no folder" in capsys.readouterr().err
    # the first expressions again: their names are taken
    assert main(["rig", "--resume", str(root / "run"), "--examples", str(root / "first"),
                 "--weights", str(root / "first.json"), "--out", str(tmp_path / "o")]) == 2
    assert "expected new training expression names, found names already used" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["rig", "--resume", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 2
    assert "expected inputs.json (written by `facebasis rig`), found no such file" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_run_made_with_virtual_edges_is_resumed_only_with_them(finished, capsys):
    """inputs.json records whether the virtual-edge energy shaped the run; resuming without it would
    silently drop that energy, so it is refused until --virtual-edges (and --template) are given."""
    root = finished
    assert json.loads((root / "run" / "inputs.json").read_text())["sources"]["virtual_edges"] is False
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "first"), "--weights", str(root / "first.json"), "--virtual-edges",
                 "--out", str(root / "ve_run"), "--iterations", "2"])
    assert code == 0
    assert json.loads((root / "ve_run" / "inputs.json").read_text())["sources"]["virtual_edges"] is True
    capsys.readouterr()
    assert main(["rig", "--resume", str(root / "ve_run"), "--out", str(root / "ve_bad")]) == 2
    assert "as the run was made with virtual edges, found none" in capsys.readouterr().err
    assert not (root / "ve_bad").exists()
    assert main(["rig", "--resume", str(root / "ve_run"), "--virtual-edges", "--template", str(root / "template"),
                 "--out", str(root / "ve_again")]) == 0
    assert json.loads((root / "ve_again" / "inputs.json").read_text())["sources"]["virtual_edges"] is True
