"""The shared mesh helpers: one ``unique_edges`` and one sparse Cholesky wrapper for the package."""

import numpy as np
import pytest
import scipy.sparse as sp

from conftest import bumpy_sheet, grid_sheet
from facebasis.geometry.cholesky import SparseCholesky
from facebasis.geometry.mesh import boundary_vertices, unique_edges
from facebasis.retarget.rbf import mean_edge_length


def _reference_edges(F):
    return np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_unique_edges_are_the_sorted_unique_undirected_edges(seed):
    rng = np.random.default_rng(seed)
    _, F = grid_sheet(7 + seed, 5)
    F = F[rng.permutation(len(F))][:, rng.permutation(3)] + 3   # shuffled, flipped, vertices 0-2 unused
    E = unique_edges(F)
    assert E.dtype == np.int64 and np.array_equal(E, _reference_edges(F))
    assert np.all(E[:, 0] < E[:, 1])
    nx, ny = 7 + seed, 5                                          # a grid's edges: rows + columns + diagonals
    assert len(E) == ny * (nx - 1) + nx * (ny - 1) + (nx - 1) * (ny - 1)
    assert unique_edges(np.zeros((0, 3), np.int64)).shape == (0, 2)
    assert np.array_equal(unique_edges([[0, 1, 2]]), [[0, 1], [0, 2], [1, 2]])


def test_mean_edge_length_uses_each_edge_once():
    V, F = bumpy_sheet()
    E = _reference_edges(F)
    assert mean_edge_length(V, F) == float(np.mean(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)))


def test_sparse_cholesky_solves_one_or_many_columns_and_refuses_an_indefinite_matrix():
    rng = np.random.default_rng(3)
    A = sp.random(40, 40, density=0.1, random_state=4)
    M = (A @ A.T + sp.eye(40)).tocsr()
    chol = SparseCholesky(M)
    b = rng.normal(size=(40, 3))
    x = chol.solve(b)
    assert x.shape == (40, 3) and np.abs(M @ x - b).max() < 1e-10
    assert np.allclose(chol.solve(b[:, 0]), x[:, 0], atol=1e-12)
    with pytest.raises((RuntimeError, ValueError)):
        SparseCholesky(sp.diags(np.r_[np.ones(5), -1.0]).tocsr())


def test_boundary_vertices_of_a_sheet_a_triangle_and_a_closed_surface():
    """A 6 x 5 grid sheet: its 18 border vertices; one triangle: all three; a tetrahedron (closed): none."""
    V, F = grid_sheet(6, 5)
    ij = np.stack(np.unravel_index(np.arange(30), (5, 6)), 1)
    border = np.flatnonzero((ij[:, 0] % 4 == 0) | (ij[:, 1] % 5 == 0))
    np.testing.assert_array_equal(boundary_vertices(F), border)
    np.testing.assert_array_equal(boundary_vertices([[4, 2, 7]]), [2, 4, 7])
    tet = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    assert boundary_vertices(tet).size == 0 and boundary_vertices(np.zeros((0, 3), int)).size == 0
