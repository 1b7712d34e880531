"""The painted open mouth (facebasis.retarget.mouthpaint) on tiny images built in code: only the opening
changes, upper teeth under the upper lip, the tongue over the lower one, the cavity darkest between them,
whichever way the mouth is turned."""

import numpy as np
import pytest

from facebasis.retarget.mouthpaint import (CAVITY_BACK_RGB, TEETH_RGB, TONGUE_RGB, mouth_coordinates,
                                           paint_mouth)

#: an open mouth 40 px wide, 12 px open in the middle: corners 60 and 64, upper 61-63, lower 65-67
MOUTH = np.array([[10, 30], [20, 25], [30, 24], [40, 25], [50, 30], [40, 35], [30, 36], [20, 35]], float)


def _outside(poly, shape):
    """Pixels farther than 1.5 px from the polygon (outside its anti-aliased edge)."""
    import cv2

    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32).reshape(-1, 1, 2)], 1, cv2.LINE_AA, 4)
    return cv2.dilate((mask > 0).astype(np.uint8), np.ones((3, 3), np.uint8)) == 0


def _rotated(poly, angle, centre=(30.0, 30.0)):
    c, s = np.cos(angle), np.sin(angle)
    return (poly - centre) @ np.array([[c, s], [-s, c]]) + centre


def test_only_the_opening_changes_and_a_closed_mouth_or_zero_opacity_draws_nothing():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (60, 60, 3), dtype=np.uint8)
    out = img.copy()
    paint_mouth(out, np.repeat(MOUTH[:1], 8, axis=0))          # closed: nothing
    paint_mouth(out, MOUTH, opacity=0.0)                         # transparent: nothing
    assert np.array_equal(out, img)
    paint_mouth(out, MOUTH)
    outside = _outside(MOUTH, img.shape[:2])
    assert np.array_equal(out[outside], img[outside])
    assert np.count_nonzero(np.any(out != img, axis=-1)) >= 0.9 * 0.5 * 40 * 11   # the polygon's area: 0.5 w h


@pytest.mark.parametrize("angle", [0.0, 0.5, np.pi / 2, np.pi], ids=["level", "tilted", "quarter", "upside-down"])
def test_teeth_under_the_upper_lip_the_tongue_over_the_lower_and_the_cavity_between(angle):
    poly = _rotated(MOUTH, angle)
    img = np.full((60, 60, 3), 200, np.uint8)
    paint_mouth(img, poly)
    # down the middle of the mouth, from the upper inner lip (62) to the lower (66)
    s = np.linspace(0.05, 0.95, 19)
    pts = (1 - s)[:, None] * poly[2] + s[:, None] * poly[6]
    col = img[np.round(pts[:, 1]).astype(int), np.round(pts[:, 0]).astype(int)].astype(int)
    near = lambda rgb: np.abs(col - rgb).max(-1) <= 30                                    # noqa: E731
    teeth, tongue = np.flatnonzero(near(TEETH_RGB)), np.flatnonzero(near(TONGUE_RGB))
    assert len(teeth) and len(tongue) and teeth.max() < tongue.min()
    assert s[teeth].max() < 0.4 and s[tongue].min() > 0.6
    luma = col @ [0.299, 0.587, 0.114]
    darkest = int(np.argmin(luma))
    assert 0.3 < s[darkest] < 0.7 and np.abs(col[darkest] - CAVITY_BACK_RGB).max() <= 30


def test_mouth_coordinates_run_from_the_upper_lip_to_the_lower_along_the_mouth():
    for angle in (0.0, 2.0):
        poly = _rotated(MOUTH, angle)
        x, y = np.array([poly[2, 0], poly[6, 0], 0.5 * (poly[2, 0] + poly[6, 0])]), \
            np.array([poly[2, 1], poly[6, 1], 0.5 * (poly[2, 1] + poly[6, 1])])
        u, s, h, w = mouth_coordinates(poly, x, y)
        np.testing.assert_allclose(s, [0.0, 1.0, 0.5], atol=1e-9)
        np.testing.assert_allclose(u, 0.5, atol=1e-9)
        np.testing.assert_allclose(h, 12.0, atol=1e-9)
        assert w == pytest.approx(40.0)


