"""The mouth of the cartoon warp (facebasis.retarget.mouth2d, .mouthpaint): a closed-mouth face driven open
shows a painted opening as large as the opening, for a capture mesh cut along the lips and for an uncut one."""

import numpy as np
import pytest

from facebasis.capture.facemesh import build_face_mesh
from facebasis.defaults.cartoon import cartoon_landmarks
from facebasis.retarget.mouth2d import (INNER_LIP_68, MOUTH_INTERIOR_RGB, fill_mouth, mouth_is_cut, opening_opacity,
                                        polygon_area)
from facebasis.retarget.mouthpaint import paint_mouth
from facebasis.retarget.raster2d import warp_image
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


def _dark_inside(anim, capture):
    """For the frame of ``capture`` (N, 2): pixels inside its inner-lip polygon (edge pixels included)
    painted opaquely (within 12 of the fully painted mouth where that differs by more than 24 from the
    unpainted warp), those the paint changes by more than 24, the polygon's area and its perimeter."""
    import cv2

    V = anim.mesh(capture)
    poly = V[INNER_LIP_68]
    frame = anim.frame(capture).astype(int)
    bare = warp_image(anim.image, anim.warp_rest, np.concatenate([V, anim.ring]), anim.draw_faces)
    full = bare.copy()
    paint_mouth(full, poly)
    mask = np.zeros(frame.shape[:2], np.uint8)
    cv2.fillPoly(mask, [np.round(poly).astype(np.int32).reshape(-1, 1, 2)], 1)
    paintable = (np.abs(full.astype(int) - bare).reshape(frame.shape).max(-1) > 24) & (mask > 0)
    opaque = paintable & (np.abs(frame - full.reshape(frame.shape)).max(-1) <= 12)
    perimeter = float(np.linalg.norm(np.diff(np.r_[poly, poly[:1]], axis=0), axis=1).sum())
    return int(np.count_nonzero(opaque)), int(np.count_nonzero(paintable)), float(polygon_area(poly)), perimeter


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
    assert polygon_area(anim.rest[INNER_LIP_68]) == pytest.approx(0.0, abs=1e-6)
    assert _dark_inside(anim, mesh.vertices)[0] == 0          # closed: nothing drawn ...
    V = anim.mesh(mesh.vertices)                              # ... the frame is the bare warp, pixel for pixel
    bare = warp_image(anim.image, anim.warp_rest, np.concatenate([V, anim.ring]), anim.draw_faces)
    assert np.array_equal(anim.frame(mesh.vertices), bare.reshape(anim.frame(mesh.vertices).shape))
    drops = np.array([4.0, 8.0, 12.0, 16.0, 20.0])
    dark, _, area, perimeter = np.array([_dark_inside(anim, _drop(mesh.vertices, d)) for d in drops]).T
    # the opening is painted, not stretched lips: (nearly) all of the inner-lip polygon, growing with the drop
    assert np.all(dark >= 0.8 * area) and np.all(dark <= area + perimeter + 8)
    assert 0.9 <= np.polyfit(area, dark, 1)[0] <= 1.1 and np.corrcoef(dark, drops)[0, 1] > 0.99
    assert np.all(np.diff(dark) > 0)


def test_a_face_drawn_with_an_open_mouth_keeps_it_at_rest_and_darkens_as_it_opens_wider():
    """The built-in cartoon (teeth drawn between open lips), uncut Delaunay mesh: at rest the frame
    is the image exactly; opened beyond its drawn mouth the opening darkens, fully from twice its area;
    the same face only scaled (a head coming closer) is not darkened."""
    from scipy.spatial import Delaunay

    from facebasis.defaults.cartoon import default_cartoon

    face = default_cartoon()
    lm = np.array(face.landmarks, float)
    anim = CartoonAnimator(np.array(face.image), lm, lm, lm, Delaunay(lm).simplices, fold_free=False)
    assert not anim.mouth_cut
    assert np.array_equal(anim.frame(lm), face.image)
    rest_area = polygon_area(lm[INNER_LIP_68])
    shares = []
    for d in (5.0, 10.0, 20.0, 40.0):
        V = _drop(lm, d)
        dark, paintable, area, perimeter = _dark_inside(anim, V)
        shares.append(dark / paintable)
        if area >= 2.2 * rest_area:                              # fully opaque from twice the drawn area
            assert 0.7 * area <= dark <= area + perimeter + 8
    opacities = [opening_opacity(_drop(lm, d)[INNER_LIP_68], lm[INNER_LIP_68]) for d in (5.0, 10.0, 20.0, 40.0)]
    assert 0 < opacities[0] < opacities[1] < 1 and opacities[2:] == [1.0, 1.0]
    # 5 and 10 px: partly blended (the few opaque-looking pixels: the drawn teeth, as light as the painted ones);
    # 20 and 40: opaque
    assert max(shares[:2]) < 0.2 and min(shares[2:]) >= 0.8
    centre = lm[INNER_LIP_68].mean(0)
    bigger = centre + 1.2 * (lm - centre)
    opacity = opening_opacity(bigger[INNER_LIP_68], lm[INNER_LIP_68])
    assert opacity == pytest.approx(0.0, abs=1e-9)


def test_a_grey_target_gets_a_grey_mouth():
    """A grey image (H, W) or (H, W, 1) is warped and painted as its colour version's luma."""
    img, lm = closed_mouth_face()
    mesh = build_face_mesh(lm)
    opened = _drop(mesh.vertices, 20.0)
    colour = CartoonAnimator(img, lm, lm, mesh.vertices, mesh.faces, fold_free=False).frame(opened)
    grey = np.round(img @ [0.299, 0.587, 0.114]).astype(np.uint8)
    for image in (grey, grey[..., None]):
        anim = CartoonAnimator(image, lm, lm, mesh.vertices, mesh.faces, fold_free=False)
        assert np.array_equal(anim.frame(mesh.vertices).reshape(grey.shape), grey)
        out = anim.frame(opened).reshape(grey.shape).astype(float)
        poly = anim.mesh(opened)[INNER_LIP_68]
        for s in (0.1, 0.5, 0.9):                            # teeth, cavity, tongue along the middle
            x, y = np.round((1 - s) * poly[2] + s * poly[6]).astype(int)
            assert abs(out[y, x] - float(colour[y, x] @ [0.299, 0.587, 0.114])) <= 2


def test_fill_mouth_blends_only_inside_an_open_polygon():
    img = np.full((60, 60, 3), 200, np.uint8)
    poly = np.array([[10, 30], [20, 25], [30, 24], [40, 25], [50, 30], [40, 35], [30, 36], [20, 35]], float)
    out = img.copy()
    fill_mouth(out, np.repeat(poly[:1], 8, axis=0))            # closed: nothing drawn
    assert np.array_equal(out, img)
    fill_mouth(out, poly, opacity=0.5)
    np.testing.assert_allclose(out[30, 30].astype(float), 0.5 * (200 + np.array(MOUTH_INTERIOR_RGB)), atol=1)
    assert np.array_equal(out[:20], img[:20]) and np.array_equal(out[40:], img[40:])
    fill_mouth(out, poly)
    assert np.array_equal(out[30, 30], MOUTH_INTERIOR_RGB)
    assert polygon_area(poly) == pytest.approx(0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1))
                                                         - np.dot(poly[:, 1], np.roll(poly[:, 0], -1))))
