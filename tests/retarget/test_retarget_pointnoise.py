"""Per-landmark noise (issue 23, target 3: on a tracking-only cut of cap13 at rest, the left brow's outer
points, which the rig reproduced 3-10 times worse than the typical landmark, drove browDown_L to 0.17
while browDown_R stayed at 0): ``RigRetargeter(point_noise=...)``, :mod:`facebasis.retarget.pointnoise`."""

import inspect

import numpy as np
import pytest

from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.retarget.calibrate import pilot_frames
from facebasis.retarget.pointnoise import noise_floor, point_sigmas, point_weights
from facebasis.retarget.rigdrive import RigRetargeter
from facebasis.retarget.synthetic import smooth_weight_curves, synthetic_capture

T = 150
#: one eye's six points of the 68-point layout (the person's left eye, image right)
NOISY = np.arange(42, 48)


def one_noisy_eye(seed: int, extra_px: float = 2.5):
    """The built-in face, symmetric expressions only (rest for 60 frames, then jawOpen, both smiles and
    browInnerUp), 0.5 px noise everywhere and ``extra_px`` more on one eye's points: a detector (or a
    lid search) that places one eye worse than the rest of the face."""
    rig, idx = default_template(), face_landmarks()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L", "mouthSmile_R", "browInnerUp"), T, seed=seed)
    X[:60] = 0.0
    P = synthetic_capture(rig, idx, X, noise_px=0.5, seed=seed, amplitude_deg=3.0).landmarks.copy()
    P[:, NOISY] += extra_px * np.random.default_rng(10 + seed).standard_normal((T, len(NOISY), 2))
    return rig, idx, X, P


def lr_difference(names, W) -> np.ndarray:
    """(T,) the largest |left - right| over the _L/_R pairs (the owner's measure)."""
    pairs = [(i, names.index(n[:-2] + "_R")) for i, n in enumerate(names) if n.endswith("_L")]
    return np.abs(W[:, [a for a, _ in pairs]] - W[:, [b for _, b in pairs]]).max(1)


def test_point_weights_follow_the_noise_and_never_exceed_one():
    """w_l = sigma_ref / max(sigma_l, sigma_ref), sigma_ref the median of the known sigmas."""
    w = point_weights([1.0, 1.0, 1.0, 4.0, 0.5, np.nan])
    np.testing.assert_allclose(w, [1.0, 1.0, 1.0, 0.25, 1.0, 1.0])
    np.testing.assert_array_equal(point_weights([0.0, 0.0, 0.0, 1.0]), np.ones(4))   # a noise-free capture
    np.testing.assert_array_equal(point_weights([np.nan, np.nan]), np.ones(2))
    np.testing.assert_allclose(point_weights([1.0, 1.0, 4.0], floor=2.0), [1.0, 1.0, 0.5])   # r = the floor
    np.testing.assert_array_equal(point_weights([0.01, 0.01, 0.04], floor=0.05), np.ones(3))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_noisy_eye_is_found_and_weighs_as_its_noise_says(seed):
    """Noise 0.5 px and sqrt(0.5^2 + 2.5^2) = 2.55 px: the maximum-likelihood square-root weight of the
    noisy points is 0.5 / 2.55 = 0.20 (measured 0.17-0.25); the others stay near 1 (the median is the
    reference: half of them are 1 exactly, the rest within their own estimate's spread, >= 0.67)."""
    rig, idx, _, P = one_noisy_eye(seed)
    r = RigRetargeter(rig, idx)
    model = r.settle(P, np.ones(P.shape[:2], bool), 30.0)[0]
    w = model.point_weights
    assert w is not None and w.shape == (len(idx),)
    assert np.all((w[NOISY] > 0.1) & (w[NOISY] < 0.35))
    others = np.delete(w, NOISY)
    assert others.min() > 0.55 and np.median(others) > 0.9
    vis = np.ones(P.shape[:2], bool)
    sigma = point_sigmas(model, P, vis, pilot_frames(vis, 40))      # the pilot fits ignore the weights
    assert np.median(sigma[NOISY]) > 3 * np.median(np.delete(sigma, NOISY))


def test_few_frames_do_not_take_weight_from_landmarks_by_chance():
    """The same 1 px noise on every landmark, 6 frames: each landmark's estimate alone (prior_frames 0)
    put 5-13 of 68 landmarks below half weight (w^2 < 0.5) over five seeds; shrunk towards the median as
    if 10 more frames had shown it, 0-1. Bounds: at most 1 per seed shrunk, at least 4 unshrunk; the
    noisy eye (2.5 px more) is still found from 6 frames."""
    rig, idx = default_template(), face_landmarks()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L"), 6, seed=7)
    vis = np.ones((6, len(idx)), bool)
    for seed in range(3):
        P = synthetic_capture(rig, idx, X, noise_px=1.0, seed=seed).landmarks
        model = RigRetargeter(rig, idx, point_noise="shared").settle(P, vis, 30.0)[0]
        low = [int((point_weights(point_sigmas(model, P, vis, range(6), prior_frames=n), noise_floor(model.v0)) ** 2
                    < 0.5).sum()) for n in (0.0, 10.0)]
        assert low[0] >= 4 and low[1] <= 1, low
    P = P.copy()
    P[:, NOISY] += 2.5 * np.random.default_rng(3).standard_normal((6, len(NOISY), 2))
    w = RigRetargeter(rig, idx).settle(P, vis, 30.0)[0].point_weights
    assert np.median(w[NOISY]) < 0.6 < np.median(np.delete(w, NOISY))


