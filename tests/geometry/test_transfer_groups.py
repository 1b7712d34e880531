"""Deformation transfer solved for groups of shapes (bounded temporaries) equals one solve of all."""

import numpy as np
import pytest

from facebasis.defaults.face import default_template
from facebasis.geometry import transfer
from facebasis.geometry.rig import Rig
from facebasis.geometry.transfer import DeformationTransfer, rig_anchors, template_motion


def _rig_and_target():
    t = default_template()
    rng = np.random.default_rng(0)
    k = 11  # not a multiple of the group size
    deltas = np.concatenate([t.deltas] * (k // len(t.deltas) + 1))[:k] * rng.uniform(0.5, 1.5, (k, 1, 1))
    rig = Rig(t.neutral, t.faces, tuple(f"s{i}" for i in range(k)), deltas, source="test")
    target = t.neutral * np.array([1.1, 0.95, 1.0]) + 0.01 * rng.normal(size=t.neutral.shape)
    return rig, target


@pytest.mark.parametrize("step", [1, 3, 4])
def test_groups_of_shapes_give_the_single_solve(monkeypatch, step):
    rig, target = _rig_and_target()
    monkeypatch.setattr(transfer, "SHAPES_PER_SOLVE", 100)
    whole = DeformationTransfer(rig, target).transfer()
    monkeypatch.setattr(transfer, "SHAPES_PER_SOLVE", step)
    grouped = DeformationTransfer(rig, target).transfer()
    assert grouped.names == whole.names
    # each shape has its own columns; grouping may only change rounding
    assert np.allclose(grouped.deltas, whole.deltas, rtol=0, atol=1e-12 * np.abs(whole.deltas).max())
    names = ["s7", "s2", "s9"]
    part = DeformationTransfer(rig, target).transfer(names)
    assert part.names == tuple(names)
    assert np.allclose(part.deltas, whole.deltas[[7, 2, 9]], rtol=0, atol=1e-12 * np.abs(whole.deltas).max())


@pytest.mark.parametrize("step", [1, 4, 100])
def test_template_motion_by_groups_is_exact(monkeypatch, step):
    rig, _ = _rig_and_target()
    expected = np.sqrt((rig.deltas ** 2).sum(-1).max(0))
    monkeypatch.setattr(transfer, "SHAPES_PER_SOLVE", step)
    assert np.array_equal(template_motion(rig), expected)
    assert len(rig_anchors(rig)) > 0
