"""Benchmark of scan registration on synthetic scans with known correspondence.

    python -m problems.bench_registration [--expressions 6] [--seeds 0 1] [--out reports/registration] [--quick]

Scans are made from the ICT data (``../shared``, never copied here; scans live in memory only): a
seeded random identity and some of its expressions (ICT expression deltas on top of the identity),
without the mouth and eye sockets (a scanner does not see them: holes at the mouth and eyes),
midpoint-subdivided twice and resampled by vertex clustering to about 100k vertices (another
topology, vertices shuffled), holes of 2.5 cm radius cut around both ears, Gaussian noise of
0.2 mm (0.02 cm) per coordinate and a random rigid motion (any rotation, up to 30 cm translation).

The template is ICT's generic neutral (14062 vertices). The neutral scan is registered first from
the template, each expression scan from the registered neutral. Error: per-vertex distance between
the registered mesh and the true mesh in the scan's frame, on the face region (ICT vertices
0..9408), in cm: median, 95th percentile, max; with and without the 68 landmarks (given as 3D
points on the scan, the true landmark positions plus the same noise). Also timed: seconds per scan.
Optionally (``--rig``) a rig is generated from registered training expressions and from exact ones
and their held-out reproduction errors compared.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from facebasis.geometry.registration import Registration

TARGETS = {"median": 0.05, "p95": 0.2, "seconds": 10.0}
EXPRESSIONS = ("jawOpen", "mouthSmile_L", "eyeBlink_R", "mouthPucker", "browInnerUp_L", "mouthFunnel",
               "cheekPuff_L", "mouthLeft")


def _cluster(V: np.ndarray, F: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering on a grid of ``cell``: one vertex (the mean) per occupied cell."""
    key = np.floor((V - V.min(0)) / cell).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    cnt = np.bincount(inv)
    W = np.stack([np.bincount(inv, V[:, k]) for k in range(3)], 1) / cnt[:, None]
    G = inv[F]
    G = G[(G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])]
    _, first = np.unique(np.sort(G, 1), axis=0, return_index=True)
    G = G[np.sort(first)]
    used = np.unique(G)
    remap = np.full(len(W), -1)
    remap[used] = np.arange(len(used))
    return W[used], remap[G]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def make_scan(V_true: np.ndarray, F: np.ndarray, keep_vertices: np.ndarray, ears: np.ndarray,
              rng: np.random.Generator, target: int = 100_000, noise: float = 0.02, hole_radius: float = 2.5):
    """A synthetic scan of ``V_true``: returns ``(S_V, S_F, R, t)`` with scan = R V_true + t."""
    import trimesh

    Fk = F[keep_vertices[F].all(1)]
    V2, F2 = V_true, Fk
    while len(V2) < 2 * target:
        V2, F2 = trimesh.remesh.subdivide(V2, F2)
    a, b, c = V2[F2[:, 0]], V2[F2[:, 1]], V2[F2[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    cell = np.sqrt(area / target) * 1.06
    S, G = _cluster(V2, F2, cell)
    cen = S[G].mean(1)
    near_ear = (np.linalg.norm(cen[:, None, :] - ears[None], axis=2) < hole_radius).any(1)
    G = G[~near_ear]
    used = np.unique(G)
    remap = np.full(len(S), -1)
    remap[used] = np.arange(len(used))
    S, G = S[used], remap[G]
    S = S + noise * rng.standard_normal(S.shape)
    perm = rng.permutation(len(S))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    S, G = S[perm], inv[G]
    R = random_rotation(rng)
    t = rng.uniform(-30, 30, 3)
    return S @ R.T + t, G, R, t


def stats(e: np.ndarray) -> dict:
    return {"median": float(np.median(e)), "p95": float(np.percentile(e, 95)), "max": float(e.max())}


def run(seeds=(0,), n_expr: int = 6, quick: bool = False, log=print):
    from problems.ict import _load, ict_random_identity, ict_regions

    d = _load()
    F = d["faces"].astype(np.int64)
    T = d["neutral"].astype(np.float64)
    names = [str(s) for s in d["expression_names"]]
    lm68 = d["landmarks68"].astype(np.int64)
    reg = ict_regions()
    face = np.arange(*reg["face"])
    keep = np.zeros(len(T), bool)
    keep[: reg["head_neck"][1]] = True
    head = np.arange(*reg["head_neck"])
    rows = []
    for seed in seeds:
        rng = np.random.default_rng(1000 + seed)
        _, B0 = ict_random_identity(seed)
        ears = np.stack([B0[head[np.argmax(B0[head, 0])]], B0[head[np.argmin(B0[head, 0])]]])
        shapes = [("neutral", B0)]
        for nm in EXPRESSIONS[:n_expr]:
            shapes.append((nm, B0 + d["expression_deltas"][names.index(nm)].astype(np.float64)))
        scans = []
        for nm, Vt in shapes:
            S, G, R, t = make_scan(Vt, F, keep, ears, rng)
            truth = Vt @ R.T + t
            lm_pts = truth[lm68] + 0.02 * rng.standard_normal((len(lm68), 3))
            scans.append((nm, S, G, truth, lm_pts))
        for use_lm in (False, True):
            reg_obj = Registration(T, F, landmarks=lm68 if use_lm else None, name="ICT neutral")
            neutral = neutral_truth = None
            for nm, S, G, truth, lm_pts in scans:
                t0 = time.perf_counter()
                res = reg_obj.register(S, G, scan_landmarks=lm_pts if use_lm else None, start=neutral, name=nm)
                sec = time.perf_counter() - t0
                if nm == "neutral":
                    neutral, neutral_truth, neutral_sim = res.vertices, truth, res.similarity
                e = np.linalg.norm(res.vertices[face] - truth[face], axis=1)
                s = stats(e)
                # the expression's motion from the neutral, both in the template frame (rigid parts removed)
                back = res.similarity.inverse()
                reg_delta = back.apply(res.vertices) - neutral_sim.inverse().apply(neutral)
                from facebasis.geometry.rigid import umeyama
                tb = umeyama(truth[face], res.vertices[face]).then(back)
                nb = umeyama(neutral_truth[face], neutral[face]).then(neutral_sim.inverse())
                true_delta = tb.apply(truth) - nb.apply(neutral_truth)
                de = np.linalg.norm(reg_delta[face] - true_delta[face], axis=1)
                row = {"seed": seed, "scan": nm, "landmarks": "yes" if use_lm else "no",
                       "scan_vertices": len(S), **{f"err_{k}": v for k, v in s.items()},
                       "motion_err_median": float(np.median(de)), "motion_err_p95": float(np.percentile(de, 95)),
                       "residual_median": float(np.median(res.distance[~res.no_surface])),
                       "no_surface": int(res.no_surface.sum()), "iterations": res.iterations,
                       "seconds": sec}
                rows.append(row)
                log(f"seed {seed} {nm:14s} lm={row['landmarks']:3s} N={len(S)} err median {s['median']:.4f} "
                    f"p95 {s['p95']:.4f} max {s['max']:.3f} cm | motion err median {row['motion_err_median']:.4f} "
                    f"p95 {row['motion_err_p95']:.4f} | residual {row['residual_median']:.4f} | "
                    f"no-surface {row['no_surface']} | it {res.iterations} | {sec:.2f} s")
            if quick:
                break
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--expressions", type=int, default=6)
    ap.add_argument("--out", default="reports/registration")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    rows = run(tuple(args.seeds), args.expressions, args.quick)
    write_tables(rows, Path(args.out))
    return rows


def write_tables(rows, out: Path) -> None:
    """``registration.csv`` (every scan) and ``registration.md`` (the table and the targets)."""
    out.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0])
    with open(out / "registration.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in r.items()})
    lines = ["# Scan registration (ICT synthetic scans, face region, cm)", "",
             "Command: `python -m problems.bench_registration " + " ".join(__import__("sys").argv[1:]) + "`", "",
             f"Targets without landmarks: median <= {TARGETS['median']} cm, p95 <= {TARGETS['p95']} cm, "
             f"<= {TARGETS['seconds']} s per scan. Seconds measured on a shared 2-core machine.", "",
             "err = registered vertex vs true vertex (scan frame); motion err = registered expression minus "
             "registered neutral vs the true ones (template frame, each similarity-aligned on the face).", "",
             "| seed | scan | landmarks | scan vertices | err median | err p95 | err max | motion err median | "
             "motion err p95 | no-surface vertices | iterations | seconds |", "|" + "---|" * 12]
    for r in rows:
        lines.append(f"| {r['seed']} | {r['scan']} | {r['landmarks']} | {r['scan_vertices']} | {r['err_median']:.4f} | "
                     f"{r['err_p95']:.4f} | {r['err_max']:.3f} | {r['motion_err_median']:.4f} | "
                     f"{r['motion_err_p95']:.4f} | {r['no_surface']} | {r['iterations']} | {r['seconds']:.1f} |")
    for lm in ("no", "yes"):
        sel = [r for r in rows if r["landmarks"] == lm]
        if sel:
            lines.append(f"| all | all | {lm} | | {np.median([r['err_median'] for r in sel]):.4f} | "
                         f"{np.median([r['err_p95'] for r in sel]):.4f} | {max(r['err_max'] for r in sel):.3f} | "
                         f"{np.median([r['motion_err_median'] for r in sel]):.4f} | "
                         f"{np.median([r['motion_err_p95'] for r in sel]):.4f} | | | "
                         f"{np.median([r['seconds'] for r in sel]):.1f} |")
    (out / "registration.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
