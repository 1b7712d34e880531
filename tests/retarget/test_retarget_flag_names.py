"""Retargeting's errors and hints name the library's parameters; the command line writes its flags (#25 item 5)."""

import pytest

from facebasis.capture.trackfile import write_capture
from facebasis.cli import main
from facebasis.cli.common import flags_of
from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError, RigError
from facebasis.retarget.pipeline import load_retarget_rig, run_animate2d
from facebasis.retarget.rigrun import _parse_ridge
from facebasis.retarget.rigdrive import resolve_pairs
from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    rig = default_template()
    X = smooth_weight_curves(rig.names, ("jawOpen",), 3, seed=1)
    cap = synthetic_capture(rig, face_landmarks(), X, noise_px=0.2, seed=1)
    folder = tmp_path_factory.mktemp("flags") / "capture"
    write_capture(folder, capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size))
    return folder


def test_cartoon_image_and_landmarks(capture, tmp_path, capsys):
    png = tmp_path / "c.png"
    png.write_bytes(b"not read: the pair is checked first")
    with pytest.raises(InputError, match=r"^image and landmarks: expected both \(a cartoon and its landmarks\) or "
                                         r"neither \(the built-in cartoon\), found only one$"):
        run_animate2d(capture, tmp_path / "o", image=png)
    assert main(["animate2d", str(capture), "--image", str(png), "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == ("error: --image and --landmarks: expected both (a cartoon and its landmarks) "
                                       "or neither (the built-in cartoon), found only one\n")
    assert not (tmp_path / "o").exists()


def test_rig_exclude_ridge_and_pairs(capture, tmp_path, capsys):
    with pytest.raises(InputError, match=r"^exclude: expected a rig folder \(rig RIG_DIR\) to leave files out of, "
                                         r"found the built-in face \(exclude id\*\)$") as ei:
        load_retarget_rig(None, exclude=("id*",))
    assert str(ei.value.renamed(flags_of("retarget"))) == (
        "--exclude: expected a rig folder (--rig RIG_DIR) to leave files out of, found the built-in face (--exclude id*)")
    with pytest.raises(InputError, match=r"^ridge: expected a finite number >= 0, found lots \(or 'auto', the default\)$"):
        _parse_ridge("lots")
    assert main(["retarget", str(capture), "--ridge", "-1", "--out", str(tmp_path / "r")]) == 2
    assert capsys.readouterr().err == "error: --ridge: expected a finite number >= 0, found -1 (or 'auto', the default)\n"
    rig = default_template()
    with pytest.raises(RigError, match=r"^exclusive: unknown blendshape names \['jawOpem'\]; did you mean") as ei:
        resolve_pairs(rig, [("jawOpen", "jawOpem")])
    assert str(ei.value.renamed(flags_of("retarget"))).startswith("--exclusive: unknown blendshape names ['jawOpem']")
    with pytest.raises(InputError, match=rf"^exclusive: expected shape indices in \[0, {rig.n_shapes}\), found \[\[0, 999\]\]$"):
        resolve_pairs(rig, [(0, 999)])
    with pytest.raises(RigError, match=r"^pairs: unknown blendshape names"):  # a caller's own label, as given
        resolve_pairs(rig, [("jawOpen", "jawOpem")], what="pairs")
    assert main(["retarget", str(capture), "--exclusive", "jawOpen:jawOpem", "--out", str(tmp_path / "r")]) == 2
    assert capsys.readouterr().err.startswith("error: --exclusive: unknown blendshape names ['jawOpem']; did you mean")
    assert not (tmp_path / "r").exists()
