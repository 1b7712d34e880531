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

Coincident and nearly coincident landmarks (beyond the paper). A closed mouth makes dlib put the
upper and lower inner-lip points (61/67, 62/66, 63/65) on one pixel; Qhull keeps only one of two
equal points, and nearly equal ones give sliver triangles across the lip line that fold as soon as
the mouth opens. When an opposite inner-lip pair is closer than :data:`CLOSED_LIP_GAP` ``h``, the
mesh is therefore cut open along the lip line: the triangulation is made with every inner-lip point
moved :data:`LIP_SPLIT` of the way towards its outer-lip partner across the same lip (61-63 -> 50-52,
65-67 -> 56-58), the triangles inside the inner-lip polygon (the mouth opening) are dropped, and the
true positions are put back. The upper lip's triangles then use only upper inner-lip points and the
lower lip's only lower ones, so coincident points share no triangle and the mouth can open (the
inner-lip follower of :mod:`.lips` moves them apart). An open mouth on the first frame keeps its
inside meshed as before. Any other landmark that coincides with an earlier one (within
:data:`DUPLICATE_TOL` ``h``, e.g. the eyelids of a closed eye) is left out of the triangulation and
kept as an isolated vertex: it is still tracked as a landmark, and the harmonic initialisation and
the mesh refinement hold it (it is a control vertex), but no triangle uses it.

Landmarks are vertices ``0 .. L-1``; grid points follow. Shewchuk's Triangle (and meshpy, which
wraps it) is deliberately not used: its licence forbids commercial use. Delaunay from SciPy (Qhull)
is BSD/MIT-style licensed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from facebasis.errors import MeshError
from facebasis.geometry.mesh import boundary_vertices

from .landmarks import INNER_LIP_PARTNERS, face_width

#: an opposite inner-lip pair (61/67, 62/66, 63/65) closer than this many mesh spacings ``h`` counts as
#: a closed mouth, and the mesh is cut open along the lip line
CLOSED_LIP_GAP = 0.25
#: fraction of the way from an inner-lip point to its outer-lip partner where the triangulation of a
#: closed mouth places it (only the connectivity is taken from there)
LIP_SPLIT = 0.35
#: landmarks closer than this many ``h`` to an earlier landmark are duplicates (isolated vertices)
DUPLICATE_TOL = 1e-3
#: iBUG-68 opposite inner-lip pairs across the mouth
INNER_LIP_PAIRS = ((61, 67), (62, 66), (63, 65))


@dataclass(frozen=True)
class FaceMesh:
    """A 2D triangle mesh of the face.

    Attributes
    ----------
    vertices : ndarray, shape (N, 2)
        Pixel positions on the first frame; rows ``0 .. L-1`` are the landmarks.
    faces : ndarray, shape (M, 3)
        Counter-clockwise (in x-right, y-down pixel coordinates: positive signed area) triangles.
        A closed mouth is cut open (no triangle inside the inner-lip polygon 60-67); duplicate
        landmarks are in no triangle (see the module notes).
    n_landmarks : int
        ``L``.
    boundary : ndarray, shape (B,)
        Landmark indices of the boundary polygon, in order.
    spacing : float
        Grid spacing ``h`` in pixels.
    isolated : ndarray, shape (D,)
        Landmarks left out of the triangulation as duplicates of an earlier landmark (module notes).
    """

    vertices: np.ndarray
    faces: np.ndarray
    n_landmarks: int
    boundary: np.ndarray
    spacing: float
    isolated: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def closed_mouth(landmarks: np.ndarray, spacing: float) -> bool:
    """True if an iBUG-68 opposite inner-lip pair is closer than ``CLOSED_LIP_GAP * spacing``."""
    lm = np.asarray(landmarks, float)
    if len(lm) != 68:
        return False
    a, b = np.array(INNER_LIP_PAIRS).T
    return bool(np.linalg.norm(lm[a] - lm[b], axis=1).min() < CLOSED_LIP_GAP * spacing)


def duplicate_landmarks(landmarks: np.ndarray, tol: float) -> np.ndarray:
    """Indices (D,) of landmarks within ``tol`` of a landmark with a smaller index."""
    lm = np.asarray(landmarks, float)
    d = np.sqrt(((lm[:, None] - lm[None]) ** 2).sum(-1))
    close = np.tril(d <= tol, -1)   # (i, j) with j < i
    return np.flatnonzero(close.any(1))


def boundary_polygon(landmarks: np.ndarray) -> np.ndarray:
    """Indices of the boundary polygon, shape ``(B,)``: jaw + reversed brows for 68 points, else hull."""
    n = len(landmarks)
    if n == 68:
        return np.r_[np.arange(0, 17), np.arange(26, 16, -1)]
    from scipy.spatial import ConvexHull

    try:
        return ConvexHull(landmarks).vertices.astype(int)
    except Exception as exc:  # noqa: BLE001 - QhullError: collinear / coincident points
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise MeshError(f"landmarks: expected points spanning an area, found a degenerate set ({first})") from None


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
    # connectivity positions: a closed mouth is opened along the lip line (module notes)
    P = lm.copy()
    hole = None
    if closed_mouth(lm, h):
        inner = np.array(sorted(INNER_LIP_PARTNERS))
        outer = np.array([INNER_LIP_PARTNERS[i] for i in inner])
        P[inner] += LIP_SPLIT * (lm[outer] - lm[inner])
        hole = P[60:68]
    dup = duplicate_landmarks(P, DUPLICATE_TOL * h)
    keep_lm = np.ones(L, bool)
    keep_lm[dup] = False
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
    lm_ids = np.flatnonzero(keep_lm)
    for _ in range(10):
        V = np.concatenate([lm, grid])
        PV = np.concatenate([P, grid])
        ids = np.r_[lm_ids, L + np.arange(len(grid))]       # vertices given to Qhull
        try:
            tri = Delaunay(PV[ids])
        except Exception as exc:  # noqa: BLE001 - QhullError: its multi-line report is not repeated
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise MeshError(f"landmarks: expected points spanning an area, Delaunay triangulation failed "
                            f"({first})") from None
        F = ids[tri.simplices.astype(np.int64)]
        cen = PV[F].mean(1)
        inside = points_in_polygon(cen, poly)
        if hole is not None:
            inside &= ~points_in_polygon(cen, hole)
        F = F[inside]
        area = signed_areas(PV, F)
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
    if hole is not None:   # the true lip positions back: no triangle may fold
        true_area = signed_areas(V, F)
        if np.any(true_area <= 1e-6 * h * h):
            raise MeshError("face mesh: the closed mouth could not be cut open without folding a triangle "
                            "(inner-lip points 61-67 lie outside the outer lip 48-59?)")
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    if not used[lm_ids].all():
        miss = lm_ids[~used[lm_ids]]
        raise MeshError(f"face mesh: landmarks {miss.tolist()} are in no triangle (outside the face outline "
                        f"jaw 0-16 + brows 17-26?)")
    used[:L] = True   # duplicates stay as isolated landmark vertices
    remap = np.cumsum(used) - 1  # drop grid points left in no triangle
    return FaceMesh(V[used], remap[F], L, bidx, h, dup.astype(np.int64))
