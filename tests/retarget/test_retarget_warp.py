"""The 2D cartoon warp: exact identity, translation, rasterisation coverage, the default cartoon."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from facebasis.defaults.cartoon import default_cartoon
from facebasis.errors import InputError
from facebasis.retarget.raster2d import rasterize_maps, warp_image
from facebasis.retarget.warp2d import CartoonAnimator, animate_cartoon


def _grid(x0=100, x1=400, y0=80, y1=450, n=12):
    g = np.stack(np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n)), -1).reshape(-1, 2)
    return g, Delaunay(g).simplices


def _image(seed=0, size=512):
    return np.random.default_rng(seed).integers(0, 256, (size, size, 3), dtype=np.uint8)


def test_zero_motion_returns_the_image_exactly():
    img = _image()
    g, F = _grid()
    assert np.array_equal(warp_image(img, g, g, F), img)
    face = default_cartoon(256)
    lm = face.landmarks
    anim = CartoonAnimator(face.image, lm, lm, lm, Delaunay(lm).simplices)
    assert anim.scale == pytest.approx(1.0)
    assert np.array_equal(anim.frame(lm), face.image)          # at rest, the image as drawn (its open mouth too)
    no_mouth = CartoonAnimator(face.image, lm[:60], lm[:60], lm[:60], Delaunay(lm[:60]).simplices)
    assert np.array_equal(no_mouth.frame(lm[:60]), face.image)


def test_translation_moves_the_image():
    img = _image(1)
    g, F = _grid()
    out = warp_image(img, g, g + [5.0, -3.0], F)
    # inside the moved mesh, content moved by (+5, -3) pixels; outside it is the source image
    np.testing.assert_array_equal(out[100:400, 110:390], img[103:403, 105:385])
    np.testing.assert_array_equal(out[:, :100], img[:, :100])
    # sub-pixel shift: bilinear interpolation of neighbours
    out = warp_image(img.astype(np.uint8), g, g + [0.5, 0.0], F)
    expect = (img[200:300, 199:299].astype(float) + img[200:300, 200:300]) / 2
    assert np.abs(out[200:300, 200:300] - expect).max() <= 1.0


def test_rasterisation_covers_every_pixel_once_and_only_inside():
    g, F = _grid(10.3, 200.7, 20.2, 150.9, n=9)
    _, _, tri = rasterize_maps(g, g, F, 160, 220)
    yy, xx = np.mgrid[0:160, 0:220]
    inside = (xx >= 10.3) & (xx <= 200.7) & (yy >= 20.2) & (yy <= 150.9)
    assert np.array_equal(tri >= 0, inside)
    # every covered pixel's triangle really contains it
    d = Delaunay(g)
    found = d.find_simplex(np.stack([xx[inside], yy[inside]], 1).astype(float))
    ok = (found == tri[inside]) | (found < 0)
    assert ok.mean() > 0.99  # the rest are ties on shared edges


def test_animate_cartoon_moves_mesh_by_scaled_displacements():
    face = default_cartoon(256)
    lm_img = face.landmarks
    lm_cap = 2.0 * lm_img + 30.0                  # the capture is twice as large: eq. 13 scale 0.5
    V = np.stack([lm_cap, lm_cap + [4.0, 0.0]])
    # a shift of the whole face is head motion: still by default, the whole cartoon follows on request
    res = animate_cartoon(face.image, lm_img, V, V, Delaunay(lm_cap).simplices)
    assert res.scale == pytest.approx(0.5)
    np.testing.assert_allclose(res.rest, lm_img, atol=1e-6)
    np.testing.assert_allclose(res.meshes, np.stack([lm_img, lm_img]), atol=1e-9)
    rest = face.image
    assert np.array_equal(res.frames[0], rest) and np.array_equal(res.frames[1], rest)
    res = animate_cartoon(face.image, lm_img, V, V, Delaunay(lm_cap).simplices, head="follow")
    np.testing.assert_allclose(res.meshes[1] - res.meshes[0], np.tile([2.0, 0.0], (68, 1)), atol=1e-9)
    assert np.array_equal(res.frames[0], rest)
    np.testing.assert_array_equal(res.frames[1][:, 2:], rest[:, :-2])   # the whole image moved 2 px
    # the paper's eq. 12 alone moves the mesh inside the still image
    anim = CartoonAnimator(face.image, lm_img, lm_cap, lm_cap, Delaunay(lm_cap).simplices)
    np.testing.assert_allclose(anim.mesh(V[1]) - lm_img, np.tile([2.0, 0.0], (68, 1)), atol=1e-9)


def test_default_cartoon():
    face = default_cartoon()
    assert face.image.shape == (512, 512, 3) and face.image.dtype == np.uint8
    assert face.landmarks.shape == (68, 2)
    assert np.all((face.landmarks > 0) & (face.landmarks < 512))
    lm = face.landmarks
    # iBUG layout: the subject's right eye (36-41) on the image's left, chin (8) lowest of the jaw
    assert lm[36:42, 0].mean() < lm[42:48, 0].mean()
    assert np.argmax(lm[0:17, 1]) == 8
    assert np.array_equal(default_cartoon().image, face.image)   # deterministic


def test_animator_errors():
    face = default_cartoon(128)
    lm = face.landmarks
    with pytest.raises(InputError, match="expected 68 points"):
        CartoonAnimator(face.image, lm[:60], lm, lm, Delaunay(lm).simplices)
    with pytest.raises(InputError, match="8-bit"):
        CartoonAnimator(face.image.astype(float), lm, lm, lm, Delaunay(lm).simplices)


def test_a_mouth_cut_open_along_closed_lips_is_drawn_as_an_opening_not_as_the_rest_lips():
    """A take that starts with the lips closed gives a capture mesh cut along the lips; as the mouth
    opens no triangle covers the gap. The cartoon must show a dark opening there, not its own closed
    lips seen through the gap."""
    from facebasis.capture.facemesh import build_face_mesh
    from facebasis.defaults.cartoon import default_cartoon
    from facebasis.retarget.mouthpaint import CAVITY_BACK_RGB
    from facebasis.retarget.warp2d import CartoonAnimator, mouth_is_cut

    face = default_cartoon()
    lm = np.array(face.landmarks, float)
    closed = lm.copy()
    closed[[65, 66, 67]] = closed[[63, 62, 61]]          # lower inner lip on the upper one
    mesh = build_face_mesh(closed)
    assert mouth_is_cut(mesh.faces, 68) and not mouth_is_cut(build_face_mesh(lm).faces, 68)
    anim = CartoonAnimator(np.array(face.image), lm, closed, mesh.vertices, mesh.faces, fold_free=False)
    assert anim.mouth_cut
    opened = mesh.vertices.copy()
    opened[[65, 66, 67]] += [0.0, 12.0]                  # the mouth opens by 12 px
    frame = anim.frame(opened)
    centre = np.round(anim.mesh(opened)[[62, 66]].mean(0)).astype(int)
    assert np.abs(frame[centre[1], centre[0], :3].astype(int) - CAVITY_BACK_RGB).max() <= 2   # the back of the mouth
    rest = anim.frame(mesh.vertices)                      # closed: nothing is filled
    np.testing.assert_array_equal(rest, anim.warp(anim.mesh(mesh.vertices)))
