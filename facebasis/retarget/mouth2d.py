"""The mouth of a 2D cartoon warp: what is drawn inside the lips as they open.

A piecewise-affine warp can only move the target's own pixels. When the capture's mouth opens wider
than the target's mouth is drawn (a painting or photograph with closed lips, a cartoon whose mouth
is drawn half open), the triangles inside the inner-lip polygon stretch what the target shows there:
a sliver of lips becomes a band of stretched lip colour, which neither a viewer nor a face detector
reads as an opening. A
capture mesh cut open along closed lips (:func:`mouth_is_cut`) has no triangle there at all, and the
target's still pixels showed through the gap.

:func:`fill_mouth` therefore draws the opening, the inner-lip polygon (iBUG 60-67) of the frame, as
a dark mouth interior whenever it is open, whatever the target draws there and whether the capture
mesh is cut or not: a closed-mouth painting driven open shows a dark opening exactly as large as the
opening. Measured on cap13 (dlib capture, every 10th frame, dlib on the output against the warped
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


def fill_mouth(image, inner_lip, colour=MOUTH_INTERIOR_RGB, opacity: float = 1.0) -> None:
    """Blend the polygon ``inner_lip`` (8, 2) of ``image`` (H, W, C) uint8 in place towards
    ``colour`` with ``opacity`` (anti-aliased edge), when the polygon is open (area above a quarter
    pixel) and the opacity above 1/255. Only the polygon's bounding box is touched."""
    import cv2

    P = np.asarray(inner_lip, np.float64)
    if polygon_area(P) <= 0.25 or opacity * 255.0 < 1.0:
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
    a = (mask.astype(np.float32) * (float(opacity) / 255.0))[..., None]
    col = np.array(tuple(colour)[:3] + (255,) * max(0, image.shape[2] - 3), np.float32)[: image.shape[2]]
    box = image[y0:y1, x0:x1].astype(np.float32)
    image[y0:y1, x0:x1] = np.clip(np.rint(box * (1.0 - a) + col * a), 0, 255).astype(np.uint8)


__all__ = ["INNER_LIP_68", "MOUTH_INTERIOR_RGB", "MOUTH_STRIP_68", "mouth_is_cut", "polygon_area", "fill_mouth"]
