"""Exact contact for deformation transfer: separating planes iterated with the exact counter."""

import dataclasses

import numpy as np
import pytest

from conftest import grid_sheet, stretched, two_sheets
from facebasis.contact.exact import contact_correct, contact_transfer
from facebasis.contact.penetration import intersecting_pairs, penetration_report, triangle_pairs_intersect
from facebasis.contact.proximity import candidate_pairs, new_pairs, triangle_distance
from facebasis.errors import InputError
from facebasis.geometry.rig import Rig
from facebasis.geometry.transfer import DeformationTransfer
from test_virtual_edges import press_rig


def new_count(rig, target, deltas, names):
    out = []
    for D, name in zip(deltas, names):
        i = rig.names.index(name)
        rep = penetration_report(target + D, rig.faces, references=(target, rig.neutral + rig.deltas[i]))
        out.append(len(rep.new))
    return out


def test_two_sheets_pushed_through_stay_apart_and_keep_their_motion_elsewhere():
    rig = two_sheets()
    target = stretched(rig.neutral)
    plain = DeformationTransfer(rig, target).transfer()
    assert new_count(rig, target, plain.deltas, plain.names)[0] > 0  # plain transfer pushes through
    res = contact_transfer(rig, target, reach=0.5)
    assert res.ok and new_count(rig, target, res.rig.deltas, res.rig.names) == [0, 0]
    rep = res.shapes[0]
    assert rep.plain_new_pairs > 0 and rep.new_pairs_left == 0 and rep.iterations >= 1
    assert rep.min_distance > 0 and rep.constrained_pairs > 0
    # beyond reach of the bottom sheet (x <= 1.72 of the stretched 4.4) the plain motion is kept exactly
    far = np.flatnonzero(target[:, 0] > 2.6)
    assert len(far) > 40
    assert np.array_equal(res.rig.deltas[0][far], plain.deltas[0][far])
    # and the shape still moves: the top sheet comes down to the bottom sheet, it is not left at rest
    top = np.arange(21 * 7)
    assert res.rig.deltas[0][top, 2].min() < -0.2
    assert np.array_equal(res.rig.deltas[1], plain.deltas[1])  # a still shape is untouched


def test_a_folded_strip_pressed_through_itself_stays_apart():
    rig, target, layer = press_rig(gap=0.4)  # template gap 1.0 pressed by 0.8: the target's 0.4 is crossed
    bump = lambda V: V + np.c_[0 * V[:, :2], 0.004 * np.sin(2.1 * V[:, 0] + 0.3) * np.cos(1.7 * V[:, 1])]
    rig = Rig(bump(rig.neutral), rig.faces, rig.names, rig.deltas)  # not coplanar: fast exact tests
    target = bump(target)
    plain = DeformationTransfer(rig, target).transfer()
    assert new_count(rig, target, plain.deltas, plain.names)[0] > 0
    res = contact_transfer(rig, target)
    assert res.ok and new_count(rig, target, res.rig.deltas, res.rig.names) == [0]
    assert res.shapes[0].min_distance > 0
    # the press still closes most of the gap
    top = layer == 2
    gap = (target + res.rig.deltas[0])[top, 2].min()
    assert gap < 0.25


def _rot_y(P, hinge, angle):
    """P (p, 3) rotated by ``angle`` about the line x = hinge, z = 0 (along y)."""
    c, s = np.cos(angle), np.sin(angle)
    Q = P.copy()
    x, z = P[:, 0] - hinge, P[:, 2]
    Q[:, 0] = hinge + c * x - s * z
    Q[:, 2] = s * x + c * z
    return Q


def hinge_strip(pre=0.5, fold=2.7, hinge=2.2):
    """One strip (x in [0, 4]) whose flap beyond x = hinge folds up and back over the strip by ``fold``
    radians in the template shape (apart: 2.7 < pi); the target neutral has the flap already bent up by
    ``pre``, so the transferred rotation (pre + fold > pi) folds the flap through the strip itself."""
    V, F = grid_sheet(25, 5, size=4.0)
    V[:, 2] = 0.003 * np.sin(2.3 * V[:, 0] + 0.4) * np.cos(1.9 * V[:, 1])  # not coplanar: fast exact tests
    flap = V[:, 0] > hinge + 1e-9
    S, B0 = V.copy(), V.copy()
    S[flap] = _rot_y(V[flap], hinge, fold)
    B0[flap] = _rot_y(V[flap], hinge, pre)
    return Rig(V, F, ("fold",), (S - V)[None]), B0, flap


