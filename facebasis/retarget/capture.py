"""The capture folder consumed by the retargeting commands, and the checks made before any work.

A capture folder holds ``track.npz`` with ``landmarks`` (T, L, 2) pixel coordinates (x right,
y down), ``vertices`` (T, N, 2), ``faces`` (M, 3), ``fps``, ``size`` (width, height) and ``lost``
(T, L) bool. When :mod:`facebasis.capture.trackfile` provides ``read_capture`` it is used;
otherwise the minimal reader here reads the same format. The source video, if the folder records
one (a ``video`` entry in ``track.npz``, a ``capture.json`` with ``"video"``, or a single video
file in the folder), is used for side-by-side output.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v")


@dataclass(frozen=True)
class Capture:
    """A tracked face video.

    Attributes
    ----------
    landmarks : (T, L, 2) float64 pixels, x right, y down
    vertices : (T, N, 2) float64 pixels, the tracked face mesh
    faces : (M, 3) int64 triangles of the tracked mesh
    fps : frames per second
    size : (width, height) of the video frames
    lost : (T, L) bool, landmarks the tracker lost
    video : path of the source video, or None
    source : where it was read from (for messages)
    """

    landmarks: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    fps: float
    size: tuple[int, int]
    lost: np.ndarray
    video: Path | None = None
    source: str = "capture"

    @property
    def n_frames(self) -> int:
        return int(self.landmarks.shape[0])

    @property
    def n_landmarks(self) -> int:
        return int(self.landmarks.shape[1])


def _get(obj, key):
    if isinstance(obj, dict):
        return obj.get(key)
    return getattr(obj, key, None)


def validate_capture(landmarks, vertices, faces, fps, size, lost, name: str, video=None) -> Capture:
    """Check shapes, finiteness and indices of capture arrays; returns a :class:`Capture`."""
    lm = np.asarray(landmarks, np.float64)
    if lm.ndim != 3 or lm.shape[2] != 2 or lm.shape[0] < 1 or lm.shape[1] < 3:
        raise InputError(f"{name}: expected landmarks of shape (T, L, 2) with T >= 1, L >= 3, found {lm.shape}")
    T, L = lm.shape[:2]
    V = np.asarray(vertices if vertices is not None else lm, np.float64)
    if V.ndim != 3 or V.shape[0] != T or V.shape[2] != 2:
        raise InputError(f"{name}: expected vertices of shape ({T}, N, 2), found {V.shape}")
    F = np.asarray(faces if faces is not None else np.zeros((0, 3)), np.int64)
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise InputError(f"{name}: expected faces of shape (M, 3) with M >= 1, found {F.shape}")
    if F.min() < 0 or F.max() >= V.shape[1]:
        raise InputError(f"{name}: expected face indices in [0, {V.shape[1]}), found [{F.min()}, {F.max()}]")
    lost_a = np.zeros((T, L), bool) if lost is None else np.asarray(lost, bool)
    if lost_a.shape != (T, L):
        raise InputError(f"{name}: expected lost of shape ({T}, {L}), found {lost_a.shape}")
    if not np.isfinite(lm[~lost_a]).all() or not np.isfinite(V).all():
        raise InputError(f"{name}: expected finite landmark and vertex coordinates, found NaN/inf")
    fps_f = float(np.asarray(fps).reshape(-1)[0]) if fps is not None else 30.0
    if not np.isfinite(fps_f) or fps_f <= 0:
        raise InputError(f"{name}: expected fps > 0, found {fps_f}")
    sz = np.asarray(size if size is not None else (0, 0)).reshape(-1)
    if len(sz) != 2:
        raise InputError(f"{name}: expected size (width, height), found {sz.tolist()}")
    # a lost landmark keeps its last tracked position (used only to draw; the solvers skip it)
    lm = np.where(lost_a[..., None] & ~np.isfinite(lm), 0.0, lm)
    return Capture(lm, V, F, fps_f, (int(sz[0]), int(sz[1])), lost_a, video, name)


def _find_video(folder: Path, recorded) -> Path | None:
    if recorded is not None:
        text = str(np.asarray(recorded).reshape(-1)[0]) if not isinstance(recorded, (str, os.PathLike)) else str(recorded)
        if text:
            p = Path(text)
            p = p if p.is_absolute() else folder / p
            if p.is_file():
                return p
    meta = folder / "capture.json"
    if meta.is_file():
        try:
            v = json.loads(meta.read_text()).get("video")
        except (ValueError, AttributeError):
            v = None
        if v:
            p = Path(v) if Path(v).is_absolute() else folder / v
            if p.is_file():
                return p
    vids = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES)
    return vids[0] if len(vids) == 1 else None


def _read_npz(path: Path) -> dict:
    try:
        with np.load(path, allow_pickle=False) as d:
            return {k: d[k] for k in d.files}
    except (OSError, ValueError) as exc:
        raise InputError(f"capture file {path}: expected a numpy .npz archive, found an unreadable file ({exc})") from exc


def read_capture_folder(folder) -> Capture:
    """Read and check a capture folder (``track.npz``); uses ``facebasis.capture.trackfile.read_capture``
    when that module exists.

    Raises
    ------
    InputError
        the folder or its ``track.npz`` is missing, or an array has the wrong shape.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"capture folder {folder}: expected a folder with track.npz, found no such folder")
    track = folder / "track.npz"
    if not track.is_file():
        raise InputError(f"capture folder {folder}: expected track.npz, found no such file")
    data = None
    try:
        from ..capture.trackfile import read_capture  # the capture engineer's reader
    except ImportError:
        read_capture = None
    if read_capture is not None:
        data = read_capture(folder)
    raw = _read_npz(track)
    if data is None:
        data = raw
    missing = [k for k in ("landmarks", "vertices", "faces") if _get(data, k) is None]
    if missing:
        raise InputError(f"capture file {track}: expected arrays landmarks, vertices, faces, found no {missing}")
    video = _find_video(folder, _get(data, "video") if _get(data, "video") is not None else raw.get("video"))
    return validate_capture(_get(data, "landmarks"), _get(data, "vertices"), _get(data, "faces"),
                            _get(data, "fps"), _get(data, "size"), _get(data, "lost"), str(track), video)


def write_capture_folder(folder, landmarks, vertices=None, faces=None, fps: float = 30.0, size=(512, 512),
                         lost=None) -> Path:
    """Write a ``track.npz`` capture folder (for tests and benchmarks); returns the folder.

    Without ``vertices``/``faces`` the landmarks themselves are the tracked mesh, triangulated by
    Delaunay on the first frame.
    """
    from scipy.spatial import Delaunay

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lm = np.asarray(landmarks, np.float64)
    if vertices is None:
        vertices = lm
    if faces is None:
        faces = Delaunay(np.asarray(vertices)[0]).simplices
    lost = np.zeros(lm.shape[:2], bool) if lost is None else np.asarray(lost, bool)
    np.savez(folder / "track.npz", landmarks=lm, vertices=np.asarray(vertices, np.float64),
             faces=np.asarray(faces, np.int64), fps=np.float64(fps), size=np.asarray(size, np.int64), lost=lost)
    return folder


__all__ = ["Capture", "read_capture_folder", "validate_capture", "write_capture_folder"]
