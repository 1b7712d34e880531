"""Plausibility of rig weights on real faces (issue 23): weights near zero at rest, left and right close.

    python -m problems.rig_plausibility CAPTURE_DIR [CAPTURE_DIR ...] [--variants default,...] [--out CSV]
    python -m problems.rig_plausibility --synthetic [--frames 600]

Each capture folder (``facebasis capture CLIP --detector dlib --out CAPTURE_DIR``) is retargeted onto
ICT-FaceKit's 53 expressions (``../shared/data/ict``, never copied) with its 68 landmark vertices,
with the options of every variant (:data:`VARIANTS`; ``default`` is ``facebasis retarget --rig ICT
--landmarks landmarks68.json`` with no other option, ``before`` the defaults before issue 23, and
each ``no_*`` the default with one of the issue's fixes taken out), and measured by what must hold on any real clip:

* ``calm_max_median``: on *calm* frames (:func:`calm_frames`: after a similarity alignment onto
  frame 0, the landmarks within 1.5% of frame 0's face width (rms) of its frame-0 position) the median
  over frames of the largest weight (target <= 0.15), and which shape it is most often;
* ``lr_diff_median``: median over all frames of the largest ``|x_L - x_R|`` over the rig's ``_L`` /
  ``_R`` pairs (target <= 0.2);
* ``cheekPuff_L`` mean and ``jawRight`` max (the owner's cap12 figures were 0.39 and 1.0).

``--synthetic``: a third face with a known answer: ICT random identities (not the rig's face) whose
expressions are the rig's own, mostly at rest with short symmetric expressions, moving head (yaw up
to 15 degrees), 1 px landmark noise plus extra noise along the jaw contour (2 px); the same
measures, and the weight error against the truth.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

from facebasis.retarget.reststart import align_similarity

ROOT = Path(__file__).resolve().parents[1]

#: variant name -> RigRetargeter keyword arguments (``default`` = the command's defaults)
VARIANTS = {
    "before": {"identity": "quantile", "contour_slide": 1.0, "sparsity": 0.0, "noise_model": "rig",
               "point_noise": "shared", "gaze": "free", "rest_depth": "none"},  # before issue 23
    "free_gaze": {"gaze": "free"},                            # each eye's look shapes on their own
    "flat_rest": {"rest_depth": "none"},                      # the rest face in-plane, without depth
    "default": {},
    "no_anchor": {"rest_anchor": False},                      # rest face: the commonest posture, never frame 0's
    "no_rest_face": {"identity": "quantile"},                 # identity: the quantile baseline only
    "no_contour": {"contour_slide": 1.0},                     # noise model: jaw line as fixed points
    "no_sparsity": {"sparsity": 0.0},                         # prior: Gaussian ridge only
    "identity_rig": {"identity": "rig"},
    "identity_first_frame": {"identity": "first-frame"},
}
CALM_TOL = 0.015


def face_width(p) -> float:
    """Jaw-contour width |p0 - p16| of one frame's 68 landmarks."""
    return float(np.linalg.norm(np.asarray(p)[0] - np.asarray(p)[16]))


def calm_frames(landmarks, tol: float = CALM_TOL) -> np.ndarray:
    """(T,) bool: frames whose landmarks, similarity-aligned onto frame 0, lie within ``tol`` times
    frame 0's face width of their frame-0 positions (rms over the landmarks) (the face at rest, as in frame 0)."""
    P = np.asarray(landmarks, np.float64)
    A = align_similarity(P, P[0])
    d = np.sqrt(np.mean(np.sum((A - P[0][None]) ** 2, axis=2), axis=1))
    return d <= tol * face_width(P[0])


def lr_pairs(names) -> list[tuple[int, int]]:
    """Index pairs (i_L, i_R) of shapes named ``X_L`` / ``X_R``."""
    names = list(names)
    return [(i, names.index(n[:-2] + "_R")) for i, n in enumerate(names)
            if n.endswith("_L") and n[:-2] + "_R" in names]


