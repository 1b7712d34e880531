"""An open mouth painted as a mouth: a shaded interior with upper teeth and a tongue.

:func:`.mouth2d.fill_mouth` darkens the inner-lip polygon with one flat colour. A face detector
trained on photographs reads a flat dark polygon poorly: on a painted face MediaPipe put both lips
on the upper lip (it read the opening as closing), dlib saw about half of it. A real open mouth
shows, from the upper lip down, a light band of upper teeth, a dark cavity (darkest in the middle,
the back of the mouth) and the tongue's lighter red over the lower lip. :func:`paint_mouth` draws
that inside the inner-lip polygon (iBUG 60-67), in the mouth's own frame (the axis from corner 60
to corner 64), so that it turns and stretches with the mouth:

* ``s`` in [0, 1] runs from the upper inner lip (61-63) down to the lower one (65-67) at each
  position ``u`` in [0, 1] along the mouth (both lips interpolated piecewise-linearly in ``u``);
* the teeth band covers ``s`` below ``min(TEETH_SHARE h, TEETH_WIDTH w) / h`` (``h`` the local
  opening, ``w`` the mouth width), narrowing towards the corners (``sqrt(1 - (2u - 1)^2)``);
* the tongue covers the band of the same form above the lower lip (``TONGUE_SHARE``,
  ``TONGUE_WIDTH``);
* the cavity between them goes from :data:`CAVITY_EDGE_RGB` at the lips to
  :data:`CAVITY_BACK_RGB` in the middle.

Every transition is a linear ramp one pixel wide and the polygon's edge is cv2's anti-aliased
fill, blended with the caller's opacity; pixels outside the polygon's anti-aliased edge are never
touched. Vectorised over the polygon's bounding box.
"""

from __future__ import annotations

import numpy as np

from .mouth2d import feature_frame

#: teeth, cavity (at the lips and at the back) and tongue colours (RGB)
TEETH_RGB = (226, 220, 204)
CAVITY_EDGE_RGB = (92, 34, 40)
CAVITY_BACK_RGB = (34, 10, 14)
TONGUE_RGB = (168, 72, 82)
#: the teeth band: its share of the local opening and its largest height in mouth widths
TEETH_SHARE, TEETH_WIDTH = 0.35, 0.09
#: the tongue band, likewise above the lower lip
TONGUE_SHARE, TONGUE_WIDTH = 0.3, 0.1
#: the channel spread (max - min of R, G, B, 0-255) from which a target counts as fully coloured
CHROMA_FULL = 24.0


def image_chroma(image, points) -> float:
    """How coloured ``image`` is around ``points`` (k, 2) (e.g. the lips, iBUG 48-67): the median channel
    spread ``max(R, G, B) - min(R, G, B)`` over the points' bounding box grown by half its size each side,
    over :data:`CHROMA_FULL`, clipped to [0, 1]; 0 for an image with one or two channels. The mouth is
    painted with this share of its colours' chroma (:func:`paint_mouth`): a grey photograph gets a grey mouth
    (MediaPipe's reading of the turned cameraman's opening: r 0.75, gain 0.31 with the red mouth, r 0.96,
    gain 0.87 with its grey)."""
    img = np.asarray(image)
    if img.ndim < 3 or img.shape[2] < 3:
        return 0.0
    P = np.asarray(points, np.float64)
    lo, hi = P.min(0), P.max(0)
    pad = 0.5 * (hi - lo)
    H, W = img.shape[:2]
    x0, y0 = np.clip(np.floor(lo - pad).astype(int), 0, [W - 1, H - 1])
    x1, y1 = np.clip(np.ceil(hi + pad).astype(int) + 1, [x0 + 1, y0 + 1], [W, H])
    box = img[y0:y1, x0:x1, :3].astype(np.int16)
    return float(np.clip(np.median(box.max(-1) - box.min(-1)) / CHROMA_FULL, 0.0, 1.0))


def _lip_curve(u_pts, v_pts, u):
    """The lip's offset v at positions u (piecewise linear; the lip's u made non-decreasing)."""
    u_pts = np.maximum.accumulate(u_pts)
    return np.interp(u, u_pts, v_pts)


