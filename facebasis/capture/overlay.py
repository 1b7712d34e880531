"""Overlay video: the input frames with the tracked mesh and landmarks drawn on them (PyAV encoder)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def draw_overlay(frame: np.ndarray, vertices: np.ndarray, faces: np.ndarray, landmarks: np.ndarray,
                 lost: np.ndarray | None = None) -> np.ndarray:
    """Draw the mesh (green) and landmarks (yellow; red where lost) on an RGB frame.

    Parameters
    ----------
    frame : ndarray, shape (H, W, 3) uint8
    vertices : ndarray, shape (N, 2)
    faces : ndarray, shape (M, 3)
    landmarks : ndarray, shape (L, 2)
    lost : ndarray, shape (L,) bool, optional

    Returns
    -------
    ndarray, shape (H, W, 3) uint8
        A new image.
    """
    import cv2

    img = np.ascontiguousarray(frame, dtype=np.uint8).copy()
    sh = 4  # fixed-point sub-pixel bits for smooth lines
    tri = np.round(vertices[faces] * (1 << sh)).astype(np.int32)  # (M, 3, 2)
    cv2.polylines(img, list(tri), True, (60, 220, 60), 1, cv2.LINE_AA, sh)
    lost = np.zeros(len(landmarks), bool) if lost is None else np.asarray(lost, bool)
    r = 2 * (1 << sh)
    diamond = np.array([[0, -r], [r, 0], [0, r], [-r, 0]], np.int32)
    marks = np.round(landmarks * (1 << sh)).astype(np.int32)[:, None, :] + diamond[None]
    if (~lost).any():
        cv2.fillPoly(img, list(marks[~lost]), (255, 230, 0), cv2.LINE_AA, sh)
    if lost.any():
        cv2.fillPoly(img, list(marks[lost]), (255, 40, 40), cv2.LINE_AA, sh)
    return img


class OverlayWriter:
    """Stream RGB frames into an H.264 (libx264; MPEG-4 part 2 as fallback) mp4 with PyAV.

    Odd frame sizes are padded by one pixel (yuv420p needs even sizes). The overlay is a preview:
    x264's ``ultrafast`` preset (CRF 23) encodes a 360 x 288 frame in about a third of ``veryfast``'s
    CPU time for a file about three times larger, and the RGB -> YUV 4:2:0 conversion (BT.601,
    limited range, as FFmpeg's default) is done by OpenCV's vectorised ``cvtColor`` instead of
    PyAV's per-frame swscale reformat.
    """

    def __init__(self, path: str | os.PathLike, fps: float, size: tuple[int, int]):
        from fractions import Fraction

        import av

        self.path = Path(path)
        self.container = av.open(str(self.path), mode="w")
        rate = Fraction(fps).limit_denominator(1001)
        try:
            self.stream = self.container.add_stream("libx264", rate=rate)
            self.stream.options = {"crf": "23", "preset": "ultrafast"}
        except Exception:  # noqa: BLE001 - encoder not in this FFmpeg build
            self.stream = self.container.add_stream("mpeg4", rate=rate)
        self.w, self.h = size[0] + size[0] % 2, size[1] + size[1] % 2
        self.stream.width, self.stream.height = self.w, self.h
        self.stream.pix_fmt = "yuv420p"

    def write(self, rgb: np.ndarray) -> None:
        import av

        if rgb.shape[1] != self.w or rgb.shape[0] != self.h:
            rgb = np.pad(rgb, ((0, self.h - rgb.shape[0]), (0, self.w - rgb.shape[1]), (0, 0)), mode="edge")
        import cv2

        yuv = cv2.cvtColor(np.ascontiguousarray(rgb, dtype=np.uint8), cv2.COLOR_RGB2YUV_I420)   # (3H/2, W)
        frame = av.VideoFrame.from_ndarray(yuv, format="yuv420p")
        for packet in self.stream.encode(frame):
            self.container.mux(packet)

    def close(self) -> None:
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()
