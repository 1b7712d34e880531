"""The painted closing eye (facebasis.retarget.eyepaint) on tiny images built in code: nothing drawn at rest or
wider, the lid's colour over a closing eye, the lash line at the lid's edge, the unsquashed eye between the lids,
only the eye's pixels touched, whichever way the eye is turned."""

import numpy as np
import pytest

from facebasis.retarget.eyepaint import eye_closure, eye_colours, lid_curves, paint_eye

#: an eye 40 px wide, 12 px open: corner 36, upper lid 37 38, corner 39, lower lid 40 41
EYE = np.array([[20, 40], [33, 34], [47, 34], [60, 40], [47, 46], [33, 46]], float)
SKIN, LID, IRIS, LASH = (200, 170, 150), (180, 140, 120), (60, 90, 140), (10, 10, 10)


def _face(shape=(80, 80)):
    """Skin with a darker lid band above the eye, a white eye with a blue iris, lashes along the upper lid."""
    import cv2

    img = np.zeros(shape + (3,), np.uint8)
    img[:] = SKIN
    img[22:34] = LID
    cv2.fillPoly(img, [np.round(EYE).astype(np.int32)], (245, 245, 240))
    cv2.circle(img, (40, 40), 6, IRIS, -1)
    cv2.polylines(img, [np.round(EYE[:4]).astype(np.int32)], False, LASH, 2)      # the lashes on the upper lid
    return img


def _closed(eye, k):
    """The eye with both lids moved k/2 of their gap towards each other."""
    E = eye.copy()
    gap = E[[5, 4], 1] - E[[1, 2], 1]
    E[[1, 2], 1] += 0.5 * k * gap
    E[[5, 4], 1] -= 0.5 * k * gap
    return E


def _rot(P, angle, centre=(40.0, 40.0)):
    c, s = np.cos(angle), np.sin(angle)
    return (P - centre) @ np.array([[c, s], [-s, c]]) + centre


def test_colours_are_the_lid_above_the_eye_and_the_darkest_inside():
    lid, under, lash = eye_colours(_face(), EYE)
    assert np.abs(lid - LID).max() <= 2 and np.abs(under - SKIN).max() <= 2
    assert np.abs(lash - LASH).max() <= 10


def test_nothing_is_drawn_at_rest_or_wider_and_closure_is_measured_against_the_rest():
    img = _face()
    cols = eye_colours(img, EYE)
    out = img.copy()
    paint_eye(out, img, EYE, EYE, cols)                               # at rest
    wide = EYE.copy()
    wide[[1, 2], 1] -= 3
    paint_eye(out, img, wide, EYE, cols)                              # opened wider
    paint_eye(out, img, _closed(EYE, 0.5), EYE, cols, closure=0.0)    # told it is open
    assert np.array_equal(out, img)
    assert eye_closure(EYE, EYE) == 0.0 and eye_closure(wide, EYE) == 0.0
    assert eye_closure(_closed(EYE, 0.5), EYE) == pytest.approx(0.5)


@pytest.mark.parametrize("angle", [0.0, 0.4, np.pi / 2, np.pi], ids=["level", "tilted", "quarter", "upside-down"])
def test_a_closing_eye_gets_the_lid_over_it_and_a_lash_line_at_its_edge(angle):
    img = _rot_image(_face(), angle)
    rest = _rot(EYE, angle)
    closed = _rot(_closed(EYE, 0.7), angle)
    cols = eye_colours(img, rest)
    out = img.copy()
    paint_eye(out, img, closed, rest, cols)
    changed = np.any(out != img, -1)
    # only pixels near the open eye change (its outline grown by the lid margin, the lash and 2 px)
    yy, xx = np.nonzero(changed)
    d = (np.stack([xx, yy], 1) - 40.0) @ np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    x, y = d[:, 0] + 40.0, d[:, 1] + 40.0
    assert x.min() >= 18 and x.max() <= 62 and y.min() >= 28 and y.max() <= 48
    # down the middle of the eye: the lid above the closed upper lid, the lash at its edge, then the iris
    lid_v, _ = lid_curves(_closed(EYE, 0.7), np.array([0.5]))
    top = 40 + 40 * lid_v[0]                                           # the closed upper lid's y at the eye centre
    col = lambda y: out[_px(40, y, angle)].astype(int)                 # noqa: E731
    assert np.abs(col(top - 4.2) - np.asarray(cols[0])).max() <= 12   # lid colour inside the old opening
    assert col(top - 1).mean() < 90                                   # the lash line
    assert np.abs(col(40) - IRIS).max() <= 20                         # the iris unsquashed at the centre


