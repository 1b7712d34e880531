"""``facebasis demo``: the main job on the built-in default face, end to end.

Writes into one folder (atomically):

* ``template/`` - the generic default rig (neutral + blendshapes as OBJ)
* ``person_neutral.obj`` - the second person's neutral
* ``transfer/`` - deformation transfer of the template onto the person
* ``summary.json`` - figures of the run
* ``figures/`` - renders and error maps (PNG)
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .atomic import atomic_directory, atomic_write_json
from .default_face import default_person, default_template
from .meshio import write_mesh
from .rig import write_shapes
from .transfer import DeformationTransfer


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
        from .figures import demo_figures

        demo_figures(stage / "figures", template, person, {"deformation transfer": transferred})
        atomic_write_json(stage / "summary.json", summary)
    log(f"wrote {out}")
    return summary
