"""The similarity search on scans showing part of the template (facebasis.geometry.rigid, the
one-sided scan-to-template refinement) and the check of the found pose (facebasis.geometry.rigidcheck)."""

from __future__ import annotations

import numpy as np
import pytest

from facebasis.errors import InputError
from facebasis.geometry.rigid import RigidOptions, search_similarity, umeyama
from facebasis.geometry.rigidcheck import rotation_angle
from problems.bench_registration import random_rotation


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


#: cuts of the other person's face (boxes of triangle centroids, the built-in face's units: 14.6 wide, 18 high)
CUTS = {"centre": ((-3.5, -6.0, -1.0), (3.5, 4.0, 10.0)),  # nose, eyes, mouth: a third of the template
        "left half": ((-9.0, -10.0, -1.0), (0.0, 10.0, 10.0)),
        "front": ((-9.0, -10.0, 2.0), (9.0, 10.0, 10.0)),
        "eyes and nose": ((-6.0, -3.0, -1.0), (6.0, 5.0, 10.0))}


def _search_cut(box, seed):
    T_V, T_F, person = _faces()
    part, part_F, _ = _cut(person, T_F, np.array(box[0]), np.array(box[1]))
    rng = np.random.default_rng(seed)
    R, t = random_rotation(rng), rng.uniform(-30, 30, 3)
    res = search_similarity(T_V, T_F, part @ R.T + t, part_F, RigidOptions(samples=800))
    best0 = umeyama(T_V, person)  # the best similarity of the template onto the whole person
    return res, rotation_angle(res.similarity.rotation @ (R @ best0.rotation).T), res.similarity.scale / best0.scale


@pytest.mark.parametrize("name", list(CUTS))
def test_a_partial_cut_of_another_face_is_found(name):
    """Cuts of the other person's face (a third to nine tenths of it) in a random pose: the pose is within
    3 degrees of the best similarity of the template onto that person, its scale within 7 %, and the
    check does not doubt it. (The candidates come from principal frames, so the cut's pose does not
    matter: different cuts are different cases, different poses of one cut are not.)"""
    res, angle, scale = _search_cut(CUTS[name], seed=3)
    assert angle < 3.0 and abs(scale - 1) < 0.07
    assert res.near_share > 0.9 and not res.ambiguous and not res.doubtful
    assert res.warning() is None


@pytest.mark.xfail(strict=True, reason="known limit (rigidcheck docstring): a half face is laid upside down "
                   "(179.6 degrees off; the one-sided residual prefers it) and the check cannot see a missed basin")
def test_the_lower_half_of_a_face_is_found():
    res, angle, _ = _search_cut(((-9.0, -10.0, -1.0), (9.0, 0.0, 10.0)), seed=3)
    assert angle < 3.0 or res.doubtful


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
    (dict(perturbations=50), r"rigid\.perturbations: expected an integer in \[0, 6\], found 50"),
    (dict(perturb_degrees=120.0), r"rigid\.perturb_degrees: expected a number in \(0, 90\], found 120\.0"),
    (dict(perturb_degrees=0), r"rigid\.perturb_degrees: expected a number in \(0, 90\], found 0"),
    (dict(distinct_degrees="10"), r"rigid\.distinct_degrees: expected a number in \(0, 90\], found '10'"),
    (dict(distinct_degrees=0.0), r"rigid\.distinct_degrees: expected a number in \(0, 90\], found 0\.0"),
    (dict(distinct_degrees=180), r"rigid\.distinct_degrees: expected a number in \(0, 90\], found 180"),
    (dict(ambiguous_ratio=0.5), r"rigid\.ambiguous_ratio: expected a number in \[1, inf\], found 0\.5"),
    (dict(near=0.0), r"rigid\.near: expected a fraction in \(0, 1\], found 0\.0"),
    (dict(min_near_share=2), r"rigid\.min_near_share: expected a fraction in \(0, 1\], found 2"),
])
def test_bad_check_options_are_one_line_errors(kw, match):
    with pytest.raises(InputError, match=match) as e:
        RigidOptions(**kw)
    assert "\n" not in str(e.value)
