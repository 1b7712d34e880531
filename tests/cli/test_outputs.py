"""The one output rule: no command changes what a user owns; crashes at any point are recovered.

Every command is pointed at each of its own inputs (the input itself, a folder holding it, a path
inside an input folder) and must refuse with exit 2 before any work, leaving every file as it was.
Run folders beside an output belong to their run by a lock, not a process id; a run killed at any
point of its swap leaves the old output or the new one, and the next run restores or finishes it.
"""

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import facebasis.atomic as atomic
from facebasis.atomic import OUTPUT_MARKER, atomic_directory, atomic_write_bytes, check_output, recover
from facebasis.cli import build_parser, main
from facebasis.errors import InputError


def _snapshot(root: Path) -> dict:
    """Every entry under ``root`` with its bytes' hash (folders and links included)."""
    snap = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = p.relative_to(root).as_posix()
            if p.is_symlink():
                snap[rel] = "link:" + os.readlink(p)
            elif p.is_file():
                snap[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
            else:
                snap[rel] = "dir"
    return snap


# ----------------------------------------------------------------------------------------------
# every command, pointed at each of its own inputs

@pytest.fixture
def owned(tmp_path, monkeypatch):
    """A user's files: folders and files of every kind the commands read (their content does not
    matter: the rule is applied before anything is read)."""
    root = tmp_path / "user"
    for folder in ("rig", "examples", "cap", "frames", "scans", "run"):
        (root / folder).mkdir(parents=True)
        (root / folder / "keep.txt").write_text(f"{folder} data\n")
    (root / "rig" / "neutral.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (root / "cap" / "track.npz").write_bytes(b"not really a track")
    (root / "run" / "history.json").write_text("{}")
    for name in ("target.obj", "mesh.obj", "weights.json", "edges.json", "first.pts", "cartoon.png",
                 "cartoon.pts", "indices.json", "scan_lm.json", "tmpl_lm.json", "results.csv", "clip.mp4"):
        (root / name).write_text(f"{name}\n")
    monkeypatch.chdir(tmp_path)
    return root


#: each command with its inputs as {placeholder: relative path} and its argv with {OUT} for the output
COMMANDS = {
    "demo": ({}, "demo --quick --out {OUT}"),
    "transfer": ({"T": "rig", "N": "target.obj", "E": "edges.json"},
                 "transfer --template {T} --target {N} --virtual-edges {E} --out {OUT}"),
    "rig": ({"T": "rig", "N": "target.obj", "X": "examples", "W": "weights.json", "E": "edges.json"},
            "rig --template {T} --target {N} --examples {X} --weights {W} --virtual-edges {E} --out {OUT}"),
    "rig --resume": ({"R": "run", "X": "examples", "W": "weights.json"},
                     "rig --resume {R} --examples {X} --weights {W} --out {OUT}"),
    "export": ({"R": "rig"}, "export {R} --out {OUT}"),
    "virtual-edges": ({"M": "mesh.obj"}, "virtual-edges {M} --out {OUT}"),
    "report": ({"R": "run"}, "report {R} --out {OUT}"),
    "report csv": ({"C": "results.csv"}, "report {C} --out {OUT}"),
    "sweep": ({}, "sweep --out {OUT}"),
    "register": ({"S": "scans", "T": "target.obj", "A": "scan_lm.json", "B": "tmpl_lm.json"},
                 "register {S} --template {T} --landmarks {A} {B} --out {OUT}"),
    "capture": ({"V": "frames", "L": "first.pts"}, "capture {V} --landmarks {L} --out {OUT}"),
    "landmarks": ({"V": "clip.mp4"}, "landmarks {V} --out {OUT}"),
    "animate2d": ({"C": "cap", "I": "cartoon.png", "L": "cartoon.pts"},
                  "animate2d {C} --image {I} --landmarks {L} --out {OUT}"),
    "animate3d": ({"C": "cap", "M": "mesh.obj", "L": "indices.json"},
                  "animate3d {C} --mesh {M} --landmarks {L} --out {OUT}"),
    "retarget": ({"C": "cap", "R": "rig", "L": "indices.json"},
                 "retarget {C} --rig {R} --landmarks {L} --out {OUT}"),
}
READ_ONLY = {"verify", "penetration"}


def test_every_command_declares_what_it_writes_and_reads_and_is_probed_here():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        spec = p.get_default("outputs")
        assert spec is not None, f"facebasis {name} declares no Outputs (facebasis.cli.outputs)"
        if spec.writes:
            assert any(key.split()[0] == name for key in COMMANDS), f"facebasis {name} is not probed by this test"
        else:
            assert name in READ_ONLY, f"facebasis {name} writes nothing? add it to READ_ONLY"


def _cases():
    for key, (inputs, argv) in COMMANDS.items():
        for ph, rel in inputs.items():
            if (key, ph) != ("rig --resume", "R"):  # `rig --resume RUN --out RUN` updates a run in place
                yield pytest.param(key, ph, "itself", id=f"{key}-{ph}-itself")
            yield pytest.param(key, ph, "holder", id=f"{key}-{ph}-holder")
            if "." not in rel:
                yield pytest.param(key, ph, "inside", id=f"{key}-{ph}-inside")


def _argv(owned, key, out):
    inputs, argv = COMMANDS[key]
    words = argv.split()
    fill = {ph: str(owned / rel) for ph, rel in inputs.items()} | {"OUT": str(out)}
    return [w.format(**fill) for w in words]


@pytest.mark.parametrize("key,ph,where", list(_cases()))
def test_a_command_pointed_at_its_own_input_refuses_before_any_work(owned, key, ph, where, capsys):
    """`retarget cap --out cap`, `register SCAN --template RIG/neutral.obj --out RIG`, `capture
    DIR/frames --out DIR`, `transfer --virtual-edges OUT/edges.json --out OUT`, `virtual-edges
    mesh.obj --out mesh.obj`, `report x.csv --out x.csv`, ...: exit 2, one line naming the input,
    nothing changed."""
    inputs, _ = COMMANDS[key]
    target = owned / inputs[ph]
    out = {"itself": target, "holder": target.parent, "inside": target / "out"}[where]
    if where == "holder" and key.startswith("register") and ph == "S":
        out = owned  # the folder holding the scans folder
    before = _snapshot(owned.parent)
    code = main(_argv(owned, key, out))
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "input" in err, err
    assert _snapshot(owned.parent) == before


def test_two_outputs_of_one_command_are_never_the_same_file(owned, capsys):
    before = _snapshot(owned.parent)
    assert main(["virtual-edges", str(owned / "mesh.obj"), "--out", "e.svg", "--figure", "e.svg"]) == 2
    assert "--figure e.svg: expected an output apart from --out, found the same path" in capsys.readouterr().err
    assert main(["virtual-edges", str(owned / "mesh.obj"), "--out", "e.json", "--figure", str(owned / "cartoon.png")]) == 2
    assert "found an existing file without facebasis's signature" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["virtual-edges", str(owned / "mesh.obj"), "--out", "e.json", "--figure", "e.obj"])
    assert "expected a .png, .pdf or .svg file name" in capsys.readouterr().err
    assert _snapshot(owned.parent) == before


def test_a_run_may_be_resumed_in_place_and_only_that_input_may_be_replaced(owned):
    run = owned / "run"
    (run / OUTPUT_MARKER).write_text("x")  # a previous `facebasis rig` output
    assert check_output(run, [run, owned / "examples"], allow=[run]) == run.resolve()
    with pytest.raises(InputError, match="found the input"):
        check_output(owned / "examples", [run, owned / "examples"], allow=[run])


def test_an_output_inside_a_previous_facebasis_output_is_allowed(owned, capsys):
    """`report RUN` writes RUN/report: a facebasis output folder may hold another output."""
    (owned / "run" / OUTPUT_MARKER).write_text("x")
    check_output(owned / "run" / "report", [owned / "run"])
    with pytest.raises(InputError, match="inside the input folder"):
        check_output(owned / "rig" / "report", [owned / "rig"])


# ----------------------------------------------------------------------------------------------
# the rule's branches, one by one

def test_refusals_name_the_output_and_what_was_found(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "in.obj").write_text("v 0 0 0\n")
    (tmp_path / "user").mkdir()
    (tmp_path / "user" / "notes.txt").write_text("mine")
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError, match="found an empty string"):
        check_output("", kind="folder")
    with pytest.raises(InputError, match="found the current folder"):
        check_output(".", kind="folder")
    with pytest.raises(InputError, match="a folder above the current one"):
        check_output("..", kind="folder")
    with pytest.raises(InputError, match="found a folder holding notes.txt"):
        check_output("user", kind="folder")
    with pytest.raises(InputError, match=r"found the file .*afile in it"):
        check_output("afile/out", kind="folder")
    with pytest.raises(InputError, match="expected a folder or a new path, found a file"):
        check_output("afile", kind="folder")
    with pytest.raises(InputError, match="found the input in.obj itself"):
        check_output("in.obj", ["in.obj"], kind="file")
    with pytest.raises(InputError, match="expected a file name, found a folder"):
        check_output("user", kind="file")
    with pytest.raises(InputError, match="expected an existing folder to write into, found no folder"):
        check_output("missing/rig.glb", kind="file")
    with pytest.raises(InputError, match="an existing file without facebasis's signature"):
        check_output("afile", kind="file", what="--out")
    os.link(tmp_path / "in.obj", tmp_path / "hard.obj")  # another name of the input
    with pytest.raises(InputError, match="found the input in.obj itself"):
        check_output("hard.obj", ["in.obj"], kind="file")
    # allowed: a new path, an empty folder, a previous output, a file facebasis wrote
    (tmp_path / "empty").mkdir()
    (tmp_path / "prev").mkdir()
    (tmp_path / "prev" / OUTPUT_MARKER).write_text("x")
    (tmp_path / "prev" / "old.obj").write_text("x")
    (tmp_path / "edges.json").write_text('{"format": "facebasis.virtual_edges/1", "edges": []}')
    for out, kind in (("new", "folder"), ("empty", "folder"), ("prev", "folder"), ("edges.json", "file"),
                      ("new.glb", "file")):
        check_output(out, ["in.obj"], kind=kind)


