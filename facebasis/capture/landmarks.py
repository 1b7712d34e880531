"""First-frame landmarks: file formats, iBUG-68 semantic regions and per-region LK windows.

Landmarks are pixel coordinates ``(x, y)`` with x to the right and y down, as an ``(L, 2)`` float
array. Two file formats are read:

* iBUG ``.pts``: ``version: 1``, ``n_points: N``, ``{``, N lines ``x y``, ``}``;
* JSON: ``[[x, y], ...]``.

Any set of ``L >= 3`` points is accepted. When ``L == 68`` the points are taken to follow the
iBUG 300-W order (jaw 0-16, brows 17-26, nose 27-35, eyes 36-47, mouth 48-67), which selects the
per-region Lucas-Kanade windows of the paper (Wu & Ju 2016, sec. 4.1): the paper tracks eye points
in a 5 x 15 region because they "move mostly vertically, little horizontally", and mouth points in
15 x 15. We read "5 x 15" as width 5 by height 15 pixels (tall window, matching mostly-vertical
motion). Windows are scaled with the face size (see :func:`lk_windows`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from facebasis.errors import InputError

#: iBUG-68 regions: name -> index range (stop exclusive).
IBUG68_REGIONS: dict[str, tuple[int, int]] = {
    "jaw": (0, 17),
    "brows": (17, 27),
    "nose": (27, 36),
    "eyes": (36, 48),
    "mouth": (48, 68),
}

#: Default LK windows (width, height) in pixels for a face about 150 px wide (paper: eyes 5 x 15,
#: mouth 15 x 15; the others are our choice: brows move mostly vertically, the nose little).
DEFAULT_WINDOWS: dict[str, tuple[int, int]] = {
    "jaw": (15, 15),
    "brows": (9, 15),
    "nose": (11, 11),
    "eyes": (5, 15),
    "mouth": (15, 15),
    "other": (15, 15),
}

#: iBUG-68 inner-lip points and the outer-lip point across the same lip (upper 61-63 -> 50-52, lower
#: 65-67 -> 56-58). Closed lips put an upper and a lower inner point on the same pixel, so LK centred
#: on the lip line moves both alike and the mouth never opens; by default they follow their outer-lip
#: partner instead (:func:`lip_partners`, ``inner_lips`` of :class:`facebasis.capture.tracker.TrackerOptions`).
INNER_LIP_PARTNERS: dict[int, int] = {61: 50, 62: 51, 63: 52, 65: 56, 66: 57, 67: 58}

#: Face width (pixels) at which :data:`DEFAULT_WINDOWS` apply unscaled.
REFERENCE_FACE_WIDTH = 150.0


def region_labels(n_points: int) -> np.ndarray:
    """Region name of each landmark, shape ``(L,)`` of str; ``"other"`` unless ``L == 68``."""
    labels = np.full(n_points, "other", dtype=object)
    if n_points == 68:
        for name, (a, b) in IBUG68_REGIONS.items():
            labels[a:b] = name
    return labels


def face_width(landmarks: np.ndarray) -> float:
    """Horizontal extent of the landmarks (pixels), at least 1."""
    lm = np.asarray(landmarks, float)
    return float(max(np.ptp(lm[:, 0]), np.ptp(lm[:, 1]) * 0.75, 1.0))


def face_scale(landmarks: np.ndarray) -> float:
    """Scale factor of the face against :data:`REFERENCE_FACE_WIDTH`, clipped to ``[1, 4]``."""
    return float(np.clip(face_width(landmarks) / REFERENCE_FACE_WIDTH, 1.0, 4.0))


def lk_windows(landmarks: np.ndarray, windows: dict | None = None) -> np.ndarray:
    """Per-landmark LK window ``(width, height)`` in pixels, shape ``(L, 2)`` int, odd sizes.

    The region windows (:data:`DEFAULT_WINDOWS` unless ``windows`` is given) are multiplied by
    :func:`face_scale` so a face filmed at higher resolution gets proportionally larger windows.
    """
    win = dict(DEFAULT_WINDOWS)
    if windows:
        win.update(windows)
    labels = region_labels(len(landmarks))
    s = face_scale(landmarks)
    base = np.array([win[str(lab)] for lab in labels], float)  # L entries, a lookup not a loop over pixels
    out = np.maximum(np.round(base * s).astype(int) | 1, 5)
    return out


def lip_partners(n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """(inner, partner): index arrays (P,) of the inner-lip points and of their outer-lip partners
    across the same lip (:data:`INNER_LIP_PARTNERS`); empty unless ``n_points == 68``."""
    if n_points != 68:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    inner = np.array(sorted(INNER_LIP_PARTNERS), np.int64)
    return inner, np.array([INNER_LIP_PARTNERS[i] for i in inner], np.int64)


def _fail(path, msg):
    raise InputError(f"landmark file {path}: {msg}")


def parse_pts(text: str, path: str = "<text>") -> np.ndarray:
    """Parse iBUG ``.pts`` text into an ``(L, 2)`` float array."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    n = None
    i = 0
    while i < len(lines) and lines[i] != "{":
        key, _, val = lines[i].partition(":")
        if key.strip() == "n_points":
            try:
                n = int(val)
            except ValueError:
                _fail(path, f"expected an integer after 'n_points:', found {val.strip()!r}")
        elif key.strip() != "version":
            _fail(path, f"line {i + 1}: expected 'version:', 'n_points:' or '{{', found {lines[i]!r}")
        i += 1
    if i == len(lines):
        _fail(path, "expected a '{' line opening the points, found none")
    if n is None:
        _fail(path, "expected an 'n_points: N' header line, found none")
    try:
        end = lines.index("}", i + 1)
    except ValueError:
        _fail(path, "expected a closing '}' line, found none")
    body = lines[i + 1:end]
    if len(body) != n:
        _fail(path, f"expected {n} point lines (n_points), found {len(body)}")
    pts = np.empty((n, 2))
    for k, ln in enumerate(body):
        parts = ln.split()
        try:
            if len(parts) != 2:
                raise ValueError
            pts[k] = [float(parts[0]), float(parts[1])]
        except ValueError:
            _fail(path, f"point line {k + 1}: expected two numbers 'x y', found {ln!r}")
    return pts


