"""A closing eye painted as an eye closing: the upper lid drawn down over the eye, a lash line at its edge.

The piecewise-affine warp closes a target's eye by squeezing the eye region between the lid landmarks:
iris, sclera and lashes squashed into a thinner copy of the open eye. On a photograph a detector reads
that as an eye closing; on a painting (flat colours, soft edges) or a small, turned face it barely does:
dlib read the painted astronaut's eyes closing with a gain of 0.13, MediaPipe 0.22
(``reports/reproduction/cartoon_readback``). A real eye closes differently: the eyeball stays, the upper
lid (skin) slides down over it and its lash line, the darkest edge of the eye, comes down with it.

:func:`paint_eye` draws that, in the eye's own frame (``u`` along the axis between its corner landmarks,
iBUG 36-39 and 42-45, ``v`` across it in eye widths), once the frame's eye is more closed than the
target's own (:func:`eye_closure`):

* the *open eye* is the target's rest eye carried into the frame's eye frame (a similarity from
  corner to corner): its upper and lower lid curves (piecewise linear in ``u`` through the lid landmarks);
* inside it, above the frame's upper lid, the lid: the target's own lid colour (:func:`eye_colours`,
  the median of the skin just above the rest eye), reaching :data:`LID_MARGIN` eye widths above the rest
  upper lid so that a painting's lid stroke, drawn above the landmarks, comes down with it; below the frame's lower lid, the lower lid's skin;
  between them, the target's own open eye unsquashed (sampled through the same similarity), so the
  lids cut the iris instead of squashing it;
* along the frame's upper lid, the lash line: the darkest colour of the target's own eye, ``LASH_WIDTH``
  eye widths thick (at least one pixel).

Every edge is a linear ramp one pixel wide and the whole is blended with an opacity that grows with the
closure (``clip(c / CLOSURE_FULL, 0, 1)``), so that an eye at rest, or opening wider than the target's,
is left byte-identical; only pixels inside the open eye's anti-aliased outline (grown by the lash line and :data:`LID_MARGIN`)
change. Vectorised over the eye's bounding box.

Measured (``problems/cartoon_readback.py``'s eye ramp, both lids closing to the warp's contact gap, read
back on the 9 frames; gain of the reading against the warped opening, bare warp -> painted lid; the lid
margin 0 / 0.1 / 0.2 eye widths compared): dlib 0.13 -> 0.28 and MediaPipe 0.22 -> 0.52 on the painted
astronaut, dlib 0.05 -> 0.28 and MediaPipe -0.14 -> 0.06 on the turned cameraman, 0.67 -> 0.92 / 0.65 -> 0.66
on the astronaut photograph, 0.66 -> 0.76 / 0.59 -> 0.59 on the built-in cartoon (margin 0.1, the largest
sum of gains of the three). Drawing the lids shut once the warp reaches its contact gap (where the capture's
lids meet) was tried: MediaPipe then read the cartoon's closing better (0.59 -> 0.68) but dlib read a shut
cartoon eye as open again (r 0.99 -> 0.64), so the lids stop where the landmarks are.
"""

from __future__ import annotations

import numpy as np

from .mouth2d import blend_pixels, feature_frame

#: the two eyes of the 68-point iBUG set: corner, upper lid (2), corner, lower lid (2) in polygon order
EYES_68 = (np.array([36, 37, 38, 39, 40, 41]), np.array([42, 43, 44, 45, 46, 47]))
#: the closure (1 - opening / rest opening) from which the lid is drawn opaque
CLOSURE_FULL = 0.25
#: the lash line's thickness, in eye widths (at least one pixel)
LASH_WIDTH = 0.07
#: how far above the rest upper lid the drawn lid reaches, in eye widths (a painting's lid stroke lies above
#: the landmarks)
LID_MARGIN = 0.1
#: the skin band sampled for the lid colour: this far above the rest upper lid, in eye widths
LID_BAND = (0.12, 0.3)


#: source pixels sampled per row of the remap maps (any width under 32767; a whole eye in few rows)
REMAP_ROW = 4096

