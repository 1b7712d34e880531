"""Benchmark: the registration's rigid stage without landmarks, on whole-head and face-only scans.

    python -m problems.bench_rigid --seeds 0 1 2 [--cuts head face] [--scans neutral ...] [--out reports/registration/rigid]
    python -m problems.bench_rigid --table --out reports/registration/rigid

Scans (:func:`problems.bench_registration.make_scan`: another topology, ~100k vertices, shuffled, 0.2 mm
noise, holes at the ears, mouth and eyes, a random rotation and a translation of up to 30 cm): a seeded ICT
identity (:func:`problems.ict.ict_random_identity`) at neutral, jawOpen, mouthSmile_L and mouthPucker (the
template's own expression displacements), cut to the head and neck (``head``: what the template's skin covers)
or to the face region alone (``face``: a frontal scan, the template's skin covering much more than the scan).
The template is ICT's generic neutral (its skin, as :class:`facebasis.geometry.registration.Registration`
aligns it).

Per scan: the pose of :func:`facebasis.geometry.rigid.search_similarity` (the orientation search, the one-sided
refinement of the best distinct candidates and the perturbed restarts) and the final pose after
:func:`~facebasis.geometry.rigid.refine_point_to_plane` (what the registration keeps without a model fit), each
as the rotation error (degrees) and the translation error at the face's centre (cm) against the similarity
that best lays the template's face region on the true face (Umeyama over the known correspondence: the floor
that an identity's other shape leaves), plus the face vertices' median distance to their true places (cm); the
pose check's fields (:class:`~facebasis.geometry.rigidcheck.RigidResult`: near share, runner-up rotation and
residual ratio, ambiguous, doubtful); CPU seconds of the search and of the refinement. Baseline:
``trimesh.registration.icp`` (nearest points, similarity Procrustes, no reflection) from the start a user
would otherwise take, the centroids matched and the scale from the RMS radii, rotation the identity (ICP has
no orientation search).

Writes ``rigid.csv`` (one row per seed, cut and scan; kept if stopped: written after every scan) and with
``--table`` ``rigid.md``.
"""

from __future__ import annotations

import argparse
import csv
import os
import time
from pathlib import Path

import numpy as np

from problems.bench_registration import _ears, _ict_setup, make_scan
from problems.csvrows import csv_bytes

SCANS = ("neutral", "jawOpen", "mouthSmile_L", "mouthPucker")
CUTS = ("head", "face")


