"""Stateful face tracker and the one-off :func:`capture` (Wu & Ju 2016, sec. 4).

:class:`FaceTracker` is built once on the first frame (face mesh, harmonic factorisation of eq. 9,
particle filter state, LK pyramid) and then advanced frame by frame with :meth:`FaceTracker.track`.
:func:`capture` runs it over a video or image folder, streaming frames (memory does not grow with
the video length except for the tracked coordinates themselves), and writes the output folder.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from facebasis.errors import InputError, parameter_error

from .facemesh import FaceMesh, build_face_mesh
from .eyelids import check_lid_options, eyelid_model
from .harmonic import HarmonicDeformer
from .inputs import CaptureResult, check_capture_args
from .landmarks import (
    REFERENCE_FACE_WIDTH,
    face_scale,
    face_width,
    lip_partners,
    lk_windows,
    neighbour_affine_prediction,
    validate_landmarks,
)
from .lips import (
    INNER_LIPS,
    LIP_RENEW,
    _from_complex,
    _to_complex,
    follow_outer_lip,
    similarity_factor,
)
from .lk import DriftTemplates, build_pyramid, lk_track, local_affine, local_affine_factor
from .meshtrack import MeshRefiner, prepare_image
from .options import TrackerOptions
from .particle import CondensationFilter, neighbour_weights
from .trackfile import OVERLAY_FILE, Capture, write_capture
from .video import VideoWarning
from .video import gray_pair as _grays

__all__ = ["CaptureResult", "FaceTracker", "FrameResult", "TrackerOptions", "capture", "check_capture_args"]


#: Drift correction: samples per side of each landmark's template grid (over its LK window; the
#: inner-lip points, on the thin lip line, DRIFT_SAMPLES_DENSE, see :class:`DriftTemplates`),
#: Gauss-Newton iterations per frame, damping of the affine part (measured on the ground-truth
#: benchmark: 7 x 7 samples and 4 iterations are as precise as 11 x 11 and 8, at a third of the cost).
DRIFT_SAMPLES, DRIFT_SAMPLES_DENSE, DRIFT_ITERATIONS, DRIFT_DAMPING = 7, 15, 4, 0.05
_NOT_RUN = object()   # no detection was run on the first frame yet


@dataclass(frozen=True)
class FrameResult:
    """Tracking result of one frame.

    Attributes
    ----------
    landmarks : ndarray, shape (L, 2)
    vertices : ndarray, shape (N, 2)
        Mesh vertices; rows ``0 .. L-1`` equal ``landmarks``.
    lost : ndarray, shape (L,) bool
        The LK measurement was rejected; the filter carried the point.
    """

    landmarks: np.ndarray
    vertices: np.ndarray
    lost: np.ndarray


class FaceTracker:
    """Markerless face tracker (LK + CONDENSATION landmarks, harmonic + LM mesh).

    Parameters
    ----------
    first_frame : ndarray, shape (H, W, 3) uint8 RGB or (H, W) grey
    landmarks : ndarray, shape (L, 2)
        Landmarks on the first frame (pixels, x right, y down), inside the frame.
    options : TrackerOptions

    Attributes
    ----------
    mesh : FaceMesh
        First-frame mesh (landmarks are vertices ``0 .. L-1``).
    first : FrameResult
        Result for the first frame (the given landmarks and the mesh).
    """

    def __init__(self, first_frame: np.ndarray, landmarks: np.ndarray, options: TrackerOptions = TrackerOptions()):
        self.opt = options
        if options.inner_lips not in INNER_LIPS:
            raise InputError(f"inner_lips: expected one of {', '.join(INNER_LIPS)}, found {options.inner_lips!r}")
        if not (np.isfinite(options.drift_blur) and options.drift_blur >= 0):
            raise InputError(f"drift_blur: expected a number >= 0, found {options.drift_blur!r}")
        if not (np.isfinite(options.outlier_distance) and options.outlier_distance >= 0):
            raise InputError(f"outlier_distance: expected a number >= 0 (face widths; 0 = off), "
                             f"found {options.outlier_distance!r}")
        check_lid_options(options)
        gray, gray8 = _grays(first_frame)
        h, w = gray.shape
        lm = validate_landmarks(landmarks, "landmarks", size=(w, h))
        self.size = (w, h)
        self.mesh: FaceMesh = build_face_mesh(lm, options.mesh_spacing)
        L = len(lm)
        self.L = L
        self.scale = face_scale(lm)
        self.windows = lk_windows(lm, options.windows)
        self._maxwin = tuple(int(x) for x in self.windows.max(0))
        self.harmonic = HarmonicDeformer(self.mesh.vertices, self.mesh.faces, np.arange(L))  # eq. 9, factored once
        held = np.arange(len(self.mesh.vertices)) < L
        self.refiner = MeshRefiner(self.mesh.vertices, self.mesh.faces, held, self.mesh.spacing, options.mesh,
                                   size=face_width(lm) / REFERENCE_FACE_WIDTH)
        self._inner, self._partner = lip_partners(L) if options.inner_lips != "track" else (np.zeros(0, np.int64),) * 2
        self._outer0 = lm[48:60].copy() if len(self._inner) else None    # outer lip of frame 0
        self._offset = lm[self._inner] - lm[self._partner]              # lip thickness, frame 0's axes
        self.filter = CondensationFilter(gray, lm, self.scale, options.filter) if options.use_filter else None
        self._lids = eyelid_model(gray, lm, self.scale, options)    # lids in the eye-corner frame
        self._pyr = build_pyramid(gray8, self._maxwin, options.lk_levels)
        self._prep = prepare_image(gray, options.mesh.blur * self.scale)
        self._lm = lm.copy()
        self._lost_prev = np.zeros(L, bool)
        self._lm0, self._width = lm.copy(), face_width(lm)
        self._W = neighbour_weights(lm, options.filter.neighbour_sigma * face_width(lm))   # LK-failure prediction
        dense = lip_partners(L)[0]                      # inner lips: a thin lip line, in every inner_lips mode
        self._drift = DriftTemplates(gray, lm, self.windows, dense, options.drift_blur * self.scale,
                                     self.windows.max() + 8.0 * self.scale, DRIFT_SAMPLES, DRIFT_SAMPLES_DENSE)
        self._V = self.mesh.vertices.copy()
        self._affine = local_affine_factor(self.mesh.vertices, np.arange(L), self.mesh.spacing)   # frame 0's part
        self.first = FrameResult(lm.copy(), self.mesh.vertices.copy(), np.zeros(L, bool))
        self.timings = {"landmarks": 0.0, "mesh": 0.0}
        self.lk_motion = np.zeros_like(lm)   # LK's motion of the landmarks in the last frame

    def _follow_lips(self, lm: np.ndarray, detections: np.ndarray | None, seen: np.ndarray | None = None) -> np.ndarray:
        """Place the inner-lip points on their outer-lip partners (``inner_lips="follow"``); with
        ``inner_lips="auto"`` the points in ``seen`` (P,) bool (their first-frame appearance found again
        by the drift correction) keep their tracked position and renew the lip-thickness offset."""
        if not len(self._inner):
            return lm
        a = similarity_factor(self._outer0, lm[48:60])
        if not np.isfinite(a) or abs(a) < 1e-9:   # a collapsed outer lip (lost tracking): keep frame 0's size
            a = 1.0 + 0.0j
        if detections is not None:
            det = np.asarray(detections, float)
            d = det[self._inner] - det[self._partner]
            ok = np.all(np.isfinite(d), axis=1)
            d0 = _from_complex(_to_complex(d) / a)                       # back in frame 0's axes
            self._offset[ok] = (1.0 - LIP_RENEW) * self._offset[ok] + LIP_RENEW * d0[ok]
        out = lm.copy()
        out[self._inner] = follow_outer_lip(lm[self._partner], self._offset, a)
        if seen is not None and seen.any():
            # a point seen again keeps its tracked position and renews the lip thickness it is
            # followed with once it is no longer seen (the mouth opened)
            out[self._inner] = np.where(seen[:, None], lm[self._inner], out[self._inner])
            self._offset[seen] = _from_complex(_to_complex(out[self._inner] - lm[self._partner]) / a)[seen]
        if self.filter is not None:
            self.filter.place(self._inner, out[self._inner])
        return out

    def _lip_seen(self) -> np.ndarray:
        """Inner-lip points (P,) bool that keep their tracked position: with ``inner_lips="auto"`` those
        whose first-frame appearance the drift correction found again this frame, else none."""
        if self.opt.inner_lips != "auto":
            return np.zeros(len(self._inner), bool)
        return self._drift_ok[self._inner].copy()

    def _predict_failed(self, lk):
        """Where LK failed (status, forward-backward check, or a point off the frame), put the point at
        its previous position moved by its confident neighbours' mean LK motion (Gaussian weights of
        the first-frame distances, as the filter's motion model), so the drift correction starts from a
        plausible place instead of LK's diverged guess (cap12 frame 618: the chin jumped 235 px and the
        track collapsed)."""
        w, h = self.size
        pts = lk.points
        inside = np.all(np.isfinite(pts), axis=1) & np.all((pts >= 0) & (pts <= [w - 1, h - 1]), axis=1)
        ok = lk.ok & inside
        if ok.all():
            return lk
        disp = np.where(ok[:, None], pts - self._lm, 0.0)
        Wc = self._W * ok[None, :]
        wsum = Wc.sum(1, keepdims=True)
        pred = self._lm + (Wc @ disp) / np.maximum(wsum, 1e-12) * (wsum > 1e-3)
        return replace(lk, points=np.where(ok[:, None], pts, pred), ok=ok)

    def _repair_outliers(self, lm: np.ndarray, lost: np.ndarray):
        """Points farther than ``outlier_distance`` face widths from where their neighbours' affine motion
        since frame 0 puts them (:func:`neighbour_affine_prediction`, leave-one-out, the other points'
        outliers left out) are moved there and reported lost. True shapes stay within 0.13 face widths
        of that prediction (per-frame dlib on both shared clips, worst frame); a jaw-contour point that
        slid along the silhouette and tangled with its neighbours (cap12, 25-50 px) does not."""
        tau = self.opt.outlier_distance * self._width
        if not tau > 0:
            return lm, lost
        conf = ~lost
        conf[self._inner] = False
        pred = neighbour_affine_prediction(self._lm0, lm, self._W, conf)
        bad = np.linalg.norm(lm - pred, axis=1) > tau
        if not bad.any():
            return lm, lost
        pred = neighbour_affine_prediction(self._lm0, lm, self._W, conf & ~bad)
        bad &= np.linalg.norm(lm - pred, axis=1) > tau
        lm = np.where(bad[:, None], pred, lm)
        if self.filter is not None:
            self.filter.place(np.flatnonzero(bad), lm[bad])
        return lm, lost | bad

    def _correct_drift(self, lk, gray):
        """Align the first frame's patches from the LK positions (``drift_correction``); sets ``_drift_ok``."""
        A = local_affine(self.mesh.vertices, self._V, np.arange(self.L), self.mesh.spacing, self._affine)
        p, zn = self._drift.align(gray, lk.points, A, self._lm, iterations=DRIFT_ITERATIONS,
                                  affine=self.opt.drift_affine, affine_damping=DRIFT_DAMPING)
        # a point lost in the previous frame or failed by LK in this one (started from its neighbours'
        # motion) may be pulled back further, on a stricter match
        far = self._lost_prev | ~lk.ok
        reach = self.opt.drift_max_shift * self.scale * np.where(far, self.opt.drift_recovery, 1.0)
        zmin = np.where(far, 0.5 * (1.0 + self.opt.drift_zncc), self.opt.drift_zncc)
        w, h = self.size
        inside = np.all(np.isfinite(p), axis=1) & np.all((p >= 0) & (p <= [w - 1, h - 1]), axis=1)
        with np.errstate(invalid="ignore"):
            acc = inside & (np.linalg.norm(p - lk.points, axis=1) <= reach) & (zn >= zmin)
        self._drift_ok = acc
        return replace(lk, points=np.where(acc[:, None], p, lk.points))

    def track(self, frame: np.ndarray, detections: np.ndarray | None = None,
              detection_sigma: np.ndarray | None = None) -> FrameResult:
        """Track the next frame.

        Parameters
        ----------
        frame : ndarray, shape (H, W, 3) uint8 RGB or (H, W) grey
            Same size as the first frame.
        detections : ndarray, shape (L, 2), optional
            Per-frame detected landmarks used as extra filter observations (rows of NaN ignored).
        detection_sigma : ndarray, shape (L,), optional
            Their standard deviation in pixels (measured by
            :class:`facebasis.capture.detect.DetectionNoise`); default: the filter option.

        Returns
        -------
        FrameResult
        """
        t0 = time.perf_counter()
        gray, gray8 = _grays(frame)
        if (gray.shape[1], gray.shape[0]) != self.size:
            raise InputError(f"frame: expected size {self.size[0]} x {self.size[1]}, "
                             f"found {gray.shape[1]} x {gray.shape[0]}")
        pyr = build_pyramid(gray8, self._maxwin, self.opt.lk_levels)
        lk = self._predict_failed(lk_track(self._pyr, pyr, self._lm, self.windows, self.opt.lk_levels,
                                           self.opt.fb_threshold * self.scale))
        prep = prepare_image(gray, self.opt.mesh.blur * self.scale)
        self._drift_ok = np.zeros(self.L, bool)
        if self.opt.drift_correction:
            lk = self._correct_drift(lk, gray)
        if self.filter is not None:
            ok = lk.ok | self._drift_ok
            ok[self._inner] = self._lip_seen()   # placed by the lip model: no LK evidence for their neighbours
            lm, lost = self.filter.step(gray, lk.points, ok, detections, detection_sigma,
                                        trusted=self._drift_ok & ok)
        else:
            lm, lost = lk.points, ~(lk.ok | self._drift_ok)
        self.lk_motion = lk.points - self._lm   # the tracked (drift-corrected) motion: detection noise estimate
        lost = np.asarray(lost, bool).copy()
        seen = self._lip_seen() if self.opt.inner_lips == "auto" else None
        lost[self._inner] = lost[self._partner] if seen is None else np.where(seen, lost[self._inner], lost[self._partner])
        lm = self._lids.follow(self._follow_lips(lm, detections, seen), detections, self.filter, gray)
        lm, lost = self._repair_outliers(lm, lost)
        self._lost_prev = lost.copy()
        lm = np.clip(lm, 0, [self.size[0] - 1, self.size[1] - 1])
        t1 = time.perf_counter()
        # harmonic initialisation from the landmark displacement (eq. 7-9), then LM (eq. 5)
        V_init = self._V + self.harmonic.solve(lm - self._lm)
        V_init[: self.L] = lm
        V = self.refiner.refine(self._prep, prep, self._V, V_init) if self.opt.refine_mesh else V_init
        t2 = time.perf_counter()
        self.timings["landmarks"] += t1 - t0
        self.timings["mesh"] += t2 - t1
        self._pyr, self._prep, self._lm, self._V = pyr, prep, lm, V
        return FrameResult(lm.copy(), V.copy(), np.asarray(lost, bool).copy())


