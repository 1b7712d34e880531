"""The face contour of a head held still: the jaw line follows the lower lip, not the head's turns.

:mod:`.headmotion` takes the head's in-plane similarity out of a capture; a head turning out of the
image plane is not a similarity, and on the 68-point iBUG set it shows most on the face contour (the jaw
line, points 0-16): the contour slides sideways as the head turns left or right and moves against the eyes as
it nods. What is left of the contour once the similarity is out is therefore mostly head motion, not
expression. Measured on the shared clips' four captures (dlib and tracking only; each capture's own
landmarks with the similarity out), in eye-corner distances: the contour's sideways shift has a standard deviation of 0.058-0.064 and
follows the nose tip's sideways offset from the inner eye corners (a yaw measure) at r -0.71 to -0.93; its
width changes by 0.04-0.06 with no relation to the mouth (|r| <= 0.1); the mouth opening itself moves by
0.03-0.055. Drawn on a still cartoon, that motion is a face outline swinging under a frontal face, and
the detector that reads the output fits its face model to the outline: with only the brows, eyes and the
contour moving, MediaPipe's reading of the brows on the built-in cartoon falls from r 0.93 to 0.43 (0.76
without the contour; cap13, 120 frames).

The contour's expression part is the jaw opening: the chin rides the mandible with the lower lip. So with
68 landmarks each contour point moves by ``w_i`` times the outer lower lip's displacement (iBUG 56-58,
their mean)::

    c_i(t) = c_i(0) + w_i (m(t) - m(0)),   w_i = 1 (i = 6..10), 0 otherwise

the chin moving with the lip as in :mod:`problems.cartoon_readback`'s mouth-opening ramp (iBUG 6-10 drop
with the lower lip; on those ramps the contour is the ramp's own, the read-back unchanged), the rest of the
contour (the jaw's angles, the cheeks and temples up to the ears) still. Measured and worse on the ramps:
a taper from the chin to the ears (``w_i = 1 - |i - 8| / 8``) pulls the cheeks down with the lip (dlib's
reading of the turned cameraman's opening r 0.61 -> 0.21, the painted astronaut 0.98 -> 0.95, MediaPipe
0.96 -> 0.91); half of the lip's motion at 5 and 11 still lowered it (0.61 -> 0.48, astronaut gain 1.02 -> 0.84).
The lower lip's own motion is unchanged. With each feature moved by its own map (``amplitude`` "feature",
:mod:`.featurescale`) the chin follows the cartoon's own lower lip, after the maps
(:meth:`.warp2d.CartoonAnimator.drive`): a cartoon mouth wider than the capture's opens further, and a chin that
followed the capture's lip moved only 0.68 of it (review9: the lip-chin gap of the built-in cartoon with a 1.6 times
wider mouth shrank from 38.4 to 4.3 px on cap13).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

#: how the face contour (iBUG 0-16) is driven on a head held still: "lips" (it follows the lower lip, module
#: docstring) or "capture" (the captured contour, head turns included)
JAW_MODES = ("lips", "capture")
#: iBUG 68: the face contour, its chin point, the outer lower lip's middle points
CONTOUR_68, CHIN_68, LOWER_LIP_68 = np.arange(17), 8, np.array([56, 57, 58])


def parse_jaw_mode(jaw) -> str:
    """``jaw`` checked against :data:`JAW_MODES` (None: "lips")."""
    from ..errors import parse_mode

    return parse_mode("jaw", jaw, JAW_MODES, "lips")


def contour_weights() -> np.ndarray:
    """(17,) how much of the lower lip's motion each contour point takes: 1 at iBUG 6-10, else 0."""
    return (np.abs(CONTOUR_68 - CHIN_68) <= 2).astype(np.float64)


def jaw_from_lips(vertices, rest) -> np.ndarray:
    """The contour driven by the lower lip (module docstring).

    Parameters
    ----------
    vertices : (T, N, 2) captured vertices with the head's similarity taken out, the 68 iBUG landmarks first
    rest : (N, 2) the same vertices at rest (the frame the cartoon was built on)

    Returns
    -------
    (T, N, 2) a copy of ``vertices`` with points 0-16 replaced
    """
    V = np.array(vertices, np.float64)
    R = np.asarray(rest, np.float64)
    if V.ndim != 3 or V.shape[1] < 68 or R.shape != V.shape[1:]:
        raise InputError(f"captured vertices: expected (T, N >= 68, 2) with a rest of shape (N, 2), found {V.shape} "
                         f"and {R.shape}")
    lip = V[:, LOWER_LIP_68].mean(1) - R[LOWER_LIP_68].mean(0)                  # (T, 2)
    V[:, CONTOUR_68] = R[CONTOUR_68][None] + contour_weights()[None, :, None] * lip[:, None, :]
    return V


__all__ = ["JAW_MODES", "parse_jaw_mode", "contour_weights", "jaw_from_lips"]