def plausibility(names, W, landmarks) -> dict:
    """The measures of the module docstring for weights W (T, k) of a capture's landmarks (T, 68, 2)."""
    names = list(names)
    W = np.asarray(W, np.float64)
    calm = calm_frames(landmarks)
    pairs = np.array(lr_pairs(names))
    lr = np.abs(W[:, pairs[:, 0]] - W[:, pairs[:, 1]]).max(1) if len(pairs) else np.zeros(len(W))
    out = {"frames": len(W), "calm_frames": int(calm.sum()),
           "calm_max_median": float(np.median(W[calm].max(1))) if calm.any() else float("nan"),
           "calm_argmax": "", "lr_diff_median": float(np.median(lr)),
           "lr_diff_calm_median": float(np.median(lr[calm])) if calm.any() else float("nan")}
    if calm.any():
        top = np.bincount(W[calm].argmax(1), minlength=len(names))
        out["calm_argmax"] = names[int(top.argmax())]
    for n, f in (("cheekPuff_L", "mean"), ("cheekSquint_L", "mean"), ("jawRight", "max"), ("jawOpen", "max")):
        if n in names:
            out[f"{n}_{f}"] = float(getattr(np, f)(W[:, names.index(n)]))
    out["mean_weight"] = float(W.mean())
    if "jawOpen" in names and np.asarray(landmarks).shape[1] == 68:
        # the rig still follows the face: jawOpen against the lip opening the landmarks show
        # (inner lips 62-66 over the jaw width), Pearson correlation over all frames
        P = np.asarray(landmarks, np.float64)
        opening = np.linalg.norm(P[:, 62] - P[:, 66], axis=1) / np.linalg.norm(P[:, 0] - P[:, 16], axis=1)
        jaw = W[:, names.index("jawOpen")]
        out["jawOpen_opening_corr"] = float(np.corrcoef(jaw, opening)[0, 1]) if jaw.std() > 0 else 0.0
    return out


def ict_problem():
    from problems.ict import _load, ict_rig

    return ict_rig(), _load()["landmarks68"].astype(np.int64)


def cut_rest(W, landmarks, first: int) -> dict:
    """A cut's weights W (T - first, k) on the frames that are calm against the whole clip's frame 0
    (landmarks (T, 68, 2)): a reference rest that does not depend on the cut's own frame 0 (which may
    be mid-sentence). Median over them of the largest weight, and their count; {} for the whole clip."""
    if not first:
        return {}
    calm = calm_frames(landmarks)[first:]
    return {"clip_calm_frames": int(calm.sum()),
            "clip_calm_max_median": float(np.median(np.asarray(W)[calm].max(1))) if calm.any() else float("nan")}


def run_capture(capture_dir, variants, start: float = 0.0, log=print) -> list[dict]:
    """Rows of every variant on a capture folder; ``start`` > 0 (seconds) cuts the capture there, a take
    whose frame 0 is a later moment of the clip (e.g. mid-sentence)."""
    from facebasis.capture.trackfile import read_capture
    from facebasis.retarget.rigdrive import RigRetargeter

    rig, idx = ict_problem()
    cap = read_capture(capture_dir)
    first = int(round(start * cap.fps))
    P, lost = cap.landmarks[first:], cap.lost[first:]
    label = Path(capture_dir).name + (f"@{start:g}s" if first else "")
    rows = []
    for name in variants:
        t0 = time.process_time()
        res = RigRetargeter(rig, idx, **VARIANTS[name]).run(P, lost, cap.fps)
        row = {"capture": label, "variant": name, **plausibility(rig.names, res.weights, P),
               "residual_px_mean": float(np.nanmean(res.residual)), "ridge": res.ridge,
               "rest_anchored": bool(res.calibration is not None and res.calibration.rest_anchored),
               **cut_rest(res.weights, cap.landmarks, first),
               "cpu_ms_per_frame": 1e3 * (time.process_time() - t0) / len(P)}
        rows.append(row)
        log(format_row(row))
    return rows


def format_row(r) -> str:
    return (f"{r['capture']:>14s} {r['variant']:>22s}: calm {r['calm_frames']:4d}/{r['frames']} max-weight median "
            f"{r['calm_max_median']:.3f} ({r['calm_argmax']}); L/R diff median {r['lr_diff_median']:.3f}; "
            f"cheekPuff_L mean {r.get('cheekPuff_L_mean', np.nan):.3f}; jawRight max {r.get('jawRight_max', np.nan):.3f}; "
            f"jawOpen~opening r {r.get('jawOpen_opening_corr', np.nan):.2f}; "
            f"residual {r['residual_px_mean']:.2f} px; ridge {r['ridge']:.3g}"
            + (f"; weight MAE {r['weight_mae']:.4f}" if "weight_mae" in r else "")
            + (f"; on the clip's calm frames ({r['clip_calm_frames']}) max-weight median {r['clip_calm_max_median']:.3f}"
               if "clip_calm_frames" in r else "")
            + f"; {r['cpu_ms_per_frame']:.1f} ms/frame CPU")


