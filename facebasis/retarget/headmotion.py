"""Head motion apart from expression: a per-frame 2D similarity fitted on stable landmarks.

A monocular capture's landmarks move for two reasons: the head moves (it comes closer, turns in
the image plane, shifts) and the face changes expression. The paper's eq. 12 (``d_target = s
d_capture``) drives the target by both, so a cartoon's face shrinks inside its unchanged head and
hair when the person leaves the camera. Here the head's in-plane motion is a similarity per frame

    p_t(l) ~ a_t p_0(l) + b_t          (complex numbers: a_t = rho_t e^{i theta_t}, b_t a translation)

fitted by least squares (Procrustes / Umeyama with scale, closed form in complex arithmetic) on
landmarks that an expression hardly moves: for the 68-point iBUG set the nose (27-35) and the
eye corners (36, 39, 42, 45); for any other set all landmarks. ``(p_t - b_t) / a_t`` is the frame
with the head brought back to frame 0: what is left is the expression (and out-of-plane head
turns, which a single view cannot tell from expression).

Everything is vectorised over frames; frame 0 against itself gives ``a = 1, b = 0`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, parse_mode

#: 68-point iBUG landmarks an expression hardly moves: nose bridge and base, eye corners
STABLE_68 = np.r_[27:36, 36, 39, 42, 45]


def stable_landmarks(n_landmarks: int) -> np.ndarray:
    """Indices of the landmarks the head similarity is fitted on: :data:`STABLE_68` for 68 points,
    else all of them."""
    return STABLE_68.copy() if n_landmarks == 68 else np.arange(n_landmarks)


def _complex(p: np.ndarray) -> np.ndarray:
    return p[..., 0] + 1j * p[..., 1]


@dataclass(frozen=True)
class HeadMotion:
    """Per-frame similarities taking frame 0's landmarks to frame t's: ``p_t ~ a_t p_0 + b_t``.

    Attributes
    ----------
    a : (T,) complex, ``rho_t exp(i theta_t)`` (scale and rotation; y points down in pixels, so a
        positive theta turns clockwise on screen)
    b : (T,) complex translation (pixels)
    """

    a: np.ndarray
    b: np.ndarray

    @property
    def scale(self) -> np.ndarray:
        """(T,) rho_t."""
        return np.abs(self.a)

    @property
    def angle(self) -> np.ndarray:
        """(T,) theta_t in radians."""
        return np.angle(self.a)

    def remove(self, points) -> np.ndarray:
        """Points (T, k, 2) with the head brought back to frame 0: ``(p_t - b_t) / a_t``."""
        P = np.asarray(points, np.float64)
        z = (_complex(P) - self.b[:, None]) / self.a[:, None]
        return np.stack([z.real, z.imag], -1)

    def apply(self, points, t: int | None = None) -> np.ndarray:
        """``a_t p + b_t`` for points (T, k, 2) (all frames) or (k, 2) with a frame index ``t``."""
        P = np.asarray(points, np.float64)
        if t is None:
            z = self.a[:, None] * _complex(P) + self.b[:, None]
        else:
            z = self.a[t] * _complex(P) + self.b[t]
        return np.stack([z.real, z.imag], -1)

    def conjugated(self, centre0, centre_target, ratio: float) -> "HeadMotion":
        """The same head motion expressed on a target placed like the capture up to scale.

        A point at ``centre_target + ratio (p - centre0)`` on the target corresponds to the capture
        point p. Returns the similarities ``y -> A_t y + B_t`` moving the target as the capture's
        head moves: same rotation and scale, translation of ``centre0`` scaled by ``ratio``.
        """
        c0 = complex(*np.asarray(centre0, np.float64))
        ct = complex(*np.asarray(centre_target, np.float64))
        moved = self.a * c0 + self.b                       # where the capture centre went
        return HeadMotion(self.a.copy(), ct + ratio * (moved - c0) - self.a * ct)

    def affine(self, t: int) -> np.ndarray:
        """(2, 3) matrix of frame t's similarity for ``cv2.warpAffine``."""
        a, b = self.a[t], self.b[t]
        return np.array([[a.real, -a.imag, b.real], [a.imag, a.real, b.imag]])


def fit_head_motion(landmarks, reference=None, stable=None) -> HeadMotion:
    """Least-squares similarity (Procrustes with scale) from ``reference`` to every frame.

    Parameters
    ----------
    landmarks : (T, L, 2) captured landmarks (pixels)
    reference : (L, 2) the pose the head is measured against (default: frame 0)
    stable : indices of the landmarks to fit on (default :func:`stable_landmarks`)

    Returns
    -------
    HeadMotion with ``landmarks[t, stable] ~ a_t reference[stable] + b_t``.
    """
    P = np.asarray(landmarks, np.float64)
    if P.ndim != 3 or P.shape[2] != 2 or P.shape[0] < 1:
        raise InputError(f"head motion: expected landmarks of shape (T, L, 2), found {P.shape}")
    ref = P[0] if reference is None else np.asarray(reference, np.float64)
    if ref.shape != P.shape[1:]:
        raise InputError(f"head motion: expected a reference of shape {P.shape[1:]}, found {ref.shape}")
    idx = stable_landmarks(P.shape[1]) if stable is None else np.asarray(stable, np.int64)
    z0 = _complex(ref[idx])
    zt = _complex(P[:, idx])
    c0 = z0.mean()
    ct = zt.mean(1)
    u = z0 - c0
    den = float(np.sum(np.abs(u) ** 2))
    if not den > 0:
        raise InputError("head motion: the stable landmarks of the reference coincide")
    a = np.sum(np.conj(u)[None] * (zt - ct[:, None]), axis=1) / den
    a = np.where(np.abs(a) > 1e-9, a, 1.0 + 0j)        # a collapsed frame: no head motion rather than inf
    b = ct - a * c0
    if reference is None:
        a[0], b[0] = 1.0 + 0j, 0.0 + 0j                  # exact, not up to rounding
    return HeadMotion(a, b)


#: values of ``--head``: "still" (the target keeps its size and place and shows the expression only)
#: or "follow" (the whole target also moves, turns and scales with the head)
HEAD_MODES = ("still", "follow")


def parse_head_mode(value) -> str:
    """Check a ``--head`` value (None: "still")."""
    return parse_mode("head", value, HEAD_MODES, "still")


__all__ = ["HeadMotion", "fit_head_motion", "stable_landmarks", "STABLE_68", "HEAD_MODES", "parse_head_mode"]
