"""Interchange (glTF), studies (Dask), report figures and their commands."""


import numpy as np
import pytest

from facebasis.cli import main
from facebasis.defaults.face import default_template
from facebasis.errors import InputError
from facebasis.geometry.gltf import write_glb
from facebasis.geometry.rig import write_rig_folder

from conftest import write_rig_inputs


def _read_glb_morphs(path):
    pygltflib = pytest.importorskip("pygltflib")
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()

    def accessor(i):
        a = g.accessors[i]
        v = g.bufferViews[a.bufferView]
        dtype = np.float32 if a.componentType == 5126 else np.uint32
        width = {"VEC3": 3, "SCALAR": 1}[a.type]
        data = np.frombuffer(blob, dtype=dtype, count=a.count * width, offset=v.byteOffset + (a.byteOffset or 0))
        return data.reshape(a.count, width) if width > 1 else data

    mesh = g.meshes[0]
    prim = mesh.primitives[0]
    names = mesh.extras["targetNames"]
    morphs = {n: accessor(t["POSITION"]) for n, t in zip(names, prim.targets)}
    return accessor(prim.attributes.POSITION), accessor(prim.indices).reshape(-1, 3), morphs, mesh.weights


def test_glb_export_loads_back_with_identical_morph_targets(tmp_path):
    rig = default_template()
    path = write_glb(rig, tmp_path / "rig.glb")
    V, F, morphs, weights = _read_glb_morphs(path)
    assert np.array_equal(F, rig.faces)
    # centimetres (the default source unit) written in metres
    assert np.array_equal(V, (rig.neutral * 0.01).astype(np.float32))
    assert list(morphs) == list(rig.names) and weights == [0.0] * rig.n_shapes
    for name, d in zip(rig.names, rig.deltas):
        assert np.array_equal(morphs[name], (d * 0.01).astype(np.float32))
    import trimesh

    scene = trimesh.load(path)  # a second, independent reader
    geom = next(iter(scene.geometry.values()))
    assert geom.vertices.shape == rig.neutral.shape and len(geom.faces) == len(rig.faces)


def test_cli_export(tmp_path, capsys):
    rig = default_template()
    write_rig_folder(tmp_path / "tpl", rig)
    assert main(["export", str(tmp_path / "tpl"), "--out", str(tmp_path / "x.glb")]) == 0
    assert f"{rig.n_shapes} morph targets" in capsys.readouterr().out
    _, _, morphs, _ = _read_glb_morphs(tmp_path / "x.glb")
    assert set(morphs) == set(rig.names)
    assert main(["export", str(tmp_path / "missing"), "--out", str(tmp_path / "y.glb")]) == 2
    assert not (tmp_path / "y.glb").exists()


def test_study_tasks_and_a_task_row():
    from facebasis.report.studies import COLUMNS, Task, run_task, study_tasks

    assert len(study_tasks("alpha", "default")) == 10 and len(study_tasks("grid", "default")) == 30
    assert len(study_tasks("noise", "default", noise_seeds=(0, 1))) == 12
    with pytest.raises(InputError, match="study: expected one of"):
        study_tasks("beta", "default")
    with pytest.raises(InputError, match="problem: expected 'default' or 'ict', found 'x'"):
        run_task(Task("alpha", "x", 0))
    a = run_task(Task("alpha", "default", 0, alpha=(0.02, 0.02)))
    b = run_task(Task("alpha", "default", 0, alpha=(5.0, 5.0)))
    assert set(a) == set(COLUMNS)
    # small alpha fits the training expressions better than large alpha (seed 000, Fig. 2)
    assert a["train_error"] < b["train_error"]
    dt = run_task(Task("methods", "default", 0, method="deformation transfer"))
    assert a["heldout_error"] < dt["heldout_error"]
    n0 = run_task(Task("noise", "default", 0, noise=0.0))
    assert n0["rig_change"] == pytest.approx(0.0, abs=1e-12)  # noise 0 reproduces the reference
    n5 = run_task(Task("noise", "default", 0, noise=0.5, noise_seed=1))
    assert 0 < n5["rig_change"] < 0.1


