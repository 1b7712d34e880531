"""Landmarks found on a 3D scan: render it from the front, run a 2D face detector, lift onto the surface.

``register --landmarks auto``: the scan, brought into the template's frame by the rigid stage (the
template looks along +z, y up), is rendered orthographically with the package's numpy rasteriser
(:func:`.raster.rasterize_mesh`, flat shading, no OpenGL); the shipped detector (dlib's 68-point
predictor, or MediaPipe's face mesh mapped to the same 68 points,
:mod:`facebasis.capture.detect`) finds the 2D landmarks; each is lifted onto the surface by casting
the viewing ray through it: the nearest front-facing triangle whose projection contains the point,
at the barycentric position inside it. The template is rendered, detected and lifted the same way
once, so both sides follow the detector's own convention (a detector on an untextured render places
a brow or the jaw line where the shading suggests; the same bias on both sides cancels); each
template landmark is its nearest vertex. Only the 51 inner points (brows, nose, eyes, mouth: iBUG
17-67) are used: the jaw line (0-16) is a silhouette, not a point of the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: iBUG 68 indices used for registration (the jaw line 0-16 is a silhouette)
INNER = np.arange(17, 68)
#: framings tried on the template (the template's x-y extent as a fraction of the image), in order
FILLS = (0.5, 0.7, 0.9, 0.35)
#: the render's background, also seen through the scan's holes (eyes, mouth): dark, as an open mouth is
BACKGROUND = (0, 0, 0)
#: the render smooths a mesh over about this many pixels (a noisy scan's small triangles, flat-shaded,
#: are speckle a detector does not take for a face; a mesh coarser than that is not smoothed)
SMOOTH_PIXELS = 2.0


@dataclass(frozen=True)
class FrontView:
    """An orthographic front camera in the template's frame: ``pixel = ((x - cx) k + W/2, -(y - cy) k + H/2)``.

    Attributes
    ----------
    centre : (2,) ``(cx, cy)``; scale : ``k`` pixels per unit; size : image side in pixels
    """

    centre: np.ndarray
    scale: float
    size: int = 512

    @classmethod
    def of(cls, V: np.ndarray, size: int = 512, fill: float = 0.8) -> "FrontView":
        """The view that fits the x-y bounding box of ``V`` (n, 3) to ``fill`` of the image."""
        lo, hi = V[:, :2].min(0), V[:, :2].max(0)
        return cls(0.5 * (lo + hi), fill * size / float(max(hi - lo)), size)

    def pixels(self, V: np.ndarray) -> np.ndarray:
        """(n, 3): x right and y down in pixels, z towards the viewer (the rasteriser's frame)."""
        c, k, s = self.centre, self.scale, self.size
        return np.stack([(V[:, 0] - c[0]) * k + s / 2, -(V[:, 1] - c[1]) * k + s / 2, V[:, 2] * k], 1)


def lift(points: np.ndarray, P: np.ndarray, V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lift 2D points onto a mesh seen from the front: the nearest front-facing triangle under each.

    Parameters
    ----------
    points : (k, 2) pixels; P : (n, 3) the mesh's vertices in pixels (:meth:`FrontView.pixels`);
    V : (n, 3) the same vertices in 3D (the lifted points are returned there); F : (m, 3)

    Returns
    -------
    X : (k, 3) surface points (NaN where no triangle lies under the point), hit : (k,) bool
    """
    from scipy.spatial import cKDTree

    A, B, C = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]
    area = (B[:, 0] - A[:, 0]) * (C[:, 1] - A[:, 1]) - (B[:, 1] - A[:, 1]) * (C[:, 0] - A[:, 0])
    front = np.flatnonzero(area < -1e-12)  # counter-clockwise seen from the viewer (y down)
    cen = (A[front, :2] + B[front, :2] + C[front, :2]) / 3.0
    reach = float(np.max(np.linalg.norm(np.stack([A[front], B[front], C[front]], 1)[:, :, :2] - cen[:, None], axis=2)))
    cand = cKDTree(cen).query_ball_point(points, reach + 1e-9)
    q = np.repeat(np.arange(len(points)), [len(c) for c in cand])  # a loop over landmarks, not triangles
    t = front[np.concatenate([np.asarray(c, np.int64) for c in cand])] if len(q) else np.zeros(0, np.int64)
    a, b, c = P[F[t, 0], :2], P[F[t, 1], :2], P[F[t, 2], :2]
    p = points[q]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    l1 = ((p[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (p[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (p[:, 0] - a[:, 0])) / det
    l0 = 1.0 - l1 - l2
    inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9)
    depth = np.where(inside, l0 * P[F[t, 0], 2] + l1 * P[F[t, 1], 2] + l2 * P[F[t, 2], 2], -np.inf)
    best = np.full(len(points), -np.inf)
    np.maximum.at(best, q, depth)
    win = inside & (depth == best[q]) & np.isfinite(depth)
    X = np.full((len(points), 3), np.nan)
    X[q[win]] = (l0[win, None] * V[F[t[win], 0]] + l1[win, None] * V[F[t[win], 1]] + l2[win, None] * V[F[t[win], 2]])
    return X, np.isfinite(X[:, 0])


def smoothed(V: np.ndarray, F: np.ndarray, iterations: int) -> np.ndarray:
    """``V`` after a few steps of uniform Laplacian smoothing (``x <- mean of the neighbours``), for
    the render only: flat shading of a noisy scan's small triangles is speckle a detector does not
    take for a face (the lift still uses the scan's own surface)."""
    import scipy.sparse as sp

    i = F[:, [0, 1, 2, 1, 2, 0]].ravel()
    j = F[:, [1, 2, 0, 0, 1, 2]].ravel()
    A = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(len(V), len(V)))
    A.data[:] = 1.0  # duplicate edges counted once
    deg = np.asarray(A.sum(1)).ravel()
    W = sp.diags(1.0 / np.maximum(deg, 1)) @ A
    X = np.asarray(V, float)
    for _ in range(iterations):  # a loop over smoothing steps, not vertices
        X = np.where(deg[:, None] > 0, W @ X, X)
    return X


def detect_on_mesh(V: np.ndarray, F: np.ndarray, view: FrontView, detector) -> tuple[np.ndarray, np.ndarray]:
    """68 landmarks of a mesh in the template's frame: render, detect, lift.

    Returns
    -------
    X : (68, 3) surface points (NaN where not found), found : (68,) bool (all False: no face)
    """
    from .raster import rasterize_mesh

    P = view.pixels(V)
    from .mesh import median_edge_length

    # smoothing over about SMOOTH_PIXELS pixels: k uniform Laplacian steps spread over ~ h sqrt(k)
    k = int(min(20, (SMOOTH_PIXELS / view.scale / max(median_edge_length(V, F), 1e-12)) ** 2))
    img = rasterize_mesh(view.pixels(smoothed(V, F, k)), F, (view.size, view.size), background=BACKGROUND)
    pts = detector.detect(img)
    if pts is None:
        return np.full((68, 3), np.nan), np.zeros(68, bool)
    return lift(np.asarray(pts, float), P, V, F)


class AutoLandmarks:
    """The template's detected landmarks, prepared once, and detection on scans.

    Parameters
    ----------
    V, F : the template (looking along +z, y up); detector : an object with ``detect(image)``
        (:func:`facebasis.capture.detect.get_detector`); name : the template's name in messages

    Raises
    ------
    InputError
        No face found on the template's front render.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, detector, name: str = "template"):
        self.detector = detector
        for fill in FILLS:  # a face detector wants some margin around the face: try a few framings
            self.view = FrontView.of(V, fill=fill)
            X, found = detect_on_mesh(V, F, self.view, detector)
            if found.any():
                break
        found[: INNER[0]] = False
        if found.sum() < 3:
            raise InputError(f"{name}: {{landmarks}} auto expected a face on the template's front render (looking "
                             f"along +z, y up), found {'no face' if not found.any() else f'{int(found.sum())} points'}",
                             params={"landmarks": "landmarks"})
        from scipy.spatial import cKDTree

        self.index = np.full(68, -1, np.int64)
        self.index[found] = cKDTree(V).query(X[found])[1]
        self.found = found

    def on_scan(self, V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Landmarks of a scan already in the template's frame.

        Returns
        -------
        template_indices : (k,) template vertices, points : (k, 3) on the scan (template frame),
        for the landmarks found on both
        """
        X, found = detect_on_mesh(V, F, self.view, self.detector)
        ok = found & self.found
        return self.index[ok], X[ok]
