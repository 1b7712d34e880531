"""Face mesh and harmonic initialisation (Wu & Ju 2016, eq. 7-9)."""

import numpy as np
import pytest

from facebasis.geometry.mesh import boundary_vertices
from facebasis.capture.facemesh import (
    build_face_mesh,
    points_in_polygon,
    signed_areas,
)
from facebasis.capture.harmonic import HarmonicDeformer
from facebasis.geometry.laplacian import cotangent_laplacian
from facebasis.capture.synthetic import ASTRONAUT_LANDMARKS, cartoon_landmarks
from facebasis.errors import MeshError


@pytest.mark.parametrize("lm", [cartoon_landmarks((192, 192)), ASTRONAUT_LANDMARKS], ids=["cartoon", "astronaut"])
def test_mesh_covers_polygon_with_landmarks_as_vertices(lm):
    m = build_face_mesh(lm)
    L = len(lm)
    assert np.array_equal(m.vertices[:L], lm)
    used = np.zeros(len(m.vertices), bool)
    used[m.faces.ravel()] = True
    assert used.all()  # every vertex (all landmarks included) is in a triangle
    area = signed_areas(m.vertices, m.faces)
    assert np.all(area > 1e-3 * m.spacing ** 2)  # consistently oriented, no degenerate triangle
    poly = lm[m.boundary]
    poly_area = 0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))
    assert area.sum() == pytest.approx(poly_area, rel=0.02)  # covers the landmark polygon
    assert np.all(boundary_vertices(m.faces) < L)  # only landmarks on the mesh boundary
    assert np.all(points_in_polygon(m.vertices[L:], poly))
    assert len(m.vertices) > L + 30  # interior grid points were added


def test_mesh_other_landmark_count_uses_hull():
    rng = np.random.default_rng(0)
    lm = rng.random((12, 2)) * 100 + 10
    m = build_face_mesh(lm, spacing=10)
    assert np.array_equal(m.vertices[:12], lm)
    assert np.all(signed_areas(m.vertices, m.faces) > 0)


def test_mesh_degenerate_landmarks():
    with pytest.raises(MeshError, match="degenerate"):
        build_face_mesh(np.array([[0, 0], [1, 1], [2, 2], [3, 3.0]]))


def _deformer():
    lm = cartoon_landmarks((192, 192))
    m = build_face_mesh(lm)
    return m, HarmonicDeformer(m.vertices, m.faces, np.arange(len(lm)))


def test_harmonic_reproduces_affine_motion_exactly():
    """The cotangent Laplacian has linear precision at interior vertices and every boundary vertex
    is a landmark, so an affine landmark motion is reproduced at all vertices (to round-off)."""
    m, h = _deformer()
    A = np.array([[1.05, 0.12], [-0.08, 0.93]])
    t = np.array([3.5, -2.0])
    target = m.vertices @ A.T + t
    d = h.solve(target[: m.n_landmarks] - m.vertices[: m.n_landmarks])
    assert np.abs(m.vertices + d - target).max() < 1e-8


def test_harmonic_zero_motion_zero_displacement():
    m, h = _deformer()
    assert np.abs(h.solve(np.zeros((m.n_landmarks, 2)))).max() == 0.0


def test_cotangent_laplacian_psd_and_annihilates_constants():
    m, _ = _deformer()
    K = cotangent_laplacian(m.vertices, m.faces)
    assert abs(K - K.T).max() < 1e-12
    assert np.abs(K @ np.ones(len(m.vertices))).max() < 1e-9
