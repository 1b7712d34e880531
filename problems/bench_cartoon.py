"""Benchmark of the cartoon warp on real captures: folds, head motion, speed, expressions kept.

    python -m problems.bench_cartoon CAPTURE_DIR [CAPTURE_DIR ...] [--out reports/reproduction]
        [--check-every 5] [--no-check] [--readers dlib,mediapipe] [--mp-every 1] [--noise-draws 12]
        [--png FRAME ...] [--images a,b] [--modes paper,still,follow] [--warp-every K]

For every capture folder (``facebasis capture`` output) and every target image (the built-in
cartoon, the same with its lips closed, the same cartoon stretched 1.3x wide, scikit-image's astronaut photograph and a painted
(``cv2.stylization``) version of it, with dlib's landmarks; ``--second-landmarks``: MediaPipe's where dlib's are
off the mouth, :func:`photo_landmarks`), three ways of driving the cartoon:

* ``paper``: eq. 12 as it is (the head's motion included, no fold handling), the earlier default;
* ``uniform``: head similarity removed, contacts closed, fold-free warp, one eq. 13 scale for the
  whole face (the default before the per-feature amplitude);
* ``still``: the default: as ``uniform`` with each eye, brow and the mouth moved in the target's own
  proportions (:mod:`facebasis.retarget.featurescale`);
* ``follow``: as ``still`` with the whole image moved with the head (``--head follow``).

Reported per (clip, image, mode): frames with at least one folded triangle (orientation flipped
against the rest cartoon) among the capture mesh's triangles (those of ``cartoon_mesh.npz``) and
among all triangles of the warp (band included), the largest count in a frame, frames where the
iteration ran / where the blend fallback was needed, the cartoon's face width (distance of jaw
landmarks 0 and 16) over the clip, ms per frame (planning + warp, single thread), and the
expression check. Each detector of ``--readers`` (:mod:`problems.cartoon_check`: dlib on every
``--check-every``-th frame, MediaPipe in static-image mode on every ``--mp-every``-th, both on every
frame of the capture's blinks as well) is run on the output frames and on the source frames, and the
Pearson correlation over time of mouth opening, mouth width, brow height and eye opening (each
divided by the eye-corner distance of the same detection) is given as ``r_<feature>`` (dlib on the
output against dlib on the source: the check; ``r_mp_<feature>`` the same with MediaPipe), beside
``r_cap_[mp_]<feature>`` (the capture's own landmarks against the detector on the source: what any
warp of this capture can reach), ``r_warp_<feature>`` (the warped cartoon's landmarks against the
capture's landmarks on every frame: does the warp carry the motion, before any detector),
``r_read_[mp_]<feature>`` (the detector on the output against the warped landmarks: does it read back
what the warp drew) and ``r_src_<feature>`` (dlib against MediaPipe on the source frames both read:
how far two detectors agree on the real face), each with its median over the four measures. Per
detector and feature, why the read-back falls short: ``gain_`` (slope of its reading against the
warped measure over the clip), ``noise_`` (its still noise: standard deviation of the measure over
``--noise-draws`` sub-pixel shifts of the unwarped image), ``floor_`` (the read-back that noise alone
allows at that gain, :func:`problems.cartoon_check.noise_ceiling`) and ``r_all_`` (the reading's
correlation with its fit on all four warped measures: above ``r_read_``, other motion is read into it).

Frames of the real clips are written only to git-ignored files (``--png``:
``OUT/cartoon_frames_*.png``, source | paper | still side by side).
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from facebasis.capture.trackfile import read_capture
from facebasis.defaults.cartoon import default_cartoon
from facebasis.retarget.warp2d import CartoonAnimator

MODES = ("paper", "uniform", "still", "follow")


def _painted(image):
    """A painted version of an RGB photograph (OpenCV's edge-preserving stylisation)."""
    import cv2

    return cv2.stylization(image[..., ::-1].copy(), sigma_s=60, sigma_r=0.45)[..., ::-1].copy()


def _cameraman():
    """scikit-image's cameraman enlarged 1.5x (dlib finds no face at its 512 px), the 512 x 512
    crop around the face: a grey photograph of a small face turned down, (512, 512, 3)."""
    import cv2
    from skimage import data

    cam = np.ascontiguousarray(np.repeat(data.camera()[..., None], 3, axis=2))
    big = cv2.resize(cam, (768, 768), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(big[:512, 100:612])


def closed_mouth_cartoon(image, landmarks):
    """The built-in cartoon with its lips closed by the warp itself (the lower lip moved up onto the
    upper inner lip, teeth hidden): a drawn face whose mouth is shut at rest, the case of most
    paintings and portraits. Returns (image (H, W, 3) uint8, landmarks (68, 2))."""
    from scipy.spatial import Delaunay

    lm = np.asarray(landmarks, np.float64)
    closed = lm.copy()
    gap = lm[[67, 66, 65], 1] - lm[[61, 62, 63], 1]
    closed[[67, 66, 65], 1] -= gap
    closed[55:60, 1] -= gap.mean()
    anim = CartoonAnimator(image, lm, lm, lm, Delaunay(lm).simplices, fold_free=False)
    return anim.frame(closed), closed


#: where a second detector's mouth centre is farther than this (eye distances) from the first's, the first's
#: landmarks are taken as off the face: 0.39 on the turned cameraman (dlib put his mouth on his nose), 0.03-0.04
#: on the astronaut photograph and painting
DISAGREE_IOD = 0.2


def photo_landmarks(image, detector, second=None):
    """The 68 landmarks of a photograph: ``detector``'s (the captures' detector: one 68-point convention
    for capture and target), unless ``second`` (:func:`default_landmarker`) finds the mouth (iBUG 48-67)
    more than :data:`DISAGREE_IOD` eye distances away, then ``second``'s. MediaPipe's points on every
    photograph were measured worse: on the astronaut with a dlib capture of cap13 the fold-free solve
    iterated 50 times per frame (3 -> 98 ms per frame, 35 % of frames blended), the two detectors'
    68-point conventions differing at the mouth corners and the jaw. None if neither finds a face.
    Not the benches' default (``--second-landmarks``): with it the turned cameraman's known opening ramp read
    back at 0.96 by MediaPipe, but the warp of the clips' captures onto it fell back on most frames (cap12
    tracking only: 1248 of 1337) and the clip check fell (dlib 0.32-0.42 -> 0.16-0.30)."""
    lm = detector.detect(image)
    other = second.detect(image) if second is not None else None
    if lm is None or other is None:
        return lm if lm is not None else other
    iod = float(np.linalg.norm(lm[45] - lm[36]))
    gap = float(np.linalg.norm(lm[48:68].mean(0) - other[48:68].mean(0))) / max(iod, 1e-9)
    return other if gap > DISAGREE_IOD else lm


def target_images(detector, second=None):
    """[(name, image (H, W, 3) uint8 RGB, landmarks (68, 2))]: several faces, drawn, photographed and
    painted: the built-in cartoon, the same with its lips closed, the same stretched 1.3x wide, scikit-image's astronaut and
    cameraman photographs and painted versions of both, the photographs' landmarks by :func:`photo_landmarks`
    (``detector``'s, ``second``'s where they disagree on the mouth: dlib put the turned cameraman's
    mouth on his nose, and a cartoon driven from those landmarks opens a mouth beside the nose, whatever
    the warp)."""
    import cv2

    face = default_cartoon()
    out = [("cartoon", face.image, face.landmarks), ("cartoon-closed",) + closed_mouth_cartoon(face.image, face.landmarks)]
    wide = cv2.resize(face.image, (int(round(1.3 * 512)), 512), interpolation=cv2.INTER_AREA)
    out.append(("cartoon-wide", wide, face.landmarks * [wide.shape[1] / 512.0, 1.0]))
    try:
        from skimage import data

        photos = [("astronaut", np.ascontiguousarray(data.astronaut())), ("cameraman", _cameraman())]
    except ImportError:
        return out
    for name, photo in photos:
        lm = photo_landmarks(photo, detector, second)
        if lm is None:
            continue
        out.append((name, photo, lm))
        painted = _painted(photo)
        lm_p = photo_landmarks(painted, detector, second)
        out.append((f"{name}-painted", painted, lm if lm_p is None else lm_p))
    return out


def default_landmarker():
    """The detector ``facebasis landmarks`` uses by default (:func:`facebasis.capture.detect.available_detector`:
    MediaPipe when installed, else dlib), reading single pictures: the second opinion of :func:`photo_landmarks`."""
    from facebasis.capture.detect import available_detector

    from problems.cartoon_check import make_reader

    return make_reader(available_detector())


def features(lm):
    """(k,) expression measures of 68 landmarks, in eye-corner distances: mouth opening, mouth
    width, brow height, eye opening."""
    iod = np.linalg.norm(lm[45] - lm[36])
    mouth_open = np.linalg.norm(lm[[61, 62, 63]] - lm[[67, 66, 65]], axis=1).mean()
    mouth_w = np.linalg.norm(lm[54] - lm[48])
    brow = (np.linalg.norm(lm[17:22].mean(0) - lm[36:42].mean(0))
            + np.linalg.norm(lm[22:27].mean(0) - lm[42:48].mean(0))) / 2
    eye = (np.linalg.norm(lm[[37, 38]] - lm[[41, 40]], axis=1).mean()
           + np.linalg.norm(lm[[43, 44]] - lm[[47, 46]], axis=1).mean()) / 2
    return np.array([mouth_open, mouth_w, brow, eye]) / iod


FEATURES = ("mouth_open", "mouth_width", "brow_height", "eye_open")


def correlation(a, b) -> float:
    """Pearson correlation of two series (n,) over the entries finite in both (NaN if fewer than 4,
    or if either is constant there)."""
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 4 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def folds_per_frame(rest, meshes, faces):
    """(T,) triangles of ``faces`` whose signed area has the other sign than (or collapsed from) the rest."""
    def area(V):
        a, b, c = V[..., faces[:, 0], :], V[..., faces[:, 1], :], V[..., faces[:, 2], :]
        return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])

    a0 = area(rest)
    ok = np.abs(a0) > 1e-9 * float(np.ptp(rest, axis=0).max()) ** 2
    a = area(meshes)
    return np.count_nonzero((a * np.sign(a0) <= 0) & ok, axis=-1)


