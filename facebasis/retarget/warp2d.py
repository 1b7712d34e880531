"""2D reproduction: animate a single cartoon image by the captured mesh (paper section on 2D
reproduction, with eq. 10-13).

The capture's first-frame mesh is placed on the cartoon by the multiquadric RBF network trained on
the landmark pairs (eq. 10-11, :mod:`.rbf`); each frame the cartoon mesh moves by the captured
vertex displacements scaled by the ratio of mean edge lengths (eq. 12-13), and the image is warped
triangle by triangle: every destination pixel inside a moved triangle takes the colour of the
corresponding point (same barycentric coordinates) of that triangle on the rest cartoon, sampled
bilinearly (the paper's piecewise-affine warp with bilinear interpolation). Pixels outside the
mesh keep the source image.

Beyond the paper, on real clips (:meth:`CartoonAnimator.drive`, the default of ``animate2d``): the
head's in-plane similarity is taken out of the capture first (:mod:`.headmotion`: the cartoon keeps
its size and place, ``head="follow"`` moves the whole image with the head instead); each eye and
the mouth move in the cartoon's own proportions, the brows with their eyes (:mod:`.featurescale`,
``amplitude="feature"``: a cartoon eye twice as tall closes by twice the pixels); the mesh's
interior points follow the landmarks by a biharmonic interpolation; lips and eyelids that meet or
cross close instead of passing through each other (:func:`close_contacts`); and
:mod:`.foldfree` keeps every triangle of the warp from turning over, with an exact check of every
frame before it is drawn.

The image is warped by :func:`.raster2d.warp_image` (a vectorised scanline rasteriser, no Python
loop over pixels or triangles).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .mouth2d import INNER_LIP_68, MOUTH_INTERIOR_RGB, MOUTH_STRIP_68, fill_mouth, mouth_is_cut, opening_opacity
from .eyepaint import EYES_68, eye_colours, paint_eye
from .mouthpaint import image_chroma, paint_mouth
from .raster2d import warp_image
from .rbf import edge_length_ratio, fit_rbf

def _check_image(image, name="cartoon image") -> np.ndarray:
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.shape[0] < 2 or img.shape[1] < 2 or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
        raise InputError(f"{name}: expected an (H, W) or (H, W, 3|4) image, found shape {img.shape}")
    if img.dtype != np.uint8:
        raise InputError(f"{name}: expected 8-bit pixels, found {img.dtype}")
    return img


def static_band(rest, faces, width: int, height: int, border: float = 0.4):
    """Static outer ring around a mesh, and the triangles joining it to the mesh.

    The ring is the mesh's convex hull scaled by ``1 + border`` about its centroid (clipped to the
    image) plus the image's corners and edge midpoints. The band triangles are the triangles of a
    Delaunay triangulation of mesh and ring vertices that use a ring vertex. Returns ring points
    (r, 2) and band faces (b, 3) indexing ``concatenate([rest, ring])``.
    """
    from scipy.spatial import ConvexHull, Delaunay

    rest = np.asarray(rest, np.float64)
    hull = rest[ConvexHull(rest).vertices]
    centre = rest.mean(0)
    # resample the scaled hull polygon evenly (about 48 points)
    poly = centre + (1.0 + border) * (hull - centre)
    closed = np.concatenate([poly, poly[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    u = np.linspace(0.0, s[-1], 48, endpoint=False)
    ring = np.stack([np.interp(u, s, closed[:, 0]), np.interp(u, s, closed[:, 1])], 1)
    ring = np.clip(ring, [0.0, 0.0], [width - 1.0, height - 1.0])
    w, h = width - 1.0, height - 1.0
    frame = np.array([[0, 0], [w / 2, 0], [w, 0], [w, h / 2], [w, h], [w / 2, h], [0, h], [0, h / 2]])
    ring = np.unique(np.round(np.concatenate([ring, frame]), 6), axis=0)
    # drop ring points that fall inside (or onto) the hull of the mesh
    inside = Delaunay(hull).find_simplex(ring) >= 0
    ring = ring[~inside]
    allp = np.concatenate([rest, ring])
    tri = Delaunay(allp).simplices
    band = tri[(tri >= len(rest)).any(axis=1)]
    return ring, band.astype(np.int64)


#: how the capture mesh's vertices that are not landmarks drive the cartoon: "smooth" (the
#: biharmonic interpolation of the landmarks' displacements over the rest warp mesh, with the outer
#: ring still: tracked interior points of a real clip drift against the lips and fold or kink the
#: warp) or "tracked" (their own tracked motion, the paper's eq. 12 for every vertex)
INTERIOR_MODES = ("smooth", "tracked")

#: iBUG-68 columns that close when the mouth or an eye closes, top to bottom (outer upper lip,
#: inner upper lip, inner lower lip, outer lower lip; upper lid, lower lid), with the two corner
#: landmarks that give each feature's horizontal axis: mouth, right eye, left eye
CONTACTS_68 = (((48, 54), ((50, 61, 67, 58), (51, 62, 66, 57), (52, 63, 65, 56))),
               ((36, 39), ((37, 41), (38, 40))),
               ((42, 45), ((43, 47), (44, 46))))


def close_contacts(meshes, rest, contacts=CONTACTS_68, sigma: float = 0.15) -> np.ndarray:
    """Lip and eyelid contact: a lower lip pushed above the upper one shows as lips closing.

    Each column of points (top to bottom) is measured along its feature's vertical axis (the
    normal of the corner-to-corner line of the rest mesh, pointing down the column). Where the
    middle pair (the inner lips, or the two lids) comes closer than ``sigma`` times its rest gap
    (lips or lids that meet, or cross in the capture), both move along the axis to their midpoint
    plus and minus half that gap: the lips close and press, they do not pass through each other.
    Then each point outward of the contact keeps at least ``sigma`` of its rest distance to its
    inner neighbour (the lips' thickness is squeezed, never turned over), pushed outward if not.

    Parameters
    ----------
    meshes : (T, N, 2) or (N, 2) target positions (the head's motion already removed)
    rest : (N, 2) rest positions (the first 68 vertices are the iBUG landmarks)
    contacts : ((corner_a, corner_b), (column, ...)) per feature, a column listing an even number
        of point indices from top to bottom
    sigma : smallest gap, as a fraction of the rest gap

    Returns
    -------
    positions of the same shape as ``meshes``
    """
    M = np.array(meshes, np.float64)
    single = M.ndim == 2
    if single:
        M = M[None]
    rest = np.asarray(rest, np.float64)
    for (ca, cb), columns in contacts:
        cols = np.asarray(columns, np.int64)                              # (k, 2 h)
        axis = rest[cb] - rest[ca]
        n = np.array([-axis[1], axis[0]]) / max(np.linalg.norm(axis), 1e-12)
        if np.sum((rest[cols[:, -1]] - rest[cols[:, 0]]) @ n) < 0:
            n = -n
        h = cols.shape[1] // 2
        up, lo = cols[:, h - 1], cols[:, h]
        g_rest = np.maximum((rest[lo] - rest[up]) @ n, 0.0)              # (k,)
        g = (M[:, lo] - M[:, up]) @ n                                     # (T, k)
        push = 0.5 * np.maximum(sigma * g_rest - g, 0.0)[..., None] * n
        M[:, up] -= push
        M[:, lo] += push
        for j in range(h - 1, 0, -1):                                     # outward, upper side
            a, b = cols[:, j - 1], cols[:, j]
            need = sigma * np.maximum((rest[b] - rest[a]) @ n, 0.0) - (M[:, b] - M[:, a]) @ n
            M[:, a] -= np.maximum(need, 0.0)[..., None] * n
        for j in range(h, cols.shape[1] - 1):                             # outward, lower side
            a, b = cols[:, j], cols[:, j + 1]
            need = sigma * np.maximum((rest[b] - rest[a]) @ n, 0.0) - (M[:, b] - M[:, a]) @ n
            M[:, b] += np.maximum(need, 0.0)[..., None] * n
    return M[0] if single else M


@dataclass(frozen=True)
class CartoonDrive:
    """The cartoon mesh of every frame, as :meth:`CartoonAnimator.drive` plans it.

    Attributes
    ----------
    still : (T, N, 2) fold-free cartoon mesh showing the expression only (the head's similarity
        removed, contacts closed)
    head : :class:`.headmotion.HeadMotion` in cartoon pixels (the similarity moving the whole
        cartoon with the head), or None when the head is kept still
    folded_target : (T,) triangles of the mesh (band included) that eq. 12 alone would flip
    iterations : (T,) local/global iterations run (0: the target was used as it is)
    alpha : (T,) 1, or the fallback's blend towards the rest
    seconds : time spent planning
    """

    still: np.ndarray
    head: object
    folded_target: np.ndarray
    iterations: np.ndarray
    alpha: np.ndarray
    seconds: float

    @property
    def meshes(self) -> np.ndarray:
        """(T, N, 2) the cartoon mesh as shown (with the head's similarity when it follows)."""
        return self.still if self.head is None else self.head.apply(self.still)


class CartoonAnimator:
    """Built once per (cartoon, capture): the RBF correspondence, the eq. 13 scale and the
    factorised fold-free solver of the warp mesh.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB cartoon
    image_landmarks : (L, 2) landmarks on the cartoon (pixels)
    capture_landmarks : (L, 2) the same landmarks on the capture's first frame (pixels)
    capture_vertices : (N, 2) the capture's first-frame mesh
    faces : (M, 3) the capture mesh's triangles
    c : multiquadric shape parameter (default: Hardy's rule, :func:`.rbf.default_shape_parameter`)
    border : width of a static band around the mesh, as a fraction of the mesh's size (default 0.4):
        the band's triangles join the moving mesh boundary to a still outer ring, so the face
        outline leaves no seam when it moves. 0 is the paper's warp exactly (pixels outside the
        mesh keep the source image).
    head : "still" (default: the cartoon keeps its size and place, only the expression moves it)
        or "follow" (the whole cartoon image also moves, turns and scales with the head)
    fold_free : True (default): :mod:`.foldfree` keeps every triangle of the warp mesh from
        flipping and lip/eyelid contacts close (:func:`close_contacts`, 68 landmarks); False: the
        paper's eq. 12 target as it is (folds where the capture's points cross)
    amplitude : "feature" (default): in :meth:`drive`, each eye and the mouth move in their own
        proportions on the target, the brows with their eyes (:mod:`.featurescale`, eq. 12 per
        feature, 68 landmarks; with another landmark set ``self.amplitude`` becomes "uniform"); "uniform":
        one eq. 13 scale for the whole face, as the paper
    jaw : "lips" (default): in :meth:`drive`, with 68 landmarks, the face contour follows the lower lip
        instead of the captured contour, whose motion on a still head is mostly the head turning
        (:mod:`.jawline`); "capture": the captured contour

    Attributes
    ----------
    rest : (N, 2) the capture mesh placed on the cartoon (eq. 10)
    scale : eq. 13 ratio of mean edge lengths (cartoon mesh / capture mesh)
    """

    def __init__(self, image, image_landmarks, capture_landmarks, capture_vertices, faces, c: float | None = None,
                 border: float = 0.4, head: str = "still", fold_free: bool = True, interior: str = "smooth",
                 amplitude: str = "feature", jaw: str = "lips"):
        from .featurescale import parse_amplitude
        from .headmotion import parse_head_mode
        from .jawline import parse_jaw_mode

        self.image = _check_image(image)
        self.head_mode = parse_head_mode(head)
        self.amplitude = parse_amplitude(amplitude)
        self.jaw = parse_jaw_mode(jaw)
        lm_img = np.asarray(image_landmarks, np.float64)
        lm_cap = np.asarray(capture_landmarks, np.float64)
        if lm_img.shape != lm_cap.shape:
            raise InputError(f"cartoon landmarks: expected {lm_cap.shape[0]} points (the capture's count), "
                             f"found {lm_img.shape[0] if lm_img.ndim == 2 else lm_img.shape}")
        if not np.isfinite(border) or border < 0:
            raise InputError(f"border: expected a number >= 0, found {border}")
        self.faces = np.asarray(faces, np.int64)
        self.capture_landmarks = lm_cap
        if self.amplitude == "feature" and len(lm_cap) != 68:  # the features are the iBUG 68 points' eyes and mouth
            self.amplitude = "uniform"
        self.capture_rest = np.asarray(capture_vertices, np.float64)
        self.rbf = fit_rbf(lm_cap, lm_img, c)                                  # eq. 10-11
        self.rest = self.rbf(self.capture_rest)
        self.scale = edge_length_ratio(self.rest, self.faces, self.capture_rest, self.faces)   # eq. 13
        if border > 0:
            ring, band = static_band(self.rest, self.faces, self.image.shape[1], self.image.shape[0], border)
        else:
            ring, band = np.zeros((0, 2)), np.zeros((0, 3), np.int64)
        self.ring = ring
        # band first, the capture mesh last: where they overlap the mesh's own triangles win
        self.warp_faces = np.concatenate([band, self.faces]).astype(np.int64)
        self.warp_rest = np.concatenate([self.rest, ring])
        if interior not in INTERIOR_MODES:
            raise InputError(f"interior: expected one of {', '.join(INTERIOR_MODES)}, found {interior!r}")
        self.interior = interior
        self._smooth = None
        L = len(lm_cap)
        if interior == "smooth" and len(self.rest) > L:
            from .drive3d import biharmonic_basis

            n = len(self.rest)
            handles = np.r_[np.arange(L), np.arange(n, n + len(ring))]
            # columns of the ring handles are not needed: the ring never moves
            self._smooth = biharmonic_basis(self.warp_rest, self.warp_faces, handles)[L:n, :L]   # (N - L, L)
        self.mouth_cut = mouth_is_cut(self.faces, L)
        # the mouth (:mod:`.mouth2d`): a cut mesh gets its inner-lip triangles back for drawing only,
        # and with 68 landmarks the opening is painted as an open mouth (:mod:`.mouthpaint`)
        self.draws_mouth = L == 68
        self.mouth_chroma = image_chroma(self.image, self.rest[48:68]) if self.draws_mouth else 1.0
        # the eyes' lid, lower-lid and lash colours, for the lids drawn over a closing eye (:mod:`.eyepaint`)
        self.eye_colours = [eye_colours(self.image, self.rest[i]) for i in EYES_68] if self.draws_mouth else []
        self.draw_faces = np.concatenate([self.warp_faces, MOUTH_STRIP_68]) if self.mouth_cut else self.warp_faces
        self.fold_free = bool(fold_free)
        self.solver = None
        if self.fold_free:
            from .foldfree import FoldFreeMap

            n = len(self.rest)
            self.solver = FoldFreeMap(self.warp_rest, self.warp_faces, np.arange(n, n + len(ring)))

    def mesh(self, capture_vertices) -> np.ndarray:
        """Cartoon mesh (..., N, 2) for captured vertices (..., N, 2): ``rest + s (v_t - v_0)`` (eq. 12)."""
        V = np.asarray(capture_vertices, np.float64)
        return self.rest + self.scale * (V - self.capture_rest)

    def drive(self, capture_vertices, capture_landmarks) -> CartoonDrive:
        """Plan every frame's cartoon mesh from the capture (vectorised over frames, then the
        fold-free solve per frame where it is needed).

        1. the head's similarity per frame (:func:`.headmotion.fit_head_motion`, stable landmarks
           against the first frame) is taken out of the captured vertices;
        2. eq. 12 on what is left: ``rest + s (v'_t - v_0)``, with ``amplitude`` "feature" each eye
           and the mouth by its own 2x2 map (a brow with its eye) instead of ``s``
           (:mod:`.featurescale`, from the capture's frame 0, the frame the correspondence is
           trained on, to the rest); with ``jaw`` "lips" the face contour then follows the cartoon's lower
           lip (:func:`.jawline.jaw_from_lips`);
        3. with ``fold_free``: lip and eyelid contacts close (:func:`close_contacts`), then
           :class:`.foldfree.FoldFreeMap` makes every triangle keep its orientation;
        4. with head "follow", the similarity is carried over to the cartoon (same rotation and
           scale, translation times s) and applied to the whole image by :meth:`frame_at`.

        Parameters
        ----------
        capture_vertices : (T, N, 2); capture_landmarks : (T, L, 2), frame 0 being the one the
            animator was built on
        """
        import time

        from .headmotion import fit_head_motion

        t0 = time.perf_counter()
        V = np.asarray(capture_vertices, np.float64)
        lm = np.asarray(capture_landmarks, np.float64)
        if V.ndim != 3 or V.shape[1:] != self.capture_rest.shape:
            raise InputError(f"capture vertices: expected shape (T, {len(self.capture_rest)}, 2), found {V.shape}")
        if lm.ndim != 3 or lm.shape[1:] != self.capture_landmarks.shape or len(lm) != len(V):
            raise InputError(f"capture landmarks: expected shape ({len(V)}, {len(self.capture_landmarks)}, 2), "
                             f"found {lm.shape}")
        motion = fit_head_motion(lm, self.capture_landmarks)
        V = motion.remove(V)
        if self.amplitude == "feature":                       # eq. 12 per feature
            from .featurescale import feature_maps

            maps = feature_maps(self.capture_landmarks, self.rest[:68], self.scale)
            target = self.rest + maps.apply(V - self.capture_rest)
        else:
            target = self.mesh(V)
        if self.jaw == "lips" and len(self.capture_landmarks) == 68:
            from .jawline import jaw_from_lips

            # the contour: the jaw opening with the cartoon's own lower lip (its mouth's map with amplitude
            # "feature"), not the head's turns
            target = jaw_from_lips(target, self.rest)
        if self._smooth is not None:                 # the interior follows the landmarks smoothly
            L = len(self.capture_landmarks)
            target[:, L:] = self.rest[L:] + np.einsum("vl,tlc->tvc", self._smooth, target[:, :L] - self.rest[:L])
        T = len(V)
        folded = np.zeros(T, np.int64)
        iters = np.zeros(T, np.int64)
        alpha = np.ones(T)
        if self.fold_free:
            if len(self.capture_landmarks) == 68:
                target = close_contacts(target, self.rest, CONTACTS_68, self.solver.sigma_lo)
            n = len(self.rest)
            still = np.empty_like(target)
            for t in range(T):                       # frames, each a vectorised solve
                X, st = self.solver.solve(np.concatenate([target[t], self.ring]))
                still[t] = X[:n]
                folded[t], iters[t], alpha[t] = st.folded_before, st.iterations, st.alpha
        else:
            still = target
        head = None
        if self.head_mode == "follow":
            from .headmotion import stable_landmarks

            idx = stable_landmarks(len(self.capture_landmarks))
            c0 = self.capture_landmarks[idx].mean(0)
            head = motion.conjugated(c0, self.rbf(c0[None])[0], self.scale)
        return CartoonDrive(still, head, folded, iters, alpha, time.perf_counter() - t0)

    def warp(self, cartoon_vertices) -> np.ndarray:
        """The cartoon warped so that ``rest`` moves to ``cartoon_vertices`` (N, 2); (H, W, C) uint8.

        With 68 landmarks the mouth opening (inner-lip polygon, iBUG 60-67), as it opens beyond the
        target's own mouth, is painted as a mouth interior (:func:`.mouthpaint.paint_mouth`: upper teeth,
        a cavity darkest in the middle, the tongue, with :func:`.mouth2d.opening_opacity`: a closed-mouth
        painting driven open shows an open mouth, not
        stretched lips; the target at rest is left as it is drawn); a capture mesh cut
        open along closed lips (:func:`mouth_is_cut`) is drawn with its inner-lip triangles
        (:data:`.mouth2d.MOUTH_STRIP_68`) so that no still pixel shows through the gap. An eye more closed than
        the target's own gets its upper lid drawn down over the unsquashed eye, with a lash line
        (:func:`.eyepaint.paint_eye`)."""
        V = np.asarray(cartoon_vertices, np.float64)
        out = warp_image(self.image, self.warp_rest, np.concatenate([V, self.ring]), self.draw_faces)
        if self.draws_mouth:
            mouth = V[INNER_LIP_68]
            paint_mouth(out, mouth, opacity=opening_opacity(mouth, self.rest[INNER_LIP_68]), chroma=self.mouth_chroma)
            for i, colours in zip(EYES_68, self.eye_colours):    # a closing eye: its lid drawn down over it
                paint_eye(out, self.image, V[i], self.rest[i], colours)
        return out

    def frame_at(self, drive: CartoonDrive, t: int) -> np.ndarray:
        """Frame t of a :class:`CartoonDrive`: the still warp, then (head "follow") the whole image
        moved by the head's similarity (bilinear, edges repeated)."""
        out = self.warp(drive.still[t])
        if drive.head is not None:
            import cv2

            out = cv2.warpAffine(out, drive.head.affine(t), (out.shape[1], out.shape[0]), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REPLICATE)
        return out

    def frame(self, capture_vertices) -> np.ndarray:
        """One frame for the captured vertices (N, 2) by eq. 12 alone (no head removal, no fold check)."""
        return self.warp(self.mesh(capture_vertices))


@dataclass(frozen=True)
class CartoonAnimation:
    """Result of :func:`animate_cartoon`: frames (T, H, W, C) uint8, meshes (T, N, 2), faces (M, 3),
    the eq. 13 scale and the rest mesh on the cartoon (N, 2)."""

    frames: np.ndarray
    meshes: np.ndarray
    faces: np.ndarray
    scale: float
    rest: np.ndarray


def animate_cartoon(image, image_landmarks, capture_landmarks, capture_vertices, faces, c=None,
                    border: float = 0.4, head: str = "still", fold_free: bool = True,
                    interior: str = "smooth", amplitude: str = "feature", jaw: str = "lips") -> CartoonAnimation:
    """One-off: animate ``image`` by captured vertices (T, N, 2) (:meth:`CartoonAnimator.drive`).

    ``capture_landmarks`` is (T, L, 2) (frame 0 trains the RBF, all frames give the head's
    motion) or (L, 2) (the first frame; then the first L captured vertices are taken as the
    landmarks of every frame).
    """
    V = np.asarray(capture_vertices, np.float64)
    lm = np.asarray(capture_landmarks, np.float64)
    lm_all = lm if lm.ndim == 3 else V[:, :len(lm)]
    anim = CartoonAnimator(image, image_landmarks, lm_all[0], V[0], faces, c, border, head, fold_free, interior,
                           amplitude, jaw)
    drive = anim.drive(V, lm_all)
    frames = np.stack([anim.frame_at(drive, t) for t in range(len(V))])
    return CartoonAnimation(frames, drive.meshes, anim.faces, anim.scale, anim.rest)


__all__ = ["static_band", "close_contacts", "fill_mouth", "mouth_is_cut", "MOUTH_INTERIOR_RGB", "CONTACTS_68", "INTERIOR_MODES", "CartoonDrive", "CartoonAnimator",
           "CartoonAnimation", "animate_cartoon"]
