"""The painting check's readers (problems.cartoon_check): blink frames, sampling, gain, still noise,
the read-back the noise allows and cross-talk, on tiny data built here."""

import numpy as np
import pytest

from problems.bench_cartoon import FEATURES, correlation, features
from problems.cartoon_check import (blink_frames, checked_frames, gain, multiple_correlation, noise_ceiling,
                                    still_noise)


def _eyes(T, closed):
    """(T, 68, 2) landmarks whose eyes (iBUG 36-47) are 10 px wide, 4 px open, shut on ``closed`` frames."""
    lm = np.zeros((T, 68, 2))
    for c, (a, u1, u2, b, l1, l2) in ((0.0, range(36, 42)), (40.0, range(42, 48))):
        lm[:, a] = [c, 0]
        lm[:, b] = [c + 10, 0]
        lm[:, [u1, u2]] = [[c + 3, -2], [c + 7, -2]]
        lm[:, [l2, l1]] = [[c + 3, 2], [c + 7, 2]]
    shut = lm[closed]
    shut[:, [37, 38, 43, 44, 40, 41, 46, 47], 1] = 0.0
    lm[closed] = shut
    return lm


def test_blink_frames_pads_the_shut_frames():
    lm = _eyes(100, [40, 41, 42])
    b = blink_frames(lm, quantile=0.03, pad=2)
    assert b.tolist() == list(range(38, 45))
    assert blink_frames(_eyes(10, [0]), quantile=0.1, pad=2).tolist() == [0, 1, 2]     # clipped at the start


def test_checked_frames_adds_blinks_to_the_regular_sampling():
    lm = _eyes(100, [43])
    lm[:, [40, 41, 46, 47], 1] += np.linspace(0, 1, 100)[:, None]     # eyes a little wider over the take
    lm[43] = _eyes(1, [0])[0]
    f = checked_frames(100, 10, lm)
    assert set(range(0, 100, 10)) <= set(f.tolist()) and 43 in f and 45 in f
    assert checked_frames(100, 10).tolist() == list(range(0, 100, 10))
    assert np.all(np.diff(f) > 0)


def test_gain_and_noise_ceiling():
    rng = np.random.default_rng(0)
    w = np.sin(np.linspace(0, 6, 400))
    r = 0.4 * w + 0.01 * rng.standard_normal(400)
    assert gain(r, w) == pytest.approx(0.4, abs=0.01)
    assert np.isnan(gain(r[:3], w[:3]))
    # a reading = g w + noise of sd n correlates with w at g sd_w / sqrt(g^2 sd_w^2 + n^2)
    n = 0.3
    r = 0.4 * w + n * rng.standard_normal(400)
    assert correlation(r, w) == pytest.approx(noise_ceiling(gain(r, w), np.std(w), n), abs=0.06)
    assert noise_ceiling(0.4, 1.0, 0.0) == pytest.approx(1.0)
    assert noise_ceiling(-0.4, 1.0, 0.0) == pytest.approx(-1.0)
    assert np.isnan(noise_ceiling(np.nan, 1.0, 0.1))


def test_multiple_correlation_sees_cross_talk():
    rng = np.random.default_rng(1)
    W = rng.standard_normal((300, 4))
    read = 0.2 * W[:, 0] + W[:, 1] + 0.05 * rng.standard_normal(300)     # feature 0 read from feature 1's motion
    assert correlation(read, W[:, 0]) < 0.4
    assert multiple_correlation(read, W) > 0.99
    assert np.isnan(multiple_correlation(read[:5], W[:5]))


class _Reader:
    """A stand-in detector: fixed landmarks whose eyes open with the sub-pixel x position of the image's dark
    centroid (a detector whose reading moves with the picture's place); no face on a blank image."""

    def detect(self, image):
        ink = 255.0 - image[..., 0].astype(float)
        if ink.sum() < 255:
            return None
        x = (ink.sum(0) * np.arange(ink.shape[1])).sum() / ink.sum()
        lm = _eyes(1, [])[0]
        lm[[37, 38, 43, 44], 1] -= 5.0 * (x % 1.0)
        return lm


def test_still_noise_is_the_spread_over_sub_pixel_shifts():
    img = np.full((40, 40, 3), 255, np.uint8)
    img[18:22, 18:22] = 0
    sd = still_noise(img, _Reader(), features, n=12, seed=0)
    assert sd.shape == (len(FEATURES),)
    assert sd[FEATURES.index("eye_open")] > 0.005          # the eye moved with the shifts
    assert sd[FEATURES.index("mouth_width")] == 0.0          # nothing else did
    assert np.array_equal(sd, still_noise(img, _Reader(), features, n=12, seed=0))   # seeded
    blank = np.full((40, 40, 3), 255, np.uint8)
    assert np.isnan(still_noise(blank, _Reader(), features, n=5)).all()         # no face found


def test_photographs_take_the_second_detectors_landmarks_only_where_the_first_is_off_the_mouth():
    """target_images: the photographs keep the first detector's landmarks (the captures' convention) unless
    the second puts the mouth more than DISAGREE_IOD eye distances away; the built-in cartoons keep
    their drawn landmarks and no detector is asked about them."""
    pytest.importorskip("skimage")
    from facebasis.defaults.cartoon import cartoon_landmarks, default_cartoon
    from problems.bench_cartoon import DISAGREE_IOD, photo_landmarks, target_images

    class Fixed:
        def __init__(self, shift):
            self.shift, self.calls = shift, 0

        def detect(self, image):
            self.calls += 1
            lm = cartoon_landmarks() * image.shape[0] / 512.0
            lm[48:68, 1] += self.shift * np.linalg.norm(lm[45] - lm[36])   # the mouth moved by shift iod
            return lm

    image = np.zeros((512, 512, 3), np.uint8)
    near, far = Fixed(0.5 * DISAGREE_IOD), Fixed(2 * DISAGREE_IOD)
    first = Fixed(0.0)
    np.testing.assert_array_equal(photo_landmarks(image, first, near), first.detect(image))
    np.testing.assert_array_equal(photo_landmarks(image, first, far), far.detect(image))
    np.testing.assert_array_equal(photo_landmarks(image, first), first.detect(image))

    reader, second = Fixed(0.0), Fixed(2 * DISAGREE_IOD)
    images = dict((n, (img, lm)) for n, img, lm in target_images(reader, second))
    assert reader.calls == 4 and second.calls == 4                # two photographs and their paintings
    for name in ("astronaut", "astronaut-painted", "cameraman", "cameraman-painted"):
        img, lm = images[name]
        np.testing.assert_allclose(lm, second.detect(img))
    np.testing.assert_array_equal(images["cartoon"][1], default_cartoon().landmarks)