def run_one(cap, name, img, lm_img, mode, readers, src_feats, png_frames, warp_every=1, noise=None):
    """One row of the table for (capture, image, mode) and the frames asked for by ``png_frames``.

    ``readers``: {detector name: (detector, (k,) frames it reads)} (:mod:`problems.cartoon_check`), empty for
    no check; ``src_feats``: {detector name: (T, F) its measures on the source video, NaN where not read};
    ``noise``: {detector name: (F,) its still noise on this image} (:func:`problems.cartoon_check.still_noise`)."""
    from problems.cartoon_check import READERS, gain, multiple_correlation, noise_ceiling

    anim = CartoonAnimator(img, lm_img, cap.landmarks[0], cap.vertices[0], cap.faces,
                           head="follow" if mode == "follow" else "still", fold_free=mode != "paper",
                           amplitude="uniform" if mode in ("paper", "uniform") else "feature")
    t0 = time.perf_counter()
    if mode == "paper":
        meshes = anim.mesh(cap.vertices)
        drive = None
    else:
        drive = anim.drive(cap.vertices, cap.landmarks)
        meshes = drive.meshes
    plan = time.perf_counter() - t0
    T = cap.n_frames
    ring = np.broadcast_to(anim.ring, (T,) + anim.ring.shape)
    folds_mesh = folds_per_frame(anim.rest, meshes, anim.faces)
    still = meshes if drive is None else drive.still
    folds_all = folds_per_frame(anim.warp_rest, np.concatenate([still, ring], 1), anim.warp_faces)
    width = np.linalg.norm(meshes[:, 16] - meshes[:, 0], axis=1)
    warp, n_warp = 0.0, 0
    frames = {}
    read = {r: np.full((T, len(FEATURES)), np.nan) for r in readers}
    wanted = {r: set(np.asarray(f).tolist()) for r, (_, f) in readers.items()}
    for t in range(T):
        who = [r for r in readers if t in wanted[r]]
        if t % warp_every and t not in png_frames and not who:
            continue
        n_warp += 1
        t1 = time.perf_counter()
        fr = anim.warp(meshes[t]) if drive is None else anim.frame_at(drive, t)
        warp += time.perf_counter() - t1
        if t in png_frames:
            frames[t] = fr
        for r in who:
            d = readers[r][0].detect(fr)
            if d is not None:
                read[r][t] = features(d)
    row = {"image": name, "mode": mode, "frames": T,
           "frames_fold_mesh": int(np.count_nonzero(folds_mesh)), "max_fold_mesh": int(folds_mesh.max()),
           "frames_fold_all": int(np.count_nonzero(folds_all)), "max_fold_all": int(folds_all.max()),
           "frames_iterated": int(np.count_nonzero(drive.iterations)) if drive else 0,
           "frames_fallback": int(np.count_nonzero(drive.alpha < 1)) if drive else 0,
           "width_min": float(width.min()), "width_max": float(width.max()),
           "ms_plan": 1e3 * plan / T, "ms_warp": 1e3 * warp / max(n_warp, 1)}
    if not readers or src_feats is None:
        return row, frames
    wf = np.array([features(m[:68]) for m in meshes])
    cf = np.array([features(x) for x in cap.landmarks])
    _correlations(row, "r_warp_", wf, cf)
    if len(src_feats) > 1:                            # the two detectors on the source: how far they agree
        _correlations(row, "r_src_", *[src_feats[r] for r, _ in READERS])
    for r, p in READERS:
        if r not in readers:
            continue
        of, sf = read[r], src_feats[r]
        row[f"checked{'_' + p[:-1] if p else ''}"] = len(wanted[r])
        row[f"detected{'_' + p[:-1] if p else ''}"] = int(np.count_nonzero(np.isfinite(of[:, 0])))
        for prefix, (a, b) in ((f"r_{p}", (of, sf)), (f"r_cap_{p}", (cf, sf)), (f"r_read_{p}", (of, wf))):
            _correlations(row, prefix, a, b)
        sd_noise = noise[r] if noise else np.full(len(FEATURES), np.nan)
        ok = np.isfinite(of[:, 0])
        for k, f in enumerate(FEATURES):
            g = gain(of[:, k], wf[:, k])
            row[f"gain_{p}{f}"] = g
            row[f"noise_{p}{f}"] = float(sd_noise[k])
            row[f"floor_{p}{f}"] = noise_ceiling(g, float(np.std(wf[ok, k])) if ok.any() else np.nan, sd_noise[k])
            row[f"r_all_{p}{f}"] = multiple_correlation(of[:, k], wf)
    return row, frames


