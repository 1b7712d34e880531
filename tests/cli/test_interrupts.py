"""Ctrl-C always stops a run, leaves the old output or none, and outputs get ordinary permissions."""

import os
import signal
import sys
import threading

import numpy as np
import pytest

import facebasis.atomic as atomic
from facebasis.atomic import atomic_directory, atomic_write_bytes
from facebasis.interrupt import interruptible


@pytest.fixture(autouse=True)
def sigint_raises():
    """These tests send SIGINT to this process: make it raise KeyboardInterrupt even where the suite
    was started with SIGINT ignored (under ``nohup``, as a background job of a script)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def test_an_interrupt_swallowed_inside_the_block_is_raised_when_it_ends():
    reached = []
    with pytest.raises(KeyboardInterrupt):
        with interruptible():
            try:  # what CasADi does with an interrupt inside IPOPT: catch it, report a status
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                pass
            reached.append("after")
    assert reached == ["after"]
    with interruptible():  # no interrupt: nothing raised
        pass


def test_ctrl_c_inside_ipopt_stops_the_weight_step():
    """A real SIGINT while IPOPT runs (a 10,600-variable problem that takes seconds) ends in
    KeyboardInterrupt, not in a failure status that the certified polish would paper over."""
    from facebasis.rigging.weightproblem import WeightProblem
    from facebasis.rigging.weights import WeightSolver

    rng = np.random.default_rng(0)
    k, m = 53, 200
    B = rng.normal(size=(300, k))
    T = rng.normal(size=(300, m))
    pairs = [(i, i + 1) for i in range(0, 20, 2)]
    solver = WeightSolver(k, m, pairs)
    problem = WeightProblem(B.T @ B, (B.T @ T).T, (T * T).sum(0), pairs, np.full((m, k), 0.5), 1.0)
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            solver.solve_problem(problem)
    finally:
        timer.cancel()


def _tree(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _replace(out):
    with atomic_directory(out) as stage:
        for i in range(3):
            (stage / f"new{i}.txt").write_bytes(b"new")
        (stage / "sub").mkdir()
        (stage / "sub" / "x.txt").write_bytes(b"new")


def _interrupt_everywhere(make, run, check):
    """Fault injection: for n = 1, 2, ... a real SIGINT is raised at the n-th line executed in
    facebasis.atomic or in this file while ``run(target)`` runs, until a run ends uninterrupted.
    ``check(root, target, interrupted)`` inspects each outcome; returns the set of outcomes."""
    outcomes = set()
    n = 0
    while True:
        n += 1
        root, target = make(n)
        count = [0]

        def tracer(frame, event, arg, n=n, count=count):
            if frame.f_code.co_filename in (atomic.__file__, __file__) and event == "line":
                count[0] += 1
                if count[0] == n:
                    signal.raise_signal(signal.SIGINT)
            return tracer

        sys.settrace(tracer)
        try:
            run(target)
            interrupted = False
        except KeyboardInterrupt:
            interrupted = True
        finally:
            sys.settrace(None)
        outcomes.add(check(root, target, interrupted))
        if not interrupted:
            return outcomes, n
        assert n < 500


def test_replacing_a_folder_interrupted_at_every_step_leaves_old_or_new_and_nothing_else(tmp_path):
    marker = {atomic.OUTPUT_MARKER: b"written by facebasis; a later run with this output folder replaces it\n"}
    old_files = {f"old{i}.txt": b"old" for i in range(18)} | marker  # a previous output: replaceable
    new_files = {"new0.txt": b"new", "new1.txt": b"new", "new2.txt": b"new", "sub/x.txt": b"new"} | marker

    def make(n):
        out = tmp_path / f"run{n}" / "out"
        out.mkdir(parents=True)
        for name, data in old_files.items():
            (out / name).write_bytes(data)
        return out.parent, out

    def check(root, out, interrupted):
        assert sorted(p.name for p in root.iterdir()) == ["out"]  # no staging or swapped-out folder
        tree = _tree(out)
        assert tree in (old_files, new_files)
        return "old" if tree == old_files else "new", interrupted

    outcomes, n = _interrupt_everywhere(make, _replace, check)
    # the interrupt landed before the swap (old kept) and after it (new in place, still reported)
    assert ("old", True) in outcomes and ("new", False) in outcomes
    assert n > 20


def test_replacing_a_file_interrupted_at_every_step_leaves_old_or_new_and_nothing_else(tmp_path):
    def make(n):
        root = tmp_path / f"run{n}"
        root.mkdir()
        (root / "f.json").write_bytes(b"old")
        return root, root / "f.json"

    def check(root, path, interrupted):
        assert sorted(p.name for p in root.iterdir()) == ["f.json"]
        assert path.read_bytes() in (b"old", b"new" * 1000)
        return path.read_bytes()[:3].decode(), interrupted

    outcomes, n = _interrupt_everywhere(make, lambda path: atomic_write_bytes(path, b"new" * 1000), check)
    assert ("old", True) in outcomes and ("new", False) in outcomes


def test_outputs_get_the_usual_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        with atomic_directory(tmp_path / "folder") as stage:
            atomic_write_bytes(stage / "f.txt", b"x")
        atomic_write_bytes(tmp_path / "single.json", b"{}")
    finally:
        os.umask(old)
    if atomic._UMASK != 0o022:
        pytest.skip(f"the test process runs under umask {atomic._UMASK:o}")
    assert (tmp_path / "folder").stat().st_mode & 0o777 == 0o755
    assert (tmp_path / "folder" / "f.txt").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "single.json").stat().st_mode & 0o777 == 0o644


def test_cli_interrupted_inside_ipopt_exits_130_with_one_line_and_no_output(tmp_path, capsys, monkeypatch):
    """`facebasis rig` with an interrupt that IPOPT swallows (as CasADi does): exit 130, one line
    on stderr, no output folder, no staging folder."""
    from conftest import swallow_signal_inside_ipopt, write_rig_inputs

    from facebasis.cli import main
    from facebasis.rigging.synthetic import default_face_problem

    root = write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=6))
    swallow_signal_inside_ipopt(monkeypatch, signal.SIGINT)
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "examples"), "--weights", str(root / "weights.json"),
                 "--out", str(root / "out"), "--iterations", "2"])
    err = capsys.readouterr().err
    assert code == 130
    assert err.strip().count("\n") == 0 and err.startswith("interrupted: facebasis rig stopped")
    assert not (root / "out").exists() and not list(root.glob(".out*"))


def test_a_file_output_that_is_a_folder_is_a_clear_error(tmp_path, capsys):
    from facebasis.cli import main
    from facebasis.defaults.face import default_template
    from facebasis.geometry.rig import write_rig_folder

    write_rig_folder(tmp_path / "rig", default_template())
    (tmp_path / "taken").mkdir()
    assert main(["export", str(tmp_path / "rig"), "--out", str(tmp_path / "taken")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --out {tmp_path / 'taken'}: expected a file name, found a folder")
    assert list((tmp_path / "taken").iterdir()) == []
