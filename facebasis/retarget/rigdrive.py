"""Rig driving: per-frame blendshape weights and weak-perspective head pose from 2D landmarks.

Beyond the paper (which drives meshes directly), a capture's landmarks p_l (T, L, 2) drive a
blendshape rig whose landmark vertices are v0_l (neutral) and d_il (deltas):

    p_l  ~=  s Pi R (v0_l + sum_i x_i d_il) + t                                   (model)

with scale s, rotation R (3 x 3), image translation t (2,) and Pi = [[1, 0, 0], [0, -1, 0]] (the
rig's +y is the image's up; image y grows downwards). Per frame, in order, warm-started from the
previous frame, pose and weights are alternated:

* pose | x: Gauss-Newton on (log s, rotation increment, t), closed-form start on frame 0 (affine
  camera fit, orthonormalised by SVD), both in :mod:`.pose` (re-exported here);
* the weight step sees the data with the pose's 6 linearised directions projected out (variable
  projection), so one round per warm-started frame is enough (about 12 rounds without it);
* x | pose: the package's weight model (seed 000, eq. 5, with the data term of the model above)

      min_x  (1/s^2) || W (A x - b) ||^2 + mu || x - x_prev ||^2 + rho || x ||^2 + sparsity rho sum_i x_i
      s.t.   0 <= x <= 1,   x_a x_b = 0 for exclusive pairs (a, b),

  W the per-landmark weights of the noise model (identity, except on a contour: the jaw line of a
  68-point capture, whose residual along the contour counts ``contour_slide`` = 0.05, see
  :func:`.pose.contour_weights`; times each landmark's own noise weight, :mod:`.pointnoise`; the
  pose step uses the same W), and the linear term the
  exponential (sparse) part of the weight prior (default ``sparsity`` 3: with the Gaussian part it
  is a Gaussian of standard deviation 0.5 centred at -1.5, truncated to [0, 1]: a weight stays at 0
  unless the landmarks push it; measured in reports/retarget/plausibility.md);

  plus, with ``gaze="conjugate"``, ``rho (sigma_w / sigma_d)^2 (x_a - x_b)^2`` for each pair of eye-look
  shapes that move the two eyes the same way (:mod:`.gaze`: landmarks see the lids, not the eyes);
  the data term measured in rig units (divided by s^2), mu the temporal smoothness (default 0.05),
  rho the ridge that keeps shapes the landmarks cannot see, or cannot tell from noise, at zero. Since
  ``mu ||x - x_prev||^2 + rho ||x||^2 = (mu + rho) ||x - mu/(mu + rho) x_prev||^2 + const``,
  this is exactly the certified solver's ``lam ||x - prior||^2`` with ``lam = mu + rho`` and
  ``prior = mu/(mu + rho) x_prev``; it is solved to a certified global optimum by
  :class:`facebasis.rigging.certify.CertifiedWeightSolver` (branch and bound over the pairs), or by
  the CasADi/IPOPT model :class:`facebasis.rigging.weights.WeightSolver` polished by the same
  certificate (``solver="ipopt"``, slower, same answer).

Landmarks marked lost are left out of both steps of that frame.

Default ridge, ``ridge="auto"``: ``rho = max(1e-3, (noise / 0.5)^2)`` (:func:`auto_ridge`), where
``noise`` (rig units) is the median, over up to 40 evenly spaced frames each fitted on its own with
rho = 1e-3 and mu = 0, of the rms landmark residual divided by that frame's scale s
(:meth:`RigRetargeter.estimate_noise`). With the data term in rig units this is the MAP ridge of a
Gaussian prior of standard deviation 0.5 on every weight against landmark noise of that size; the
noise holds whatever the rig cannot reproduce (tracker jitter, a face shape that is not the rig's,
landmark definitions that differ from the rig's). Measured (reports/reproduction/real_clips_notes.md):
noise-free synthetic captures keep rho = 1e-3 and their exact answers, 0.5 / 1 px synthetic noise at
20 px/cm gives rho ~0.004 / 0.015 and a lower weight error than 1e-3; a 400-frame dlib webcam capture
(6.7 px/cm) gives rho 0.49 with ICT's own neutral and 0.20 with ``first_frame_neutral``, and no
weight saturated (11% above 0.95 with rho = 1e-3). A number given as ``ridge`` is used as is.
Landmark noise model (``noise_model="pixels"``, the default): a detector's error has a fixed size in
pixels, so each frame's data term is weighted ``(s / s_ref)^2`` (s_ref the median scale of the
pilot fits that set the ridge): a person who leans away from the camera is not read as an expression
(cap12's last 20 s: browDown_R 0.45 on calm frames, following the scale at r = -0.81 -> 0.11).

Identity (``identity``): the rig's neutral landmarks are not the filmed person's. ``"auto"`` (the
default) estimates a static landmark offset from the capture (:func:`.calibrate.calibrate_auto`):
the rest face (median of the densest quarter of the pilot faces) and on top of it the baseline of
shapes that stay on through nearly all of it plus the median in-plane residual, or that second
step alone (``"quantile"``, the default before issue 23), whichever fits the pilot frames better; ``"first-frame"``
takes frame 0 as the neutral (wrong when the capture starts on an expression; the former
``first_frame_neutral=True``); ``"rig"`` uses the rig's neutral as it is.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, parameter_error, parse_mode
from ..geometry.rig import Rig
from .calibrate import IdentityCalibration, calibrate_auto, calibrate_identity, first_frame_offset, pilot_frames
from .framefit import RIDGE_FLOOR, FrameFit, FrameSolver, check_camera
from .observe import Identifiability, identifiability, landmark_jacobian
from .gaze import GAZE_MODES, conjugate_gaze_pairs, gaze_tie
from .pointnoise import POINT_NOISE_MODES, noise_floor, point_sigmas, point_weights
from .reststart import rest_start
from .restdepth import REST_DEPTH_MODES, landmark_normals
from .rigoptions import DEFAULT_IDENTITY, IDENTITY_MODES, check_landmark_indices, resolve_identity, resolve_pairs
from .pose import (
    PI,
    fit_pose_affine,
    fit_pose_gn,
    project_landmarks,
    rotation_from_vector,
    rotation_to_vector,
)

#: default temporal smoothness mu (rig units^2 per unit weight^2)
DEFAULT_SMOOTH = 0.05
#: default ridge rho towards the neutral: set from the capture's landmark noise (see :func:`auto_ridge`)
DEFAULT_RIDGE = "auto"
#: prior standard deviation of a weight in the "auto" rule, rho = (noise / s / PRIOR_STD)^2
PRIOR_STD = 0.5
#: at most this many frames, evenly spaced, are fitted for the noise estimate of the "auto" rule
PILOT_FRAMES = 40
#: weight of a contour landmark's residual along the contour, relative to across it (see
#: :func:`.pose.contour_weights`): the jaw line of a 68-point capture slides along the face's outline
CONTOUR_SLIDE = 0.05
#: the 68-point iBUG jaw line (points 0-16), the contour of ``contour="auto"`` when L is 68
IBUG_CONTOUR = tuple(range(17))
#: sparsity of the weight prior: the linear term ``sparsity * rho * sum_i x_i`` (see the module docstring)
DEFAULT_SPARSITY = 3.0
#: landmark noise models of :class:`RigRetargeter` (``noise_model``)
NOISE_MODELS = ("pixels", "rig")


def auto_ridge(noise_rig: float, prior_std: float = PRIOR_STD, floor: float = RIDGE_FLOOR) -> float:
    """The "auto" ridge ``max(floor, (noise_rig / prior_std)^2)``.

    ``noise_rig`` is the landmark noise in rig units (rms landmark residual in pixels divided by the
    pose scale s). With the data term in rig units, this is the MAP ridge of a Gaussian prior of
    standard deviation ``prior_std`` on every weight against Gaussian landmark noise of that size:
    ``||A x - b||^2 / noise^2 + ||x||^2 / prior_std^2`` times ``noise^2``.
    """
    if not np.isfinite(noise_rig) or noise_rig < 0:
        return float(floor)
    return float(max(floor, (noise_rig / prior_std) ** 2))



@dataclass(frozen=True)
class RetargetResult:
    """Per-frame rig weights and head pose.

    Attributes
    ----------
    names : k shape names
    weights : (T, k) in [0, 1]
    scale : (T,) pixels per rig unit
    rotation : (T, 3, 3)
    translation : (T, 2) pixels
    residual : (T,) rms landmark residual in pixels (visible landmarks)
    nodes : (T,) branch-and-bound nodes of the last weight solve of each frame
    fps : frames per second of the capture
    seconds : wall time of the solve
    ridge : the ridge rho the frames were solved with (the "auto" rule's value when it was used)
    noise : landmark noise estimate of the "auto" rule, rig units (rms residual px / s of the pilot
        fit; nan when the ridge was given)
    identity : how the neutral landmarks were obtained ("auto", "first-frame" or "rig")
    calibration : the :class:`.calibrate.IdentityCalibration` of ``identity="auto"`` or
        ``"quantile"`` (else None)
    neutral_landmarks : (L, 3) the neutral landmark positions the frames were solved with (the rig's,
        or the person's from the identity step); None when the result was built by hand
    pixel_scale : s_ref of the pixel noise model (:attr:`.framefit.FrameSolver.pixel_scale`; None: rig units)
    point_weights : (L,) the landmarks' square-root weights of the per-point noise model
        (:mod:`.pointnoise`; None: ``point_noise="shared"``)
    """

    names: tuple[str, ...]
    weights: np.ndarray
    scale: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    residual: np.ndarray
    nodes: np.ndarray
    fps: float
    seconds: float
    ridge: float = float("nan")
    noise: float = float("nan")
    identity: str = "rig"
    calibration: IdentityCalibration | None = None
    neutral_landmarks: np.ndarray | None = None
    pixel_scale: float | None = None
    point_weights: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return len(self.weights)

    def rotation_vectors(self) -> np.ndarray:
        """(T, 3) rotation vectors (radians)."""
        return np.stack([rotation_to_vector(R) for R in self.rotation])


class RigRetargeter:
    """Built once per (rig, landmark vertices, options); :meth:`run` solves a whole capture.

    Parameters
    ----------
    rig : the blendshape rig
    indices : (L,) landmark vertex indices on the rig (the capture's landmark order)
    pairs : exclusive shape pairs (names or indices), complementarity ``x_a x_b = 0``
    smooth : mu, temporal smoothness (rig units^2; 0 solves frames independently)
    ridge : rho, pull towards the neutral (keeps unobservable shapes at 0), rig units^2; "auto" (the
        default) sets it per capture from the landmark noise, see :meth:`estimate_noise` and
        :func:`auto_ridge`
    alternations : most pose/weight rounds per frame (the first frame, which starts from the neutral,
        gets at least 6); a frame stops once a round changes no weight by more than ``tol``
    tol : weight change that ends the rounds of a frame (warm-started frames usually need 2)
    identity : "auto" (default, :data:`DEFAULT_IDENTITY`): the person's neutral landmarks estimated
        from the capture (:func:`.calibrate.calibrate_identity`); "first-frame": frame 0 is the neutral
        expression, the rig's landmarks are shifted (in frame 0's image plane) to match it exactly;
        "rig": the rig's own neutral. The first two keep a face whose shape differs from the rig's
        from showing up as expression (see :meth:`run`)
    first_frame_neutral : older spelling: True is ``identity="first-frame"``, False ``"rig"``
    solver : "certified" (branch and bound, default) or "ipopt" (CasADi/IPOPT polished by it)
    contour : landmark indices of a silhouette contour whose points may slide along it; "auto" (the
        default): the iBUG jaw line 0-16 when there are 68 landmarks, else none
    contour_slide : weight of a contour landmark's residual along the contour (:data:`CONTOUR_SLIDE`;
        1 measures it as every other landmark), see :func:`.pose.contour_weights`
    sparsity : the exponential part of the weight prior, ``sparsity * rho * sum_i x_i``
        (:data:`DEFAULT_SPARSITY`; 0 leaves the Gaussian ridge alone)
    rest_anchor : ``identity="auto"``: take the start's posture as the rest face when the take starts
        at rest (a 68-point capture: still for 0.3 s with closed lips, :func:`.reststart.rest_start`;
        other layouts: the first frame's posture recurs) and it is one-sided enough
        (:func:`.calibrate.calibrate_auto`, step 2; default True); False keeps the capture's commonest
        posture (the default before it)
    focal : the camera's focal length in pixels (None, the default: a weak-perspective camera);
        ``centre`` its principal point (2,) px (None: the median of the visible landmarks, the
        capture's in :meth:`run` / :meth:`estimate_noise`, the frame's in :meth:`solve_frame`:
        :meth:`.framefit.FrameSolver.at_centre`; ``retarget`` gives the image centre). Given,
        every fit sees the landmarks with the perspective of the current estimate divided out
        (:meth:`.framefit.FrameSolver.flatten`): a face that comes closer is not read as an expression
    noise_model : "pixels" (the default): the landmark noise has a fixed size in pixels, so a frame
        whose face is smaller in the image weighs its landmarks less (the data term times
        ``(s / s_ref)^2``, s_ref the median scale of the pilot fits that set the noise: :meth:`pilot_stats`);
        "rig": a fixed size on the face (the former model; the same while the face keeps its size)
    point_noise : "per-point" (the default): every landmark has its own noise, estimated from the pilot
        fits, and a landmark noisier than the typical one weighs less (:mod:`.pointnoise`); "shared":
        one noise for every landmark (the former model)
    gaze : "conjugate" (the default): the eyes look the same way, a Gaussian prior on the difference of
        each conjugate eye-look pair the rig has by name (:mod:`.gaze`); "free": no such prior
    rest_depth : "tangent" (the default): the rest face (``identity="auto"``'s rest face only; the quantile
        baseline and the first-frame neutral stay flat) is also built with its offsets lifted into the rig's
        tangent plane at each vertex, and kept if its check frames fit better than the flat one's, so a rest
        face measured on a turned head holds as it turns back (:mod:`.restdepth`); "none": flat offsets
        without depth (the former model)
    """

    def __init__(self, rig: Rig, indices, pairs=(), smooth: float = DEFAULT_SMOOTH, ridge: float = DEFAULT_RIDGE,
                 alternations: int = 2, solver: str = "certified", tol: float = 1e-4,
                 first_frame_neutral: bool | None = None, identity: str | None = None,
                 contour="auto", contour_slide: float = CONTOUR_SLIDE,
                 sparsity: float = DEFAULT_SPARSITY, rest_anchor: bool = True,
                 focal: float | None = None, centre=None, noise_model: str = "pixels",
                 point_noise: str = "per-point", gaze: str = "conjugate", rest_depth: str = "tangent"):
        self.identity = resolve_identity(identity, first_frame_neutral)
        self.auto = isinstance(ridge, str)
        if self.auto:
            if ridge != "auto":
                raise InputError(f"ridge: expected a finite number >= 0 or 'auto', found {ridge!r}")
            ridge = RIDGE_FLOOR
        for name, v in (("smooth", smooth), ("ridge", ridge)):
            if not np.isfinite(v) or v < 0:
                raise InputError(f"{name}: expected a finite number >= 0, found {v}")
        if smooth + ridge <= 0:
            raise InputError("smooth and ridge: expected at least one > 0 (else unobservable shapes are undetermined)")
        if alternations < 1:
            raise InputError(f"alternations: expected >= 1, found {alternations}")
        if solver not in ("certified", "ipopt"):
            raise InputError(f"solver: expected 'certified' or 'ipopt', found {solver!r}")
        self.rig = rig
        idx = np.asarray(indices, np.int64)
        self.indices = check_landmark_indices(idx, rig.n_vertices, len(idx))
        self.pairs = resolve_pairs(rig, pairs)
        self.smooth, self.ridge, self.alternations, self.solver = float(smooth), float(ridge), int(alternations), solver
        self.tol = float(tol)
        self.first_frame_neutral = self.identity == "first-frame"
        L = len(self.indices)
        if isinstance(contour, str):
            if contour != "auto":
                raise InputError(f"contour: expected 'auto' or landmark indices, found {contour!r}")
            contour = IBUG_CONTOUR if L == 68 else ()
        self.contour = np.asarray(contour, np.int64).reshape(-1)
        if len(self.contour) and (self.contour.min() < 0 or self.contour.max() >= L):
            raise InputError(f"contour: expected landmark indices in [0, {L}), found {self.contour.tolist()}")
        for name, v in (("contour_slide", contour_slide), ("sparsity", sparsity)):
            if not np.isfinite(v) or v < 0:
                raise InputError(f"{name}: expected a finite number >= 0, found {v}")
        self.contour_slide = float(contour_slide)
        if not isinstance(rest_anchor, (bool, np.bool_)):
            raise parameter_error("rest_anchor", "True or False", repr(rest_anchor))
        self.rest_anchor = bool(rest_anchor)
        self.sparsity = float(sparsity)
        focal, centre = check_camera(focal, centre)
        self.noise_model = parse_mode("noise_model", noise_model, NOISE_MODELS, "pixels")
        self.point_noise = parse_mode("point_noise", point_noise, POINT_NOISE_MODES, "per-point")
        self.gaze = parse_mode("gaze", gaze, GAZE_MODES, "conjugate")
        self.rest_depth = parse_mode("rest_depth", rest_depth, REST_DEPTH_MODES, "tangent")
        self.gaze_pairs = conjugate_gaze_pairs(rig.names) if self.gaze == "conjugate" else np.zeros((0, 2), np.int64)
        ipopt = None
        if solver == "ipopt":
            from ..rigging.weights import WeightSolver

            ipopt = WeightSolver(rig.n_shapes, 1, self.pairs)
        #: the frame solver on the rig's own neutral landmarks, with these settings (frozen: run()
        #: builds the one it settles on from it and returns what it settled on in its result)
        self.model = FrameSolver(
            v0=rig.neutral[self.indices].copy(),                                       # (L, 3)
            D=np.ascontiguousarray(rig.deltas[:, self.indices].transpose(1, 2, 0)),    # (L, 3, k)
            pairs=self.pairs, smooth=self.smooth, ridge=self.ridge, sparsity=self.sparsity,
            contour=self.contour, contour_slide=self.contour_slide, alternations=self.alternations,
            tol=self.tol, ipopt=ipopt, focal=focal, centre=centre,
            tie=gaze_tie(rig.n_shapes, self.gaze_pairs, PRIOR_STD),
            normals=landmark_normals(rig.neutral, rig.faces, self.indices) if self.rest_depth == "tangent" else None)

    @property
    def n_landmarks(self) -> int:
        return len(self.indices)

    @property
    def v0(self) -> np.ndarray:
        """(L, 3) the rig's neutral landmark positions."""
        return self.model.v0

    @property
    def D(self) -> np.ndarray:
        """(L, 3, k) the shapes' landmark deltas."""
        return self.model.D

    def landmarks3d(self, x) -> np.ndarray:
        """Rig landmark positions (L, 3) at weights x (k,), on the rig's neutral."""
        return self.model.landmarks3d(x)

    def solve_frame(self, p, visible=None, state=None) -> FrameFit:
        """One frame on the rig's own neutral (:meth:`.framefit.FrameSolver.solve_frame`): landmarks
        p (L, 2), visible (L,) bool, state = previous (x, s, R, t) or None; a :class:`FrameFit`."""
        return self.model.solve_frame(p, visible, state)

    def estimate_noise(self, landmarks, visible, model: FrameSolver | None = None) -> float:
        """Landmark noise of a capture in rig units, for the "auto" ridge (:meth:`pilot_stats`)."""
        return self.pilot_stats(landmarks, visible, model)[0]

    def pilot_stats(self, landmarks, visible, model: FrameSolver | None = None) -> tuple[float, float]:
        """(noise, s_ref): landmark noise in rig units (the "auto" ridge) and the pilot scale.

        Up to :data:`PILOT_FRAMES` frames, evenly spaced, are each fitted on their own (pose and
        weights, no temporal term, ridge :data:`RIDGE_FLOOR`: :meth:`.framefit.FrameSolver.pilot` of
        ``model``, by default :attr:`model`); noise is the median over them of the rms landmark
        residual divided by the frame's scale s, s_ref their median s (px per rig unit: the pixel
        noise model's, :attr:`.framefit.FrameSolver.pixel_scale`); nan without a frame of 4 visible
        landmarks. The noise holds whatever the rig cannot reproduce: tracker noise, a face shape
        that differs from the rig's, landmark definitions that differ from the rig's landmark
        vertices. Noise-free captures of the rig give ~0.
        """
        pilot = (self.model if model is None else model).at_centre(landmarks, visible).pilot()
        T = len(landmarks)
        frames = np.unique(np.linspace(0, T - 1, min(T, PILOT_FRAMES)).round().astype(int))
        fits = [pilot.solve_frame(landmarks[f], visible[f], None) for f in frames if visible[f].sum() >= 4]
        fits = [fit for fit in fits if np.isfinite(fit.rms) and fit.s > 0]
        if not fits:
            return float("nan"), float("nan")
        return float(np.median([fit.rms / fit.s for fit in fits])), float(np.median([fit.s for fit in fits]))

    def settle(self, landmarks, visible, fps: float = 30.0, finite=None) -> tuple[FrameSolver, IdentityCalibration | None, float]:
        """What a capture's frames are solved with: (the frame solver on the person's neutral, with the
        ridge of the "auto" rule, the pixel noise's s_ref, the principal point and the landmarks' own noise
        weights (``point_noise="per-point"``, :mod:`.pointnoise`), the identity calibration or None, the noise estimate (nan when the ridge was given)). ``landmarks`` (T, L, 2) without NaN,
        ``visible`` (T, L) bool, ``fps`` (the start window of :func:`.reststart.rest_start`), ``finite``
        (T, L) bool: the points that had coordinates before NaN was replaced (default all; the others are
        left out of the start evidence: it keeps a lost point's estimate but cannot use a made-up one)."""
        model, calibration, noise = self.model.at_centre(landmarks, visible), None, float("nan")   # principal point
        if self.identity == "first-frame":
            model = model.shifted(first_frame_offset(model, landmarks[0], visible[0]))
        elif self.identity in ("auto", "quantile"):
            if self.identity == "auto":
                P = landmarks if finite is None else np.where(np.asarray(finite, bool)[..., None], landmarks, np.nan)
                start = rest_start(P, visible, fps) if self.rest_anchor else None
                calibration = calibrate_auto(model, landmarks, visible, anchor=self.rest_anchor, start=start)
            else:
                calibration = calibrate_identity(model, landmarks, visible)
            model = model.with_neutral(calibration.neutral)
        if self.auto or self.noise_model == "pixels":     # the pilot fits (the calibration's last pass is one)
            known = calibration is not None and np.isfinite(calibration.noise)
            pilot_noise, s_ref = (calibration.noise, calibration.scale) if known else self.pilot_stats(landmarks, visible, model)
            if self.auto:
                noise = pilot_noise
                model = replace(model, ridge=auto_ridge(noise))
            if self.noise_model == "pixels":
                model = replace(model, pixel_scale=s_ref if np.isfinite(s_ref) and s_ref > 0 else None)
        if self.point_noise == "per-point":             # each landmark's own noise (pointnoise.py)
            sigma = point_sigmas(model, landmarks, visible, pilot_frames(visible, PILOT_FRAMES))
            model = replace(model, point_weights=point_weights(sigma, noise_floor(model.v0)))
        return model, calibration, noise

    def run(self, landmarks, lost=None, fps: float = 30.0, progress=None) -> RetargetResult:
        """Solve every frame in order. landmarks (T, L, 2); lost (T, L) bool (skipped).

        The result holds what the run settled on (:meth:`settle`): the ridge, the noise estimate, the
        identity calibration and the neutral landmarks the frames were solved with; this retargeter
        is left as it is, so one retargeter runs any number of captures."""
        P = np.asarray(landmarks, np.float64)
        if P.ndim != 3 or P.shape[1:] != (self.n_landmarks, 2):
            raise InputError(f"capture landmarks: expected shape (T, {self.n_landmarks}, 2), found {P.shape}")
        T = len(P)
        vis = np.ones(P.shape[:2], bool) if lost is None else ~np.asarray(lost, bool)
        vis &= np.isfinite(P).all(axis=2)
        k = self.rig.n_shapes
        X, S, Rs, Ts = np.zeros((T, k)), np.zeros(T), np.zeros((T, 3, 3)), np.zeros((T, 2))
        res, nodes = np.zeros(T), np.zeros(T, np.int64)
        state = None
        t0 = time.perf_counter()
        model, calibration, noise = self.settle(np.nan_to_num(P), vis, fps, finite=np.isfinite(P).all(axis=2))
        for f in range(T):               # frames in order, each warm-started from the previous one
            fit = model.solve_frame(np.nan_to_num(P[f]), vis[f], state)
            X[f], S[f], Rs[f], Ts[f], res[f], nodes[f] = fit
            state = fit.state
            if progress is not None:
                progress(f, T)
        return RetargetResult(self.rig.names, X, S, Rs, Ts, res, nodes, float(fps), time.perf_counter() - t0,
                              model.ridge, noise, self.identity, calibration, model.v0, model.pixel_scale,
                              model.point_weights)


def retarget_landmarks(rig: Rig, indices, landmarks, lost=None, pairs=(), smooth: float = DEFAULT_SMOOTH,
                       ridge: float = DEFAULT_RIDGE, fps: float = 30.0, **kw) -> RetargetResult:
    """One-off: :class:`RigRetargeter` built and run on landmarks (T, L, 2)."""
    idx = np.asarray(indices, np.int64)
    lm = np.asarray(landmarks)
    if lm.ndim == 3 and lm.shape[1] != len(idx):
        raise InputError(f"landmark indices: expected {lm.shape[1]} indices (one per capture landmark), found {len(idx)}")
    return RigRetargeter(rig, idx, pairs, smooth, ridge, **kw).run(landmarks, lost, fps)


__all__ = ["RigRetargeter", "RetargetResult", "retarget_landmarks", "project_landmarks", "fit_pose_affine", "fit_pose_gn",
           "rotation_from_vector", "rotation_to_vector", "check_landmark_indices", "resolve_pairs", "Identifiability",
           "identifiability", "landmark_jacobian", "DEFAULT_SMOOTH", "DEFAULT_RIDGE", "DEFAULT_IDENTITY", "IDENTITY_MODES",
           "resolve_identity", "RIDGE_FLOOR", "PRIOR_STD", "PILOT_FRAMES", "auto_ridge", "PI", "NOISE_MODELS",
           "POINT_NOISE_MODES", "GAZE_MODES"]
