"""The mouth of the cartoon warp (facebasis.retarget.mouth2d): a closed-mouth face driven open shows a
dark opening as large as the opening, for a capture mesh cut along the lips and for an uncut one."""

import numpy as np
import pytest

from facebasis.capture.facemesh import build_face_mesh
from facebasis.defaults.cartoon import cartoon_landmarks
from facebasis.retarget.mouth2d import (INNER_LIP_68, MOUTH_INTERIOR_RGB, draw_opening, mouth_is_cut,
                                        opening_opacity, polygon_area)
from facebasis.retarget.warp2d import CartoonAnimator

SKIN, LIP = (236, 200, 170), (200, 70, 80)


def closed_mouth_face():
    """A 512 x 512 face drawn in code with its lips closed: skin, a red mouth whose inner lips meet
    on one line (iBUG 61-63 on 67-65), dark eyes; returns (image, landmarks (68, 2))."""
    import cv2

    lm = cartoon_landmarks().copy()
    mid = 0.5 * (lm[[61, 62, 63]] + lm[[67, 66, 65]])
    lm[[61, 62, 63]] = mid
    lm[[67, 66, 65]] = mid
    img = np.zeros((512, 512, 3), np.uint8)
    img[:] = (225, 235, 245)
    cv2.fillPoly(img, [np.round(lm[:17]).astype(np.int32).reshape(-1, 1, 2)], SKIN)
    cv2.ellipse(img, (256, 250), (150, 200), 0, 180, 360, SKIN, -1)
    cv2.fillPoly(img, [np.round(lm[48:60]).astype(np.int32).reshape(-1, 1, 2)], LIP)
    cv2.polylines(img, [np.round(lm[[60, 61, 62, 63, 64]]).astype(np.int32).reshape(-1, 1, 2)], False, (120, 30, 40), 2)
    for eye in (lm[36:42], lm[42:48]):
        cv2.fillPoly(img, [np.round(eye).astype(np.int32).reshape(-1, 1, 2)], (40, 40, 40))
    return img, lm


def _dark_inside(frame, poly):
    """Pixels inside ``poly`` (edge pixels included) within 12 of the mouth interior's colour, the
    polygon's area and its perimeter."""
    import cv2

    mask = np.zeros(frame.shape[:2], np.uint8)
    cv2.fillPoly(mask, [np.round(poly).astype(np.int32).reshape(-1, 1, 2)], 1)
    dark = np.abs(frame.astype(int) - MOUTH_INTERIOR_RGB).max(-1) <= 12
    perimeter = float(np.linalg.norm(np.diff(np.r_[poly, poly[:1]], axis=0), axis=1).sum())
    return int(np.count_nonzero(dark & (mask > 0))), float(polygon_area(poly)), perimeter


def _drop(V, d):
    """The capture with the lower lip (inner and outer) and the chin moved down by d px."""
    out = np.array(V, float)
    out[np.r_[65:68, 55:60, 6:11], 1] += d
    return out


@pytest.mark.parametrize("start_gap", [0.0, 10.0], ids=["cut", "uncut"])
def test_a_closed_mouth_face_driven_open_shows_a_dark_opening_proportional_to_it(start_gap):
    img, lm = closed_mouth_face()
    cap = lm.copy()
    cap[[65, 66, 67], 1] += start_gap                   # the take's first frame: closed, or a little open
    mesh = build_face_mesh(cap)
    assert mouth_is_cut(mesh.faces, 68) == (start_gap == 0.0)
    anim = CartoonAnimator(img, lm, cap, mesh.vertices, mesh.faces, fold_free=False)
    assert anim.rest_mouth_area == pytest.approx(0.0, abs=1e-6)
    rest = anim.frame(mesh.vertices)
    assert _dark_inside(rest, anim.rest[INNER_LIP_68])[0] == 0          # closed: nothing drawn
    drops = np.array([4.0, 8.0, 12.0, 16.0, 20.0])
    dark, area, perimeter = np.array([_dark_inside(anim.frame(_drop(mesh.vertices, d)),
                                        anim.mesh(_drop(mesh.vertices, d))[INNER_LIP_68]) for d in drops]).T
    # the opening is dark, not stretched lips: (nearly) all of the inner-lip polygon, growing with the drop
    assert np.all(dark >= 0.8 * area) and np.all(dark <= area + perimeter + 8)
    assert 0.9 <= np.polyfit(area, dark, 1)[0] <= 1.1 and np.corrcoef(dark, drops)[0, 1] > 0.99
    assert np.all(np.diff(dark) > 0)


def test_an_open_mouth_keeps_its_own_interior_at_rest_and_darkens_by_the_new_part():
    """A target drawn with an open mouth: at rest its own mouth is shown unchanged; as the polygon
    grows to k times its rest area the interior is blended towards dark with opacity 1 - 1/k."""
    assert opening_opacity(100.0, 100.0) == 0.0 and opening_opacity(50.0, 100.0) == 0.0
    assert opening_opacity(400.0, 100.0) == pytest.approx(0.75)
    assert opening_opacity(10.0, 0.0) == 1.0
    img = np.full((60, 60, 3), 200, np.uint8)
    poly = np.array([[10, 30], [20, 25], [30, 24], [40, 25], [50, 30], [40, 35], [30, 36], [20, 35]], float)
    out = img.copy()
    assert draw_opening(out, poly, polygon_area(poly)) == 0.0 and np.array_equal(out, img)
    assert draw_opening(out, poly, 0.5 * polygon_area(poly)) == pytest.approx(0.5)
    centre = out[30, 30].astype(float)
    np.testing.assert_allclose(centre, 0.5 * (200 + np.array(MOUTH_INTERIOR_RGB)), atol=1)
    assert np.array_equal(out[:20], img[:20]) and np.array_equal(out[40:], img[40:])
