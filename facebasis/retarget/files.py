"""Input files of the retargeting commands: landmark index lists, 2D landmark files, images."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..jsonio import check_json_text, read_json


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
    idx = np.asarray(data, np.int64)
    dup = repeated_indices(idx)
    if dup:
        raise InputError(f"landmark index file {path}: expected distinct vertex indices (one vertex per landmark), "
                         f"found {dup}")
    return idx


def repeated_indices(idx) -> str:
    """'' if the integers ``idx`` (L,) are distinct, else a description of the repeats for an error
    message: ``"vertex 12 at positions 0, 5 and 7; vertex 40 at positions 2, 3"`` (first 3 shown)."""
    idx = np.asarray(idx).ravel()
    values, inverse, counts = np.unique(idx, return_inverse=True, return_counts=True)
    rep = np.flatnonzero(counts > 1)
    if not len(rep):
        return ""
    parts = []
    for r in rep[:3]:
        pos = np.flatnonzero(inverse == r)
        shown = ", ".join(str(p) for p in pos[:5]) + (f" and {len(pos) - 5} more" if len(pos) > 5 else "")
        parts.append(f"vertex {int(values[r])} {len(pos)} times (positions {shown})")
    more = f"; and {len(rep) - 3} more repeated" if len(rep) > 3 else ""
    return "; ".join(parts) + more


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
        check_json_text(text, f"cartoon landmark file {path}", "a list of [x, y] pairs")
        try:
            data = json.loads(text)
        except (ValueError, RecursionError) as exc:
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
    flat = flat_spread(pts)
    if flat:
        raise InputError(f"cartoon landmark file {path}: expected points spread over the face, found {flat} "
                         "(no face can be placed on them)")
    return pts


def flat_spread(points, rtol: float = 1e-6) -> str:
    """'' if the points (L, 2) span an area, else ``"all points equal at (x, y)"`` or ``"all points
    on one line"``: the singular values of the centred points (a rank test, scale-free)."""
    P = np.asarray(points, np.float64)
    C = P - P.mean(0)
    s = np.linalg.svd(C, compute_uv=False) if len(P) > 1 else np.zeros(2)
    if len(P) < 3 or s[0] <= rtol * max(1.0, float(np.abs(P).max())):
        return f"all points equal at ({P[0, 0]:g}, {P[0, 1]:g})" if len(P) and s[0] == 0 else \
            f"{len(P)} points that span no area"
    if s[1] <= rtol * s[0]:
        return "all points on one line"
    return ""


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


__all__ = ["read_indices", "repeated_indices", "flat_spread", "read_points2d", "write_pts", "read_image"]
