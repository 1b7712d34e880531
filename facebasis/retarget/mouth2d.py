"""The mouth of a 2D cartoon warp: what is drawn inside the lips as they open.

A piecewise-affine warp can only move the target's own pixels. When the capture's mouth opens wider
than the target's mouth is drawn (a painting or photograph with closed lips, a cartoon whose mouth
is drawn half open), the triangles inside the inner-lip polygon stretch what the target shows there:
a sliver of lips becomes a band of stretched lip colour, which neither a viewer nor a face detector
reads as an opening. A
capture mesh cut open along closed lips (:func:`mouth_is_cut`) has no triangle there at all, and the
target's still pixels showed through the gap.

The warp therefore draws the opening, the inner-lip polygon (iBUG 60-67) of the frame, as a mouth
interior as it opens beyond the target's own mouth, whether the capture mesh is cut or not: painted
with teeth, cavity and tongue (:func:`.mouthpaint.paint_mouth`; :func:`fill_mouth`, one flat dark colour,
is the former drawing and the baseline it was measured against), with the opacity :func:`opening_opacity` ``clip(A_t / A_rest - 1, 0, 1)`` (``A`` the polygon's
area over the squared mouth width, ``A_rest`` the target's own, at least a quarter pixel): the target at rest is left exactly as it
is drawn (a capture that does not move leaves the cartoon unchanged), a closed-mouth painting driven
open shows a dark opening as large as the opening (its ``A_rest`` is about 0, so any opening is
opaque), and a mouth drawn open darkens until it is twice its drawn area. Measured on cap13 (dlib capture, every 10th frame, dlib on the output against the warped
landmarks, median of the four measures), against blending the target's own interior towards dark
by ``1 - A_rest / A_t`` (``A`` the polygon's area): astronaut 0.84 against 0.78, its painting 0.30
against 0.17, the built-in cartoon 0.40 against 0.33, the cameraman 0.49 both: a detector reads a
uniformly dark opening better than the target's teeth stretched and darkened, so the target's own
teeth are not shown once the mouth is open. A cut mesh is given back the triangles inside the
polygon (:data:`MOUTH_STRIP_68`, draw-only: not part of the fold-free solve), so that cut and uncut
captures draw the same lips around it.
"""

from __future__ import annotations

import numpy as np

#: the inner-lip ring of the 68-point iBUG set, in order around the mouth opening
INNER_LIP_68 = np.arange(60, 68)
#: the colour of an open mouth's interior (RGB)
MOUTH_INTERIOR_RGB = (72, 24, 34)
#: triangles filling the inner-lip polygon (corners 60 and 64, upper 61-63 over lower 67-65)
MOUTH_STRIP_68 = np.array([[60, 61, 67], [61, 62, 66], [61, 66, 67], [62, 63, 65], [62, 65, 66], [63, 64, 65]],
                          np.int64)


def mouth_is_cut(faces, n_landmarks: int) -> bool:
    """Whether a 68-point capture mesh has no triangle joining the upper inner lip (61-63) to the
    lower (65-67): the mesh was cut open along closed lips (:func:`facebasis.capture.facemesh.build_face_mesh`)."""
    if n_landmarks != 68:
        return False
    F = np.asarray(faces, np.int64)
    upper = np.isin(F, (61, 62, 63)).any(1)
    lower = np.isin(F, (65, 66, 67)).any(1)
    return not bool((upper & lower).any())


def polygon_area(P) -> np.ndarray:
    """Unsigned area of polygons (..., k, 2) (shoelace), shape (...)."""
    P = np.asarray(P, np.float64)
    x, y = P[..., 0], P[..., 1]
    return 0.5 * np.abs((x * np.roll(y, -1, axis=-1) - y * np.roll(x, -1, axis=-1)).sum(-1))


#: the smallest polygon area (px^2) counted as open
MIN_OPEN_AREA = 0.25


def opening_opacity(mouth, rest_mouth) -> float:
    """Opacity of the drawn mouth interior for the inner-lip polygon ``mouth`` (8, 2) of a frame
    against the target's own ``rest_mouth`` (8, 2): ``clip(a / max(a_rest, MIN_OPEN_AREA / w_rest^2) - 1,
    0, 1)`` with ``a = A / w^2`` the polygon's area over the squared width between the mouth corners
    (iBUG 60 and 64), so that a head that comes closer (a similarity) does not open the mouth; 0 while
    the opening is no larger than the target's own mouth, 1 from twice its area on."""
    def shape(P):
        P = np.asarray(P, np.float64)
        w2 = max(float(np.sum((P[0] - P[4]) ** 2)), 1e-12)
        return float(polygon_area(P)) / w2, w2

    a, _ = shape(mouth)
    a_rest, w2_rest = shape(rest_mouth)
    return float(np.clip(a / max(a_rest, MIN_OPEN_AREA / w2_rest) - 1.0, 0.0, 1.0))