def _correlations(row, prefix, a, b):
    """row[prefix + feature] = correlation of the columns of a and b (T, F), and their median."""
    for k, fname in enumerate(FEATURES):
        row[f"{prefix}{fname}"] = correlation(a[:, k], b[:, k])
    vals = np.array([row[f"{prefix}{f}"] for f in FEATURES])
    row[f"{prefix}median"] = float(np.median(vals[np.isfinite(vals)])) if np.isfinite(vals).any() else float("nan")


def source_features(cap, readers):
    """{detector: (T, F) measures of the source video's frames it reads (NaN elsewhere)}."""
    from facebasis.retarget.media import read_video_frames

    out = {r: np.full((cap.n_frames, len(FEATURES)), np.nan) for r in readers}
    wanted = {r: set(np.asarray(f).tolist()) for r, (_, f) in readers.items()}
    for t, fr in enumerate(read_video_frames(cap.video)):
        if t >= cap.n_frames:
            break
        for r in readers:
            if t in wanted[r]:
                d = readers[r][0].detect(fr)
                if d is not None:
                    out[r][t] = features(d)
    return out


COLUMNS = ("clip", "image", "mode", "frames", "frames_fold_mesh", "max_fold_mesh", "frames_fold_all", "frames_iterated",
           "frames_fallback", "width_min", "width_max", "ms_plan", "ms_warp", "checked", "detected", "r_median",
           "checked_mp", "detected_mp", "r_mp_median")
