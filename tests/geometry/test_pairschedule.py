"""When the expression fit's scan pairs join it (geometry/pairschedule.py): eq. S2, the ``after`` schedule's
choice, bad values of the option and its command-line flag.

Tiny data: the built-in default face and the ambiguous rig of test_scanpairs (its expressions plus
``jawOpenLipsClosed``, scanned without the mouth socket).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import parser_refuses

from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.mesh import median_edge_length
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.nricp import NonRigidICP, ScanSurface
from facebasis.geometry.pairschedule import CAP, MARGIN, scan_unexplained, whole_expression_fit
from facebasis.geometry.registration import Registration, RegistrationOptions
from facebasis.geometry.scanpairs import ScanToModel
from facebasis.geometry.shapemodel import ModelFitOptions, ShapeBasis
from test_scanpairs import ambiguous_rig
from test_shapemodel import as_scan, face


def test_eq_s2_is_the_capped_scan_to_model_residual():
    rig = face()
    V, F = rig.neutral, rig.faces
    h = median_edge_length(V, F)
    normals = NonRigidICP(F, len(V)).vertex_normals(V)
    pairs = ScanToModel(ScanSurface(V, F), np.arange(len(V)), ModelFitOptions(scan_pairs=500), h)
    assert scan_unexplained(V, normals, pairs, h) < 1e-9  # the model on the scan: nothing unexplained
    # the model moved along its normals by 0.3 h: every scan point 0.3 h from its nearest model vertex's plane
    assert scan_unexplained(V + 0.3 * h * normals, normals, pairs, h) == pytest.approx(0.3, rel=0.05)
    # 6 h off: capped at CAP h (a scan point is unexplained, however far; a few pair on curved parts nearer)
    far = scan_unexplained(V + 6.0 * h * normals, normals, pairs, h)
    assert 0.97 * CAP < far <= CAP
    assert scan_unexplained(V + [500.0 * h, 0.0, 0.0], normals, pairs, h) == np.inf  # no pair left


def register(weights: dict, schedule: str, monkeypatch):
    """Register a scan of the ambiguous rig at ``weights`` with ``schedule``; (weights by name, p95, info)."""
    import facebasis.geometry.expressionregions as er

    seen = []

    def spy(*a, **k):
        out = whole_expression_fit(*a, **k)
        seen.append(out[1])
        return out

    monkeypatch.setattr(er, "whole_expression_fit", spy)
    T, F, names, D, keep = ambiguous_rig()
    w = np.array([weights.get(n, 0.0) for n in names])
    V = T + np.tensordot(w, D, 1)
    S, G, R, t = as_scan(V, F[keep[F].all(1)], seed=1)
    opts = RegistrationOptions(expression_pairs_schedule=schedule)
    res = Registration(T, F, opts, expressions=ShapeBasis(names, D, "test")).register(S, G, start=T, expressions=D)
    err = np.linalg.norm(res.vertices - (V @ R.T + t), axis=1)
    return dict(zip(names, res.model.coefficients)), float(np.percentile(err, 95)), seen[0]


def test_after_keeps_the_fit_that_explains_more_of_the_scan(monkeypatch):
    assert RegistrationOptions().expression_pairs_schedule == "after"
    # an opened mouth: the one-sided fit closes the lips over the hole (test_scanpairs), the continued fit opens
    # them, and eq. S2 sees the scan's lips unexplained by the first
    w, p95, info = register({"jawOpen": 1.0}, "after", monkeypatch)
    assert info["kept"] == "continued" and info["s2"][1] < 0.8 * info["s2"][0], info["s2"]
    assert w["jawOpen"] > 0.95 and w["jawOpenLipsClosed"] < 0.05 and p95 < 0.01, (w, p95)
    one_sided, continued = info["fits"]
    assert one_sided.coefficients[-1] > 0.3  # the first fit was in the closed-lips basin
    # closed lips over an opened jaw: both fits right, eq. S2 within noise of each other; whichever is kept (by
    # eq. S2 and MARGIN), the lips stay closed and the other weights small
    w, p95, info = register({"jawOpenLipsClosed": 1.0}, "after", monkeypatch)
    assert w["jawOpenLipsClosed"] > 0.95 and w["jawOpen"] < 0.05 and p95 < 0.01, (w, p95)
    assert info["kept"] == ("one-sided", "continued")[int(info["s2"][1] < MARGIN * info["s2"][0])]
    assert max(abs(v) for k, v in w.items() if k != "jawOpenLipsClosed") < 0.1, w


@pytest.mark.parametrize("schedule, pairs, label", [("joint", 500, "joint"), ("after", 0, "one-sided")])
def test_joint_and_no_pairs_fit_once(schedule, pairs, label):
    rig = face()
    V, F = rig.neutral, rig.faces
    h = median_edge_length(V, F)
    w = np.zeros(len(rig.names))
    w[rig.names.index("jawOpen")] = 0.6
    S = V + np.tensordot(w, rig.deltas, 1)
    fit, info = whole_expression_fit(V, rig.deltas, ScanSurface(S, F), NonRigidICP(F, len(V)).vertex_normals, h,
                                     ModelFitOptions(scan_pairs=pairs, scale=False), (0.0, 1.5), schedule=schedule)
    assert info == {"schedule": label}
    assert np.abs(fit.coefficients - w).max() < 0.05, fit.coefficients


@pytest.mark.parametrize("value", ["both", "", None, 1, "After"])
def test_bad_schedules_are_refused(value):
    with pytest.raises(InputError, match="^" + re.escape(f"expression_pairs_schedule: expected one of after, joint, "
                                                         f"found {value!r}") + "$"):
        RegistrationOptions(expression_pairs_schedule=value)
    with pytest.raises(InputError, match="expression_pairs_schedule"):
        whole_expression_fit(None, None, None, None, 1.0, ModelFitOptions(), None, schedule=value)


def test_cli_expression_pairs_schedule(tmp_path, capsys, monkeypatch):
    rig = face()
    write_mesh(tmp_path / "t.obj", rig.neutral, rig.faces)
    write_mesh(tmp_path / "scan.obj", rig.neutral + 0.1, rig.faces)
    base = ["register", str(tmp_path / "scan.obj"), "--template", str(tmp_path / "t.obj"), "--out", str(tmp_path / "o")]
    parser_refuses(main, base + ["--expression-pairs-schedule", "both"], capsys, "--expression-pairs-schedule",
                   "invalid choice")
    parser_refuses(main, base + ["--expression-pairs-schedule", "after", "--expression-pairs-schedule", "joint"],
                   capsys, "--expression-pairs-schedule")
    assert not (tmp_path / "o").exists()
    seen = []  # the value (and the default) reach the library

    def spy(*a, **k):
        seen.append(a[5].expression_pairs_schedule)
        return {"scans": []}

    monkeypatch.setattr("facebasis.geometry.registerfiles.register_files", spy)
    assert main(base + ["--expression-pairs-schedule", "joint"]) == 0 and main(base) == 0
    assert seen == ["joint", "after"]