def test_a_fold_of_one_strip_is_prevented():
    rig, target, flap = hinge_strip()
    S = rig.neutral + rig.deltas[0]
    assert len(intersecting_pairs(S, rig.faces)) == 0 and len(intersecting_pairs(target, rig.faces)) == 0
    plain = DeformationTransfer(rig, target).transfer()
    rep = penetration_report(target + plain.deltas[0], rig.faces, references=(target, S))
    assert len(rep.new) > 0  # plain transfer folds the flap through the strip
    res = contact_transfer(rig, target)
    X = target + res.rig.deltas[0]
    assert res.ok and len(penetration_report(X, rig.faces, references=(target, S)).new) == 0
    shape = res.shapes[0]
    assert shape.plain_new_pairs == len(rep.new) and shape.iterations >= 1 and shape.min_distance > 0
    # the flap still folds back over the strip (its tip above it, beyond the hinge's other side) ...
    tip = flap & (rig.neutral[:, 0] > 3.9)
    assert np.all(X[tip, 2] > 0.0) and np.all(X[tip, 0] < 1.0)
    assert np.all((target + plain.deltas[0])[tip, 2] < 0.0)
    # ... and the far end of the strip keeps the plain motion exactly
    far = rig.neutral[:, 0] < 0.8
    assert np.array_equal(res.rig.deltas[0][far], plain.deltas[0][far])


def test_generated_shapes_are_corrected_by_the_smallest_displacement():
    """``contact_correct`` (``rig --contact``): shapes made otherwise stay apart, far vertices keep their
    delta exactly, an excluded shape is returned as given; bad input is refused."""
    rig = two_sheets()
    target = stretched(rig.neutral)
    made = DeformationTransfer(rig, target).transfer()  # stands in for generated shapes
    made = Rig(made.neutral, made.faces, made.names, made.deltas * np.array([1.2, 1.0])[:, None, None])
    res = contact_correct(made, rig, reach=0.5)
    assert res.ok and res.plain is made
    assert new_count(rig, target, res.rig.deltas, res.rig.names) == [0, 0]
    assert new_count(rig, target, made.deltas, made.names)[0] > 0
    far = np.flatnonzero(target[:, 0] > 2.6)
    assert np.array_equal(res.rig.deltas[0][far], made.deltas[0][far])
    # the smallest displacement moves less, in vertex positions, than the transfer energy's correction
    smooth = contact_correct(made, rig, reach=0.5, stiffness=0.0)
    assert smooth.ok
    assert np.linalg.norm(res.rig.deltas[0] - made.deltas[0]) < np.linalg.norm(smooth.rig.deltas[0] - made.deltas[0])
    ex = contact_correct(made, rig, exclude="push")
    assert ex.shapes[0].excluded and np.array_equal(ex.rig.deltas[0], made.deltas[0])
    with pytest.raises(InputError, match=r"contact exclude: expected shape names of the rig .*found unknown 'pull'"):
        contact_correct(made, rig, exclude=["pull"])
    with pytest.raises(InputError, match=r"contact: expected a mesh of at most 50 vertices .*found 210"):
        contact_correct(made, rig, max_vertices=50)


def generated_two_sheets():
    """``contact_generation``'s inputs on the two sheets: a generator whose examples come from a person
    pushing the top sheet through the bottom one (1.3 x the plain transfer), and its result."""
    from facebasis.rigging.generation import BlendshapeGenerator
    from facebasis.rigging.problem import GenerationOptions
    from facebasis.rigging.problem import GenerationProblem

    rig = two_sheets()
    target = stretched(rig.neutral)
    plain = DeformationTransfer(rig, target).transfer()
    truth = Rig(target, rig.faces, plain.names, plain.deltas * np.array([1.3, 1.0])[:, None, None])
    W = np.array([[1.0, 0.0], [0.6, 0.3], [0.3, 1.0], [0.9, 0.5]])
    problem = GenerationProblem(rig, target, truth.evaluate(W), np.clip(W + 0.1, 0.0, 1.0),
                                tuple(f"e{j}" for j in range(len(W))))
    gen = BlendshapeGenerator(problem, GenerationOptions(iterations=1, ipopt="never"))
    return rig, target, gen, gen.run()


