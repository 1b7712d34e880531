"""``facebasis capture``: markerless face capture from a video or an image folder."""

from __future__ import annotations

import argparse
import sys

from .common import Once
from .outputs import Outputs

DESCRIPTION = """\
Track a face through a video file or a folder of images (sorted by name).
Give the face's landmarks on the first frame with --landmarks (an iBUG .pts file
or a JSON list of [x, y] pairs, in pixels; 'facebasis landmarks' writes one) or let a
detector find them with --detector mediapipe (Apache-2.0 model shipped in its wheel:
pip install 'facebasis[mediapipe]') or --detector dlib (pip install 'facebasis[detect]';
its model carries iBUG 300-W's non-commercial terms). With a detector, every frame's
detection also corrects the track's drift, weighed by the detector's noise measured
on the video. A triangle mesh is laid over the face and tracked with it.

Writes OUT_DIR/track.npz (landmark and mesh-vertex positions per frame, mesh
triangles, frame rate, frame size, lost-point flags), OUT_DIR/landmarks.csv and,
unless --no-overlay, OUT_DIR/overlay.mp4 with the mesh drawn on the input.
"""


def _number(text: str) -> float:
    """An option's text as a number; NaN where it is none (the caller's range check then refuses it)."""
    try:
        return float(text)
    except ValueError:
        return float("nan")


def _int_option(text: str, flag: str, minimum: int, expected: str) -> int:
    """A whole-number option (``--max-frames``, ``--frame``): InputError naming the flag below ``minimum``."""
    from facebasis.errors import InputError

    try:
        v = int(text)
    except ValueError:
        raise InputError(f"{flag}: expected {expected}, found {text!r}") from None
    if v < minimum:
        raise InputError(f"{flag}: expected {expected}, found {v}")
    return v


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``capture`` subcommand to an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "capture", help="track face landmarks and a face mesh through a video or image folder",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", metavar="VIDEO_OR_DIR", help="video file (mp4, avi, ...) or folder of png/jpg images")
    p.add_argument("--landmarks", metavar="FIRST.pts",
                   help="landmarks on the first frame: iBUG .pts file or JSON [[x, y], ...] (pixels)")
    p.add_argument("--detector", metavar="NAME",
                   help="detect the landmarks instead, and use every frame's detection against drift: "
                        "mediapipe or dlib")
    p.add_argument("--out", required=True, metavar="OUT_DIR", help="output folder (replaced only on success)")
    p.add_argument("--max-frames", type=str, default=None, metavar="N", help="stop after N frames")
    p.add_argument("--no-overlay", action="store_true", help="do not write overlay.mp4")
    p.add_argument("--fps", type=float, default=None, metavar="F",
                   help="frame rate of an image folder (default 25)")
    p.add_argument("--inner-lips", default="auto", metavar="auto|follow|track",
                   help="inner-lip points of a 68-point iBUG set: 'auto' (default) tracks a point while its "
                        "first-frame appearance is found again and otherwise moves it with the outer lip; "
                        "'follow' always moves them with the outer lip across the same lip, keeping the first "
                        "frame's lip thickness (renewed from the detections with --detector), since closed lips "
                        "put an upper and a lower point on one patch that LK cannot split; 'track' tracks the "
                        "lip line itself (the mouth may not open)")
    p.add_argument("--drift-blur", default=None, action=Once, metavar="PX",
                   help="blur (pixels for a 150 px wide face, scaled with the face) of the image the drift "
                        "correction aligns first-frame patches on; default 0.5: sharp enough that patches do not "
                        "slide along lip lines and eyelids on clean footage; strongly compressed webcam video may "
                        "track better with more (1.5 was the former value)")
    p.add_argument("--detected-lids", default=None, action=Once, metavar="G",
                   help="with --detector: weight in [0, 1] of each frame's detected eyelids, placed on the tracked "
                        "eye corners and averaged over time (z += G (z_detected - z)); default 0.7; 1 = the "
                        "detector's lids as they are (jitter included), 0 = the lids as without a detector")
    p.add_argument("--no-lid-search", action="store_true",
                   help="without a detection, track the eyelid points as the other points (they slide along the "
                        "lid line and miss blinks) instead of searching each lid across the eye for its "
                        "first-frame look")
    p.add_argument("--no-progress", action="store_true", help="do not show a progress bar")
    p.set_defaults(func=cmd_capture, outputs=Outputs(writes=(("out", "folder", "--out"),), reads=("input", "landmarks")))
    register_landmarks(subparsers)
    return p


