"""Exception hierarchy owned by facebasis.

Every error a user can trigger with bad input derives from :class:`FacebasisError`, so a caller
can catch the toolkit's errors without catching programming errors. Messages name the file or
parameter, what was expected and what was found.
"""

from __future__ import annotations


class FacebasisError(Exception):
    """Base class of every error raised on purpose by facebasis."""


class MeshError(FacebasisError):
    """A mesh is unreadable, malformed or geometrically unusable (NaN, degenerate, bad indices)."""


class TopologyError(MeshError):
    """Meshes that must share one topology do not (vertex count, faces)."""


class RigError(FacebasisError):
    """A rig folder or rig object is inconsistent (missing neutral, unknown shape names, ...)."""


class InputError(FacebasisError):
    """A parameter or input file has a wrong value (weights out of range, bad JSON, ...)."""


class SolverError(FacebasisError):
    """A numerical solver failed; the message carries the solver's own status."""

    def __init__(self, message: str, status: str | None = None):
        super().__init__(message)
        self.status = status
