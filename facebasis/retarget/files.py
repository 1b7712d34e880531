"""Input files of the retargeting commands: landmark index lists, 2D landmark files, images."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..jsonio import read_json


def read_indices(path) -> np.ndarray:
    """A landmark vertex index file: JSON list of integers, or ``{"indices": [...]}``; (L,) int64.

    Range and count are checked against the mesh and the capture by the caller
    (:func:`facebasis.retarget.rigdrive.check_landmark_indices`).
    """
    path = Path(path)
    data = read_json(path, "a JSON list of vertex indices", what="landmark index file")
    if isinstance(data, dict):
        data = data.get("indices", data.get("landmarks"))
    if not isinstance(data, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in data):
        raise InputError(f"landmark index file {path}: expected a JSON list of integers (or {{\"indices\": [...]}}), "
                         f"found {type(data).__name__}")
    return np.asarray(data, np.int64)


def read_points2d(path) -> np.ndarray:
    """2D landmarks (L, 2) from an iBUG ``.pts`` file or a JSON file (list of [x, y], or
    ``{"landmarks": [[x, y], ...]}``); pixels, x right, y down."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"cartoon landmark file {path}: expected a .pts or .json file, found no such file")
    suffix = path.suffix.lower()
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise InputError(f"cartoon landmark file {path}: expected text, found binary data") from exc
    if suffix == ".pts":
        if "{" not in text or "}" not in text:
            raise InputError(f"cartoon landmark file {path}: expected iBUG .pts with points between '{{' and '}}'")
        body = text[text.index("{") + 1:text.rindex("}")]
        try:
            pts = np.array([[float(v) for v in line.split()] for line in body.splitlines() if line.strip()])
        except ValueError as exc:
            raise InputError(f"cartoon landmark file {path}: expected two numbers per line ({exc})") from exc
    elif suffix == ".json":
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise InputError(f"cartoon landmark file {path}: expected JSON ({exc})") from exc
        if isinstance(data, dict):
            data = data.get("landmarks", data.get("points"))
        try:
            pts = np.asarray(data, np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(f"cartoon landmark file {path}: expected a list of [x, y] pairs") from exc
    else:
        raise InputError(f"cartoon landmark file {path}: expected a .pts or .json file, found '{suffix}'")
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
        raise InputError(f"cartoon landmark file {path}: expected (L, 2) points, found shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError(f"cartoon landmark file {path}: expected finite coordinates, found NaN/inf")
    return pts


def write_pts(path, points) -> None:
    """Write 2D points (L, 2) as an iBUG ``.pts`` file."""
    from ..atomic import atomic_write_bytes

    P = np.asarray(points, np.float64)
    body = "\n".join(f"{x:.3f} {y:.3f}" for x, y in P)
    atomic_write_bytes(path, f"version: 1\nn_points: {len(P)}\n{{\n{body}\n}}\n".encode())


def read_image(path) -> np.ndarray:
    """An image file as (H, W, 3) uint8 RGB (alpha dropped, grey expanded)."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InputError(f"cartoon image {path}: expected an image file, found no such file")
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError(f"cartoon image {path}: expected an image (PNG, JPEG, ...), found a file OpenCV cannot read")
    return np.ascontiguousarray(img[..., ::-1])


__all__ = ["read_indices", "read_points2d", "write_pts", "read_image"]
