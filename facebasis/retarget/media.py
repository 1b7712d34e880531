"""Video and GIF output of animated frames (PyAV for H.264 MP4, imageio/Pillow for GIF)."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from ..errors import InputError


def _even(img: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    return np.ascontiguousarray(img[: h - h % 2, : w - w % 2])


def pick_codec() -> str:
    """The best video encoder the installed PyAV wheel has: libx264, else h264, else mpeg4."""
    import av

    for name in ("libx264", "h264", "mpeg4"):
        try:
            av.codec.Codec(name, "w")
            return name
        except Exception:  # noqa: BLE001 - PyAV raises several kinds for a missing codec
            continue
    raise InputError("video output: expected PyAV with an H.264 or MPEG-4 encoder, found none")


def write_mp4(path, frames: Iterable[np.ndarray], fps: float, preset: str = "veryfast") -> int:
    """Encode RGB frames (H, W, 3) uint8 to ``path`` (MP4); returns the number of frames written.
    ``preset``: libx264's speed preset ("ultrafast" halves the encoding time of a preview)."""
    import av
    from fractions import Fraction

    codec = pick_codec()
    n = 0
    with av.open(str(path), mode="w") as container:
        stream = None
        for img in frames:
            img = _even(np.asarray(img, np.uint8))
            if stream is None:
                stream = container.add_stream(codec, rate=Fraction(fps).limit_denominator(1000))
                stream.width, stream.height = img.shape[1], img.shape[0]
                stream.pix_fmt = "yuv420p"
                if codec == "libx264":
                    stream.options = {"crf": "20", "preset": preset}
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                container.mux(packet)
            n += 1
        if stream is not None:
            for packet in stream.encode():
                container.mux(packet)
    return n


def read_video_frames(path, limit: int | None = None, what: str = "video"):
    """Yield RGB frames (H, W, 3) uint8 of a video file (PyAV).

    Raises
    ------
    InputError
        The file is missing or cannot be decoded (PyAV's error, named with the file), when opened
        or at any frame.
    """
    import av

    try:
        with av.open(str(path)) as container:
            for i, frame in enumerate(container.decode(video=0)):
                if limit is not None and i >= limit:
                    break
                yield frame.to_ndarray(format="rgb24")
    except (av.error.FFmpegError, OSError) as exc:
        raise InputError(f"{what} {path}: expected a decodable video, found {type(exc).__name__}: "
                         f"{getattr(exc, 'strerror', None) or exc}") from None


def check_video(path, what: str = "video") -> None:
    """Decode the first frame of ``path`` (an :class:`InputError` naming it if that fails): a
    video found undecodable only after the work would cost the whole run."""
    for _ in read_video_frames(path, limit=1, what=what):
        break


def side_by_side(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Two RGB images next to each other, the left one resized to the right one's height."""
    import cv2

    h = right.shape[0]
    if left.shape[0] != h:
        w = max(2, int(round(left.shape[1] * h / left.shape[0])))
        left = cv2.resize(left, (w, h), interpolation=cv2.INTER_AREA)
    return np.concatenate([left, right], axis=1)


def write_gif(path, frames, fps: float, max_seconds: float = 4.0, width: int = 256) -> int:
    """A short GIF (first ``max_seconds``) of RGB frames, reduced to ``width`` pixels; returns frames written."""
    import cv2
    from PIL import Image

    step = max(1, int(round(fps / 15.0)))               # at most ~15 frames per second
    keep = [f for f in frames[: int(max_seconds * fps) + 1: step]]
    if not keep:
        return 0
    h, w = keep[0].shape[:2]
    size = (width, max(2, int(round(h * width / w))))
    imgs = [Image.fromarray(cv2.resize(np.asarray(f, np.uint8), size, interpolation=cv2.INTER_AREA)) for f in keep]
    imgs[0].save(str(Path(path)), save_all=True, append_images=imgs[1:], duration=int(round(1000 * step / fps)),
                 loop=0, optimize=False)
    return len(imgs)


__all__ = ["pick_codec", "write_mp4", "read_video_frames", "check_video", "side_by_side", "write_gif"]
