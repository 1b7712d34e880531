"""Landmark noise of a fixed size in pixels (issue 23, target 3: calm frames of a person who leans
away from the camera carried browDown_R 0.45-0.85 on cap12's last 20 s, following the solved scale at
r = -0.81 while the residual in pixels did not follow it, r = -0.04): ``RigRetargeter(noise_model=...)``,
:meth:`facebasis.retarget.rigdrive.RigRetargeter.pilot_stats`."""

import numpy as np
import pytest
from test_retarget_restface import own_face

from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.retarget.pose import project_landmarks, rotation_from_vector
from facebasis.retarget.rigdrive import RigRetargeter
from facebasis.retarget.synthetic import smooth_weight_curves

FPS, T = 25.0, 200


def take(rig, idx, seed):
    """A face of its own shape that talks (frames 40-139) and rests at the start (0-39, 9 px per rig
    unit) and at the end (140-199) after it moved away (4 px per unit), head turning +-4-5 degrees,
    1 px landmark noise in every frame (a detector's error does not shrink with the face)."""
    t = np.arange(T) / FPS
    X = smooth_weight_curves(rig.names, ["jawOpen", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L", "eyeBlink_R"],
                             T, fps=FPS, seed=3)
    X[:40] = 0.0
    X[140:] = 0.0
    Q = own_face(rig, idx)[idx] + np.tensordot(X, rig.deltas[:, idx], axes=(1, 0))
    R = np.stack([rotation_from_vector([np.deg2rad(5) * np.sin(2 * np.pi * u / 3), np.deg2rad(4) * np.sin(2 * np.pi * u / 2.5),
                                        0.0]) for u in t])
    s = np.concatenate([np.full(100, 9.0), np.linspace(9.0, 4.0, 40), np.full(60, 4.0)])
    P = project_landmarks(Q, s, R, np.tile([200.0, 150.0], (T, 1)))
    return X, s, P + np.random.default_rng(seed).standard_normal(P.shape)


@pytest.mark.parametrize("seed", [0])
def test_a_face_at_rest_far_from_the_camera_keeps_weights_near_zero(seed):
    """Bound 0.05 on the median largest weight of the far rest frames: the near rest frames (the same
    noise in pixels on a face 2.25x larger) carry 0.01-0.03 with either model; the former model (noise
    of a fixed size in rig units, its ridge set at the median scale) gives 0.16-0.19 there."""
    rig, idx = default_template(), face_landmarks()
    X, s, P = take(rig, idx, seed)
    px = RigRetargeter(rig, idx, noise_model="pixels").run(P, fps=FPS)
    rig_units = RigRetargeter(rig, idx, noise_model="rig").run(P, fps=FPS)
    far, near, talk = slice(140, 200), slice(0, 40), slice(40, 100)
    assert np.median(px.weights[far].max(1)) <= 0.05
    assert np.median(rig_units.weights[far].max(1)) >= 0.1                      # the cause, measured
    assert abs(np.median(px.weights[near].max(1)) - np.median(rig_units.weights[near].max(1))) <= 0.01
    assert np.abs(px.weights - X)[talk].mean() <= np.abs(rig_units.weights - X)[talk].mean() + 0.002
    assert np.abs(px.weights - X).mean() < np.abs(rig_units.weights - X).mean()


def test_reference_scale_is_the_median_scale_of_the_capture():
    """s_ref: the median scale of the pilot fits that set the noise (RigRetargeter.pilot_stats)."""
    rig, idx = default_template(), face_landmarks()
    X, s, P = take(rig, idx, 0)
    r = RigRetargeter(rig, idx)
    vis = np.ones(P.shape[:2], bool)
    noise, s_ref = r.pilot_stats(P, vis)
    assert abs(s_ref - np.median(s)) < 0.05 * np.median(s) and noise == r.estimate_noise(P, vis)
    assert np.isnan(r.pilot_stats(P, np.zeros_like(vis))[1])


@pytest.mark.parametrize("bad", ["metres", "", 3, None])
def test_bad_noise_model_is_a_one_line_error(bad):
    rig, idx = default_template(), face_landmarks()
    if bad is None:                                   # None is the default
        assert RigRetargeter(rig, idx, noise_model=None).noise_model == "pixels"
        return
    with pytest.raises(InputError, match=r"^noise_model: expected .*pixels.*rig.*, found "):
        RigRetargeter(rig, idx, noise_model=bad)
