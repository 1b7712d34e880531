"""Analytic checks of frames, deformation gradients and the edge reconstruction."""

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import grid_sheet

from facebasis.errors import InputError
from facebasis.geometry.gradients import (deformation_gradients, edge_columns_to_rows, edge_operator, frames_cm,
                                 triangle_edges, triangle_frames)
from facebasis.geometry.poisson import EdgePoisson, choose_anchors


def random_rotation(seed):
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def test_rigid_motion_has_rotation_gradients(sheet):
    V, F = sheet
    R, t = random_rotation(1), np.array([0.3, -2.0, 5.0])
    Q = deformation_gradients(V, V @ R.T + t, F)
    assert np.allclose(Q, R, atol=1e-12)
    # rotations: orthogonal with determinant +1
    assert np.allclose(np.einsum("mij,mkj->mik", Q, Q), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(Q), 1.0)


def test_identity_motion_has_identity_gradients(sheet):
    V, F = sheet
    assert np.allclose(deformation_gradients(V, V + 7.0, F), np.eye(3), atol=1e-12)


def test_affine_map_gives_its_own_matrix(sheet):
    V, F = sheet
    M = np.array([[1.2, 0.3, 0.0], [-0.1, 0.9, 0.2], [0.05, 0.0, 1.4]])
    Q = deformation_gradients(V, V @ M.T + 1.0, F)
    # on the tangent plane the gradient must map like M exactly; the normal column follows the
    # Sumner-Popovic scaled normal, which equals M only for maps preserving it: compare edges
    E_rest = triangle_edges(V, F)
    E_def = triangle_edges(V @ M.T, F)
    assert np.allclose(np.einsum("mij,mej->mei", Q, E_rest), E_def, atol=1e-12)
    # for a similarity (rotation * scale) the whole 3x3 gradient equals the map
    s, R = 1.7, random_rotation(2)
    Q = deformation_gradients(V, s * V @ R.T, F)
    assert np.allclose(Q, s * R, atol=1e-10)


def test_frames_batch_matches_single(sheet):
    V, F = sheet
    batch = np.stack([V, 2 * V, V + 1])
    A = triangle_frames(batch, F)
    assert A.shape == (3, len(F), 3, 3)
    assert np.allclose(A[0], triangle_frames(V, F))
    assert np.allclose(A[1], 2 * A[0])  # frames scale like lengths (normal / sqrt|n|)
    assert np.allclose(frames_cm(V, F), np.moveaxis(triangle_frames(V, F), 0, -1))


def test_edge_operator_matches_edges(sheet):
    V, F = sheet
    E = edge_operator(F, len(V))
    assert np.allclose((E @ V).reshape(len(F), 3, 3), triangle_edges(V, F))
    L = (E.T @ E).toarray()
    assert np.allclose(L.sum(1), 0)  # constants are in the null space


def test_reconstruction_recovers_positions_from_exact_edges(sheet):
    V, F = sheet
    anchors = choose_anchors(F, len(V))
    rec = EdgePoisson(F, len(V), anchors)
    X = rec.solve(triangle_edges(V, F), V[anchors])
    assert np.allclose(X, V, atol=1e-12)
    # batched: several meshes and a translation fixed by the anchor values
    batch = np.stack([V, V * 2, V + 3])
    X = rec.solve(triangle_edges(batch, F), batch[:, anchors])
    assert np.allclose(X, batch, atol=1e-11)


def test_edge_columns_to_rows_is_consistent(sheet):
    V, F = sheet
    A = frames_cm(V[None], F)[:, :, :2]  # (1, 3, 2, m)
    rows = edge_columns_to_rows(A)  # (3, 3m)
    E = edge_operator(F, len(V))
    assert np.allclose(rows, (E @ V).T)


def test_anchors_cover_every_component():
    V1, F1 = grid_sheet(4, 4)
    V2, F2 = grid_sheet(3, 3, z=5.0)
    V = np.concatenate([V1, V2])
    F = np.concatenate([F1, F2 + len(V1)])
    anchors = choose_anchors(F, len(V))
    assert len(anchors) == 2 and anchors[0] < len(V1) <= anchors[1]
    motion = np.ones(len(V))
    motion[[3, 5]] = 0.0  # two still vertices in component 0, none in component 1
    motion[len(V1) + 4] = 0.5
    a = choose_anchors(F, len(V), motion, tolerance=1e-9)
    assert a.tolist() == [3, 5, len(V1) + 4]


def test_reconstruction_rejects_unanchored_component():
    V1, F1 = grid_sheet(4, 4)
    V2, F2 = grid_sheet(3, 3, z=5.0)
    F = np.concatenate([F1, F2 + len(V1)])
    with pytest.raises(InputError, match="expected an anchor in every connected component"):
        EdgePoisson(F, len(V1) + len(V2), [0])
    with pytest.raises(InputError, match=r"expected indices in \[0, 16\)"):
        EdgePoisson(F1, len(V1), [99])
    with pytest.raises(InputError, match="expected at least one anchor"):
        EdgePoisson(F1, len(V1), [])


def test_reconstruction_checks_target_shape(sheet):
    V, F = sheet
    rec = EdgePoisson(F, len(V), [0])
    with pytest.raises(InputError, match=r"edge_targets: expected shape \(\.\.\., 84, 3, d\)"):
        rec.solve(np.zeros((10, 3, 3)))


def test_reconstruction_extra_rows_enter_the_energy(sheet):
    """Extra rows (e.g. virtual edges): consistent targets keep the exact answer; a heavily weighted
    extra edge with another target pulls its two vertices to that vector."""
    import scipy.sparse as sp

    V, F = sheet
    anchors = choose_anchors(F, len(V))
    i, j = 3, 40
    X = sp.csr_matrix(([1.0, -1.0], ([0, 0], [j, i])), shape=(1, len(V)))
    rec = EdgePoisson(F, len(V), anchors, extra_rows=X, extra_weight=5.0)
    exact = rec.solve(triangle_edges(V, F), V[anchors], extra_targets=(V[j] - V[i])[None])
    assert np.allclose(exact, V, atol=1e-12)
    want = V[j] - V[i] + np.array([0.0, 0.0, 0.3])
    strong = EdgePoisson(F, len(V), anchors, extra_rows=X, extra_weight=1e8)
    out = strong.solve(triangle_edges(V, F), V[anchors], extra_targets=want[None])
    assert np.allclose(out[j] - out[i], want, atol=1e-6)
    with pytest.raises(InputError, match="expected targets for the extra"):
        strong.solve(triangle_edges(V, F), V[anchors])


def test_cotangent_laplacian_is_libigls_and_works_in_the_plane(sheet):
    """-K equals libigl's cotmatrix on a bumpy sheet; rows sum to 0; a planar mesh gives the same
    operator as the same mesh embedded in z = 0; the lumped masses sum to the surface area."""
    import igl

    from facebasis.geometry.laplacian import cotangent_laplacian, lumped_mass

    V, F = sheet
    K = cotangent_laplacian(V, F)
    assert abs(K + igl.cotmatrix(V, F)).max() < 1e-12
    assert np.abs(np.asarray(K.sum(axis=1))).max() < 1e-12
    flat = V.copy()
    flat[:, 2] = 0.0
    assert abs(cotangent_laplacian(flat[:, :2], F) - cotangent_laplacian(flat, F)).max() < 1e-12
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    assert abs(lumped_mass(V, F).sum() - area) < 1e-12
    clipped = cotangent_laplacian(V, F, clip_negative=True)
    assert (clipped - sp.diags(clipped.diagonal())).max() <= 0.0  # off-diagonal weights >= 0 after clipping