def test_opacity_blends_and_grey_and_alpha_images_are_painted_in_place():
    rgb = np.full((60, 60, 3), 200, np.uint8)
    paint_mouth(rgb, MOUTH)
    half = np.full((60, 60, 3), 200, np.uint8)
    paint_mouth(half, MOUTH, opacity=0.5)
    np.testing.assert_allclose(half[30, 30].astype(float), 0.5 * (200 + rgb[30, 30].astype(float)), atol=1)
    grey = np.full((60, 60), 200, np.uint8)
    paint_mouth(grey, MOUTH)
    luma = rgb.astype(float) @ [0.299, 0.587, 0.114]
    inside = ~_outside(MOUTH, grey.shape)
    assert np.abs(grey[inside] - luma[inside]).max() <= 1
    rgba = np.zeros((60, 60, 4), np.uint8)
    paint_mouth(rgba, MOUTH)
    assert np.array_equal(rgba[30, 30, :3], rgb[30, 30]) and rgba[30, 30, 3] == 255


def test_a_grey_photograph_stored_as_rgb_gets_a_grey_mouth_and_a_coloured_one_its_colours():
    from facebasis.retarget.mouthpaint import image_chroma

    grey = np.full((60, 60, 3), 120, np.uint8)
    skin = np.zeros((60, 60, 3), np.uint8)
    skin[:] = (225, 180, 160)
    assert image_chroma(grey, MOUTH) == 0.0 and image_chroma(skin, MOUTH) == 1.0
    assert image_chroma(grey[..., 0], MOUTH) == 0.0
    for img in (grey, skin):
        out = img.copy()
        paint_mouth(out, MOUTH, chroma=image_chroma(img, MOUTH))
        changed = np.any(out != img, axis=-1)
        spread = out[changed].max(-1).astype(int) - out[changed].min(-1)
        assert (spread.max() <= 1) if img is grey else (spread.max() > 50)
    # the driven warp: the cameraman-like grey target is painted grey
    from facebasis.defaults.cartoon import default_cartoon
    from scipy.spatial import Delaunay

    from facebasis.retarget.warp2d import CartoonAnimator

    face = default_cartoon()
    lm = np.array(face.landmarks, float)
    g = np.repeat(np.round(face.image @ [0.299, 0.587, 0.114]).astype(np.uint8)[..., None], 3, axis=2)
    anim = CartoonAnimator(g, lm, lm, lm, Delaunay(lm).simplices, fold_free=False)
    V = lm.copy()
    V[np.r_[65:68, 55:60, 6:11], 1] += 40.0
    out = anim.frame(V)
    assert anim.mouth_chroma == 0.0 and int((out.max(-1).astype(int) - out.min(-1)).max()) <= 1


@pytest.mark.parametrize("gap", [0.4, 0.8])
def test_a_nearly_closed_mouth_is_a_dark_line_not_a_light_seam(gap):
    """Lips ``gap`` px apart on lip-coloured skin: teeth and tongue bands narrower than a pixel cover only
    their width, so what the opening changes gets darker than the lips (review: before, both bands took at
    least half of every such pixel and drew a light line, (184, 156, 148) on lips of (200, 70, 80))."""
    lips = np.array([200, 70, 80], np.uint8)
    img = np.broadcast_to(lips, (60, 60, 3)).copy()
    P = np.array([[10, 30], [20, 30], [30, 30], [40, 30], [50, 30], [40, 30 + gap], [30, 30 + gap], [20, 30 + gap]])
    out = img.copy()
    paint_mouth(out, P)
    changed = np.any(out != img, axis=-1)
    assert changed.any()
    luma = np.float64([0.299, 0.587, 0.114])
    assert (out[changed] @ luma).mean() < 0.9 * (lips @ luma)
