"""The animated GLB: loads back with pygltflib and trimesh; keyframes, weights in [0, 1]; validator."""


import numpy as np
import pytest

from conftest import gltf_validate as _validate
from facebasis.defaults.face import default_template
from facebasis.errors import InputError
from facebasis.retarget.animation import animated_glb_bytes, frame_times, write_rig_animation


def _weights(T, k, seed=0):
    rng = np.random.default_rng(seed)
    return np.clip(rng.uniform(-0.2, 1.2, (T, k)), 0.0, 1.0)


@pytest.fixture(scope="module")
def glb(tmp_path_factory):
    rig = default_template()
    W = _weights(25, rig.n_shapes)
    path = tmp_path_factory.mktemp("glb") / "animation.glb"
    write_rig_animation(path, rig, W, fps=24.0)
    return path, rig, W


def _accessor_array(g, index):
    acc = g.accessors[index]
    view = g.bufferViews[acc.bufferView]
    data = g.binary_blob()
    n = {"SCALAR": 1, "VEC3": 3}[acc.type] * acc.count
    return np.frombuffer(data, np.float32, n, (view.byteOffset or 0) + (acc.byteOffset or 0))


def test_pygltflib_reads_the_animation(glb):
    pygltflib = pytest.importorskip("pygltflib")
    path, rig, W = glb
    g = pygltflib.GLTF2().load(str(path))
    assert len(g.meshes[0].primitives[0].targets) == rig.n_shapes
    assert g.meshes[0].extras["targetNames"] == list(rig.names)
    (anim,) = g.animations
    (ch,) = anim.channels
    assert ch.target.path == "weights" and ch.target.node == 0
    sampler = anim.samplers[ch.sampler]
    times = _accessor_array(g, sampler.input)
    weights = _accessor_array(g, sampler.output).reshape(len(times), rig.n_shapes)
    assert len(times) == 25
    np.testing.assert_allclose(times, np.arange(25) / 24.0, rtol=1e-6)
    np.testing.assert_allclose(weights, W, atol=1e-7)
    assert weights.min() >= 0.0 and weights.max() <= 1.0


def test_trimesh_loads_the_mesh(glb):
    trimesh = pytest.importorskip("trimesh")
    path, rig, _ = glb
    scene = trimesh.load(str(path), force="scene", process=False)
    (geom,) = scene.geometry.values()
    assert len(geom.vertices) == rig.n_vertices
    assert len(geom.faces) == len(rig.faces)


def test_gltf_validator_reports_no_errors(glb):
    issues = _validate(glb[0])
    assert issues["numErrors"] == 0, issues["messages"][:5]


def test_rig_export_glb_passes_the_validator(tmp_path):
    from facebasis.geometry.gltf import write_glb

    path = write_glb(default_template(), tmp_path / "rig.glb")
    issues = _validate(path)
    assert issues["numErrors"] == 0, issues["messages"][:5]


def test_mesh_animation_glb_is_valid_and_exact(tmp_path):
    from facebasis.defaults.face_landmarks import face_landmarks
    from facebasis.retarget.drive3d import MeshDriver

    rig = default_template()
    idx = face_landmarks()
    rng = np.random.default_rng(3)
    lm0 = rng.uniform(100, 400, (68, 2))
    lm = lm0 + np.cumsum(rng.normal(0, 0.5, (12, 68, 2)), axis=0)
    lm[0] = lm0
    driver = MeshDriver(rig.neutral, rig.faces, idx, lm0)
    targets, names, weights = driver.morph_basis(lm)
    assert weights.min() >= 0.0 and weights.max() <= 1.0
    assert driver.morph_error(lm, targets, weights) < 2e-3 * np.linalg.norm(np.ptp(rig.neutral, axis=0)) * 5
    path = tmp_path / "mesh.glb"
    path.write_bytes(animated_glb_bytes(rig.neutral, rig.faces, targets, names, frame_times(12, 25.0), weights))
    issues = _validate(path)
    assert issues["numErrors"] == 0, issues["messages"][:5]


def test_writer_errors():
    rig = default_template()
    with pytest.raises(InputError, match="expected weights of shape"):
        animated_glb_bytes(rig.neutral, rig.faces, rig.deltas, rig.names, frame_times(3, 30), np.zeros((3, 2)))
    with pytest.raises(InputError, match="strictly increasing"):
        animated_glb_bytes(rig.neutral, rig.faces, rig.deltas, rig.names, [0.0, 0.0, 1.0], np.zeros((3, 15)))
    with pytest.raises(InputError, match="fps"):
        frame_times(3, 0.0)
