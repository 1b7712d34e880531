"""Correspondence between two face meshes by a multiquadric RBF network (paper eq. 10-13).

Wu & Ju (2016) place every vertex of the captured first-frame mesh on a target face with a radial
basis function network trained on point pairs of known correspondence (the landmarks):

    f(x) = sum_j w_j h(||x - x_j||) (+ an affine tail here)          (eq. 10)
    h(r) = sqrt(r^2 + c^2)     (Hardy's multiquadric)                  (eq. 11)

and scale the captured displacements by the ratio of the two meshes' mean edge lengths:

    d_target = s d_capture,   s = (1/n sum_i b_t,i) / (1/m sum_i b_o,i)   (eq. 12-13)

The network is :class:`scipy.interpolate.RBFInterpolator` with ``kernel="multiquadric"`` (its
kernel ``-sqrt(1 + (eps r)^2)`` is eq. 11 up to the constant factor ``-1/c`` with ``eps = 1/c``, which
the trained weights absorb) and a degree-1 polynomial tail, so affine maps are reproduced exactly
and the training pairs are interpolated exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry.mesh import unique_edges


def _points(a, name: str, dim: int | None = None) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or (dim is not None and a.shape[1] != dim):
        want = f"(k, {dim})" if dim else "(k, d)"
        raise InputError(f"{name}: expected points of shape {want}, found {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"{name}: expected finite coordinates, found NaN/inf")
    return a


def default_shape_parameter(centres: np.ndarray) -> float:
    """Hardy's rule for the multiquadric's ``c`` (eq. 11): the mean nearest-neighbour distance of
    the training centres (k, d). Returns a positive float (1.0 if all centres coincide)."""
    from scipy.spatial import cKDTree

    if len(centres) < 2:
        return 1.0
    d, _ = cKDTree(centres).query(centres, k=2)
    c = float(np.mean(d[:, 1]))
    return c if c > 0 else 1.0


@dataclass(frozen=True)
class RBFMap:
    """A trained multiquadric RBF network ``R^d -> R^e`` (eq. 10-11) with an affine tail.

    Attributes
    ----------
    source : (k, d) training inputs (e.g. landmarks of the capture's first frame, pixels)
    target : (k, e) training outputs (the same landmarks on the target face)
    c : the multiquadric's shape parameter (eq. 11), in source units
    """

    source: np.ndarray
    target: np.ndarray
    c: float
    _interp: object

    def __call__(self, points) -> np.ndarray:
        """Map points (n, d) -> (n, e) (eq. 10)."""
        P = _points(points, "RBF input", self.source.shape[1])
        return np.asarray(self._interp(P), dtype=np.float64)


def merge_duplicate_sources(S, T):
    """Source points that coincide (closed lips put an upper and a lower inner-lip landmark on one
    pixel) cannot be interpolated to different targets: each set of coincident sources (k, d) is
    trained once, on the mean of its targets (k, e). Returns (S, T) unchanged when all are distinct."""
    U, inverse, counts = np.unique(S, axis=0, return_inverse=True, return_counts=True)
    if len(U) == len(S):
        return S, T
    inverse = inverse.ravel()
    merged = np.zeros((len(U), T.shape[1]))
    np.add.at(merged, inverse, T)
    return U, merged / counts[:, None]


def fit_rbf(source, target, c: float | None = None, smoothing: float = 0.0) -> RBFMap:
    """Train the multiquadric network of eq. 10-11 on known pairs ``source[j] -> target[j]``.

    Parameters
    ----------
    source : (k, d) inputs; target : (k, e) outputs
    c : multiquadric shape parameter (default :func:`default_shape_parameter` of ``source``)
    smoothing : 0 interpolates the pairs exactly (the paper's network)

    Raises
    ------
    InputError
        mismatched counts, too few pairs for the affine tail (k < d + 1) or a degenerate
        (collinear) set. Coincident source points are merged (:func:`merge_duplicate_sources`).
    """
    from scipy.interpolate import RBFInterpolator

    S = _points(source, "RBF training inputs")
    T = _points(target, "RBF training outputs")
    if len(S) != len(T):
        raise InputError(f"RBF training pairs: expected as many targets as sources ({len(S)}), found {len(T)}")
    S, T = merge_duplicate_sources(S, T)
    d = S.shape[1]
    if len(S) < d + 1:
        raise InputError(f"RBF training pairs: expected at least {d + 1} pairs, found {len(S)}")
    c = default_shape_parameter(S) if c is None else float(c)
    if not np.isfinite(c) or c <= 0:
        raise InputError(f"RBF shape parameter c: expected a positive number, found {c}")
    try:
        interp = RBFInterpolator(S, T, kernel="multiquadric", epsilon=1.0 / c, degree=1, smoothing=smoothing)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise InputError(f"RBF training pairs: the network cannot be trained ({exc}); expected distinct, "
                         f"non-collinear landmarks") from exc
    return RBFMap(S, T, c, interp)


def mean_edge_length(V, F) -> float:
    """Mean length of the unique edges of a triangle mesh V (n, d), F (m, 3) (eq. 13's averages)."""
    V = np.asarray(V, np.float64)
    E = unique_edges(F)
    if len(E) == 0:
        raise InputError("mean edge length: expected a mesh with triangles, found none")
    return float(np.mean(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)))


def edge_length_ratio(V_target, F_target, V_source, F_source) -> float:
    """Eq. 13: ``s = mean edge length of the target mesh / mean edge length of the source mesh``.

    Displacements measured on the source (the capture) are multiplied by ``s`` before they drive
    the target (eq. 12).
    """
    lo = mean_edge_length(V_source, F_source)
    if lo <= 0:
        raise InputError("eq. 13 scale: the source mesh has zero mean edge length")
    return mean_edge_length(V_target, F_target) / lo


__all__ = ["RBFMap", "fit_rbf", "default_shape_parameter", "mean_edge_length", "edge_length_ratio"]
