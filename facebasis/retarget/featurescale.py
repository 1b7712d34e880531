"""Expression amplitude in the target face's own proportions: eq. 12 per facial feature.

The paper's eq. 12 scales every captured displacement by one number, the ratio of the two meshes'
mean edge lengths (eq. 13). A target whose features have other proportions than the captured face
(a cartoon with eyes twice as tall, a wide mouth) then moves each
feature by the *face's* scale, not the feature's: an eye that closes on the capture moves the
cartoon's lids by a fraction of the cartoon's eye height, and a detector (or a viewer) reads a
feature that barely moves.

Here each feature f (an eye, the mouth; a brow with its eye) carries the capture's displacements over by its own
2x2 map, built from the feature's own measures on the two faces. In the feature's frame (``u`` the
unit vector between its two corner landmarks, ``n`` its normal), a displacement's component along
``u`` scales by the ratio ``h_f`` of the feature's widths and its component along ``n`` by the ratio
``v_f`` of its heights, and the frame turns from the capture's to the target's:

    d_target,i = h_f (d_i . u_c) u_t + v_f (d_i . n_c) n_t      for the landmarks i of feature f   (eq. 12 per feature)

with the measures: an eye's width is the distance of its corners, its height the mean gap between
its upper and lower lid points (an eye twice as tall on the target relative to the face closes by
twice the pixels, the same fraction of itself); a brow moves with its eye's centre (as the eye's
map moves it) and by the face's ``s`` relative to it, so that the lids' own ratio does not carry the
brow's height over the eye away (a brow's own ratio, its height over the eye on the two faces, was
tried: its warped height followed the capture's at 0.78-0.95 on the photographs, 0.98-0.999 with
``s``; scaling the brow's displacement without the anchor, next to lids moved by another ratio,
at 0.72 on the built-in cartoon);
the mouth scales by the ratio of its corner distances in both directions (an opening from closed
lips has no height of its own to compare). Jaw and nose keep the paper's scalar ``s``. Every ratio
is clamped to ``[s / bound, s bound]``: a feature that is degenerate on one face (an eye shut on the
capture's first frame) cannot blow the motion up. (A least-squares linear fit of each feature's
landmarks was tried first: an eye's corners and lids sit differently on a drawn eye, and the fit
scaled the built-in cartoon's lid motion by 0.66 where its lid gap is 0.97 of the capture's.)

The capture's reference shape is its first frame, the one the correspondence (eq. 10) is trained on
and the displacements are measured from: both faces are taken at rest there. (A median over the
frames was tried: it measures the capture's mouth while it talks, open half the time, and carried a
known opening over at 0.77 of its proportion instead of 1.) The bounds keep a take that starts
mid-blink from multiplying a feature's motion by more than ``bound``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: the features of the iBUG-68 set with their own map: (name, landmarks moved, the two corner landmarks
#: giving the feature's axis or None (the map is ``s I``), height pairs (from, to) of landmark groups
#: whose distance along the normal is the feature's height or None (the width ratio in both
#: directions), the landmarks the feature's motion is measured against or None (a brow moves with
#: its eye's centre as the eye's map moves it, plus ``s`` times its motion relative to that centre)
FEATURES_68 = (
    ("right eye", np.r_[36:42], (36, 39), (((37,), (41,)), ((38,), (40,))), None),
    ("left eye", np.r_[42:48], (42, 45), (((43,), (47,)), ((44,), (46,))), None),
    ("right brow", np.r_[17:22], None, None, np.r_[36:42]),
    ("left brow", np.r_[22:27], None, None, np.r_[42:48]),
    ("mouth", np.r_[48:68], (48, 54), None, None),
)

#: values of ``amplitude``: "feature" (each feature moves in its own proportions, this module) or
#: "uniform" (the paper's eq. 12: one scale for the whole face)
AMPLITUDE_MODES = ("feature", "uniform")

#: how far (a factor either way) a feature's map may scale against the face's eq. 13 scale
BOUND = 3.0


@dataclass(frozen=True)
class FeatureMaps:
    """Per-feature displacement maps (eq. 12 per feature).

    Attributes
    ----------
    names : tuple of feature names
    moved : tuple of (k_f,) landmark indices each map moves
    anchors : tuple of (a_f,) landmark indices (an earlier feature's) whose mean a feature's motion
        is taken relative to, or None
    maps : (F, 2, 2) each feature's map acting on row vectors, ``d @ maps[f]``
        (``h u_c^T u_t + v n_c^T n_t``)
    ratios : (F, 2) the clamped width and height ratios ``(h_f, v_f)``
    scale : the eq. 13 scalar ``s`` of the other vertices
    """

    names: tuple
    moved: tuple
    anchors: tuple
    maps: np.ndarray
    ratios: np.ndarray
    scale: float

    def apply(self, displacements) -> np.ndarray:
        """Target displacements (..., N, 2) for capture displacements (..., N, 2): ``s d`` everywhere,
        ``d @ maps[f]`` on each feature's landmarks; with an anchor a (the brows):
        ``mean(out[a]) + (d - mean(d[a])) @ maps[f]``."""
        D = np.asarray(displacements, np.float64)
        out = self.scale * D
        for idx, anchor, A in zip(self.moved, self.anchors, self.maps):
            if anchor is None:
                out[..., idx, :] = D[..., idx, :] @ A
            else:
                base = D[..., anchor, :].mean(-2, keepdims=True)
                out[..., idx, :] = out[..., anchor, :].mean(-2, keepdims=True) + (D[..., idx, :] - base) @ A
        return out


def feature_frame(points, corners):
    """(u, n, width) of a feature on one face: the unit vector between its corner landmarks
    ``points[corners]``, its normal (u turned a quarter towards +y, image down) and the corners' distance."""
    a, b = np.asarray(points, np.float64)[list(corners)]
    width = float(np.linalg.norm(b - a))
    u = (b - a) / width if width > 0 else np.array([1.0, 0.0])
    return u, np.array([-u[1], u[0]]), width


def feature_height(points, n, pairs) -> float:
    """Mean over ``pairs`` of ``|(mean of points[to] - mean of points[from]) . n|``."""
    P = np.asarray(points, np.float64)
    return float(np.mean([abs((P[list(q)].mean(0) - P[list(p)].mean(0)) @ n) for p, q in pairs]))


def feature_maps(capture_reference, target_rest, scale: float, features=FEATURES_68,
                 bound: float = BOUND) -> FeatureMaps:
    """The per-feature maps of the module docstring.

    Parameters
    ----------
    capture_reference : (L, 2) the capture's landmarks at rest (its first frame)
    target_rest : (L, 2) the same landmarks on the target
    scale : the eq. 13 scale ``s`` (target / capture mean edge length)
    features : (name, moved indices, (corner, corner) or None, height pairs or None, anchor indices
        or None) per feature, an anchor's feature listed before
    bound : every ratio is clamped to ``[s / bound, s bound]``

    Returns
    -------
    FeatureMaps
    """
    P = np.asarray(capture_reference, np.float64)
    Q = np.asarray(target_rest, np.float64)
    if P.shape != Q.shape or P.ndim != 2 or P.shape[1] != 2:
        raise InputError(f"feature maps: expected two landmark sets of the same shape (L, 2), found {P.shape} "
                         f"and {Q.shape}")
    if not (np.isfinite(scale) and scale > 0 and np.isfinite(bound) and bound >= 1):
        raise InputError(f"feature maps: expected a scale > 0 and a bound >= 1, found {scale} and {bound}")
    lo, hi = scale / bound, scale * bound

    def ratio(target, capture):          # a feature flat on the capture: the bound, on both: s
        r = target / capture if capture > 0 else (hi if target > 0 else scale)
        return float(np.clip(r, lo, hi))

    names, moved, anchors, maps, ratios = [], [], [], [], []
    for name, idx, corners, pairs, anchor in features:
        if corners is None:                  # the face's scale (a brow, relative to its eye)
            uc = ut = np.array([1.0, 0.0])
            nc = nt = np.array([0.0, 1.0])
            h = v = float(scale)
        else:
            uc, nc, wc = feature_frame(P, corners)
            ut, nt, wt = feature_frame(Q, corners)
            h = ratio(wt, wc)
            v = h if pairs is None else ratio(feature_height(Q, nt, pairs), feature_height(P, nc, pairs))
        names.append(name)
        moved.append(np.asarray(idx, np.int64))
        anchors.append(None if anchor is None else np.asarray(anchor, np.int64))
        maps.append(h * np.outer(uc, ut) + v * np.outer(nc, nt))
        ratios.append((h, v))
    return FeatureMaps(tuple(names), tuple(moved), tuple(anchors), np.array(maps).reshape(-1, 2, 2),
                       np.array(ratios).reshape(-1, 2), float(scale))


def parse_amplitude(value) -> str:
    """Check an ``amplitude`` value (None: "feature")."""
    from ..errors import parse_mode

    return parse_mode("amplitude", value, AMPLITUDE_MODES, "feature")


__all__ = ["FeatureMaps", "feature_maps", "feature_frame", "feature_height", "parse_amplitude", "FEATURES_68",
           "AMPLITUDE_MODES", "BOUND"]