def _angle(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def pose_errors(sim, best, T_face: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """``(rotation error degrees, translation error at the face's centre, face median distance)`` of the
    template -> scan similarity ``sim`` against ``best`` (the known correspondence's Umeyama)."""
    c = T_face.mean(0)
    return (_angle(sim.rotation @ best.rotation.T), float(np.linalg.norm(sim.apply(c) - best.apply(c))),
            float(np.median(np.linalg.norm(sim.apply(T_face) - truth, axis=1))))


def trimesh_icp(P: np.ndarray, S: np.ndarray, rng: np.random.Generator):
    """The baseline: ``trimesh.registration.icp`` of 4000 template points ``P`` onto the scan's vertices ``S``
    from the centroids and RMS radii (identity rotation), as a :class:`~facebasis.geometry.rigid.Similarity`."""
    import trimesh

    from facebasis.geometry.rigid import Similarity

    sub = P[rng.choice(len(P), min(len(P), 4000), replace=False)]
    cp, cs = P.mean(0), S.mean(0)
    s = np.sqrt(((S - cs) ** 2).sum(1).mean() / ((P - cp) ** 2).sum(1).mean())
    M0 = np.eye(4)
    M0[:3, :3] *= s
    M0[:3, 3] = cs - s * cp
    M, _, _ = trimesh.registration.icp(sub, S, initial=M0, max_iterations=50, reflection=False, scale=True)
    A = M[:3, :3]
    sc = float(np.cbrt(np.linalg.det(A)))
    return Similarity(sc, A / sc, M[:3, 3].copy())


def run(seeds, cuts=CUTS, scans=SCANS, log=print, write=None) -> list[dict]:
    """Rows of the benchmark (module docstring); ``write(rows)`` after every scan."""
    from facebasis.geometry.nricp import ScanSurface
    from facebasis.geometry.registration import Registration, RegistrationOptions
    from facebasis.geometry.rigid import refine_point_to_plane, search_similarity, umeyama
    from problems.ict import ict_random_identity

    d, F, T, face, keep_head, head = _ict_setup()
    names = [str(s) for s in d["expression_names"]]
    reg = Registration(T, F, RegistrationOptions(), name="ICT")
    Ps, Fs = (T, F) if reg.skin is None else (T[reg.skin], reg._skin_icp.F)
    rigid = reg.options.rigid
    rows = []
    for seed in seeds:
        _, B0 = ict_random_identity(seed)
        shapes = [(nm, B0 if nm == "neutral" else B0 + d["expression_deltas"][names.index(nm)]) for nm in scans]
        for cut in cuts:
            keep = keep_head
            if cut == "face":
                keep = np.zeros(len(T), bool)
                keep[face] = True
            rng = np.random.default_rng(2000 + seed)  # the same seed for both cuts; the cuts' vertex counts differ,
            # so make_scan's draws (noise, shuffle, then the motion) give each cut its own motions: poses not paired
            ears = _ears(B0, head)
            for nm, Vt in shapes:
                S, G, R, t = make_scan(Vt, F, keep, ears, rng)
                truth = Vt[face] @ R.T + t
                best = umeyama(T[face], truth)
                c0 = time.process_time()
                check = search_similarity(Ps, Fs, S, G, rigid)
                c1 = time.process_time()
                sub = Ps[np.random.default_rng(rigid.seed).choice(len(Ps), min(len(Ps), 4000), replace=False)]
                final, _ = refine_point_to_plane(sub, ScanSurface(S, G).closest, check.similarity,
                                                 rigid.plane_iterations, rigid.keep_template, scale=rigid.scale)
                c2 = time.process_time()
                base = trimesh_icp(Ps, S, np.random.default_rng(seed))
                c3 = time.process_time()
                row = {"seed": seed, "cut": cut, "scan": nm, "scan_vertices": len(S)}
                for key, sim in (("search", check.similarity), ("final", final), ("trimesh_icp", base)):
                    rot, tr, med = pose_errors(sim, best, T[face], truth)
                    row |= {f"{key}_rot_deg": rot, f"{key}_trans_cm": tr, f"{key}_face_median_cm": med}
                row |= {"floor_face_median_cm": float(np.median(np.linalg.norm(best.apply(T[face]) - truth, axis=1))),
                        "near_share": check.near_share, "runner_up_deg": check.runner_up_degrees,
                        "runner_up_ratio": check.runner_up_ratio, "ambiguous": bool(check.ambiguous),
                        "doubtful": bool(check.doubtful), "search_cpu_s": c1 - c0, "refine_cpu_s": c2 - c1,
                        "trimesh_icp_cpu_s": c3 - c2, "load": os.getloadavg()[0]}
                rows.append(row)
                log(f"seed {seed} {cut:4s} {nm:12s} search {row['search_rot_deg']:5.1f} deg {row['search_trans_cm']:.2f} cm"
                    f" | final {row['final_rot_deg']:5.1f} deg {row['final_trans_cm']:.2f} cm face "
                    f"{row['final_face_median_cm']:.2f} (floor {row['floor_face_median_cm']:.2f}) | trimesh icp "
                    f"{row['trimesh_icp_rot_deg']:5.1f} deg | near {check.near_share:.2f} runner "
                    f"{check.runner_up_degrees:.0f} deg x{check.runner_up_ratio:.2f} doubtful {check.doubtful} | "
                    f"{row['search_cpu_s']:.1f} s CPU load {row['load']:.1f}")
                if write is not None:
                    write(rows)
    return rows


def write_table(out: Path) -> Path:
    """``rigid.md`` from ``rigid.csv``: per cut, median / max of each method's errors, the check's verdicts and
    CPU; then every row."""
    from facebasis.atomic import atomic_write_bytes

    with open(out / "rigid.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    f = lambda r, k: float(r[k])  # noqa: E731
    lines = ["# The rigid stage without landmarks (ICT identities, generic template)", "",
             "Written by `python -m problems.bench_rigid --table` from `rigid.csv` (commands: `python -m "
             "problems.reproduce registration-rigid --dry-run`). Errors against the similarity that best lays the "
             "template's face on the true face (known correspondence): rotation (degrees), translation at the face's "
             "centre (cm); `face` the face vertices' median distance to their true places (cm; `floor`: that best "
             "similarity's). `search`: search_similarity; `final`: then refine_point_to_plane; baseline "
             "`trimesh icp`: trimesh.registration.icp from the centroids and RMS radii.", "",
             "| cut | scans | method | rotation median / max | translation median / max | face median / max | CPU s median / max |",
             "|---|---|---|---|---|---|---|"]
    for cut in dict.fromkeys(r["cut"] for r in rows):
        sel = [r for r in rows if r["cut"] == cut]
        for key, lab in (("search", "search"), ("final", "final"), ("trimesh_icp", "trimesh icp")):
            cpu = "search_cpu_s" if key == "search" else ("refine_cpu_s" if key == "final" else "trimesh_icp_cpu_s")
            cols = [np.array([f(r, f"{key}_{k}") for r in sel]) for k in ("rot_deg", "trans_cm", "face_median_cm")]
            c = np.array([f(r, cpu) for r in sel])
            lines.append(f"| {cut} | {len(sel)} | {lab} | " + " | ".join(f"{np.median(a):.2f} / {a.max():.2f}" for a in cols)
                         + f" | {np.median(c):.1f} / {c.max():.1f} |")
        fl = np.array([f(r, "floor_face_median_cm") for r in sel])
        lines.append(f"| {cut} | {len(sel)} | floor | | | {np.median(fl):.2f} / {fl.max():.2f} | |")
    bad = [r for r in rows if r["doubtful"] == "True" or r["ambiguous"] == "True"]
    load = [f(r, "load") for r in rows]
    lines += ["", f"The check: {len(bad)} of {len(rows)} poses doubtful or ambiguous"
              + (": " + ", ".join(f"seed {r['seed']} {r['cut']} {r['scan']} (final rotation error "
                                  f"{f(r, 'final_rot_deg'):.1f} deg)" for r in bad) if bad else "")
              + f"; near share {min(f(r, 'near_share') for r in rows):.2f}-{max(f(r, 'near_share') for r in rows):.2f};"
              f" runner-up residual ratio {min(f(r, 'runner_up_ratio') for r in rows):.2f} at the lowest. Load "
              f"{min(load):.1f}-{max(load):.1f}.", "",
              "| seed | cut | scan | search rot / trans | final rot / trans / face (floor) | trimesh icp rot / trans | "
              "near share | runner-up deg / ratio | doubtful | search CPU s |", "|" + "---|" * 10]
    for r in rows:
        lines.append(f"| {r['seed']} | {r['cut']} | {r['scan']} | {f(r, 'search_rot_deg'):.1f} / {f(r, 'search_trans_cm'):.2f} | "
                     f"{f(r, 'final_rot_deg'):.1f} / {f(r, 'final_trans_cm'):.2f} / {f(r, 'final_face_median_cm'):.2f} "
                     f"({f(r, 'floor_face_median_cm'):.2f}) | {f(r, 'trimesh_icp_rot_deg'):.1f} / "
                     f"{f(r, 'trimesh_icp_trans_cm'):.2f} | {f(r, 'near_share'):.2f} | {f(r, 'runner_up_deg'):.0f} / "
                     f"{f(r, 'runner_up_ratio'):.2f} | {r['doubtful']} | {f(r, 'search_cpu_s'):.1f} |")
    atomic_write_bytes(out / "rigid.md", ("\n".join(lines) + "\n").encode())
    return out / "rigid.md"


def main(argv=None):
    from facebasis.atomic import atomic_write_bytes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--cuts", nargs="+", choices=CUTS, default=list(CUTS))
    ap.add_argument("--scans", nargs="+", choices=SCANS, default=list(SCANS))
    ap.add_argument("--out", default="reports/registration/rigid")
    ap.add_argument("--table", action="store_true", help="only write rigid.md from rigid.csv")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not args.table:
        run(args.seeds, args.cuts, args.scans, write=lambda rows: atomic_write_bytes(out / "rigid.csv", csv_bytes(rows)))
    print(write_table(out))


if __name__ == "__main__":
    main()
