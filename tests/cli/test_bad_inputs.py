"""A corpus of malformed inputs for every command: each is a one-line error on stderr, exit status 2,
raised before any work, and nothing is written.

Each case is (command line, a fragment the one-line message must contain). ``{d}`` is a folder of
valid inputs (a rig folder, a target, examples, weights, a capture folder, a cartoon, a frame
folder) that every case shares; ``{o}`` is an output path that must not appear.
"""

import json
import shlex

import numpy as np
import pytest

from facebasis.cli import main

CASES = [
    # the parser itself
    ("nosuch", "invalid choice: 'nosuch'"),
    ("rig --iterations abc --template {d}/template", "argument --iterations: invalid int value: 'abc'"),
    ("transfer --target {d}/target.obj --out {o}", "the following arguments are required: --template"),
    # transfer
    ("transfer --template {d}/nope --target {d}/target.obj --out {o}", "expected a folder of meshes, found no such folder"),
    ("transfer --template {d}/template --target {d}/nope.obj --out {o}", "nope.obj: expected a mesh file, found no such file"),
    ("transfer --template {d}/template --target {d}/bad.obj --out {o}", "bad.obj: expected 4497 vertices"),
    ("transfer --template {d}/template --target {d}/empty.obj --out {o}", "empty.obj: expected a mesh, found an empty file"),
    ("transfer --template {d}/template --target {d}/target.txt --out {o}", "expected a mesh file ending in .obj or .ply"),
    ("transfer --template {d}/template --neutral other.obj --target {d}/target.obj --out {o}", "expected the neutral 'other.obj'"),
    ("transfer --template {d}/template --exclude 'identiy*' --exclude jawOpen --target {d}/target.obj --out {o}", "expected every --exclude pattern to match a mesh file, found none for 'identiy*' (mesh files there:"),
    ("transfer --template {d}/template --target {d}/target.obj --out {d}/afile", "expected a folder or a new path, found a file"),
    ("transfer --template {d}/template --target {d}/target.obj --virtual-edges {d}/nope.json --out {o}", "expected a virtual-edges JSON file"),
    ("transfer --template {d}/template --target {d}/target.obj --virtual-edges --virtual-weight -1 --out {o}", "expected a positive number, found -1"),
    ("transfer --template {d}/template --target {d}/target.obj --virtual-mode sideways --out {o}", "invalid choice: 'sideways'"),
    ("transfer --template {d}/template --target {d}/target.obj --virtual-weight 2 --out {o}", "--virtual-weight: expected --virtual-edges as well, found none"),
    ("rig {rig} --virtual-mode gradient --virtual-weight 3", "--virtual-weight, --virtual-mode: expected --virtual-edges as well, found none"),
    # rig
    ("rig {rig} --alpha big", "--alpha: expected two numbers FIRST,LAST, found 'big'"),
    ("rig {rig} --alpha 1,2,3", "--alpha: expected two numbers FIRST,LAST, found '1,2,3'"),
    ("rig {rig} --lambda x,1", "--lambda: expected two numbers FIRST,LAST, found 'x,1'"),
    ("rig {rig} --iterations 0", "error: --iterations: expected >= 1, found 0"),
    ("rig {rig} --support 2", "error: --support: expected a rough weight in [0, 1], found 2"),
    ("rig {rig} --alpha 0,1", "error: --alpha: expected values > 0, found (0.0, 1.0)"),
    ("rig {rig} --exclusive jawOpen", "--exclusive: expected SHAPE_A:SHAPE_B, found 'jawOpen'"),
    ("rig {rig} --exclusive jawOpen:jawShut", "unknown blendshape names ['jawShut']"),
    ("rig {rig} --exclusive jawOpen:jawOpen", "expected two different shapes, found one twice"),
    ("rig {rig} --alpha auto --cv-candidates warm", "--cv-candidates: invalid choice: 'warm'"),
    ("rig {rig} --cv-grid 0.1", "--cv-grid: expected --alpha auto as well (cross-validation chooses alpha only then), found --alpha 0.5,0.1"),
    ("rig {rig} --alpha 1,0.2 --cv-folds 3 --cv-candidates cold", "--cv-folds, --cv-candidates: expected --alpha auto as well"),
    ("rig {rig} --contact-allow-target-pairs", "--contact-allow-target-pairs: expected --contact as well, found none"),
    ("rig {rig} --contact-strict", "--contact-strict: expected --contact as well, found none"),
    ("transfer --template {d}/template --target {d}/target.obj --contact-strict --contact-exclude jawOpen --out {o}", "--contact-exclude, --contact-strict: expected --contact as well, found none"),
    ("rig {rig} --contact --contact-exclude noSuchShape", "noSuchShape"),
    ("transfer --template {d}/template --target {d}/target.obj --contact-allow-target-pairs --out {o}", "expected --contact as well"),
    ("rig --template {d}/template --target {d}/target.obj --examples {d}/nope --weights {d}/weights.json --out {o}", "expected a folder of meshes, found no such folder"),
    ("rig --template {d}/template --target {d}/target.obj --examples {d}/examples --weights {d}/nope.json --out {o}", "expected a weights JSON file, found no such file"),
    ("rig --template {d}/template --target {d}/target.obj --examples {d}/examples --weights {d}/notjson.json --out {o}", "expected a weights JSON file, found invalid JSON"),
    ("rig --template {d}/template --target {d}/target.obj --examples {d}/examples --weights {d}/list.json --out {o}", "expected a JSON object {example: {shape: weight}}, found list"),
    # output folders that are not ours to replace (an input, a folder holding one, an empty path)
    ("transfer --template {d}/template --target {d}/target.obj --out {d}/template", "/template: expected an output apart from the inputs, found the input"),
    ("transfer --template {d}/template --target {d}/target.obj --out {d}", "found a folder holding the input"),
    ("transfer --template {d}/template --target {d}/target.obj --out ''", "--out: expected an output folder path, found an empty string"),
    ("rig --template {d}/template --target {d}/target.obj --examples {d}/examples --weights {d}/weights.json --out {d}/examples", "expected an output apart from the inputs, found the input"),
    ("transfer --template {d}/template --target {d}/target.obj --out {d}/afile/out", "/afile/out: expected a folder path, found the file"),
    ("transfer --template {d}/template --target {d}/target.obj --out {d}/userfolder", "/userfolder: expected a new or empty folder or a previous facebasis output (with its .facebasis-output file), found a folder holding notes.txt"),
    # rig options a resumed run takes from the run, contradictory options, inputs that would be dropped
    ("rig --resume {d}/template --examples {d}/examples --weights {d}/weights.json --ipopt never --out {o}", "--resume: expected the run's own schedule and pairs, found --ipopt"),
    ("rig --resume {d}/contactrun --examples {d}/examples --weights {d}/weights.json --out {o}", "expected a run made without --contact, found contact.json"),
    ("rig {rig} --unobserved fit --support 0.5", "--support 0.5: expected --unobserved transfer"),
    ("rig --template {d}/template --target {d}/target.obj --examples {d}/examples --weights {d}/dupkeys.json --out {o}", "with each key once, found 'ex00' twice"),
    ("transfer --template {d}/template --target {d}/utf16.obj --out {o}", "utf16.obj: expected an ASCII/UTF-8 OBJ file, found UTF-16 text"),
    # verify and export
    ("verify {d}/template --tolerance -1", "--tolerance: expected a relative gap >= 0, found -1"),
    ("verify {d}/template", "expected inputs.json (written by `facebasis rig`), found no such file"),
    ("verify {d}/nope", "expected inputs.json"),
    ("export {d}/template --out {d}/template", "found the input"),
    ("export {d}/template --out {d}/userfolder", "expected a file name, found a folder"),
    ("export {d}/nope --out {o}.glb", "expected a folder of meshes, found no such folder"),
    # virtual edges, penetration
    ("virtual-edges {d}/nope.obj --out {o}.json", "nope.obj: expected a mesh file, found no such file"),
    ("virtual-edges {d}/target.obj --region 9:x --out {o}.json", "region"),
    ("penetration {d}/target.obj --reference {d}/bad.obj", "bad.obj: expected 4497 vertices"),
    ("penetration {d}/target.obj --rest {d}/target.obj --local-within -2", "--local-within: expected a positive number of edge lengths, found -2"),
    # report, sweep
    ("report {d}/nope", "nope"),
    ("report {d}/empty.csv", "empty.csv"),
    ("sweep --study nosuch --out {o}.csv", "nosuch"),
    ("sweep --seeds a,b --out {o}.csv", "--seeds"),
    # capture
    ("capture {d}/nope.mp4 --landmarks {d}/first.pts --out {o}", "nope.mp4"),
    ("capture {d}/frames --out {o}", "--landmarks"),
    ("capture {d}/frames --landmarks {d}/first.pts --detector dlib --out {o}", "--detector"),
    ("capture {d}/frames --landmarks {d}/header68.pts --out {o}", "header68.pts"),
    ("capture {d}/frames --landmarks {d}/outside.pts --out {o}", "outside"),
    ("capture {d}/frames --landmarks {d}/first.pts --max-frames 0 --out {o}", "--max-frames"),
    ("capture {d}/noframes --landmarks {d}/first.pts --out {o}", "noframes"),
    ("capture {d}/frames --landmarks {d}/first.pts --out {d}/afile", "afile"),
    ("capture {d}/notvideo.mp4 --landmarks {d}/first.pts --out {o}", "notvideo.mp4"),
    ("capture {d}/frames --landmarks {d}/first.pts --inner-lips open --out {o}", "--inner-lips"),
    ("capture {d}/frames --detector opencv --out {o}", "--detector: expected one of dlib, mediapipe, found 'opencv'"),
    ("landmarks {d}/nope.mp4 --out {o}.pts", "nope.mp4: expected a video file, an image or an image folder"),
    ("landmarks {d}/frames --out {o}.txt", "--out: expected a file name ending in .pts"),
    ("landmarks {d}/frames --frame -2 --out {o}.pts", "--frame: expected a frame number >= 0, found -2"),
    ("landmarks {d}/frames --detector opencv --out {o}.pts", "--detector: expected one of dlib, mediapipe, found 'opencv'"),
    # reproduction
    ("animate2d {d}/template --out {o}", "track.npz"),
    ("animate2d {d}/capture --image {d}/cartoon.png --out {o}", "--image and --landmarks"),
    ("animate2d {d}/capture --image {d}/cartoon.png --landmarks {d}/short.pts --out {o}", "short.pts"),
    ("animate2d {d}/capture --image {d}/notimage.png --landmarks {d}/first.pts --out {o}", "notimage.png"),
    ("animate3d {d}/capture --mesh {d}/target.obj --landmarks {d}/short_idx.json --out {o}", "short_idx.json"),
    ("animate3d {d}/capture --mesh {d}/target.obj --landmarks {d}/far_idx.json --out {o}", "far_idx.json"),
    ("retarget {d}/capture --exclusive jawOpen:smileBig --out {o}", "smileBig"),
    ("retarget {d}/capture --identity person --out {o}", "--identity"),
    ("retarget {d}/capture --identity rig --first-frame-neutral --out {o}", "--first-frame-neutral: expected no other --identity, found --identity rig"),
    ("retarget {d}/capture --rig {d}/template --landmarks {d}/far_idx.json --out {o}", "far_idx.json"),
    ("retarget {d}/capture --smooth -1 --out {o}", "--smooth"),
    ("retarget {d}/capture --ridge nan --out {o}", "--ridge: expected a finite number >= 0, found nan"),
    ("retarget {d}/nope --out {o}", "nope"),
    # registration
    ("register {d}/nope.obj --template {d}/target.obj --out {o}", "nope.obj"),
    ("register {d}/target.obj --template {d}/nope.obj --out {o}", "nope.obj"),
    ("register {d}/points.obj --template {d}/target.obj --out {o}", "points.obj"),
    ("register {d}/target.obj --template {d}/target.obj --landmarks {d}/lm3.json {d}/lm4.json --out {o}", "lm"),
    ("register {d}/target.obj --template {d}/target.obj --landmarks {d}/lm3.json {d}/far3.json --out {o}", "far3.json"),
    ("register {d}/huge.obj --template {d}/target.obj --out {o}", "scale"),
    ("register {d}/target.obj --template {d}/target.obj --out {d}/afile", "afile"),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    from PIL import Image

    from facebasis.capture.synthetic import synthetic_sequence
    from facebasis.capture.trackfile import write_capture
    from facebasis.defaults.face import default_person, default_template
    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import write_rig_folder
    from facebasis.retarget.files import write_pts
    from facebasis.retarget.synthetic import capture_from_landmarks

    d = tmp_path_factory.mktemp("inputs")
    t, person = default_template(), default_person()
    write_rig_folder(d / "template", t)
    write_mesh(d / "target.obj", person.neutral, person.faces)
    write_mesh(d / "bad.obj", person.neutral[:-3], person.faces[:50])
    (d / "empty.obj").write_bytes(b"")
    (d / "target.txt").write_text("not a mesh")
    (d / "afile").write_text("a file where a folder is expected")
    (d / "examples").mkdir()
    write_mesh(d / "examples" / "ex00.obj", person.neutral + person.deltas[0], person.faces)
    (d / "weights.json").write_text(json.dumps({"ex00": {"jawOpen": 1.0}}))
    (d / "notjson.json").write_text("{not json")
    (d / "list.json").write_text("[1, 2]")
    (d / "dupkeys.json").write_text('{"ex00": {"jawOpen": 1.0}, "ex00": {"jawOpen": 0.5}}')
    (d / "utf16.obj").write_bytes("\ufeffv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("utf-16"))
    (d / "userfolder").mkdir()
    (d / "userfolder" / "notes.txt").write_text("the user's own file")
    (d / "contactrun").mkdir()
    (d / "contactrun" / "contact.json").write_text("{}")
    (d / "empty.csv").write_text("")
    (d / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    write_mesh(d / "huge.obj", person.neutral * 1000.0, person.faces)
    (d / "lm3.json").write_text(json.dumps([0, 100, 200]))
    (d / "lm4.json").write_text(json.dumps([0, 100, 200, 300]))
    (d / "far3.json").write_text(json.dumps([0, 100, 10 ** 7]))
    seq = synthetic_sequence(3, size=(96, 96))
    (d / "frames").mkdir()
    for i, f in enumerate(seq.frames):
        Image.fromarray(f).save(d / "frames" / f"f{i}.png")
    (d / "noframes").mkdir()
    (d / "notvideo.mp4").write_text("not a video")
    write_pts(d / "first.pts", seq.landmarks[0])
    write_pts(d / "short.pts", seq.landmarks[0][:60])
    text = (d / "short.pts").read_text()
    (d / "header68.pts").write_text(text.replace("n_points: 60", "n_points: 68"))  # header and body disagree
    write_pts(d / "outside.pts", seq.landmarks[0] + 500)
    write_capture(d / "capture", capture_from_landmarks(seq.landmarks, fps=25, size=(96, 96)))
    Image.fromarray(seq.frames[0]).save(d / "cartoon.png")
    (d / "notimage.png").write_text("not an image")
    (d / "short_idx.json").write_text(json.dumps(list(range(60))))
    (d / "far_idx.json").write_text(json.dumps([10 ** 6] * 68))
    return d


def _snapshot(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("line,fragment", CASES, ids=[c[0][:60] for c in CASES])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(inputs, tmp_path, capsys, line, fragment):
    d, o = inputs, tmp_path / "out"
    rig = (f"--template {d}/template --target {d}/target.obj --examples {d}/examples "
           f"--weights {d}/weights.json --out {o}")
    argv = shlex.split(line.format(d=d, o=o, rig=rig))
    before = _snapshot(d)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert fragment in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == [], "an output was written"
    assert _snapshot(d) == before, "an input folder changed"


def test_the_corpus_covers_every_command():
    from facebasis.cli import build_parser

    commands = {c[0].split()[0] for c in CASES}
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert set(sub.choices) - {"demo"} <= commands, sorted(set(sub.choices) - commands)
    assert np.all([len(c) == 2 for c in CASES])


@pytest.mark.parametrize("out", [".", "..", ""])
def test_the_current_folder_and_those_above_are_never_replaced(inputs, tmp_path, monkeypatch, capsys, out):
    """``--out .`` (or an unset variable: ``--out ""``) would replace the folder the user stands in."""
    here = tmp_path / "work" / "here"
    here.mkdir(parents=True)
    (here / "precious.txt").write_text("keep me")
    monkeypatch.chdir(here)
    d = inputs
    code = main(["transfer", "--template", str(d / "template"), "--target", str(d / "target.obj"), "--out", out])
    err = capsys.readouterr().err
    assert code == 2 and ("current folder" in err or "folder above the current one" in err), err
    assert (here / "precious.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["here", "precious.txt", "work"]


def test_an_output_folder_is_replaced_only_when_empty_or_written_by_facebasis(inputs, tmp_path, capsys):
    d = inputs
    base = ["transfer", "--template", str(d / "template"), "--target", str(d / "target.obj"), "--out"]
    (tmp_path / "empty").mkdir()
    assert main(base + [str(tmp_path / "empty")]) == 0  # an empty folder: used
    assert (tmp_path / "empty" / ".facebasis-output").is_file() and (tmp_path / "empty" / "jawOpen.obj").is_file()
    assert main(base + [str(tmp_path / "empty")]) == 0  # a previous output: replaced
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("years of work")
    capsys.readouterr()
    assert main(base + [str(tmp_path / "mine")]) == 2
    assert "found a folder holding thesis.tex" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["thesis.tex"]
