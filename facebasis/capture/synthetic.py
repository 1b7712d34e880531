"""Generated test sequences with exact ground truth (no data files).

A neutral face image with known landmarks is animated by a known smooth deformation
``phi_t = S_t o (id + sum_k a_k(t) D_k)``: Gaussian-bump displacement fields ``D_k`` placed at
landmarks (mouth opening, smile, blink, brow raise) with smooth weights ``a_k(t)``, followed by a
small head motion ``S_t`` (rotation, scale, translation). Frame ``t`` is the neutral image sampled
at ``phi_t^{-1}`` (inverted by fixed-point iteration on a coarse grid, then interpolated); the true
position of any neutral point ``q`` in frame ``t`` is ``phi_t(q)``, evaluated exactly. Frame 0 is
the neutral image itself (``phi_0 = id``).

Two neutral faces are available:

* :func:`cartoon_face`: a drawn face (skin noise, eyes, brows, nose, lips) at any size with exact
  iBUG-68 landmarks on its features;
* :func:`astronaut_face`: ``skimage.data.astronaut()`` (public domain, ships with scikit-image)
  with 68 landmarks placed once by a detector and stored here as numbers (approximate placement is
  fine: ground truth is the warp of whatever first-frame points are used).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .landmarks import face_width

#: 68 approximate landmarks of skimage.data.astronaut() (pixels, 512 x 512 image).
ASTRONAUT_LANDMARKS = np.array([
    [179, 104], [180, 116], [181, 127], [182, 139], [185, 150], [191, 160], [200, 168], [209, 176],
    [220, 178], [232, 177], [243, 171], [253, 163], [260, 154], [265, 143], [268, 131], [270, 120],
    [272, 108], [186, 94], [192, 88], [200, 87], [208, 89], [216, 92], [236, 93], [244, 91], [252, 91],
    [260, 92], [265, 99], [226, 102], [225, 111], [225, 119], [225, 127], [214, 131], [219, 133],
    [224, 134], [229, 133], [234, 132], [195, 101], [200, 98], [207, 98], [212, 104], [206, 104],
    [199, 104], [237, 106], [243, 100], [250, 100], [255, 105], [250, 107], [244, 107], [201, 139],
    [209, 139], [218, 139], [224, 141], [230, 140], [238, 140], [246, 141], [238, 151], [229, 155],
    [222, 156], [216, 155], [208, 150], [204, 141], [218, 143], [223, 144], [230, 143], [243, 142],
    [229, 150], [223, 151], [217, 150]], float)


def astronaut_face() -> tuple[np.ndarray, np.ndarray]:
    """``skimage.data.astronaut()`` (512 x 512 RGB uint8) and its 68 landmarks ``(68, 2)``."""
    from skimage import data

    return data.astronaut(), ASTRONAUT_LANDMARKS.copy()


def cartoon_landmarks(size: tuple[int, int] = (192, 192)) -> np.ndarray:
    """The 68 iBUG-ordered landmarks of :func:`cartoon_face`, shape ``(68, 2)``."""
    W, H = size
    cx, cy = W / 2, H * 0.44
    a, b = 0.32 * W, 0.40 * H
    th = np.pi - np.arange(17) * np.pi / 16
    jaw = np.stack([cx + a * np.cos(th), cy + b * np.sin(th)], 1)
    u = np.linspace(0, 1, 5)
    brow_l = np.stack([cx - 0.26 * W + 0.20 * W * u, cy - 0.12 * H - 0.04 * H * np.sin(np.pi * (u * 0.8 + 0.1))], 1)
    brow_r = np.stack([2 * cx - brow_l[::-1, 0], brow_l[::-1, 1]], 1)
    nose_bridge = np.stack([np.full(4, cx), cy - 0.02 * H + np.arange(4) * 0.06 * H], 1)
    nb = np.linspace(-1, 1, 5)
    nose_base = np.stack([cx + 0.06 * W * nb, cy + 0.21 * H + 0.015 * H * (1 - nb ** 2)], 1)
    ex, ey, ew, eh = 0.15 * W, cy - 0.03 * H, 0.065 * W, 0.028 * H

    def eye(c):
        ang = np.array([np.pi, 2 * np.pi / 3, np.pi / 3, 0, -np.pi / 3, -2 * np.pi / 3])
        return np.stack([c + ew * np.cos(ang), ey - eh * np.sin(ang)], 1)

    eye_l = eye(cx - ex)
    eye_r = eye(cx + ex)[[3, 2, 1, 0, 5, 4]]  # 42 inner corner, 43-44 upper, 45 outer, 46-47 lower
    my, mw = cy + 0.31 * H, 0.12 * W
    ang = np.pi - np.arange(12) * (2 * np.pi / 12)
    outer = np.stack([cx + mw * np.cos(ang), my - 0.045 * H * np.sin(ang)], 1)
    outer[1:6, 1] -= 0.004 * H * np.array([0, 1, -1, 1, 0])  # cupid's bow
    iang = np.array([np.pi, 3 * np.pi / 4, np.pi / 2, np.pi / 4, 0, -np.pi / 4, -np.pi / 2, -3 * np.pi / 4])
    inner = np.stack([cx + 0.8 * mw * np.cos(iang), my - 0.012 * H * np.sin(iang)], 1)
    return np.concatenate([jaw, brow_l, brow_r, nose_bridge, nose_base, eye_l, eye_r, outer, inner])


def cartoon_face(size: tuple[int, int] = (192, 192), seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A drawn, textured cartoon face and its exact 68 landmarks.

    Parameters
    ----------
    size : tuple of int
        ``(width, height)``.
    seed : int
        Seed of the skin and background noise.

    Returns
    -------
    image : ndarray, shape (H, W, 3) uint8 RGB
    landmarks : ndarray, shape (68, 2)
    """
    import cv2

    W, H = size
    lm = cartoon_landmarks(size)
    rng = np.random.default_rng(seed)
    s = W / 192.0
    bg = cv2.GaussianBlur(rng.random((H, W)).astype(np.float32), (0, 0), 3 * s)
    bg = (bg - bg.mean()) / (bg.std() + 1e-6)
    img = np.empty((H, W, 3), np.float32)
    img[:] = np.array([70, 90, 120], np.float32) + 25 * bg[..., None]
    sh = 4
    P = lambda pts: np.round(np.asarray(pts) * (1 << sh)).astype(np.int32)
    # face: jaw arc closed over the forehead
    cx, cy = W / 2, H * 0.44
    top = np.stack([cx + 0.32 * W * np.cos(np.linspace(0, np.pi, 24)),
                    cy - 0.36 * H * np.sin(np.linspace(0, np.pi, 24))], 1)
    face_poly = np.concatenate([lm[:17], top[1:-1]])
    mask = np.zeros((H, W), np.uint8)
    cv2.fillPoly(mask, [P(face_poly)], 255, cv2.LINE_AA, sh)
    skin_noise = cv2.GaussianBlur(rng.standard_normal((H, W)).astype(np.float32), (0, 0), 1.2 * s)
    skin_noise2 = cv2.GaussianBlur(rng.standard_normal((H, W)).astype(np.float32), (0, 0), 4 * s)
    skin = np.array([225, 180, 150], np.float32) * (1 + 0.10 * skin_noise[..., None] / skin_noise.std()
                                                   + 0.08 * skin_noise2[..., None] / skin_noise2.std())
    m = (mask.astype(np.float32) / 255)[..., None]
    img = img * (1 - m) + skin * m
    img = np.clip(img, 0, 255).astype(np.uint8)
    t = max(1, round(2 * s))
    # brows
    cv2.polylines(img, [P(lm[17:22]), P(lm[22:27])], False, (70, 45, 30), 2 * t + 1, cv2.LINE_AA, sh)
    # eyes: white, iris, outline
    for e in (lm[36:42], lm[42:48]):
        cv2.fillPoly(img, [P(e)], (245, 245, 240), cv2.LINE_AA, sh)
        c = e.mean(0)
        cv2.circle(img, tuple(P(c)), int(0.022 * W * (1 << sh)), (60, 100, 60), -1, cv2.LINE_AA, sh)
        cv2.circle(img, tuple(P(c)), int(0.010 * W * (1 << sh)), (15, 15, 15), -1, cv2.LINE_AA, sh)
        cv2.polylines(img, [P(e)], True, (40, 30, 25), t, cv2.LINE_AA, sh)
    # nose
    cv2.polylines(img, [P(lm[27:31] + [0.01 * W, 0])], False, (170, 120, 100), t, cv2.LINE_AA, sh)
    cv2.polylines(img, [P(lm[31:36])], False, (120, 70, 60), t, cv2.LINE_AA, sh)
    # mouth: lips and the dark opening
    cv2.fillPoly(img, [P(lm[48:60])], (190, 70, 80), cv2.LINE_AA, sh)
    cv2.fillPoly(img, [P(lm[60:68])], (60, 20, 25), cv2.LINE_AA, sh)
    cv2.polylines(img, [P(lm[48:60])], True, (120, 40, 50), t, cv2.LINE_AA, sh)
    return img, lm


