"""Frame sources: a video file (decoded by PyAV, which ships its own FFmpeg) or a folder of images.

A :class:`FrameSource` is opened and checked up front (first frame decoded, frame rate and size
known) and then iterated as a generator of RGB ``uint8`` arrays of shape ``(height, width, 3)``,
one at a time, so memory does not grow with the length of the video.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facebasis.errors import InputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
DEFAULT_FOLDER_FPS = 25.0


@dataclass(frozen=True)
class FrameSource:
    """An opened, validated frame source.

    Attributes
    ----------
    path : Path
        Video file or image folder.
    kind : str
        ``"video"`` or ``"images"``.
    fps : float
        Frames per second (container rate for videos; the given or default rate for folders).
    size : tuple of int
        ``(width, height)`` in pixels.
    n_frames : int or None
        Frame count if known up front (always for folders; from the container for videos).
    files : tuple of Path
        The sorted image files (folders only).
    """

    path: Path
    kind: str
    fps: float
    size: tuple[int, int]
    n_frames: int | None
    files: tuple = ()

    def frames(self, max_frames: int | None = None) -> Iterator[np.ndarray]:
        """Yield RGB frames, shape ``(height, width, 3)`` uint8, at most ``max_frames`` of them."""
        gen = _video_frames(self.path) if self.kind == "video" else _image_frames(self.files, self.size)
        for i, fr in enumerate(gen):
            if max_frames is not None and i >= max_frames:
                break
            yield fr

    def __iter__(self):
        return self.frames()


def _read_image(path: Path) -> np.ndarray | None:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        return None
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _image_frames(files, size) -> Iterator[np.ndarray]:
    for f in files:
        img = _read_image(f)
        if img is None:
            raise InputError(f"image {f}: cannot decode it as an image")
        if (img.shape[1], img.shape[0]) != tuple(size):
            raise InputError(f"image {f}: expected size {size[0]} x {size[1]} like the first image, "
                             f"found {img.shape[1]} x {img.shape[0]}")
        yield img


def _video_frames(path: Path) -> Iterator[np.ndarray]:
    import av

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        for frame in container.decode(stream):
            yield frame.to_ndarray(format="rgb24")


def open_frames(path: str | os.PathLike, fps: float | None = None) -> FrameSource:
    """Open a video file or an image folder and check it can be read.

    Parameters
    ----------
    path : path-like
        A video file (mp4, avi, mkv, ... anything FFmpeg reads) or a folder of png/jpg images
        (sorted by file name).
    fps : float, optional
        Frame rate for an image folder (default 25). For a video it overrides the container rate.

    Returns
    -------
    FrameSource

    Raises
    ------
    InputError
        Path missing, folder without images, video unreadable or without a decodable frame,
        ``fps`` not positive.
    """
    p = Path(path)
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise InputError(f"--fps: expected a positive number, found {fps}")
    if not p.exists():
        raise InputError(f"input {p}: expected a video file or an image folder, found nothing")
    if p.is_dir():
        files = tuple(sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES and f.is_file()))
        if not files:
            raise InputError(f"image folder {p}: expected png/jpg images, found none")
        first = _read_image(files[0])
        if first is None:
            raise InputError(f"image {files[0]}: cannot decode it as an image")
        return FrameSource(p, "images", float(fps or DEFAULT_FOLDER_FPS),
                           (int(first.shape[1]), int(first.shape[0])), len(files), files)
    import av

    try:
        with av.open(str(p)) as container:
            if not container.streams.video:
                raise InputError(f"video {p}: expected a video stream, found none")
            stream = container.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate or stream.base_rate
            n = int(stream.frames) if stream.frames else None
            first = next(iter(container.decode(stream)), None)
            if first is None:
                raise InputError(f"video {p}: expected at least one frame, found none")
            size = (int(first.width), int(first.height))
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - PyAV raises many error types (InvalidDataError, FFmpegError, ...)
        raise InputError(f"video {p}: cannot decode it ({type(exc).__name__}: {exc})") from None
    f = float(fps) if fps else (float(rate) if rate else DEFAULT_FOLDER_FPS)
    return FrameSource(p, "video", f, size, n)


def to_gray(frame: np.ndarray) -> np.ndarray:
    """Grey image in ``[0, 1]``, float32, shape ``(height, width)``.

    Accepts RGB or grey frames, uint8 (0-255) or float (0-1).
    """
    import cv2

    a = np.asarray(frame)
    if a.dtype == np.uint8:
        if a.ndim == 3:
            a = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)
        return a.astype(np.float32) / 255.0
    a = a.astype(np.float32)
    if a.ndim == 3:
        a = a[..., :3] @ np.array([0.299, 0.587, 0.114], np.float32)
    return a
