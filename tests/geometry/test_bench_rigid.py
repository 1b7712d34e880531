"""problems/bench_rigid.py's measures on tiny data: the pose errors against a known similarity and the
trimesh ICP baseline's similarity."""

from __future__ import annotations

import numpy as np
import pytest

from facebasis.geometry.rigid import Similarity, _rotation_from_vector
from problems.bench_rigid import pose_errors, trimesh_icp


def test_pose_errors_measure_rotation_and_translation_at_the_face_centre():
    rng = np.random.default_rng(0)
    T = rng.normal(size=(200, 3)) * [3.0, 4.0, 2.0]
    best = Similarity(1.1, _rotation_from_vector(np.array([0.1, -0.2, 0.3])), np.array([1.0, 2.0, 3.0]))
    truth = best.apply(T)
    assert pose_errors(best, best, T, truth) == pytest.approx((0.0, 0.0, 0.0), abs=1e-5)
    c = T.mean(0)  # 10 degrees about the face centre as placed: no translation error there
    turn = _rotation_from_vector(np.radians(10.0) * np.array([0.0, 1.0, 0.0]))
    p = best.apply(c)
    off = best.then(Similarity(1.0, turn, p - turn @ p + np.array([0.0, 0.0, 0.5])))
    rot, tr, med = pose_errors(off, best, T, truth)
    assert rot == pytest.approx(10.0, abs=1e-3) and tr == pytest.approx(0.5, abs=1e-6) and med > 0.5


def test_trimesh_icp_baseline_recovers_a_small_similarity():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(3000, 3)) * [3.0, 4.0, 2.0]
    true = Similarity(1.2, _rotation_from_vector(np.array([0.05, 0.0, -0.05])), np.array([0.3, -0.2, 0.1]))
    sim = trimesh_icp(P, true.apply(P), np.random.default_rng(0))
    assert sim.scale == pytest.approx(1.2, rel=0.02)
    assert np.abs(sim.rotation - true.rotation).max() < 0.02