def cmd_capture(args) -> int:
    """Run ``facebasis capture``; every user error is raised as a FacebasisError before work starts."""
    import warnings

    from tqdm import tqdm

    from facebasis.capture.tracker import (
        INNER_LIPS,
        TrackerOptions,
        capture,
        check_capture_args,
    )
    from facebasis.capture.video import VideoWarning
    from facebasis.errors import InputError

    if args.inner_lips not in INNER_LIPS:
        raise InputError(f"--inner-lips: expected one of {', '.join(INNER_LIPS)}, found {args.inner_lips!r}")
    drift_blur = TrackerOptions.drift_blur
    if args.drift_blur is not None:
        drift_blur = _number(args.drift_blur)
        if not (drift_blur >= 0 and drift_blur != float("inf")):
            raise InputError(f"--drift-blur: expected a number of pixels >= 0, found {args.drift_blur!r}")
    lids = TrackerOptions.detected_lids
    if args.detected_lids is not None:
        lids = _number(args.detected_lids)
        if not 0 <= lids <= 1:
            raise InputError(f"--detected-lids: expected a number in [0, 1], found {args.detected_lids!r}")
        if args.detector is None:     # without detections the option has nothing to act on
            raise InputError("--detected-lids: expected together with --detector, found tracking only "
                             "(--landmarks)")
    max_frames = (None if args.max_frames is None
                  else _int_option(args.max_frames, "--max-frames", 1, "a positive integer"))
    src, lm, det = check_capture_args(args.input, args.landmarks, args.detector, args.out, max_frames, args.fps)
    total = src.n_frames if max_frames is None else (min(max_frames, src.n_frames) if src.n_frames else max_frames)
    bar = None if args.no_progress else tqdm(total=total, unit="frame", desc="capture")

    def progress(done, _total):
        if bar is not None:
            bar.update(done - bar.n)

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", VideoWarning)
            res = capture(src, landmarks=lm, detector=det, out=args.out, max_frames=max_frames,
                          overlay=not args.no_overlay, progress=progress,
                          options=TrackerOptions(inner_lips=args.inner_lips, drift_blur=drift_blur,
                                                 detected_lids=lids, lid_search=not args.no_lid_search))
    finally:
        if bar is not None:
            bar.close()
    for w in caught:
        if issubclass(w.category, VideoWarning):
            print(f"warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    cap = res.capture
    s = res.seconds
    print(f"tracked {cap.n_frames} frames, {cap.landmarks.shape[1]} landmarks, {cap.vertices.shape[1]} mesh vertices, "
          f"{len(cap.faces)} triangles")
    print(lost_summary(cap.lost))
    print(f"time: decode {s['decode']:.1f} s, landmarks {s['landmarks']:.1f} s, mesh {s['mesh']:.1f} s, "
          f"detector {s['detect']:.1f} s, output {s['output']:.1f} s (decoding, the overlay and MediaPipe's "
          f"detections run in background threads beside the tracking)")
    print(f"wrote {res.out}")
    return 0


def lost_summary(lost) -> str:
    """One line on the lost-point flags ``(T, L)``: frames with any lost point and the mean count per frame.

    A landmark is 'lost' for a frame when its Lucas-Kanade measurement was rejected and the filter
    carried it; a point or two per frame is normal, so both figures are printed.
    """
    import numpy as np

    lost = np.asarray(lost, bool)
    T, L = lost.shape
    per_frame = lost.sum(1)
    return (f"lost landmarks (Lucas-Kanade rejected, carried by the filter): {per_frame.mean():.1f} of {L} "
            f"per frame on average; {int((per_frame > 0).sum())} of {T} frames had at least one")


LANDMARKS_DESCRIPTION = """Detect the 68 iBUG landmarks on one frame (the first, or --frame N counting from 0)
of a video, an image folder or a single image, and write them as an iBUG .pts file
that 'facebasis capture --landmarks' reads. --detector mediapipe (Apache-2.0, pip
install 'facebasis[mediapipe]') or dlib (pip install 'facebasis[detect]'); by default
the first of the two that is installed. From a clone: pip install '.[mediapipe]'.
The .pts is plain text, one 'x y' line per point in iBUG order (pixels, x right, y
down): correct a point by editing its line (README, "Correcting first-frame landmarks").
"""


def register_landmarks(subparsers) -> argparse.ArgumentParser:
    """Add the ``landmarks`` subcommand."""
    p = subparsers.add_parser(
        "landmarks", help="write a frame's 68 landmarks (.pts) from a detector, for capture --landmarks",
        description=LANDMARKS_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", metavar="VIDEO_OR_IMAGE", help="video file, image file or folder of images")
    p.add_argument("--out", required=True, metavar="FIRST.pts", help="the .pts file to write")
    p.add_argument("--detector", default=None, metavar="NAME",
                   help="mediapipe or dlib (default: the first of them that is installed)")
    p.add_argument("--frame", default="0", metavar="N", help="frame number, counting from 0 (default 0)")
    p.set_defaults(func=cmd_landmarks, outputs=Outputs(writes=(("out", "file", "--out"),), reads=("input",)))
    return p


def cmd_landmarks(args) -> int:
    """Run ``facebasis landmarks``: checks every argument, then detects and writes the .pts."""
    from pathlib import Path

    from facebasis.atomic import atomic_write_bytes
    from facebasis.capture.detect import detect_landmarks
    from facebasis.capture.landmarks import format_pts
    from facebasis.errors import InputError

    out = Path(args.out)
    if out.suffix.lower() != ".pts":
        raise InputError(f"--out: expected a file name ending in .pts, found {str(out)!r}")
    if out.is_dir():
        raise InputError(f"--out {out}: expected a file name, found a folder")
    if not Path(args.input).exists():
        raise InputError(f"input {args.input}: expected a video file, an image or an image folder, found nothing")
    index = _int_option(args.frame, "--frame", 0, "a frame number >= 0")
    pts, name = detect_landmarks(args.input, args.detector, index)
    atomic_write_bytes(out, format_pts(pts).encode())
    print(f"{name}: {len(pts)} landmarks on frame {index} of {args.input}")
    print(f"wrote {out}")
    return 0
