"""The face contour of a still head (retarget.jawline): it follows the lower lip, not the head turning."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from facebasis.defaults.cartoon import cartoon_landmarks
from facebasis.errors import InputError
from facebasis.retarget.jawline import contour_weights, jaw_from_lips
from facebasis.retarget.warp2d import CartoonAnimator

T = 8


def _rest():
    return cartoon_landmarks() / 4.0          # 68 points on a 128 px canvas


def _turning(rest, shift):
    """(T, 68, 2): the face contour (0-16) slides sideways by ``shift`` (T,) pixels, the rest still: what a
    head turning out of the image plane leaves once its similarity is out."""
    P = np.repeat(rest[None], T, axis=0)
    P[:, :17, 0] += shift[:, None] * np.cos(np.linspace(-1.2, 1.2, 17))[None]
    return P


def _opening(rest, drop):
    """(T, 68, 2): the lower lip (inner 65-67, outer 55-59) drops by ``drop`` (T,) pixels."""
    P = np.repeat(rest[None], T, axis=0)
    P[:, np.r_[55:60, 65:68], 1] += drop[:, None]
    return P


def test_contour_follows_the_lower_lip_and_ignores_its_own_sideways_slide():
    rest = _rest()
    shift = np.linspace(0.0, 6.0, T)
    out = jaw_from_lips(_turning(rest, shift), rest)
    assert np.abs(out[:, :17] - rest[:17]).max() < 1e-12          # a turn leaves the contour where it was
    drop = np.linspace(0.0, 5.0, T)
    out = jaw_from_lips(_opening(rest, drop) + (_turning(rest, shift) - rest), rest)     # opens while turning
    assert out[:, 8, 1] - rest[8, 1] == pytest.approx(drop)       # the chin with the lip
    assert out[:, 6, 1] - rest[6, 1] == pytest.approx(drop)
    assert np.abs(out[:, np.r_[0:6, 11:17]] - rest[np.r_[0:6, 11:17]]).max() < 1e-12  # jaw angles to the ears still
    assert np.array_equal(out[:, 17:], _opening(rest, drop)[:, 17:])
    w = contour_weights()
    assert w[8] == 1 and w[0] == w[16] == 0 and np.allclose(w, w[::-1]) and w.tolist().count(1.0) == 5


def test_jaw_from_lips_refuses_other_shapes():
    with pytest.raises(InputError, match="expected .T, N >= 68, 2."):
        jaw_from_lips(np.zeros((3, 20, 2)), np.zeros((20, 2)))


def _animator(jaw="lips"):
    rest = _rest()
    img = np.full((128, 128, 3), 180, np.uint8)
    return rest, CartoonAnimator(img, rest, rest, rest, Delaunay(rest).simplices, jaw=jaw)


def test_cartoon_contour_stays_when_the_head_turns_by_default():
    rest, anim = _animator()
    P = _turning(rest, np.linspace(0.0, 6.0, T))
    still = anim.drive(P, P).still
    assert np.abs(still[:, :68] - anim.rest[:68]).max() < 1e-6
    _, captured = _animator("capture")
    moved = captured.drive(P, P).still
    assert np.abs(moved[-1, :17, 0] - captured.rest[:17, 0]).max() > 3.0      # the captured contour slides


def test_bad_jaw_mode_is_refused():
    with pytest.raises(InputError, match="jaw: expected one of lips, capture, found 'chin'"):
        _animator("chin")


def test_the_readback_ramps_keep_their_own_contour():
    from problems.bench_cartoon import FEATURES
    from problems.cartoon_readback import ramp

    rest = _rest()
    for feature in FEATURES:
        P = ramp(rest, feature, 5)
        assert np.allclose(jaw_from_lips(P, rest), P, atol=1e-9), feature


def test_the_chin_follows_the_cartoons_own_lower_lip():
    """A cartoon whose mouth is 1.6 times as wide as the capture's opens it by its own mouth's map (amplitude
    "feature"): the chin moves with that lower lip, not with the capture's (review9: 0.68 of the lip before)."""
    rest = _rest()
    cartoon = rest.copy()
    m = cartoon[48:68].mean(0)
    cartoon[48:68] = m + 1.6 * (cartoon[48:68] - m)
    img = np.full((128, 128, 3), 180, np.uint8)
    anim = CartoonAnimator(img, cartoon, rest, rest, Delaunay(rest).simplices)
    P = _opening(rest, np.linspace(0.0, 2.0, T))
    d = anim.drive(P, P)
    assert not d.folded_target.any()
    still = d.still
    lip = still[:, 56:59].mean(1) - anim.rest[56:59].mean(0)
    assert lip[-1, 1] > 2.5                                          # the wider mouth opens further than the capture
    np.testing.assert_allclose(still[:, 6:11] - anim.rest[6:11], np.repeat(lip[:, None], 5, 1), atol=1e-6)