@pytest.mark.parametrize("link", ["dangling", "loop", "to a folder"])
def test_a_symbolic_link_as_output_is_refused(tmp_path, link):
    out = tmp_path / "out"
    (tmp_path / "real").mkdir()
    os.symlink({"dangling": tmp_path / "nowhere", "loop": out, "to a folder": tmp_path / "real"}[link], out)
    with pytest.raises(InputError, match="found a symbolic link"):
        check_output(out, kind="folder")


def test_a_file_is_replaced_only_if_facebasis_wrote_it(tmp_path):
    import json

    from facebasis.geometry.gltf import glb_bytes
    from facebasis.defaults.face import default_template

    glb = tmp_path / "rig.glb"
    glb.write_bytes(glb_bytes(default_template()))
    assert atomic.written_by_facebasis(glb)
    (tmp_path / "other.glb").write_bytes(b"glTF" + (2).to_bytes(4, "little") + bytes(12) + b'{"asset":{"generator":"x"}}')
    assert not atomic.written_by_facebasis(tmp_path / "other.glb")
    (tmp_path / "mine.json").write_text(json.dumps({"generator": "someone"}))
    assert not atomic.written_by_facebasis(tmp_path / "mine.json")
    from facebasis.report import studies  # noqa: F401  (registers the results table's header)
    from facebasis.report.studies import table_csv

    (tmp_path / "results.csv").write_text(table_csv([]))
    assert atomic.written_by_facebasis(tmp_path / "results.csv")
    (tmp_path / "user.csv").write_text("a,b\n1,2\n")
    assert not atomic.written_by_facebasis(tmp_path / "user.csv")


