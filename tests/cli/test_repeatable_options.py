"""Every repeatable option of every command keeps every value it is given.

A constraint toolkit that silently drops a constraint is broken: ``--exclusive A:B --exclusive C:D``
once kept only C:D (argparse's ``store`` with ``nargs``). These tests parse every repeatable
option repeated, guard against the ``store``-with-``nargs`` pattern anywhere in the parser, and
run the commands end to end with repeated flags.
"""

import argparse
import json

import numpy as np
import pytest

from facebasis.cli import build_parser, main
from facebasis.defaults.face import default_person, default_template
from facebasis.geometry.meshio import write_mesh
from facebasis.geometry.rig import load_rig_folder, write_rig_folder
from facebasis.rigging.synthetic import default_face_problem

from conftest import write_rig_inputs

from facebasis.cli.common import Once

REPEATABLE = (argparse._AppendAction, argparse._ExtendAction)


def _subparsers(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def _options(sub):
    return [a for a in sub._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]


def test_no_option_takes_several_values_and_keeps_only_the_last():
    """An option that takes a list (nargs '*'/'+'/N) must append or extend, never store: with
    ``store`` a repeated flag overwrites the earlier values without a word."""
    offenders = []
    for name, sub in _subparsers(build_parser()):
        for a in _options(sub):
            takes_list = a.nargs in ("*", "+") or isinstance(a.nargs, int) and a.nargs > 1
            if takes_list and not isinstance(a, REPEATABLE + (Once,)):
                offenders.append(f"{name} {a.option_strings[0]}")
    assert offenders == []


def test_an_option_taken_once_refuses_a_second_time(capsys):
    """``register --landmarks SCAN TEMPLATE`` is a pair: a second pair is an error, not an overwrite."""
    from facebasis.cli import main

    line = ["register", "s.obj", "--template", "t.obj", "--out", "o", "--landmarks", "a.json", "b.json",
            "--landmarks", "c.json", "d.json"]
    with pytest.raises(SystemExit) as exc:
        main(line)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "argument --landmarks: expected once, found it given twice" in err


# minimal valid command lines, to which a repeatable option is added twice
BASE = {
    "transfer": ["transfer", "--template", "T", "--target", "t.obj", "--out", "o"],
    "rig": ["rig", "--template", "T", "--target", "t.obj", "--examples", "E", "--weights", "w.json",
            "--out", "o"],
    "penetration": ["penetration", "m.obj"],
    "export": ["export", "R", "--out", "r.glb"],
    "verify": ["verify", "RUN"],
    "retarget": ["retarget", "CAP", "--out", "o"],
    "animate3d": ["animate3d", "CAP", "--out", "o"],
}


def _repeatable_options():
    found = []
    for name, sub in _subparsers(build_parser()):
        for a in _options(sub):
            if isinstance(a, REPEATABLE):
                found.append((name, a.option_strings[0], a.dest))
    return found


def test_every_repeatable_option_is_listed_here():
    """A new repeatable option must get a base command line above (and so the tests below)."""
    assert {cmd for cmd, _, _ in _repeatable_options()} <= set(BASE)
    assert len(_repeatable_options()) >= 6


@pytest.mark.parametrize("command,flag,dest", _repeatable_options())
def test_repeated_flag_keeps_every_value(command, flag, dest):
    values = ["a1:b1", "a2:b2", "a3:b3"]
    parser = build_parser()
    repeated = parser.parse_args(BASE[command] + [flag, values[0], flag, values[1], flag, values[2]])
    assert getattr(repeated, dest) == values
    action = next(a for a in _subparsers(parser) if a[0] == command)[1]
    act = next(a for a in _options(action) if a.option_strings[0] == flag)
    if isinstance(act, argparse._ExtendAction):  # several values after one flag, mixed with repeats
        mixed = parser.parse_args(BASE[command] + [flag, values[0], values[1], flag, values[2]])
        assert getattr(mixed, dest) == values


@pytest.fixture(scope="module")
def rig_inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("rig_rep")
    pp = default_face_problem(seed=0, n_train=6)
    return write_rig_inputs(root, pp), pp


def _rig(root, out, *extra):
    return ["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
            "--examples", str(root / "examples"), "--weights", str(root / "weights.json"),
            "--out", str(root / out), "--iterations", "2", *extra]


PAIRS = [("mouthLeft", "mouthRight"), ("eyeBlink_L", "eyeWide_L"), ("mouthSmile_L", "mouthFrown_L"),
         ("jawOpen", "mouthPucker")]


def test_rig_keeps_every_exclusive_pair_given_in_any_form(rig_inputs, capsys):
    root, pp = rig_inputs
    names = pp.problem.template.names
    missing = [s for p in PAIRS for s in p if s not in names]
    assert not missing, missing
    flags = ["--exclusive", "mouthLeft:mouthRight", "--exclusive", "eyeBlink_L:eyeWide_L", "mouthSmile_L:mouthFrown_L",
             "--exclusive", "jawOpen:mouthPucker", "--exclusive", "mouthRight:mouthLeft"]  # a repeat, reversed
    assert main(_rig(root, "rep", *flags)) == 0
    out = capsys.readouterr().out
    assert "4 exclusive pairs: mouthLeft:mouthRight, eyeBlink_L:eyeWide_L, mouthSmile_L:mouthFrown_L, " \
           "jawOpen:mouthPucker (1 repeated pair(s) merged)" in out
    run = root / "rep"
    inputs = json.loads((run / "inputs.json").read_text())
    history = json.loads((run / "history.json").read_text())
    assert [tuple(p) for p in inputs["exclusive"]] == PAIRS
    assert [tuple(p) for p in history["exclusive"]] == PAIRS
    w = json.loads((run / "weights.json").read_text())
    for a, b in PAIRS:  # every pair holds in the stored weights, not only the last one given
        assert max(row.get(a, 0.0) * row.get(b, 0.0) for row in w.values()) <= 1e-8
    # verify re-solves with all four pairs and certifies
    assert main(["verify", str(run)]) == 0
    vout = capsys.readouterr().out
    assert "4 exclusive pairs" in vout and "certified optimal" in vout


def test_verify_reports_pairs_named_at_verify_time(rig_inputs, capsys):
    """verify --exclusive reports the largest product for each named pair (repeated flag): a pair
    of the run holds, a pair the run did not impose and that the weights breach fails the check."""
    root, _ = rig_inputs
    assert main(_rig(root, "free", "--exclusive", "mouthLeft:mouthRight")) == 0
    run = root / "free"
    w = json.loads((run / "weights.json").read_text())
    shapes = load_rig_folder(run).names
    X = np.array([[w[e].get(s, 0.0) for s in shapes] for e in sorted(w)])
    prod = np.einsum("ji,jk->ik", X, X)  # find a pair that some example uses together
    np.fill_diagonal(prod, 0)
    i, k = np.unravel_index(np.argmax(prod), prod.shape)
    a, b = shapes[i], shapes[k]
    expected = float(np.max(X[:, i] * X[:, k]))
    assert expected > 1e-3
    capsys.readouterr()
    code = main(["verify", str(run), "--exclusive", "mouthRight:mouthLeft", "--exclusive", f"{a}:{b}"])
    assert code == 1
    out, err = capsys.readouterr()
    assert "mouthRight:mouthLeft  0  " in out and "(a constraint of the run)  ok" in out
    assert f"{a}:{b}  {expected:.3g}" in out and "(not a constraint of the run)  BREACHED" in out
    assert f"NOT EXCLUSIVE: the stored weights breach 1 pair(s) named with --exclusive ({a}:{b})" in err
    assert main(["verify", str(run), "--exclusive", "mouthRight:mouthLeft"]) == 0
    capsys.readouterr()
    assert main(["verify", str(run), "--exclusive", "jawOpen:nope"]) == 2
    err = capsys.readouterr().err   # the library names its parameter, the command line its flag
    assert err.startswith("error: --exclusive jawOpen:nope: expected names of") and "unknown blendshape names ['nope']" in err


def test_transfer_and_export_keep_every_exclude_glob(tmp_path, capsys):
    write_rig_folder(tmp_path / "template", default_template())
    for extra in ("identity01.obj", "scan_raw.obj"):  # files that are not blendshapes
        write_mesh(tmp_path / "template" / extra, default_template().neutral[:10], default_template().faces[:3])
    write_mesh(tmp_path / "person.obj", default_person().neutral, default_person().faces)
    base = ["transfer", "--template", str(tmp_path / "template"), "--target", str(tmp_path / "person.obj")]
    # with only one of the two globs, the other file is read and rejected
    assert main(base + ["--out", str(tmp_path / "a"), "--exclude", "identity*"]) == 2
    assert "scan_raw.obj" in capsys.readouterr().err
    assert main(base + ["--out", str(tmp_path / "b"), "--exclude", "identity*", "--exclude", "scan_*"]) == 0
    assert main(["export", str(tmp_path / "template"), "--out", str(tmp_path / "r.glb"),
                 "--exclude", "scan_*", "--exclude", "identity*"]) == 0
    assert main(["export", str(tmp_path / "template"), "--out", str(tmp_path / "r2.glb"),
                 "--exclude", "scan_*"]) == 2


def test_penetration_keeps_every_reference(tmp_path, capsys):
    from conftest import grid_sheet

    V, F = grid_sheet(6, 5)
    top = V + [0, 0, 0.05]
    both = np.concatenate([V, top])
    FF = np.concatenate([F, F + len(V)])
    pushed = both.copy()
    centre = np.linalg.norm(V[:, :2] - V[:, :2].mean(0), axis=1) < 0.25
    pushed[len(V):][centre, 2] -= 0.1  # a dent of the top sheet passes through the bottom one
    write_mesh(tmp_path / "m.obj", pushed, FF)
    write_mesh(tmp_path / "r1.obj", both, FF)
    write_mesh(tmp_path / "r2.obj", pushed, FF)
    assert main(["penetration", str(tmp_path / "m.obj"), "--reference", str(tmp_path / "r1.obj")]) == 0
    out1 = capsys.readouterr().out
    assert "new relative to 1 reference(s)" in out1 and "new relative to 1 reference(s): 0" not in out1
    assert main(["penetration", str(tmp_path / "m.obj"), "--reference", str(tmp_path / "r1.obj"),
                 "--reference", str(tmp_path / "r2.obj")]) == 0
    assert "new relative to 2 reference(s): 0" in capsys.readouterr().out


def test_help_is_plain_words():
    """No reST/Markdown markup, no internal paper codes, every option's default a value."""
    for name, sub in _subparsers(build_parser()):
        text = sub.format_help()
        assert "`" not in text and "seed 00" not in text and "DEFAULT_" not in text, name
        assert sub.description, name


def test_a_value_repeated_within_a_repeatable_option_is_kept_once_and_said(tmp_path, capsys):
    """``--contact-exclude jawOpen jawOpen`` and ``--cv-grid 0.1 0.1,0.1`` keep the value once (no
    duplicate candidates, no doubled names) and say so."""
    from facebasis.cli.rig import cv_grid as _cv_grid

    assert _cv_grid(["0.1", "0.1,0.3", "0.1"]) == (0.1, 0.3)
    assert "note: --cv-grid 0.1 given more than once: used once" in capsys.readouterr().err
    t = default_template()
    write_rig_folder(tmp_path / "template", t)
    write_mesh(tmp_path / "person.obj", default_person().neutral, default_person().faces)
    code = main(["transfer", "--template", str(tmp_path / "template"), "--target", str(tmp_path / "person.obj"),
                 "--out", str(tmp_path / "c"), "--contact", "--contact-exclude", "jawOpen", "jawOpen",
                 "--contact-exclude", "mouthPucker"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "note: --contact-exclude jawOpen given more than once: used once" in captured.err
    assert "(excluded: jawOpen, mouthPucker)" in captured.out
    assert sorted(json.loads((tmp_path / "c" / "contact.json").read_text())["excluded"]) == ["jawOpen", "mouthPucker"]


def test_a_once_option_cannot_be_declared_with_a_default():
    """Given once, an option with a default would read as given twice: the declaration is refused."""
    p = argparse.ArgumentParser()
    with pytest.raises(ValueError, match="--pair: a Once option cannot have a default"):
        p.add_argument("--pair", nargs=2, action=Once, default=["a", "b"])
    p.add_argument("--other", nargs=2, action=Once)
    assert p.parse_args([]).other is None and p.parse_args(["--other", "x", "y"]).other == ["x", "y"]
