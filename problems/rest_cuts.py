"""Calm-frame weights on many cuts of the real clips: does the rest decision hold wherever a take starts?

    python -m problems.rest_cuts LABEL=CAPTURE_DIR [LABEL=PATTERN{start} ...] [--step 50] [--length 500]
        [--variants rig_noise,default] [--first 0] [--out reports/retarget/rest_cuts.csv] [--md reports/retarget/rest_cuts.md]
    python -m problems.rest_cuts --make-track-cuts CLIP.mp4 OUT_ROOT [--step 50] [--length 500]

Each source is ``clip:mode=PATH``. A capture folder (``facebasis capture CLIP --detector dlib|mediapipe``)
is cut by slicing: a cut from frame ``start`` holds frames ``start .. start + length - 1`` (the detector
corrects every frame, so a capture of the cut itself differs only in its first frames). A ``PATH`` with
``{start}`` names one capture per cut, made from the cut itself (tracking-only captures drift from
their first frame, so slicing would not be the take the owner captures): ``--make-track-cuts`` writes
them, ``facebasis landmarks --detector dlib`` on the cut's first frame, then ``facebasis capture
--landmarks`` on the cut's frames. Cuts start every ``step`` frames from frame ``first`` and are kept
when at least 150 frames long. The recipe (``python -m problems.reproduce rest-cuts``) cuts the detector
captures (dlib and MediaPipe) every 8 s from 4 s (``--step 200 --first 100`` at 25 fps) plus the takes'
starts (``--step 100000``), and the tracking-only captures every 8 s from 0, with the variants
*previous* and *default*, merged into one table (the per-cut table compares
*default* with the first of them).

Every cut's frame 0 is labelled at rest or not by landmarks alone (:func:`facebasis.retarget.reststart.rest_start`:
the first 0.5 s held within the owner's 1.5% calm tolerance, lips closed against the capture's own
closed-lip gap), independently of any weights, then retargeted onto ICT-FaceKit's 53 expressions
(``../shared/data/ict``) with ``facebasis retarget``'s defaults (*default*), with the rest face's offsets
in-plane without depth (*previous*: ``rest_depth="none"``, the default before :mod:`facebasis.retarget.restdepth`),
with each eye's look shapes on their own (*free_gaze*: ``gaze="free"``), with the landmark noise of
a fixed size in rig units (*rig_noise*: ``noise_model="rig"``, the default before the pixel noise
model), with one noise for every landmark (*shared_points*: ``point_noise="shared"``, the default
before the per-point noise model of :mod:`facebasis.retarget.pointnoise`) and, on request, with the former model altogether (*before*: the rest rule before the landmark
evidence, the first frame's posture when it recurs and demands <= 1.25 times the commonest posture's
negative weight, ``noise_model="rig"`` and no rest depth), and measured by the owner's metric (calm frames:
landmarks within 1.5% of the face width of the cut's frame 0 after a similarity alignment; the
median over them of the largest weight, target <= 0.15; over all frames the median of the largest
left/right difference, target <= 0.2), with jawOpen on the calm frames and its correlation with the
inner-lip opening (a cut that starts with the mouth open carries jawOpen on its calm frames: those
cuts are reported apart, not counted against the target).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from facebasis.atomic import atomic_write_bytes
from problems.rig_plausibility import calm_frames, ict_problem, plausibility

MIN_FRAMES = 150
LABELS = ("rest", "not", "unknown")
LABELS_TEXT = {"rest": "at rest", "not": "not at rest", "unknown": "no evidence"}
#: variant -> (RigRetargeter keyword arguments, landmark evidence used)
VARIANTS = {"before": ({"noise_model": "rig", "point_noise": "shared", "gaze": "free", "rest_depth": "none"}, False),
            "default": ({}, True),
            "previous": ({"rest_depth": "none"}, True), "free_gaze": ({"gaze": "free"}, True),
            "no_anchor": ({"rest_anchor": False}, True),
            "rig_noise": ({"noise_model": "rig"}, True),
            "shared_points": ({"point_noise": "shared"}, True)}


@contextlib.contextmanager
def _evidence(on: bool):
    """The rest rule before the landmark evidence: rigdrive's ``rest_start`` gives none."""
    import facebasis.retarget.rigdrive as rd

    keep = rd.rest_start
    if not on:
        rd.rest_start = lambda *a, **k: None
    try:
        yield
    finally:
        rd.rest_start = keep


def cuts_of(path: str, step: int, length: int, first: int = 0):
    """(start, landmarks (T, 68, 2), lost (T, 68), fps) of every cut of a source (module docstring)."""
    from facebasis.capture.trackfile import read_capture

    if "{start}" in path:
        for start in range(first, 100000, step):
            d = Path(path.format(start=start))
            if not d.exists():
                if start > first:
                    return
                continue
            cap = read_capture(d)
            if len(cap.landmarks) >= MIN_FRAMES:
                yield start, cap.landmarks[:length], cap.lost[:length], cap.fps
        return
    cap = read_capture(path)
    for start in range(first, len(cap.landmarks) - MIN_FRAMES + 1, step):
        sl = slice(start, start + length)
        yield start, cap.landmarks[sl], cap.lost[sl], cap.fps


