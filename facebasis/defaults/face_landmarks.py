"""68 landmark vertices of the built-in 3D face (iBUG / Multi-PIE order), chosen from its geometry.

The built-in face (:mod:`facebasis.defaults.face`) looks along +z with its own left at +x, so a
camera in front of it sees the face's left on the image's right, as iBUG expects: jaw 0-16 runs
from -x to +x, the right brow (17-21) and right eye (36-41) are at -x.

* eyes (36-47) and inner lips (60-67): vertices of the eye and mouth slit loops (corners, and the
  upper/lower copies at 1/3 and 2/3 (eyes) or 1/4, 1/2, 3/4 (lips) of the slit);
* every other point: the front-surface vertex nearest (in x, y) to a point of a curve laid out in
  the face's own grid frame (jaw: the lower half of an ellipse through the mask; brows above the
  eyes on the brow ridges; nose bridge down the midline to the tip, the highest point; outer lips
  just above and below the lip line).

:func:`face_landmarks` computes them once; ``DEFAULT_EXCLUSIVE`` pairs of the rig live in
:mod:`facebasis.defaults.face`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=1)
def _indices() -> tuple[int, ...]:
    from scipy.spatial import cKDTree

    from .face import EYE_L, EYE_R, MOUTH, NU, NV, _topology, default_template

    topo = _topology()
    V = default_template().neutral
    front = np.flatnonzero((topo.pocket == 0) & (topo.side == 0))
    tree = cKDTree(V[front, :2])
    W = np.ptp(V[front, 0]) / 2
    H = np.ptp(V[front, 1]) / 2

    def near(xy):
        _, i = tree.query(np.asarray(xy, float))
        return front[np.atleast_1d(i)]

    def grid_y(row):
        return H * (-1.0 + 2.0 * row / (NV - 1))

    def grid_x(col):
        return V[front, 0].min() + (V[front, 0].max() - V[front, 0].min()) * col / (NU - 1)

    mouth_y, eye_y = grid_y(MOUTH[0]), grid_y(EYE_L[0])
    # jaw: lower half ellipse from ear level (just below the eyes) round the chin
    phi = np.pi + np.arange(17) * np.pi / 16            # pi .. 2 pi: left (-x) -> bottom -> right (+x)
    jaw = near(np.stack([0.93 * W * np.cos(phi), (eye_y - 0.1 * H) + 0.95 * (eye_y - 0.1 * H + H) * np.sin(phi)], 1))
    # brows: 5 points over each eye, outer -> inner on the right, inner -> outer on the left
    def slit_span(slit):
        return grid_x(slit[1]), grid_x(slit[2])

    rx0, rx1 = slit_span(EYE_R)
    lx0, lx1 = slit_span(EYE_L)
    brow_y = eye_y + 0.16 * H
    t = np.linspace(0.0, 1.0, 5)
    brow_r = near(np.stack([rx0 + (rx1 - rx0) * t, brow_y + 0.05 * H * np.sin(np.pi * t)], 1))
    brow_l = near(np.stack([lx0 + (lx1 - lx0) * t, brow_y + 0.05 * H * np.sin(np.pi * t)], 1))
    # nose: bridge from between the eyes down the midline to the tip (highest midline point)
    mid = front[np.abs(V[front, 0]) < 1e-9]
    tip_y = V[mid[np.argmax(V[mid, 2])], 1]
    bridge = near(np.stack([np.zeros(4), np.linspace(eye_y, tip_y, 4)], 1))
    base_y = tip_y - 0.35 * (tip_y - mouth_y)
    nostrils = near(np.stack([np.linspace(-0.13, 0.13, 5) * W, base_y + np.array([0.3, 0.1, 0, 0.1, 0.3]) * 0.1 * H], 1))

    def loop_points(sid, slit, fracs):
        upper, lower = topo.slit_pairs[sid]
        loop = topo.loops[sid][0]
        c_lo, c_hi = loop[0], loop[len(upper) + 1]        # corner at column c0 (-x), at c1 (+x)
        n = len(upper)
        pick = np.clip(np.round(np.asarray(fracs) * (n + 1)).astype(int) - 1, 0, n - 1)
        return c_lo, c_hi, upper[pick], lower[pick]

    # eyes: 36 outer (-x), 37-38 upper, 39 inner, 40-41 lower (right eye, -x side)
    c_lo, c_hi, up, lo = loop_points(2, EYE_R, (1 / 3, 2 / 3))
    eye_r = [c_lo, up[0], up[1], c_hi, lo[1], lo[0]]
    # left eye: 42 inner (-x end), 43-44 upper, 45 outer (+x), 46-47 lower
    c_lo, c_hi, up, lo = loop_points(1, EYE_L, (1 / 3, 2 / 3))
    eye_l = [c_lo, up[0], up[1], c_hi, lo[1], lo[0]]
    # inner lips: 60 corner (-x), 61-63 upper, 64 corner (+x), 65-67 lower (from +x back)
    c_lo, c_hi, up, lo = loop_points(0, MOUTH, (0.25, 0.5, 0.75))
    inner = [c_lo, up[0], up[1], up[2], c_hi, lo[2], lo[1], lo[0]]
    # outer lips: 48 / 54 just outside the corners, 49-53 above the lip line, 55-59 below
    m0, m1 = grid_x(MOUTH[1]), grid_x(MOUTH[2])
    half = (m1 - m0) / 2
    xs = np.array([-0.7, -0.38, 0.0, 0.38, 0.7]) * half
    upper_lip = near(np.stack([xs, mouth_y + np.array([0.06, 0.085, 0.07, 0.085, 0.06]) * H], 1))
    lower_lip = near(np.stack([xs[::-1], mouth_y - np.array([0.07, 0.1, 0.11, 0.1, 0.07])[::-1] * H], 1))
    corners = near([[m0 - 0.02 * W, mouth_y], [m1 + 0.02 * W, mouth_y]])
    outer = np.concatenate([[corners[0]], upper_lip, [corners[1]], lower_lip])
    idx = np.concatenate([jaw, brow_r, brow_l, bridge, nostrils, eye_r, eye_l, outer, inner]).astype(np.int64)
    if len(idx) != 68 or len(np.unique(idx)) != 68:
        raise RuntimeError(f"built-in face landmarks: expected 68 distinct vertices, found {len(np.unique(idx))}")
    return tuple(int(i) for i in idx)


def face_landmarks() -> np.ndarray:
    """The 68 landmark vertex indices (iBUG order) of :func:`facebasis.defaults.face.default_template`, (68,) int64."""
    return np.array(_indices(), dtype=np.int64)


__all__ = ["face_landmarks"]
