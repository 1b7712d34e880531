"""A misspelt shape name in a rough-weights file is answered with the nearest name (jawOpem ->
jawOpen), not the template's whole list; a name near nothing still lists them."""

import json

from facebasis.cli import main


def test_rough_weights_suggest_the_nearest_shape_name(tmp_path, capsys):
    from facebasis.rigging.synthetic import default_face_problem
    from facebasis.rigging.runs import write_problem_inputs
    from facebasis.geometry.rig import write_rig_folder
    from facebasis.geometry.meshio import write_mesh

    p = default_face_problem(seed=0, n_train=2).problem
    examples, weights = write_problem_inputs(tmp_path / "inputs", p)
    write_rig_folder(tmp_path / "template", p.template)
    write_mesh(tmp_path / "target.obj", p.target_neutral, p.template.faces)
    rough = json.loads(weights.read_text())
    first = sorted(rough)[0]
    argv = ["rig", "--template", str(tmp_path / "template"), "--target", str(tmp_path / "target.obj"),
            "--examples", str(examples), "--weights", str(tmp_path / "w.json"), "--out", str(tmp_path / "run")]
    (tmp_path / "w.json").write_text(json.dumps({**rough, first: {**rough[first], "jawOpem": 0.5}}))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{first}: unknown blendshape names ['jawOpem']; did you mean 'jawOpen' for 'jawOpem'?" in err
    assert "mouthPucker" not in err and len(err.strip().splitlines()) == 1
    (tmp_path / "w.json").write_text(json.dumps({**rough, first: {**rough[first], "zzz": 0.5}}))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "unknown blendshape names ['zzz']; expected names of the template: [" in err and "jawOpen" in err
    assert not (tmp_path / "run").exists()
