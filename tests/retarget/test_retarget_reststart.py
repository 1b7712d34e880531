"""Whether a take starts at rest, from its landmarks (issue 23, :mod:`facebasis.retarget.reststart`):
the rest decision of ``identity="auto"`` on synthetic takes that start at rest, with the mouth open
or mid-motion, under several noise draws."""

import numpy as np
import pytest
from test_retarget_restface import own_face

from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.retarget import calibrate
from facebasis.retarget.reststart import STILL_TOL, inner_lip_gap, rest_start
from facebasis.retarget.rigdrive import RigRetargeter
from facebasis.retarget.synthetic import synthetic_capture

FPS = 30.0
T = 300


@pytest.fixture(scope="module")
def rig_idx():
    return default_template(), face_landmarks()


def talking(rig, start: str):
    """Weights (T, k) of a take that talks (jawOpen 0.3-0.45 with a smile) with pauses at rest (frames
    100-119, 200-219) and starts (frames 0-29) ``"rest"``: at rest; ``"open"``: the mouth held open
    (jawOpen 0.6); ``"moving"``: mid-sentence (jawOpen swinging 0-0.5 at 3 Hz); the pause mask."""
    t = np.arange(T) / FPS
    X = np.zeros((T, rig.n_shapes))
    jaw, sl, sr = (rig.names.index(n) for n in ("jawOpen", "mouthSmile_L", "mouthSmile_R"))
    X[:, jaw] = 0.375 + 0.075 * np.sin(2 * np.pi * t / 0.7)
    X[:, sl] = X[:, sr] = 0.2 + 0.1 * np.sin(2 * np.pi * t / 2.3)
    pause = ((np.arange(T) % 100) < 20) & (np.arange(T) >= 100)
    X[pause] = 0.0
    X[:30] = 0.0
    if start == "open":
        X[:30, jaw] = 0.6
    elif start == "moving":
        X[:30, jaw] = 0.25 - 0.25 * np.cos(2 * np.pi * 3.0 * t[:30])
    return X, pause


def capture(rig, idx, X, seed=3, noise_px=0.3):
    person = rig.with_neutral(own_face(rig, idx), rig.deltas, "a person")
    return synthetic_capture(person, idx, X, noise_px=noise_px, fps=FPS, seed=seed, amplitude_deg=5.0)


@pytest.mark.parametrize("seed", range(5))
def test_the_start_evidence_does_not_flip_with_landmark_noise(rig_idx, seed):
    rig, idx = rig_idx
    vis = np.ones((T, len(idx)), bool)
    verdicts = {}
    for start in ("rest", "open", "moving"):
        cap = capture(rig, idx, talking(rig, start)[0], seed=seed, noise_px=0.5)
        verdicts[start] = rest_start(cap.landmarks, vis, FPS)
    assert verdicts["rest"].at_rest and verdicts["rest"].still and verdicts["rest"].closed
    assert verdicts["open"].still and not verdicts["open"].closed and not verdicts["open"].at_rest
    assert not verdicts["moving"].still and not verdicts["moving"].at_rest
    assert verdicts["moving"].deviation > STILL_TOL > 2 * verdicts["rest"].deviation
    assert list(verdicts["rest"].frames) == list(range(15))                   # half a second at 30 fps


def test_a_short_rest_start_counts_and_its_window_ends_where_the_face_leaves_it(rig_idx):
    rig, idx = rig_idx
    X, _ = talking(rig, "rest")
    X[12:30, rig.names.index("jawOpen")] = 0.6                 # at rest for 0.4 s, then the mouth opens at once
    ev = rest_start(capture(rig, idx, X).landmarks, np.ones((T, len(idx)), bool), FPS)
    assert ev.at_rest and list(ev.frames) == list(range(12))
    X[6:30, rig.names.index("jawOpen")] = 0.6                  # 0.2 s: shorter than START_MIN, not a held posture
    assert not rest_start(capture(rig, idx, X).landmarks, np.ones((T, len(idx)), bool), FPS).still


def test_no_evidence_on_other_layouts_or_a_lost_first_frame(rig_idx):
    rig, idx = rig_idx
    cap = capture(rig, idx, talking(rig, "rest")[0])
    vis = np.ones((T, len(idx)), bool)
    assert rest_start(cap.landmarks[:, :60], vis[:, :60], FPS) is None            # not the 68-point iBUG layout
    lost = vis.copy()
    lost[0, :10] = False                                                           # frame 0 lost 10 of 68
    assert rest_start(cap.landmarks, lost, FPS) is None
    lost[0, :10], lost[3, :10] = True, False                                       # a later window frame left out
    ev = rest_start(cap.landmarks, lost, FPS)
    assert ev.at_rest and 3 not in ev.frames and 0 in ev.frames
    gap = inner_lip_gap(cap.clean)
    assert gap[:30].max() < 0.05 < 0.1 < np.median(gap[30:100])                    # closed lips, then talking


@pytest.fixture(scope="module")
def runs(rig_idx):
    rig, idx = rig_idx
    out = {}
    for start in ("rest", "open"):
        X, pause = talking(rig, start)
        cap = capture(rig, idx, X)
        out[start] = (X, pause, RigRetargeter(rig, idx).run(cap.landmarks, fps=FPS))
    return out


def test_a_take_that_starts_at_rest_is_anchored_and_rests_at_zero(runs):
    X, pause, res = runs["rest"]
    cal = res.calibration
    assert cal.rest_start is True and cal.rest_anchored and cal.demand_ratio <= calibrate.ANCHOR_DEMAND_MAX
    assert np.median(res.weights[:30].max(1)) < 0.05                               # the owner's calm frames
    assert np.median(res.weights[pause].max(1)) < 0.1                              # and the pauses later on


def test_a_missing_point_in_the_start_window_leaves_the_rest_verdict(rig_idx, runs):
    """A landmark given as NaN on one frame of the start window (a library caller's capture): that
    frame is left out of the evidence instead of entering it as a point at (0, 0)."""
    rig, idx = rig_idx
    X, pause, _ = runs["rest"]
    P = capture(rig, idx, X).landmarks.copy()
    P[5, 3] = np.nan
    cal = RigRetargeter(rig, idx).run(P, fps=FPS).calibration
    assert cal.rest_start is True and cal.rest_anchored


def test_a_take_that_starts_with_the_mouth_open_keeps_its_jaw_open(rig_idx, runs):
    rig, _ = rig_idx
    X, pause, res = runs["open"]
    cal = res.calibration
    assert cal.rest_start is False and not cal.rest_anchored and np.isnan(cal.demand_ratio)
    jaw = rig.names.index("jawOpen")
    # what the face does on the frames that resemble frame 0: the jaw held open (truth 0.6), not zeroed
    assert np.median(res.weights[:30, jaw]) > 0.4
    assert np.median(res.weights[:30, jaw]) > np.median(res.weights[30:100, jaw]) + 0.1    # more open than speech


def test_evidence_of_rest_is_still_checked_by_the_demand(rig_idx, monkeypatch):
    rig, idx = rig_idx
    X, _ = talking(rig, "rest")
    cap = capture(rig, idx, X)
    model = RigRetargeter(rig, idx).model
    vis = np.ones(cap.landmarks.shape[:2], bool)
    ev = rest_start(cap.landmarks, vis, FPS)
    monkeypatch.setattr(calibrate, "ANCHOR_DEMAND_MAX", 0.0)                       # no demand is small enough
    cal = calibrate.calibrate_auto(model, cap.landmarks, vis, start=ev)
    assert cal.rest_start is True and not cal.rest_anchored and np.isfinite(cal.demand_ratio)

