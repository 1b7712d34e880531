"""The two captures' expression measures against two detectors on the source video, frame by frame.

    python -m problems.capture_features CLIP=DET_CAPTURE,TRACK_CAPTURE [...] [--out reports/reproduction]
        [--dlib-every 3]

The painting check compares a detector's reading of the animated picture with its reading of the
source video; no warp can follow the source better than the capture driving it does. For each clip,
the capture made with ``--detector dlib`` and the tracking-only capture (no detector after frame 0)
are compared, per expression measure of :func:`problems.bench_cartoon.features`, with dlib (every
``--dlib-every``-th frame) and MediaPipe (static-image mode, every frame) run on the source frames:
the Pearson correlation over the whole take and over each quarter of it (drift shows as a
correlation that falls quarter by quarter), the mean offset of the tracking-only measure from the
dlib capture's per quarter, and the two detectors' agreement with each other (what a check on the
real face can reach at all). Writes ``capture_features.csv`` / ``.md``.
"""

from __future__ import annotations

import argparse

import numpy as np

from problems.bench_cartoon import FEATURES, correlation, features


def source_measures(cap, dlib_every: int):
    """(T, F) dlib (every ``dlib_every``-th frame, NaN elsewhere) and MediaPipe measures of the source frames."""
    from facebasis.retarget.media import read_video_frames
    from problems.cartoon_check import make_reader

    mp, dl = make_reader("mediapipe"), make_reader("dlib")
    T = cap.n_frames
    M, D = np.full((T, len(FEATURES)), np.nan), np.full((T, len(FEATURES)), np.nan)
    for t, fr in enumerate(read_video_frames(cap.video)):
        if t >= T:
            break
        a = mp.detect(fr)
        if a is not None:
            M[t] = features(a)
        if t % dlib_every == 0:
            b = dl.detect(fr)
            if b is not None:
                D[t] = features(b)
    return D, M


def rows_for_clip(clip, det, trk, dlib_every: int) -> list[dict]:
    D, M = source_measures(det, dlib_every)
    fd = np.array([features(x) for x in det.landmarks])
    ft = np.array([features(x) for x in trk.landmarks[:det.n_frames]])
    quarters = np.array_split(np.arange(len(fd)), 4)
    rows = []
    for k, f in enumerate(FEATURES):
        row = {"clip": clip, "feature": f,
               "det_dlib": correlation(fd[:, k], D[:, k]), "track_dlib": correlation(ft[:, k], D[:, k]),
               "det_mp": correlation(fd[:, k], M[:, k]), "track_mp": correlation(ft[:, k], M[:, k]),
               "dlib_mp": correlation(D[:, k], M[:, k]), "det_track": correlation(fd[:, k], ft[:, k])}
        for q, i in enumerate(quarters, 1):
            row[f"det_dlib_q{q}"] = correlation(fd[i, k], D[i, k])
            row[f"track_dlib_q{q}"] = correlation(ft[i, k], D[i, k])
            row[f"track_minus_det_q{q}"] = float(np.mean(ft[i, k] - fd[i, k]))
        rows.append(row)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("clips", nargs="+", help="CLIP=DET_CAPTURE,TRACK_CAPTURE")
    ap.add_argument("--out", default="reports/reproduction")
    ap.add_argument("--dlib-every", type=int, default=3)
    args = ap.parse_args(argv)
    from facebasis.capture.trackfile import read_capture
    from problems.cartoon_check import row_text, write_rows_table

    rows = []
    for spec in args.clips:
        clip, dirs = spec.split("=", 1)
        det_dir, trk_dir = dirs.split(",")
        for row in rows_for_clip(clip, read_capture(det_dir), read_capture(trk_dir), args.dlib_every):
            rows.append(row)
            print(row_text(row), flush=True)
    write_rows_table(args.out, "capture_features", rows)


if __name__ == "__main__":
    main()
