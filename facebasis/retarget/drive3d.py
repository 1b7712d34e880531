"""3D reproduction: drive a target mesh by the captured landmark motion (paper, 3D reproduction, with
eq. 10-13).

The paper drives the target's points that correspond to the capture and deforms the rest of the
mesh smoothly. Here the driven points are the target's landmark vertices (one per capture
landmark); their motion is the captured 2D landmark displacement ``p_l(t) - p_l(0)`` scaled by
eq. 13 (the ratio of mean edge lengths of the capture mesh placed on the target by the
multiquadric RBF of eq. 10-11, in the target's image plane, to the capture mesh), applied in the
mesh's image-plane axes: image x -> mesh +x, image y (down) -> mesh -y.

Head motion: the capture's in-plane head similarity (scale, rotation, shift; Procrustes on stable
landmarks, :mod:`.headmotion`) is taken out of the landmarks first, so by default (``head="still"``)
the mesh keeps its size and place and shows the expression only; ``head="follow"`` then applies that
similarity to the whole mesh (rotation about the view axis z, uniform scale about the landmark
centroid, the shift scaled by eq. 13).

How z is handled: a single video gives no depth, so the driven points get no z displacement and the
smooth deformation, solved per coordinate, leaves z unchanged everywhere: the motion is in the
mesh's x-y plane (a frontal view of the face).

The rest of the mesh follows by a biharmonic deformation: the displacement field d minimises
``d^T (L^T M^-1 L + eps M) d`` (cotangent Laplacian L, lumped Voronoi/barycentric mass M; the eps
term keeps parts without any driven point still) with the driven points fixed. The free block is
factorised once (sparse LU), and solved once for all L driven points, giving a dense basis
``W`` (n, L) with ``d = W delta`` (delta (L, 2) the driven displacements): each frame is then one
(n, L) x (L, 2) product.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, MeshError
from ..geometry.laplacian import cotangent_laplacian, lumped_mass
from .rbf import edge_length_ratio, fit_rbf


def biharmonic_basis(V, F, handles, eps: float = 1e-9) -> np.ndarray:
    """Dense deformation basis W (n, h): the biharmonic displacement of every vertex when handle j
    moves by 1 and the other handles stay (handle rows of W are the identity).

    One sparse LU factorisation of the free block, solved for all h right-hand sides at once.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    V = np.asarray(V, np.float64)
    n = len(V)
    h = np.asarray(handles, np.int64)
    L, mass = cotangent_laplacian(V, F).tocsc(), lumped_mass(V, F)
    m = np.where(mass > 0, mass, max(float(mass[mass > 0].mean()) if (mass > 0).any() else 1.0, 1e-12))
    A = (L.T @ sp.diags(1.0 / m) @ L).tocsc()
    # eps relative to the operator's scale: parts with no handle (e.g. separate components) stay put
    scale = float(A.diagonal().mean() / m.mean())
    A = (A + eps * scale * sp.diags(m)).tocsc()
    free = np.ones(n, bool)
    free[h] = False
    fi = np.flatnonzero(free)
    W = np.zeros((n, len(h)))
    W[h, np.arange(len(h))] = 1.0
    if len(fi):
        A_ff = A[fi][:, fi].tocsc()
        A_fh = A[fi][:, h].toarray()
        try:
            lu = splu(A_ff)                                # factor once
        except RuntimeError as exc:
            raise MeshError(f"mesh deformation: the smoothness matrix is singular ({exc})") from exc
        W[fi] = lu.solve(-A_fh)
    return W


@dataclass(frozen=True)
class MeshAnimation:
    """Result of :class:`MeshDriver`: vertices (T, n, 3), faces (m, 3), the driven vertex indices (L,),
    the eq. 13 scale, the capture's fps."""

    vertices: np.ndarray
    faces: np.ndarray
    indices: np.ndarray
    scale: float
    fps: float
    seconds: float


