"""The rig fit's arguments checked and resolved: the identity mode, landmark vertex indices and
exclusive shape pairs of :class:`.rigdrive.RigRetargeter` (re-exported there)."""

from __future__ import annotations

import numpy as np

from ..errors import InputError, named_params
from ..geometry.rig import Rig

#: how the person's neutral landmarks are obtained (see :mod:`.rigdrive` and :mod:`.calibrate`)
IDENTITY_MODES = ("auto", "first-frame", "rig", "quantile")
#: default identity mode (measured in reports/reproduction/real_clips_notes.md and reports/retarget)
DEFAULT_IDENTITY = "auto"


def resolve_identity(identity=None, first_frame_neutral=None) -> str:
    """The identity mode from ``identity`` and the older boolean ``first_frame_neutral`` (True is
    ``"first-frame"``, False is ``"rig"``); both given and disagreeing: :class:`InputError`."""
    if identity is not None and identity not in IDENTITY_MODES:
        raise InputError(f"identity: expected one of {', '.join(IDENTITY_MODES)}, found {identity!r}")
    if first_frame_neutral is None:
        return DEFAULT_IDENTITY if identity is None else identity
    old = "first-frame" if first_frame_neutral else "rig"
    if identity is not None and identity != old:
        raise InputError(what="identity", expected="one setting", found=f"identity={identity!r} and "
                         f"first_frame_neutral={bool(first_frame_neutral)} (which means {old!r})")
    return old


def check_landmark_indices(indices, n_vertices: int, n_landmarks: int, name: str = "landmark indices") -> np.ndarray:
    """(L,) int64 vertex indices; :class:`InputError` if the count is not the capture's L, an index
    is out of range or one vertex is given twice (two landmarks pinned to one vertex)."""
    idx = np.asarray(indices)
    if idx.ndim != 1 or not (np.issubdtype(idx.dtype, np.integer) or (idx.size == 0)):
        if idx.ndim == 1 and np.issubdtype(idx.dtype, np.floating) and np.all(idx == np.round(idx)):
            idx = idx.astype(np.int64)
        else:
            raise InputError(f"{name}: expected a flat list of integer vertex indices, found shape {idx.shape} "
                             f"of {idx.dtype}")
    idx = idx.astype(np.int64)
    if len(idx) != n_landmarks:
        raise InputError(f"{name}: expected {n_landmarks} indices (one per capture landmark), found {len(idx)}")
    bad = idx[(idx < 0) | (idx >= n_vertices)]
    if len(bad):
        raise InputError(f"{name}: expected vertex indices in [0, {n_vertices}), found {bad[:10].tolist()}")
    from .files import repeated_indices

    dup = repeated_indices(idx)
    if dup:
        raise InputError(f"{name}: expected distinct vertex indices (one vertex per landmark), found {dup}")
    return idx


def resolve_pairs(rig: Rig, pairs, what: str = "{exclusive}") -> np.ndarray:
    """Exclusive pairs given as names (a, b) or indices -> (p, 2) int64 (unknown names: RigError;
    ``what`` names them, a ``{name}`` placeholder for a library parameter, see :mod:`facebasis.errors`)."""
    P = list(pairs or ())
    if not P:
        return np.zeros((0, 2), np.int64)
    if all(isinstance(a, str) and isinstance(b, str) for a, b in P):
        flat = [n for ab in P for n in ab]
        return rig.index(flat, what=what, named=named_params(what)).reshape(-1, 2)
    arr = np.asarray(P, np.int64).reshape(-1, 2)
    if arr.min() < 0 or arr.max() >= rig.n_shapes:
        raise InputError(what=what, expected=f"shape indices in [0, {rig.n_shapes})", found=arr.tolist(),
                         params=named_params(what))
    return arr


__all__ = ["IDENTITY_MODES", "DEFAULT_IDENTITY", "resolve_identity", "check_landmark_indices", "resolve_pairs"]
