"""Mesh tracking: Levenberg-Marquardt on ``E = E_data + lambda E_smooth`` (Wu & Ju 2016, eq. 1-5).

Given the mesh ``M_n`` in frame ``I_n`` and an initial guess for ``M_{n+1}`` (the harmonic
deformation driven by the tracked landmarks, eq. 7-9), find vertex positions in ``I_{n+1}`` that
minimise

* ``E_data`` (eq. 2-3): over triangles ``T``, the squared difference between the intensity *sum*
  inside ``T`` in ``I_n`` and inside the corresponding (affinely mapped, eq. 1) triangle in
  ``I_{n+1}``. The sum over the pixels ``p`` of ``T_n`` of ``I_n(p) - I_{n+1}(f(p))`` is evaluated
  with fixed barycentric sample points (the centroids of an ``n x n`` subdivision of the triangle,
  ``n^2`` points) and bilinear interpolation, times the triangle area in frame ``n`` (normalised by
  the mean area, a constant absorbed in ``lambda``). ``residuals_per_triangle=4`` splits each sum
  into the four midpoint sub-triangles (a finer variant; ``1`` is the paper's exact form).
* ``E_smooth`` (eq. 4): the cotangent Dirichlet energy ``delta^T K delta`` of the correction
  ``delta = V - V_init`` to the harmonic initialisation (edge weights clipped at zero).

Landmarks are held at their tracked positions (they are not unknowns). A vertex whose neighbourhood
has (almost) no image gradient in either frame is also held, so it stays exactly where the
harmonic initialisation put it. The Jacobian of ``E_data`` comes from the image gradients of
``I_{n+1}`` at the sample points and is assembled as a sparse matrix; nothing loops over triangles,
vertices or pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .particle import sample


#: up to this many unknown coordinates the LM normal equations are dense (a face mesh at the default
#: spacing has about 170: a dense solve takes a fraction of a millisecond, SciPy's sparse LU and
#: matrix assembly took most of the mesh stage); larger meshes use the sparse LU
DENSE_MAX = 600


@dataclass(frozen=True)
class MeshOptions:
    """Options of the mesh tracking.

    Attributes
    ----------
    smooth_weight : float
        ``lambda`` of eq. 5 for a face of the reference width
        (:data:`facebasis.capture.landmarks.REFERENCE_FACE_WIDTH`, 150 px). ``E_smooth`` is
        quadratic in pixel displacements while ``E_data`` is in grey levels, so a face ``s`` times
        that width (``s`` = face width / 150, not clipped) uses ``lambda / s^2``: the same motion
        filmed at any resolution gives the same solution in face units. (A fixed ``lambda``
        over-smoothed large faces: mesh vertices 0.61 px on a 205 px wide face against 0.26 px on
        the same face at 103 px.)
    iterations : int
        Levenberg-Marquardt iterations per frame (0 = harmonic initialisation only). 2: on the
        ground-truth benchmark (astronaut and cap12x2, 300 frames) 4 iterations gave the same mesh
        vertex error to 3 decimals (0.179 / 0.580 px) at 1.8x the mesh stage's time.
    subdivision : int
        ``n``: each triangle is sampled at ``n^2`` barycentric points.
    residuals_per_triangle : int
        1 (paper: one intensity sum per triangle) or 4 (one per midpoint sub-triangle; needs an
        even ``subdivision``).
    blur : float
        Gaussian blur (pixels at reference face size) applied before sampling.
    texture_threshold : float
        RMS image gradient (grey levels in [0, 1] per pixel, at the reference face width; divided
        by ``s``) below which a vertex is held at its initial position.
    max_step : float
        Largest vertex move per LM step, as a fraction of the mesh spacing.
    """

    smooth_weight: float = 7e-5
    iterations: int = 2
    subdivision: int = 4
    residuals_per_triangle: int = 4
    blur: float = 1.5
    texture_threshold: float = 1.4e-3
    max_step: float = 0.25


def barycentric_samples(n: int) -> np.ndarray:
    """Centroids of the ``n^2`` sub-triangles of an ``n``-subdivided triangle, ``(n^2, 3)`` barycentric."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (i + j) <= n - 1
    dn = (i + j) <= n - 2
    s = np.concatenate([(i[up] + 1 / 3) / n, (i[dn] + 2 / 3) / n])
    t = np.concatenate([(j[up] + 1 / 3) / n, (j[dn] + 2 / 3) / n])
    return np.stack([1 - s - t, s, t], 1)


