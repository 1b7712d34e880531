"""One frame of rig driving: the pose/weight alternation of :mod:`.rigdrive` as a frozen solver.

:class:`FrameSolver` holds everything one frame's fit needs (the neutral landmarks ``v0`` (L, 3),
the landmark deltas ``D`` (L, 3, k) and the frozen settings of the weight model, eq. 5 with the data
term of the rig-driving model); :meth:`FrameSolver.solve_frame` returns a :class:`FrameFit`. Nothing
here changes its own state: a calibration (:mod:`.calibrate`) or the "auto" ridge of
:class:`.rigdrive.RigRetargeter` builds a new solver with :meth:`FrameSolver.with_neutral`,
:meth:`FrameSolver.shifted`, :meth:`FrameSolver.pilot` or :func:`dataclasses.replace`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, parameter_error
from .pose import PI, contour_weights, fit_pose_affine, fit_pose_gn, pose_jacobian, whiten

#: smallest ridge of the "auto" rule (and the pilot fit's ridge): noise-free captures are solved with it
RIDGE_FLOOR = 1e-3


def _number(name, value, expected):
    try:
        return np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise parameter_error(name, expected, repr(value)) from None


def check_camera(focal, centre) -> tuple[float, np.ndarray | None]:
    """The camera of :class:`FrameSolver` checked: (focal length px, inf for None; principal point
    (2,) px or None). A bad value is one :class:`InputError` naming the parameter."""
    f = float("inf") if focal is None else _number("focal", focal, "a focal length in pixels > 0")
    if focal is not None and not (np.ndim(f) == 0 and np.isfinite(f) and f > 0):
        raise parameter_error("focal", "a focal length in pixels > 0", repr(focal))
    c = None if centre is None else _number("centre", centre, "two pixel coordinates (x, y)")
    if c is not None and (c.shape != (2,) or not np.isfinite(c).all()):
        raise parameter_error("centre", "two finite pixel coordinates (x, y)", repr(centre))
    return float(f), c


@dataclass(frozen=True)
class FrameFit:
    """One frame's fit (:meth:`FrameSolver.solve_frame`): weights x (k,), scale s (px per rig
    unit), rotation R (3, 3), translation t (2,) px, rms landmark residual px (visible landmarks;
    nan when too few were visible), branch-and-bound nodes, and ``flat`` (L, 2): the landmarks as
    the weak-perspective model saw them (:meth:`FrameSolver.flatten` at the fitted pose; the
    landmarks themselves without a focal length). Unpacks as the former 6-tuple
    ``x, s, R, t, rms, nodes``."""

    x: np.ndarray
    s: float
    R: np.ndarray
    t: np.ndarray
    rms: float
    nodes: int
    flat: np.ndarray | None = None


    @property
    def state(self) -> tuple:
        """(x, s, R, t): the warm start of the next frame."""
        return self.x, self.s, self.R, self.t

    def __iter__(self):
        return iter((self.x, self.s, self.R, self.t, self.rms, self.nodes))


@dataclass(frozen=True, eq=False)
class FrameSolver:
    """The per-frame fit of :mod:`.rigdrive` with frozen settings (see its module docstring).

    Attributes
    ----------
    v0 : (L, 3) neutral landmark positions (rig units)
    D : (L, 3, k) landmark deltas of the k shapes
    pairs : (p, 2) int64 exclusive shape pairs
    smooth, ridge, sparsity : mu, rho and the sparse part of the weight prior
    contour : (c,) int64 landmark indices of a sliding contour; contour_slide its along-contour weight
    alternations, tol : pose/weight rounds of a warm-started frame; they end when the weights change by
        at most tol and the scale by at most tol times itself
    ipopt : a :class:`facebasis.rigging.weights.WeightSolver` (``solver="ipopt"``) or None (certified)
    pixel_scale : None: the data term in rig units (landmark noise of a fixed size on the face); a
        scale s_ref (px per rig unit): the data term in pixels over s_ref, i.e. each frame's term
        times ``(s / s_ref)^2`` (landmark noise of a fixed size in pixels; s_ref: the median scale of the
        pilot fits, :meth:`.rigdrive.RigRetargeter.pilot_stats`)
    point_weights : None, or (L,) square-root weights of the landmarks' residuals in both steps (the
        per-point noise model, :mod:`.pointnoise`; on top of the contour's sliding)
    normals : None, or (L, 3) unit normals of the rig's neutral at the landmark vertices: the rest face's
        offsets get depth in their tangent plane (:mod:`.restdepth`); None: in-plane offsets, no depth
    tie : None, or (k, k) a Gaussian prior on differences of weights per unit ridge: the weight step adds
        ``ridge * tie`` to its Gram matrix (the conjugate gaze prior, :func:`.gaze.gaze_tie`)
    focal : the camera's focal length in pixels (inf: a weak-perspective camera, the model as it is);
        centre (2,) its principal point, px (see :meth:`flatten`)
    """

    v0: np.ndarray
    D: np.ndarray
    pairs: np.ndarray
    smooth: float
    ridge: float
    sparsity: float
    contour: np.ndarray
    contour_slide: float
    alternations: int
    tol: float
    ipopt: object = None
    focal: float = float("inf")
    centre: np.ndarray | None = None
    pixel_scale: float | None = None
    point_weights: np.ndarray | None = None
    tie: np.ndarray | None = None
    normals: np.ndarray | None = None

    @property
    def n_shapes(self) -> int:
        return self.D.shape[2]

    def with_neutral(self, v0) -> "FrameSolver":
        """The same solver on the neutral landmarks ``v0`` (L, 3)."""
        return replace(self, v0=v0)

    def shifted(self, offset) -> "FrameSolver":
        """The same solver on the neutral landmarks ``v0 + offset`` (offset (L, 3), rig units)."""
        return replace(self, v0=self.v0 + offset)

    def pilot(self, plain: bool = True) -> "FrameSolver":
        """The solver as the pilot fits use it: frames on their own (no temporal term), ridge
        :data:`RIDGE_FLOOR`, no sparsity and, if ``plain``, the contour landmarks as fixed points
        (plain least squares: what the neutral or the noise estimate must explain; ``plain=False``
        keeps the contour's sliding, to compare fits as the frames will be solved); every landmark
        weighs alike (no ``point_weights``) and no weights are tied (no ``tie``)."""
        return replace(self, smooth=0.0, ridge=RIDGE_FLOOR, sparsity=0.0, point_weights=None, tie=None,
                       contour_slide=1.0 if plain else self.contour_slide)

    def whitened_residual(self, p, fit: "FrameFit") -> np.ndarray:
        """(L, 2) landmark residual of a fit of the landmarks p (L, 2), in rig units as the weight step
        measures it, ``(flat - t) / s - Pi R q`` (q the rig points at the fit's weights), whitened by the
        contour weights of p (:func:`.pose.contour_weights`; not by ``point_weights``)."""
        r = (fit.flat - fit.t) / fit.s - self.landmarks3d(fit.x) @ (PI @ fit.R).T
        W = contour_weights(p, self.contour, self.contour_slide, len(p))
        return r if W is None else np.einsum("lij,lj->li", W, r)

    def at_centre(self, landmarks, visible) -> "FrameSolver":
        """The solver with its principal point resolved: ``centre`` as given (the ``retarget`` command
        gives the image centre), else, with a focal length, the median of the visible landmarks
        (``landmarks`` (T, L, 2) or (L, 2), ``visible`` (T, L) or (L,) bool: :meth:`.rigdrive.RigRetargeter.run`
        passes the capture's, :meth:`solve_frame` the frame's). Without a focal length: itself."""
        if not np.isfinite(self.focal) or self.centre is not None:
            return self
        P, vis = np.asarray(landmarks, np.float64), np.asarray(visible, bool)
        return replace(self, centre=np.median(P[vis], axis=0) if vis.any() else np.median(P.reshape(-1, 2), axis=0))

    def flatten(self, p, q, s, R) -> np.ndarray:
        """Landmarks p (L, 2) as a weak-perspective camera would see the rig points q (L, 3) at the
        pose (s, R): ``c + (p - c) (1 - s z_l / f)``, z_l = (R q_l)_z the depth of a point towards the
        camera from the rig's origin (at distance f / s).

        A pinhole camera of focal f (px) and principal point c sees a point at depth z_l in front of
        the origin magnified by ``Z / (Z - z_l)`` about c relative to the weak-perspective image
        ``s Pi R q + t`` (s = f / Z); dividing that factor out (the scaled-orthographic iteration of
        POSIT, DeMenthon & Davis 1995, with the pose and the weights of the current estimate) lets
        the weak-perspective fit see a face that comes closer as a larger face, not as a face whose
        nose and brows grow against its jaw line (measured on cap12: the jaw width over the eye
        distance follows the scale at r = -0.89, read as browDown/jawLeft). ``focal`` inf: p itself.
        A focal length at which a landmark is at or behind the camera (s z_l >= f) is an
        :class:`InputError` naming ``focal``.
        """
        if not np.isfinite(self.focal):
            return p
        g = self._magnification(q, s, R)
        return self.centre + (np.asarray(p, np.float64) - self.centre) * g[:, None]

    def _magnification(self, q, s, R) -> np.ndarray:
        """(L,) ``1 - s z_l / f`` of the rig points q (L, 3) at the pose (s, R); > 0 or an InputError."""
        z = np.asarray(q, np.float64) @ np.asarray(R)[2]                     # (L,) towards the camera
        g = 1.0 - s * z / self.focal
        if g.min() <= 0.0:
            raise parameter_error("focal", f"a focal length in pixels above {s * z.max():.4g} (the face's scale "
                                  f"{s:.4g} px per rig unit times its nearest landmark's depth {z.max():.4g}: "
                                  "a smaller one puts it at or behind the camera)", f"{self.focal:g}")
        return g

    def fit_pose(self, q, p, vis, s, R, t, rounds: int = 1, iterations: int = 3, sqrtw=None):
        """The pose of the rig points q (L, 3) on the landmarks p (L, 2) (visible (L,) bool) from
        (s, R, t): ``rounds`` times (once without a focal length) the landmarks flattened at the
        current pose (:meth:`flatten`) and the pose fitted to them (:func:`.pose.fit_pose_gn`,
        ``iterations``, ``sqrtw`` (Lv, 2, 2) of the visible landmarks) -- POSIT's loop.

        Returns (s, R, t, rms, flat): rms the residual of the visible landmarks in image pixels (the
        pinhole image of the fitted model against p), flat (L, 2) the landmarks flattened at the
        fitted pose."""
        pf = self.flatten(p, q, s, R)
        for _ in range(1 if not np.isfinite(self.focal) else rounds):
            s, R, t, rms = fit_pose_gn(q[vis], pf[vis], s, R, t, iterations=iterations, sqrtw=sqrtw)
            pf = self.flatten(p, q, s, R)
        if np.isfinite(self.focal):                      # the residual in the image, not the flattened one
            g = self._magnification(q, s, R)
            image = self.centre + (s * (q @ R.T @ PI.T) + t - self.centre) / g[:, None]
            rms = float(np.sqrt(np.mean(np.sum((image - p)[vis] ** 2, axis=1))))
        return s, R, t, rms, pf

    def landmarks3d(self, x) -> np.ndarray:
        """Rig landmark positions (L, 3) at weights x (k,)."""
        return self.v0 + self.D @ x

    def _weights(self, p, vis, s, R, t, x_prev, x_cur, sqrtw=None):
        """x | pose: the certified weight solve (eq. 5 form) of one frame."""
        from ..rigging.certify import CertifiedWeightSolver
        from ..rigging.weightproblem import WeightProblem

        E = whiten(np.einsum("ij,ljk->lik", PI @ R, self.D[vis]).reshape(-1, self.n_shapes), sqrtw)  # (2Lv, k)
        b = whiten((((p[vis] - t) / s) - self.v0[vis] @ (PI @ R).T).reshape(-1), sqrtw)                # rig units
        # variable projection: the pose may still move along its 6 linearised directions (at the
        # current landmarks), so the weights see the data with those directions projected out
        Qp, _ = np.linalg.qr(whiten(pose_jacobian(self.landmarks3d(x_cur)[vis] @ R.T), sqrtw))
        E = E - Qp @ (Qp.T @ E)
        b = b - Qp @ (Qp.T @ b)
        if self.pixel_scale is not None:                # landmark noise of a fixed size in pixels, not rig units
            E, b = E * (s / self.pixel_scale), b * (s / self.pixel_scale)   # eq. 5's data term weighted (s/s_ref)^2
        G = E.T @ E                                     # data term (1/s^2)||A x - b||^2 = x'Gx - 2c'x + b'b
        if self.tie is not None:                        # rho (sigma_w/sigma_d)^2 sum (x_a - x_b)^2 (gaze.py)
            G = G + self.ridge * self.tie
        c = E.T @ b
        lin = self.sparsity * self.ridge          # exponential (sparse) part of the prior, see :mod:`.rigdrive`
        if lin > 1e-6 * np.trace(G) / len(G):     # smaller moves no weight by 1e-6 (and makes DAQP cycle on
            c = c - 0.5 * lin                     # near-singular problems such as ridge 1e-9 on exact data)
        lam = self.smooth + self.ridge
        prior = (self.smooth / lam) * x_prev            # mu||x - x_prev||^2 + rho||x||^2, completed square
        problem = WeightProblem(G, c[None], np.array([b @ b]), self.pairs, prior[None], lam)   # eq. 5, one frame
        if self.ipopt is not None:
            sol = self.ipopt.solve_problem(problem, X0=x_cur[None])
            return sol.X[0], sol.certificate_nodes
        sol = CertifiedWeightSolver(problem).solve_example(0, start=x_cur)
        return sol.x, sol.nodes

    def solve_frame(self, p, visible=None, state=None) -> FrameFit:
        """One frame: landmarks p (L, 2), visible (L,) bool, state = previous (x, s, R, t) or None.

        Returns a :class:`FrameFit` (unpacks as ``x, s, R, t, rms, nodes``).
        """
        p = np.asarray(p, np.float64)
        vis = np.ones(len(p), bool) if visible is None else np.asarray(visible, bool)
        if np.isfinite(self.focal) and self.centre is None:      # the principal point of this frame alone
            return self.at_centre(p, vis).solve_frame(p, vis, state)
        k = self.n_shapes
        if vis.sum() < 4:
            if state is None:
                raise InputError(f"frame landmarks: expected at least 4 visible landmarks on the first frame, "
                                 f"found {int(vis.sum())}")
            x, s, R, t = state                          # the previous frame's fit; flat at its pose
            return FrameFit(x.copy(), s, R.copy(), t.copy(), float("nan"), 0, self.flatten(p, self.landmarks3d(x), s, R))
        if state is None:
            x_prev = np.zeros(k)
            s, R, t = fit_pose_affine(self.v0[vis], p[vis])
            n_alt, rounds = max(6, 2 * self.alternations), 3    # no pose yet: POSIT's loop runs longer
        else:
            x_prev, s, R, t = state
            n_alt, rounds = self.alternations, 1
        W = contour_weights(p, self.contour, self.contour_slide, len(p))
        if self.point_weights is not None:
            W = (np.tile(np.eye(2), (len(p), 1, 1)) if W is None else W) * self.point_weights[:, None, None]
        W = None if W is None else W[vis]
        x, nodes = x_prev.copy(), 0
        for _ in range(n_alt):
            s_old = s
            s, R, t, _, pf = self.fit_pose(self.landmarks3d(x), p, vis, s, R, t, rounds=rounds, sqrtw=W)
            x_old = x
            x, nodes = self._weights(pf, vis, s, R, t, x_prev, x, W)
            if np.abs(x - x_old).max() <= self.tol and abs(s - s_old) <= self.tol * s:   # weights and pose settled
                break
        s, R, t, rms, pf = self.fit_pose(self.landmarks3d(x), p, vis, s, R, t, sqrtw=W)
        return FrameFit(x, float(s), R, t, float(rms), int(nodes), pf)


__all__ = ["FrameFit", "FrameSolver", "RIDGE_FLOOR", "check_camera"]
