"""The detail field along the person's normals (geometry/fieldnormals.py, eq. D4).

Tiny data built here: the built-in default face with smooth random identity modes and a field along the
person's normals (tests/geometry/test_detailprior.py's person).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import check_detail_choice_flag
from test_detailprior import person_parts

from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.detailprior import DetailPriorOptions
from facebasis.geometry.fieldnormals import person_normals
from facebasis.geometry.nricp import NonRigidICP
from facebasis.geometry.registration import Registration, RegistrationOptions
from facebasis.geometry.shapemodel import ShapeBasis


def test_person_normals_are_the_normals_of_the_modes_mesh():
    from test_shapemodel import face, modes

    rig = face()
    T, F = rig.neutral, rig.faces
    D = modes(T, 5)
    c = np.array([1.0, -0.5, 2.0, 0.0, 0.3])
    icp = NonRigidICP(F, len(T))
    m = person_normals(T, D, np.concatenate([c, np.ones(7)]), icp.vertex_normals)  # the field's coefficients ignored
    assert np.allclose(m, icp.vertex_normals(T + np.tensordot(c, D, 1)), atol=1e-12)
    assert np.allclose(np.linalg.norm(m, axis=1), 1.0)


def test_the_field_along_the_persons_normals_slides_the_points_less():
    """The person's detail lies along its own normals; along the template's, part of the field runs along the
    skin. The joint fit with each (the same s and noise level: chosen by the evidence at the modes-only fit)."""
    from test_shapemodel import as_scan

    T, F, D, c, _, f, _ = person_parts()
    c = 3.0 * c          # a person far from the template: its normals 9 degrees off the template's (median), 21 (p95)
    normals = NonRigidICP(F, len(T)).vertex_normals
    person = T + np.tensordot(c, D, 1)
    person = person + f[:, None] * normals(person)
    S, G, R, t = as_scan(person, F, seed=1)
    truth, basis = person @ R.T + t, ShapeBasis(tuple(f"m{j}" for j in range(len(D))), D, "test")
    out = {}
    for how in ("template", "person"):
        res = Registration(T, F, RegistrationOptions(after_model="normal", detail=DetailPriorOptions(field_normals=how)),
                           identity=basis).register(S, G)
        err = np.linalg.norm(res.vertices - truth, axis=1)
        out[how] = np.median(err), np.percentile(err, 95), np.sqrt(np.mean(err ** 2))
    # measured: median 0.0060 -> 0.0031 cm, p95 0.0181 -> 0.0104, RMS 0.0106 -> 0.0051
    assert out["person"][2] < 0.7 * out["template"][2]
    assert out["person"][0] < 0.75 * out["template"][0] and out["person"][1] < 0.75 * out["template"][1]


@pytest.mark.parametrize("value", ["normals", None, 1])
def test_bad_field_normals_are_refused(value):
    with pytest.raises(InputError, match=r"detail\.field_normals: expected one of person, template, found "):
        DetailPriorOptions(field_normals=value)


def test_cli_detail_field_normals_bad_value_repeat_without_the_prior_and_reaching_the_registration(tmp_path, capsys,
                                                                                                   monkeypatch):
    check_detail_choice_flag(main, tmp_path, capsys, monkeypatch, "--detail-field-normals", "field_normals", "scan",
                             ("person", "template"))
