"""The last resort of exact contact: a shape pulled back towards the target neutral around the
pairs its solve left, until the exact check finds no new pair.

Used by :class:`facebasis.contact.solver.ContactSolver` after its rounds (and the transfer-energy
fallback) still leave new pairs. The shape is intersection-free afterwards, at the price of part of
its motion near those pairs; the solver reports how much (``ContactShape.retreat_loss``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import SolverError
from .proximity import new_pairs


def retreat(d: np.ndarray, B0: np.ndarray, F: np.ndarray, S: np.ndarray, left: np.ndarray, reach: float,
            vertex_faces: sp.spmatrix) -> tuple[np.ndarray, int]:
    """Pull the delta ``d`` back towards ``B0`` around the pairs ``left`` until none is new.

    Vertices within ``r`` (distance in ``B0``) of the corners of the pairs take ``B0``, the next
    ``r`` blend linearly back to ``d``: ``d' = (1 - w) d`` with ``w = clip(2 - dist / r, 0, 1)``.
    ``r`` starts at ``reach`` and doubles, the pairs found on the way joining the centres, until the
    exact check (:func:`~facebasis.contact.proximity.new_pairs` against ``B0`` and the template
    shape ``S``, on every pair holding a blended triangle; the others keep ``d``'s geometry, whose
    new pairs are all in ``left``) finds none. It ends: once ``r`` exceeds the neutral's bounding
    box diagonal, ``d'`` is 0 and the shape is ``B0``, which has no new pair.

    Parameters
    ----------
    d : (n, 3) delta of the shape; B0 : (n, 3) target neutral; F : (m, 3) triangles
    S : (n, 3) the template shape (its pairs are allowed); left : (q, 2) new pairs of ``B0 + d``
    reach : starting radius (> 0); vertex_faces : (n, m) sparse vertex-triangle incidence

    Returns
    -------
    (d' (n, 3), number of vertices moved)
    """
    centres = np.unique(F[left].ravel())
    r = float(reach)
    span = float(np.linalg.norm(B0.max(0) - B0.min(0)))
    while True:
        dist, _ = cKDTree(B0[centres]).query(B0, distance_upper_bound=2.0 * r)
        w = np.clip(2.0 - dist / r, 0.0, 1.0)  # 1 within r, 0 beyond 2 r (dist inf there)
        out = d * (1.0 - w)[:, None]
        touch = (vertex_faces.T @ (w > 0).astype(np.float64)) > 0
        found = new_pairs(B0 + out, F, (B0, S), faces=touch)
        if len(found) == 0 or r > span:
            if len(found):  # cannot happen: the shape is B0 itself
                raise SolverError(f"contact: expected no new pair at the target neutral, found {len(found)}")
            return out, int((w > 0).sum())
        centres = np.union1d(centres, F[found].ravel())
        r *= 2.0


__all__ = ["retreat"]
