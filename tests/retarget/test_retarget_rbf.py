"""Eq. 10-13: the multiquadric RBF correspondence and the edge-length scale."""

import numpy as np
import pytest

from facebasis.errors import InputError
from facebasis.retarget.rbf import edge_length_ratio, fit_rbf, mean_edge_length


def test_rbf_reproduces_training_pairs():
    rng = np.random.default_rng(0)
    S = rng.uniform(0, 100, (30, 2))
    T = rng.uniform(-5, 5, (30, 3))
    f = fit_rbf(S, T)
    np.testing.assert_allclose(f(S), T, atol=1e-8)


def test_rbf_reproduces_affine_maps_everywhere():
    rng = np.random.default_rng(1)
    S = rng.uniform(0, 100, (25, 2))
    A = np.array([[1.3, -0.4], [0.2, 0.9]])
    b = np.array([7.0, -3.0])
    f = fit_rbf(S, S @ A.T + b)
    X = rng.uniform(-50, 150, (500, 2))            # inside and far outside the training set
    np.testing.assert_allclose(f(X), X @ A.T + b, atol=1e-7)


def test_edge_length_ratio_is_the_scale_of_a_scaled_mesh():
    V = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    assert mean_edge_length(V, F) == pytest.approx((4 + np.sqrt(2)) / 5)
    assert edge_length_ratio(2.5 * V, F, V, F) == pytest.approx(2.5)


def test_rbf_errors():
    with pytest.raises(InputError, match="expected as many targets"):
        fit_rbf(np.zeros((5, 2)), np.zeros((4, 2)))
    with pytest.raises(InputError, match="at least 3 pairs"):
        fit_rbf(np.eye(2), np.eye(2))
    with pytest.raises(InputError, match="finite"):
        fit_rbf(np.full((5, 2), np.nan), np.zeros((5, 2)))


def test_coincident_sources_are_trained_once_on_the_mean_of_their_targets():
    """Closed lips put two landmarks on one pixel: the network maps that pixel to the mean of their
    targets instead of failing or blowing up."""
    from facebasis.retarget.rbf import fit_rbf

    S = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0], [5.0, 5.0], [5.0, 5.0]])
    T = S.copy()
    T[4], T[5] = [5.0, 4.0], [5.0, 6.0]
    rbf = fit_rbf(S, T)
    np.testing.assert_allclose(rbf(S[:4]), T[:4], atol=1e-9)
    np.testing.assert_allclose(rbf(S[4:5]), [[5.0, 5.0]], atol=1e-9)
