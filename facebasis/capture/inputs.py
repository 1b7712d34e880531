"""What :func:`facebasis.capture.tracker.capture` checks before any work, and what it returns."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facebasis.errors import InputError, parameter_error

from .landmarks import read_landmarks, validate_landmarks
from .trackfile import Capture
from .video import FrameSource, open_frames


@dataclass(frozen=True)
class CaptureResult:
    """Result of :func:`capture`.

    Attributes
    ----------
    capture : Capture
        The tracked sequence (landmarks (T, L, 2), vertices (T, N, 2), faces, fps, size, lost).
    out : Path or None
        Output folder, if one was written.
    seconds : dict
        Wall time by stage: ``decode``, ``landmarks``, ``mesh``, ``detect``, ``output``, each timed in
        the thread that runs it (with :func:`capture`'s background threads, decoding, a MediaPipe
        detector and the overlay overlap the tracking: the sum exceeds the run's wall time).
    """

    capture: Capture
    out: Path | None
    seconds: dict

    @property
    def landmarks(self) -> np.ndarray:
        return self.capture.landmarks

    @property
    def vertices(self) -> np.ndarray:
        return self.capture.vertices

    @property
    def lost(self) -> np.ndarray:
        return self.capture.lost


def check_capture_args(video, landmarks, detector, out, max_frames, fps):
    """Validate the arguments of :func:`capture` before any work; returns (source, landmarks, detector)."""
    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, (int, np.integer))
                                   or max_frames < 1):
        raise parameter_error("max_frames", "a positive integer", max_frames)
    if (landmarks is None) == (detector is None):
        raise InputError(what="landmarks", expected="exactly one of {landmarks} FILE or {detector} NAME",
                         found="both" if landmarks is not None else "neither",
                         params={"landmarks": "landmarks", "detector": "detector"})
    if out is not None:
        o = Path(out)
        if o.exists() and not o.is_dir():
            raise InputError(f"output folder {o}: expected a folder or a new path, found a file")
    src = video if isinstance(video, FrameSource) else open_frames(video, fps)
    det = None
    if detector is not None:
        if isinstance(detector, str):
            from .detect import get_detector

            det = get_detector(detector)
        else:
            det = detector
        lm = None
    elif isinstance(landmarks, (str, os.PathLike)):
        lm = validate_landmarks(read_landmarks(landmarks), f"landmark file {landmarks}", size=src.size)
    else:
        lm = validate_landmarks(landmarks, "landmarks", size=src.size)
    return src, lm, det
