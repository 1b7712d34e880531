"""Scan-to-model pairs in the expression fit (geometry/scanpairs.py): an opened mouth is not fitted as lips
closed over its hole, closed lips stay closed, bad values of the option.

Tiny data built here: the built-in default face (it has lips and a mouth socket) with its own expressions and
one more, ``jawOpenLipsClosed``: the jaw's motion everywhere but on the lips (the jaw opened behind closed lips,
ICT's jawOpen + mouthClose in one shape). Scanned without the mouth socket (a scanner does not see it), an
opened mouth is then a hole between the lips, and over that hole the two shapes differ only where the
model-to-scan pairs are dropped (they land on the hole's rim): the one-sided fit splits the jaw between them.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest
from conftest import parser_refuses
from scipy.spatial import cKDTree

from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.registration import Registration, RegistrationOptions
from facebasis.geometry.mesh import median_edge_length
from facebasis.geometry.scanpairs import ScanToModel
from facebasis.geometry.shapemodel import ModelFitOptions, ShapeBasis
from test_shapemodel import as_scan, face


@lru_cache(maxsize=1)
def ambiguous_rig():
    """``(T, F, names, D, keep)``: the built-in face, its expressions plus ``jawOpenLipsClosed``, and the
    vertices a scanner sees (all but the mouth socket)."""
    from facebasis.defaults.face import region_masks

    rig = face()
    m = region_masks()
    jaw = rig.deltas[rig.names.index("jawOpen")]
    D = np.concatenate([rig.deltas, (jaw * (1.0 - m["lips"])[:, None])[None]])
    return rig.neutral, rig.faces, (*rig.names, "jawOpenLipsClosed"), D, ~m["mouth_socket"]


def fit(weights: dict, scan_pairs: int | None = None, fringe: float = 0.0):
    """Register a scan of the tiny rig at ``weights`` from the exact neutral; ``(weights by name, p95 error)``.
    ``fringe`` > 0: the scan also holds a copy of the forehead that far in front of it (a fringe of hair, a
    cap's brim: a layer the model lacks)."""
    T, F, names, D, keep = ambiguous_rig()
    w = np.array([weights.get(n, 0.0) for n in names])
    V = T + np.tensordot(w, D, 1)
    S0, G0 = V, F[keep[F].all(1)]
    if fringe:
        Ff = G0[V[G0].mean(1)[:, 1] > 4.0]
        used = np.unique(Ff)
        remap = np.full(len(V), -1)
        remap[used] = np.arange(len(used))
        S0, G0 = np.concatenate([V, V[used] + [0.0, 0.0, fringe]]), np.concatenate([G0, remap[Ff] + len(V)])
    S, G, R, t = as_scan(S0, G0, seed=1)
    opts = RegistrationOptions()
    if scan_pairs is not None:
        opts = dataclasses.replace(opts, expression_fit=dataclasses.replace(opts.expression_fit, scan_pairs=scan_pairs))
    res = Registration(T, F, opts, expressions=ShapeBasis(names, D, "test")).register(S, G, start=T, expressions=D)
    err = np.linalg.norm(res.vertices - (V @ R.T + t), axis=1)
    return dict(zip(names, res.model.coefficients)), float(np.percentile(err, 95)), float(err.max())


def test_an_opened_mouth_is_not_fitted_as_lips_closed_over_its_hole():
    assert RegistrationOptions().expression_fit.scan_pairs == 5000
    w, p95, mx = fit({"jawOpen": 1.0})
    assert w["jawOpen"] > 0.95 and w["jawOpenLipsClosed"] < 0.05, w
    assert p95 < 0.01 and mx < 0.05, (p95, mx)
    # the model-to-scan pairs alone (the previous fit): the jaw split between the two, the lips half closed
    w0, _, mx0 = fit({"jawOpen": 1.0}, scan_pairs=0)
    assert w0["jawOpenLipsClosed"] > 0.3 and mx0 > 0.5, (w0, mx0)


@pytest.mark.parametrize("offset", [0.5, 1.0])
@pytest.mark.parametrize("jaw", [0.0, 1.0])
def test_a_layer_the_model_lacks_pulls_nothing(offset, jaw):
    """A copy of the forehead 0.5 or 1 cm (1.7-3.5 edge lengths) in front of it: without eq. S3 its points
    pulled the brows up (browInnerUp 1.1-1.5, eyeWide up to 0.6, face p95 0.03-0.06) or, through eq. S2's
    choice, left the opened mouth half closed (max 1.2); with it the scan's own face decides."""
    w, p95, mx = fit({"jawOpen": jaw}, fringe=offset)
    assert w["browInnerUp"] < 0.05 and max(w["eyeWide_L"], w["eyeWide_R"]) < 0.1, w
    assert abs(w["jawOpen"] - jaw) < 0.05 and w["jawOpenLipsClosed"] < 0.05, w
    assert p95 < 0.01 and mx < 0.05, (p95, mx)


def test_a_scan_denser_than_the_model_keeps_its_pairs_at_the_exact_fit():
    """Eq. S3 compares offsets along the model's normal: the points of a midpoint-subdivided scan lying along
    the skin between the model's vertices all pair at the exact fit (straight-line distances dropped 35 %)."""
    import trimesh

    from facebasis.geometry.nricp import NonRigidICP, ScanSurface

    T, F, names, D, keep = ambiguous_rig()
    S, G = trimesh.remesh.subdivide(T, F[keep[F].all(1)])
    h = median_edge_length(T, F)
    pairs = ScanToModel(ScanSurface(S, G), np.arange(len(T)), RegistrationOptions().expression_fit, h)
    n = NonRigidICP(F, len(T)).vertex_normals(T)
    free = pairs.pairs(T, n)[0]  # every pair eq. S3 lets through
    dist, j = cKDTree(T).query(pairs.Q, distance_upper_bound=pairs.dmax)
    agree = np.isfinite(dist) & ((n[np.where(np.isfinite(dist), j, 0)] * pairs.N).sum(1) >= pairs.cos_max)
    assert agree.sum() == len(pairs.Q) == 5000 and len(free) >= 0.95 * agree.sum(), (len(free), agree.sum())


def test_closed_lips_over_an_opened_jaw_stay_closed():
    w, p95, _ = fit({"jawOpenLipsClosed": 1.0})
    assert w["jawOpenLipsClosed"] > 0.95 and w["jawOpen"] < 0.05, w
    assert p95 < 0.01


@pytest.mark.parametrize("value", [-1, 2.5, True, "5000"])
def test_bad_scan_pairs_are_refused(value):
    with pytest.raises(InputError, match=r"scan_pairs: expected an integer >= 0 \(0: model-to-scan pairs only\), "
                                         rf"found {value!r}"):
        ModelFitOptions(scan_pairs=value)


def test_cli_expression_scan_pairs(tmp_path, capsys, monkeypatch):
    rig = face()
    write_mesh(tmp_path / "t.obj", rig.neutral, rig.faces)
    write_mesh(tmp_path / "scan.obj", rig.neutral + 0.1, rig.faces)
    base = ["register", str(tmp_path / "scan.obj"), "--template", str(tmp_path / "t.obj"), "--out", str(tmp_path / "o")]
    assert main(base + ["--expression-scan-pairs", "-2"]) == 2
    err = capsys.readouterr().err
    assert "error: --expression-scan-pairs: expected an integer >= 0 (0: model-to-scan pairs only), found -2" in err
    assert not (tmp_path / "o").exists()
    parser_refuses(main, base + ["--expression-scan-pairs", "0", "--expression-scan-pairs", "9"], capsys,
                   "--expression-scan-pairs")
    parser_refuses(main, base + ["--expression-scan-pairs", "many"], capsys, "--expression-scan-pairs")
    seen = []  # the value (and the default) reach the library

    def spy(*a, **k):
        seen.append(a[5].expression_fit.scan_pairs)
        return {"scans": []}

    monkeypatch.setattr("facebasis.geometry.registerfiles.register_files", spy)
    assert main(base + ["--expression-scan-pairs", "0"]) == 0 and main(base) == 0
    assert seen == [0, 5000]