def test_rig_contact_falls_back_to_the_transfer_energy_when_the_smallest_displacement_fails():
    """``contact_generation`` when the stiff (smallest-displacement) correction leaves pairs after its
    rounds (here one round): the transfer-energy fallback ends clean by the independent counter, and
    the motion away from the contact is kept exactly."""
    from facebasis.rigging.contactstep import contact_generation

    rig, target, gen, res = generated_two_sheets()
    assert new_count(rig, target, res.rig.deltas, res.rig.names)[0] > 0  # the generated shape pushes through
    contact, out = contact_generation(gen, res, reach=0.5, max_iterations=1, fallback_iterations=40)
    rep = contact.shapes[0]
    assert rep.fallback and rep.retreated == 0 and rep.iterations > 1  # the stiff pass did not finish in one round
    assert contact.ok and "(transfer energy)" in contact.table()
    assert new_count(rig, target, out.rig.deltas, out.rig.names) == [0, 0]
    far = np.flatnonzero(target[:, 0] > 2.6)  # beyond reach of the bottom sheet
    assert len(far) > 40 and np.array_equal(out.rig.deltas[0][far], res.rig.deltas[0][far])
    assert np.array_equal(out.rig.deltas[1], res.rig.deltas[1])  # the shape without pairs is untouched
    top = np.arange(21 * 7)
    assert out.rig.deltas[0][top, 2].min() < -0.2  # still pressed down to the bottom sheet, not left at rest
    # the stored weights and residuals are those of the corrected rig
    assert out.rig is contact.rig and out.weights.shape == res.weights.shape
    assert not np.allclose(out.residuals, res.residuals)
    # with the default rounds the stiff pass itself finishes: no fallback
    stiff, _ = contact_generation(gen, res, reach=0.5)
    assert stiff.ok and not stiff.shapes[0].fallback


def test_rig_contact_last_resort_retreats_only_around_the_pairs_left():
    """When neither pass ends clean within its rounds, the last resort pulls the shape back towards the
    target neutral around the pairs left until the exact check passes; the rest keeps its delta."""
    from facebasis.rigging.contactstep import contact_generation

    rig, target, gen, res = generated_two_sheets()
    contact, out = contact_generation(gen, res, reach=0.25, max_iterations=1, fallback_iterations=1)
    rep = contact.shapes[0]
    assert rep.retreated > 0 and rep.new_pairs_left == 0 and contact.ok
    assert 0 < rep.retreat_loss < 1 and np.isnan(rep.min_distance)  # part of the delta is gone, not all
    assert f"{100 * rep.retreat_loss:.1f}% of its delta" in contact.table()
    assert new_count(rig, target, out.rig.deltas, out.rig.names) == [0, 0]
    changed = np.linalg.norm(out.rig.deltas[0] - res.rig.deltas[0], axis=1) > 0
    assert 0 < changed.sum() <= rep.retreated < rig.n_vertices
    far = np.flatnonzero(target[:, 0] > 3.5)
    assert len(far) > 20 and np.array_equal(out.rig.deltas[0][far], res.rig.deltas[0][far])


def test_template_pairs_stay_allowed_and_excluded_shapes_are_plain():
    rig = two_sheets(gap=0.3, push=0.6)  # the template itself pushes through: those pairs are meant
    assert len(intersecting_pairs(rig.neutral + rig.deltas[0], rig.faces)) > 0
    res = contact_transfer(rig, rig.neutral)  # onto itself: the plain result is the template shape
    assert res.ok and res.shapes[0].constrained_pairs == 0
    assert np.allclose(res.rig.deltas, rig.deltas, atol=1e-9)
    target = stretched(rig.neutral)
    target = stretched(rig.neutral, gap=0.6)  # the top sheet stays 0.3 above the bottom one
    ex = contact_transfer(rig, target, exclude=["push"])
    plain = DeformationTransfer(rig, target).transfer()
    assert ex.shapes[0].excluded and np.array_equal(ex.rig.deltas[0], plain.deltas[0])
    assert "excluded" in ex.table()


