"""The painting check's readers: which frames each detector reads, and how much of its reading is its own noise.

Used by :mod:`problems.bench_cartoon` (the expression check on the real clips) and
:mod:`problems.cartoon_readback`. Two detectors read the animated picture and the source video:

* ``dlib`` (HOG face detector + 68-point shape predictor, 0.25-0.35 s on a 512 px picture with its
  one up-sampling): every ``check_every``-th frame, plus every frame of the capture's blinks
  (:func:`blink_frames`: a blink lasts 3-6 frames, every 10th frame almost never sees one);
* ``mediapipe`` (face mesh mapped on the 68 iBUG points, 10-45 ms): every ``mp_every``-th frame
  (a denser sampling: 2 in the recipe) plus the blinks, each frame an independent detection
  (``static_image_mode``: nothing carried over from the previous frame, as a detector run on single
  frames of the output video).

The detector's own noise on a still picture (:func:`still_noise`): the target at rest (the warp of
the rest mesh, what every frame of a motionless capture shows) shifted by ``n`` random sub-pixel
offsets and read ``n`` times; the standard deviation of each expression measure is the noise the
detector adds to any frame. With the detector's gain ``g`` on the clip (the slope of its reading
against the warped measure) and the warped measure's standard deviation ``sd_w`` over the clip, a
reading that is the warped measure times ``g`` plus that noise correlates with the warp at

    r_floor = g sd_w / sqrt((g sd_w)^2 + sd_noise^2)

(:func:`noise_ceiling`): the read-back the detector's still noise alone allows. A read-back well
below it is motion the detector reads as something else (another feature, the head), not noise.
"""

from __future__ import annotations

import numpy as np

#: the detectors of the check, with the column prefix of their check correlation (dlib's is the
#: former ``r_`` columns)
READERS = (("dlib", ""), ("mediapipe", "mp_"))


def row_text(row: dict) -> str:
    """One result row as ``key=value`` words (floats to 3 significant digits): the benches' progress line."""
    return " ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items())


def write_rows_table(out, name: str, rows: list[dict]) -> None:
    """``name``.csv and .md under ``out`` (made if missing) from dict rows, columns in the first row's order."""
    from pathlib import Path

    from facebasis.report.tables import write_table

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cols = list(rows[0])
    write_table(out, name, cols, [[r[c] for c in cols] for r in rows], floatfmt="{:.3g}")
    print(f"wrote {out / (name + '.csv')} and {name}.md")


def make_reader(name: str):
    """A detector reading single pictures: dlib, or MediaPipe in static-image mode."""
    from facebasis.capture.detect import DlibDetector, MediaPipeDetector

    return DlibDetector() if name == "dlib" else MediaPipeDetector(video=False)


def blink_frames(landmarks, quantile: float = 0.05, pad: int = 2) -> np.ndarray:
    """(k,) frame indices where the capture's eyes are most closed (its blinks, when the take has them):
    frames whose mean eye opening (lid gap over eye width, iBUG 37-41, 38-40, 43-47, 44-46 over 36-39,
    42-45) lies in the lowest ``quantile`` of the take, with ``pad`` frames either side."""
    lm = np.asarray(landmarks, np.float64)
    gap = (np.linalg.norm(lm[:, [37, 38, 43, 44]] - lm[:, [41, 40, 47, 46]], axis=2).mean(1)
           / np.linalg.norm(lm[:, [39, 45]] - lm[:, [36, 42]], axis=2).mean(1))
    low = np.flatnonzero(gap <= np.quantile(gap, quantile))
    near = (low[:, None] + np.arange(-pad, pad + 1)[None]).ravel()
    return np.unique(near[(near >= 0) & (near < len(lm))])


def checked_frames(n_frames: int, check_every: int, landmarks=None) -> np.ndarray:
    """Sorted frame indices a reader reads: every ``check_every``-th frame plus the capture's blinks
    (:func:`blink_frames`) when ``landmarks`` (T, 68, 2) are given."""
    frames = np.arange(0, n_frames, max(int(check_every), 1))
    if landmarks is not None and np.asarray(landmarks).shape[1] == 68:
        frames = np.union1d(frames, blink_frames(landmarks))
    return frames


def still_noise(image, reader, features, n: int = 12, seed: int = 0) -> np.ndarray:
    """(F,) standard deviation of ``features(reader.detect(x))`` over ``n`` copies of ``image`` shifted by
    random sub-pixel offsets (uniform in [-0.5, 0.5] px each axis, bilinear; seeded), NaN where the
    detector finds a face on fewer than 3."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = image.shape[:2]
    out = []
    for dx, dy in rng.uniform(-0.5, 0.5, (n, 2)):
        moved = cv2.warpAffine(image, np.float32([[1, 0, dx], [0, 1, dy]]), (w, h), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_REPLICATE)
        d = reader.detect(moved)
        if d is not None:
            out.append(features(d))
    if len(out) < 3:
        return np.full(4, np.nan)
    return np.std(np.array(out), axis=0, ddof=1)


def gain(read, warped) -> float:
    """Slope of ``read`` against ``warped`` (least squares over the frames finite in both; NaN if < 4)."""
    ok = np.isfinite(read) & np.isfinite(warped)
    if ok.sum() < 4 or np.std(warped[ok]) == 0:
        return float("nan")
    return float(np.polyfit(warped[ok], read[ok], 1)[0])


def multiple_correlation(read, warped) -> float:
    """Correlation of ``read`` (T,) with its least-squares fit on all columns of ``warped`` (T, F) (and a
    constant) over the frames finite everywhere (NaN if fewer than F + 3): beside the correlation with the
    feature's own warped measure, how much of the reading the other features' motion explains (cross-talk:
    a mouth widening read as opening)."""
    ok = np.isfinite(read) & np.isfinite(warped).all(1)
    if ok.sum() < warped.shape[1] + 3 or np.std(read[ok]) == 0:
        return float("nan")
    A = np.c_[warped[ok], np.ones(ok.sum())]
    fit = A @ np.linalg.lstsq(A, read[ok], rcond=None)[0]
    return float(np.corrcoef(fit, read[ok])[0, 1]) if np.std(fit) > 0 else float("nan")


def noise_ceiling(g: float, sd_warp: float, sd_noise: float) -> float:
    """``g sd_w / sqrt((g sd_w)^2 + sd_noise^2)`` (module docstring); NaN when any is not finite."""
    if not (np.isfinite(g) and np.isfinite(sd_warp) and np.isfinite(sd_noise)):
        return float("nan")
    s = abs(g) * sd_warp
    return float(np.sign(g) * s / np.hypot(s, sd_noise)) if np.hypot(s, sd_noise) > 0 else float("nan")


__all__ = ["READERS", "make_reader", "blink_frames", "checked_frames", "still_noise", "gain", "multiple_correlation", "noise_ceiling"]
