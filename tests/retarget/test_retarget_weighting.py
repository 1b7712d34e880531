"""The pixel noise model's weighting of one frame's weight solve (:meth:`FrameSolver._weights`,
``pixel_scale``): the data term times ``(s / s_ref)^2``. At s_ref = s it is the rig-unit problem; at
s_ref = s / 2 the data term is 4 times heavier, which is the rig-unit problem with the prior (smooth,
ridge, and the sparse part ``sparsity * ridge``) divided by 4 -- the minimiser of ``4 f(x) + P(x)`` is
that of ``f(x) + P(x) / 4``."""

from dataclasses import replace

import numpy as np

from facebasis.retarget.framefit import FrameFit, FrameSolver
from facebasis.retarget.pose import PI, rotation_from_vector


def _solver(seed=0, L=20, k=6):
    rng = np.random.default_rng(seed)
    return FrameSolver(v0=rng.normal(scale=3.0, size=(L, 3)), D=rng.normal(scale=0.5, size=(L, 3, k)),
                       pairs=np.zeros((0, 2), np.int64), smooth=0.05, ridge=0.02, sparsity=3.0,
                       contour=np.zeros(0, np.int64), contour_slide=1.0, alternations=2, tol=1e-4)


def test_pixel_scale_weights_the_data_term_by_s_over_s_ref_squared():
    solver = _solver()
    rng = np.random.default_rng(1)
    L, k = solver.v0.shape[0], solver.n_shapes
    s, R, t = 6.0, rotation_from_vector([0.1, -0.2, 0.05]), np.array([200.0, 150.0])
    x_true = rng.uniform(0, 0.8, k)
    q = solver.landmarks3d(x_true)
    p = s * (q @ R.T @ PI.T) + t + rng.normal(scale=1.5, size=(L, 2))
    vis, x_prev = np.ones(L, bool), rng.uniform(0, 0.5, k)

    def solve(sv):
        return sv._weights(p, vis, s, R, t, x_prev, x_prev.copy())[0]

    plain = solve(solver)
    assert np.allclose(solve(replace(solver, pixel_scale=s)), plain, atol=1e-9)
    heavy = solve(replace(solver, pixel_scale=s / 2))
    assert np.allclose(heavy, solve(replace(solver, smooth=solver.smooth / 4, ridge=solver.ridge / 4)), atol=1e-7)
    assert np.abs(heavy - plain).max() > 1e-3                  # the weighting changes the answer


def test_a_frame_with_too_few_landmarks_keeps_the_previous_fit_and_its_flat_landmarks():
    solver = _solver()
    p = np.random.default_rng(2).normal(size=(solver.v0.shape[0], 2))
    state = (np.zeros(solver.n_shapes), 5.0, np.eye(3), np.zeros(2))
    fit = solver.solve_frame(p, np.zeros(len(p), bool), state)
    assert isinstance(fit, FrameFit) and np.isnan(fit.rms) and fit.flat is not None and np.allclose(fit.flat, p)
