"""facebasis: personalised facial blendshape rigs.

Core pieces (pure functions over numpy arrays, stateful solvers for repeated solves):

* :mod:`facebasis.gradients` - triangle frames, deformation gradients, the edge operator
* :mod:`facebasis.poisson` - factor-once reconstruction of vertices from edges
* :mod:`facebasis.transfer` - deformation transfer (Sumner & Popovic 2004)
* :mod:`facebasis.rig`, :mod:`facebasis.meshio` - rigs, rig folders, OBJ/PLY
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
