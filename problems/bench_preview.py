"""Benchmark of the retarget preview video (issue 23: <= 20 ms per frame, 1000 frames at 400x300).

    python -m problems.bench_preview [--frames 1000] [--rig ict|builtin]

A 400x300 source video of ``--frames`` frames is written to a temporary folder (generated moving
gradients, so the benchmark needs no data), then :func:`facebasis.retarget.preview.write_preview`
encodes it beside the rig (ICT-FaceKit's 14062-vertex / 28068-triangle head when the data is there,
else the built-in face) rendered with smooth weight curves and head rotations, framed on the face
(its 68 landmark vertices, as ``retarget`` does). Reported: wall and
CPU ms per frame of the whole preview (decoding the source, rendering, side by side, encoding),
and of the rendering alone, with the load average (the machine may be shared).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def source_frames(n: int, size=(300, 400)):
    h, w = size
    y, x = np.mgrid[0:h, 0:w]
    for f in range(n):
        img = np.empty((h, w, 3), np.uint8)
        img[..., 0] = (x + 3 * f) % 256
        img[..., 1] = (y + 2 * f) % 256
        img[..., 2] = 128
        yield img


def main(argv=None) -> int:
    from facebasis.retarget.media import write_mp4
    from facebasis.retarget.pose import rotation_from_vector
    from facebasis.retarget.preview import MeshRenderer, rig_frames, write_preview
    from facebasis.retarget.synthetic import smooth_weight_curves

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--rig", choices=("ict", "builtin"), default="ict")
    args = ap.parse_args(argv)
    T = args.frames
    rig = None
    if args.rig == "ict":
        from problems.ict import ict_available, ict_rig

        rig = ict_rig() if ict_available() else None
    if rig is None:
        from facebasis.defaults.face import default_template

        rig = default_template()
    active = [n for n in ("jawOpen", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L", "eyeBlink_R", "browInnerUp")
              if n in rig.names]
    W = smooth_weight_curves(rig.names, active, T, seed=1)
    t = np.arange(T) / 30.0
    Rs = np.stack([rotation_from_vector([0.1 * np.sin(0.7 * s), 0.3 * np.sin(0.4 * s), 0.05 * np.sin(s)]) for s in t])
    with tempfile.TemporaryDirectory(prefix="facebasis-preview-") as tmp:
        src = Path(tmp) / "source.mp4"
        write_mp4(src, source_frames(T), 30.0)
        frame_v = rig_frames(rig, W)
        c0, t0 = time.process_time(), time.perf_counter()
        focus = None
        if args.rig == "ict" and rig.source == "ICT-FaceKit":
            from problems.ict import _load

            focus = _load()["landmarks68"]
        st = write_preview(Path(tmp) / "preview.mp4", rig.neutral, rig.faces, frame_v, T, 30.0, Rs, src, focus=focus)
        cpu = 1e3 * (time.process_time() - c0) / T
        wall = 1e3 * (time.perf_counter() - t0) / T
        r = MeshRenderer(rig.neutral, rig.faces, (300, 300), focus)
        n_r = min(T, 200)
        c0, t0 = time.process_time(), time.perf_counter()
        for f in range(n_r):
            r.render(frame_v(f), Rs[f])
        rcpu = 1e3 * (time.process_time() - c0) / n_r
        rwall = 1e3 * (time.perf_counter() - t0) / n_r
    load = os.getloadavg()
    print(f"rig {rig.source}: {rig.n_vertices} vertices, {len(rig.faces)} triangles; {st.frames} frames, preview "
          f"{st.width}x{st.height}")
    print(f"preview (decode + render + encode): {wall:.1f} ms/frame wall, {cpu:.1f} ms/frame CPU (target <= 20)")
    print(f"render alone (300x300 panel): {rwall:.1f} ms/frame wall, {rcpu:.1f} ms/frame CPU")
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
