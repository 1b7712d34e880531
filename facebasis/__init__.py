"""facebasis: personalised facial blendshape rigs, kept free of layer penetration, driven from video.

One sub-package per method over a shared geometry core; imports run downward only
(``tests/test_layout.py`` keeps it so):

* :mod:`facebasis.geometry` - meshes and files, triangle frames, factor-once reconstruction,
  deformation transfer, the :class:`Rig` type, glTF
* :mod:`facebasis.contact` - virtual edges against layer penetration and the exact counter
  (Li, Shen, Liu, Chinese Journal of Computers 2023)
* :mod:`facebasis.rigging` - example-based blendshape generation with certified weights
  (Gao, Tan, Guo, Fan, Computer Engineering 2015)
* :mod:`facebasis.report` - studies, figures and tables that only read results
* :mod:`facebasis.defaults` - the generated built-in face (data only)
* :mod:`facebasis.apps` - applications on top of everything: the demo
* :mod:`facebasis.cli` - the thin command line
* :mod:`facebasis.errors`, :mod:`facebasis.atomic` - the exception hierarchy and atomic outputs
"""

from .errors import FacebasisError, InputError, MeshError, RigError, SolverError, TopologyError
from .geometry.rig import Rig, load_rig_folder, write_rig_folder
from .geometry.transfer import DeformationTransfer, deformation_transfer

from ._version import __version__  # noqa: E402

__all__ = [
    "__version__", "FacebasisError", "InputError", "MeshError", "RigError", "SolverError", "TopologyError",
    "Rig", "load_rig_folder", "write_rig_folder", "DeformationTransfer", "deformation_transfer",
]