def synthetic_face(seed: int, frames: int = 600, noise_px: float = 1.0, jaw_noise_px: float = 2.0,
                   yaw_deg: float = 15.0):
    """A capture of another face with a known answer (see the module docstring): (rig, indices,
    truth weights (T, k), landmarks (T, 68, 2), fps)."""
    from facebasis.retarget.pose import project_landmarks, rotation_from_vector
    from problems.ict import ict_random_identity

    rig, idx = ict_problem()
    _, neutral = ict_random_identity(seed)
    rng = np.random.default_rng(seed)
    fps = 30.0
    t = np.arange(frames) / fps
    X = np.zeros((frames, rig.n_shapes))
    # short symmetric expressions on a face mostly at rest (about 30% of the frames)
    for a, b, level in (("mouthSmile_L", "mouthSmile_R", 0.7), ("browInnerUp_L", "browInnerUp_R", 0.6),
                        ("eyeBlink_L", "eyeBlink_R", 1.0)):
        period = rng.uniform(4.0, 7.0)
        bump = np.clip(2.0 * np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi)) - 1.0, 0, 1) ** 2
        X[:, rig.names.index(a)] = X[:, rig.names.index(b)] = level * bump
    X[:, rig.names.index("jawOpen")] = 0.5 * np.clip(2.0 * np.sin(2 * np.pi * t / 3.1 + 1.0) - 1.0, 0, 1) ** 2
    ph = rng.uniform(0, 2 * np.pi, 3)
    y = np.deg2rad(yaw_deg)
    rv = np.stack([0.4 * y * np.sin(2 * np.pi * 0.13 * t + ph[0]), y * np.sin(2 * np.pi * 0.07 * t + ph[1]),
                   0.3 * y * np.sin(2 * np.pi * 0.11 * t + ph[2])], 1)
    R = np.stack([rotation_from_vector(v) for v in rv])
    s = 9.0 * (1.0 + 0.1 * np.sin(2 * np.pi * 0.05 * t))       # ~ a 400x300 webcam face (px per cm)
    tr = np.array([200.0, 150.0]) + np.stack([10 * np.sin(2 * np.pi * 0.09 * t), 6 * np.sin(2 * np.pi * 0.06 * t)], 1)
    Q = neutral[idx] + np.tensordot(X, rig.deltas[:, idx], axes=(1, 0))
    P = project_landmarks(Q, s, R, tr)
    P = P + noise_px * rng.standard_normal(P.shape)
    # jaw contour (0-16): extra noise along the contour (tangent from the neighbours)
    jaw = P[:, :17]
    tan = np.gradient(jaw, axis=1)
    tan /= np.linalg.norm(tan, axis=2, keepdims=True) + 1e-12
    P[:, :17] += jaw_noise_px * rng.standard_normal((frames, 17, 1)) * tan
    return rig, idx, X, P, fps


def run_synthetic(variants, seeds=(1, 2, 3), frames: int = 600, log=print) -> list[dict]:
    from facebasis.retarget.rigdrive import RigRetargeter

    rows = []
    for seed in seeds:
        rig, idx, X, P, fps = synthetic_face(seed, frames)
        for name in variants:
            t0 = time.process_time()
            res = RigRetargeter(rig, idx, **VARIANTS[name]).run(P, None, fps)
            row = {"capture": f"ict_identity{seed}", "variant": name, **plausibility(rig.names, res.weights, P),
                   "weight_mae": float(np.abs(res.weights - X).mean()),
                   "residual_px_mean": float(np.nanmean(res.residual)), "ridge": res.ridge,
                   "cpu_ms_per_frame": 1e3 * (time.process_time() - t0) / frames}
            rest = X.max(1) == 0
            row["rest_max_median_truth"] = float(np.median(res.weights[rest].max(1)))
            rows.append(row)
            log(format_row(row) + f"; at true rest max-weight median {row['rest_max_median_truth']:.3f}")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("captures", nargs="*", help="capture folders")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--synthetic", action="store_true")
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--out", default=None, help="CSV of the rows")
    ap.add_argument("--starts", default="0", help="comma-separated start times (s) of cuts of every capture")
    args = ap.parse_args(argv)
    variants = [v for v in args.variants.split(",") if v]
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        ap.error(f"--variants: unknown {unknown}, expected some of {list(VARIANTS)}")
    rows = []
    starts = [float(v) for v in args.starts.split(",") if v]
    for c in args.captures:
        for start in starts:
            rows += run_capture(c, variants, start)
    if args.synthetic:
        rows += run_synthetic(variants, frames=args.frames)
    if args.out and rows:
        keys = sorted({k for r in rows for k in r}, key=lambda k: (k not in rows[0], k))
        with open(args.out, "w", newline="") as fh:
            w = csv.DictWriter(fh, keys)
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