def test_sweep_cli_on_dask_and_report(tmp_path, capsys):
    out = tmp_path / "res.csv"
    assert main(["sweep", "--problem", "default", "--study", "methods", "--out", str(out), "--workers", "2",
                 "--quiet"]) == 0
    from facebasis.report.studies import read_table

    rows = read_table(out)
    assert [r["method"] for r in rows] == ["template deltas", "deformation transfer", "vertex PCA", "example-based",
                                           "example-based + virtual edges"]
    capsys.readouterr()
    assert main(["report", str(out), "--formats", "png"]) == 0
    md = (tmp_path / "res" / "methods.md").read_text()
    assert "| example-based |" in md and (tmp_path / "res" / "methods.png").is_file()


def test_sweep_report_from_rows(tmp_path):
    from facebasis.report.run_report import sweep_report

    rows = []
    for a in (0.01, 0.1, 1.0):
        rows.append({"study": "alpha", "problem": "default", "seed": 0.0, "method": "example-based", "alpha0": a,
                     "lam0": None, "noise": None, "noise_seed": None, "heldout_error": 0.05 + a / 100,
                     "train_error": 0.02 + a / 50, "shape_error": 0.2, "rig_change": None, "seconds": 1.0})
    paths = sweep_report(rows, tmp_path, formats=("png",))
    assert [p.name for p in paths] == ["alpha_sweep.png"]


def test_report_of_a_rig_run(tmp_path, capsys):
    from facebasis.rigging.synthetic import default_face_problem

    write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=4))
    assert main(["rig", "--template", str(tmp_path / "template"), "--target", str(tmp_path / "target.obj"),
                 "--examples", str(tmp_path / "examples"), "--weights", str(tmp_path / "weights.json"), "--out",
                 str(tmp_path / "run"), "--iterations", "2"]) == 0
    assert main(["report", str(tmp_path / "run"), "--formats", "png"]) == 0
    names = {p.name for p in (tmp_path / "run" / "report").iterdir()}
    assert {"convergence.png", "weights.png", "residuals.png", "shapes.png", "index.md"} <= names
    assert main(["report", str(tmp_path / "template")]) == 2
    assert "expected history.json" in capsys.readouterr().err


def test_formulation_report(tmp_path):
    from facebasis.rigging.formulations import compare_formulations
    from facebasis.report.run_report import formulation_report
    from problems.weights_suite import closed_form_instances

    rows = compare_formulations(closed_form_instances())
    paths = formulation_report(rows, tmp_path, formats=("png",))
    md = (tmp_path / "formulations.md").read_text()
    assert md.splitlines()[2].startswith("| certified | 6 | 6 |")
    assert (tmp_path / "formulations.png") in paths


def test_run_tasks_on_an_existing_scheduler():
    """`--scheduler ADDR`: the tasks go to a running Dask scheduler (here a local one started by the
    test) and come back in task order, equal to a direct run."""
    from dask.distributed import LocalCluster

    from facebasis.report.studies import Task, run_task, run_tasks

    tasks = [Task("methods", "default", 0, method=m) for m in ("template deltas", "vertex PCA")]
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        rows = run_tasks(tasks, scheduler=cluster.scheduler_address, progress=False)
    direct = [run_task(t) for t in tasks]
    assert [r["method"] for r in rows] == ["template deltas", "vertex PCA"]
    assert [r["heldout_error"] for r in rows] == [r["heldout_error"] for r in direct]


def test_generation_problem_rejects_mismatched_virtual_edges():
    import dataclasses

    from facebasis.rigging.synthetic import default_face_problem
    from facebasis.contact.virtual_edges import VirtualEdges

    p = default_face_problem(seed=0, n_train=3).problem
    other = VirtualEdges(np.array([[0, 1]]), np.ones(1), np.ones(1), 10, 1.0, 2.0, 4, 0.0)
    with pytest.raises(InputError, match=f"virtual_edges: expected edges for {p.template.n_vertices} vertices, found 10"):
        dataclasses.replace(p, virtual_edges=other)


def test_write_dict_csv_reads_back_as_written(tmp_path):
    """Benchmarks write their rows of dicts through one writer: header from the first row's keys,
    ``None`` as an empty cell, read back unchanged by csv.DictReader."""
    import csv

    from facebasis.report.tables import write_dict_csv

    rows = [{"clip": "a, b", "mean_px": 2.5, "note": None}, {"clip": "c", "mean_px": 3, "note": "x"}]
    path = write_dict_csv(tmp_path / "t.csv", rows)
    with path.open(newline="") as fh:
        back = list(csv.DictReader(fh))
    assert back == [{"clip": "a, b", "mean_px": "2.5", "note": ""}, {"clip": "c", "mean_px": "3", "note": "x"}]
