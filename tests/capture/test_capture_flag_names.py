"""Capture's errors name the library's parameters; the command line writes them as its flags (#25 item 5)."""

import numpy as np
import pytest

from facebasis.capture.detect import available_detector, detect_landmarks, get_detector
from facebasis.capture.inputs import check_capture_args
from facebasis.capture.landmarks import validate_landmarks
from facebasis.capture.video import open_frames, read_frame
from facebasis.cli import main
from facebasis.cli.common import flags_of
from facebasis.errors import InputError


def _frames(tmp_path, n=3):
    import cv2

    d = tmp_path / "frames"
    d.mkdir()
    for i in range(n):
        cv2.imwrite(str(d / f"f{i}.png"), np.full((32, 32, 3), 40 * i, np.uint8))
    return d


def test_capture_inputs_name_parameters_and_the_command_its_flags(tmp_path, capsys):
    d = _frames(tmp_path)
    with pytest.raises(InputError, match=r"^max_frames: expected a positive integer, found 0$"):
        check_capture_args(d, tmp_path / "a.pts", None, None, 0, None)
    with pytest.raises(InputError, match=r"^landmarks: expected exactly one of landmarks FILE or detector NAME, "
                                         r"found both$"):
        check_capture_args(d, tmp_path / "a.pts", "dlib", None, None, None)
    (tmp_path / "a.pts").write_text("version: 1\nn_points: 3\n{\n1 2\n3 4\n5 1\n}\n")
    assert main(["capture", str(d), "--landmarks", str(tmp_path / "a.pts"), "--detector", "dlib",
                 "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == ("error: landmarks: expected exactly one of --landmarks FILE or --detector NAME, "
                                       "found both\n")
    with pytest.raises(InputError, match=r"^fps: expected a positive number, found 0$"):
        open_frames(d, fps=0)


def test_frame_index_is_the_landmarks_command_s_frame(tmp_path, capsys):
    d = _frames(tmp_path)
    with pytest.raises(InputError, match=r"^index: expected a frame number >= 0, found -1$"):
        read_frame(d, -1)
    with pytest.raises(InputError, match=r"^index: expected a frame number below the 3 frames decoded from "):
        read_frame(d, 3)
    assert flags_of("landmarks")["index"] == "--frame" and "index" not in flags_of("capture")
    assert main(["landmarks", str(d), "--frame", "3", "--detector", "dlib", "--out", str(tmp_path / "o.pts")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --frame: expected a frame number below the 3 frames decoded from ") and \
        err.endswith(", found 3\n")
    with pytest.raises(InputError, match=r"^detector: expected one of dlib, mediapipe, found 'opencv'$"):
        detect_landmarks(d, "opencv")


def test_detectors_name_the_parameter(tmp_path, capsys):
    with pytest.raises(InputError, match=r"^detector: expected one of dlib, mediapipe, found 'x'$") as ei:
        get_detector("x")
    assert str(ei.value.renamed(flags_of("capture"))) == "--detector: expected one of dlib, mediapipe, found 'x'"
    assert available_detector() in ("dlib", "mediapipe")
    d = _frames(tmp_path)
    assert main(["capture", str(d), "--detector", "opencv", "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == "error: --detector: expected one of dlib, mediapipe, found 'opencv'\n"


def test_a_landmark_source_may_name_a_parameter():
    with pytest.raises(InputError, match=r"^detector dlib on x.mp4: expected at least 3 points, found 2$") as ei:
        validate_landmarks(np.zeros((2, 2)), "{detector} dlib on x.mp4", params={"detector": "detector"})
    assert str(ei.value.renamed(flags_of("landmarks"))).startswith("--detector dlib on x.mp4: expected at least 3")
    with pytest.raises(InputError, match=r"^landmark file a\{b\}.pts: expected at least 3 points"):
        validate_landmarks(np.zeros((2, 2)), "landmark file a{b}.pts")
