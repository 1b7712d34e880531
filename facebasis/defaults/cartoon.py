"""The built-in default cartoon face: an image drawn by code and its 68 landmarks (iBUG order).

``facebasis animate2d`` animates this face when no ``--image`` is given. The landmarks are laid out
first (jaw 0-16, brows 17-26, nose 27-35, eyes 36-47, outer lips 48-59, inner lips 60-67; the
subject's right side on the image's left, as in iBUG/Multi-PIE), and the features are drawn
through them, so the landmarks sit exactly on the drawn contours. Drawn at twice the size with
anti-aliasing, then reduced.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: the layout is designed on a 512 x 512 canvas and scaled to the requested size
_BASE = 512.0
#: the brows (layout pixels): thickness at the inner end, its loss towards the outer end, the part above the
#: landmarks, colour; and the upper teeth's band under the upper inner lip. Chosen on dlib and MediaPipe
#: reading the face back (problems/cartoon_readback.py's ramps, still noise over 12 sub-pixel shifts): an 8 px
#: line through the brow landmarks gave dlib's brow reading r 0.25, gain 0.23, still noise 0.040 eye distances;
#: this body r 0.99, gain 1.08, noise 0.014 (16 px: noise 0.002 but MediaPipe's gain 0.45, 14 px above the
#: landmarks: dlib's eye reading r 0.68). Without teeth dlib's still noise on the mouth opening was 0.033, with
#: them 0.015 (gain 1.21 -> 1.02).
BROW_THICK, BROW_TAPER, BROW_ABOVE, BROW_RGB = 12.0, 0.5, 1.0, (70, 42, 30)
MOUTH_TEETH = 6.0


@dataclass(frozen=True)
class CartoonFace:
    """image : (S, S, 3) uint8 RGB; landmarks : (68, 2) float64 pixels (x right, y down)."""

    image: np.ndarray
    landmarks: np.ndarray


def cartoon_landmarks() -> np.ndarray:
    """The 68 landmarks (iBUG order) of the default cartoon on the 512 x 512 canvas, (68, 2)."""
    cx = 256.0
    # jaw 0-16: lower half of the head outline, from the subject's right ear to the left one
    phi = np.pi - np.arange(17) * np.pi / 16
    jaw = np.stack([cx + 150.0 * np.cos(phi), 250.0 + 205.0 * np.sin(phi) ** 1.0], 1)
    brow_r = np.array([[160, 208], [174, 196], [190, 191], [206, 192], [222, 198]], float)
    brow_l = np.stack([2 * cx - brow_r[::-1, 0], brow_r[::-1, 1]], 1)
    nose = np.array([[256, 238], [256, 260], [256, 282], [256, 304],
                     [238, 317], [247, 322], [256, 324], [265, 322], [274, 317]], float)
    eye_r = np.array([[166, 244], [184, 226], [206, 225], [226, 242], [206, 256], [185, 256]], float)
    # left eye: 42 inner, 43-44 upper, 45 outer, 46-47 lower (mirror of 39, 38, 37, 36, 41, 40)
    eye_l = np.stack([2 * cx - eye_r[[3, 2, 1, 0, 5, 4], 0], eye_r[[3, 2, 1, 0, 5, 4], 1]], 1)
    outer = np.array([[204, 364], [220, 358], [238, 352], [256, 356], [274, 352], [292, 358], [308, 364],
                      [292, 388], [274, 398], [256, 400], [238, 398], [220, 388]], float)
    inner = np.array([[212, 366], [238, 364], [256, 366], [274, 364], [300, 366],
                      [274, 380], [256, 383], [238, 380]], float)
    return np.concatenate([jaw, brow_r, brow_l, nose, eye_r, eye_l, outer, inner])


def _closed_curve(points: np.ndarray, n: int = 200) -> np.ndarray:
    """A smooth closed curve (periodic cubic spline) through ``points`` (k, 2) -> (n, 2)."""
    from scipy.interpolate import CubicSpline

    P = np.concatenate([points, points[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    return CubicSpline(s, P, bc_type="periodic")(np.linspace(0.0, s[-1], n, endpoint=False))


def _open_curve(points: np.ndarray, n: int = 100) -> np.ndarray:
    from scipy.interpolate import CubicSpline

    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    return CubicSpline(s, points)(np.linspace(0.0, s[-1], n))


def _draw_mouth(img, lm, pts, poly, line) -> None:
    """The mouth, in place on the supersampled canvas: lips through the outer contour, the opening through
    the inner one (dark, the upper teeth as a light band under the upper inner lip, clipped to the opening,
    the tongue over the lower lip), the lips' outline."""
    import cv2

    poly(_closed_curve(lm[48:60], 200), (214, 96, 102))
    inner = lm[60:68]
    poly(_closed_curve(inner, 160), (70, 20, 28))
    layer = img.copy()
    edge = inner[[0, 1, 2, 3, 4]]
    lower = edge + np.array([0.0, 1.0, 1.0, 1.0, 0.0])[:, None] * [0.0, MOUTH_TEETH]
    cv2.fillPoly(layer, [pts(np.concatenate([_open_curve(edge, 80), _open_curve(lower, 80)[::-1]]))],
                 (236, 232, 222), cv2.LINE_AA, 4)
    mask = np.zeros(img.shape[:2], np.uint8)
    cv2.fillPoly(mask, [pts(_closed_curve(inner, 160))], 255, cv2.LINE_AA, 4)
    a = (mask.astype(np.float32) / 255.0)[..., None]
    img[:] = (img * (1 - a) + layer * a).astype(np.uint8)
    poly(_closed_curve(np.array([[236, 377], [256, 372], [276, 377], [256, 383]]), 60), (232, 120, 130))
    line(_closed_curve(lm[48:60], 200), (150, 56, 62), 1.6, closed=True)


