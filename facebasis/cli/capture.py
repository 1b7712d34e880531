"""``facebasis capture``: markerless face capture from a video or an image folder."""

from __future__ import annotations

import argparse

from .outputs import Outputs

DESCRIPTION = """\
Track a face through a video file or a folder of images (sorted by name).
Give the face's landmarks on the first frame with --landmarks (an iBUG .pts file
or a JSON list of [x, y] pairs, in pixels) or let a detector find them with
--detector dlib (needs the optional packages: pip install 'facebasis[detect]').
A triangle mesh is laid over the face and tracked with it.

Writes OUT_DIR/track.npz (landmark and mesh-vertex positions per frame, mesh
triangles, frame rate, frame size, lost-point flags), OUT_DIR/landmarks.csv and,
unless --no-overlay, OUT_DIR/overlay.mp4 with the mesh drawn on the input.
"""


def _positive_int(text: str) -> int:
    from facebasis.errors import InputError

    try:
        v = int(text)
    except ValueError:
        raise InputError(f"--max-frames: expected a positive integer, found {text!r}") from None
    if v < 1:
        raise InputError(f"--max-frames: expected a positive integer, found {v}")
    return v


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``capture`` subcommand to an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "capture", help="track face landmarks and a face mesh through a video or image folder",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", metavar="VIDEO_OR_DIR", help="video file (mp4, avi, ...) or folder of png/jpg images")
    p.add_argument("--landmarks", metavar="FIRST.pts",
                   help="landmarks on the first frame: iBUG .pts file or JSON [[x, y], ...] (pixels)")
    p.add_argument("--detector", metavar="NAME", help="detect the landmarks instead; NAME is dlib")
    p.add_argument("--out", required=True, metavar="OUT_DIR", help="output folder (replaced only on success)")
    p.add_argument("--max-frames", type=str, default=None, metavar="N", help="stop after N frames")
    p.add_argument("--no-overlay", action="store_true", help="do not write overlay.mp4")
    p.add_argument("--fps", type=float, default=None, metavar="F",
                   help="frame rate of an image folder (default 25)")
    p.add_argument("--inner-lips", default="follow", metavar="follow|track",
                   help="inner-lip points of a 68-point iBUG set: 'follow' (default) moves them with the outer "
                        "lip across the same lip, keeping the first frame's lip thickness (renewed from the "
                        "detections with --detector), since closed lips put an upper and a lower point on one "
                        "patch that LK cannot split; 'track' tracks the lip line itself (the mouth may not open)")
    p.add_argument("--no-progress", action="store_true", help="do not show a progress bar")
    p.set_defaults(func=cmd_capture, outputs=Outputs(writes=(("out", "folder", "--out"),), reads=("input", "landmarks")))
    return p


def cmd_capture(args) -> int:
    """Run ``facebasis capture``; every user error is raised as a FacebasisError before work starts."""
    from tqdm import tqdm

    from facebasis.capture.tracker import (
        INNER_LIPS,
        TrackerOptions,
        capture,
        check_capture_args,
    )
    from facebasis.errors import InputError

    if args.inner_lips not in INNER_LIPS:
        raise InputError(f"--inner-lips: expected one of {', '.join(INNER_LIPS)}, found {args.inner_lips!r}")
    max_frames = None if args.max_frames is None else _positive_int(args.max_frames)
    src, lm, det = check_capture_args(args.input, args.landmarks, args.detector, args.out, max_frames, args.fps)
    total = src.n_frames if max_frames is None else (min(max_frames, src.n_frames) if src.n_frames else max_frames)
    bar = None if args.no_progress else tqdm(total=total, unit="frame", desc="capture")

    def progress(done, _total):
        if bar is not None:
            bar.update(done - bar.n)

    try:
        res = capture(src, landmarks=lm, detector=det, out=args.out, max_frames=max_frames,
                      overlay=not args.no_overlay, progress=progress,
                      options=TrackerOptions(inner_lips=args.inner_lips))
    finally:
        if bar is not None:
            bar.close()
    cap = res.capture
    s = res.seconds
    n_lost = int(cap.lost.any(axis=1).sum())
    print(f"tracked {cap.n_frames} frames, {cap.landmarks.shape[1]} landmarks, {cap.vertices.shape[1]} mesh vertices, "
          f"{len(cap.faces)} triangles")
    print(f"frames with a lost landmark: {n_lost}")
    print(f"time: decode {s['decode']:.1f} s, landmarks {s['landmarks']:.1f} s, mesh {s['mesh']:.1f} s, "
          f"detector {s['detect']:.1f} s, output {s['output']:.1f} s")
    print(f"wrote {res.out}")
    return 0
