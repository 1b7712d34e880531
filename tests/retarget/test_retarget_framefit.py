"""The frame solver with frozen settings: ``FrameFit``'s fields, calibrations that return an offset
and leave the solver they are given as it was, and a ``run()`` that returns what it settled on."""

import dataclasses

import numpy as np
import pytest

from facebasis.defaults.face import EXCLUSIVE_PAIRS, default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.retarget.calibrate import calibrate_auto, calibrate_identity, calibrate_rest, first_frame_offset
from facebasis.retarget.framefit import RIDGE_FLOOR, FrameFit, FrameSolver
from facebasis.retarget.rigdrive import RigRetargeter
from facebasis.retarget.synthetic import smooth_weight_curves, synthetic_capture


@pytest.fixture(scope="module")
def shifted_person():
    """A short capture of a face whose neutral landmarks sit off the rig's (a static in-plane shift
    of the mouth corners and a puffed cheek), so that every calibration has something to find."""
    rig, idx = default_template(), face_landmarks()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L", "eyeBlink_L"), 24, seed=7)
    neutral = rig.neutral + 0.3 * rig.deltas[rig.names.index("cheekPuff_L")]
    neutral[idx[48:55], 0] += 0.25
    other = rig.with_neutral(neutral, rig.deltas, "the person")
    cap = synthetic_capture(other, idx, X, noise_px=0.3, seed=7, amplitude_deg=3.0)
    return rig, idx, cap


def _frozen_copy(model: FrameSolver):
    return {f.name: np.array(getattr(model, f.name), copy=True) for f in dataclasses.fields(model) if f.name != "ipopt"}


def _same(model: FrameSolver, before) -> bool:
    return all(np.array_equal(np.asarray(getattr(model, k)), v) for k, v in before.items())


def test_frame_fit_has_named_fields_and_unpacks_as_before(shifted_person):
    rig, idx, cap = shifted_person
    fit = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity="rig").solve_frame(cap.landmarks[0])
    assert isinstance(fit, FrameFit)
    assert fit.x.shape == (rig.n_shapes,) and fit.R.shape == (3, 3) and fit.t.shape == (2,)
    assert isinstance(fit.s, float) and fit.s > 0 and isinstance(fit.nodes, int)
    assert np.isfinite(fit.rms) and fit.rms < 20.0
    x, s, R, t, rms, nodes = fit
    assert x is fit.x and s == fit.s and R is fit.R and t is fit.t and rms == fit.rms and nodes == fit.nodes
    assert fit.state == (fit.x, fit.s, fit.R, fit.t)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.s = 1.0
    # too few landmarks visible: the previous state is kept, rms nan, no solve
    lost = RigRetargeter(rig, idx).solve_frame(cap.landmarks[1], np.zeros(len(idx), bool), fit.state)
    assert np.array_equal(lost.x, fit.x) and lost.x is not fit.x and np.isnan(lost.rms) and lost.nodes == 0
    with pytest.raises(InputError, match="expected at least 4 visible landmarks on the first frame, found 0"):
        RigRetargeter(rig, idx).solve_frame(cap.landmarks[1], np.zeros(len(idx), bool))


@pytest.mark.parametrize("calibrate", [calibrate_identity, calibrate_rest, calibrate_auto])
def test_a_calibration_returns_an_offset_and_leaves_its_solver_as_it_was(shifted_person, calibrate):
    rig, idx, cap = shifted_person
    model = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS).model
    before = _frozen_copy(model)
    P, vis = cap.landmarks, np.ones(cap.landmarks.shape[:2], bool)
    cal = calibrate(model, P, vis)
    assert _same(model, before)                                   # nothing in the solver moved
    assert cal.applied and cal.rms_after < cal.rms_before
    assert cal.offset.shape == (len(idx), 3) and np.abs(cal.offset).max() > 0.01
    assert np.allclose(cal.neutral, model.v0 + cal.offset, atol=1e-12)
    again = calibrate(model, P, vis)                              # same solver, same answer
    assert np.array_equal(again.neutral, cal.neutral) and again.rms_after == cal.rms_after
    with pytest.raises(dataclasses.FrozenInstanceError):
        cal.offset = None


def test_first_frame_offset_leaves_its_solver_as_it_was(shifted_person):
    rig, idx, cap = shifted_person
    model = RigRetargeter(rig, idx).model
    before = _frozen_copy(model)
    off = first_frame_offset(model, cap.landmarks[0], np.ones(len(idx), bool))
    assert _same(model, before) and off.shape == (len(idx), 3) and np.abs(off).max() > 0.01
    # the neutral shifted by it reproduces frame 0 far better than the rig's (no weights)
    fit_rig = model.pilot().solve_frame(cap.landmarks[0]).rms
    fit_off = model.shifted(off).pilot().solve_frame(cap.landmarks[0]).rms
    assert fit_off < 0.5 * fit_rig
    with pytest.raises(InputError, match="first-frame neutral: expected at least 4 visible landmarks"):
        first_frame_offset(model, cap.landmarks[0], np.zeros(len(idx), bool))


def test_pilot_and_shifted_build_new_solvers():
    rig, idx = default_template(), face_landmarks()
    model = RigRetargeter(rig, idx, smooth=0.2, ridge=0.03).model
    pilot = model.pilot()
    assert (pilot.smooth, pilot.ridge, pilot.sparsity, pilot.contour_slide) == (0.0, RIDGE_FLOOR, 0.0, 1.0)
    assert model.pilot(plain=False).contour_slide == model.contour_slide != 1.0
    assert (model.smooth, model.ridge) == (0.2, 0.03)
    moved = model.shifted(np.ones((len(idx), 3)))
    assert np.array_equal(moved.v0, model.v0 + 1.0) and moved.D is model.D
    assert np.array_equal(model.v0, rig.neutral[idx])


@pytest.mark.parametrize("identity", ["auto", "first-frame"])
def test_run_returns_what_it_settled_on_and_leaves_the_retargeter_as_it_was(shifted_person, identity):
    rig, idx, cap = shifted_person
    rt = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity=identity)
    before = _frozen_copy(rt.model)
    settings = (rt.smooth, rt.ridge, rt.sparsity, rt.contour_slide)
    first = rt.run(cap.landmarks[:8])
    assert _same(rt.model, before) and (rt.smooth, rt.ridge, rt.sparsity, rt.contour_slide) == settings
    assert first.ridge > RIDGE_FLOOR                              # the "auto" rule's value, in the result only
    assert first.neutral_landmarks.shape == (len(idx), 3)
    assert not np.allclose(first.neutral_landmarks, rig.neutral[idx])
    if identity == "auto":
        assert np.array_equal(first.neutral_landmarks, first.calibration.neutral)
    else:
        assert first.calibration is None
    # the frames were solved on that neutral with that ridge: frame 0 again by hand, same answer
    assert first.pixel_scale > 0                                  # the pixel noise model's s_ref, recorded
    assert first.point_weights is not None and first.point_weights.shape == (len(idx),)   # per-point noise, recorded
    model = dataclasses.replace(rt.model.with_neutral(first.neutral_landmarks), ridge=first.ridge,
                                pixel_scale=first.pixel_scale, point_weights=first.point_weights)
    fit = model.solve_frame(cap.landmarks[0])
    assert np.array_equal(fit.x, first.weights[0]) and fit.rms == first.residual[0]
    # a second run of the same retargeter gives the same result
    second = rt.run(cap.landmarks[:8])
    assert np.array_equal(second.weights, first.weights) and second.ridge == first.ridge
