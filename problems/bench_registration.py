"""Benchmark of scan registration on synthetic scans with known correspondence.

    python -m problems.bench_registration [--expressions 6] [--seeds 0 1] [--templates generic identity]
        [--no-landmarks] [--rig M] [--out reports/registration] [--quick]

Scans are made from the ICT data (``../shared``, never copied here; scans live in memory only): a
seeded random identity and some of its expressions (ICT expression deltas on top of the identity),
without the mouth and eye sockets (a scanner does not see them: holes at the mouth and eyes),
midpoint-subdivided twice and resampled by vertex clustering to about 100k vertices (another
topology, vertices shuffled), holes of 2.5 cm radius cut around both ears, Gaussian noise of
0.2 mm (0.02 cm) per coordinate and a random rigid motion (any rotation, up to 30 cm translation).

Templates: ``generic``, ICT's generic neutral (14062 vertices; the issue's setting, another person's
face) and ``identity``, the person's own exact neutral (no correspondence ambiguity, so its error is
the pipeline's own: remeshing, noise, holes, pose). With the generic template, the person's exact
neutral mesh itself (no remesh, noise, holes or motion) is also registered: the floor set by the
ambiguity of correspondence between two faces. The neutral scan is registered first from the
template, each expression scan from the registered neutral. Error: per-vertex distance between
the registered mesh and the true mesh in the scan's frame, on the face region (ICT vertices
0..9408), in cm: median, 95th percentile, max, and its parts along the true normal and along the
surface; for expressions also the error against the registered neutral plus the true expression
delta; with and without the 68 landmarks (given as 3D points on the scan, the true landmark
positions plus the same noise). For expressions also how much of the motion a closest-point term can
see (:func:`motion_visibility`). Timed per scan: wall and CPU seconds, load average.
With ``--rig M`` a rig is generated from M registered training scans and from the exact examples
and their held-out reproduction errors compared (:func:`rig_comparison`). This benchmark runs
without identity or expression bases; with them (issue #27) see
:mod:`problems.bench_registration_rig`.
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


def error_parts(X: np.ndarray, truth: np.ndarray, normals: np.ndarray) -> dict:
    """Per-vertex error (q, 3) split along the true surface normal (off the surface) and across it
    (along the surface, a correspondence error a scan cannot show): medians and 95th percentiles."""
    e = X - truth
    en = np.abs((e * normals).sum(1))
    et = np.linalg.norm(e - (e * normals).sum(1, keepdims=True) * normals, axis=1)
    return {"normal_median": float(np.median(en)), "normal_p95": float(np.percentile(en, 95)),
            "tangential_median": float(np.median(et)), "tangential_p95": float(np.percentile(et, 95))}


def _measure(res, truth, face, normals, relative_to=None) -> dict:
    """The issue's metric (registered vs true vertex, scan frame) and its normal/tangential parts;
    with ``relative_to`` (the registered neutral plus the true expression delta, in this scan's frame)
    also the error against it: how consistently a vertex means the same point across the set."""
    e = np.linalg.norm(res.vertices[face] - truth[face], axis=1)
    row = {**{f"err_{k}": v for k, v in stats(e).items()},
           **error_parts(res.vertices[face], truth[face], normals[face])}
    if relative_to is not None:
        r = np.linalg.norm(res.vertices[face] - relative_to[face], axis=1)
        row.update({"rel_median": float(np.median(r)), "rel_p95": float(np.percentile(r, 95))})
    return row


def motion_visibility(B0: np.ndarray, Vt: np.ndarray, S: np.ndarray, G: np.ndarray, R: np.ndarray,
                      t: np.ndarray, face: np.ndarray) -> dict:
    """How much of an expression's motion a closest-point data term can see.

    ``motion``: |true expression vertex - true neutral vertex| on the face region; ``visible``: the
    distance of the true neutral, in the scan's true pose, to the expression scan's surface, i.e. what
    the data term measures before the non-rigid stage moves anything. The difference is motion along
    the surface (a jaw rotating about a hinge ~10 cm away moves the chin mostly along its own
    surface): only features (rims, curvature, landmarks) can show it. Returns 95th percentiles (cm).
    """
    from facebasis.geometry.nricp import ScanSurface

    d = ScanSurface(S, G).closest(B0[face] @ R.T + t)[2]
    m = np.linalg.norm(Vt[face] - B0[face], axis=1)
    return {"motion_p95": float(np.percentile(m, 95)), "visible_p95": float(np.percentile(d, 95))}


def _timed(fn, *args, **kwargs):
    import os

    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0, time.process_time() - c0, os.getloadavg()[0]


def _ict_setup():
    """The ICT data, its faces F and neutral T, the face region's vertices, the head-and-neck mask a
    scan keeps and the head's vertices: what every part of this benchmark starts from."""
    from problems.ict import _load, ict_regions

    d = _load()
    F = d["faces"].astype(np.int64)
    T = d["neutral"].astype(np.float64)
    reg = ict_regions()
    keep = np.zeros(len(T), bool)
    keep[: reg["head_neck"][1]] = True
    return d, F, T, np.arange(*reg["face"]), keep, np.arange(*reg["head_neck"])


def _ears(B0, head):
    """The leftmost and rightmost head vertices of ``B0`` (2, 3): where a scanner's view ends."""
    return np.stack([B0[head[np.argmax(B0[head, 0])]], B0[head[np.argmin(B0[head, 0])]]])


def run(seeds=(0,), n_expr: int = 6, quick: bool = False, templates=("generic", "identity"),
        landmarks=(False, True), log=print):
    """Rows of the benchmark (module docstring): per seed, template, landmark use and scan."""
    from facebasis.geometry.nricp import NonRigidICP
    from problems.ict import ict_random_identity

    d, F, T, face, keep, head = _ict_setup()
    names = [str(s) for s in d["expression_names"]]
    lm68 = d["landmarks68"].astype(np.int64)
    normals_of = NonRigidICP(F, len(T)).vertex_normals
    rows = []

    def add(row, res, sec, cpu, load):
        row.update({"no_surface": int(res.no_surface.sum()), "iterations": res.iterations, "seconds": sec,
                    "cpu_seconds": cpu, "load": load})
        rows.append(row)
        rel = (f" | rel median {row['rel_median']:.4f} p95 {row['rel_p95']:.4f}" if "rel_median" in row else "")
        if "motion_p95" in row:
            rel += f" | motion p95 {row['motion_p95']:.4f} visible p95 {row['visible_p95']:.4f}"
        log(f"seed {row['seed']} {row['template']:8s} {row['scan']:18s} lm={row['landmarks']:3s} err median "
            f"{row['err_median']:.4f} p95 {row['err_p95']:.4f} max {row['err_max']:.3f} | normal "
            f"{row['normal_median']:.4f}/{row['normal_p95']:.4f} tangential {row['tangential_median']:.4f}/"
            f"{row['tangential_p95']:.4f}{rel} | it {res.iterations} | {sec:.1f} s wall {cpu:.1f} s CPU load {load:.1f}")

    for seed in seeds:
        rng = np.random.default_rng(1000 + seed)
        _, B0 = ict_random_identity(seed)
        ears = _ears(B0, head)
        shapes = [("neutral", B0)]
        for nm in EXPRESSIONS[:n_expr]:
            shapes.append((nm, B0 + d["expression_deltas"][names.index(nm)].astype(np.float64)))
        scans = []
        for nm, Vt in shapes:
            S, G, R, t = make_scan(Vt, F, keep, ears, rng)
            truth = Vt @ R.T + t
            lm_pts = truth[lm68] + 0.02 * rng.standard_normal((len(lm68), 3))
            scans.append((nm, S, G, R, t, Vt, truth, lm_pts, motion_visibility(B0, Vt, S, G, R, t, face)))
        if "generic" in templates:
            # the floor of correspondence ambiguity: the exact identity mesh (same topology, no remesh,
            # noise, holes or motion; without the mouth and eye sockets) from the generic template
            Fk = F[keep[F].all(1)]
            nB = normals_of(B0)
            reg_obj = Registration(T, F, name="ICT neutral")
            res, sec, cpu, load = _timed(reg_obj.register, B0, Fk, name="exact identity")
            add({"seed": seed, "template": "generic", "scan": "neutral (exact mesh)", "landmarks": "no",
                 "scan_vertices": int(keep.sum()), **_measure(res, B0, face, nB)}, res, sec, cpu, load)
            # ... with the true pose (the similarity fitted with known correspondence) instead of the
            # rigid stage, and two references without any registration: that fitted template itself
            # (how far the identities differ) and its closest points on the true surface
            from facebasis.geometry.mesh import median_edge_length
            from facebasis.geometry.nricp import ScanSurface
            from facebasis.geometry.rigid import umeyama

            pose = umeyama(T[face], B0[face])
            surf = ScanSurface(pose.inverse().apply(B0), Fk)
            fit, sec, cpu, load = _timed(reg_obj.nricp.fit, T, surf, reg_obj.options.nricp,
                                            h=median_edge_length(T, F))
            res = type("R", (), {"vertices": pose.apply(fit.vertices), "no_surface": fit.no_surface,
                                 "iterations": fit.iterations})
            add({"seed": seed, "template": "generic", "scan": "exact mesh, true pose", "landmarks": "no",
                 "scan_vertices": int(keep.sum()), **_measure(res, B0, face, nB)}, res, sec, cpu, load)
            X = pose.apply(T)
            for nm, Y in (("no registration: fit", X),
                          ("no registration: closest", ScanSurface(B0, Fk).closest(X)[0])):
                res = type("R", (), {"vertices": Y, "no_surface": np.zeros(len(T), bool), "iterations": 0})
                add({"seed": seed, "template": "generic", "scan": nm, "landmarks": "no",
                     "scan_vertices": int(keep.sum()), **_measure(res, B0, face, nB)}, res, 0.0, 0.0, 0.0)
        for tname in templates:
            tmpl = T if tname == "generic" else B0
            for use_lm in landmarks:
                reg_obj = Registration(tmpl, F, landmarks=lm68 if use_lm else None, name=f"{tname} template")
                neutral = None
                for nm, S, G, R, t, Vt, truth, lm_pts, vis in scans:
                    res, sec, cpu, load = _timed(reg_obj.register, S, G, scan_landmarks=lm_pts if use_lm else None,
                                                    start=neutral, name=nm)
                    rel = None
                    if nm == "neutral":
                        neutral, (Rn, tn) = res.vertices, (R, t)
                    else:  # registered neutral in the ICT frame (true motion), + true delta, into this frame
                        rel = ((neutral - tn) @ Rn + (Vt - B0)) @ R.T + t
                    add({"seed": seed, "template": tname, "scan": nm, "landmarks": "yes" if use_lm else "no",
                         "scan_vertices": len(S), **_measure(res, truth, face, normals_of(truth), rel),
                         **(vis if nm != "neutral" else {})},
                        res, sec, cpu, load)
                if quick:
                    break
    return rows


def rig_comparison(seed: int = 0, n_train: int = 12, log=print) -> dict:
    """Generate a rig from registered scans of a person's training expressions and from the exact
    examples; compare their held-out errors (:func:`facebasis.rigging.crossval.heldout_error`).

    The person is :func:`problems.generation.ict_person_problem`'s (seeded identity, personalised
    rig, sparse training combinations, held-out expressions). Each training example and the neutral
    becomes a synthetic scan (:func:`make_scan`); the neutral is registered from the generic template,
    each example from the registered neutral (no landmarks). Registered meshes are brought back into
    the neutral scan's frame by the registration's own similarity, then one rigid motion (the
    best fit of the registered neutral's face onto the true neutral's) puts the set in the truth's
    frame for measuring.
    """
    import dataclasses

    from facebasis.geometry.rigid import umeyama
    from facebasis.rigging.heldout import heldout_error
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from problems.generation import ict_person_problem

    _, F, T, face, keep, head = _ict_setup()
    pp = ict_person_problem(seed=seed, n_train=n_train)
    p = pp.problem
    B0 = p.target_neutral
    ears = _ears(B0, head)
    rng = np.random.default_rng(2000 + seed)
    reg_obj = Registration(T, F, name="ICT neutral")
    out, secs = [], []
    neutral = None
    for k, Vt in enumerate([B0, *p.examples]):
        S, G, _, _ = make_scan(Vt, F, keep, ears, rng)
        res, sec, cpu, load = _timed(reg_obj.register, S, G, start=neutral)
        secs.append((sec, cpu, load))
        if k == 0:
            neutral = res.vertices
            out.append(neutral)
        else:  # back into the neutral scan's frame: the rigid stage mapped the neutral onto this scan
            out.append(res.similarity.inverse().apply(res.vertices))
        log(f"rig: registered {'neutral' if k == 0 else p.example_names[k - 1] if p.example_names else k} "
            f"{sec:.1f} s wall {cpu:.1f} s CPU load {load:.1f}")
    gauge = umeyama(out[0][face], B0[face], scale=False)
    X = gauge.apply(np.stack(out))
    reg_problem = dataclasses.replace(p, target_neutral=X[0], examples=X[1:])
    opts = GenerationOptions(ipopt="never")
    exact = BlendshapeGenerator(p, opts).run().rig
    regd = BlendshapeGenerator(reg_problem, opts).run().rig
    pairs = p.pair_indices
    e_exact = heldout_error(exact, pp.heldout, pairs)
    e_reg = heldout_error(regd, pp.heldout, pairs)
    ex_err = np.linalg.norm(X[1:, face] - p.examples[:, face], axis=2)
    row = {"seed": seed, "n_train": n_train, "heldout_exact": e_exact, "heldout_registered": e_reg,
           "example_err_median": float(np.median(ex_err)), "example_err_p95": float(np.percentile(ex_err, 95)),
           "neutral_err_median": float(np.median(np.linalg.norm(X[0, face] - B0[face], axis=1))),
           "seconds_median": float(np.median([s[0] for s in secs])),
           "cpu_seconds_median": float(np.median([s[1] for s in secs])), "load": float(np.mean([s[2] for s in secs]))}
    log(f"rig: held-out relative error, generated from exact examples {e_exact:.4f}, from registered scans "
        f"{e_reg:.4f}; registered examples vs exact: median {row['example_err_median']:.4f} cm, p95 "
        f"{row['example_err_p95']:.4f} cm")
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--expressions", type=int, default=6)
    ap.add_argument("--templates", nargs="+", choices=("generic", "identity"), default=["generic", "identity"])
    ap.add_argument("--no-landmarks", action="store_true", help="only the runs without landmarks")
    ap.add_argument("--rig", type=int, default=0, metavar="M",
                    help="also compare rigs generated from M registered vs exact training examples")
    ap.add_argument("--out", default="reports/registration")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    rows = run(tuple(args.seeds), args.expressions, args.quick, tuple(args.templates),
               (False,) if args.no_landmarks else (False, True))
    rig = rig_comparison(args.seeds[0], args.rig) if args.rig else None
    write_tables(rows, Path(args.out), rig)
    return rows


def write_tables(rows, out: Path, rig: dict | None = None) -> None:
    """``registration.csv`` (every scan) and ``registration.md`` (the table and the targets)."""
    import os
    import sys

    out.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "registration.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in r.items()})
    def f(v):
        return "" if v is None else f"{v:.4f}"

    lines = ["# Scan registration (ICT synthetic scans, face region, cm)", "",
             "Command: `python -m problems.bench_registration " + " ".join(sys.argv[1:]) + "`", "",
             f"Targets without landmarks: median <= {TARGETS['median']} cm, p95 <= {TARGETS['p95']} cm, "
             f"<= {TARGETS['seconds']} s per scan. Shared 2-core machine: wall and CPU seconds and the 1-minute "
             "load average are given per scan.", "",
             "template: `generic` = ICT's generic neutral (the issue's setting: another person's face); "
             "`identity` = the person's own exact neutral (no correspondence ambiguity: the pipeline's own error). "
             "`neutral (exact mesh)`: the person's exact neutral mesh itself (no remesh, noise, holes or motion) "
             "as the scan; `exact mesh, true pose`: the same with the true pose (similarity fitted with known "
             "correspondence) instead of the rigid stage; `no registration: fit`: the template under that "
             "similarity (how far the two identities differ); `no registration: closest`: its closest points "
             "on the true surface.", "",
             "err = registered vertex vs true vertex (scan frame, the issue's metric), split into its part "
             "along the true normal (off the surface) and across it (along the surface); rel = vs the "
             "registered neutral + the true expression delta (consistency across the set). motion p95 = 95th "
             "percentile of |true expression - true neutral|; visible p95 = of the true neutral's distance (in the "
             "scan's true pose) to the expression scan: the part of the motion a closest-point term can see, the "
             "rest is motion along the surface.", "",
             "| seed | template | scan | landmarks | err median | err p95 | err max | normal median | normal p95 | "
             "tangential median | tangential p95 | rel median | rel p95 | motion p95 | visible p95 | iterations | "
             "wall s | CPU s | load |",
             "|" + "---|" * 19]
    for r in rows:
        lines.append(f"| {r['seed']} | {r['template']} | {r['scan']} | {r['landmarks']} | {f(r['err_median'])} | "
                     f"{f(r['err_p95'])} | {r['err_max']:.3f} | {f(r['normal_median'])} | {f(r['normal_p95'])} | "
                     f"{f(r['tangential_median'])} | {f(r['tangential_p95'])} | {f(r.get('rel_median'))} | "
                     f"{f(r.get('rel_p95'))} | {f(r.get('motion_p95'))} | {f(r.get('visible_p95'))} | "
                     f"{r['iterations']} | {r['seconds']:.1f} | {r['cpu_seconds']:.1f} | "
                     f"{r['load']:.1f} |")
    if rig:
        lines += ["", f"Rig from {rig['n_train']} registered training scans (generic template, no landmarks) vs "
                  "from the exact examples: held-out relative error "
                  f"{rig['heldout_registered']:.4f} vs {rig['heldout_exact']:.4f}; registered examples vs exact: "
                  f"median {rig['example_err_median']:.4f} cm, p95 {rig['example_err_p95']:.4f} cm; "
                  f"{rig['seconds_median']:.1f} s wall, {rig['cpu_seconds_median']:.1f} s CPU per scan (median), "
                  f"load {rig['load']:.1f}."]
    lines += ["", f"Machine: {os.cpu_count()} cores."]
    (out / "registration.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
