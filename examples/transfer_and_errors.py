"""Deformation transfer of the built-in rig onto a second face, scored against that face's truth.

The built-in template (15 ARKit-named shapes) is transferred onto the built-in person's neutral
with one sparse factorisation (Sumner & Popovic 2004); the person's true, person-specific shapes
are known, so each transferred shape's error can be measured. The figure renders the transferred
shapes coloured by their displacement.
"""

import numpy as np

from _common import output_folder
from facebasis import DeformationTransfer
from facebasis.defaults.face import default_person, default_template
from facebasis.report.run_report import shapes_figure

out = output_folder(__file__)
template, person = default_template(), default_person()
rig = DeformationTransfer(template, person.neutral).transfer()     # all shapes; rig.deltas (k, n, 3)
print(f"transferred {rig.n_shapes} shapes onto a face of {rig.n_vertices} vertices")
# the person's rig is the truth here (its shapes are person-specific: a stronger left smile, ...)
truth = person.deltas[person.index(list(rig.names))]
err = np.linalg.norm(rig.deltas - truth, axis=2)
size = np.linalg.norm(truth, axis=2).max(1)
for name, e, s in zip(rig.names, err.max(1), size):
    print(f"  {name:14s} largest error {e:.3f} cm of a {s:.2f} cm motion")
shapes_figure(rig, out / "transferred_shapes", formats=("png",))
print(f"figure: {out / 'transferred_shapes.png'}")