class MeshDriver:
    """Built once per (target mesh, landmark vertices, capture first frame).

    Parameters
    ----------
    vertices : (n, 3) target mesh (x right, y up, facing +z); faces : (m, 3)
    indices : (L,) target vertices driven by the capture's L landmarks
    capture_landmarks : (L, 2) first-frame landmarks (pixels)
    capture_vertices : (N, 2) first-frame capture mesh and capture_faces (K, 3), for eq. 13
    eps : biharmonic regularisation (relative)
    """

    def __init__(self, vertices, faces, indices, capture_landmarks, capture_vertices=None, capture_faces=None,
                 eps: float = 1e-9, head: str = "still"):
        from .headmotion import parse_head_mode

        self.head_mode = parse_head_mode(head)
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(faces, np.int64)
        self.indices = np.asarray(indices, np.int64)
        lm0 = np.asarray(capture_landmarks, np.float64)
        if len(np.unique(self.indices)) != len(self.indices):
            raise InputError("landmark indices: expected distinct vertices, found repeats")
        if lm0.shape != (len(self.indices), 2):
            raise InputError(f"capture landmarks: expected shape ({len(self.indices)}, 2), found {lm0.shape}")
        self.lm0 = lm0
        # eq. 10-11: the capture mesh placed on the target's image plane (x, -y)
        target_xy = self.V[self.indices, :2] * [1.0, -1.0]
        cv = lm0 if capture_vertices is None else np.asarray(capture_vertices, np.float64)
        if capture_faces is None:
            from scipy.spatial import Delaunay

            capture_faces = Delaunay(cv).simplices
        cf = np.asarray(capture_faces, np.int64)
        self.rbf = fit_rbf(lm0, target_xy)
        self.scale = edge_length_ratio(self.rbf(cv), cf, cv, cf)            # eq. 13
        t0 = time.perf_counter()
        self.W = biharmonic_basis(self.V, self.F, self.indices, eps)        # factor once
        self.setup_seconds = time.perf_counter() - t0

    def head_motion(self, landmarks):
        """:class:`.headmotion.HeadMotion` of landmarks (T, L, 2) against the first frame's."""
        from .headmotion import fit_head_motion

        return fit_head_motion(np.asarray(landmarks, np.float64), self.lm0)

    def handle_displacements(self, landmarks) -> np.ndarray:
        """Driven displacements (..., L, 2) in mesh x, y for captured landmarks (..., L, 2) (eq. 12),
        the head's similarity taken out first."""
        lm = np.asarray(landmarks, np.float64)
        single = lm.ndim == 2
        lm3 = lm[None] if single else lm.reshape((-1,) + lm.shape[-2:])
        expr = self.head_motion(lm3).remove(lm3).reshape(lm.shape)
        d = self.scale * (expr - self.lm0)
        return d * np.array([1.0, -1.0])

    def _follow(self, frames, motion) -> np.ndarray:
        """Apply the head's similarity per frame to whole meshes (T, n, 3), in place and returned."""
        from .headmotion import stable_landmarks

        idx = stable_landmarks(len(self.lm0))
        c0 = self.lm0[idx].mean(0)
        moved = motion.a * complex(*c0) + motion.b - complex(*c0)            # capture centre shift (px)
        a = np.conj(motion.a)                                               # y up: the turn reverses
        shift = self.scale * np.conj(moved)                                 # (T,) mesh units, y up
        cm = self.V[self.indices[idx]].mean(0)
        z = (frames[..., 0] - cm[0]) + 1j * (frames[..., 1] - cm[1])
        z = cm[0] + 1j * cm[1] + a[:, None] * z + shift[:, None]
        frames[..., 0], frames[..., 1] = z.real, z.imag
        frames[..., 2] = cm[2] + np.abs(motion.a)[:, None] * (frames[..., 2] - cm[2])
        return frames

    def frame(self, landmarks) -> np.ndarray:
        """Deformed vertices (n, 3) for one frame's landmarks (L, 2)."""
        d = self.W @ self.handle_displacements(landmarks)
        out = self.V.copy()
        out[:, :2] += d
        if self.head_mode == "follow":
            out = self._follow(out[None], self.head_motion(np.asarray(landmarks, np.float64)[None]))[0]
        return out

    def run(self, landmarks, fps: float = 30.0) -> MeshAnimation:
        """All frames (T, L, 2) -> :class:`MeshAnimation`."""
        lm = np.asarray(landmarks, np.float64)
        if lm.ndim != 3 or lm.shape[1:] != self.lm0.shape:
            raise InputError(f"capture landmarks: expected shape (T, {len(self.lm0)}, 2), found {lm.shape}")
        t0 = time.perf_counter()
        D = self.handle_displacements(lm)                                    # (T, L, 2)
        out = np.repeat(self.V[None], len(lm), axis=0)
        out[:, :, :2] += np.einsum("nl,tlc->tnc", self.W, D)
        if self.head_mode == "follow":
            out = self._follow(out, self.head_motion(lm))
        return MeshAnimation(out, self.F, self.indices, self.scale, float(fps), time.perf_counter() - t0)

    def morph_basis(self, landmarks, tol: float = 1e-3):
        """The animation as morph targets with weights in [0, 1].

        The displacement of every frame is ``W delta_t``, linear in the driven displacements
        delta_t (2L,). An SVD of the frames' delta (T, 2L) keeps the fewest components r for which
        no driven point of any frame is off by more than ``tol`` times the mesh's bounding-box
        diagonal; each component becomes two targets, ``+m_k B_k`` and ``-m_k B_k`` (``B_k = W v_k``,
        ``m_k`` the largest |coefficient|), whose weights are the positive and the negative part of
        the coefficient divided by ``m_k``. Splitting a coefficient this way is linear between keys,
        so glTF's LINEAR interpolation reproduces it exactly.

        Returns targets (2r, n, 3), names (2r,), weights (T, 2r); :meth:`morph_error` measures the
        largest vertex error.
        """
        D = self.handle_displacements(np.asarray(landmarks, np.float64))
        T, L = D.shape[:2]
        if self.head_mode == "follow":          # not linear in D any more: components of the whole motion
            return self._morph_basis_follow(landmarks, tol)
        H = D.reshape(T, -1)
        U, S, Vt = np.linalg.svd(H, full_matrices=False)
        limit = tol * float(np.linalg.norm(np.ptp(self.V, axis=0)))
        resid = H.copy()
        r = 0
        while r < len(S) and np.abs(resid).max() > limit:       # components, not vertices
            resid -= np.outer(U[:, r] * S[r], Vt[r])
            r += 1
        coef = U[:, :r] * S[:r]                                              # (T, r)
        m = np.abs(coef).max(axis=0) if r else np.zeros(0)
        B = np.einsum("nl,rlc->rnc", self.W, Vt[:r].reshape(r, L, 2))        # (r, n, 2)
        targets = np.zeros((2 * r, len(self.V), 3))
        targets[0::2, :, :2] = B * m[:, None, None]
        targets[1::2, :, :2] = -B * m[:, None, None]
        weights = np.zeros((T, 2 * r))
        weights[:, 0::2] = np.maximum(coef, 0) / np.where(m > 0, m, 1)
        weights[:, 1::2] = np.maximum(-coef, 0) / np.where(m > 0, m, 1)
        names = [f"motion{k:02d}{sign}" for k in range(r) for sign in ("+", "-")]
        return targets, names, weights

    def _morph_basis_follow(self, landmarks, tol):
        """:meth:`morph_basis` with the head's similarity (head "follow").

        A frame is ``V + (A_t - I)(V - c) + W (D_t A_t^T) + tau_t`` in x, y (z scaled by rho_t about
        c): linear in the per-frame coefficients h_t = (D_t A_t^T, A_t - I, rho_t - 1, tau_t) over a
        fixed lifted basis Phi (3n, 2L + 7). With Phi = QR, the SVD of ``h R^T`` (T, 2L + 7) gives the
        components (rows of ``V^T Q^T``) without forming the (T, 3n) frames; the fewest are kept for
        which every frame's displacement error (its norm, a bound on any vertex's) is within tol.
        """
        from .headmotion import stable_landmarks

        lm = np.asarray(landmarks, np.float64)
        motion = self.head_motion(lm)
        D = self.handle_displacements(lm)                                   # (T, L, 2)
        T, L = D.shape[:2]
        n = len(self.V)
        a = np.conj(motion.a)
        A = np.stack([np.stack([a.real, -a.imag], -1), np.stack([a.imag, a.real], -1)], 1)   # (T, 2, 2)
        E = np.einsum("tlj,tij->tli", D, A)                                 # D_t A_t^T
        idx = stable_landmarks(len(self.lm0))
        c0 = self.lm0[idx].mean(0)
        moved = motion.a * complex(*c0) + motion.b - complex(*c0)
        shift = self.scale * np.conj(moved)
        cm = self.V[self.indices[idx]].mean(0)
        rel = self.V - cm
        k = 2 * L + 7
        Phi = np.zeros((n, 3, k))
        Phi[:, 0, 0:2 * L:2] = self.W                                       # E[:, l, x]
        Phi[:, 1, 1:2 * L:2] = self.W                                       # E[:, l, y]
        for i in range(2):                                                  # (A - I)[i, j] (V - c)_j
            for j in range(2):
                Phi[:, i, 2 * L + 2 * i + j] = rel[:, j]
        Phi[:, 2, 2 * L + 4] = rel[:, 2]                                    # (rho - 1)(z - c_z)
        Phi[:, 0, 2 * L + 5] = 1.0
        Phi[:, 1, 2 * L + 6] = 1.0
        h = np.concatenate([E.reshape(T, -1), (A - np.eye(2)).reshape(T, 4), (np.abs(a) - 1.0)[:, None],
                            shift.real[:, None], shift.imag[:, None]], 1)
        Q, R = np.linalg.qr(Phi.reshape(3 * n, k))
        U, S, Vt = np.linalg.svd(h @ R.T, full_matrices=False)
        limit = tol * float(np.linalg.norm(np.ptp(self.V, axis=0)))
        coef_all = U * S
        # residual row norms for every r at once: the tail of the squared coefficients
        tail = np.sqrt(np.maximum(np.cumsum((coef_all ** 2)[:, ::-1], axis=1)[:, ::-1], 0.0))   # (T, k')
        ok = np.flatnonzero(np.r_[tail.max(0), 0.0] <= limit)
        r = int(ok[0]) if len(ok) else len(S)
        coef = coef_all[:, :r]
        m = np.abs(coef).max(axis=0) if r else np.zeros(0)
        B = (Vt[:r] @ Q.T).reshape(r, n, 3)
        targets = np.zeros((2 * r, n, 3))
        targets[0::2] = B * m[:, None, None]
        targets[1::2] = -B * m[:, None, None]
        weights = np.zeros((T, 2 * r))
        weights[:, 0::2] = np.maximum(coef, 0) / np.where(m > 0, m, 1)
        weights[:, 1::2] = np.maximum(-coef, 0) / np.where(m > 0, m, 1)
        names = [f"motion{k:02d}{sign}" for k in range(r) for sign in ("+", "-")]
        return targets, names, weights

    def morph_error(self, landmarks, targets, weights) -> float:
        """Largest vertex distance between :meth:`run`'s frames and the morph-target animation."""
        full = self.run(landmarks).vertices
        approx = self.V + np.tensordot(np.asarray(weights), np.asarray(targets), axes=(1, 0))
        return float(np.linalg.norm(full - approx, axis=2).max())


def drive_mesh(vertices, faces, indices, landmarks, capture_vertices=None, capture_faces=None,
               fps: float = 30.0, head: str = "still") -> MeshAnimation:
    """One-off: drive a mesh by landmarks (T, L, 2) (frame 0 is the rest pose)."""
    lm = np.asarray(landmarks, np.float64)
    cv = None if capture_vertices is None else np.asarray(capture_vertices, np.float64)[0]
    return MeshDriver(vertices, faces, indices, lm[0], cv, capture_faces, head=head).run(lm, fps)


__all__ = ["MeshDriver", "MeshAnimation", "drive_mesh", "biharmonic_basis"]