#: the expression table's stages, in the order of the pipeline: capture, warp, detector read-back, the check
STAGES = (("cap", "r_cap_"), ("warp", "r_warp_"), ("read", "r_read_"), ("check", "r_"))
#: the noise table's columns: the detector's gain on the clip, its still noise, the read-back that noise
#: allows, the read-back measured
NOISE = (("gain", "gain_"), ("noise", "noise_"), ("floor", "floor_"), ("read", "r_read_"), ("all", "r_all_"))


def _cell(v) -> str:
    try:
        f = float(v)
    except ValueError:
        return v
    if not np.isfinite(f):
        return "-"
    return f"{f:.0f}" if f == int(f) else f"{f:.3g}"


def _feature_table(rows, title, stages, reader, detected, feats) -> list[str]:
    """Markdown lines of one per-feature table: ``stage / stage / ...`` per feature, ``reader`` the
    detector's column prefix inserted after each stage's own ("" for dlib, "mp_")."""
    head = ["clip", "image", "mode", "detected"] + [f"{n} ({' / '.join(s for s, _ in stages)})" for n in feats]
    lines = ["", title, "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["clip"], r["image"], r["mode"], _cell(r.get(detected, ""))]
        cells += [" / ".join(_cell(r.get(f"{p}{n}" if p == "r_warp_" else f"{p}{reader}{n}", "")) for _, p in stages)
                  for n in feats]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def markdown(csv_path) -> str:
    """The CSV written by :func:`main` as markdown: the folds/speed table, and (with the expression
    check) per detector a table of the four correlations per feature, ``cap / warp / read / check``,
    and a table of the detector's gain, still noise, the read-back that noise allows and the one measured."""
    with open(csv_path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    cols = [c for c in COLUMNS if rows and c in rows[0]]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_cell(r.get(c, "")) for c in cols) + " |" for r in rows]
    for reader, label, det in (("", "dlib", "detected"), ("mp_", "MediaPipe", "detected_mp")):
        if not rows or f"r_cap_{reader}median" not in rows[0]:
            continue
        lines += _feature_table(rows, f"Expression check, {label} reading (cap / warp / read / check):", STAGES,
                                reader, det, FEATURES + ("median",))
        lines += _feature_table(rows, f"{label}: gain on the clip / still noise (sd) / read-back that noise "
                                      "allows / read-back measured / read-back on all four warped measures:", NOISE, reader, det, FEATURES)
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("captures", nargs="+")
    ap.add_argument("--out", default="reports/reproduction")
    ap.add_argument("--check-every", type=int, default=5)
    ap.add_argument("--no-check", action="store_true", help="skip the expression check")
    ap.add_argument("--readers", default="dlib", help="detectors of the check: dlib,mediapipe")
    ap.add_argument("--mp-every", type=int, default=1, help="MediaPipe reads every k-th frame (+ the blinks)")
    ap.add_argument("--noise-draws", type=int, default=12, help="jittered copies of each image for the still noise")
    ap.add_argument("--png", type=int, nargs="*", default=[], help="frames to save side by side (git-ignored)")
    ap.add_argument("--images", default=None, help="comma-separated subset of the target images")
    ap.add_argument("--second-landmarks", action="store_true",
                    help="photographs take the default landmarker's points where dlib's are off the mouth "
                         "(photo_landmarks; measured and not the default: on the turned cameraman the warp of "
                         "a dlib capture then fell back on most frames)")
    ap.add_argument("--modes", default=",".join(MODES))
    ap.add_argument("--warp-every", type=int, default=1, help="time the warp on every k-th frame only")
    args = ap.parse_args(argv)
    from facebasis.capture.detect import DlibDetector

    from problems.cartoon_check import checked_frames, make_reader, still_noise

    det = DlibDetector()
    images = target_images(det, default_landmarker() if args.second_landmarks else None)
    names = [] if args.no_check else args.readers.split(",")
    detectors = {r: (det if r == "dlib" else make_reader(r)) for r in names}
    noise = {im[0]: {r: still_noise(im[1], d, features, args.noise_draws) for r, d in detectors.items()}
             for im in images} if names else {}
    if args.images:
        keep = args.images.split(",")
        images = [im for im in images if im[0] in keep]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for cdir in args.captures:
        cap = read_capture(cdir)
        clip = Path(cdir).name
        readers = {r: (d, checked_frames(cap.n_frames, args.mp_every if r == "mediapipe" else args.check_every,
                                         cap.landmarks))
                   for r, d in detectors.items()}
        src = None if not readers or cap.video is None else source_features(cap, readers)
        src_frames = {}
        if args.png and cap.video is not None:
            from facebasis.retarget.media import read_video_frames

            for t, fr in enumerate(read_video_frames(cap.video)):
                if t in args.png:
                    src_frames[t] = fr
                if t > max(args.png):
                    break
        for name, img, lm in images:
            shown = {}
            for mode in args.modes.split(","):
                row, frames = run_one(cap, name, img, lm, mode, readers, src, set(args.png), args.warp_every,
                                      noise.get(name))
                row = {"clip": clip, **row}
                rows.append(row)
                shown[mode] = frames
                print(" ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
                      flush=True)
            if args.png:
                import cv2

                for t in args.png:
                    if t >= cap.n_frames:
                        continue
                    parts = [shown[m][t] for m in shown]
                    h = parts[0].shape[0]
                    if t in src_frames:
                        s = src_frames[t]
                        parts.insert(0, cv2.resize(s, (int(s.shape[1] * h / s.shape[0]), h)))
                    strip = np.concatenate([p[:h] for p in parts], axis=1)
                    cv2.imwrite(str(out / f"cartoon_frames_{clip}_{name}_{t}.png"), strip[..., ::-1])
    from facebasis.atomic import atomic_write_bytes
    from facebasis.report.tables import write_dict_csv

    keys = list(dict.fromkeys(k for r in rows for k in r))
    write_dict_csv(out / "bench_cartoon.csv", [{k: r.get(k, "") for k in keys} for r in rows])
    atomic_write_bytes(out / "bench_cartoon.md", markdown(out / "bench_cartoon.csv").encode())
    print(f"wrote {out / 'bench_cartoon.csv'} and bench_cartoon.md")


if __name__ == "__main__":
    main()
