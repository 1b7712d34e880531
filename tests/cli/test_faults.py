"""Fault injection: commands that write are killed (SIGKILL, SIGTERM, SIGINT, SIGHUP) at several
points, pointed at a full disk, a read-only mount, an unwritable folder, a dangling or looping
symbolic link, and fed hostile inputs (JSON nested 100k deep, a 5,001-digit number, a sparse OBJ,
an undecodable video, duplicate landmark indices, flat landmarks, a broken shape link, a scan named
``summary``). Every outcome: the documented exit status, at most one line on stderr and no
traceback, the old output intact or the new one complete, and no staging left after the next run.

Kills happen in a child process (``DRIVER`` below) that wraps a library function so that its n-th
call sends the signal to the process itself: the same point every run, no timing. Mounts need root
(``mount -t tmpfs``, a read-only bind mount); the tests that need one skip where it fails.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import grid_sheet

from facebasis.errors import InputError, MeshError, RigError

ROOT = Path(__file__).resolve().parents[2]

DRIVER = r'''
import importlib, json, os, signal, sys, time
spec = json.loads(sys.argv[1])

def hook(dotted, n, signame):
    """The n-th call of module:attr[.attr] sends signal ``signame`` to this process first."""
    mod_name, path = dotted.split(":")
    owner = importlib.import_module(mod_name)
    *outer, name = path.split(".")
    for part in outer:
        owner = getattr(owner, part)
    real, calls = getattr(owner, name), [0]

    def wrapped(*a, **k):
        calls[0] += 1
        if calls[0] == n:
            os.kill(os.getpid(), getattr(signal, signame))
        return real(*a, **k)
    setattr(owner, name, wrapped)

for dotted, n, signame in spec.get("hooks", []):
    hook(dotted, n, signame)
if spec.get("slow_worker"):  # a contact worker that takes long: it says so, then works for 2 minutes
    import facebasis.contact.exact as ex
    marker = spec["slow_worker"]

    def slow(*args):
        with open(marker, "a") as fh:
            fh.write(f"{os.getpid()}\n")
        time.sleep(120)
    ex._correct_job = slow
from facebasis.cli import main
sys.exit(main(spec["argv"]))
'''


def _default_signals():
    """The child takes the stop signals with their default action, whatever this process ignores
    (under ``nohup`` or as a background job SIGHUP / SIGINT are ignored and would be inherited)."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def run_driver(tmp_path, argv, hooks=(), slow_worker=None, wait=True, **popen):
    driver = tmp_path / "driver.py"
    if not driver.exists():
        driver.write_text(DRIVER)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               OMP_NUM_THREADS="1", FACEBASIS_PROGRESS="0")
    spec = {"argv": [str(a) for a in argv], "hooks": [list(h) for h in hooks], "slow_worker": slow_worker}
    p = subprocess.Popen([sys.executable, str(driver), json.dumps(spec)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=env, preexec_fn=_default_signals, **popen)
    if not wait:
        return p
    out, err = p.communicate(timeout=120)
    return p.returncode, out.decode(), err.decode()


@pytest.fixture
def own_handlers():
    """main() installs SIGTERM/SIGHUP handlers: put this process's back afterwards."""
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


def tree(folder: Path) -> dict:
    """Every file's bytes; provenance.json without the fields that name the run (its command line,
    working folder, the git tree's state), which legitimately differ between two runs of one output."""
    import json

    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            data = p.read_bytes()
            if p.name == "provenance.json":
                rec = json.loads(data)
                for key in ("argv", "cwd", "git_dirty"):
                    rec.pop(key)
                data = json.dumps(rec, sort_keys=True).encode()
            out[p.relative_to(folder).as_posix()] = data
    return out


def leftovers(parent: Path, name: str) -> list:
    """What lies beside the output ``parent/name`` besides it and the test's own files: staging or
    swapped-out folders, temporary files (whatever their names)."""
    return sorted(p.name for p in parent.iterdir() if p.name not in (name, "driver.py", "template", "target.obj",
                                                                      "workers.txt"))


def one_line(err: str) -> bool:
    return err.count("\n") == 1 and err.endswith("\n") and "Traceback" not in err


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 6-shape grid rig, two target neutrals and a reference output per target."""
    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import Rig, write_rig_folder

    d = tmp_path_factory.mktemp("small")
    V, F = grid_sheet(9, 8)
    rng = np.random.default_rng(0)
    x, y = V[:, 0:1], V[:, 1:2]
    deltas = np.stack([np.hstack([0 * x, 0 * x, 0.1 * np.sin((k + 1) * x + y)]) * rng.uniform(0.5, 1.5)
                       for k in range(6)])
    write_rig_folder(d / "template", Rig(V, F, tuple(f"s{k}" for k in range(6)), deltas))
    for name, s in (("a", 1.1), ("b", 0.9)):
        W = V.copy()
        W[:, 0] *= s
        write_mesh(d / f"{name}.obj", W, F)
    return d


def transfer_args(small, target, out):
    return ["transfer", "--template", small / "template", "--target", small / f"{target}.obj", "--out", out]


@pytest.fixture(scope="module")
def references(small, tmp_path_factory):
    from facebasis.cli import main

    saved = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP)}
    d = tmp_path_factory.mktemp("refs")
    try:
        for t in ("a", "b"):
            assert main([str(a) for a in transfer_args(small, t, d / t)]) == 0
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    return {t: tree(d / t) for t in ("a", "b")}


# ------------------------------------------------------------------------------------------------
# kills at several points of `transfer` (a folder output) and of `export` (a single file)

STATUS = {"SIGKILL": -9, "SIGTERM": 143, "SIGINT": 130, "SIGHUP": 129}


@pytest.mark.parametrize("point, n, sig", [
    ("facebasis.geometry.rig:read_mesh_like", 2, "SIGTERM"),  # reading the template's shapes
    ("facebasis.geometry.transfer:DeformationTransfer.transfer", 1, "SIGHUP"),  # before the solve
    ("facebasis.geometry.rig:write_mesh", 1, "SIGINT"),  # first file of the staging folder
    ("facebasis.geometry.rig:write_mesh", 4, "SIGKILL"),  # half-way through the staging folder
    ("facebasis.geometry.rig:write_mesh", 7, "SIGTERM"),  # its last file
])
def test_a_killed_transfer_leaves_the_old_output_and_the_next_run_the_new_one(small, references, tmp_path, point,
                                                                             n, sig, own_handlers):
    from facebasis.cli import main

    out = tmp_path / "out"
    assert main([str(a) for a in transfer_args(small, "a", out)]) == 0  # the old output
    code, stdout, err = run_driver(tmp_path, transfer_args(small, "b", out), hooks=[(point, n, sig)])
    assert code == STATUS[sig], err
    if sig == "SIGKILL":
        assert err == ""
    else:
        assert one_line(err) and err.startswith(f"interrupted: facebasis transfer stopped by {sig}"), err
        assert leftovers(tmp_path, "out") == []  # staging removed at once
    assert tree(out) == references["a"]  # the old output, untouched
    assert main([str(a) for a in transfer_args(small, "b", out)]) == 0  # the next run
    assert tree(out) == references["b"] and leftovers(tmp_path, "out") == []


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    from PIL import Image

    from facebasis.capture.synthetic import synthetic_sequence
    from facebasis.retarget.files import write_pts

    d = tmp_path_factory.mktemp("frames")
    seq = synthetic_sequence(4, size=(96, 96))
    (d / "frames").mkdir()
    for i, f in enumerate(seq.frames):
        Image.fromarray(f).save(d / "frames" / f"f{i}.png")
    write_pts(d / "first.pts", seq.landmarks[0])
    return d


@pytest.mark.parametrize("point, n, sig", [
    ("facebasis.capture.overlay:draw_overlay", 3, "SIGTERM"),  # mid-video, the overlay being encoded
    ("facebasis.capture.tracker:write_capture", 1, "SIGKILL"),  # the tracks about to be written
])
def test_a_killed_capture_leaves_the_old_output(frames, tmp_path, point, n, sig, own_handlers):
    from facebasis.capture.trackfile import read_capture
    from facebasis.cli import main

    out = tmp_path / "cap"
    argv = ["capture", frames / "frames", "--landmarks", frames / "first.pts", "--out", out]
    assert main([str(a) for a in argv] + ["--max-frames", "2"]) == 0  # the old output: 2 frames
    old = tree(out)
    code, _, err = run_driver(tmp_path, argv, hooks=[(point, n, sig)])
    assert code == STATUS[sig]
    last = err.rstrip("\n").rsplit("\n", 1)[-1].rsplit("\r", 1)[-1]  # after capture's own progress bar
    assert "Traceback" not in err and "Error" not in err, err
    if sig != "SIGKILL":
        assert last.startswith(f"interrupted: facebasis capture stopped by {sig}"), err
    assert tree(out) == old
    assert main([str(a) for a in argv]) == 0
    assert read_capture(out).n_frames == 4 and leftovers(tmp_path, "cap") == []


def test_a_killed_first_run_leaves_nothing(small, tmp_path):
    code, _, err = run_driver(tmp_path, transfer_args(small, "b", tmp_path / "out"),
                              hooks=[("facebasis.geometry.rig:write_mesh", 3, "SIGTERM")])
    assert code == 143 and one_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["driver.py"]


def test_a_killed_export_leaves_the_old_file(small, references, tmp_path, own_handlers):
    from facebasis.cli import main

    glb = tmp_path / "rig.glb"
    assert main(["export", str(small / "template"), "--out", str(glb)]) == 0
    old = glb.read_bytes()
    code, _, err = run_driver(tmp_path, ["export", small / "template", "--out", glb],
                              hooks=[("os:replace", 1, "SIGTERM")])
    assert code == 143 and one_line(err), err
    assert glb.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["driver.py", "rig.glb"]


def test_a_file_output_killed_before_its_rename_is_cleaned_by_the_next_run(small, tmp_path, own_handlers):
    from facebasis.cli import main

    glb = tmp_path / "rig.glb"
    code, _, err = run_driver(tmp_path, ["export", small / "template", "--out", glb],
                              hooks=[("os:replace", 1, "SIGKILL")])
    assert code == -9 and err == "" and not glb.exists()
    assert main(["export", str(small / "template"), "--out", str(glb)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["driver.py", "rig.glb"]


# ------------------------------------------------------------------------------------------------
# the contact solver's worker processes

def _cores():
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


@pytest.mark.skipif(sys.platform != "linux" or _cores() < 2, reason="the worker pool needs fork and 2 cores")
@pytest.mark.parametrize("sig, group", [("SIGKILL", False), ("SIGTERM", False), ("SIGINT", True)])
def test_contact_workers_stop_with_their_parent_and_print_nothing(tmp_path, sig, group):
    """`transfer --contact` killed while its workers correct shapes: no worker survives its parent
    (SIGKILL: the kernel ends them, PR_SET_PDEATHSIG), none prints (Ctrl-C reaches the whole
    group: the workers ignore it, the parent prints one line)."""
    psutil = pytest.importorskip("psutil")
    from conftest import stretched, two_sheets

    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import write_rig_folder

    rig = two_sheets()
    write_rig_folder(tmp_path / "template", rig)
    write_mesh(tmp_path / "target.obj", stretched(rig.neutral), rig.faces)
    marker = tmp_path / "workers.txt"
    p = run_driver(tmp_path, ["transfer", "--template", tmp_path / "template", "--target", tmp_path / "target.obj",
                              "--contact", "--out", tmp_path / "out"], slow_worker=str(marker), wait=False,
                   start_new_session=True)
    try:
        t0 = time.monotonic()
        while (not marker.exists() or len(marker.read_text().split()) < 2) and time.monotonic() - t0 < 60:
            assert p.poll() is None, p.communicate()
            time.sleep(0.05)
        workers = [psutil.Process(int(w)) for w in marker.read_text().split()]
        assert len(workers) == 2
        if group:
            os.killpg(p.pid, getattr(signal, sig))
        else:
            p.send_signal(getattr(signal, sig))
        out, err = p.communicate(timeout=30)  # returns once every holder of the pipes (workers too) is gone
        gone, alive = psutil.wait_procs(workers, timeout=5)
    finally:
        if p.poll() is None:
            p.kill()
    assert alive == []
    err = err.decode()
    assert p.returncode == STATUS[sig]
    if sig == "SIGKILL":
        assert err == ""
    else:
        assert one_line(err) and err.startswith(f"interrupted: facebasis transfer stopped by {sig}"), err
    assert not (tmp_path / "out").exists() and leftovers(tmp_path, "out") == []


# ------------------------------------------------------------------------------------------------
# full disk, read-only location, no permission, symbolic links

def _mount(args, target: Path):
    r = subprocess.run(["mount", *args, str(target)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount here ({r.stderr.decode().strip() or r.returncode})")


def _umount(target: Path):
    subprocess.run(["umount", "-l", str(target)], capture_output=True)


@pytest.fixture
def small_disk(tmp_path):
    disk = tmp_path / "disk"
    disk.mkdir()
    _mount(["-t", "tmpfs", "-o", "size=128k", "tmpfs"], disk)
    yield disk
    _umount(disk)


@pytest.fixture
def read_only(tmp_path):
    src, ro = tmp_path / "rosrc", tmp_path / "ro"
    src.mkdir()
    ro.mkdir()
    _mount(["--bind", str(src)], ro)
    r = subprocess.run(["mount", "-o", "remount,bind,ro", str(ro)], capture_output=True)
    if r.returncode != 0:
        _umount(ro)
        pytest.skip("cannot remount read-only")
    yield ro
    _umount(ro)


def test_a_full_disk_is_one_line_and_keeps_the_old_output(small, small_disk, capsys, own_handlers):
    from facebasis.cli import main
    from facebasis.defaults.face import default_template
    from facebasis.geometry.rig import write_rig_folder

    out = small_disk / "out"
    assert main([str(a) for a in transfer_args(small, "a", out)]) == 0  # 6 small shapes: fit
    old = tree(out)
    big = small_disk.parent / "big"
    write_rig_folder(big / "template", default_template())  # 15 shapes of 4,497 vertices: do not
    capsys.readouterr()
    code = main(["transfer", "--template", str(big / "template"), "--target",
                 str(big / "template" / "neutral.obj"), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and one_line(err), err
    assert err.startswith(f"error: facebasis transfer: writing output {out}") and "[ENOSPC]" in err
    assert tree(out) == old and leftovers(small_disk, "out") == []


def test_a_read_only_location_is_one_line(small, read_only, capsys, own_handlers):
    from facebasis.cli import main

    for argv, out in ((transfer_args(small, "a", read_only / "out"), read_only / "out"),
                      (["export", small / "template", "--out", read_only / "rig.glb"], read_only / "rig.glb"),
                      (["virtual-edges", small / "a.obj", "--out", read_only / "ve.json"], read_only / "ve.json")):
        assert main([str(a) for a in argv]) == 2
        err = capsys.readouterr().err
        assert one_line(err) and err.startswith(f"error: facebasis {argv[0]}: writing output {out}"), err
        assert "Read-only file system [EROFS]; the location is read-only" in err
    assert list(read_only.iterdir()) == []


def test_a_folder_without_write_permission_is_one_line(small, tmp_path, capsys, monkeypatch, own_handlers):
    """For real when not root; as root (who may write anywhere) the refusal the kernel would give
    is injected where the staging folder is made."""
    import tempfile

    from facebasis.cli import main

    locked = tmp_path / "locked"
    locked.mkdir()
    if os.geteuid() == 0:
        def refuse(*a, dir=None, **k):
            raise PermissionError(13, "Permission denied", str(Path(dir) / ".out.partial-x"))

        monkeypatch.setattr(tempfile, "mkdtemp", refuse)
        monkeypatch.setattr(tempfile, "mkstemp", refuse)
    locked.chmod(0o555)
    try:
        assert main([str(a) for a in transfer_args(small, "a", locked / "out")]) == 2
    finally:
        locked.chmod(0o755)
    err = capsys.readouterr().err
    assert one_line(err) and f"writing output {locked / 'out'}" in err, err
    assert "Permission denied [EACCES]; no permission" in err
    assert list(locked.iterdir()) == []


def test_an_out_that_is_a_dangling_or_looping_symlink_is_one_line(small, tmp_path, capsys, own_handlers):
    from facebasis.cli import main

    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere" / "x")
    (tmp_path / "loop1").symlink_to(tmp_path / "loop2")
    (tmp_path / "loop2").symlink_to(tmp_path / "loop1")
    assert main([str(a) for a in transfer_args(small, "a", tmp_path / "dangling")]) == 2
    err = capsys.readouterr().err
    assert one_line(err) and f"dangling: expected a new path or a previous facebasis folder, found a symbolic link (to " \
        f"{tmp_path / 'nowhere' / 'x'})" in err, err
    assert main([str(a) for a in transfer_args(small, "a", tmp_path / "loop1")]) == 2
    err = capsys.readouterr().err
    assert one_line(err) and "loop1: expected a new path or a previous facebasis folder, found a symbolic link" in err
    assert main([str(a) for a in transfer_args(small, "a", tmp_path / "loop1" / "x")]) == 2
    err = capsys.readouterr().err
    assert one_line(err) and f"found the symbolic link {tmp_path / 'loop1'} (to {tmp_path / 'loop2'}), which leads to " \
        "no folder (it is broken or loops), in it" in err, err
    assert (tmp_path / "dangling").is_symlink() and sorted(p.name for p in tmp_path.iterdir()) == [
        "dangling", "loop1", "loop2"]


def test_a_closed_stdout_does_not_stop_the_command(small, tmp_path, references):
    """`facebasis transfer ... | head -0`: the reader has gone before the command prints; the command
    still writes its output, exits 0 and prints no BrokenPipeError."""
    p = run_driver(tmp_path, transfer_args(small, "b", tmp_path / "out"), wait=False)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 0 and err == ""
    assert tree(tmp_path / "out") == references["b"]


def test_os_error_lines():
    from facebasis.cli import os_error_line

    e = OSError(28, "No space left on device", "/data/.run.partial-1-ab/s0.obj")
    assert os_error_line(e, "rig", "/data/run") == ("facebasis rig: writing output /data/run (staging "
                                                    ".run.partial-1-ab/s0.obj): No space left on device [ENOSPC]; "
                                                    "the disk is full: free space or write elsewhere")
    e = OSError(13, "Permission denied", "/etc/x.json")
    assert os_error_line(e, "export", None) == ("facebasis export: /etc/x.json: Permission denied [EACCES]; no "
                                                "permission: check the folder's owner and mode, or write elsewhere")
    e = OSError(5, "Input/output error")
    assert os_error_line(e, "capture", "cap") == ("facebasis capture: while reading the inputs or writing output "
                                                  "cap: Input/output error [EIO]")


# ------------------------------------------------------------------------------------------------
# interrupts: SIGTERM and SIGHUP like Ctrl-C, held back during renames, not lost inside IPOPT

def test_sigterm_swallowed_inside_the_block_is_raised_when_it_ends(own_handlers):
    from facebasis.interrupt import Terminated, deferred_interrupts, install_stop_handlers, interruptible

    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # as in a fresh process, even under nohup
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    install_stop_handlers()
    with pytest.raises(Terminated) as info:
        with interruptible():
            try:  # what CasADi does with an exception inside IPOPT
                signal.raise_signal(signal.SIGTERM)
            except KeyboardInterrupt:
                pass
    assert info.value.signum == signal.SIGTERM and isinstance(info.value, KeyboardInterrupt)
    reached = []
    with pytest.raises(Terminated):
        with deferred_interrupts():
            os.kill(os.getpid(), signal.SIGHUP)
            reached.append("held back")
    assert reached == ["held back"]


def test_signals_are_held_back_during_renames_even_with_other_threads_running(own_handlers):
    """A process-directed signal goes to any thread not blocking it: deferred_interrupts must hold it
    back whichever thread the kernel picks (a BLAS, tqdm or pool thread is usually running)."""
    import threading

    from facebasis.interrupt import deferred_interrupts

    signal.signal(signal.SIGINT, signal.default_int_handler)
    stop = threading.Event()
    helper = threading.Thread(target=stop.wait, daemon=True)
    helper.start()
    reached = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with deferred_interrupts():
                for _ in range(20):
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(0.005)
                reached.append("held back")
    finally:
        stop.set()
    assert reached == ["held back"]


def test_sigterm_swallowed_by_ipopt_stops_rig_with_143(tmp_path, capsys, monkeypatch, own_handlers):
    """`facebasis rig` with a SIGTERM that IPOPT swallows (as CasADi does with any exception raised
    in a callback): exit 143, one line, no output folder, no staging folder."""
    from conftest import swallow_signal_inside_ipopt, write_rig_inputs

    from facebasis.cli import main
    from facebasis.rigging.synthetic import default_face_problem

    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # what a fresh process has; main() installs its handler
    root = write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=6))
    swallow_signal_inside_ipopt(monkeypatch, signal.SIGTERM)
    code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                 "--examples", str(root / "examples"), "--weights", str(root / "weights.json"),
                 "--out", str(root / "out"), "--iterations", "2"])
    err = capsys.readouterr().err
    assert code == 143 and one_line(err) and err.startswith("interrupted: facebasis rig stopped by SIGTERM"), err
    assert not (root / "out").exists() and not list(root.glob(".out*"))
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL  # main() put the caller's handler back


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_replacing_a_folder_stopped_by_sigterm_at_every_step_leaves_old_or_new(tmp_path, sig, own_handlers):
    """As test_interrupts' every-line test for Ctrl-C: SIGTERM / SIGHUP raised at the n-th line run in
    facebasis.atomic (n = 1, 2, ... until a run ends undisturbed) leave the old folder or the new one,
    and nothing beside it."""
    from test_interrupts import _interrupt_everywhere, _replace, _tree

    import facebasis.atomic as atomic
    from facebasis.interrupt import install_stop_handlers

    signum = getattr(signal, sig)
    signal.signal(signum, signal.SIG_DFL)
    install_stop_handlers()
    marker = {atomic.OUTPUT_MARKER: (atomic.OUTPUT_MARKER, None)}  # compared by name only: its text may change
    old_files = {f"old{i}.txt": b"old" for i in range(6)}
    new_files = {"new0.txt": b"new", "new1.txt": b"new", "new2.txt": b"new", "sub/x.txt": b"new"}

    def make(n):
        out = tmp_path / f"run{n}" / "out"
        out.mkdir(parents=True)
        for name, data in old_files.items():
            (out / name).write_bytes(data)
        (out / atomic.OUTPUT_MARKER).write_text("written by facebasis\n")
        return out.parent, out

    def check(root, out, interrupted):
        assert sorted(p.name for p in root.iterdir()) == ["out"]
        tree = {k: v for k, v in _tree(out).items() if k not in marker}
        assert tree in (old_files, new_files)
        return "old" if tree == old_files else "new", interrupted

    import test_interrupts

    real_raise = signal.raise_signal
    try:  # the helper raises SIGINT at each line: raise this signal instead
        test_interrupts.signal.raise_signal = lambda s: real_raise(signum)
        outcomes, n = _interrupt_everywhere(make, _replace, check)
    finally:
        test_interrupts.signal.raise_signal = real_raise
    assert ("old", True) in outcomes and ("new", False) in outcomes and n > 10


def test_an_ignored_signal_stays_ignored(own_handlers):
    """`nohup` ignores SIGHUP: the command keeps it ignored (and interruptible() leaves it alone)."""
    from facebasis.interrupt import install_stop_handlers, interruptible

    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    install_stop_handlers()
    assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
    with interruptible():
        os.kill(os.getpid(), signal.SIGHUP)
    assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN


def test_a_forked_worker_ignores_ctrl_c_and_dies_with_its_parent(tmp_path):
    """worker_init in a pool: SIGINT ignored, SIGTERM the default; the parent killed by SIGKILL takes
    its worker along at once (Linux: PR_SET_PDEATHSIG)."""
    psutil = pytest.importorskip("psutil")
    code = r'''
import os, sys, time, signal
from facebasis.workers import fork_pool
from facebasis.interrupt import install_stop_handlers
install_stop_handlers()

def report(_):
    return (signal.getsignal(signal.SIGINT) == signal.SIG_IGN, signal.getsignal(signal.SIGTERM) == signal.SIG_DFL,
            os.getpid())

pool = fork_pool(1)
ign, dfl, pid = pool.apply(report, (0,))
print(ign, dfl, pid, flush=True)
pool.apply_async(time.sleep, (120,))
time.sleep(120)
'''
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                         preexec_fn=_default_signals)
    try:
        ign, dfl, pid = p.stdout.readline().decode().split()
        worker = psutil.Process(int(pid))
        assert (ign, dfl) == ("True", "True")
        p.kill()
        _, err = p.communicate(timeout=30)
        gone, alive = psutil.wait_procs([worker], timeout=5)
    finally:
        if p.poll() is None:
            p.kill()
    assert alive == [] and err == b""


# ------------------------------------------------------------------------------------------------
# inputs refused before any work

def test_hostile_json_is_refused_before_parsing(tmp_path):
    from facebasis.jsonio import MAX_DEPTH, read_json

    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (tmp_path / "long.json").write_text('{"ex": {"jawOpen": ' + "1" * 5001 + "}}")
    (tmp_path / "ok.json").write_text(json.dumps({"a": "[[[[{{{" * 50, "b": [[["x"]]], "c": "9" * 6000}))
    (tmp_path / "edge.json").write_text("[" * MAX_DEPTH + "]" * MAX_DEPTH)
    (tmp_path / "over.json").write_text("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1))
    with pytest.raises(InputError, match=r"^weights file .*deep.json: expected weights, found arrays/objects nested "
                                         r"100000 levels deep \(at most 64 are read\)$"):
        read_json(tmp_path / "deep.json", "weights", "weights file")
    with pytest.raises(InputError, match=r"long.json: expected weights, found a number of 5001 digits on line 1"):
        read_json(tmp_path / "long.json", "weights", "weights file")
    with pytest.raises(InputError, match="nested 65 levels deep"):
        read_json(tmp_path / "over.json", "x")
    assert read_json(tmp_path / "ok.json", "x")["b"] == [[["x"]]]  # brackets and digits in strings do not count
    assert isinstance(read_json(tmp_path / "edge.json", "x"), list)  # the limit itself is read
    with open(tmp_path / "sparse.json", "wb") as fh:  # 1 GB never written: refused unread
        fh.write(b'{"a": 1}')
        fh.truncate(1 << 30)
    with pytest.raises(InputError, match=r"sparse.json: expected x, found (a sparse file of 1,073,741,824 bytes with a "
                                         r"hole|invalid JSON)"):
        read_json(tmp_path / "sparse.json", "x")


def test_hostile_weights_through_the_cli_are_one_line(tmp_path, capsys, own_handlers):
    from conftest import write_rig_inputs

    from facebasis.cli import main
    from facebasis.rigging.synthetic import default_face_problem

    root = write_rig_inputs(tmp_path, default_face_problem(seed=0, n_train=6))
    (root / "deep.json").write_text("{" + '"a": {' * 100_000 + "}" * 100_001)
    (root / "long.json").write_text('{"ex00": {"jawOpen": ' + "1" * 5001 + "}}")
    for name, found in (("deep.json", "nested 100001 levels deep"), ("long.json", "a number of 5001 digits")):
        code = main(["rig", "--template", str(root / "template"), "--target", str(root / "target.obj"),
                     "--examples", str(root / "examples"), "--weights", str(root / name),
                     "--out", str(root / "out")])
        err = capsys.readouterr().err
        assert code == 2 and one_line(err) and found in err and name in err, err
    assert not (root / "out").exists()


def test_a_sparse_or_binary_obj_is_refused_before_it_is_read(tmp_path):
    from facebasis.geometry.meshio import read_mesh

    (tmp_path / "zeros.obj").write_bytes(b"\0" * 100_000)
    with pytest.raises(MeshError, match=r"zeros.obj: expected OBJ text, found a zero byte at byte 0 \(line 1\): "
                                        r"binary data or a damaged file"):
        read_mesh(tmp_path / "zeros.obj")
    from facebasis.geometry.obj import SNIFF_BYTES, obj_bytes

    text = obj_bytes(*grid_sheet(60, 60))  # longer than the sniffed head
    assert len(text) > SNIFF_BYTES
    with open(tmp_path / "sparse.obj", "wb") as fh:  # a real mesh, then 1 GB never written
        fh.write(text)
        fh.truncate(1 << 30)
    with pytest.raises(MeshError, match=r"sparse.obj: expected OBJ text, found (a sparse file of 1,073,741,824 "
                                        r"bytes with a hole|a zero byte)"):
        read_mesh(tmp_path / "sparse.obj")
    # (a file system without hole reporting: the zero bytes are found after reading, before parsing)
    (tmp_path / "nul.obj").write_bytes(text + b"v 1 2 3\0\n")
    line = text.count(b"\n") + 1
    with pytest.raises(MeshError, match=rf"nul.obj: expected OBJ text, found a zero byte at byte {len(text) + 7:,} "
                                        rf"\(line {line}\)"):
        read_mesh(tmp_path / "nul.obj")


def test_a_broken_shape_link_in_a_rig_folder_is_named(small, tmp_path):
    import shutil

    from facebasis.geometry.rig import load_rig_folder

    shutil.copytree(small / "template", tmp_path / "rig")
    (tmp_path / "rig" / "s2.obj").unlink()
    (tmp_path / "rig" / "s2.obj").symlink_to(tmp_path / "gone.obj")
    with pytest.raises(RigError, match=rf"rig folder .*rig: expected every mesh file to be readable, found 1 symbolic "
                                       rf"link leading nowhere \(s2.obj -> {tmp_path / 'gone.obj'}\)"):
        load_rig_folder(tmp_path / "rig")
    assert load_rig_folder(tmp_path / "rig", exclude=["s2"]).names == ("s0", "s1", "s3", "s4", "s5")


def test_a_scan_named_summary_is_refused(small, tmp_path):
    import shutil

    from facebasis.geometry.registerfiles import register_files

    (tmp_path / "scans").mkdir()
    shutil.copy(small / "a.obj", tmp_path / "scans" / "neutral.obj")
    shutil.copy(small / "b.obj", tmp_path / "scans" / "Summary.obj")
    for scans in (tmp_path / "scans", tmp_path / "scans" / "Summary.obj"):
        with pytest.raises(InputError, match=r"expected scan names other than 'summary' \(the run writes summary.json, "
                                             r"which would overwrite the report Summary.json of this scan\), found "
                                             r"Summary.obj; rename the scan"):
            register_files(scans, small / "a.obj", tmp_path / "out")
    (tmp_path / "scans" / "Summary.obj").unlink()
    (tmp_path / "scans" / "smile.obj").symlink_to(tmp_path / "gone.obj")
    with pytest.raises(InputError, match=r"found symbolic link\(s\) leading nowhere: smile.obj"):
        register_files(tmp_path / "scans", small / "a.obj", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_repeated_landmark_indices_are_named(tmp_path):
    from facebasis.retarget.files import read_indices
    from facebasis.retarget.rigdrive import check_landmark_indices

    idx = list(range(68))
    idx[10:20] = [5] * 10
    (tmp_path / "dup.json").write_text(json.dumps(idx))
    with pytest.raises(InputError, match=r"^landmark index file .*dup.json: expected distinct vertex indices \(one "
                                         r"vertex per landmark\), found vertex 5 11 times \(positions 5, 10, 11, 12, "
                                         r"13 and 6 more\)$"):
        read_indices(tmp_path / "dup.json")
    with pytest.raises(InputError, match=r"found vertex 3 2 times \(positions 0, 2\)"):
        check_landmark_indices([3, 4, 3], 10, 3)
    assert check_landmark_indices([3, 4, 5], 10, 3).tolist() == [3, 4, 5]


def test_flat_cartoon_landmarks_are_one_line(tmp_path):
    from facebasis.retarget.files import read_points2d, write_pts

    write_pts(tmp_path / "equal.pts", np.full((68, 2), 100.0))
    write_pts(tmp_path / "line.pts", np.c_[np.arange(68.0), 2 * np.arange(68.0) + 1])
    (tmp_path / "equal.json").write_text(json.dumps([[3, 4]] * 68))
    for name, found in (("equal.pts", r"all points equal at \(100, 100\)"), ("line.pts", "all points on one line"),
                        ("equal.json", r"all points equal at \(3, 4\)")):
        with pytest.raises(InputError, match=rf"cartoon landmark file .*{name}: expected points spread over the face, "
                                             rf"found {found}"):
            read_points2d(tmp_path / name)
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InputError, match="nested 100000 levels deep"):
        read_points2d(tmp_path / "deep.json")


def test_animate2d_on_an_undecodable_video_is_one_line(tmp_path, capsys, own_handlers):
    import dataclasses

    from facebasis.capture.synthetic import synthetic_sequence
    from facebasis.capture.trackfile import write_capture
    from facebasis.cli import main
    from facebasis.retarget.synthetic import capture_from_landmarks

    seq = synthetic_sequence(3, size=(96, 96))
    (tmp_path / "video.mp4").write_bytes(bytes(range(256)) * 64)  # was a video; now damaged
    cap = dataclasses.replace(capture_from_landmarks(seq.landmarks, fps=25, size=(96, 96)),
                              video=tmp_path / "video.mp4")
    write_capture(tmp_path / "cap", cap)
    assert main(["animate2d", str(tmp_path / "cap"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert one_line(err) and err.startswith(f"error: capture {tmp_path / 'cap'}: its video {tmp_path / 'video.mp4'}: "
                                            "expected a decodable video, found InvalidDataError"), err
    assert not (tmp_path / "out").exists()


def test_progress_bars_appear_only_for_long_loops_and_write_no_newline(capsys, monkeypatch):
    import facebasis.progress as progress

    monkeypatch.setenv("FACEBASIS_PROGRESS", "1")
    assert list(progress.progress(range(50), desc="reading")) == list(range(50))  # fast: nothing shown
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(progress, "DELAY", 0.0)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    with progress.progress(total=4, desc="writing shapes") as bar:
        for _ in range(4):
            bar.update(1)
    err = capsys.readouterr().err
    assert "writing shapes" in err and "\n" not in err  # a bar, erased at the end: the one-line rule holds
    monkeypatch.setenv("FACEBASIS_PROGRESS", "0")
    list(progress.progress(range(3), desc="off"))
    assert capsys.readouterr().err == ""
