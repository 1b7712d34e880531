"""Synthetic captures with known answers: a rig animated by known weights and head motion, its
landmark vertices seen through a weak-perspective camera (the model of :mod:`.rigdrive`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.rig import Rig
from .pose import project_landmarks, rotation_from_vector


@dataclass(frozen=True)
class SyntheticCapture:
    """Known answer: weights (T, k), scale (T,), rotation (T, 3, 3), translation (T, 2); the clean
    landmarks (T, L, 2) and the noisy ones (what the solver sees)."""

    weights: np.ndarray
    scale: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    clean: np.ndarray
    landmarks: np.ndarray
    fps: float
    size: tuple[int, int]


def smooth_weight_curves(names, active, n_frames: int, fps: float = 30.0, seed: int = 0) -> np.ndarray:
    """Weights (T, k): each shape in ``active`` follows a smooth raised bump train in [0, 1] with a
    seeded period (1.5-4 s) and phase; every other shape stays 0."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / fps
    X = np.zeros((n_frames, len(names)))
    for name in active:
        i = list(names).index(name)
        period = rng.uniform(1.5, 4.0)
        phase = rng.uniform(0, 2 * np.pi)
        peak = rng.uniform(0.6, 1.0)
        X[:, i] = peak * np.clip(np.sin(2 * np.pi * t / period + phase), 0.0, 1.0) ** 2
    return X


def head_motion(n_frames: int, fps: float = 30.0, scale: float = 20.0, centre=(256.0, 256.0),
                amplitude_deg: float = 10.0, seed: int = 0):
    """Smooth head motion: scale (T,), rotation (T, 3, 3) (yaw/pitch/roll up to ``amplitude_deg``),
    translation (T, 2) around ``centre`` (pixels)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / fps
    f = rng.uniform(0.1, 0.4, 6)
    ph = rng.uniform(0, 2 * np.pi, 6)
    a = np.deg2rad(amplitude_deg)
    rv = np.stack([a * 0.6 * np.sin(2 * np.pi * f[0] * t + ph[0]), a * np.sin(2 * np.pi * f[1] * t + ph[1]),
                   a * 0.4 * np.sin(2 * np.pi * f[2] * t + ph[2])], 1)
    R = np.stack([rotation_from_vector(v) for v in rv])
    s = scale * (1.0 + 0.05 * np.sin(2 * np.pi * f[3] * t + ph[3]))
    tr = np.asarray(centre, float) + np.stack([8 * np.sin(2 * np.pi * f[4] * t + ph[4]),
                                               5 * np.sin(2 * np.pi * f[5] * t + ph[5])], 1)
    return s, R, tr


def synthetic_capture(rig: Rig, indices, weights, noise_px: float = 0.0, fps: float = 30.0, scale: float = 20.0,
                      size=(512, 512), amplitude_deg: float = 10.0, seed: int = 0) -> SyntheticCapture:
    """Project the rig's landmark vertices, animated by ``weights`` (T, k), through a moving
    weak-perspective camera and add Gaussian pixel noise (seeded)."""
    W = np.asarray(weights, np.float64)
    idx = np.asarray(indices, np.int64)
    s, R, t = head_motion(len(W), fps, scale, (size[0] / 2, size[1] / 2), amplitude_deg, seed)
    Q = rig.neutral[idx] + np.tensordot(W, rig.deltas[:, idx], axes=(1, 0))
    clean = project_landmarks(Q, s, R, t)
    noisy = clean + noise_px * np.random.default_rng(seed + 1).standard_normal(clean.shape)
    return SyntheticCapture(W, s, R, t, clean, noisy, float(fps), (int(size[0]), int(size[1])))


__all__ = ["SyntheticCapture", "smooth_weight_curves", "head_motion", "synthetic_capture"]


def capture_from_landmarks(landmarks, fps: float = 30.0, size=(512, 512), lost=None):
    """A :class:`facebasis.capture.trackfile.Capture` whose tracked mesh is the landmarks themselves,
    triangulated by Delaunay on the first frame (for synthetic captures: write it with
    :func:`facebasis.capture.trackfile.write_capture`)."""
    from scipy.spatial import Delaunay

    from ..capture.trackfile import Capture

    lm = np.asarray(landmarks, np.float64)
    lost = np.zeros(lm.shape[:2], bool) if lost is None else np.asarray(lost, bool)
    return Capture(lm, lm.copy(), Delaunay(lm[0]).simplices.astype(np.int64), float(fps),
                   (int(size[0]), int(size[1])), lost)