def test_pairs_intersecting_in_the_target_neutral_stay_allowed():
    rig = two_sheets()
    target = stretched(rig.neutral)
    # dip one corner of the top sheet through the bottom sheet in the target neutral
    corner = np.flatnonzero((target[:, 0] < 0.5) & (target[:, 1] > 1.0) & (target[:, 1] < 2.2) & (target[:, 2] > 0.1))
    target[corner, 2] = -0.2
    at_rest = intersecting_pairs(target, rig.faces)
    assert len(at_rest) > 0
    with pytest.raises(InputError, match=r"target neutral: expected no intersecting triangle pairs beyond the "
                                         r"template neutral's, found \d+ \(triangles \(\d+, \d+\)"):
        contact_transfer(rig, target)
    res = contact_transfer(rig, target, allow_target_pairs=True)
    assert res.ok and new_count(rig, target, res.rig.deltas, res.rig.names) == [0, 0]


def test_transfer_contact_keeps_a_targets_own_intersections_by_default(tmp_path, capsys):
    """A target neutral that intersects itself (as scans and sculpted heads often do): by default its
    pairs are kept as they are, one line says how many and where, and no new pair appears; with
    --contact-strict the target is refused before any solving."""
    from facebasis.cli import main
    from facebasis.geometry.meshio import read_mesh, write_mesh
    from facebasis.geometry.rig import write_rig_folder

    rig = two_sheets()
    target = stretched(rig.neutral)
    corner = np.flatnonzero((target[:, 0] < 0.5) & (target[:, 1] > 1.0) & (target[:, 1] < 2.2) & (target[:, 2] > 0.1))
    target[corner, 2] = -0.2
    write_rig_folder(tmp_path / "rig", rig)
    write_mesh(tmp_path / "target.obj", target, rig.faces)
    target = read_mesh(tmp_path / "target.obj")[0]  # as the command reads them (10 decimals)
    own = new_pairs(target, rig.faces, (read_mesh(tmp_path / "rig" / "neutral.obj")[0],))
    assert len(own) > 0
    argv = ["transfer", "--template", str(tmp_path / "rig"), "--target", str(tmp_path / "target.obj"), "--contact"]
    assert main(argv + ["--contact-strict", "--out", str(tmp_path / "strict")]) == 2
    assert "expected no intersecting triangle pairs beyond the template neutral's" in capsys.readouterr().err
    assert not (tmp_path / "strict").exists()
    assert main(argv + ["--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    said = [line for line in err.splitlines() if line.startswith("contact: the target neutral")]
    assert len(said) == 1 and f"in {len(own)} triangle pair(s)" in said[0] and "kept as they are" in said[0]
    names = [n for n in rig.names]
    deltas = np.stack([read_mesh(tmp_path / "out" / f"{n}.obj")[0] - target for n in names])
    assert new_count(rig, target, deltas, names) == [0] * len(names)


def test_errors():
    rig = two_sheets()
    with pytest.raises(InputError, match=r"contact exclude: expected shape names of the template .*found unknown 'nope'"):
        contact_transfer(rig, rig.neutral, exclude=["nope"])
    with pytest.raises(InputError, match=r"contact: expected a mesh of at most 100 vertices .* found 210"):
        contact_transfer(rig, rig.neutral, max_vertices=100)
    with pytest.raises(InputError, match=r"contact margin: expected a positive distance, found -1"):
        contact_transfer(rig, rig.neutral, margin=-1.0)


def test_fast_search_matches_the_exact_counter():
    rng = np.random.default_rng(3)
    rig = two_sheets(gap=0.3, push=0.7)
    V = rig.neutral + rig.deltas[0] + 0.02 * rng.standard_normal(rig.neutral.shape)
    assert np.array_equal(new_pairs(V, rig.faces), intersecting_pairs(V, rig.faces))
    sel = np.zeros(len(rig.faces), bool)
    sel[rng.choice(len(rig.faces), 40, replace=False)] = True
    full = intersecting_pairs(V, rig.faces)
    assert np.array_equal(new_pairs(V, rig.faces, faces=sel), full[sel[full].any(1)])
    assert len(candidate_pairs(V, rig.faces, faces=sel)) <= len(candidate_pairs(V, rig.faces))


def test_triangle_distance_and_separating_direction():
    rng = np.random.default_rng(0)
    T1 = rng.normal(size=(200, 3, 3))
    T2 = rng.normal(size=(200, 3, 3)) + 3 * rng.normal(size=(200, 1, 3))
    disjoint = ~triangle_pairs_intersect(T1, T2)
    d, n = triangle_distance(T1[disjoint], T2[disjoint])
    # the plane normal to n separates the triangles with margin exactly d
    gap = np.einsum("pkx,px->pk", T1[disjoint], n).min(1) - np.einsum("pkx,px->pk", T2[disjoint], n).max(1)
    assert np.allclose(gap, d, atol=1e-12)
    # no sampled pair of points is closer than d
    u = rng.random((400, 2))
    w = np.c_[1 - u.sum(1), u][u.sum(1) <= 1]
    P1 = np.einsum("sk,pkx->psx", w, T1[disjoint])
    P2 = np.einsum("sk,pkx->psx", w, T2[disjoint])
    sampled = np.sqrt(((P1[:, :, None] - P2[:, None]) ** 2).sum(-1)).min(axis=(1, 2))
    assert np.all(sampled >= d - 1e-12)


def test_cli_transfer_with_contact(tmp_path, capsys):
    """`facebasis transfer --contact`: the pushed sheet stays apart (checked with the package's exact
    counter on the written files), an excluded shape (repeated flag) is written as plain transfer,
    and the command says what the exact check found."""
    from facebasis.cli import main
    from facebasis.contact.penetration import penetration_report
    from facebasis.geometry.meshio import read_mesh, write_mesh
    from facebasis.geometry.rig import write_rig_folder

    rig = two_sheets()
    target = stretched(rig.neutral)
    write_rig_folder(tmp_path / "template", rig)
    write_mesh(tmp_path / "target.obj", target, rig.faces)
    base = ["transfer", "--template", str(tmp_path / "template"), "--target", str(tmp_path / "target.obj")]
    assert main(base + ["--out", str(tmp_path / "plain")]) == 0
    assert main(base + ["--out", str(tmp_path / "contact"), "--contact"]) == 0
    out = capsys.readouterr().out
    assert "exact check: no transferred shape has a triangle pair intersecting" in out
    V_plain, F = read_mesh(tmp_path / "plain" / "push.obj")
    V_contact, _ = read_mesh(tmp_path / "contact" / "push.obj")
    refs = [target, rig.neutral + rig.deltas[0]]
    assert len(penetration_report(V_plain, F, refs).new) > 0
    assert len(penetration_report(V_contact, F, refs).new) == 0
    import json

    record = json.loads((tmp_path / "contact" / "contact.json").read_text())  # the verdict kept with the shapes
    push = next(r for r in record["shapes"] if r["name"] == "push")
    assert record["ok"] is True and record["excluded"] == [] and push["plain_new_pairs"] > 0
    assert push["new_pairs_left"] == 0 and push["constrained_pairs"] > 0 and push["min_distance"] > 0
    assert not (tmp_path / "plain" / "contact.json").exists()
    assert main(base + ["--out", str(tmp_path / "excluded"), "--contact", "--contact-exclude", "push",
                        "--contact-exclude", "still"]) == 0
    assert np.allclose(read_mesh(tmp_path / "excluded" / "push.obj")[0], V_plain, atol=1e-9)
    excl = json.loads((tmp_path / "excluded" / "contact.json").read_text())
    assert sorted(excl["excluded"]) == ["push", "still"]
    capsys.readouterr()
    assert main(base + ["--out", str(tmp_path / "x"), "--contact-exclude", "push"]) == 2
    assert "expected --contact as well" in capsys.readouterr().err
    assert main(base + ["--out", str(tmp_path / "x"), "--contact", "--contact-exclude", "pull"]) == 2
    assert "--contact-exclude: unknown blendshape names ['pull']" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_rig_cli_contact_generated_shapes_have_no_new_pairs(tmp_path, capsys):
    """``rig --contact``: every generated shape is checked exactly against the target neutral and the
    template shape; flags are validated before any work."""
    from conftest import write_rig_inputs
    from facebasis.cli import main
    from facebasis.geometry.rig import load_rig_folder
    from facebasis.rigging.synthetic import default_face_problem

    pp = default_face_problem(seed=0, n_train=6)
    root = write_rig_inputs(tmp_path, pp)
    base = ["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"), "--examples",
            str(root / "examples"), "--weights", str(root / "weights.json"), "--iterations", "2"]
    assert main(base + ["--out", str(tmp_path / "x"), "--contact-exclude", "jawOpen"]) == 2
    assert "expected --contact as well" in capsys.readouterr().err
    assert main(base + ["--out", str(tmp_path / "y"), "--contact", "--contact-exclude", "noSuchShape"]) == 2
    assert "noSuchShape" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    code = main(base + ["--out", str(tmp_path / "run"), "--contact"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "exact check: no generated shape" in out
    # per shape: solve-and-check rounds, solver iterations and the smallest distance kept
    assert "rounds" in out and "QP it" in out and "min dist" in out
    import json

    record = json.loads((tmp_path / "run" / "contact.json").read_text())
    assert record["ok"] is True and len(record["shapes"]) == pp.problem.template.n_shapes
    assert all(r["new_pairs_left"] == 0 for r in record["shapes"]) and record["seconds"]["total"] > 0
    template = load_rig_folder(root / "template")
    gen = load_rig_folder(tmp_path / "run")
    assert set(gen.names) == set(template.names)
    for name, D in zip(gen.names, gen.deltas):
        i = template.names.index(name)
        rep = penetration_report(gen.neutral + D, template.faces,
                                 references=(gen.neutral, template.neutral + template.deltas[i]))
        assert len(rep.new) == 0, name
    # the stored weights are the certified optimum for the corrected blendshapes actually written
    assert main(["verify", str(tmp_path / "run")]) == 0
    assert "certified optimal" in capsys.readouterr().out


def test_rig_cli_contact_bad_inputs(tmp_path, capsys, monkeypatch):
    """``rig --contact`` refuses, before any solving, a target neutral intersecting itself where the
    template does not (naming the pairs) and a mesh too large for the time budget."""
    import facebasis.contact.exact as exact
    from conftest import write_rig_inputs
    from facebasis.cli import main
    from facebasis.geometry.meshio import write_mesh
    from facebasis.rigging.synthetic import default_face_problem

    pp = default_face_problem(seed=0, n_train=6)
    root = write_rig_inputs(tmp_path, pp)
    # the jaw closed beyond the neutral pushes the lower lip through the upper one
    jaw = pp.truth.deltas[pp.truth.names.index("jawOpen")]
    write_mesh(root / "closed.obj", pp.problem.target_neutral - 0.5 * jaw, pp.problem.template.faces)
    base = ["rig", "--template", str(root / "template"), "--examples", str(root / "examples"), "--weights",
            str(root / "weights.json"), "--iterations", "1", "--out", str(tmp_path / "out")]
    assert main(base + ["--target", str(root / "closed.obj"), "--contact", "--contact-strict"]) == 2
    err = capsys.readouterr().err
    assert "closed.obj: expected no intersecting triangle pairs beyond the template neutral's, found" in err
    assert "(triangles (" in err
    assert main(base + ["--target", str(root / "closed.obj"), "--contact", "--contact-strict",
                        "--contact-allow-target-pairs"]) == 2
    assert "--contact-strict: expected it or --contact-allow-target-pairs, found both" in capsys.readouterr().err
    assert main(base + ["--target", str(root / "target.obj"), "--contact-strict"]) == 2
    assert "expected --contact as well" in capsys.readouterr().err
    assert main(base + ["--target", str(root / "target.obj"), "--contact-allow-target-pairs"]) == 2
    assert "expected --contact as well" in capsys.readouterr().err
    monkeypatch.setattr(exact, "MAX_VERTICES", 1000)
    assert main(base + ["--target", str(root / "target.obj"), "--contact"]) == 2
    err = capsys.readouterr().err
    assert "--contact: expected a mesh of at most 1000 vertices for the time budget" in err
    assert f"found {pp.problem.template.n_vertices}; run without --contact" in err
    transfer = ["transfer", "--template", str(root / "template"), "--target", str(root / "target.obj"), "--out",
                str(tmp_path / "out"), "--contact"]
    assert main(transfer) == 2
    assert "--contact: expected a mesh of at most 1000 vertices" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_generate_blendshapes_contact_api():
    """``generate_blendshapes(..., contact=True)``: the Python form of ``rig --contact``; the contact
    inputs are checked before generation, the result carries the ContactResult and certified weights."""
    from facebasis.errors import RigError
    from facebasis.rigging.certify import certify_problem
    from facebasis.rigging.problem import GenerationOptions
    from facebasis.rigging.generation import generate_blendshapes
    from facebasis.rigging.synthetic import default_face_problem
    from facebasis.rigging.weightproblem import WeightProblem

    pp = default_face_problem(seed=0, n_train=6)
    options = GenerationOptions(iterations=1, ipopt="never")
    with pytest.raises(InputError, match="contact_exclude / allow_target_pairs: expected contact=True as well"):
        generate_blendshapes(pp.problem, options, contact_exclude=("jawOpen",))
    with pytest.raises(RigError, match=r"contact_exclude: unknown blendshape names \['noSuchShape'\]"):
        generate_blendshapes(pp.problem, options, contact=True, contact_exclude=("noSuchShape",))
    jaw = pp.truth.deltas[pp.truth.names.index("jawOpen")]
    closed = dataclasses.replace(pp.problem, target_neutral=pp.problem.target_neutral - 0.5 * jaw)
    with pytest.raises(InputError, match="contact: target neutral: expected no intersecting triangle pairs"):
        generate_blendshapes(closed, options, contact=True)
    res = generate_blendshapes(pp.problem, options, contact=True)
    assert res.contact is not None and res.contact.ok
    template = pp.problem.template
    for name, D in zip(res.rig.names, res.rig.deltas):
        i = template.names.index(name)
        rep = penetration_report(res.rig.neutral + D, template.faces,
                                 references=(res.rig.neutral, template.neutral + template.deltas[i]))
        assert len(rep.new) == 0, name
    # the weights are the certified optimum of the final weight step for the corrected shapes
    names = list(template.names)
    pairs = [(names.index(a), names.index(b)) for a, b in pp.problem.exclusive]
    free = np.array([n not in res.unobserved for n in names])
    problem = WeightProblem.from_rig(res.rig, pp.problem.examples, pairs, pp.problem.initial_weights,
                                     options.schedule()[-1][1])
    best = certify_problem(problem, free=free)
    np.testing.assert_allclose(res.weights, best.X, atol=1e-12)
    assert problem.complementarity(res.weights).max() == 0.0 and problem.bounds(res.weights).max() == 0.0


def test_cli_verdict_names_shapes_pulled_back_by_the_last_resort(capsys):
    """The command says which shapes the last resort pulled back, and still reports the exact check."""
    from facebasis.cli.exact_contact import contact_verdict as _contact_verdict
    from facebasis.contact.solver import ContactResult, ContactShape

    shapes = (ContactShape("jawOpen", plain_new_pairs=4, retreated=37, retreat_loss=0.125),
              ContactShape("blink", plain_new_pairs=2),
              ContactShape("mouthClose", excluded=True))
    assert _contact_verdict(ContactResult(None, None, shapes), "transferred", ("mouthClose",)) == 0
    captured = capsys.readouterr()
    assert "left pairs in 1 shape(s)" in captured.err and "jawOpen (37 vertices, 12.5% of its delta)" in captured.err
    assert "blink" not in captured.err
    assert "exact check: no transferred shape" in captured.out and "(excluded: mouthClose)" in captured.out
    left = (ContactShape("jawOpen", plain_new_pairs=4, new_pairs_left=2),)
    assert _contact_verdict(ContactResult(None, None, left), "transferred", ()) == 1
    assert "CONTACT NOT MET: 1 shape(s)" in capsys.readouterr().err
