"""Fold-free cartoon warp and head motion apart from expression (issue 23, items 1-2).

Every check of orientation is exact: the signed area of every triangle of the warp mesh (band
included) against its signed area on the rest cartoon.
"""

import numpy as np
import pytest

from facebasis.capture.facemesh import build_face_mesh
from facebasis.defaults.cartoon import default_cartoon
from facebasis.defaults.face import default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.retarget.drive3d import MeshDriver
from facebasis.retarget.foldfree import FoldFreeMap, project_jacobians, smallest_singular_signed
from facebasis.retarget.headmotion import fit_head_motion, parse_head_mode
from facebasis.retarget.warp2d import CartoonAnimator, animate_cartoon


def _signed(V, F):
    a, b, c = V[..., F[:, 0], :], V[..., F[:, 1], :], V[..., F[:, 2], :]
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _flipped(anim, drive):
    """(T,) triangles of the whole warp mesh whose orientation differs from the rest cartoon's."""
    T = len(drive.still)
    X = np.concatenate([drive.still, np.broadcast_to(anim.ring, (T,) + anim.ring.shape)], 1)
    a0 = _signed(anim.warp_rest, anim.warp_faces)
    return np.count_nonzero(_signed(X, anim.warp_faces) * np.sign(a0) <= 0, axis=1)


def _similar(P, s, deg, t, about):
    th = np.deg2rad(deg)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return (P - about) @ R.T * s + about + t


@pytest.fixture(scope="module")
def toon():
    face = default_cartoon(256)
    cap0 = 1.6 * face.landmarks + [20.0, 10.0]              # the capture: another size and place
    mesh = build_face_mesh(cap0)
    return face, cap0, mesh


def _lip_push(mesh, T=24, depth=22.0, seed=0, lower=np.r_[56:59, 65:68]):
    """Captured vertices (T, N, 2): the lower lip pushed up through the upper one (``depth`` px;
    the inner lips are 12.8 px apart at rest), plus seeded jitter of every vertex."""
    V0 = mesh.vertices
    rng = np.random.default_rng(seed)
    lift = np.linspace(0.0, depth, T)
    V = np.repeat(V0[None], T, axis=0)
    V[:, lower, 1] -= lift[:, None]
    V += rng.normal(0.0, 1.5, V.shape)
    V[0] = V0
    return V


@pytest.mark.parametrize("interior", ["smooth", "tracked"])
def test_lower_lip_through_the_upper_never_folds(toon, interior):
    face, cap0, mesh = toon
    V = _lip_push(mesh)
    anim = CartoonAnimator(face.image, face.landmarks, cap0, mesh.vertices, mesh.faces, interior=interior)
    # the paper's eq. 12 target folds (the test would be empty otherwise)
    paper = anim.mesh(V)
    a0 = _signed(anim.rest, anim.faces)
    assert np.count_nonzero(_signed(paper, anim.faces) * np.sign(a0) <= 0, axis=1).max() > 0
    drive = anim.drive(V, V[:, :68])
    assert _flipped(anim, drive).max() == 0
    # the lips closed: the inner lower lip is not above the upper one (y down), on every frame
    gap = drive.still[:, [67, 66, 65], 1] - drive.still[:, [61, 62, 63], 1]
    assert gap.min() >= -1e-6
    assert gap[-1].max() < 0.5 * (anim.rest[[67, 66, 65], 1] - anim.rest[[61, 62, 63], 1]).min()
    assert (drive.alpha == 1.0).all()                       # no blend towards the rest was needed
    frames = [anim.frame_at(drive, t) for t in (0, len(V) - 1)]
    assert np.array_equal(frames[0], face.image)
    assert not np.array_equal(frames[1], face.image)


def test_chin_and_whole_lower_lip_through_the_mouth_never_folds(toon):
    """Beyond any real face: chin, lower lip and its corners 40 px up, through the upper lip."""
    face, cap0, mesh = toon
    V = _lip_push(mesh, depth=40.0, lower=np.r_[5:12, 55:60, 64:68])
    for interior in ("smooth", "tracked"):
        anim = CartoonAnimator(face.image, face.landmarks, cap0, mesh.vertices, mesh.faces, interior=interior)
        drive = anim.drive(V, V[:, :68])
        assert _flipped(anim, drive).max() == 0


def test_wild_capture_never_folds_even_without_iterations(toon):
    """Large random motion, and the iteration cut to nothing: the exact fallback still holds."""
    face, cap0, mesh = toon
    rng = np.random.default_rng(3)
    V = mesh.vertices[None] + rng.normal(0.0, 12.0, (10,) + mesh.vertices.shape)
    V[0] = mesh.vertices
    anim = CartoonAnimator(face.image, face.landmarks, cap0, mesh.vertices, mesh.faces, interior="tracked")
    drive = anim.drive(V, V[:, :68])
    assert _flipped(anim, drive).max() == 0
    n = len(anim.rest)
    solver = FoldFreeMap(anim.warp_rest, anim.warp_faces, np.arange(n, len(anim.warp_rest)), iterations=0)
    for t in range(1, len(V)):
        X, st = solver.solve(np.concatenate([anim.mesh(V[t]), anim.ring]))
        assert st.folded_before > 0 and st.alpha < 1.0
        assert solver.area_ratios(X).min() >= solver.margin
        assert np.array_equal(X[n:], anim.ring)


