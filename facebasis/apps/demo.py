"""``facebasis demo``: the main job on the built-in default face, end to end.

Writes into one folder (atomically):

* ``template/`` - the generic default rig (neutral + blendshapes as OBJ)
* ``person_neutral.obj`` - the second person's neutral
* ``transfer/`` - deformation transfer of the template onto the person
* ``rig/`` - example-based generation (Gao et al. 2015) from 10 training expressions of the person with
  rough (noisy) weights: the generated blendshapes, ``weights.json``, ``history.json``,
  ``inputs.json`` (``facebasis verify OUT/rig`` certifies its weights) and ``rig.glb`` (glTF 2.0,
  one morph target per blendshape)
* ``rig_inputs/`` - those training expressions (OBJ) and rough weights
* ``summary.json`` - figures of the run (times, errors against the person's true shapes)
* ``figures/`` - renders, error maps and the convergence plot (PNG)
* ``video/`` - a generated test sequence (``frames/``, PNG images of a cartoon face that talks,
  smiles, blinks and raises its brows while the head moves) with its first frame's landmarks
  (``first.pts``), as a user would bring a video
* ``capture/`` - ``facebasis capture`` of that sequence (``track.npz``, ``landmarks.csv``,
  ``overlay.mp4``)
* ``cartoon/`` - ``facebasis animate2d``: the built-in cartoon face animated by the capture
* ``retarget/`` - ``facebasis retarget``: the built-in rig's weights and head pose per frame, and
  ``animation.glb``, the rig animated by them
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..atomic import atomic_directory, atomic_write_json
from ..defaults.face import default_person, default_template
from ..geometry.meshio import write_mesh
from ..geometry.rig import write_shapes
from ..geometry.transfer import DeformationTransfer


def _relative_errors(result_deltas, truth_deltas):
    num = np.linalg.norm(result_deltas - truth_deltas, axis=(1, 2))
    den = np.linalg.norm(truth_deltas, axis=(1, 2))
    return num / den


def _capture_and_reproduce(stage: Path, quick: bool, log) -> dict:
    """Capture a generated sequence and reproduce it on the built-in cartoon and rig."""
    from PIL import Image

    from ..capture.synthetic import synthetic_sequence
    from ..capture.tracker import capture
    from ..retarget.files import write_pts
    from ..retarget.pipeline import run_animate2d, run_retarget

    n_frames = 30 if quick else 120
    seq = synthetic_sequence(n_frames, size=(256, 256), face="cartoon", seed=0)
    frames_dir = stage / "video" / "frames"
    frames_dir.mkdir(parents=True)
    for t, frame in enumerate(seq.frames):
        Image.fromarray(frame).save(frames_dir / f"frame{t:04d}.png")
    write_pts(stage / "video" / "first.pts", seq.landmarks[0])
    t0 = time.perf_counter()
    res = capture(frames_dir, landmarks=stage / "video" / "first.pts", out=stage / "capture", fps=25.0)
    seconds = time.perf_counter() - t0
    err = np.linalg.norm(res.capture.landmarks - seq.landmarks, axis=-1)
    log(f"capture: {n_frames} frames of a generated sequence in {seconds:.2f} s; landmark error against the "
        f"known motion: mean {err.mean():.2f} px, worst {err.max():.2f} px")
    cartoon = run_animate2d(stage / "capture", stage / "cartoon")
    rig = run_retarget(stage / "capture", stage / "retarget", first_frame_neutral=True)
    log(f"reproduction: built-in cartoon animated ({cartoon['warp_ms_per_frame']:.1f} ms per frame); built-in rig "
        f"retargeted ({rig['ms_per_frame']:.2f} ms per frame, landmark residual {rig['residual_px_mean']:.2f} px)")
    return {"frames": n_frames, "capture_seconds": seconds, "landmark_error_px_mean": float(err.mean()),
            "landmark_error_px_max": float(err.max()), "cartoon_warp_ms_per_frame": cartoon["warp_ms_per_frame"],
            "retarget_ms_per_frame": rig["ms_per_frame"], "retarget_residual_px_mean": rig["residual_px_mean"]}


def run_demo(out: Path, quick: bool = False, log=print) -> dict:
    """Run the demo into ``out``; returns the summary dict."""
    template = default_template()
    person = default_person()
    summary: dict = {"template_vertices": template.n_vertices, "template_faces": len(template.faces),
                     "shapes": list(template.names)}
    with atomic_directory(out) as stage:
        write_shapes(stage / "template", template)
        write_mesh(stage / "person_neutral.obj", person.neutral, person.faces)
        t0 = time.perf_counter()
        transferred = DeformationTransfer(template, person.neutral).transfer()
        summary["transfer_seconds"] = time.perf_counter() - t0
        write_shapes(stage / "transfer", transferred)
        err = _relative_errors(transferred.deltas, person.deltas)
        summary["transfer_relative_error_vs_person_truth"] = dict(zip(template.names, map(float, err)))
        log(f"deformation transfer: {template.n_shapes} shapes in {summary['transfer_seconds']:.3f} s; "
            f"median relative error against the person's true shapes {np.median(err):.3f}")
        # example-based generation from training expressions of the person
        from ..rigging.synthetic import default_face_problem

        from ..rigging.problem import GenerationOptions
        from ..rigging.heldout import heldout_error
        from ..rigging.generation import generate_blendshapes
        from ..rigging.runs import write_problem_inputs, write_rig_run

        pp = default_face_problem(seed=0, n_train=10, n_heldout=10, noise=0.3)
        options = GenerationOptions(iterations=3 if quick else 10)

        def progress(rec, total):
            log(f"  iteration {rec.iteration}/{total}: E_fit {rec.e_fit:.4g} E_reg {rec.e_reg:.4g} "
                f"weight objective {rec.weight_objective:.6g} IPOPT {rec.ipopt_status}")

        result = generate_blendshapes(pp.problem, options, progress)
        # the run as `facebasis rig` writes it, with its inputs as files (`facebasis verify OUT/rig`)
        examples_dir, weights_file = write_problem_inputs(stage / "rig_inputs", pp.problem)
        history = write_rig_run(stage / "rig", result, options, pp.problem, examples_dir, weights_file,
                                relative_to=stage / "rig")
        gen_err = _relative_errors(result.rig.deltas, person.deltas)
        heldout = {label: heldout_error(rig, pp.heldout, pp.problem.pair_indices)
                   for label, rig in (("example-based", result.rig), ("deformation transfer", transferred))}
        summary["generation"] = {
            "seconds": result.seconds + result.precompute_seconds,
            "ipopt_statuses": [h.ipopt_status for h in result.history],
            "shape_relative_error_vs_truth_median": float(np.median(gen_err)),
            "heldout_relative_error": heldout,
            "missing_expressions": list(result.missing),
        }
        log(f"example-based generation: {len(result.history)} iterations in "
            f"{summary['generation']['seconds']:.2f} s; held-out expression error {heldout['example-based']:.4f} "
            f"vs deformation transfer {heldout['deformation transfer']:.4f}")
        from ..report.figures import convergence_figure, demo_figures

        demo_figures(stage / "figures", template, person,
                     {"deformation transfer": transferred, "example-based": result.rig})
        convergence_figure(history, stage / "figures" / "convergence")
        summary["video"] = _capture_and_reproduce(stage, quick, log)
        atomic_write_json(stage / "summary.json", summary)
    log(f"wrote {out}")
    return summary
