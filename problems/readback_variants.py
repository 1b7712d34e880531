"""What a detector needs to read a closing eye and a raised brow: drawing variants on the read-back ramps.

    python -m problems.readback_variants [--out reports/reproduction] [--steps 9] [--readers dlib,mediapipe]

For every target image of :mod:`problems.bench_cartoon`, the ``eye_open`` and ``brow_height`` ramps of
:mod:`problems.cartoon_readback` (both eyes closing to the warp's contact gap; both brows rising by 0.06 iod)
are warped (:class:`facebasis.retarget.warp2d.CartoonAnimator`, the defaults) and drawn in several ways,
each read back by each detector; per (image, reader, feature, variant) the table gives the correlation of
the reading with the warped measure (``r_read``), its slope (``gain``), and the reading's change from the
first frame to the last of the ramp for every measure (``d_<measure>``, in iod: what else the detector
reads into the drawing, e.g. MediaPipe lowering its brows as a painted eye closes):

* ``eye_open``: ``warp`` the bare warp (the eye squeezed between the lid landmarks); ``lid`` the lid drawn
  down over the unsquashed eye with a lash line (:func:`facebasis.retarget.eyepaint.paint_eye`, what the
  warp draws);
* ``brow_height``: ``warp`` (with the lids, as drawn); ``stroke`` a brow stroke along the warped brow
  (iBUG 17-21, 22-26) in the darkest fifth of the target's own brow colours, :data:`STROKE_WIDTH` iod wide,
  its opacity ``clip(rise / STROKE_FULL, 0, 1)``: what a detector reads when the brow is drawn as a dark
  line (not what the warp draws: a brow that darkens as it rises shows on a photograph as a painted stroke).
"""

from __future__ import annotations

import argparse

import numpy as np

from problems.bench_cartoon import FEATURES, correlation, features, target_images

#: the brow stroke's width and the rise (iod) from which it is opaque
STROKE_WIDTH, STROKE_FULL = 0.06, 0.03
BROWS = (np.arange(17, 22), np.arange(22, 27))


def brow_colour(image, landmarks, idx, iod) -> np.ndarray:
    """The mean of the darkest fifth (by luma) of the pixels under the brow's polyline, (C,) float32."""
    import cv2

    mask = np.zeros(image.shape[:2], np.uint8)
    cv2.polylines(mask, [np.round(landmarks[idx]).astype(np.int32)], False, 1, max(1, int(round(0.1 * iod))))
    pix = image[mask > 0].reshape(-1, image.shape[2] if image.ndim == 3 else 1).astype(np.float32)
    luma = pix[:, :3] @ np.float32([0.299, 0.587, 0.114]) if pix.shape[1] >= 3 else pix[:, 0]
    return pix[luma <= np.percentile(luma, 20)].mean(0)


def paint_brow_stroke(frame, brow, rest_brow, colour, iod) -> None:
    """Blend an anti-aliased stroke along ``brow`` (5, 2) into ``frame`` (H, W, C) uint8 in place, opacity
    ``clip(mean vertical move / (STROKE_FULL iod), 0, 1)`` against ``rest_brow``."""
    import cv2

    a = float(np.clip(np.abs(brow[:, 1] - rest_brow[:, 1]).mean() / (STROKE_FULL * iod), 0.0, 1.0))
    if a * 255.0 < 1.0:
        return
    mask = np.zeros(frame.shape[:2], np.uint8)
    cv2.polylines(mask, [np.round(brow * 16).astype(np.int32)], False, 255, max(1, int(round(STROKE_WIDTH * iod))),
                  cv2.LINE_AA, 4)
    ys, xs = np.nonzero(mask)
    al = (mask[ys, xs].astype(np.float32) * (a / 255.0))[:, None]
    view = frame[..., None] if frame.ndim == 2 else frame  # a grey frame: (n, 1) pixels, not (n,) against (n, 1)
    c = np.asarray(colour, np.float32)[:3]
    c = c @ np.float32([0.299, 0.587, 0.114]) if view.shape[-1] == 1 else c
    view[ys, xs] = np.clip(np.rint(view[ys, xs] * (1 - al) + c * al), 0, 255).astype(np.uint8)


def variant_rows(name, image, landmarks, detector, reader: str, steps: int) -> list[dict]:
    """Rows of the table for one image and one detector."""
    from scipy.spatial import Delaunay

    from facebasis.retarget.warp2d import CartoonAnimator
    from problems.cartoon_readback import ramp

    lm = np.asarray(landmarks, np.float64)
    iod = float(np.linalg.norm(lm[45] - lm[36]))
    rows = []
    for feature, variants in (("eye_open", ("warp", "lid")), ("brow_height", ("warp", "stroke"))):
        k = FEATURES.index(feature)
        P = ramp(lm, feature, steps)
        for variant in variants:
            anim = CartoonAnimator(image, lm, lm, lm, Delaunay(lm).simplices, amplitude="feature")
            if feature == "eye_open" and variant == "warp":
                anim.eye_colours = []                          # the bare warp: no lid drawn
            drive = anim.drive(P, P)
            W = drive.still[:, :68]
            warped = np.array([features(x)[k] for x in W])
            cols = [brow_colour(image, lm, b, iod) for b in BROWS]
            read = np.full((steps, len(FEATURES)), np.nan)
            for t in range(steps):
                frame = anim.frame_at(drive, t)
                if variant == "stroke":
                    for b, c in zip(BROWS, cols):
                        paint_brow_stroke(frame, W[t][b], lm[b], c, iod)
                d = detector.detect(frame)
                if d is not None:
                    read[t] = features(d)
            ok = np.isfinite(read[:, k])
            gain = float(np.polyfit(warped[ok], read[ok, k], 1)[0]) if ok.sum() >= 3 else float("nan")
            row = {"image": name, "reader": reader, "feature": feature, "variant": variant, "detected": int(ok.sum()),
                   "r_read": correlation(read[:, k], warped), "gain": gain}
            row.update({f"d_{f}": float(read[-1, j] - read[0, j]) for j, f in enumerate(FEATURES)})
            rows.append(row)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="reports/reproduction")
    ap.add_argument("--steps", type=int, default=9)
    ap.add_argument("--readers", default="dlib,mediapipe", help="detectors reading the ramps back")
    args = ap.parse_args(argv)
    from facebasis.capture.detect import DlibDetector

    from problems.cartoon_check import make_reader, row_text, write_rows_table

    det = DlibDetector()
    readers = {r: (det if r == "dlib" else make_reader(r)) for r in args.readers.split(",")}
    rows = []
    for name, img, lm in target_images(det):
        for r, reader in readers.items():
            for row in variant_rows(name, img, lm, reader, r, args.steps):
                rows.append(row)
                print(row_text(row), flush=True)
    write_rows_table(args.out, "readback_variants", rows)


if __name__ == "__main__":
    main()