def feature_frame(P, corners, upper, lower):
    """The frame of a feature outline (eye or inner lips) ``P`` (k, 2): origin at corner ``corners[0]``, unit
    axis ``e`` to ``corners[1]``, unit normal ``n`` pointing from the ``upper`` points to the ``lower`` ones
    (index lists), and the corner-to-corner width ``w`` (pixels, at least 1e-9)."""
    P = np.asarray(P, np.float64)
    axis = P[corners[1]] - P[corners[0]]
    w = max(float(np.hypot(*axis)), 1e-9)
    e = axis / w
    n = np.array([-e[1], e[0]])
    rel = P - P[corners[0]]
    if (rel[lower] @ n).mean() < (rel[upper] @ n).mean():
        n = -n
    return P[corners[0]], e, n, w


def blend_polygon(image, polygon, colours, opacity: float = 1.0) -> None:
    """Blend the polygon (k, 2) of ``image`` (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) uint8 in place
    towards ``colours`` with ``opacity`` (anti-aliased edge, cv2's sub-pixel fill), when the polygon is
    open (area above :data:`MIN_OPEN_AREA`) and the opacity above 1/255; a grey image gets the
    colours' luma, an alpha channel is made opaque. ``colours``: an RGB triple, or a function of the
    pixel coordinates ``(xx, yy)`` (n,) of the pixels the polygon covers giving (n, 3) float32 RGB.
    Only those pixels are touched."""
    import cv2

    P = np.asarray(polygon, np.float64)
    if polygon_area(P) <= MIN_OPEN_AREA or opacity * 255.0 < 1.0:
        return
    H, W = image.shape[:2]
    x0, y0 = np.maximum(np.floor(P.min(0)).astype(int) - 1, 0)
    x1, y1 = np.minimum(np.ceil(P.max(0)).astype(int) + 2, [W, H])
    if x1 <= x0 or y1 <= y0:
        return
    shift = 4  # sub-pixel vertices (1/16 px)
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.fillPoly(mask, np.round((P - [x0, y0]) * (1 << shift)).astype(np.int32)[None], 255, lineType=cv2.LINE_AA,
                 shift=shift)
    ys, xs = np.nonzero(mask)                        # only the covered pixels are coloured and blended
    a = (mask[ys, xs].astype(np.float32) * (float(opacity) / 255.0))[:, None]
    if callable(colours):
        rgb = np.asarray(colours(xs + x0, ys + y0), np.float32)
    else:
        rgb = np.broadcast_to(np.asarray(tuple(colours)[:3], np.float32), (len(ys), 3))
    blend_pixels(image, x0, y0, ys, xs, rgb, a)


def blend_pixels(image, x0: int, y0: int, ys, xs, rgb, a) -> None:
    """Blend the pixels ``(y0 + ys, x0 + xs)`` (n,) of ``image`` (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) uint8 in
    place towards ``rgb`` (n, 3) float32 with opacities ``a`` (n, 1): a grey image gets the colours' luma, an alpha
    channel is made opaque (:func:`blend_polygon`, :func:`.eyepaint.paint_eye`)."""
    if image.ndim == 2:
        image = image[..., None]                     # a view: writes go to the caller's array
    C = image.shape[2]
    col = np.concatenate([rgb, np.full((len(ys), 1), 255, np.float32)], -1) if C == 4 else rgb if C == 3 \
        else (rgb @ np.float32([0.299, 0.587, 0.114]))[:, None]
    box = image[y0:, x0:]                            # a view: writes go to the caller's array
    box[ys, xs] = np.clip(np.rint(box[ys, xs].astype(np.float32) * (1.0 - a) + col * a), 0, 255).astype(np.uint8)


def fill_mouth(image, inner_lip, colour=MOUTH_INTERIOR_RGB, opacity: float = 1.0) -> None:
    """Blend the polygon ``inner_lip`` (8, 2) of ``image`` (H, W), (H, W, 1), (H, W, 3) or (H, W, 4)
    uint8 in place towards one ``colour`` (RGB; its luma on a grey image, opaque alpha) with ``opacity``
    (:func:`blend_polygon`)."""
    blend_polygon(image, inner_lip, colour, opacity)


__all__ = ["INNER_LIP_68", "MOUTH_INTERIOR_RGB", "MOUTH_STRIP_68", "MIN_OPEN_AREA", "mouth_is_cut", "polygon_area", "blend_pixels",
           "opening_opacity", "blend_polygon", "fill_mouth"]