def mouth_coordinates(inner_lip, x, y):
    """Coordinates of pixels (x, y) (any equal shapes) in the mouth's frame of the inner-lip polygon
    (8, 2): ``u`` along the mouth (0 at corner 60, 1 at corner 64), ``s`` from the upper lip (0) to
    the lower lip (1), the local opening ``h`` and the mouth width ``w`` in pixels."""
    P = np.asarray(inner_lip, np.float64)
    _, e, n, w = feature_frame(P, (0, 4), [1, 2, 3], [5, 6, 7])   # n points from the upper lip to the lower
    rel = P - P[0]
    pu, pv = rel @ e / w, rel @ n
    dx, dy = np.asarray(x, np.float64) - P[0, 0], np.asarray(y, np.float64) - P[0, 1]
    u = np.clip((dx * e[0] + dy * e[1]) / w, 0.0, 1.0)
    v = dx * n[0] + dy * n[1]
    up = _lip_curve(pu[[0, 1, 2, 3, 4]], pv[[0, 1, 2, 3, 4]], u)
    lo = _lip_curve(pu[[0, 7, 6, 5, 4]], pv[[0, 7, 6, 5, 4]], u)
    h = np.maximum(lo - up, 1e-6)
    return u, (v - up) / h, h, w


def mouth_colours(u, s, h, w, teeth: bool = True, tongue: bool = True) -> np.ndarray:
    """(..., 3) float32 RGB of the painted interior at mouth coordinates (:func:`mouth_coordinates`)."""
    taper = np.sqrt(np.clip(1.0 - (2.0 * u - 1.0) ** 2, 0.0, 1.0))
    depth = 1.0 - np.abs(2.0 * np.clip(s, 0.0, 1.0) - 1.0)            # 0 at the lips, 1 in the middle
    edge, back = np.float32(CAVITY_EDGE_RGB), np.float32(CAVITY_BACK_RGB)
    col = edge + (back - edge) * np.sqrt(depth)[..., None].astype(np.float32)
    dist_up, dist_lo = s * h, (1.0 - s) * h                          # pixels from each lip
    for on, share, width, rgb, dist in ((tongue, TONGUE_SHARE, TONGUE_WIDTH, TONGUE_RGB, dist_lo),
                                        (teeth, TEETH_SHARE, TEETH_WIDTH, TEETH_RGB, dist_up)):
        if not on:
            continue
        band = np.minimum(share * h, width * w) * taper
        # 1 px ramp, times the band's own width where it is under a pixel (a nearly closed mouth: no light seam)
        a = (np.clip(band - dist + 0.5, 0.0, 1.0) * np.clip(band, 0.0, 1.0))[..., None].astype(np.float32)
        col = col * (1 - a) + np.float32(rgb) * a
    return col


def paint_mouth(image, inner_lip, opacity: float = 1.0, teeth: bool = True, tongue: bool = True,
                chroma: float = 1.0) -> None:
    """Paint the open mouth inside the polygon ``inner_lip`` (8, 2) (iBUG 60-67) of ``image`` (H, W),
    (H, W, 1), (H, W, 3) or (H, W, 4) uint8 in place, blended with ``opacity`` (anti-aliased edge;
    a grey image gets the luma, an alpha channel is made opaque), the colours' chroma scaled by ``chroma``
    (0: their luma; the warp passes :func:`image_chroma` of the target). Nothing is drawn for a polygon of
    area at most :data:`.mouth2d.MIN_OPEN_AREA` px^2 or an opacity below 1/255; only pixels under
    the polygon's anti-aliased edge change."""
    from .mouth2d import blend_polygon

    P = np.asarray(inner_lip, np.float64)

    def colours(xx, yy):
        rgb = mouth_colours(*mouth_coordinates(P, xx, yy), teeth, tongue)
        if chroma < 1.0:                             # towards the colours' luma: a grey photograph's grey mouth
            luma = (rgb @ np.float32([0.299, 0.587, 0.114]))[..., None]
            rgb = luma + np.float32(max(chroma, 0.0)) * (rgb - luma)
        return rgb

    blend_polygon(image, P, colours, opacity)


__all__ = ["TEETH_RGB", "CAVITY_EDGE_RGB", "CAVITY_BACK_RGB", "TONGUE_RGB", "CHROMA_FULL", "image_chroma",
           "mouth_coordinates", "mouth_colours", "paint_mouth"]