def test_the_noisy_eye_is_found_on_a_rig_in_metres():
    """The floor scales with the face (a fixed floor in rig units, 0.016, switched the model off on a rig
    in metres: every weight 1). The pilot fits' ridge floor does not scale (a fixed 1e-3 in rig units^2,
    older than this model), so the weights are not equal to the centimetre rig's, only alike."""
    rig, idx, _, P = one_noisy_eye(0)
    metres = rig.with_neutral(rig.neutral / 100.0, rig.deltas / 100.0, "in metres")
    vis = np.ones(P.shape[:2], bool)
    w = RigRetargeter(metres, idx).settle(P, vis, 30.0)[0].point_weights
    assert np.all(w[NOISY] < 0.35) and np.median(np.delete(w, NOISY)) > 0.9
    assert noise_floor(metres.neutral[idx]) == pytest.approx(noise_floor(rig.neutral[idx]) / 100.0)


@pytest.mark.parametrize("seed", [0, 2])
def test_a_symmetric_face_with_one_noisy_eye_keeps_left_and_right_together(seed):
    """The owner's measures on a symmetric face whose expressions are symmetric: with one noise for every
    landmark the noisy eye is read as one-sided shapes (rest frames' largest weight 0.056-0.100, median
    left/right difference 0.12-0.18 over three seeds); per point, 0.010-0.013 and 0.019-0.028. Bounds:
    the rest frames' largest weight <= 0.03 and the left/right difference <= 0.05 (twice the worst
    measured), each at most half the shared model's, and a lower weight error."""
    rig, idx, X, P = one_noisy_eye(seed)
    per_point = RigRetargeter(rig, idx).run(P, fps=30.0)                      # the default
    shared = RigRetargeter(rig, idx, point_noise="shared").run(P, fps=30.0)
    assert shared.point_weights is None and per_point.point_weights is not None
    rest_pp, rest_sh = np.median(per_point.weights[:60].max(1)), np.median(shared.weights[:60].max(1))
    lr_pp, lr_sh = np.median(lr_difference(rig.names, per_point.weights)), np.median(lr_difference(rig.names, shared.weights))
    assert rest_pp <= 0.03 and rest_pp <= 0.5 * rest_sh
    assert lr_pp <= 0.05 and lr_pp <= 0.5 * lr_sh
    assert np.abs(per_point.weights - X).mean() < np.abs(shared.weights - X).mean()


def test_equal_noise_changes_little_and_noise_free_data_stays_close():
    """Every landmark with the same noise: the estimated weights scatter around 1 and a 0.5 px capture's
    weight error moves by at most 10 % (measured 0.0070 against 0.0071, seeds 4 and 5: 1-3 %). Noise-free
    landmarks: what the pilot fits leave is the priors' bias (below the noise floor), so every weight is
    1 and the answer is the shared model's (without the floor: errors 0.00065-0.00072 against 0.00036)."""
    rig, idx = default_template(), face_landmarks()
    X = smooth_weight_curves(rig.names, ("jawOpen", "mouthSmile_L", "eyeBlink_L", "browInnerUp"), 90, seed=4)
    noisy = synthetic_capture(rig, idx, X, noise_px=0.5, seed=4).landmarks
    e = [np.abs(RigRetargeter(rig, idx, point_noise=m).run(noisy).weights - X).mean() for m in ("per-point", "shared")]
    assert abs(e[0] - e[1]) <= 0.1 * e[1]
    exact = synthetic_capture(rig, idx, X, noise_px=0.0, seed=4).landmarks
    a, b = (RigRetargeter(rig, idx, point_noise=m).run(exact) for m in ("per-point", "shared"))
    np.testing.assert_array_equal(a.point_weights, np.ones(len(idx)))
    np.testing.assert_array_equal(a.weights, b.weights)
    assert np.abs(a.weights - X).mean() < 1e-3


def test_point_noise_values():
    rig, idx = default_template(), face_landmarks()
    assert inspect.signature(RigRetargeter).parameters["point_noise"].default == "per-point"
    for bad in ("pointwise", "", 3):
        with pytest.raises(InputError, match=r"^point_noise: expected one of per-point, shared, found "):
            RigRetargeter(rig, idx, point_noise=bad)
