"""facebasis rig: inputs, validation before solving, outputs."""

import json

import pytest

from facebasis.cli import main
from facebasis.defaults.face import default_template
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.rig import load_rig_folder
from facebasis.rigging.synthetic import default_face_problem

from conftest import write_rig_inputs


@pytest.fixture(scope="module")
def rig_inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("rig")
    pp = default_face_problem(seed=0, n_train=6)
    return write_rig_inputs(root, pp), pp


def args(root, **over):
    a = {"--template": root / "template", "--target": root / "target.obj", "--examples": root / "examples",
         "--weights": root / "weights.json", "--out": root / "out", "--iterations": "3"}
    a.update(over)
    out = ["rig"]
    for k, v in a.items():
        out += [k, str(v)]
    return out


def test_rig_cli_writes_everything(rig_inputs, capsys):
    root, pp = rig_inputs
    code = main(args(root) + ["--exclusive", "mouthLeft:mouthRight", "eyeBlink_L:eyeWide_L"])
    assert code == 0
    out = capsys.readouterr().out
    assert "iteration 3/3" in out and "generated 15 blendshapes" in out
    rig = load_rig_folder(root / "out")
    assert set(rig.names) == set(default_template().names)
    w = json.loads((root / "out" / "weights.json").read_text())
    assert set(w) == set(pp.problem.example_names)
    for row in w.values():
        assert all(0.0 <= v <= 1.0 for v in row.values())
        assert not (row.get("mouthLeft", 0) > 0 and row.get("mouthRight", 0) > 0)
    hist = json.loads((root / "out" / "history.json").read_text())
    # default --ipopt final: the certified solver alone, then IPOPT's cross-check at the last alternation
    assert len(hist["iterations"]) == 3 and hist["iterations"][-1]["ipopt_status"] == "Solve_Succeeded"
    assert [h["ipopt_status"] for h in hist["iterations"][:-1]] == ["not run", "not run"]
    for key in ("alpha", "lam", "e_fit", "e_reg", "weight_objective", "max_complementarity",
                "max_bound_violation", "ipopt_iterations", "basis_seconds", "weight_seconds"):
        assert key in hist["iterations"][0]
    res = json.loads((root / "out" / "residuals.json").read_text())
    assert set(res["relative_residual"]) == set(pp.problem.example_names)


@pytest.mark.parametrize("mutate,message", [
    (lambda w: w["ex00"].update({"jawOpn": 0.3}), r"ex00: unknown blendshape names \['jawOpn'\]"),
    (lambda w: w["ex01"].update({"jawOpen": 1.3}), r"ex01.jawOpen: expected a weight in \[0, 1\], found 1.3"),
    (lambda w: w.pop("ex02"), r"expected weights for every example, found none for \['ex02'\]"),
    (lambda w: w.update({"ex99": {}}), r"found weights for examples that are not in the examples folder: \['ex99'\]"),
    (lambda w: w["ex00"].update({"jawOpen": "high"}), r"ex00.jawOpen: expected a number in \[0, 1\], found 'high'"),
])
def test_rig_cli_weight_errors(rig_inputs, tmp_path, capsys, mutate, message):
    root, _ = rig_inputs
    w = json.loads((root / "weights.json").read_text())
    mutate(w)
    bad = tmp_path / "w.json"
    bad.write_text(json.dumps(w))
    assert main(args(root, **{"--weights": bad, "--out": tmp_path / "o"})) == 2
    err = capsys.readouterr().err
    assert "w.json" in err
    import re

    assert re.search(message, err), err
    assert not (tmp_path / "o").exists()


