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
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..atomic import atomic_directory, atomic_write_json
from .face import default_person, default_template
from ..geometry.meshio import write_mesh
from ..geometry.rig import write_shapes
from ..geometry.transfer import DeformationTransfer


def _relative_errors(result_deltas, truth_deltas):
    num = np.linalg.norm(result_deltas - truth_deltas, axis=(1, 2))
    den = np.linalg.norm(truth_deltas, axis=(1, 2))
    return num / den


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

        from ..rigging.generation import GenerationOptions, generate_blendshapes, reproduction_error
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
        heldout = {label: reproduction_error(rig, pp.heldout, pp.problem.pair_indices)
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
        atomic_write_json(stage / "summary.json", summary)
    log(f"wrote {out}")
    return summary
