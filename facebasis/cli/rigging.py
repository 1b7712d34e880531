"""The rig commands of ``facebasis``: ``transfer`` (:mod:`.transfer`), ``rig`` and ``rig --resume``
(:mod:`.rig`, :mod:`.resume`), ``export`` and ``verify`` (:mod:`.export`): deformation transfer and
example-based rig generation (Gao, Tan, Guo, Fan 2015) with certified weights."""

from __future__ import annotations

from . import export, rig, transfer


def register(sub) -> None:
    """Add this group's subcommands to the ``facebasis`` parser, in the order ``--help`` lists them."""
    transfer.register(sub)
    rig.register(sub)
    export.register(sub)