def write_rows(path, rows) -> None:
    keys = sorted({k for r in rows for k in r}, key=lambda k: (k not in rows[0], k))
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, keys)
        w.writeheader()
        w.writerows(rows)


def cut_rows(label: str, path: str, variants, step: int, length: int, first: int = 0, log=print,
             done=None) -> list[dict]:
    """Rows of every cut of one source and variant; ``done(rows)`` is called after each cut (the
    rows so far), so that a long run can be followed and kept while it goes."""
    from facebasis.retarget.reststart import inner_lip_gap, rest_start
    from facebasis.retarget.rigdrive import RigRetargeter

    rig, idx = ict_problem()
    clip, _, mode = label.partition(":")
    jaw = rig.names.index("jawOpen")
    rows = []
    for start, P, lost, fps in cuts_of(path, step, length, first):
        ev = rest_start(np.nan_to_num(P), ~lost & np.isfinite(P).all(2), fps)
        calm = calm_frames(P)
        nan = float("nan")
        base = {"clip": clip, "mode": mode, "start_s": start / fps, "frames": len(P),
                "start": label_of(ev), "still": ev is not None and ev.still, "closed": ev is not None and ev.closed,
                "start_deviation": ev.deviation if ev else nan, "start_gap": ev.gap if ev else nan,
                "closed_gap": ev.closed_gap if ev else nan,
                "calm_gap_median": float(np.median(inner_lip_gap(P[calm])))}
        for name in variants:
            kw, evidence = VARIANTS[name]
            t0 = time.process_time()
            with _evidence(evidence):
                res = RigRetargeter(rig, idx, **kw).run(P, lost, fps)
            cal = res.calibration
            row = {**base, "variant": name, **plausibility(rig.names, res.weights, P),
                   "calm_jawOpen_median": float(np.median(res.weights[calm, jaw])),
                   "anchored": bool(cal is not None and cal.rest_anchored),
                   "demand_ratio": float(cal.demand_ratio) if cal is not None else float("nan"),
                   "residual_px_mean": float(np.nanmean(res.residual)), "ridge": res.ridge,
                   "cpu_ms_per_frame": 1e3 * (time.process_time() - t0) / len(P)}
            rows.append(row)
            log(f"{clip:>12s} {mode:>9s} @{row['start_s']:5.1f}s {row['start']:>7s} (dev {row['start_deviation']:.4f} "
                f"gap {row['start_gap']:.3f}/{row['closed_gap']:.3f}) {name:>9s}: anchored {row['anchored']:d} "
                f"ratio {row['demand_ratio']:.2f} calm {row['calm_frames']:3d} max {row['calm_max_median']:.3f} "
                f"({row['calm_argmax']}) jawOpen {row['calm_jawOpen_median']:.3f} L/R {row['lr_diff_median']:.3f} "
                f"{row['cpu_ms_per_frame']:.1f} ms/frame")
        if done is not None:
            done(rows)
    return rows


def label_of(ev) -> str:
    """A cut's frame-0 label: 'rest', 'not' or 'unknown' (no evidence: frame 0 lost too many landmarks)."""
    return "unknown" if ev is None else ("rest" if ev.at_rest else "not")


def _stat(rows, key, fn):
    v = np.array([r[key] for r in rows], float)
    v = v[np.isfinite(v)]
    return fn(v) if len(v) else float("nan")


