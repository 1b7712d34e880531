"""The command line: transfer and demo, outputs and atomic failure."""

import json

import numpy as np
import pytest

from facebasis.cli import main
from facebasis.defaults.face import default_person, default_template
from facebasis.geometry.meshio import read_mesh, write_mesh
from facebasis.geometry.rig import load_rig_folder, write_rig_folder


@pytest.fixture
def template_dir(tmp_path):
    write_rig_folder(tmp_path / "template", default_template())
    write_mesh(tmp_path / "person.obj", default_person().neutral, default_person().faces)
    return tmp_path


def test_transfer_cli_writes_every_shape(template_dir, capsys):
    out = template_dir / "out"
    assert main(["transfer", "--template", str(template_dir / "template"), "--target",
                 str(template_dir / "person.obj"), "--out", str(out)]) == 0
    names = default_template().names
    assert sorted(p.stem for p in out.glob("*.obj")) == sorted(list(names) + ["neutral"])
    V, F = read_mesh(out / "jawOpen.obj")
    assert np.array_equal(F, default_template().faces)
    rig = load_rig_folder(out)
    from facebasis import deformation_transfer

    ref = deformation_transfer(default_template(), default_person().neutral)
    assert np.allclose(rig.deltas[rig.index(["jawOpen"])[0]], ref.deltas[ref.index(["jawOpen"])[0]], atol=1e-7)
    assert "transferred 15 shapes" in capsys.readouterr().out


def test_transfer_cli_bad_target_leaves_nothing(template_dir, capsys):
    bad = template_dir / "bad.obj"
    V, F = default_person().neutral, default_person().faces
    write_mesh(bad, V[:-5], F[:100])
    out = template_dir / "out"
    code = main(["transfer", "--template", str(template_dir / "template"), "--target", str(bad), "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert "bad.obj: expected 4497 vertices as in template" in err and "found 4492" in err
    assert not out.exists()
    assert not list(template_dir.glob(".out*"))  # no staging folder left behind


def test_atomic_output_keeps_previous_result_on_failure(template_dir, monkeypatch, capsys):
    out = template_dir / "out"
    args = ["transfer", "--template", str(template_dir / "template"), "--target",
            str(template_dir / "person.obj"), "--out", str(out)]
    assert main(args) == 0
    before = sorted(p.name for p in out.iterdir())
    import facebasis.geometry.rig as rigmod

    calls = {"n": 0}
    real = rigmod.write_mesh

    def failing(path, V, F):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(28, "No space left on device", str(path))
        return real(path, V, F)

    monkeypatch.setattr(rigmod, "write_mesh", failing)
    capsys.readouterr()
    assert main(args) == 2  # an OS error is one line naming the output, exit 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: facebasis transfer: writing output {out} (staging .out.")
    assert "No space left on device [ENOSPC]; the disk is full" in err
    assert sorted(p.name for p in out.iterdir()) == before
    assert not list(template_dir.glob(".out*"))


def test_cli_unknown_neutral_name(template_dir, capsys):
    code = main(["transfer", "--template", str(template_dir / "template"), "--neutral", "generic.obj",
                 "--target", str(template_dir / "person.obj"), "--out", str(template_dir / "o")])
    assert code == 2
    assert "expected the neutral 'generic.obj', found no such file" in capsys.readouterr().err


def test_demo_quick(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["template_vertices"] == default_template().n_vertices
    prov = json.loads((out / "provenance.json").read_text())  # what made the folder (no inputs: built-in data)
    assert prov["argv"][:2] == ["facebasis", "demo"] and prov["inputs"] == [] and prov["libraries"]["casadi"]
    assert (out / "figures" / "error_maps.png").stat().st_size > 10000
    assert len(list((out / "transfer").glob("*.obj"))) == 16
    # the demo's rig is a complete `facebasis rig` folder: it verifies, reports and exports
    assert main(["verify", str(out / "rig")]) == 0
    assert main(["report", str(out / "rig"), "--formats", "png"]) == 0
    assert (out / "rig" / "report" / "convergence.png").is_file() and (out / "rig" / "rig.glb").is_file()
    # and it captures its generated sequence and reproduces it on the built-in cartoon and rig
    from facebasis.capture.trackfile import read_capture

    cap = read_capture(out / "capture")
    assert cap.landmarks.shape == (summary["video"]["frames"], 68, 2)
    assert summary["video"]["landmark_error_px_mean"] < 2.0  # against the generated sequence's known motion
    assert (out / "capture" / "overlay.mp4").stat().st_size > 0 and (out / "cartoon" / "cartoon.mp4").is_file()
    weights = (out / "retarget" / "weights.csv").read_text().splitlines()
    assert len(weights) == 1 + summary["video"]["frames"] and weights[0].startswith("frame,jawOpen")
    assert (out / "retarget" / "animation.glb").is_file()
