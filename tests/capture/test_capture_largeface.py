"""Precision on a large face (issue 29): the drift correction's template alignment works on an image
blurred by ``TrackerOptions.drift_blur`` (x the face scale). Blurred as the mesh stage's image (1.5,
before) the first-frame patches lost the fine texture that pins them along an edge, and on large
faces the aligned points slid along the lip line and the eyelids as the mouth opened and the eyes
blinked (Grace Hopper upscaled 2x: eyelid point 38 off by 3.9 px)."""

import numpy as np
import pytest

from facebasis.capture.synthetic import Motion, WarpAnimation, cartoon_face
from facebasis.capture.tracker import FaceTracker, TrackerOptions
from facebasis.errors import InputError

FRAMES = 30
LIDS = [37, 38, 43, 44]          # upper eyelid points


@pytest.fixture(scope="module")
def blink_sequence():
    """The cartoon face (built in code) upscaled 3x (384 x 384, face ~245 px wide), a blink every 16
    frames (peak at frame 8 and 24) with the mouth opening, a smile and head motion."""
    import cv2

    img, lm = cartoon_face((128, 128), seed=3)
    img = cv2.resize(img, None, fx=3, fy=3, interpolation=cv2.INTER_CUBIC)
    lm = lm * 3 + 1.0                                   # pixel centres of the upscaled image
    anim = WarpAnimation(img, lm, Motion(mouth_open=0.10, smile=0.03, blink=0.03, brow_raise=0.04,
                                         rotation_deg=3.0, scale=0.03, translation=0.04,
                                         periods=(24.0, 40.0, 16.0, 30.0, 50.0)))
    frames = np.stack([anim.frame(t) for t in range(FRAMES)])
    truth = np.stack([anim.points(t, lm) for t in range(FRAMES)])
    return frames, truth


def _errors(seq, options):
    frames, truth = seq
    tr = FaceTracker(frames[0], truth[0], options)
    lm = np.stack([tr.track(f).landmarks for f in frames[1:]])
    return np.linalg.norm(lm - truth[1:], axis=-1)      # (T-1, 68)


def test_blinking_eyelids_and_opening_mouth_on_a_large_face(blink_sequence):
    """Default options: mean <= 0.3 px, every upper-lid point <= 0.6 px in every frame, no point over
    2.5 px (measured 0.215 mean, lids <= 0.46, max 2.11 at the lower inner lip); the earlier blur of
    1.5 misses all three (0.416, lids up to 0.83, max 4.82)."""
    e = _errors(blink_sequence, TrackerOptions())
    assert e.mean() <= 0.3
    assert e[:, LIDS].max() <= 0.6
    assert e.max() <= 2.5
    old = _errors(blink_sequence, TrackerOptions(drift_blur=1.5))
    assert old.mean() > 0.3 and old[:, LIDS].max() > 0.6 and old.max() > 2.5


@pytest.mark.parametrize("bad", [-0.5, float("nan"), float("inf")])
def test_drift_blur_bad_values_refused(bad):
    img, lm = cartoon_face((128, 128), seed=3)
    with pytest.raises(InputError, match=r"^drift_blur: expected a number >= 0, found"):
        FaceTracker(img, lm, TrackerOptions(drift_blur=bad))