def summary(rows) -> str:
    """Markdown: per capture mode, start label and variant, the owner's two measures over the cuts."""
    lines = ["| mode | frame 0 | variant | cuts | anchored | calm max: median / worst | calm max <= 0.15 | "
             "calm jawOpen median | L/R: median / worst | L/R <= 0.2 | CPU ms/frame |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    keys = sorted({(r["mode"], r["start"], r["variant"]) for r in rows}, key=lambda k: (k[0], LABELS.index(k[1]), k[2]))
    for mode, start, variant in keys:
        g = [r for r in rows if (r["mode"], r["start"], r["variant"]) == (mode, start, variant)]
        ok = sum(r["calm_max_median"] <= 0.15 for r in g)
        lr = sum(r["lr_diff_median"] <= 0.2 for r in g)
        lines.append(
            f"| {mode} | {LABELS_TEXT[start]} | {variant} | {len(g)} | "
            f"{sum(r['anchored'] for r in g)} | {_stat(g, 'calm_max_median', np.median):.3f} / "
            f"{_stat(g, 'calm_max_median', np.max):.3f} | {ok}/{len(g)} | {_stat(g, 'calm_jawOpen_median', np.median):.3f} | "
            f"{_stat(g, 'lr_diff_median', np.median):.3f} / {_stat(g, 'lr_diff_median', np.max):.3f} | {lr}/{len(g)} | "
            f"{_stat(g, 'cpu_ms_per_frame', np.median):.1f} |")
    return "\n".join(lines) + "\n"


def cut_table(rows) -> str:
    """Markdown: every cut of the default variant beside the first other variant of the rows (the baseline)."""
    by = {(r["clip"], r["mode"], r["start_s"], r["variant"]): r for r in rows}
    base = next((r["variant"] for r in rows if r["variant"] != "default"), "before")
    lines = [f"| clip | mode | start s | frame 0 | still dev | lip gap / closed | calm | {base}: anchored, calm max, L/R | "
             "default: anchored, ratio, calm max (shape), calm jawOpen, L/R |", "|---|---|---|---|---|---|---|---|---|"]
    for (clip, mode, st, v), r in sorted(by.items()):
        if v != "default":
            continue
        b = by.get((clip, mode, st, base))
        bt = f"{b['anchored']:d}, {b['calm_max_median']:.3f}, {b['lr_diff_median']:.3f}" if b else ""
        lines.append(f"| {clip} | {mode} | {st:g} | {r['start']} | {r['start_deviation']:.4f} | "
                     f"{r['start_gap']:.3f} / {r['closed_gap']:.3f} | {int(r['calm_frames'])} | {bt} | {r['anchored']:d}, "
                     f"{r['demand_ratio']:.2f}, {r['calm_max_median']:.3f} ({r['calm_argmax']}), "
                     f"{r['calm_jawOpen_median']:.3f}, {r['lr_diff_median']:.3f} |")
    return "\n".join(lines) + "\n"


def make_track_cuts(video: str, out_root: str, step: int, length: int, python: str = sys.executable) -> None:
    """Tracking-only captures of the cuts of ``video`` (module docstring): ``OUT_ROOT/frames`` (every
    frame as PNG), ``OUT_ROOT/cut{start}`` (the cut's frames, links), ``OUT_ROOT/cap{start}`` (its capture)."""
    import av
    from PIL import Image

    root = Path(out_root)
    frames = root / "frames"
    if not frames.exists():
        frames.mkdir(parents=True)
        with av.open(video) as c:
            for i, fr in enumerate(c.decode(video=0)):
                Image.fromarray(fr.to_ndarray(format="rgb24")).save(frames / f"{i:05d}.png")
    names = sorted(p.name for p in frames.glob("*.png"))
    for start in range(0, len(names) - MIN_FRAMES + 1, step):
        cut, cap = root / f"cut{start}", root / f"cap{start}"
        if cap.exists():
            continue
        cut.mkdir(exist_ok=True)
        for n in names[start:start + length]:
            if not (cut / n).exists():
                (cut / n).symlink_to(frames / n)
        cli = [python, "-m", "facebasis.cli"]
        subprocess.run(cli + ["landmarks", str(cut), "--detector", "dlib", "--out", f"{cut}.pts"], check=True)
        subprocess.run(cli + ["capture", str(cut), "--landmarks", f"{cut}.pts", "--fps", "25", "--no-overlay",
                              "--no-progress", "--out", str(cap)], check=True)


def read_rows(path) -> list[dict]:
    """Rows of a CSV this bench wrote (numbers and booleans parsed back)."""
    def value(v):
        if v in ("True", "False"):
            return v == "True"
        try:
            return float(v)
        except ValueError:
            return v
    with open(path, newline="") as fh:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sources", nargs="*", help="clip:mode=CAPTURE_DIR or clip:mode=PATTERN with {start}")
    ap.add_argument("--variants", default="rig_noise,default")
    ap.add_argument("--step", type=int, default=50, help="frames between cut starts")
    ap.add_argument("--length", type=int, default=500, help="most frames of a cut")
    ap.add_argument("--first", type=int, default=0, help="frame of the first cut's start")
    ap.add_argument("--merge", nargs="+", default=(), help="CSVs of earlier runs whose rows join these")
    ap.add_argument("--out", default=None, help="CSV of the rows")
    ap.add_argument("--md", default=None, help="markdown summary and every cut")
    ap.add_argument("--summary-md", default=None, help="markdown summary table alone (the docs include it)")
    ap.add_argument("--make-track-cuts", nargs=2, metavar=("VIDEO", "OUT_ROOT"))
    args = ap.parse_args(argv)
    if args.make_track_cuts:
        make_track_cuts(*args.make_track_cuts, args.step, args.length)
        return 0
    variants = [v for v in args.variants.split(",") if v]
    if [v for v in variants if v not in VARIANTS]:
        ap.error(f"--variants: expected some of {list(VARIANTS)}, found {variants}")
    rows = [r for f in args.merge for r in read_rows(f)]
    for src in args.sources:
        label, _, path = src.partition("=")
        before = list(rows)
        rows = before + cut_rows(label, path, variants, args.step, args.length, args.first,
                                 done=lambda new: args.out and write_rows(args.out, before + new))
    if args.out and rows:
        write_rows(args.out, rows)
    if args.md and rows:
        atomic_write_bytes(args.md, ("# Calm-frame weights on cuts of the real clips (issue 23)\n\n" + summary(rows)
                                     + "\n## Every cut\n\n" + cut_table(rows)).encode())
    if args.summary_md and rows:
        atomic_write_bytes(args.summary_md, summary(rows).encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
