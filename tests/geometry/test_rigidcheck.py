"""The similarity search on scans showing part of the template (facebasis.geometry.rigid, the
one-sided scan-to-template refinement) and the check of the found pose (facebasis.geometry.rigidcheck)."""

from __future__ import annotations

import numpy as np
import pytest

from facebasis.errors import InputError
from facebasis.geometry.rigid import RigidOptions, search_similarity, umeyama
from problems.bench_registration import random_rotation


def _angle(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def _faces():
    from facebasis.defaults.face import default_person, default_template

    T = default_template()
    return T.neutral.astype(float), T.faces.astype(np.int64), default_person().neutral.astype(float)


def _cut(V, F, lo, hi):
    """The triangles of ``F`` whose centroids lie in the box [lo, hi] (3,), on their own vertices."""
    cen = V[F].mean(1)
    Fk = F[((cen >= lo) & (cen <= hi)).all(1)]
    used = np.unique(Fk)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    return V[used], remap[Fk], used


def test_a_partial_cut_of_another_face_is_found_in_any_pose():
    """The centre of the other person's face (nose, eyes, mouth: about a third of the template's width,
    half its height) in random poses: the pose is within 3 degrees of the best similarity of the
    template onto that person, its scale within 5 %, and the check does not doubt it."""
    T_V, T_F, person = _faces()
    part, part_F, used = _cut(person, T_F, np.array([-3.5, -6.0, -1.0]), np.array([3.5, 4.0, 10.0]))
    assert len(part_F) < 0.4 * len(T_F)
    best0 = umeyama(T_V, person)
    rng = np.random.default_rng(3)
    for _ in range(4):
        R, t = random_rotation(rng), rng.uniform(-30, 30, 3)
        res = search_similarity(T_V, T_F, part @ R.T + t, part_F, RigidOptions(samples=800))
        assert _angle(res.similarity.rotation @ (R @ best0.rotation).T) < 3.0
        assert abs(res.similarity.scale / best0.scale - 1) < 0.05
        assert res.near_share > 0.9 and not res.ambiguous and not res.doubtful
        assert res.warning() is None


def _ellipsoid(axes):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3)
    return np.asarray(m.vertices) * axes, np.asarray(m.faces, dtype=np.int64)


def test_the_check_flags_the_ambiguous_pose_of_a_symmetric_shape():
    """An ellipsoid fits itself equally in four rotations (its symmetry group): the check finds a
    distinct pose with nearly the same residual and says so in a one-line warning."""
    V, F = _ellipsoid(np.array([3.0, 2.0, 1.2]))
    rng = np.random.default_rng(0)
    R = random_rotation(rng)
    res = search_similarity(V, F, V @ R.T + 5.0, F, RigidOptions(samples=600))
    assert res.ambiguous and res.doubtful
    assert res.runner_up_ratio < 1.1 and res.runner_up_degrees > 90
    w = res.warning()
    assert w.startswith("rigid pose doubtful: a pose") and "\n" not in w


def test_the_check_flags_a_scan_unlike_the_template():
    """A sphere is not a face: few of its points lie near the template in any pose."""
    T_V, T_F, _ = _faces()
    V, F = _ellipsoid(np.array([7.0, 7.0, 7.0]))
    res = search_similarity(T_V, T_F, V, F, RigidOptions(samples=600))
    assert res.near_share < 0.6 and res.doubtful
    assert "of the scan lies near the template" in res.warning()


def test_register_warns_in_one_line_when_the_pose_is_doubtful(tmp_path, capsys):
    """'facebasis register' of an ellipsoid onto a turned copy: the pose is ambiguous; the CLI says so
    in one line per scan and the scan's report carries the check."""
    import json

    from facebasis.cli import main
    from facebasis.geometry.meshio import write_mesh

    V, F = _ellipsoid(np.array([3.0, 2.0, 1.2]))
    scans = tmp_path / "scans"
    scans.mkdir()
    write_mesh(scans / "neutral.obj", V @ random_rotation(np.random.default_rng(2)).T, F)
    write_mesh(tmp_path / "template.obj", V, F)
    code = main(["register", str(scans), "--template", str(tmp_path / "template.obj"), "--out", str(tmp_path / "out")])
    assert code == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "warning" in ln]
    assert len(lines) == 1 and lines[0].startswith("neutral.obj: warning: rigid pose doubtful: a pose")
    chk = json.loads((tmp_path / "out" / "neutral.json").read_text())["rigid"]["check"]
    assert chk["ambiguous"] and chk["runner_up_ratio"] < 1.1


@pytest.mark.parametrize("kw, match", [
    (dict(perturbations=-1), r"rigid\.perturbations: expected an integer >= 0, found -1"),
    (dict(perturb_degrees=120.0), r"rigid\.perturb_degrees: expected a number in \[0, 90\], found 120\.0"),
    (dict(distinct_degrees="10"), r"rigid\.distinct_degrees: expected a number in \[0, 180\], found '10'"),
    (dict(ambiguous_ratio=0.5), r"rigid\.ambiguous_ratio: expected a number in \[1, inf\], found 0\.5"),
    (dict(near=0.0), r"rigid\.near: expected a fraction in \(0, 1\], found 0\.0"),
    (dict(min_near_share=2), r"rigid\.min_near_share: expected a fraction in \(0, 1\], found 2"),
])
def test_bad_check_options_are_one_line_errors(kw, match):
    with pytest.raises(InputError, match=match) as e:
        RigidOptions(**kw)
    assert "\n" not in str(e.value)
