"""Scan registration: rigid + non-rigid ICP onto scans of another topology (tiny meshes built here)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from facebasis.errors import InputError, MeshError
from facebasis.geometry.nricp import closest_point_on_triangles
from facebasis.geometry.registerfiles import register_files
from facebasis.geometry.registration import Registration, register_scan
from facebasis.geometry.rigid import Similarity
from problems.bench_registration import random_rotation


def icosphere(subdiv: int = 3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdiv)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def uv_sphere(count=(40, 40)):
    import trimesh

    m = trimesh.creation.uv_sphere(count=count)
    m.merge_vertices()
    m.update_faces(m.nondegenerate_faces())
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def bumpy(V):
    """A smooth, not symmetric deformation of a unit sphere (so its pose is well defined)."""
    x, y, z = V.T
    r = 1.0 + 0.25 * np.exp(-((x - 0.8) ** 2 + y ** 2 + (z - 0.6) ** 2) * 4) + 0.1 * x * y + 0.08 * z
    return V * r[:, None]


def test_closest_point_on_triangles_matches_brute_force():
    rng = np.random.default_rng(0)
    A, B, C = (rng.standard_normal((150, 3)) for _ in range(3))
    P = 2 * rng.standard_normal((150, 3))
    Q = closest_point_on_triangles(P, A, B, C)
    # brute force over a fine barycentric grid
    u, v = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    G = A[:, None] + u[None, :, None] * (B - A)[:, None] + v[None, :, None] * (C - A)[:, None]
    best = np.linalg.norm(G - P[:, None], axis=2).min(1)
    got = np.linalg.norm(Q - P, axis=1)
    assert np.all(got <= best + 1e-9) and np.all(got >= best - 0.02)


def test_rigid_motion_of_itself_returns_itself():
    V, F = icosphere(3)
    V = bumpy(V)
    rng = np.random.default_rng(1)
    sim = Similarity(1.3, random_rotation(rng), rng.uniform(-2, 2, 3))
    S = sim.apply(V)
    perm = rng.permutation(len(S))
    inv = np.argsort(perm)
    res = register_scan(V, F, S[perm], inv[F])
    err = np.linalg.norm(res.vertices - S, axis=1)
    # the template lies on the scan exactly, so the only error is the solver's: 1e-3 of the size
    assert err.max() < 2e-3 * 1.3, err.max()
    assert abs(res.similarity.scale - 1.3) < 1e-3
    assert res.no_surface.sum() == 0


def test_remeshed_sphere_registers_onto_the_surface():
    """Icosphere template (642 vertices) onto a bumpy UV sphere (another topology, other vertex
    spacing), moved and scaled. Bound: every vertex within 1% of the radius of the scan surface (the
    scan's own chords deviate from the smooth surface by ~0.3%), and vertex positions within 5% of
    the radius of where the same bump deformation puts them (tangential freedom on a smooth
    surface is only limited by the stiffness term)."""
    V, F = icosphere(3)
    S, G = uv_sphere((48, 48))
    rng = np.random.default_rng(2)
    sim = Similarity(2.0, random_rotation(rng), np.array([5.0, -1.0, 3.0]))
    res = register_scan(bumpy(V), F, sim.apply(bumpy(S)), G)
    # distance to the true smooth surface, measured in the template frame
    back = sim.inverse().apply(res.vertices)
    truth = bumpy(V)
    assert np.percentile(res.distance, 95) / 2.0 < 0.01
    assert np.median(np.linalg.norm(back - truth, axis=1)) < 0.05


def plane(n=25, size=1.0):
    x, y = np.meshgrid(np.linspace(-size, size, n), np.linspace(-size, size, n))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return V, F


def test_hole_leaves_a_smooth_surface_not_the_rim():
    """A plane with a 0.27 high Gaussian bump registered onto a denser plane with a 0.30 bump and a
    hole (radius 0.25) on the bump's flank. The vertices over the hole get no data term and follow
    the stiffness term: they stay on a smooth surface between the two bumps (within 0.03 = the
    bumps' difference of the true surface) and are not dragged to the hole's rim, which is at least
    0.1 (one template edge) away from each of them: they stay within half an edge (0.05) of their
    place in the plane."""
    V, F = plane(21)
    S, G = plane(41)

    def bump(P, a):
        return np.c_[P[:, :2], a * np.exp(-((P[:, 0] - 0.1) ** 2 + P[:, 1] ** 2) * 3)]

    Sb = bump(S, 0.3)
    hole_c = np.array([0.35, 0.0])
    G = G[np.linalg.norm(Sb[G].mean(1)[:, :2] - hole_c, axis=1) > 0.25]
    res = register_scan(bump(V, 0.27), F, Sb, G)
    inside = np.linalg.norm(V[:, :2] - hole_c, axis=1) < 0.15
    assert inside.sum() >= 3 and res.no_surface[inside].all()
    truth = bump(V, 0.3)
    assert np.abs(res.vertices[inside, 2] - truth[inside, 2]).max() < 0.03
    assert np.linalg.norm(res.vertices[inside, :2] - V[inside, :2], axis=1).max() < 0.05
    # elsewhere the vertices lie on the scanned bump (a plane leaves them free to slide along it)
    outside = np.linalg.norm(V[:, :2] - hole_c, axis=1) > 0.35
    on = np.abs(res.vertices[outside, 2] - bump(res.vertices[outside], 0.3)[:, 2])
    assert np.median(on) < 2e-3 and on.max() < 0.01


def test_landmarks_give_the_pose_and_are_reported():
    V, F = icosphere(3)
    V = bumpy(V)
    rng = np.random.default_rng(4)
    sim = Similarity(1.0, random_rotation(rng), np.array([0.5, 0.0, 0.0]))
    lm = np.array([0, 50, 100, 200, 400, 600])
    res = register_scan(V, F, sim.apply(V), F, template_landmarks=lm, scan_landmarks=sim.apply(V[lm]))
    assert res.landmark_error is not None and res.landmark_error.max() < 5e-3
    res2 = register_scan(V, F, sim.apply(V), F, template_landmarks=lm, scan_landmarks=lm)  # scan indices
    assert res2.landmark_error.max() < 5e-3


def test_scan_without_faces_is_refused():
    V, F = icosphere(2)
    with pytest.raises(MeshError, match="no faces"):
        register_scan(V, F, V, np.zeros((0, 3), np.int64))


def test_landmark_lists_of_different_lengths_are_refused():
    V, F = icosphere(2)
    with pytest.raises(InputError, match="same number of landmarks.*found 3 and 4"):
        register_scan(V, F, V, F, template_landmarks=[0, 1, 2, 3], scan_landmarks=[0, 1, 2])


def test_landmark_indices_out_of_range_are_refused():
    V, F = icosphere(2)
    with pytest.raises(InputError, match=r"vertex indices in \[0, 162\), found 999"):
        register_scan(V, F, V, F, template_landmarks=[0, 1, 999], scan_landmarks=[0, 1, 2])
    with pytest.raises(InputError, match=r"scan landmarks: expected vertex indices in \[0, 162\), found 500"):
        register_scan(V, F, V, F, template_landmarks=[0, 1, 2], scan_landmarks=[0, 1, 500])


def test_scan_in_other_units_is_refused_with_a_scale_factor():
    V, F = icosphere(2)
    with pytest.raises(InputError, match=r"10 times as large.*scale the scan by about 0.1"):
        register_scan(V, F, 10 * V, F)
    with pytest.raises(InputError, match=r"scale the scan by about 1000"):
        register_scan(V, F, V / 1000, F)


def _write_obj(path, V, F):
    from facebasis.geometry.meshio import write_mesh

    write_mesh(path, V, F)


def test_bad_inputs_leave_no_output_folder(tmp_path):
    V, F = icosphere(2)
    _write_obj(tmp_path / "t.obj", V, F)
    _write_obj(tmp_path / "s.obj", 100 * V, F)
    out = tmp_path / "out"
    with pytest.raises(InputError, match="units differ"):
        register_files(tmp_path / "s.obj", tmp_path / "t.obj", out)
    (tmp_path / "lm_s.json").write_text(json.dumps([0, 1, 2]))
    (tmp_path / "lm_t.json").write_text(json.dumps([0, 1, 2, 3]))
    with pytest.raises(InputError, match="same number"):
        register_files(tmp_path / "t.obj", tmp_path / "t.obj", out, (tmp_path / "lm_s.json", tmp_path / "lm_t.json"))
    assert not out.exists() and not list(tmp_path.glob(".out*"))


def test_cli_end_to_end_on_a_folder(tmp_path, capsys):
    from facebasis.cli import main
    from facebasis.geometry.meshio import read_mesh

    V, F = icosphere(3)
    T = bumpy(V)
    S, G = uv_sphere((30, 30))
    rng = np.random.default_rng(5)
    sim = Similarity(1.0, random_rotation(rng), np.array([1.0, 2.0, 0.0]))
    scans = tmp_path / "scans"
    scans.mkdir()
    _write_obj(scans / "neutral.obj", sim.apply(bumpy(S)), G)
    stretched = bumpy(S) * [1.1, 1.0, 0.95]
    _write_obj(scans / "smile.obj", sim.apply(stretched), G)
    _write_obj(tmp_path / "template.obj", T, F)
    out = tmp_path / "out"
    code = main(["register", str(scans), "--template", str(tmp_path / "template.obj"), "--out", str(out)])
    assert code == 0
    assert "registered 2 scan(s)" in capsys.readouterr().out
    for stem in ("neutral", "smile"):
        Vr, Fr = read_mesh(out / f"{stem}.obj")
        assert Vr.shape == T.shape and np.array_equal(Fr, F)
        rep = json.loads((out / f"{stem}.json").read_text())
        assert set(rep) >= {"residual", "iterations", "landmark_error", "no_surface_vertices"}
        assert rep["residual"]["p95"] < 0.02
        chk = rep["rigid"]["check"]  # the rigid stage's pose check (facebasis.geometry.rigidcheck)
        assert 0.6 < chk["near_share"] <= 1.0 and chk["scan_to_template_rms"] >= 0.0
    # the bumps decide the neutral's pose; the smile's 10 % stretch outweighs them: a pose 56 degrees away
    # fits within 3 % as well, and the check says so (ratio 1.02, near share 0.82)
    assert not json.loads((out / "neutral.json").read_text())["rigid"]["check"]["doubtful"]
    smile = json.loads((out / "smile.json").read_text())["rigid"]["check"]
    assert smile["doubtful"] and smile["ambiguous"] and smile["runner_up_ratio"] < 1.1
    assert json.loads((out / "smile.json").read_text())["started_from"] == "neutral.obj"


def test_cli_reports_a_missing_neutral(tmp_path, capsys):
    from facebasis.cli import main

    V, F = icosphere(2)
    scans = tmp_path / "scans"
    scans.mkdir()
    _write_obj(scans / "a.obj", V, F)
    _write_obj(scans / "b.obj", V, F)
    _write_obj(tmp_path / "t.obj", V, F)
    code = main(["register", str(scans), "--template", str(tmp_path / "t.obj"), "--out", str(tmp_path / "o")])
    assert code == 2 and "neutral" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_plane_targets_project_onto_the_tangent_plane_and_skip_far_points():
    """A flat scan (z = 0): a point above it gets its foot on the plane as target (not the nearest
    scan vertex), a point farther than the bound gets no partner (flagged, target = itself)."""
    from facebasis.geometry.nricp import ScanSurface

    S, G = plane(11)  # spacing 0.2
    surf = ScanSurface(S, G)
    P = np.array([[0.05, 0.03, 0.1], [0.33, -0.47, -0.05], [0.0, 0.0, 5.0]])
    U, n, dist, flag = surf.nearest_planes(P, max_distance=1.0)
    assert np.allclose(U[:2], np.c_[P[:2, :2], np.zeros(2)], atol=1e-12)
    assert np.allclose(np.abs(n[:2, 2]), 1.0)
    assert not flag[:2].any() and flag[2] and np.array_equal(U[2], P[2]) and np.isinf(dist[2])
    V_near, _, _, _ = surf.nearest_planes(P[:2], plane=False)
    assert np.all(np.isin(V_near.round(9), S.round(9)).all(1))  # point-to-point: scan vertices
    # a rim point: the plane's border
    assert surf.nearest_planes(np.array([[1.0, 0.0, 0.01]]))[3][0]


def test_moved_surface_equals_a_fresh_one():
    from facebasis.geometry.nricp import ScanSurface

    V, F = icosphere(2)
    V = bumpy(V)
    sim = Similarity(0.7, random_rotation(np.random.default_rng(7)), np.array([1.0, 2.0, 3.0]))
    a, b = ScanSurface(V, F).moved(sim.apply(V)), ScanSurface(sim.apply(V), F)
    P = np.random.default_rng(8).standard_normal((50, 3))
    for x, y in zip(a.closest(P), b.closest(P)):
        assert np.allclose(x, y)
    assert np.allclose(a.vertex_normals, b.vertex_normals)


def test_local_similarities_recover_a_uniform_scale():
    """Local rotations of a mesh turned and grown by 1.5: R_i = rotation (ARAP); with local scale,
    1.5 x rotation (as similar as possible)."""
    from facebasis.geometry.nricp import NonRigidICP

    V, F = icosphere(2)
    Rot = random_rotation(np.random.default_rng(9))
    X = 1.5 * V @ Rot.T
    nr = NonRigidICP(F, len(V))
    assert np.allclose(nr.local_rotations(V, X), Rot, atol=1e-9)
    assert np.allclose(nr.local_rotations(V, X, scale=True), 1.5 * Rot, atol=1e-9)


def test_expression_from_the_registered_neutral_keeps_correspondence():
    """A person's neutral (the template itself, moved) and an "expression": a smooth local bulge
    of 0.3 x the radius, both as shuffled scans in their own poses. The expression registered from
    the registered neutral lands on its scan (95% of the vertices within 1% of the radius) and keeps
    vertex meaning: every vertex within one edge of its true place, i.e. inside its own one-ring
    (measured: 0.078, about half an edge; the rotation-aware stiffness term lets vertices slide a
    little toward the bulge rather than stretch, and point-to-plane targets do not hold them
    tangentially; scan vertices as point-to-point targets would, but only because this scan shares
    the template's vertices). The shape has a "nose" (a sharp
    bump) so that its pose is unambiguous, as a face's is (on the mildly bumpy sphere alone the
    orientation search can settle in a turned pose)."""
    V, F = icosphere(3)
    T = bumpy(V) + 0.4 * np.exp(-np.sum((V - [1.0, 0.0, 0.0]) ** 2, 1) / 0.05)[:, None] * V
    c = np.array([0.0, 0.0, 1.0])
    E = T + 0.3 * np.exp(-np.sum((V - c) ** 2, 1) / 0.3)[:, None] * V
    rng = np.random.default_rng(10)
    reg = Registration(T, F)
    out = []
    for shape in (T, E):
        sim = Similarity(1.0, random_rotation(rng), rng.uniform(-1, 1, 3))
        perm = rng.permutation(len(T))
        res = reg.register(sim.apply(shape)[perm], np.argsort(perm)[F], start=out[0][0] if out else None)
        out.append((res.vertices, sim.apply(shape), res))
    X, truth, res = out[1]
    err = np.linalg.norm(X - truth, axis=1)
    edge = np.median(np.linalg.norm(T[F[:, 1]] - T[F[:, 0]], axis=1))
    assert err.max() < edge, (err.max(), edge)
    assert np.percentile(res.distance, 95) < 0.01


def test_point_to_plane_refinement_converges_from_far_off():
    """From a pose 40 degrees, 0.3 and 10% in scale off, the trimmed point-to-plane refinement lands
    on the exact pose (the surface is the template's own, so the answer is exact) within its
    default number of steps; 15 steps (the former count) leave it 0.08 off."""
    from facebasis.geometry.nricp import ScanSurface
    from facebasis.geometry.rigid import RigidOptions, _rotation_from_vector, refine_point_to_plane

    V, F = icosphere(3)
    V = bumpy(V) + 0.4 * np.exp(-np.sum((V - [1.0, 0.0, 0.0]) ** 2, 1) / 0.05)[:, None] * V
    rng = np.random.default_rng(11)
    true = Similarity(1.2, random_rotation(rng), np.array([0.3, -0.2, 0.1]))
    surface = ScanSurface(true.apply(V), F)
    off = Similarity(1.1, _rotation_from_vector(np.radians(40.0) * np.array([0.6, 0.8, 0.0])),
                     np.array([0.3, 0.0, 0.0]))
    start = off.then(true)
    sim, _ = refine_point_to_plane(V, surface.closest, start, RigidOptions().plane_iterations)
    assert np.abs(sim.apply(V) - true.apply(V)).max() < 1e-6
    assert abs(sim.scale - 1.2) < 1e-6
    short, _ = refine_point_to_plane(V, surface.closest, start, 15)
    assert np.abs(short.apply(V) - true.apply(V)).max() > 1e-3


def test_motion_visibility_separates_motion_along_the_surface_from_motion_off_it():
    """The benchmark's diagnosis of expression errors: a closest-point term sees only the part of a
    motion that leaves the surface. A sphere turned about its centre (all motion along the surface)
    is invisible; the same sphere inflated by 10% (all motion off the surface) is fully visible."""
    from problems.bench_registration import motion_visibility

    V, F = icosphere(3)
    S, G = uv_sphere((60, 60))
    a = np.radians(20)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    R, t = random_rotation(np.random.default_rng(3)), np.array([1.0, -2.0, 0.5])
    face = np.arange(len(V))
    turned = motion_visibility(V, V @ Rz.T, S @ Rz.T @ R.T + t, G, R, t, face)
    assert turned["motion_p95"] > 0.3
    assert turned["visible_p95"] < 0.05 * turned["motion_p95"]
    inflated = motion_visibility(V, 1.1 * V, 1.1 * S @ R.T + t, G, R, t, face)
    assert abs(inflated["visible_p95"] - inflated["motion_p95"]) < 0.2 * inflated["motion_p95"]
