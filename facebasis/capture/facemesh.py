"""Uniform triangle mesh over the face region bounded by the landmarks (Wu & Ju 2016, sec. 3).

The paper meshes the region bounded by its ASM points (about 85% of the face) uniformly, with the
feature points as vertices. We build it as follows:

1. boundary polygon: for iBUG-68 landmarks the jaw line 0..16 followed by the brows 26..17
   (reversed, so the polygon is simple); for any other landmark set the convex hull;
2. interior points on a hexagonal grid of spacing ``h`` (default: face width / 12), dropping grid
   points closer than ``0.6 h`` to a landmark or to a boundary edge;
3. ``scipy.spatial.Delaunay`` of landmarks + grid points, keeping the triangles whose centroid lies
   inside the polygon and dropping collinear (zero-area) ones;
4. grid points that end up on the mesh boundary are removed and the triangulation redone, so every
   boundary vertex is a landmark (then the harmonic initialisation, eq. 7-9, has Dirichlet values on
   the whole boundary and reproduces affine motions exactly).

Landmarks are vertices ``0 .. L-1``; grid points follow. Shewchuk's Triangle (and meshpy, which
wraps it) is deliberately not used: its licence forbids commercial use. Delaunay from SciPy (Qhull)
is BSD/MIT-style licensed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facebasis.errors import MeshError

from .landmarks import face_width


@dataclass(frozen=True)
class FaceMesh:
    """A 2D triangle mesh of the face.

    Attributes
    ----------
    vertices : ndarray, shape (N, 2)
        Pixel positions on the first frame; rows ``0 .. L-1`` are the landmarks.
    faces : ndarray, shape (M, 3)
        Counter-clockwise (in x-right, y-down pixel coordinates: positive signed area) triangles.
    n_landmarks : int
        ``L``.
    boundary : ndarray, shape (B,)
        Landmark indices of the boundary polygon, in order.
    spacing : float
        Grid spacing ``h`` in pixels.
    """

    vertices: np.ndarray
    faces: np.ndarray
    n_landmarks: int
    boundary: np.ndarray
    spacing: float


def boundary_polygon(landmarks: np.ndarray) -> np.ndarray:
    """Indices of the boundary polygon, shape ``(B,)``: jaw + reversed brows for 68 points, else hull."""
    n = len(landmarks)
    if n == 68:
        return np.r_[np.arange(0, 17), np.arange(26, 16, -1)]
    from scipy.spatial import ConvexHull

    try:
        return ConvexHull(landmarks).vertices.astype(int)
    except Exception as exc:  # noqa: BLE001 - QhullError: collinear / coincident points
        raise MeshError(f"landmarks: expected points spanning an area, found a degenerate set ({exc})") from None


def points_in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test, vectorised over points and edges; ``(P,)`` bool."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    ya, yb = a[None, :, 1], b[None, :, 1]
    cond = (ya > y) != (yb > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = a[None, :, 0] + (y - ya) * (b[None, :, 0] - a[None, :, 0]) / (yb - ya)
    return (np.count_nonzero(cond & (x < xint), axis=1) % 2) == 1


def distance_to_segments(pts: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest segment ``a[k] b[k]``; ``(P,)``."""
    ab = b - a
    t = np.einsum("pkd,kd->pk", pts[:, None, :] - a[None], ab) / np.maximum((ab ** 2).sum(1), 1e-12)
    t = np.clip(t, 0, 1)
    proj = a[None] + t[..., None] * ab[None]
    return np.sqrt(((pts[:, None, :] - proj) ** 2).sum(-1)).min(1)


def signed_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Signed triangle areas, ``(M,)`` (positive = counter-clockwise in x-right, y-up terms)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def boundary_vertices(F: np.ndarray) -> np.ndarray:
    """Vertices on boundary edges (edges used by one triangle only)."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(E, axis=0, return_counts=True)
    return np.unique(uniq[counts == 1])


def build_face_mesh(landmarks: np.ndarray, spacing: float | None = None) -> FaceMesh:
    """Build the uniform face mesh with the landmarks as its first vertices.

    Parameters
    ----------
    landmarks : ndarray, shape (L, 2)
        First-frame landmarks (pixels).
    spacing : float, optional
        Target edge length ``h`` in pixels; default ``face_width / 12``.

    Returns
    -------
    FaceMesh
    """
    from scipy.spatial import Delaunay

    lm = np.asarray(landmarks, float)
    L = len(lm)
    h = float(spacing) if spacing else face_width(lm) / 12.0
    if not h > 0:
        raise MeshError(f"mesh spacing: expected a positive number, found {spacing}")
    bidx = boundary_polygon(lm)
    poly = lm[bidx]
    lo, hi = poly.min(0), poly.max(0)
    dy = h * np.sqrt(3) / 2
    ys = np.arange(lo[1] + dy / 2, hi[1], dy)
    xs = np.arange(lo[0], hi[0] + h, h)
    gx, gy = np.meshgrid(xs, ys)
    gx = gx + (np.arange(len(ys))[:, None] % 2) * h / 2
    grid = np.stack([gx.ravel(), gy.ravel()], 1)
    grid = grid[points_in_polygon(grid, poly)]
    if len(grid):
        d_lm = np.sqrt(((grid[:, None] - lm[None]) ** 2).sum(-1)).min(1)
        d_edge = distance_to_segments(grid, poly, np.roll(poly, -1, axis=0))
        grid = grid[(d_lm > 0.6 * h) & (d_edge > 0.6 * h)]
    for _ in range(10):
        V = np.concatenate([lm, grid])
        try:
            tri = Delaunay(V)
        except Exception as exc:  # noqa: BLE001 - QhullError
            raise MeshError(f"landmarks: Delaunay triangulation failed ({exc})") from None
        F = tri.simplices.astype(np.int64)
        cen = V[F].mean(1)
        F = F[points_in_polygon(cen, poly)]
        area = signed_areas(V, F)
        keep = np.abs(area) > 1e-6 * h * h
        F = F[keep]
        area = area[keep]
        F[area < 0] = F[area < 0][:, [0, 2, 1]]
        bad = boundary_vertices(F)
        bad = bad[bad >= L]
        if len(bad) == 0:
            break
        grid = np.delete(grid, bad - L, axis=0)
    else:
        raise MeshError("face mesh: could not make every boundary vertex a landmark")
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    if not used[:L].all():
        miss = np.flatnonzero(~used[:L])
        raise MeshError(f"face mesh: landmarks {miss.tolist()} are in no triangle (duplicate or outside points?)")
    remap = np.cumsum(used) - 1  # drop grid points left in no triangle
    return FaceMesh(V[used], remap[F], L, bidx, h)


def mesh_edges(F: np.ndarray) -> np.ndarray:
    """Unique undirected edges, ``(E, 2)``."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(E, axis=0)