def eye_frame(eye):
    """The frame of an eye (6, 2) (corner, upper lid 2, corner, lower lid 2): origin at the first
    corner, unit axis ``e`` to the other corner, normal ``n`` pointing from the upper lid to the lower,
    and the width ``w`` (pixels)."""
    return feature_frame(eye, (0, 3), [1, 2], [4, 5])


def lid_curves(eye, u, frame=None):
    """Upper and lower lid offsets ``v`` (eye widths, along the normal) of an eye (6, 2) at positions
    ``u`` (any shape, eye widths from the first corner): piecewise linear through the lid landmarks
    (``frame``: the eye's :func:`eye_frame`, when already known)."""
    o, e, n, w = eye_frame(eye) if frame is None else frame
    rel = (np.asarray(eye, np.float64) - o) / w
    pu, pv = rel @ e, rel @ n
    up_u, up_v = np.maximum.accumulate(pu[[0, 1, 2, 3]]), pv[[0, 1, 2, 3]]
    lo_u, lo_v = np.maximum.accumulate(pu[[0, 5, 4, 3]]), pv[[0, 5, 4, 3]]
    return np.interp(u, up_u, up_v), np.interp(u, lo_u, lo_v)


def eye_opening(eye) -> float:
    """Mean gap between the lid landmarks (37-41, 38-40) over the corner distance."""
    P = np.asarray(eye, np.float64)
    w = max(float(np.linalg.norm(P[3] - P[0])), 1e-9)
    return float(np.linalg.norm(P[[1, 2]] - P[[5, 4]], axis=1).mean()) / w


def eye_closure(eye, rest_eye) -> float:
    """``clip(1 - opening / rest opening, 0, 1)`` (:func:`eye_opening`): 0 at rest or wider, 1 shut."""
    r = eye_opening(rest_eye)
    return float(np.clip(1.0 - eye_opening(eye) / r, 0.0, 1.0)) if r > 1e-6 else 0.0


def eye_colours(image, rest_eye):
    """(lid, lower lid, lash) RGB float32 colours of the target's own eye (6, 2) on ``image`` (H, W, 3):
    the median of the skin band :data:`LID_BAND` above the upper lid, the same below the lower lid, and
    the 5th percentile (by luma) of the pixels inside the eye."""
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[..., None]
    rgb = np.repeat(img[..., :1], 3, -1) if img.shape[2] < 3 else img[..., :3]
    H, W = rgb.shape[:2]
    o, e, n, w = eye_frame(rest_eye)
    lo, hi = np.floor(np.asarray(rest_eye).min(0) - w).astype(int), np.ceil(np.asarray(rest_eye).max(0) + w)
    x0, y0 = np.clip(lo, 0, [W - 1, H - 1])
    x1, y1 = np.clip(hi.astype(int) + 1, [x0 + 1, y0 + 1], [W, H])
    yy, xx = np.mgrid[y0:y1, x0:x1]
    dx, dy = xx - o[0], yy - o[1]
    u, v = (dx * e[0] + dy * e[1]) / w, (dx * n[0] + dy * n[1]) / w
    up, low = lid_curves(rest_eye, u)
    mid = (u > 0.2) & (u < 0.8)
    box = rgb[y0:y1, x0:x1].astype(np.float32)

    def median(m):
        return np.median(box[m], 0) if m.any() else np.median(box.reshape(-1, 3), 0)

    lid = median(mid & (v < up - LID_BAND[0]) & (v > up - LID_BAND[1]))
    under = median(mid & (v > low + LID_BAND[0]) & (v < low + LID_BAND[1]))
    inside = (u > 0) & (u < 1) & (v > up) & (v < low)
    pix = box[inside] if inside.any() else box.reshape(-1, 3)
    luma = pix @ np.float32([0.299, 0.587, 0.114])
    lash = pix[luma <= np.percentile(luma, 5)].mean(0)
    return lid.astype(np.float32), under.astype(np.float32), lash.astype(np.float32)


