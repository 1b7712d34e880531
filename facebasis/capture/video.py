"""Frame sources: a video file (decoded by PyAV, which ships its own FFmpeg) or a folder of images.

A :class:`FrameSource` is opened and checked up front (first frame decoded, frame rate and size
known) and then iterated as a generator of RGB ``uint8`` arrays of shape ``(height, width, 3)``,
one at a time, so memory does not grow with the length of the video.

What a container announces is not always what decodes: a cut file (a faststart mp4 cut in half)
announces its full length and stops early, sometimes with a decoding error. The frames decoded so
far are kept; :attr:`FrameSource.stats` counts them and a :class:`VideoWarning` says how many of the
announced frames were decoded. A frame of another size than the first stops the run with an
:class:`~facebasis.errors.InputError` naming the frame; for image folders every file's size is
checked up front from its header.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facebasis.errors import InputError, parameter_error

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
DEFAULT_FOLDER_FPS = 25.0


class VideoWarning(UserWarning):
    """A video decoded fewer frames than its container announced (the frames decoded are used)."""


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
    stats : dict
        Filled by :meth:`frames`: ``decoded`` (frames yielded by the last pass), ``complete`` (the
        pass reached the end of the input), ``error`` (the decoding error that ended it early, or None).
    """

    path: Path
    kind: str
    fps: float
    size: tuple[int, int]
    n_frames: int | None
    files: tuple = ()
    stats: dict = field(default_factory=dict, compare=False, repr=False)

    def frames(self, max_frames: int | None = None, warn: bool = True) -> Iterator[np.ndarray]:
        """Yield RGB frames, shape ``(height, width, 3)`` uint8, at most ``max_frames`` of them.

        Warns (:class:`VideoWarning`, unless ``warn`` is False: a caller that iterates in another
        thread warns itself from :meth:`shortfall`) when a video ends before the frame count its
        container announced; raises :class:`~facebasis.errors.InputError` on a frame of another size.
        """
        self.stats.clear()
        self.stats.update(decoded=0, complete=False, error=None)
        gen = (_video_frames(self.path, self.size, self.stats) if self.kind == "video"
               else _image_frames(self.files, self.size))
        for i, fr in enumerate(gen):
            if max_frames is not None and i >= max_frames:
                return
            self.stats["decoded"] = i + 1
            yield fr
        self.stats["complete"] = True
        msg = self.shortfall() if warn else None
        if msg:
            warnings.warn(msg, VideoWarning, stacklevel=2)

    def shortfall(self) -> str | None:
        """Warning text if the last full pass decoded fewer frames than announced, else None."""
        st = self.stats
        if self.kind != "video" or not st.get("complete"):
            return None
        n, announced = st["decoded"], self.n_frames
        if announced and n < announced:
            why = f" (decoding stopped: {st['error']})" if st.get("error") else ""
            return (f"video {self.path}: decoded {n} frames, its container announced {announced}; "
                    f"the file is probably cut short{why}; tracking the {n} decoded frames")
        if st.get("error"):
            return f"video {self.path}: decoding stopped after {n} frames ({st['error']}); tracking those"
        return None

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


def _video_frames(path: Path, size=None, stats=None) -> Iterator[np.ndarray]:
    import av

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        it = container.decode(stream)
        i = 0
        while True:
            try:
                frame = next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - PyAV's decoding errors (InvalidDataError, ...)
                if i == 0:
                    raise InputError(f"video {path}: cannot decode it ({type(exc).__name__}: {exc})") from None
                if stats is not None:
                    stats["error"] = f"{type(exc).__name__}: {exc}"
                return
            if size is not None and (frame.width, frame.height) != tuple(size):
                raise InputError(f"video {path}: expected every frame {size[0]} x {size[1]} like the first, "
                                 f"found frame {i} (counting from 0) {frame.width} x {frame.height}")
            yield frame.to_ndarray(format="rgb24")
            i += 1


def _image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from an image file's header (Pillow reads no pixels here), or None."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return int(im.size[0]), int(im.size[1])
    except Exception:  # noqa: BLE001 - unreadable: left to the decoder, which names the file
        return None


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
        raise parameter_error("fps", "a positive number", fps)
    if not p.exists():
        raise InputError(f"input {p}: expected a video file or an image folder, found nothing")
    if p.is_dir():
        files = tuple(sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES and f.is_file()))
        if not files:
            raise InputError(f"image folder {p}: expected png/jpg images, found none")
        first = _read_image(files[0])
        if first is None:
            raise InputError(f"image {files[0]}: cannot decode it as an image")
        size0 = (int(first.shape[1]), int(first.shape[0]))
        for k, f in enumerate(files[1:], 1):   # headers only: cheap, and the run never starts on a mixed folder
            sz = _image_size(f)
            if sz is not None and sz != size0:
                raise InputError(f"image {f}: expected size {size0[0]} x {size0[1]} like the first image "
                                 f"{files[0].name}, found {sz[0]} x {sz[1]} (frame {k}, counting from 0)")
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


def gray_pair(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frame as grey float32 in ``[0, 1]`` (:func:`to_gray`) and as grey uint8 (for Lucas-Kanade).

    A uint8 RGB frame's uint8 grey is OpenCV's conversion itself (rounding ``to_gray``'s result back
    to 0-255 gives exactly it), so it is not recomputed from the float image."""
    a = np.asarray(frame)
    if a.dtype == np.uint8 and a.ndim == 3:
        import cv2

        g8 = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)
        return g8.astype(np.float32) / 255.0, g8
    if a.dtype == np.uint8 and a.ndim == 2:
        return a.astype(np.float32) / 255.0, np.ascontiguousarray(a)
    gray = to_gray(a)
    return gray, np.clip(gray * 255.0 + 0.5, 0, 255).astype(np.uint8)


def read_frame(path: str | os.PathLike, index: int = 0) -> np.ndarray:
    """One frame of a video, an image folder or a single image file, RGB ``(H, W, 3)`` uint8.

    Parameters
    ----------
    path : path-like
        Video file, image folder (sorted by name) or one image (png, jpg, ...).
    index : int
        Frame number, counting from 0 (must be 0 for a single image).

    Raises
    ------
    InputError
        Missing or unreadable input, or no frame ``index`` in it.
    """
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
        raise parameter_error("index", "a frame number >= 0", repr(index))
    p = Path(path)
    if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES:
        img = _read_image(p)
        if img is None:
            raise InputError(f"image {p}: cannot decode it as an image")
        if index != 0:
            raise parameter_error("index", f"0 for the single image {p}", index)
        return img
    src = open_frames(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VideoWarning)
        for i, fr in enumerate(src.frames(index + 1)):
            if i == index:
                return fr
    raise parameter_error("index", f"a frame number below the {src.stats.get('decoded', 0)} frames decoded from {p}",
                          index)
