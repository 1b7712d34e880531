"""Can a detector read back what the cartoon warp draws? Known expression ramps on every target image.

    python -m problems.cartoon_readback [--out reports/reproduction] [--steps 9] [--amplitude feature]

No video: for every target image of :mod:`problems.bench_cartoon` (drawn, photographed, painted),
a synthetic capture made of the image's own 68 landmarks moves one expression measure at a time
along a ramp of ``--steps`` frames, from rest to a strong expression (in eye-corner distances, iod):

* ``mouth_open``: the lower lip (inner and outer) and the chin drop by up to 0.25 iod;
* ``mouth_width``: the mouth corners move out by up to 0.06 iod each (their neighbours half);
* ``brow_height``: both brows rise by up to 0.06 iod (at 0.12 dlib puts the built-in cartoon's brows back down onto
  its eyes, reading a raise as a frown);
* ``eye_open``: both eyes close, the lids meeting at the end (the warp stops them at its smallest
  gap, 15% of the rest).

The cartoon is driven through :meth:`facebasis.retarget.warp2d.CartoonAnimator.drive` (the default:
head still, fold-free, contacts closed), each detector of ``--readers`` (dlib, MediaPipe in
static-image mode, :mod:`problems.cartoon_check`) is run on every output frame, and the table gives,
per (image, detector, measure): frames where it found a face, the Pearson correlation between the
measure on its landmarks and on the warped landmarks (``r_read``), the slope of its reading against
the warped one (``gain``: 1 = read back in full, 0 = not seen), its still noise on the unwarped image
(``still_noise``: the measure's standard deviation over 12 sub-pixel shifts,
:func:`problems.cartoon_check.still_noise`) and ``range_over_noise`` = gain x warped range / still
noise (how many noise widths the strongest expression moves the reading). A measure the detector
cannot read back on an image caps the expression check of every clip on that image, whatever the
warp does.
"""

from __future__ import annotations

import argparse

import numpy as np

from problems.bench_cartoon import FEATURES, correlation, default_landmarker, features, target_images

#: the ramps' ends, in eye-corner distances
MOUTH_DROP, CORNER_OUT, BROW_RISE = 0.25, 0.06, 0.06


def ramp(landmarks, feature: str, steps: int) -> np.ndarray:
    """(steps, 68, 2) landmarks moving ``feature`` from rest (frame 0) to its strongest."""
    lm = np.asarray(landmarks, np.float64)
    iod = float(np.linalg.norm(lm[45] - lm[36]))
    k = np.linspace(0.0, 1.0, steps)[:, None]
    P = np.repeat(lm[None], steps, axis=0)
    if feature == "mouth_open":
        P[:, np.r_[65:68, 55:60, 6:11], 1] += MOUTH_DROP * iod * k
    elif feature == "mouth_width":
        for side, idx, half in ((-1.0, [48, 60], [49, 59, 61, 67]), (1.0, [54, 64], [53, 55, 63, 65])):
            P[:, idx, 0] += side * CORNER_OUT * iod * k
            P[:, half, 0] += 0.5 * side * CORNER_OUT * iod * k
    elif feature == "brow_height":
        P[:, 17:27, 1] -= BROW_RISE * iod * k
    elif feature == "eye_open":
        for up, lo in (([37, 38], [41, 40]), ([43, 44], [47, 46])):
            gap = lm[lo, 1] - lm[up, 1]
            P[:, up, 1] += 0.5 * k * gap
            P[:, lo, 1] -= 0.5 * k * gap
    else:
        raise ValueError(feature)
    return P


def readback(name, image, landmarks, detector, steps: int, amplitude: str, reader: str = "dlib",
             noise=None) -> list[dict]:
    """Rows of the table for one image and one detector (``reader``; ``noise`` (F,) its still noise on the
    image, :func:`problems.cartoon_check.still_noise`)."""
    from scipy.spatial import Delaunay

    from facebasis.retarget.warp2d import CartoonAnimator

    lm = np.asarray(landmarks, np.float64)
    faces = Delaunay(lm).simplices
    rows = []
    for k, feature in enumerate(FEATURES):
        P = ramp(lm, feature, steps)
        anim = CartoonAnimator(image, lm, lm, lm, faces, amplitude=amplitude)
        drive = anim.drive(P, P)
        warped = np.array([features(x)[k] for x in drive.still[:, :68]])
        read = []
        for t in range(steps):
            d = detector.detect(anim.frame_at(drive, t))
            read.append(features(d)[k] if d is not None else np.nan)
        read = np.array(read)
        ok = np.isfinite(read)
        gain = float(np.polyfit(warped[ok], read[ok], 1)[0]) if ok.sum() >= 3 else float("nan")
        sd = float(noise[k]) if noise is not None else float("nan")
        rows.append({"image": name, "reader": reader, "feature": feature, "detected": int(ok.sum()), "frames": steps,
                     "warped_range": float(np.ptp(warped)), "r_read": correlation(read, warped), "gain": gain,
                     "still_noise": sd, "range_over_noise": abs(gain) * float(np.ptp(warped)) / sd if sd > 0 else
                     float("nan")})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="reports/reproduction")
    ap.add_argument("--steps", type=int, default=9)
    ap.add_argument("--amplitude", default="feature")
    ap.add_argument("--readers", default="dlib,mediapipe", help="detectors reading the ramps back")
    ap.add_argument("--noise-draws", type=int, default=12)
    ap.add_argument("--second-landmarks", action="store_true",
                    help="photographs take the default landmarker's points where dlib's are off the mouth")
    args = ap.parse_args(argv)
    from facebasis.capture.detect import DlibDetector

    from problems.cartoon_check import make_reader, row_text, still_noise, write_rows_table

    det = DlibDetector()
    readers = {r: (det if r == "dlib" else make_reader(r)) for r in args.readers.split(",")}
    rows = []
    for name, img, lm in target_images(det, default_landmarker() if args.second_landmarks else None):
        for r, reader in readers.items():
            noise = still_noise(img, reader, features, args.noise_draws)
            for row in readback(name, img, lm, reader, args.steps, args.amplitude, r, noise):
                rows.append(row)
            print(row_text(row), flush=True)
    write_rows_table(args.out, "cartoon_readback", rows)


if __name__ == "__main__":
    main()