def _draw(size: int) -> np.ndarray:
    import cv2

    k = 2.0 * size / _BASE            # supersampling factor x layout scale
    S = int(round(2 * size))
    lm = cartoon_landmarks()
    yy, xx = np.mgrid[0:S, 0:S] / S
    # background: soft vertical gradient (RGB)
    top, bottom = np.array([196, 228, 246]), np.array([247, 236, 214])
    img = (top * (1 - yy[..., None]) + bottom * yy[..., None]).astype(np.uint8)
    img = np.ascontiguousarray(img)

    def pts(a):
        return np.round(np.asarray(a) * k * 16).astype(np.int32).reshape(-1, 1, 2)

    def poly(a, color):
        cv2.fillPoly(img, [pts(a)], color, cv2.LINE_AA, 4)

    def line(a, color, width, closed=False):
        cv2.polylines(img, [pts(a)], closed, color, int(round(width * k)), cv2.LINE_AA, 4)

    def ellipse(c, axes, color, angle=0.0, thick=-1):
        cv2.ellipse(img, tuple(int(v) for v in np.round(np.asarray(c) * k * 16)),
                    tuple(int(v) for v in np.round(np.asarray(axes) * k * 16)), angle, 0, 360, color,
                    thick if thick < 0 else int(round(thick * k)), cv2.LINE_AA, 4)

    skin, skin_dark, hair = (252, 214, 180), (226, 170, 138), (96, 58, 40)
    outline = (120, 72, 52)
    # neck and shoulders
    poly([[196, 420], [316, 420], [322, 512], [190, 512]], skin_dark)
    ellipse((256, 540), (190, 70), (86, 140, 196))
    # hair behind the head
    ellipse((256, 215), (178, 190), hair)
    # ears
    for sx in (-1, 1):
        ellipse((256 + sx * 148, 268), (22, 34), skin)
        ellipse((256 + sx * 150, 268), (10, 18), skin_dark)
    # head: the jaw curve below, a rounder skull above
    theta = np.linspace(np.pi, 2 * np.pi, 60)
    skull = np.stack([256 + 150 * np.cos(theta), 250 + 190 * np.sin(theta)], 1)
    head = np.concatenate([_open_curve(lm[0:17], 120), skull[::-1][:-1][::-1][::-1]])
    poly(head, skin)
    line(head, outline, 2.0, closed=True)
    # fringe over the forehead
    fringe = np.array([[106, 200], [120, 120], [180, 70], [256, 58], [332, 70], [392, 120], [406, 200],
                       [380, 150], [340, 140], [300, 120], [262, 150], [220, 118], [172, 140], [132, 160]])
    poly(_closed_curve(fringe, 240), hair)
    # cheeks (blush), blended
    blush = img.copy()
    for sx in (-1, 1):
        cv2.ellipse(blush, (int((256 + sx * 92) * k), int(318 * k)), (int(30 * k), int(18 * k)), 0, 0, 360,
                    (246, 150, 150), -1, cv2.LINE_AA)
    img[:] = (0.55 * img + 0.45 * blush).astype(np.uint8)
    # eyes: white through the six landmarks, iris and pupil clipped to it, lid line on top
    for e in (lm[36:42], lm[42:48]):
        curve = _closed_curve(e, 160)
        mask = np.zeros(img.shape[:2], np.uint8)
        cv2.fillPoly(mask, [pts(curve)], 255, cv2.LINE_AA, 4)
        c = e.mean(0) + [0, 1]
        layer = img.copy()
        poly_layer = layer
        cv2.fillPoly(poly_layer, [pts(curve)], (255, 255, 255), cv2.LINE_AA, 4)
        for r, col in ((14.5, (70, 120, 60)), (10.5, (40, 80, 40)), (6.5, (20, 20, 24))):
            cv2.circle(layer, tuple(int(v) for v in np.round(c * k * 16)), int(round(r * k * 16)), col, -1,
                       cv2.LINE_AA, 4)
        cv2.circle(layer, tuple(int(v) for v in np.round((c + [4, -5]) * k * 16)), int(round(3.5 * k * 16)),
                   (255, 255, 255), -1, cv2.LINE_AA, 4)
        a = (mask.astype(np.float32) / 255.0)[..., None]
        img[:] = (img * (1 - a) + layer * a).astype(np.uint8)
        upper = _open_curve(np.concatenate([e[0:1], e[1:3], e[3:4]]) if e is lm[36:42] else
                            np.concatenate([e[0:1], e[1:3], e[3:4]]), 60)
        line(upper, (40, 28, 24), 3.2)
        line(_open_curve(np.concatenate([e[3:4], e[4:6], e[0:1]]), 60), outline, 1.4)
    # brows: the landmarks on the upper edge (as iBUG annotates them), the body below, thick at the inner end
    for b, inner_first in ((lm[17:22], False), (lm[22:27], True)):
        top = _open_curve(b, 60)
        s = np.linspace(0.0, 1.0, len(top))
        thick = BROW_THICK * (1.0 - BROW_TAPER * (s if inner_first else 1.0 - s))
        bottom = top + np.c_[np.zeros_like(s), thick]
        poly(np.concatenate([top - [0, BROW_ABOVE], bottom[::-1]]), BROW_RGB)
    # nose: bridge shade and nostril arc
    line(_open_curve(lm[[28, 29, 30]] + [4, 0], 40), skin_dark, 2.5)
    line(_open_curve(lm[31:36], 60), outline, 2.6)
    ellipse(lm[30] + [0, 6], (11, 5), (236, 186, 156))
    _draw_mouth(img, lm, pts, poly, line)
    out = cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
    return out


@lru_cache(maxsize=4)
def _cached(size: int) -> CartoonFace:
    img = _draw(size)
    lm = cartoon_landmarks() * (size / _BASE)
    img.setflags(write=False)
    lm.setflags(write=False)
    return CartoonFace(img, lm)


def default_cartoon(size: int = 512) -> CartoonFace:
    """The default cartoon face at ``size`` x ``size`` pixels (drawn once per size, read-only arrays)."""
    if int(size) < 64:
        from ..errors import InputError

        raise InputError(f"cartoon size: expected at least 64 pixels, found {size}")
    return _cached(int(size))


__all__ = ["CartoonFace", "cartoon_landmarks", "default_cartoon"]