def capture(video, landmarks=None, detector=None, out=None, max_frames: int | None = None,
            overlay: bool = True, fps: float | None = None, options: TrackerOptions = TrackerOptions(),
            detections_as_observations: bool = True,
            progress: Callable[[int, int | None], None] | None = None, threads: bool = True) -> CaptureResult:
    """Track a face through a video or an image folder.

    Parameters
    ----------
    video : path-like or FrameSource
        Video file or folder of images.
    landmarks : path-like or ndarray (L, 2), optional
        First-frame landmarks (``.pts`` / ``.json`` file or array). Exactly one of ``landmarks``
        and ``detector``.
    detector : str or detector object, optional
        ``"mediapipe"`` or ``"dlib"``: detect the 68 landmarks on the first frame (and, with
        ``detections_as_observations``, on every frame as extra filter observations). An object
        with ``detect(frame, near=None) -> (L, 2) array or None``; unless its attribute
        ``needs_near`` is False it is called after the previous frame is tracked, with
        ``near`` = the previous landmarks, else ahead in the reader thread without ``near``.
    out : path-like, optional
        Output folder (written atomically): ``track.npz``, ``landmarks.csv``, ``overlay.mp4``.
    max_frames : int, optional
        Stop after this many frames (>= 1).
    overlay : bool
        Write ``overlay.mp4`` (only with ``out``).
    fps : float, optional
        Frame rate of an image folder (default 25).
    options : TrackerOptions
    detections_as_observations : bool
        In detector mode, feed per-frame detections to the particle filter.
    progress : callable, optional
        Called as ``progress(frames_done, total_or_None)`` after every frame.
    threads : bool
        Decode (and run a detector that does not use the track, MediaPipe) ahead in a background
        thread, and draw and encode the overlay behind in another (:mod:`facebasis.capture.pipeline`);
        the results are bitwise those of ``threads=False``, everything in the calling thread.
        ``seconds`` then holds each stage's wall time in its own thread (they overlap).

    Returns
    -------
    CaptureResult

    Raises
    ------
    InputError
        Any bad input, before any work starts (and no output folder is left behind).
    """
    if not isinstance(threads, (bool, np.bool_)):
        raise parameter_error("threads", "True or False", repr(threads))
    src, lm0, det = check_capture_args(video, landmarks, detector, out, max_frames, fps)
    total = src.n_frames if max_frames is None else (min(max_frames, src.n_frames) if src.n_frames else max_frames)
    secs = {"decode": 0.0, "landmarks": 0.0, "mesh": 0.0, "detect": 0.0, "output": 0.0}
    run = _Run(src, lm0, det, max_frames, overlay, options, detections_as_observations, progress, total, secs,
               bool(threads))
    if out is None:
        return CaptureResult(run(None), None, secs)
    from facebasis.atomic import atomic_directory

    out = Path(out)
    with atomic_directory(out) as stage:
        cap = run(stage)
    cap = replace(cap, folder=out)
    return CaptureResult(cap, out, secs)


