"""Robustness of the tracker on long takes: LK failures and landmarks that tangle (#29 item 1)."""

import numpy as np
import pytest

import facebasis.capture.tracker as tracker_module
from facebasis.capture.landmarks import face_width, neighbour_affine_prediction
from facebasis.capture.lk import LKResult
from facebasis.capture.particle import neighbour_weights
from facebasis.capture.synthetic import synthetic_sequence
from facebasis.capture.tracker import FaceTracker, TrackerOptions
from facebasis.errors import InputError


@pytest.fixture(scope="module")
def seq():
    return synthetic_sequence(24, size=(160, 160))


def test_neighbour_affine_prediction_is_exact_for_an_affine_motion(seq):
    """Leave-one-out: every point is predicted from the others alone, exactly for an affine motion,
    also when some points may not serve as neighbours (their own prediction still comes out)."""
    P0 = seq.landmarks[0]
    A, b = np.array([[1.1, 0.2], [-0.15, 0.9]]), np.array([3.0, -2.0])
    Pt = P0 @ A.T + b
    W = neighbour_weights(P0, 0.2 * face_width(P0))
    conf = np.ones(len(P0), bool)
    conf[[8, 30, 48]] = False
    Pt_bad = Pt.copy()
    Pt_bad[[8, 30, 48]] += 40.0       # non-neighbours: their positions must not matter
    pred = neighbour_affine_prediction(P0, Pt_bad, W, conf)
    assert np.abs(pred - Pt).max() < 1e-4


def test_a_tangled_landmark_is_put_back_and_reported_lost(seq):
    """A jaw point 0.3 face widths off its neighbours' motion is moved back onto it (within 0.05 face
    widths of the truth on the cartoon whose mouth opens: the chin's motion is not quite its
    neighbours' affine motion, measured 0.03) and reported lost; a point 0.05 face widths off (a real
    expression's size) is left where it is."""
    tr = FaceTracker(seq.frames[0], seq.landmarks[0])
    tr.track(seq.frames[1])
    truth = seq.landmarks[12]
    w = face_width(seq.landmarks[0])
    lm = truth.copy()
    lm[8] += [0.0, 0.3 * w]
    lm[36] += [0.05 * w, 0.0]
    out, lost = tr._repair_outliers(lm, np.zeros(68, bool))
    assert lost[8] and not lost[36] and lost.sum() == 1
    assert np.linalg.norm(out[8] - truth[8]) < 0.05 * w
    assert np.array_equal(out[36], lm[36])
    off, lost_off = FaceTracker(seq.frames[0], seq.landmarks[0],
                                TrackerOptions(outlier_distance=0.0))._repair_outliers(lm, np.zeros(68, bool))
    assert np.array_equal(off, lm) and not lost_off.any()


def test_a_diverged_lk_point_does_not_take_the_track_with_it(seq, monkeypatch):
    """LK diverging on one frame (the chin sent off the frame with a failed status, as on cap12 frame
    618) must not move the tracked chin: it restarts from its neighbours' motion and stays within
    2 px of the truth on that frame and every later one."""
    real = tracker_module.lk_track
    calls = {"n": 0}

    def lk_diverging(*a, **k):
        r = real(*a, **k)
        calls["n"] += 1
        if calls["n"] == 10:
            pts, ok = r.points.copy(), r.ok.copy()
            pts[8], ok[8] = [-23.7, 150.0], False
            return LKResult(pts, ok, np.where(ok, r.fb_error, np.inf))
        return r

    monkeypatch.setattr(tracker_module, "lk_track", lk_diverging)
    tr = FaceTracker(seq.frames[0], seq.landmarks[0])
    lm = np.stack([tr.track(f).landmarks for f in seq.frames[1:]])
    e = np.linalg.norm(lm[:, 8] - seq.landmarks[1:, 8], axis=-1)
    assert e[9:].max() < 2.0


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_bad_outlier_distance_is_one_line(seq, bad):
    with pytest.raises(InputError, match=r"^outlier_distance: expected a number >= 0 .*found"):
        FaceTracker(seq.frames[0], seq.landmarks[0], TrackerOptions(outlier_distance=bad))