def read_landmarks(path: str | os.PathLike, expected: int | None = None) -> np.ndarray:
    """Read first-frame landmarks from a ``.pts`` or ``.json`` file.

    Parameters
    ----------
    path : path-like
        ``.pts`` (iBUG) or ``.json`` (``[[x, y], ...]``) file.
    expected : int, optional
        Required number of points (e.g. 68); checked if given.

    Returns
    -------
    ndarray, shape (L, 2)
        Pixel coordinates, x right, y down.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"landmark file {p}: expected an existing .pts or .json file, found nothing")
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"landmark file {p}: cannot read it ({exc})") from None
    if p.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"landmark file {p}: expected JSON [[x, y], ...], found invalid JSON ({exc})") from None
        try:
            pts = np.asarray(data, dtype=float)
        except (TypeError, ValueError):
            _fail(p, "expected a JSON list of [x, y] pairs, found mixed or non-numeric entries")
        if pts.ndim != 2 or pts.shape[1] != 2:
            _fail(p, f"expected a JSON list of [x, y] pairs, found an array of shape {pts.shape}")
    elif p.suffix.lower() == ".pts":
        pts = parse_pts(text, str(p))
    else:
        _fail(p, f"expected a .pts or .json file, found suffix {p.suffix!r}")
    return validate_landmarks(pts, source=f"landmark file {p}", expected=expected)


def _source_error(params: dict | None, text: str) -> InputError:
    """An error whose text may name library parameters (``"{detector} dlib on x.mp4"``, ``params``)."""
    return InputError(text, params=params)


def validate_landmarks(pts, source: str = "landmarks", expected: int | None = None,
                       size: tuple[int, int] | None = None, params: dict | None = None) -> np.ndarray:
    """Check shape, count, finiteness and (if ``size=(width, height)``) that points lie in the frame;
    ``params``: the library parameters ``source`` names as ``{name}`` (:mod:`facebasis.errors`)."""
    pts = np.asarray(pts, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise _source_error(params, f"{source}: expected an (L, 2) array of x, y, found shape {pts.shape}")
    if expected is not None and len(pts) != expected:
        raise _source_error(params, f"{source}: expected {expected} points, found {len(pts)}")
    if len(pts) < 3:
        raise _source_error(params, f"{source}: expected at least 3 points, found {len(pts)}")
    if not np.all(np.isfinite(pts)):
        raise _source_error(params, f"{source}: expected finite coordinates, found NaN or infinity")
    # a face mesh needs points spanning an area: all-equal or collinear points are refused here, in
    # one line, instead of as Qhull's multi-line report from the triangulation
    c = pts - pts.mean(0)
    sv = np.linalg.svd(c, compute_uv=False)
    if sv[0] <= 1e-9 * max(1.0, float(np.abs(pts).max())):
        raise _source_error(params, f"{source}: expected points spanning an area, found all {len(pts)} points at "
                         f"x={pts[0, 0]:g}, y={pts[0, 1]:g}")
    if sv[1] <= 1e-6 * sv[0]:
        raise _source_error(params, f"{source}: expected points spanning an area, found all {len(pts)} points on "
                                    "one line")
    if size is not None:
        w, h = size
        bad = np.flatnonzero((pts[:, 0] < 0) | (pts[:, 0] > w - 1) | (pts[:, 1] < 0) | (pts[:, 1] > h - 1))
        if len(bad):
            k = int(bad[0])
            raise _source_error(params,
                f"{source}: expected points inside the {w} x {h} frame, found {len(bad)} outside "
                f"(point {k} at x={pts[k, 0]:g}, y={pts[k, 1]:g})")
    return pts


def format_pts(pts: np.ndarray) -> str:
    """iBUG ``.pts`` text of an ``(L, 2)`` array."""
    pts = np.asarray(pts, float)
    body = "\n".join(f"{x:.3f} {y:.3f}" for x, y in pts)
    return f"version: 1\nn_points: {len(pts)}\n{{\n{body}\n}}\n"


def neighbour_affine_prediction(P0: np.ndarray, Pt: np.ndarray, W: np.ndarray, conf: np.ndarray) -> np.ndarray:
    """Each point predicted from the others by a weighted least-squares affine map from frame 0.

    For point ``i``, the affine map ``x -> M_i^T [x, 1]`` minimising
    ``sum_{j != i} W_ij c_j |M_i^T [P0_j, 1] - Pt_j|^2`` (``c`` = ``conf``) is applied to ``P0_i``
    (leave-one-out: ``W`` has a zero diagonal). Coordinates are centred on ``P0_i``, so the prediction
    is the map's translation; a ridge of 1e-9 of its trace on the linear part keeps a point whose
    confident neighbours are collinear at a finite prediction.

    Parameters
    ----------
    P0, Pt : ndarray, shape (L, 2)
        Points in frame 0 and frame t.
    W : ndarray, shape (L, L)
        Non-negative weights with a zero diagonal (:func:`facebasis.capture.particle.neighbour_weights`).
    conf : ndarray, shape (L,) bool
        Points that may serve as neighbours.

    Returns
    -------
    ndarray, shape (L, 2)
    """
    Wc = W * np.asarray(conf, float)[None, :]
    L = len(P0)
    X = np.concatenate([P0[None, :, :] - P0[:, None, :], np.ones((L, L, 1))], -1)   # (L, L, 3), centred on i
    A = np.einsum("ij,ijk,ijl->ikl", Wc, X, X)                          # (L, 3, 3)
    B = np.einsum("ij,ijk,jl->ikl", Wc, X, Pt)                          # (L, 3, 2)
    ridge = 1e-9 * (A[:, 0, 0] + A[:, 1, 1]) + 1e-12
    A[:, [0, 1], [0, 1]] += ridge[:, None]
    A[:, 2, 2] += 1e-12
    return np.linalg.solve(A, B)[:, 2, :]                               # the map at P0_i: its translation
