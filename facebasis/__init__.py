"""facebasis: personalised facial blendshape rigs.

Core pieces (pure functions over numpy arrays, stateful solvers for repeated solves):

* :mod:`facebasis.gradients` - triangle frames, deformation gradients, the edge operator
* :mod:`facebasis.poisson` - factor-once reconstruction of vertices from edges
* :mod:`facebasis.transfer` - deformation transfer (Sumner & Popovic 2004)
* :mod:`facebasis.rig`, :mod:`facebasis.meshio` - rigs, rig folders, OBJ/PLY
* :mod:`facebasis.generation`, :mod:`facebasis.weights` - example-based generation (seed 000)
* :mod:`facebasis.certify`, :mod:`facebasis.formulations`, :mod:`facebasis.verify` - certified
  optima of the weight step and the IPOPT formulations compared against them
* :mod:`facebasis.virtual_edges`, :mod:`facebasis.penetration` - virtual edges (seed 004) and the
  exact count of intersecting triangle pairs
* :mod:`facebasis.studies`, :mod:`facebasis.report`, :mod:`facebasis.export` - Dask studies,
  paper-style figures from stored results, glTF export
* :mod:`facebasis.default_face` - the generated built-in face
"""

from .errors import FacebasisError, InputError, MeshError, RigError, SolverError, TopologyError
from .rig import Rig, load_rig_folder, write_rig_folder
from .transfer import DeformationTransfer, deformation_transfer

__version__ = "0.1.0"

__all__ = [
    "FacebasisError", "InputError", "MeshError", "RigError", "SolverError", "TopologyError",
    "Rig", "load_rig_folder", "write_rig_folder", "DeformationTransfer", "deformation_transfer",
]