def test_rig_cli_other_errors(rig_inputs, tmp_path, capsys):
    root, _ = rig_inputs
    assert main(args(root, **{"--out": tmp_path / "o"}) + ["--exclusive", "mouthLeft:mouthUp"]) == 2
    assert "exclusive pair mouthLeft:mouthUp: unknown blendshape names ['mouthUp']" in capsys.readouterr().err
    assert main(args(root, **{"--out": tmp_path / "o"}) + ["--exclusive", "mouthLeft"]) == 2
    assert "--exclusive: expected SHAPE_A:SHAPE_B, found 'mouthLeft'" in capsys.readouterr().err
    assert main(args(root, **{"--out": tmp_path / "o", "--alpha": "big"})) == 2
    assert "--alpha: expected two numbers FIRST,LAST, found 'big'" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{not json")
    assert main(args(root, **{"--out": tmp_path / "o", "--weights": tmp_path / "bad.json"})) == 2
    assert "bad.json: expected a weights JSON file, found invalid JSON" in capsys.readouterr().err
    ex = tmp_path / "ex"
    ex.mkdir()
    V = default_template().neutral
    write_mesh(ex / "ex00.obj", V[:-1], default_template().faces[:-30])
    assert main(args(root, **{"--out": tmp_path / "o", "--examples": ex})) == 2
    assert "ex00.obj: expected 4497 vertices as in template" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def _run_rig(root, out):
    code = main(args(root, **{"--out": root / out}) + ["--exclusive", "mouthLeft:mouthRight",
                                                       "mouthSmile_L:mouthFrown_L"])
    assert code == 0
    return root / out


def test_verify_certifies_a_rig_run(rig_inputs, capsys):
    root, pp = rig_inputs
    run = _run_rig(root, "verified")
    capsys.readouterr()
    assert main(["verify", str(run)]) == 0
    out = capsys.readouterr().out
    assert f"all {len(pp.problem.example_names)} stored answers are certified optimal" in out
    assert out.count(" optimal") >= len(pp.problem.example_names)


def test_verify_flags_a_stored_answer_that_is_not_optimal(rig_inputs, capsys):
    import shutil

    root, pp = rig_inputs
    run = _run_rig(root, "tampered")
    bad = root / "tampered_copy"
    shutil.copytree(run, bad)
    w = json.loads((bad / "weights.json").read_text())
    first = sorted(w)[0]
    w[first] = {k: min(1.0, v + 0.2) for k, v in w[first].items()}  # feasible, but no longer optimal
    (bad / "weights.json").write_text(json.dumps(w))
    capsys.readouterr()
    assert main(["verify", str(bad)]) == 1
    captured = capsys.readouterr()
    assert f"NOT OPTIMAL: 1 of {len(w)} stored answers ({first})" in captured.err
    # a stored answer that breaks a complementarity pair is flagged even if its objective is lower
    w = json.loads((run / "weights.json").read_text())
    w[first]["mouthLeft"] = w[first]["mouthRight"] = 0.5
    (bad / "weights.json").write_text(json.dumps(w))
    assert main(["verify", str(bad)]) == 1


def test_verify_needs_the_inputs_record(rig_inputs, tmp_path, capsys):
    root, _ = rig_inputs
    assert main(["verify", str(root / "template")]) == 2
    assert "expected inputs.json (written by `facebasis rig`), found no such file" in capsys.readouterr().err
    run = _run_rig(root, "broken")
    (run / "inputs.json").write_text("{not json")
    assert main(["verify", str(run)]) == 2
    assert "expected keys examples, weights, exclusive, final_lambda" in capsys.readouterr().err


def test_rig_with_virtual_edges(rig_inputs, capsys):
    """The virtual-edge energy joins the basis step's reconstruction; the run still reproduces the
    training expressions (residuals recorded) and the edges are reported."""
    root, pp = rig_inputs
    code = main(args(root, **{"--out": root / "ve_run"}) + ["--virtual-edges", "--virtual-weight", "1"])
    assert code == 0
    out = capsys.readouterr().out
    assert "virtual edges:" in out and "detected on the template neutral" in out
    res = json.loads((root / "ve_run" / "residuals.json").read_text())
    plain = json.loads((root / "out" / "residuals.json").read_text()) if (root / "out").exists() else None
    assert max(res["relative_residual"].values()) < 0.5
    if plain is not None:  # the energy changes the rig (it is not ignored)
        assert res["relative_residual"] != plain["relative_residual"]
    hist = json.loads((root / "ve_run" / "history.json").read_text())
    assert hist["options"]["virtual_weight"] == 1.0 and hist["options"]["virtual_mode"] == "proportional"


def test_rig_says_what_it_does_with_a_single_alpha_and_with_pairs_used_together(rig_inputs, tmp_path, capsys):
    root, _ = rig_inputs
    w = json.loads((root / "weights.json").read_text())
    w["ex00"].update({"mouthLeft": 0.3, "mouthRight": 0.4})
    w["ex01"].update({"mouthLeft": 0.2, "mouthRight": 0.1})
    w["ex02"].pop("mouthLeft", None)
    (tmp_path / "w.json").write_text(json.dumps(w))
    code = main(args(root, **{"--out": tmp_path / "o", "--weights": tmp_path / "w.json", "--alpha": "0.3",
                              "--iterations": "1"}) + ["--exclusive", "mouthLeft:mouthRight"])
    assert code == 0
    out, err = capsys.readouterr()
    assert "note: --alpha 0.3 is one number: held constant over all iterations" in out
    line = next(s for s in err.splitlines() if s.startswith("warning: exclusive pair mouthLeft:mouthRight"))
    assert "ex00" in line and "ex01" in line and "ex02" not in line


def test_verify_flags_a_weight_on_a_shape_the_run_held_at_zero(rig_inputs, capsys):
    """Shapes without support in the examples are held at 0 (``unobserved`` in inputs.json); a stored
    weight on one of them is a broken constraint, not a better answer."""
    import shutil

    root, pp = rig_inputs
    code = main(args(root, **{"--out": root / "held", "--support": "0.99"}))
    assert code == 0
    held = json.loads((root / "held" / "inputs.json").read_text())["unobserved"]
    assert held, "a support of 0.99 leaves some shape without support"
    capsys.readouterr()
    assert main(["verify", str(root / "held")]) == 0
    bad = root / "held_copy"
    shutil.copytree(root / "held", bad)
    w = json.loads((bad / "weights.json").read_text())
    first = sorted(w)[0]
    w[first][held[0]] = 0.01
    (bad / "weights.json").write_text(json.dumps(w))
    assert main(["verify", str(bad)]) == 1
    assert f"NOT OPTIMAL: 1 of {len(w)} stored answers ({first})" in capsys.readouterr().err


def test_verify_names_a_shape_file_missing_from_the_run(rig_inputs, capsys):
    import shutil

    root, pp = rig_inputs
    run = _run_rig(root, "verified_missing")
    broken = root / "missing_shape"
    shutil.copytree(run, broken)
    used = sorted({s for row in json.loads((broken / "weights.json").read_text()).values() for s in row})
    (broken / f"{used[0]}.obj").unlink()
    capsys.readouterr()
    assert main(["verify", str(broken)]) == 2
    assert f"expected a mesh for every shape its weights.json names, found none for ['{used[0]}']" in capsys.readouterr().err
