"""Why a detector reads the warped picture well on a ramp and poorly on a clip: the clip's own motion replayed.

    python -m problems.clip_readback CAPTURE_DIR [CAPTURE_DIR ...] [--frames 40] [--images a,b]
        [--readers dlib,mediapipe] [--out reports/reproduction]

:mod:`problems.cartoon_readback` moves one expression measure at a time along a ramp and every target is read
back at gain ~1 (dlib on the built-in cartoon: mouth opening r 0.994); :mod:`problems.bench_cartoon` drives the
same targets by a real capture and the same detector reads the output at r 0.1-0.5. This bench takes
``--frames`` frames of each capture (evenly spread, frame 0 first), drives each target image with them as
``facebasis animate`` does without flags (:meth:`facebasis.retarget.warp2d.CartoonAnimator.drive`: head still,
fold-free, per-feature amplitude), and reads every output frame with each detector three ways:

* ``clip``: the package's warp of the capture mesh, as animated (the bench's ``r_read_``);
* ``together``: the same warped 68 landmarks replayed through the target's own landmark mesh (the ramps'
  warp: Delaunay triangles of the 68 points), every feature moving as on the clip;
* ``alone``: as ``together`` with only the measure's own landmarks moving (mouth opening: lower lip and chin;
  mouth width: the corners and their neighbours; brows; eyes), the rest held at rest: the ramp's condition
  with the clip's natural amplitudes.

Per (clip, image, reader, measure): the warped measure's standard deviation over the frames (``sd_warp``, eye
distances) against the detector's still noise on the image (``noise``, :func:`problems.cartoon_check.still_noise`)
and the read-back that noise allows at gain 1 (``floor``); the read-back correlation of each way, and for dlib
the fraction of output frames whose face box is not the one found on the unwarped image (``box_other``: the
HOG detector's scale pyramid; a frame on the other scale moves the shape predictor's whole reading) and the
read-back over the frames on the rest image's box only (``r_clip_rest_box``).

``alone`` against ``together`` is the cost of several features moving at once (cross-talk in the detector's
fit); ``together`` against ``clip`` the cost of the capture mesh's interior; ``floor`` the cost of the clip's
small amplitudes against the detector's noise. Output: ``clip_readback.csv`` / ``.md``, and
``clip_readback_summary.csv`` / ``.md`` (per image, reader and measure, the medians over the clips).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from problems.bench_cartoon import FEATURES, correlation, features, target_images

#: landmarks moved in the ``alone`` replay of each measure (iBUG 68)
GROUPS = {"mouth_open": np.r_[5:12, 55:60, 65:68],
          "mouth_width": np.r_[48, 49, 53, 54, 55, 59, 60, 61, 63, 64, 65, 67],
          "brow_height": np.r_[17:27], "eye_open": np.r_[36:48]}


def dlib_box(detector, image) -> tuple[float, np.ndarray | None]:
    """(width of dlib's largest face box or NaN, its 68 landmarks or None) on one picture."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    rects = list(detector._detector(img, detector.upsample))
    if not rects:
        return float("nan"), None
    rect = max(rects, key=lambda r: r.area())
    return float(rect.width()), np.array([[p.x, p.y] for p in detector._predictor(img, rect).parts()], float)


def read_frames(reader, name: str, animator, drive, n: int):
    """(n, F) measures of ``reader`` on the drive's frames (NaN where no face) and (n,) dlib box widths."""
    out, box = np.full((n, len(FEATURES)), np.nan), np.full(n, np.nan)
    for t in range(n):
        frame = animator.frame_at(drive, t)
        if name == "dlib":
            box[t], lm = dlib_box(reader, frame)
        else:
            lm = reader.detect(frame)
        if lm is not None:
            out[t] = features(lm)
    return out, box


def replay_rows(cap, clip: str, image_name: str, image, landmarks, readers: dict, frames, noise: dict) -> list[dict]:
    """Rows for one capture and one target image, every reader and measure (module docstring)."""
    from scipy.spatial import Delaunay

    from facebasis.retarget.warp2d import CartoonAnimator

    anim = CartoonAnimator(image, landmarks, cap.landmarks[0], cap.vertices[0], cap.faces)
    drive = anim.drive(cap.vertices[frames], cap.landmarks[frames])
    W = drive.still[:, :68]
    own = CartoonAnimator(image, landmarks, landmarks, landmarks, Delaunay(landmarks).simplices, jaw="capture")
    together = own.drive(W, W)
    n = len(frames)
    rows = []
    for rname, reader in readers.items():
        rest_box = dlib_box(reader, image)[0] if rname == "dlib" else float("nan")
        wf = np.array([features(x) for x in W])
        read_clip, box = read_frames(reader, rname, anim, drive, n)
        wf_t = np.array([features(x) for x in together.still[:, :68]])
        read_t, _ = read_frames(reader, rname, own, together, n)
        for k, feat in enumerate(FEATURES):
            P = np.repeat(W[:1], n, axis=0)
            P[:, GROUPS[feat]] = W[:, GROUPS[feat]]
            alone = own.drive(P, P)
            wf_a = np.array([features(x) for x in alone.still[:, :68]])
            read_a, _ = read_frames(reader, rname, own, alone, n)
            sd = float(np.std(wf[:, k]))
            sd_noise = float(noise[rname][k])
            on_rest = box == rest_box
            rows.append({
                "clip": clip, "image": image_name, "reader": rname, "feature": feat, "frames": n,
                "detected": int(np.count_nonzero(np.isfinite(read_clip[:, k]))),
                "sd_warp": sd, "noise": sd_noise, "floor": sd / np.hypot(sd, sd_noise) if sd_noise >= 0 else float("nan"),
                "r_alone": correlation(read_a[:, k], wf_a[:, k]), "r_together": correlation(read_t[:, k], wf_t[:, k]),
                "r_clip": correlation(read_clip[:, k], wf[:, k]),
                "box_other": float(np.mean(box[np.isfinite(box)] != rest_box)) if rname == "dlib" and np.isfinite(box).any()
                else float("nan"),
                "r_clip_rest_box": correlation(np.where(on_rest, read_clip[:, k], np.nan), wf[:, k]) if rname == "dlib"
                else float("nan")})
    return rows


#: the summary's columns: medians over the clips of each (image, reader, measure)
SUMMARY = ("floor", "r_alone", "r_together", "r_clip", "box_other")


def summary_rows(rows: list[dict]) -> list[dict]:
    """Per (image, reader, measure), in the rows' order: the median over the clips of :data:`SUMMARY` (NaN-aware)
    and the clips' count."""
    keys = list(dict.fromkeys((r["image"], r["reader"], r["feature"]) for r in rows))
    out = []
    for image, reader, feat in keys:
        sel = [r for r in rows if (r["image"], r["reader"], r["feature"]) == (image, reader, feat)]
        row = {"image": image, "reader": reader, "feature": feat, "clips": len(sel)}
        for c in SUMMARY:
            v = np.array([float(r[c]) for r in sel])
            row[c] = float(np.median(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")
        out.append(row)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("captures", nargs="+")
    ap.add_argument("--frames", type=int, default=40, help="frames of each capture replayed (evenly spread)")
    ap.add_argument("--images", default="cartoon,cartoon-closed,astronaut,astronaut-painted,cameraman")
    ap.add_argument("--readers", default="dlib,mediapipe")
    ap.add_argument("--noise-draws", type=int, default=12)
    ap.add_argument("--out", default="reports/reproduction")
    args = ap.parse_args(argv)
    from facebasis.capture.detect import DlibDetector
    from facebasis.capture.trackfile import read_capture

    from problems.cartoon_check import make_reader, row_text, still_noise, write_rows_table

    det = DlibDetector()
    readers = {r: (det if r == "dlib" else make_reader(r)) for r in args.readers.split(",")}
    keep = args.images.split(",")
    images = [im for im in target_images(det) if im[0] in keep]
    noise = {name: {r: still_noise(img, d, features, args.noise_draws) for r, d in readers.items()}
             for name, img, _ in images}
    rows = []
    for cdir in args.captures:
        cap = read_capture(cdir)
        frames = np.unique(np.linspace(0, cap.n_frames - 1, args.frames).round().astype(int))
        for name, img, lm in images:
            for row in replay_rows(cap, Path(cdir).name, name, img, lm, readers, frames, noise[name]):
                rows.append(row)
                print(row_text(row), flush=True)
    write_rows_table(args.out, "clip_readback", rows)
    write_rows_table(args.out, "clip_readback_summary", summary_rows(rows))


if __name__ == "__main__":
    main()
