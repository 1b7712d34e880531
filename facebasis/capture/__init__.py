"""Markerless face capture (Wu & Ju, "Markerless facial expression capture and reproduction",
Acta Electronica Sinica, 2016(9)).

Landmarks given (or detected) on the first frame bound a uniform triangle mesh of the face.
Landmarks are tracked with pyramidal Lucas-Kanade in region-dependent windows, stabilised by a
CONDENSATION particle filter; their displacements drive a harmonic deformation of the mesh
(cotangent Laplacian, factored once, eq. 7-9), refined by Levenberg-Marquardt on an intensity-sum
data term plus a smoothness term (eq. 1-5).

Modules: ``video`` (frame sources), ``landmarks`` (files, iBUG-68 regions, LK windows),
``detect`` (optional dlib and MediaPipe detectors), ``lips`` (inner lips placed from the outer lip),
``eyelids`` (lids placed in the eye-corner frame: from detections, or searched across the eye),
``facemesh`` (mesh), ``harmonic`` (eq. 6-9), ``lk`` (Lucas-Kanade, drift correction), ``particle``
(CONDENSATION), ``meshtrack`` (eq. 1-5), ``options`` (:class:`TrackerOptions`), ``tracker``
(:class:`FaceTracker`, :func:`capture`), ``inputs`` (what :func:`capture` checks before any work,
:class:`CaptureResult`), ``trackfile`` (output format, :func:`read_capture`),
``overlay`` (overlay video), ``pipeline`` (:func:`capture`'s background threads: decoding and
detection ahead of the tracker, the overlay behind it), ``synthetic`` (generated sequences with
ground truth).
"""

from ..geometry.laplacian import cotangent_laplacian
from .facemesh import FaceMesh, build_face_mesh
from .harmonic import HarmonicDeformer
from .landmarks import IBUG68_REGIONS, read_landmarks
from .meshtrack import MeshOptions
from .particle import FilterOptions
from .synthetic import (
    Motion,
    SyntheticSequence,
    astronaut_face,
    cartoon_face,
    synthetic_sequence,
)
from .tracker import CaptureResult, FaceTracker, FrameResult, TrackerOptions, capture
from .trackfile import Capture, read_capture, write_capture
from .video import FrameSource, open_frames

__all__ = [
    "IBUG68_REGIONS",
    "Capture",
    "CaptureResult",
    "FaceMesh",
    "FaceTracker",
    "FilterOptions",
    "FrameResult",
    "FrameSource",
    "HarmonicDeformer",
    "MeshOptions",
    "Motion",
    "SyntheticSequence",
    "TrackerOptions",
    "astronaut_face",
    "build_face_mesh",
    "capture",
    "cartoon_face",
    "cotangent_laplacian",
    "open_frames",
    "read_capture",
    "read_landmarks",
    "synthetic_sequence",
    "write_capture",
]