def residual_groups(bary: np.ndarray, per_triangle: int) -> np.ndarray:
    """Averaging matrix from samples to residuals, shape ``(K, G)``: one group, or the 4 midpoint sub-triangles."""
    K = len(bary)
    if per_triangle == 1:
        return np.full((K, 1), 1.0 / K)
    if per_triangle != 4:
        from facebasis.errors import InputError

        raise InputError(f"residuals_per_triangle: expected 1 or 4, found {per_triangle}")
    corner = np.argmax(bary, axis=1)
    gid = np.where(bary.max(1) > 0.5, corner, 3)
    A = np.zeros((K, 4))
    A[np.arange(K), gid] = 1.0
    cnt = A.sum(0)
    if np.any(cnt == 0):
        from facebasis.errors import InputError

        raise InputError("residuals_per_triangle=4 needs subdivision >= 2")
    return A / cnt


def prepare_image(gray: np.ndarray, sigma: float):
    """Blurred image and its x, y gradients (float32, per pixel)."""
    import cv2

    g = cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else gray
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8)
    return g, gx, gy


class MeshRefiner:
    """Levenberg-Marquardt refinement of mesh vertex positions between consecutive frames.

    Parameters
    ----------
    V0 : ndarray, shape (N, 2)
        First-frame mesh (for areas and the smoothness operator).
    F : ndarray, shape (M, 3)
    held : ndarray, shape (N,) bool
        Vertices that are never unknowns (the landmarks).
    spacing : float
        Mesh spacing in pixels (limits the step length).
    options : MeshOptions
    size : float
        Face width over the reference width (``s`` of :class:`MeshOptions`, not clipped): the
        smoothness weight is divided by ``s^2`` and the texture threshold by ``s``.
    """

    def __init__(self, V0, F, held, spacing, options: MeshOptions = MeshOptions(), size: float = 1.0):
        from facebasis.geometry.laplacian import cotangent_laplacian

        self.opt = options
        size = float(size)
        self.lam = options.smooth_weight / size ** 2
        self.texture = options.texture_threshold / size
        self.F = np.asarray(F, int)
        self.N = len(V0)
        self.held = np.asarray(held, bool)
        self.spacing = float(spacing)
        self.bary = barycentric_samples(options.subdivision)  # (K, 3)
        self.agg = residual_groups(self.bary, options.residuals_per_triangle)  # (K, G)
        self.K = cotangent_laplacian(V0, F, clip_negative=True).tocsr()  # E_smooth operator, eq. 4
        self._Kd = self.K.toarray() if 2 * self.N <= DENSE_MAX else None    # dense copy for the dense path
        a0 = np.abs(_areas(V0, self.F))
        self.mean_area = float(a0.mean())
        # residual g of triangle T from its samples' image gradient: (K, G * 3) factors agg[k, g] b_kj
        self._AB = np.einsum("kg,kj->kgj", self.agg, self.bary).reshape(len(self.bary), -1)

    def _samples(self, V):
        return self.bary @ V[self.F]  # (M, K, 2), eq. 1 affine map

    def _unknowns(self, prev, nxt, Xp, V_init) -> np.ndarray:
        """Vertices solved for, ``(U,)``: not held, with an RMS image gradient around them (both frames)
        of at least ``texture_threshold``."""
        _, gx, gy = nxt
        F = self.F
        Xi = self._samples(V_init)
        g2 = 0.5 * (sample(gx, Xi) ** 2 + sample(gy, Xi) ** 2 + _grad2(prev, Xp))  # mean |grad I|^2 of both frames
        tri_g2 = g2.mean(1)
        vsum = np.bincount(F.ravel(), np.repeat(tri_g2, 3), minlength=self.N)
        vcnt = np.bincount(F.ravel(), minlength=self.N)
        textured = np.sqrt(vsum / np.maximum(vcnt, 1)) >= self.texture
        return np.flatnonzero(~self.held & textured)

    def refine(self, prev, nxt, V_prev: np.ndarray, V_init: np.ndarray) -> np.ndarray:
        """Refine ``V_init`` (positions in the new frame).

        Parameters
        ----------
        prev : tuple
            ``prepare_image`` output of frame ``n``.
        nxt : tuple
            ``prepare_image`` output of frame ``n + 1``.
        V_prev : ndarray, shape (N, 2)
            Mesh in frame ``n``.
        V_init : ndarray, shape (N, 2)
            Harmonic initialisation in frame ``n + 1`` (eq. 9).

        Returns
        -------
        ndarray, shape (N, 2)
            Refined positions; held vertices equal ``V_init``.
        """
        o = self.opt
        if o.iterations <= 0:
            return V_init.copy()
        Ip, _, _ = prev
        In, gx, gy = nxt
        F, M = self.F, len(self.F)
        Xp = self._samples(V_prev)
        s_prev = sample(Ip, Xp)  # (M, K): I_n at the samples of T_n
        area = np.abs(_areas(V_prev, F)) / self.mean_area  # eq. 2: sum = area x mean
        U = self._unknowns(prev, nxt, Xp, V_init)
        if len(U) == 0:
            return V_init.copy()
        col = np.full(self.N, -1)
        col[U] = np.arange(len(U))
        n = 2 * len(U)
        dense = n <= DENSE_MAX
        if dense and self._Kd is not None:   # (2U, 2U), unknowns ordered (u, coordinate)
            K2 = np.kron(self._Kd[np.ix_(U, U)], np.eye(2))
        else:
            K2 = sp.kron(self.K[U][:, U], sp.eye(2), format="csr")
            if dense:
                K2 = K2.toarray()
        lam = self.lam
        G = self.agg.shape[1]
        dof, pair, pair_ok = _jacobian_pattern(col[F])
        def residual(V):
            X = self._samples(V)
            diff = s_prev - sample(In, X)  # eq. 2: I_n(p) - I_{n+1}(f(p))
            return area[:, None] * (diff @ self.agg), X  # (M, G)

        def energy(r, d):
            return float((r ** 2).sum() + lam * d @ (K2 @ d))  # eq. 5

        V = V_init.copy()
        delta = np.zeros(2 * len(U))
        r, X = residual(V)
        E = energy(r, delta)
        mu = 1e-2
        step_cap = o.max_step * self.spacing
        sign0 = np.sign(_areas(V_init, F))
        for _ in range(o.iterations):
            grad = np.stack([sample(gx, X), sample(gy, X)], 1)  # (M, 2, K)
            # d r_{T,g} / d v_{F[T,j], c} = -area_T * sum_k agg[k,g] b_kj dI/dc (eq. 3 Jacobian), (M, G, 6)
            Jv = (grad @ self._AB).reshape(M, 2, G, 3).transpose(0, 2, 3, 1).reshape(M, G, 6)
            Jv *= -area[:, None, None] * (dof >= 0)[:, None, :]
            # normal equations assembled from per-triangle 6 x 6 blocks (nothing loops over triangles)
            JtJ = Jv.transpose(0, 2, 1) @ Jv                      # (M, 6, 6)
            Jtr = (Jv.transpose(0, 2, 1) @ r[..., None])[..., 0]  # (M, 6)
            g = np.bincount(dof[dof >= 0], Jtr[dof >= 0], minlength=n) + lam * (K2 @ delta)
            if dense:
                Hb = np.bincount(pair, JtJ[pair_ok], minlength=n * n).reshape(n, n) + lam * K2
                diag = np.diagonal(Hb) + 1e-9
            else:
                Hb = sp.csr_matrix((JtJ[pair_ok], (pair // n, pair % n)), shape=(n, n)) + lam * K2
                diag = Hb.diagonal() + 1e-9
            for _try in range(4):
                try:
                    step = -(np.linalg.solve(Hb + np.diag(mu * diag), g) if dense
                             else splu((Hb + sp.diags(mu * diag)).tocsc()).solve(g))
                except (RuntimeError, np.linalg.LinAlgError):
                    mu *= 10
                    continue
                s2 = step.reshape(-1, 2)
                length = np.linalg.norm(s2, axis=1, keepdims=True)
                s2 = s2 * np.minimum(1.0, step_cap / np.maximum(length, 1e-12))
                d_new = delta + s2.ravel()
                V_new = V_init.copy()
                V_new[U] += d_new.reshape(-1, 2)
                if np.any(np.sign(_areas(V_new, F)) != sign0):
                    mu *= 10
                    continue
                r_new, X_new = residual(V_new)
                E_new = energy(r_new, d_new)
                if E_new < E:
                    V, delta, r, X, E = V_new, d_new, r_new, X_new, E_new
                    mu = max(mu / 10, 1e-6)
                    break
                mu *= 10
            else:
                break
        return V


def _areas(V, F):
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _grad2(prep, X):
    _, gx, gy = prep
    return sample(gx, X) ** 2 + sample(gy, X) ** 2


def _jacobian_pattern(colF: np.ndarray):
    """Unknowns of each triangle's 6 coordinates and the normal matrix entries they fill.

    ``colF (M, 3)``: unknown number of each corner (-1: held). Returns ``dof (M, 6)`` (coordinate
    ``2 u + c`` of corner ``j`` at ``2 j + c``, -1 where held), and for the pairs of unknown coordinates
    of a triangle the flat index ``row * n + col`` into the ``(n, n)`` normal matrix and the mask
    ``(M, 6, 6)`` selecting them (``n`` = twice the number of unknowns).
    """
    n = 2 * (int(colF.max()) + 1)
    dof = np.where(colF[:, :, None] >= 0, colF[:, :, None] * 2 + np.arange(2), -1).reshape(len(colF), 6)
    ok = (dof[:, :, None] >= 0) & (dof[:, None, :] >= 0)
    pair = (dof[:, :, None] * n + dof[:, None, :])[ok]
    return dof, pair, ok