def _rot_image(img, angle):
    import cv2

    M = cv2.getRotationMatrix2D((40.0, 40.0), -np.degrees(angle), 1.0)
    return cv2.warpAffine(img, M, img.shape[1::-1], flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)


def _px(x, y, angle):
    p = _rot(np.array([[x, y]], float), angle)[0]
    return int(round(p[1])), int(round(p[0]))


def test_grey_and_alpha_images():
    img = _face()
    closed = _closed(EYE, 0.7)
    cols = eye_colours(img, EYE)
    grey = (img @ [0.299, 0.587, 0.114]).round().astype(np.uint8)
    g = grey.copy()
    paint_eye(g, grey, closed, EYE, eye_colours(grey, EYE))
    assert g.shape == grey.shape and np.any(g != grey)
    rgba = np.concatenate([img, np.full((80, 80, 1), 100, np.uint8)], -1)
    out = rgba.copy()
    paint_eye(out, rgba, closed, EYE, cols)
    changed = np.any(out[..., :3] != rgba[..., :3], -1)
    assert changed.any() and np.all(out[changed, 3] > 100)


def test_the_cartoon_warp_paints_only_a_closing_eye_and_leaves_a_still_capture_as_drawn():
    """CartoonAnimator: a capture that does not move gives the image back byte for byte (no lid drawn); one
    that closes the right eye changes, against the bare warp, only pixels around that eye."""
    from scipy.spatial import Delaunay

    from facebasis.defaults.cartoon import default_cartoon
    from facebasis.retarget.raster2d import warp_image
    from facebasis.retarget.warp2d import CartoonAnimator

    face = default_cartoon(128)
    lm = np.array(face.landmarks, float)
    anim = CartoonAnimator(np.array(face.image), lm, lm, lm, Delaunay(lm).simplices, fold_free=False)
    np.testing.assert_array_equal(anim.frame(lm), face.image)
    shut = lm.copy()
    shut[36:42] = _closed(lm[36:42], 0.7)
    V = anim.mesh(shut)
    painted = anim.warp(V)
    bare = warp_image(anim.image, anim.warp_rest, np.concatenate([V, anim.ring]), anim.draw_faces)
    yy, xx = np.nonzero(np.any(painted != bare, -1))
    assert len(yy) > 5
    w = np.linalg.norm(lm[39] - lm[36])
    centre = lm[36:42].mean(0)
    assert np.abs(xx - centre[0]).max() <= 0.6 * w + 2 and np.abs(yy - centre[1]).max() <= 0.5 * w + 2


def test_an_eye_wider_than_the_remap_limit_is_painted():
    """An eye 400 px wide (about 40 000 of its pixels sampled: cv2.remap refuses a map side of 32767 or more)
    is painted as the 40 px one, scaled: the lid's colour above the closed lid, the iris unsquashed."""
    import cv2

    k = 10
    img = cv2.resize(_face(), (80 * k, 80 * k), interpolation=cv2.INTER_NEAREST)
    rest, closed = EYE * k, _closed(EYE, 0.7) * k
    cols = eye_colours(img, rest)
    out = img.copy()
    paint_eye(out, img, closed, rest, cols)
    lid_v, _ = lid_curves(_closed(EYE, 0.7), np.array([0.5]))
    top = k * (40 + 40 * lid_v[0])
    assert np.abs(out[int(top - 4.2 * k), 40 * k].astype(int) - np.asarray(cols[0])).max() <= 12
    assert np.abs(out[40 * k, 40 * k].astype(int) - IRIS).max() <= 20