def paint_eye(image, source, eye, rest_eye, colours, closure: float | None = None) -> None:
    """Paint the closing eye ``eye`` (6, 2) of the warped ``image`` (H, W, C) uint8 in place: the open eye
    of ``source`` (the target image, (H', W', C)) at ``rest_eye`` (6, 2) carried into the frame's eye, its
    lids drawn at the frame's lid landmarks, a lash line on the upper lid (module docstring); ``colours``
    from :func:`eye_colours`. Nothing is drawn below a closure (:func:`eye_closure`) of 1/255 of
    :data:`CLOSURE_FULL`."""
    import cv2

    c = eye_closure(eye, rest_eye) if closure is None else float(closure)
    alpha = float(np.clip(c / CLOSURE_FULL, 0.0, 1.0))
    if alpha * 255.0 < 1.0:
        return
    lid, under, lash = colours
    o, e, n, w = frame = eye_frame(eye)
    ro, re_, rn, rw = rest_frame = eye_frame(rest_eye)
    ks = np.linspace(0.0, 1.0, 17)
    up_r, lo_r = lid_curves(rest_eye, ks, rest_frame)
    lash_w = max(LASH_WIDTH, 1.0 / w)
    outline = np.concatenate([o + w * (ks[:, None] * e + (up_r - lash_w - LID_MARGIN)[:, None] * n),
                              (o + w * (ks[:, None] * e + lo_r[:, None] * n))[::-1]])
    H, W = image.shape[:2]
    x0, y0 = np.maximum(np.floor(outline.min(0)).astype(int) - 2, 0)
    x1, y1 = np.minimum(np.ceil(outline.max(0)).astype(int) + 3, [W, H])
    if x1 <= x0 or y1 <= y0:
        return
    shift = 4
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.fillPoly(mask, np.round((outline - [x0, y0]) * (1 << shift)).astype(np.int32)[None], 255,
                 lineType=cv2.LINE_AA, shift=shift)
    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return
    dx, dy = xs + x0 - o[0], ys + y0 - o[1]
    u, v = (dx * e[0] + dy * e[1]) / w, (dx * n[0] + dy * n[1]) / w
    up_t, lo_t = lid_curves(eye, u, frame)
    up_o, lo_o = lid_curves(rest_eye, u, rest_frame)
    up_t, lo_t = np.maximum(up_t, up_o), np.minimum(lo_t, lo_o)   # never wider than the open eye
    a_top = np.clip((v - (up_o - LID_MARGIN)) * w + 0.5, 0.0, 1.0)[:, None]
    # the open eye unsquashed: the source's pixel at the same eye coordinates
    sx = (ro[0] + rw * (u * re_[0] + v * rn[0])).astype(np.float32)
    sy = (ro[1] + rw * (u * re_[1] + v * rn[1])).astype(np.float32)
    # the maps as rows of REMAP_ROW (cv2.remap needs each side under 32767: a (k, 1) map failed on eyes ~300 px wide)
    rows = -(-len(sx) // REMAP_ROW)
    pad = rows * REMAP_ROW - len(sx)
    sx, sy = (np.pad(m, (0, pad), mode="edge").reshape(rows, REMAP_ROW) for m in (sx, sy))
    src = cv2.remap(source, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    src = src.reshape(rows * REMAP_ROW, -1)[: len(ys)].astype(np.float32)[:, :3]
    if src.shape[1] == 1:
        src = np.repeat(src, 3, 1)
    px = w                                               # pixels per eye width: 1 px ramps
    a_lid = np.clip((up_t - v) * px + 0.5, 0.0, 1.0)[:, None]
    a_low = np.clip((v - lo_t) * px + 0.5, 0.0, 1.0)[:, None]
    a_lash = np.clip(0.5 * lash_w * px + 0.5 - np.abs(v - (up_t - 0.5 * lash_w)) * px, 0.0, 1.0)[:, None]
    col = src * (1 - a_lid) + lid * a_lid
    col = col * (1 - a_low) + under * a_low
    col = col * (1 - a_lash) + lash * a_lash
    blend_pixels(image, x0, y0, ys, xs, col, (mask[ys, xs].astype(np.float32) * (alpha / 255.0))[:, None] * a_top)


__all__ = ["EYES_68", "CLOSURE_FULL", "LASH_WIDTH", "LID_MARGIN", "LID_BAND", "eye_frame", "lid_curves", "eye_opening",
           "eye_closure", "eye_colours", "paint_eye"]