@dataclass
class _Run:
    """One :func:`capture` run over a checked source, timing each stage into ``secs``."""

    src: object
    lm0: np.ndarray | None
    det: object
    max_frames: int | None
    overlay: bool
    options: TrackerOptions
    observe: bool
    progress: Callable | None
    total: int | None
    secs: dict
    threads: bool = True

    def _timed(self, stage: str, fn, *args, **kw):
        t = time.perf_counter()
        r = fn(*args, **kw)
        self.secs[stage] += time.perf_counter() - t
        return r

    def _start(self, first, detection):
        """First-frame landmarks (``detection`` if the reader ran the detector, else detected now), the
        tracker and the detection-noise estimate."""
        det = self.det
        if self.lm0 is None:
            self.lm0 = detection if detection is not _NOT_RUN else self._timed("detect", det.detect, first)
            if self.lm0 is None:
                raise InputError(what=f"{{detector}} {getattr(det, 'name', det)}",
                                 expected=f"a face on the first frame of {self.src.path}", found="none",
                                 params={"detector": "detector"})
        tracker = FaceTracker(first, self.lm0, self.options)
        noise = None
        if det is not None and self.observe:
            from .detect import DetectionNoise

            fo = self.options.filter
            noise = DetectionNoise(tracker.L, prior=fo.detection_sigma * tracker.scale,
                                   floor=fo.measurement_sigma * tracker.scale)
            noise.update(self.lm0, np.zeros_like(self.lm0))
        return tracker, noise

    def __call__(self, stage: Path | None) -> Capture:
        from .pipeline import FrameReader, OverlayThread, thread_settings

        src, det, secs = self.src, self.det, self.secs
        # a detector that does not look at the track runs ahead with the decoding
        ahead = det is not None and not getattr(det, "needs_near", True)
        with thread_settings(self.threads):
            reader = FrameReader(src.frames(self.max_frames, warn=False), det.detect if ahead else None, secs,
                                 detect_first=self.lm0 is None, detect_rest=self.observe, threaded=self.threads)
            overlay = None
            try:
                first, d0 = next(reader)
                tracker, noise = self._start(first, d0 if ahead else _NOT_RUN)
                if stage is not None and self.overlay:
                    from .overlay import OverlayWriter

                    overlay = OverlayThread(OverlayWriter(stage / OVERLAY_FILE, src.fps, src.size),
                                            tracker.mesh.faces, secs, threaded=self.threads)
                    overlay.put(first, tracker.first.vertices, self.lm0)
                lms, Vs, losts = [tracker.first.landmarks], [tracker.first.vertices], [tracker.first.lost]
                if self.progress:
                    self.progress(1, self.total)
                for frame, d in reader:
                    dets = None
                    if det is not None and self.observe:
                        if not ahead:
                            d = self._timed("detect", det.detect, frame, near=lms[-1])
                        dets = d if d is not None and len(d) == tracker.L else None
                    res = tracker.track(frame, dets, None if noise is None else noise.sigma)
                    if noise is not None:
                        noise.update(dets, tracker.lk_motion, res.landmarks)
                    lms.append(res.landmarks)
                    Vs.append(res.vertices)
                    losts.append(res.lost)
                    if overlay is not None:
                        overlay.put(frame, res.vertices, res.landmarks, res.lost)
                    if self.progress:
                        self.progress(len(lms), self.total)
                if overlay is not None:
                    overlay, done = None, overlay
                    done.close()
            finally:
                reader.close()
                if overlay is not None:
                    overlay.close(finish=False)
        msg = src.shortfall()
        if msg:
            warnings.warn(msg, VideoWarning, stacklevel=3)
        secs["landmarks"] = tracker.timings["landmarks"]
        secs["mesh"] = tracker.timings["mesh"]
        cap = Capture(np.stack(lms), np.stack(Vs), tracker.mesh.faces.copy(), float(src.fps), src.size,
                      np.stack(losts), None, Path(src.path) if src.kind == "video" else None)
        if stage is not None:
            self._timed("output", write_capture, stage, cap)
        return cap