@dataclass(frozen=True)
class Motion:
    """Amplitudes of the animation (fractions of the face width unless stated).

    Attributes
    ----------
    mouth_open, smile, blink, brow_raise : float
        Peak displacement of each expression field.
    rotation_deg : float
        Peak in-plane head rotation (degrees).
    scale : float
        Peak relative scale change.
    translation : float
        Peak head translation.
    periods : tuple of float
        Periods (frames) of mouth, smile, blink, brow and head motion.
    lid_close : float
        Fraction (0-1) of the eye opening the upper lids close at the peak of each blink (same timing
        as ``blink``) by *covering* the eye, as a real lid does: the part of the eye above the lowered
        lid line is painted with the surrounding skin (the eye inpainted away) and the lid line drawn
        at its new place, so the eye's appearance changes instead of its texture being warped
        (:meth:`WarpAnimation.lid_shift` gives the lid landmarks' motion). 0: off.
    """

    mouth_open: float = 0.10
    smile: float = 0.04
    blink: float = 0.025
    brow_raise: float = 0.05
    rotation_deg: float = 4.0
    scale: float = 0.04
    translation: float = 0.06
    periods: tuple = (40.0, 70.0, 25.0, 55.0, 90.0)
    lid_close: float = 0.0


class WarpAnimation:
    """Known smooth deformation of a neutral face image over time.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) uint8
        Neutral frame (frame 0).
    landmarks : ndarray, shape (68, 2)
        Neutral landmarks (iBUG order, used to place the expression fields).
    motion : Motion
    """

    def __init__(self, image: np.ndarray, landmarks: np.ndarray, motion: Motion = Motion()):
        self.image = np.ascontiguousarray(image)
        self.lm0 = np.asarray(landmarks, float)
        self.motion = motion
        lm = self.lm0
        fw = face_width(lm)
        self.fw = fw
        self.center = lm.mean(0)
        eye_h = np.linalg.norm(lm[[37, 38, 43, 44]] - lm[[41, 40, 47, 46]], axis=1).mean()
        # Gaussian bumps: centre (K, 2), direction (K, 2) [fractions of fw], width (K,), expression id (K,)
        c = [lm[57], lm[8], lm[51], lm[48], lm[54], lm[[37, 38]].mean(0), lm[[43, 44]].mean(0), lm[19], lm[24]]
        d = [[0, 1.0], [0, 0.6], [0, -0.25], [-0.6, -0.5], [0.6, -0.5], [0, 1], [0, 1], [0, -1], [0, -1]]
        sig = [0.16, 0.25, 0.08, 0.09, 0.09, 0.06, 0.06, 0.14, 0.14]
        kind = [0, 0, 0, 1, 1, 2, 2, 3, 3]
        self.c = np.array(c)
        self.dirs = np.array(d, float)
        self.sig = np.array(sig) * fw
        self.kind = np.array(kind)
        amp = np.array([motion.mouth_open, motion.smile, motion.blink, motion.brow_raise]) * fw
        amp[2] = min(motion.blink * fw, 0.8 * eye_h)
        self.amp = amp
        self._lid_skin = _eyes_inpainted(self.image, lm) if motion.lid_close > 0 else None

    def lid_shift(self, t: float) -> np.ndarray:
        """Displacement ``(68, 2)`` of the neutral landmarks by the covering lids at frame ``t`` (before the
        warp): upper-lid points 37, 38, 43, 44 moved towards their lower partners 41, 40, 47, 46 by
        ``lid_close`` times the blink weight; zero elsewhere."""
        d = np.zeros((len(self.lm0), 2))
        if self.motion.lid_close > 0 and len(self.lm0) == 68:
            w = self.params(t)[0][2] * self.motion.lid_close
            d[_UPPER] = w * (self.lm0[_LOWER] - self.lm0[_UPPER])
        return d

    def _lidded(self, t: float) -> np.ndarray:
        """The neutral image with the lids of frame ``t`` drawn over the eyes."""
        import cv2

        if self._lid_skin is None or not np.any(self.lid_shift(t)):
            return self.image
        lm, new = self.lm0, self.lm0 + self.lid_shift(t)
        img, mask = self.image.copy(), np.zeros(self.image.shape[:2], np.uint8)
        P = lambda pts: np.round(np.asarray(pts) * 16).astype(np.int32)
        t_px = max(1, round(face_width(lm) / 61.0))   # the drawn outline's width (cartoon_face's)
        lift = np.array([[0, 0], [0, 0.5 * t_px + 0.5], [0, 0.5 * t_px + 0.5], [0, 0]])
        for a in (36, 42):     # the old lid line (its outline too) down to the lowered lid, corners kept
            cover = np.concatenate([lm[a:a + 4] - lift, new[[a + 3, a + 2, a + 1, a]]])
            cv2.fillPoly(mask, [P(cover)], 255, cv2.LINE_AA, 4)
        m = (mask.astype(np.float32) / 255)[..., None]
        img = np.clip(img * (1 - m) + self._lid_skin * m, 0, 255).astype(np.uint8)
        for a in (36, 42):
            cv2.polylines(img, [P(new[a:a + 4])], False, (40, 30, 25), t_px, cv2.LINE_AA, 4)
        return img

    def params(self, t: float):
        """Expression weights ``(4,)`` in [0, 1] and head motion ``(angle rad, scale, tx, ty)`` at frame ``t``."""
        m = self.motion
        P = np.asarray(m.periods, float)
        w = 0.5 * (1 - np.cos(2 * np.pi * t / P[:4]))
        ph = 2 * np.pi * t / P[4]
        head = (np.deg2rad(m.rotation_deg) * np.sin(ph), 1 + m.scale * np.sin(0.7 * ph),
                m.translation * self.fw * np.sin(1.3 * ph), 0.6 * m.translation * self.fw * (1 - np.cos(ph)))
        return w, head

    def _field(self, q: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Expression displacement ``sum_k a_k D_k(q)`` at points ``(P, 2)``."""
        d2 = ((q[:, None, :] - self.c[None]) ** 2).sum(-1)  # (P, K)
        g = np.exp(-d2 / (2 * self.sig ** 2)) * (w[self.kind] * self.amp[self.kind])[None]
        return g @ self.dirs

    def _head(self, head):
        ang, s, tx, ty = head
        R = s * np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        return R, self.center + np.array([tx, ty])

    def points(self, t: float, q: np.ndarray) -> np.ndarray:
        """True positions in frame ``t`` of neutral points ``q (P, 2)`` -> ``(P, 2)``: ``phi_t(q)``."""
        q = np.asarray(q, float)
        w, head = self.params(t)
        R, c = self._head(head)
        return (q + self._field(q, w) - self.center) @ R.T + c

    def frame(self, t: float, step: int = 8) -> np.ndarray:
        """Frame ``t``, RGB uint8 of the neutral image's size."""
        import cv2

        H, W = self.image.shape[:2]
        if t == 0:
            return self.image.copy()
        w, head = self.params(t)
        R, c = self._head(head)
        gx, gy = np.meshgrid(np.arange(0, W + step, step, dtype=float), np.arange(0, H + step, step, dtype=float))
        p = np.stack([gx.ravel(), gy.ravel()], 1)
        u = (p - c) @ np.linalg.inv(R).T + self.center  # undo head motion
        q = u.copy()
        for _ in range(15):  # fixed point q = u - D(q) (contraction: |grad D| < 1)
            q = u - self._field(q, w)
        mx = q[:, 0].reshape(gx.shape).astype(np.float32)
        my = q[:, 1].reshape(gx.shape).astype(np.float32)
        big_x = cv2.resize(mx, (gx.shape[1] * step, gx.shape[0] * step), interpolation=cv2.INTER_LINEAR)
        big_y = cv2.resize(my, (gx.shape[1] * step, gx.shape[0] * step), interpolation=cv2.INTER_LINEAR)
        # cv2.resize maps pixel centres; shift so that coarse node k lands on pixel k*step exactly
        off = (step - 1) / 2.0
        xs = np.clip(np.arange(W) + off, 0, big_x.shape[1] - 1).astype(np.float32)
        ys = np.clip(np.arange(H) + off, 0, big_x.shape[0] - 1).astype(np.float32)
        mxx, myy = np.meshgrid(xs, ys)
        fx = cv2.remap(big_x, mxx, myy, cv2.INTER_LINEAR)
        fy = cv2.remap(big_y, mxx, myy, cv2.INTER_LINEAR)
        return cv2.remap(self._lidded(t), fx, fy, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)


#: iBUG-68 upper-lid points and the lower-lid points below them
_UPPER, _LOWER = np.array([37, 38, 43, 44]), np.array([41, 40, 47, 46])


def _eyes_inpainted(image: np.ndarray, lm: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with both eyes (68 landmarks) inpainted from the skin around them
    (OpenCV's Telea inpainting): the skin of a closed lid, float32."""
    import cv2

    mask = np.zeros(image.shape[:2], np.uint8)
    for a in (36, 42):
        cv2.fillPoly(mask, [np.round(lm[a:a + 6]).astype(np.int32)], 255)
    r = max(2, round(face_width(lm) / 60))
    mask = cv2.dilate(mask, np.ones((2 * r + 1, 2 * r + 1), np.uint8))
    return cv2.inpaint(np.ascontiguousarray(image), mask, 2 * r, cv2.INPAINT_TELEA).astype(np.float32)


@dataclass(frozen=True)
class SyntheticSequence:
    """A generated sequence with ground truth.

    Attributes
    ----------
    frames : ndarray, shape (T, H, W, 3) uint8
    landmarks : ndarray, shape (T, 68, 2)
        True landmark positions.
    animation : WarpAnimation
        Use ``animation.points(t, V0)`` for the true trajectory of any first-frame point (e.g. mesh
        vertices).
    fps : float
    """

    frames: np.ndarray
    landmarks: np.ndarray
    animation: WarpAnimation
    fps: float = 25.0

    def truth(self, points0: np.ndarray) -> np.ndarray:
        """True trajectories ``(T, P, 2)`` of first-frame points ``(P, 2)``."""
        return np.stack([self.animation.points(t, points0) for t in range(len(self.frames))])


def synthetic_sequence(n_frames: int = 40, size: tuple[int, int] = (192, 192), face: str = "cartoon",
                       motion: Motion = Motion(), seed: int = 0) -> SyntheticSequence:
    """Render a synthetic face sequence with exact landmark trajectories.

    Parameters
    ----------
    n_frames : int
        ``T``.
    size : tuple of int
        ``(width, height)`` of the cartoon face (ignored for ``face="astronaut"``, 512 x 512).
    face : {"cartoon", "astronaut"}
    motion : Motion
    seed : int
        Noise seed of the cartoon texture.

    Returns
    -------
    SyntheticSequence
    """
    if face == "cartoon":
        img, lm = cartoon_face(size, seed)
    elif face == "astronaut":
        img, lm = astronaut_face()
    else:
        from facebasis.errors import InputError

        raise InputError(f"face: expected 'cartoon' or 'astronaut', found {face!r}")
    anim = WarpAnimation(img, lm, motion)
    frames = np.stack([anim.frame(t) for t in range(n_frames)])
    lms = np.stack([anim.points(t, lm + anim.lid_shift(t)) for t in range(n_frames)])
    return SyntheticSequence(frames, lms, anim)
