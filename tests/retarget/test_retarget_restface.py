"""The rest face of ``identity="auto"`` (issue 23): the first frame's posture when it recurs and is a
rest from which the take's faces are reached with non-negative weights; the commonest posture
otherwise (``rest_anchor``)."""

import numpy as np
import pytest

from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.retarget import calibrate
from facebasis.retarget.calibrate import densest_frames, rest_frames
from facebasis.retarget.observe import landmark_jacobian
from facebasis.retarget.onesided import negative_demand
from facebasis.retarget.rigdrive import RigRetargeter
from facebasis.retarget.synthetic import synthetic_capture

FPS = 30.0


def clusters(rest_frames_at, n=100, L=10, seed=0):
    """Offsets (n, L, 3): most frames around a 'speech' posture (jitter 0.05), the frames
    ``rest_frames_at`` around a 'rest' posture 1 away, held stiller (jitter 0.02)."""
    rng = np.random.default_rng(seed)
    O = np.zeros((n, L, 3))
    O[:, :, :2] = 1.0 + 0.05 * rng.standard_normal((n, L, 2))
    O[rest_frames_at, :, :2] = 0.02 * rng.standard_normal((len(rest_frames_at), L, 2))
    return O


def test_rest_frames_takes_the_first_frames_posture_only_when_it_recurs():
    rest = [0, 9, 23, 41, 57, 70, 88]                        # recurs through the take
    O = clusters(rest)
    dense = densest_frames(O)
    assert not set(dense) & set(rest)                        # the commonest posture is the other one
    near, anchored = rest_frames(O, anchor=0)
    assert anchored and set(near) == set(rest)
    near, anchored = rest_frames(O, anchor=None)
    assert not anchored and set(near) == set(dense)
    lone = clusters([0, 1])                                  # the take starts on a posture it never returns to
    near, anchored = rest_frames(lone, anchor=0)
    assert not anchored and set(near) == set(densest_frames(lone))


def own_face(rig, idx, scale: float = 0.15, seed: int = 4):
    """The rig's neutral with its landmark vertices moved by a static in-plane offset (rms ``scale``
    per landmark) that neither the shapes nor the pose produce: another person's face shape."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(landmark_jacobian(rig, idx))                  # (2L, k + 6), frontal
    o = rng.normal(size=2 * len(idx))
    o = o - Q @ (Q.T @ o)
    o *= scale / np.sqrt(np.mean(o.reshape(-1, 2) ** 2) * 2)
    neutral = rig.neutral.copy()
    neutral[idx, 0] += o.reshape(-1, 2)[:, 0]
    neutral[idx, 1] -= o.reshape(-1, 2)[:, 1]                         # image y down -> rig y up
    return neutral


@pytest.fixture(scope="module")
def rig_and_capture():
    """The built-in face with a face shape of its own (:func:`own_face`), a take that starts at rest and talks: jawOpen 0.3-0.45 on most
    frames, back at rest in pauses (frames 0-19, 100-119, 200-219)."""
    rig, idx = default_template(), face_landmarks()
    T = 300
    t = np.arange(T) / FPS
    X = np.zeros((T, rig.n_shapes))
    X[:, rig.names.index("jawOpen")] = 0.375 + 0.075 * np.sin(2 * np.pi * t / 0.7)
    X[:, rig.names.index("mouthSmile_L")] = X[:, rig.names.index("mouthSmile_R")] = 0.2 + 0.1 * np.sin(2 * np.pi * t / 2.3)
    pause = (np.arange(T) % 100) < 20
    X[pause] = 0.0
    person = rig.with_neutral(own_face(rig, idx), rig.deltas, "a person")
    cap = synthetic_capture(person, idx, X, noise_px=0.3, fps=FPS, seed=3, amplitude_deg=5.0)
    return rig, idx, X, pause, cap


def test_negative_demand_tells_a_rest_neutral_from_an_expression(rig_and_capture):
    rig, idx, X, pause, cap = rig_and_capture
    model = RigRetargeter(rig, idx).model
    truth = model.with_neutral(own_face(rig, idx)[idx])                           # the person's own neutral
    speech = truth.shifted(0.375 * model.D[:, :, rig.names.index("jawOpen")])     # a talking face as neutral
    frames = np.arange(0, len(X), 10)
    at_truth = np.nanmedian(negative_demand(truth, cap.landmarks, np.ones(cap.landmarks.shape[:2], bool), frames))
    at_speech = np.nanmedian(negative_demand(speech, cap.landmarks, np.ones(cap.landmarks.shape[:2], bool), frames))
    assert at_speech > 5 * at_truth
    # the pauses need jawOpen below 0 with the talking neutral: their demand is most of it
    d = negative_demand(speech, cap.landmarks, np.ones(cap.landmarks.shape[:2], bool), np.array([5, 105, 150]))
    assert d[0] > 3 * d[2] and d[1] > 3 * d[2]


def test_a_take_that_starts_at_rest_keeps_weights_near_zero_at_rest(rig_and_capture):
    rig, idx, X, pause, cap = rig_and_capture
    anchored = RigRetargeter(rig, idx).run(cap.landmarks, fps=FPS)
    common = RigRetargeter(rig, idx, rest_anchor=False).run(cap.landmarks, fps=FPS)
    assert not common.calibration.rest_anchored
    assert np.median(anchored.weights[pause].max(1)) < 0.1
    assert np.abs(anchored.weights - X).mean() < 1.1 * np.abs(common.weights - X).mean() + 1e-3


def test_the_first_frames_rest_face_is_kept_only_if_one_sided_enough(rig_and_capture, monkeypatch):
    rig, idx, X, pause, cap = rig_and_capture
    model = RigRetargeter(rig, idx).model
    vis = np.ones(cap.landmarks.shape[:2], bool)
    monkeypatch.setattr(calibrate, "ANCHOR_DEMAND_RATIO", np.inf)         # any demand: the first frame's posture
    cal = calibrate.calibrate_auto(model, cap.landmarks, vis)
    assert cal.rest_anchored and cal.rest_applied and not cal.quantile_applied
    assert not calibrate.calibrate_auto(model, cap.landmarks, vis, anchor=False).rest_anchored
    monkeypatch.setattr(calibrate, "ANCHOR_DEMAND_RATIO", 0.0)            # no demand is small enough
    assert not calibrate.calibrate_auto(model, cap.landmarks, vis).rest_anchored


def test_a_take_that_starts_on_a_held_expression_is_not_anchored_to_it(rig_and_capture):
    rig, idx, X, pause, cap = rig_and_capture
    Y = X.copy()
    Y[:20] = 0.0
    Y[:12, rig.names.index("mouthSmile_L")] = Y[:12, rig.names.index("mouthSmile_R")] = 0.8   # held, never again
    Y[:12, rig.names.index("jawOpen")] = 0.6
    person = rig.with_neutral(own_face(rig, idx), rig.deltas, "p")
    cap2 = synthetic_capture(person, idx, Y, noise_px=0.3, fps=FPS, seed=3, amplitude_deg=5.0)
    res = RigRetargeter(rig, idx).run(cap2.landmarks, fps=FPS)
    assert not res.calibration.rest_anchored


@pytest.mark.parametrize("bad", ["yes", 1, None, 0.0])
def test_rest_anchor_bad_values(bad):
    with pytest.raises(InputError, match=r"rest_anchor: expected True or False, found"):
        RigRetargeter(default_template(), face_landmarks(), rest_anchor=bad)
