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


def test_reconstruction_extra_operator_enters_the_energy(sheet):
    """Extra rows (e.g. virtual edges): consistent targets keep the exact answer; a heavily weighted
    extra edge with another target pulls its two vertices to that vector."""
    import scipy.sparse as sp

    V, F = sheet
    anchors = choose_anchors(F, len(V))
    i, j = 3, 40
    X = sp.csr_matrix(([1.0, -1.0], ([0, 0], [j, i])), shape=(1, len(V)))
    rec = EdgePoisson(F, len(V), anchors, extra_operator=X, extra_weight=5.0)
    exact = rec.solve(triangle_edges(V, F), V[anchors], extra_targets=(V[j] - V[i])[None])
    assert np.allclose(exact, V, atol=1e-12)
    want = V[j] - V[i] + np.array([0.0, 0.0, 0.3])
    strong = EdgePoisson(F, len(V), anchors, extra_operator=X, extra_weight=1e8)
    out = strong.solve(triangle_edges(V, F), V[anchors], extra_targets=want[None])
    assert np.allclose(out[j] - out[i], want, atol=1e-6)
    with pytest.raises(InputError, match="expected targets for the extra"):
        strong.solve(triangle_edges(V, F), V[anchors])


def test_reconstruction_layouts_agree():
    """Every entry point of EdgePoisson solves the same problem: batched and one-at-a-time
    :meth:`solve`, one coordinate at a time, and the frame-row fast path all match a dense
    least-squares reference to 1e-10, on a two-component mesh with triangle weights, several
    anchors and extra rows."""
    from facebasis.geometry.gradients import frame_edges_to_triangle_edges

    V1, F1 = grid_sheet(5, 4)
    V2, F2 = grid_sheet(3, 4, z=2.0)
    V = np.concatenate([V1, V2])
    F = np.concatenate([F1, F2 + len(V1)])
    n, m = len(V), len(F)
    rng = np.random.default_rng(7)
    anchors = np.array([0, 7, len(V1) + 2])
    c_t = rng.uniform(0.5, 2.0, m)
    pairs = np.array([[1, 15], [4, len(V1) + 5], [9, 18]])  # the middle one links the components
    r = len(pairs)
    X = sp.csr_matrix((np.tile([1.0, -1.0], r), (np.repeat(np.arange(r), 2), pairs[:, ::-1].ravel())), shape=(r, n))
    w = 2.5
    rec = EdgePoisson(F, n, anchors, triangle_weights=c_t, extra_operator=X, extra_weight=w)
    assert rec.extra_rows is rec.extra_operator and rec.n_extra == r

    k = 4
    Y = rng.standard_normal((k, 3, 2, m))  # frame edge columns (shape, coordinate, column, triangle)
    T = frame_edges_to_triangle_edges(np.moveaxis(Y, -1, -3))  # (k, m, 3 edges, 3 coords)
    A = rng.standard_normal((k, len(anchors), 3))
    XT = rng.standard_normal((k, r, 3))

    # dense reference: weighted least squares over the free vertices
    E = edge_operator(F, n).toarray()
    M = np.vstack([np.sqrt(np.repeat(c_t, 3))[:, None] * E, np.sqrt(w) * X.toarray()])
    free = np.setdiff1d(np.arange(n), anchors)
    ref = np.empty((k, n, 3))
    for i in range(k):
        rhs = np.vstack([np.sqrt(np.repeat(c_t, 3))[:, None] * T[i].reshape(3 * m, 3), np.sqrt(w) * XT[i]])
        rhs = rhs - M[:, anchors] @ A[i]
        ref[i, anchors] = A[i]
        ref[i, free] = np.linalg.lstsq(M[:, free], rhs, rcond=None)[0]

    batched = rec.solve(T, A, extra_targets=XT)
    assert batched.shape == (k, n, 3)
    assert np.abs(batched - ref).max() < 1e-10
    single = np.stack([rec.solve(T[i], A[i], extra_targets=XT[i]) for i in range(k)])
    assert np.abs(single - ref).max() < 1e-10
    per_coord = np.concatenate([rec.solve(T[..., x:x + 1], A[..., x:x + 1], extra_targets=XT[..., x:x + 1])
                                for x in range(3)], axis=-1)
    assert np.abs(per_coord - ref).max() < 1e-10
    # fast path: one problem per column, column 3 i + x = coordinate x of shape i
    rows = np.ascontiguousarray(Y.reshape(3 * k, 2 * m).T)
    a_rows = np.ascontiguousarray(np.moveaxis(A, 2, 1).reshape(3 * k, -1).T)
    x_rows = np.ascontiguousarray(np.moveaxis(XT, 2, 1).reshape(3 * k, -1).T)
    fast = rec.solve_frame_rows(rows, a_rows, x_rows)
    assert fast.shape == (n, 3 * k)
    assert np.abs(np.moveaxis(fast.T.reshape(k, 3, n), 1, 2) - ref).max() < 1e-10
    # without anchor values the anchors are held at 0, in every layout
    zero = rec.solve(T, extra_targets=XT)
    assert np.abs(zero[:, anchors]).max() == 0.0
    assert np.abs(np.moveaxis(rec.solve_frame_rows(rows, None, x_rows).T.reshape(k, 3, n), 1, 2) - zero).max() < 1e-10
    # shapes are checked, and the extra targets are required
    with pytest.raises(InputError, match=r"frame_rows: expected shape"):
        rec.solve_frame_rows(rows[1:], a_rows, x_rows)
    with pytest.raises(InputError, match=r"anchor_values: expected shape \(3, 12\)"):
        rec.solve_frame_rows(rows, a_rows[1:], x_rows)
    with pytest.raises(InputError, match=r"extra_targets: expected shape \(3, 12\)"):
        rec.solve_frame_rows(rows, a_rows, x_rows[:, 1:])
    with pytest.raises(InputError, match=r"extra_targets: expected shape \(\.\.\., 3, 3\)"):
        rec.solve(T, A, extra_targets=XT[:, 1:])
    with pytest.raises(InputError, match="expected targets for the extra"):
        rec.solve_frame_rows(rows, a_rows)


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