def test_projection_lands_in_the_set_and_keeps_members():
    rng = np.random.default_rng(0)
    J = rng.normal(0.0, 1.0, (500, 2, 2))
    P = project_jacobians(J, 0.2)
    assert np.linalg.det(P).min() > 0
    assert smallest_singular_signed(P).min() >= 0.2 - 1e-9
    sv = np.linalg.svd(P, compute_uv=False)
    np.testing.assert_allclose(sv[:, 1], np.abs(smallest_singular_signed(P)), atol=1e-9)
    inside = smallest_singular_signed(J) >= 0.2
    np.testing.assert_allclose(P[inside], J[inside], atol=1e-12)
    # nearest: no member of the set sampled nearby is closer
    Q = project_jacobians(P + rng.normal(0, 0.05, P.shape), 0.2)
    assert (np.linalg.norm(J - P, axis=(1, 2)) <= np.linalg.norm(J - Q, axis=(1, 2)) + 1e-9).all()


@pytest.mark.parametrize("interior", ["smooth", "tracked"])
def test_head_similarity_alone_leaves_the_cartoon_still_or_moves_it(toon, interior):
    face, cap0, mesh = toon
    about = mesh.vertices[:68].mean(0)
    V = np.stack([mesh.vertices] + [_similar(mesh.vertices, s, d, t, about)
                                     for s, d, t in ((0.7, 0.0, [0, 0]), (1.3, 12.0, [15.0, -8.0]),
                                                     (1.0, -20.0, [-30.0, 5.0]))])
    res = animate_cartoon(face.image, face.landmarks, V[:, :68], V, mesh.faces, interior=interior)
    np.testing.assert_allclose(res.meshes, np.broadcast_to(res.rest, res.meshes.shape), atol=1e-8)
    for f in res.frames:
        assert np.abs(f.astype(int) - face.image).max() <= 1
    res = animate_cartoon(face.image, face.landmarks, V[:, :68], V, mesh.faces, head="follow", interior=interior)
    width = np.linalg.norm(res.meshes[:, 16] - res.meshes[:, 0], axis=1)
    np.testing.assert_allclose(width / width[0], [1.0, 0.7, 1.3, 1.0], rtol=1e-9)
    turn = res.meshes[2, 16] - res.meshes[2, 0]
    assert np.rad2deg(np.arctan2(turn[1], turn[0])) == pytest.approx(12.0, abs=1e-6)
    assert not np.array_equal(res.frames[1], face.image)


def test_head_motion_fit_is_exact_for_a_similarity():
    rng = np.random.default_rng(1)
    P0 = rng.uniform(0, 300, (68, 2))
    P = np.stack([P0, _similar(P0, 1.2, 30.0, [5.0, 7.0], P0.mean(0))])
    m = fit_head_motion(P)
    assert m.scale[1] == pytest.approx(1.2) and np.rad2deg(m.angle[1]) == pytest.approx(30.0)
    np.testing.assert_allclose(m.remove(P), np.stack([P0, P0]), atol=1e-9)
    assert m.a[0] == 1 and m.b[0] == 0


def test_mesh_driver_head_still_and_follow():
    rig = default_template()
    idx = face_landmarks()
    lm0 = rig.neutral[idx, :2] * [1.0, -1.0] * 20.0 + [200.0, 150.0]
    about = lm0.mean(0)
    lm = np.stack([lm0, _similar(lm0, 1.25, 10.0, [12.0, -4.0], about)])
    still = MeshDriver(rig.neutral, rig.faces, idx, lm0).run(lm).vertices
    np.testing.assert_allclose(still[1], rig.neutral, atol=1e-9)
    drv = MeshDriver(rig.neutral, rig.faces, idx, lm0, head="follow")
    moved = drv.run(lm).vertices
    np.testing.assert_allclose(moved[0], rig.neutral, atol=1e-9)
    d0 = rig.neutral[idx[16]] - rig.neutral[idx[0]]
    d1 = moved[1, idx[16]] - moved[1, idx[0]]
    assert np.linalg.norm(d1) / np.linalg.norm(d0) == pytest.approx(1.25, rel=1e-6)
    # 10 degrees clockwise on screen (y down) is 10 degrees clockwise in the mesh (y up): angle -10
    ang = np.rad2deg(np.arctan2(d1[1], d1[0]) - np.arctan2(d0[1], d0[0]))
    assert ang == pytest.approx(-10.0, abs=1e-6)
    np.testing.assert_allclose(drv.frame(lm[1]), moved[1], atol=1e-9)
    targets, names, weights = drv.morph_basis(lm)
    assert drv.morph_error(lm, targets, weights) < 1e-3 * np.linalg.norm(np.ptp(rig.neutral, axis=0)) + 1e-9


@pytest.mark.parametrize("bad", ["sideways", "", "FOLLOWS", 3, True])
def test_bad_head_values(toon, bad):
    face, cap0, mesh = toon
    with pytest.raises(InputError, match="^head: expected one of still, follow") as ei:
        parse_head_mode(bad)
    assert str(ei.value.renamed({"head": "--head"})).startswith("--head: expected one of still, follow")
    with pytest.raises(InputError, match="^head: expected"):
        CartoonAnimator(face.image, face.landmarks, cap0, mesh.vertices, mesh.faces, head=bad)
    with pytest.raises(InputError, match="^head: expected"):
        MeshDriver(default_template().neutral, default_template().faces, face_landmarks(), cap0, head=bad)


def test_bad_interior_and_solver_values(toon):
    face, cap0, mesh = toon
    with pytest.raises(InputError, match="interior: expected one of smooth, tracked, found 'rough'"):
        CartoonAnimator(face.image, face.landmarks, cap0, mesh.vertices, mesh.faces, interior="rough")
    rest = mesh.vertices
    for kw, msg in (({"sigma_lo": 0.0}, "sigma_lo"), ({"sigma_lo": 1.5}, "sigma_lo"), ({"weight": -1.0}, "data weight"),
                    ({"margin": 0.5}, "margin")):
        with pytest.raises(InputError, match=msg):
            FoldFreeMap(rest, mesh.faces, **kw)

