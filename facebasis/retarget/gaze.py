"""Conjugate gaze: the two eyes look the same way, a prior the landmarks cannot give.

A 68-point capture sees no iris. The rig's eye-look shapes (ARKit's ``eyeLook{Up,Down,In,Out}_{L,R}``)
reach the landmarks only through the lids they move, so a lid that one eye's landmarks place a
little lower than the other's is fitted as that eye alone looking down (measured on a MediaPipe cut
of cap12 that starts at rest: eyeLookDown_L 0.12-0.19 on its calm frames, eyeLookDown_R 0). Yet the
eyes move together (Hering's law of equal innervation): vertically they stay within a fraction of a
degree of each other, and horizontally one looks in while the other looks out, apart from the
vergence of a near target. So the weight step gets a Gaussian prior on each conjugate pair's
difference (:func:`conjugate_gaze_pairs`):

    x_a - x_b ~ N(0, sigma_d^2),   (a, b) in {(Up_L, Up_R), (Down_L, Down_R), (In_L, Out_R), (Out_L, In_R)},

next to the ridge's ``x_i ~ N(0, sigma_w^2)`` (sigma_w = ``PRIOR_STD`` = 0.5 of :mod:`.rigdrive`). In the weight
step's units (the ridge rho = noise^2 / sigma_w^2) it is the term ``rho (sigma_w / sigma_d)^2 (x_a - x_b)^2``
(:func:`gaze_tie`); ``sigma_d`` (:data:`GAZE_SD`) 0.05: a vertical difference of 0.05 of a full look
is a few degrees, more than eyes hold apart. Horizontally the prior also pulls against vergence (both
eyes looking in at a near target), which 68 landmarks cannot see either; that was not measured.
Left-right differences of the lid shapes themselves (a wink, one squinting eye) stay free: they are
real. The prior scales with the ridge: a ridge of 0 (a temporal term alone) has no prior at all, this
one included. Names: ICT-FaceKit's ``eyeLookDown_L`` and Apple ARKit's ``eyeLookDownLeft`` spellings.

Measured on the shared clips' cuts (``reports/retarget/rest_cuts_summary.md``): the one-eyed lid signal
on MediaPipe cap12 from 4 s moves partly from eyeLookDown_L (0.12 on the calm frames) to eyeBlink_L
(0.06), a lid shape that is allowed one eye.
"""

from __future__ import annotations

import numpy as np

#: standard deviation of a conjugate pair's weight difference (module docstring)
GAZE_SD = 0.05
#: the conjugate eye-look pairs, ARKit names: each eye's look direction paired with the other eye's same direction
CONJUGATE = tuple((f"eyeLook{a}{sa}", f"eyeLook{b}{sb}") for sa, sb in (("_L", "_R"), ("Left", "Right"))
                  for a, b in (("Up", "Up"), ("Down", "Down"), ("In", "Out"), ("Out", "In")))
#: the modes of the prior: "conjugate" (pairs found by name) or "free" (no prior)
GAZE_MODES = ("conjugate", "free")


def conjugate_gaze_pairs(names) -> np.ndarray:
    """(g, 2) int64 index pairs of the rig's shapes that are conjugate eye-look directions
    (:data:`CONJUGATE`, both names present; ``names`` a sequence of shape names); (0, 2) when the rig has none."""
    where = {n: i for i, n in enumerate(names)}
    pairs = [(where[a], where[b]) for a, b in CONJUGATE if a in where and b in where]
    return np.asarray(pairs, np.int64).reshape(-1, 2)


def gaze_tie(n_shapes: int, pairs, prior_std: float, sd: float = GAZE_SD) -> np.ndarray | None:
    """(k, k) the prior's matrix per unit ridge, ``(prior_std / sd)^2 sum_(a,b) (e_a - e_b)(e_a - e_b)^T``
    (the weight step adds ``rho`` times it to its Gram matrix); None without pairs."""
    P = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(P) == 0:
        return None
    T = np.zeros((len(P), int(n_shapes)))
    T[np.arange(len(P)), P[:, 0]] = 1.0
    T[np.arange(len(P)), P[:, 1]] = -1.0
    return (float(prior_std) / float(sd)) ** 2 * (T.T @ T)


__all__ = ["GAZE_SD", "CONJUGATE", "GAZE_MODES", "conjugate_gaze_pairs", "gaze_tie"]
