"""Detectors on the real clips: ``python -m problems.bench_detectors [--clips cap13_edit2 ...] [--max-frames N]``.

For each clip of ``../shared/data/video`` (skipped if absent; needs both detector extras):

1. MediaPipe's mapped 68 points against dlib's on the same frame, per iBUG group (mean distance, px),
   the check behind :data:`facebasis.capture.detect.MEDIAPIPE_TO_IBUG68`;
2. ``capture`` against per-frame dlib (mean, p95, mean of the last 100 frames, px): tracking only
   from MediaPipe's first frame; ``--detector mediapipe`` with the fixed prior weight (the filter's
   ``detection_sigma``, the path ``--detector dlib`` used before issue 29); ``--detector mediapipe``
   with the noise measured on the video (:class:`facebasis.capture.detect.DetectionNoise`, the default);
3. the whole ``capture --detector mediapipe --no-overlay`` time per frame (decoding included).

Prints a table; writes nothing. Timings depend on the machine's load: ``cat /proc/loadavg`` beside them.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

VIDEO_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "video"
GROUPS = {"jaw": (0, 17), "brows": (17, 27), "nose": (27, 36), "eyes": (36, 48), "outer lip": (48, 60),
          "inner lip": (60, 68)}


class _FixedNoise:
    """Stand-in for DetectionNoise keeping the prior weight (the pre-issue-29 behaviour)."""

    def __init__(self, n_landmarks, prior, floor, **_):
        self._s = np.full(n_landmarks, prior)

    @property
    def sigma(self):
        return self._s

    def update(self, *_):
        return self._s


def per_frame(path, max_frames):
    from facebasis.capture.detect import get_detector, mediapipe_to_ibug68
    from facebasis.capture.video import open_frames

    dl, mp = get_detector("dlib"), get_detector("mediapipe")
    D, M, prev = [], [], None
    for fr in open_frames(path).frames(max_frames):
        d = dl.detect(fr, near=prev)
        prev = d if d is not None else prev
        D.append(np.full((68, 2), np.nan) if d is None else d)
        m = mp.detect_dense(fr)
        M.append(np.full((68, 2), np.nan) if m is None else mediapipe_to_ibug68(m))
    return np.array(D), np.array(M)


def errors(L, D):
    ok = np.isfinite(D).all((1, 2)) & np.isfinite(L).all((1, 2))
    e = np.linalg.norm(L[ok] - D[ok], axis=-1)
    return e


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", nargs="+", default=["cap12_edit", "cap13_edit2"])
    ap.add_argument("--max-frames", type=int, default=None)
    args = ap.parse_args(argv)
    import facebasis.capture.detect as detect
    from facebasis.capture import capture
    from facebasis.capture.video import read_frame

    for name in args.clips:
        path = VIDEO_DIR / f"{name}.mp4"
        if not path.exists():
            print(f"{name}: not found in {VIDEO_DIR}, skipped")
            continue
        D, M = per_frame(path, args.max_frames)
        e = errors(M, D)
        print(f"\n{name}: {len(D)} frames; MediaPipe mapped vs dlib, same frame (mean px): "
              + ", ".join(f"{g} {e[:, a:b].mean():.2f}" for g, (a, b) in GROUPS.items()) + f", all {e.mean():.2f}")
        lm0 = detect.get_detector("mediapipe", video=False).detect(read_frame(path, 0))
        runs = {"tracking only (MediaPipe frame 0)": dict(landmarks=lm0),
                "--detector mediapipe, fixed weight": dict(detector="mediapipe", fixed=True),
                "--detector mediapipe, measured noise": dict(detector="mediapipe")}
        print(f"  {'capture vs per-frame dlib':40s} {'mean':>6s} {'p95':>6s} {'last100':>8s} {'ms/frame':>9s}")
        for label, kw in runs.items():
            saved = detect.DetectionNoise
            if kw.pop("fixed", False):
                detect.DetectionNoise = _FixedNoise
            try:
                t = time.perf_counter()
                res = capture(path, overlay=False, max_frames=args.max_frames, **kw)
                ms = 1000 * (time.perf_counter() - t) / len(res.landmarks)
            finally:
                detect.DetectionNoise = saved
            e = errors(res.landmarks, D)
            print(f"  {label:40s} {e.mean():6.2f} {np.percentile(e, 95):6.2f} {e[-100:].mean():8.2f} {ms:9.1f}")
    try:
        print(f"\nload: {open('/proc/loadavg').read().strip()}")
    except OSError:
        pass


if __name__ == "__main__":
    main()