def test_report_into_a_users_folder_is_refused_and_report_is_atomic(tmp_path, capsys, monkeypatch):
    """`report` wrote into any folder and overwrote index.md there; now it is an output folder like
    every other: a user's folder is refused, the report is built in staging and swapped in."""
    from facebasis.report.studies import table_csv

    monkeypatch.chdir(tmp_path)
    csv = tmp_path / "results.csv"
    csv.write_text(table_csv([{"study": "alpha", "problem": "default", "seed": 0, "method": "x", "alpha0": 0.1,
                               "alpha1": 0.1, "lam0": 1.0, "lam1": 1.0, "heldout_error": 0.2, "train_error": 0.1}]))
    user = tmp_path / "paper"
    user.mkdir()
    (user / "index.md").write_text("my own notes")
    before = _snapshot(tmp_path)
    assert main(["report", str(csv), "--out", str(user)]) == 2
    assert "found a folder holding index.md" in capsys.readouterr().err
    assert _snapshot(tmp_path) == before
    assert main(["report", str(csv), "--out", str(csv)]) == 2  # its own input
    assert "found the input" in capsys.readouterr().err
    assert _snapshot(tmp_path) == before
    assert main(["report", str(csv), "--formats", "png"]) == 0  # default: results/ beside the CSV
    out = tmp_path / "results"
    assert (out / OUTPUT_MARKER).is_file() and any(out.glob("*.png"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paper", "results", "results.csv"]  # no staging left


# ----------------------------------------------------------------------------------------------
# run folders: owned by a lock, recovered after a kill at any point

_CHILD = textwrap.dedent("""
    import os, signal, sys
    from pathlib import Path
    import facebasis.atomic as atomic
    out, when, mode = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    at, n = when.split(":")
    calls = [0]
    real_replace = os.replace
    def replace(a, b):
        calls[0] += 1
        if at == "before" and calls[0] == int(n):
            os.kill(os.getpid(), signal.SIGKILL)
        real_replace(a, b)
        if at == "after" and calls[0] == int(n):
            os.kill(os.getpid(), signal.SIGKILL)
    atomic.os.replace = replace
    if mode == "folder":
        with atomic.atomic_directory(out) as stage:
            (stage / "new.txt").write_text("new")
            if at == "staging":
                os.kill(os.getpid(), signal.SIGKILL)
    else:
        atomic.atomic_write_bytes(out, b"new")
""")


def _run_child(out, kill_at, mode):
    env = dict(os.environ, PYTHONPATH=str(Path(atomic.__file__).parents[1]))
    return subprocess.run([sys.executable, "-c", _CHILD, str(out), str(kill_at), mode], env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("kill_at", ["staging:0", "before:1", "after:1", "after:2"])
def test_a_folder_swap_killed_at_any_point_is_recovered_never_lost(tmp_path, kill_at):
    """SIGKILL while staging, before the swap, between its two renames (after:1: the old output
    already moved aside, the new not yet in place) and after it (after:2): the next run of the same
    output restores the old output or keeps the new one and removes the run folder; nothing is lost."""
    out = tmp_path / "out"
    out.mkdir()
    (out / OUTPUT_MARKER).write_text("x")
    (out / "old.txt").write_text("old")
    proc = _run_child(out, kill_at, "folder")
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    leftovers = [p for p in tmp_path.iterdir() if p.name != "out"]
    assert leftovers and all(p.name.startswith(".out.facebasis-") for p in leftovers)
    recover(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    files = sorted(p.name for p in out.iterdir() if p.name != OUTPUT_MARKER)
    assert files == (["new.txt"] if kill_at == "after:2" else ["old.txt"])


def test_a_single_file_write_killed_leaves_the_old_file_and_the_next_write_cleans_up(tmp_path):
    path = tmp_path / "edges.json"
    path.write_text("old")
    proc = _run_child(path, "before:1", "file")  # killed just before the rename
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert path.read_text() == "old"
    assert len(list(tmp_path.iterdir())) == 2  # the run folder of the dead write
    atomic_write_bytes(path, b"newer")
    assert path.read_bytes() == b"newer"
    assert [p.name for p in tmp_path.iterdir()] == ["edges.json"]


def test_a_live_runs_staging_is_never_taken_whatever_its_process_id(tmp_path):
    """A run in another PID namespace (a container sharing the folder) has a process id that means
    nothing here; the staging belongs to it by its lock. A second run must leave it alone, and the
    first still completes with its full output."""
    out = tmp_path / "out"
    script = textwrap.dedent("""
        import sys, time
        from pathlib import Path
        import facebasis.atomic as atomic
        with atomic.atomic_directory(Path(sys.argv[1])) as stage:
            (stage / "a.txt").write_text("a")
            print("staged", flush=True)
            time.sleep(float(sys.argv[2]))
            (stage / "b.txt").write_text("b")
    """)
    env = dict(os.environ, PYTHONPATH=str(Path(atomic.__file__).parents[1]))
    first = subprocess.Popen([sys.executable, "-c", script, str(out), "3"], env=env, stdout=subprocess.PIPE,
                             text=True)
    try:
        assert first.stdout.readline().strip() == "staged"
        staging = [p for p in tmp_path.iterdir() if p.name.startswith(".out.facebasis-")]
        assert len(staging) == 1
        (staging[0] / "token").write_text((staging[0] / "token").read_text())  # touched, still locked
        assert recover(out) == [] and staging[0].is_dir()
        with atomic_directory(tmp_path / "other") as stage:  # another output beside it: no effect on it
            (stage / "x").write_text("x")
        assert staging[0].is_dir()
    finally:
        assert first.wait(timeout=60) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([OUTPUT_MARKER, "a.txt", "b.txt"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other", "out"]


def test_a_run_whose_staging_was_taken_away_fails_instead_of_reporting_success(tmp_path):
    import shutil

    out = tmp_path / "out"
    with pytest.raises(InputError, match="removed or replaced by another process"):
        with atomic_directory(out) as stage:
            (stage / "a.txt").write_text("a")
            shutil.rmtree(stage.parent)
    assert not out.exists()


def test_a_lockless_run_folder_is_left_alone_while_young(tmp_path):
    out = tmp_path / "out"
    young = tmp_path / ".out.facebasis-young1"
    young.mkdir()
    recover(out)
    assert young.is_dir()
    old = tmp_path / ".out.facebasis-old1"
    (old / "old").mkdir(parents=True)
    (old / "old" / "kept.txt").write_text("the previous output")
    past = time.time() - 3600
    os.utime(old, (past, past))
    recover(out)
    assert (out / "kept.txt").read_text() == "the previous output"  # restored, never deleted
    assert not old.exists()


def test_a_gltf_export_spares_a_users_bin_and_replaces_its_own(tmp_path, capsys, monkeypatch):
    from facebasis.defaults.face import default_template
    from facebasis.geometry.rig import write_rig_folder

    monkeypatch.chdir(tmp_path)
    write_rig_folder(tmp_path / "rig", default_template())
    (tmp_path / "mine.bin").write_bytes(b"a user's buffer")
    assert main(["export", "rig", "--out", "mine.gltf"]) == 2
    assert "--out (its .bin)" in capsys.readouterr().err and (tmp_path / "mine.bin").read_bytes() == b"a user's buffer"
    assert not (tmp_path / "mine.gltf").exists()
    assert main(["export", "rig", "--out", "rig.gltf"]) == 0
    assert atomic.written_by_facebasis(tmp_path / "rig.bin")
    assert main(["export", "rig", "--out", "rig.gltf"]) == 0  # its own files: replaced


def test_every_output_folder_records_its_provenance_and_its_inputs_hashes(tmp_path, monkeypatch):
    """provenance.json: package version, Python and library versions, the command line, and the
    SHA-256 of every input file: one changed byte in an input changes its recorded hash."""
    import json

    from facebasis import __version__
    from facebasis.defaults.face import default_template
    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import write_rig_folder
    from facebasis.provenance import PROVENANCE_FILE, sha256_file

    monkeypatch.chdir(tmp_path)
    rig = default_template()
    write_rig_folder(tmp_path / "tmpl", rig)
    write_mesh(tmp_path / "target.obj", rig.neutral * 1.05, rig.faces)
    argv = ["transfer", "--template", "tmpl", "--target", "target.obj", "--out"]
    assert main(argv + ["a"]) == 0
    rec = json.loads((tmp_path / "a" / PROVENANCE_FILE).read_text())
    assert rec["version"] == __version__ and rec["argv"] == ["facebasis", *argv, "a"]
    assert set(rec["libraries"]) >= {"numpy", "scipy", "casadi", "trimesh", "matplotlib"}
    hashes = {Path(r["path"]).name: r["sha256"] for r in rec["inputs"]}
    assert hashes["target.obj"] == sha256_file(tmp_path / "target.obj")
    assert len(hashes) == 1 + 1 + rig.n_shapes  # the target, the template's neutral and shapes
    first = (tmp_path / "target.obj").read_bytes()
    i = first.index(b"\nv ") + 4                       # the second vertex's x: one digit changed
    j = first.index(b".", i) + 1
    changed_byte = b"1" if first[j:j + 1] != b"1" else b"2"
    (tmp_path / "target.obj").write_bytes(first[:j] + changed_byte + first[j + 1:])
    assert main(argv + ["b"]) == 0
    rec_b = json.loads((tmp_path / "b" / PROVENANCE_FILE).read_text())
    changed = {Path(r["path"]).name: r["sha256"] for r in rec_b["inputs"]}
    assert changed["target.obj"] != hashes["target.obj"] and changed["jawOpen.obj"] == hashes["jawOpen.obj"]
    from facebasis.provenance import input_records

    assert input_records([tmp_path / "target.obj"])[0]["sha256"] != hashes["target.obj"]
