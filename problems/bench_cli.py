"""What the user waits for: the CLI as a whole process, on ICT-sized data.

``python -m problems.bench cli [--repeat N] [--facex DIR]``

Writes the ICT rig (53 expressions, 14,062 vertices) as a rig folder, a target identity and a
20-example person problem into a temporary folder (never into the repository), then times, as
separate processes: ``facebasis transfer``, ``facebasis rig`` (20 examples, 10 iterations), the
CLI's import, and OBJ reading/writing of one 14k-vertex mesh in process (the read figure parses the
f lines each time; with them cached, as for a rig's second and later shapes, it is printed too).
Wall and CPU time (the child processes' user + system) are printed with the machine's load
average, so a loaded machine shows. With ``--facex DIR`` (ICT-FaceKit's ``FaceXModel`` folder as it
ships) it also times the transfer of the raw folder (the generic neutral and its expressions,
26,719 vertices, quads, materials) onto one of its identities.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _run(cmd, repeat):
    """Wall and CPU seconds of ``cmd`` as a subprocess, ``repeat`` times; the last run's output."""
    walls, cpus = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{proc.stderr}")
    return walls, cpus, proc.stdout


def _line(label, walls, cpus, target):
    print(f"  {label:44s} wall median {statistics.median(walls):6.2f} s (min {min(walls):.2f}, max {max(walls):.2f}), "
          f"CPU median {statistics.median(cpus):6.2f} s over {len(walls)} runs  [target <= {target}]")


def bench_cli(repeat: int, facex: str | None = None) -> dict:
    import numpy as np

    from facebasis.geometry import obj
    from facebasis.geometry.meshio import read_mesh, write_mesh
    from facebasis.geometry.rig import load_rig_folder, write_rig_folder
    from facebasis.geometry.transfer import deformation_transfer
    from facebasis.rigging.runs import write_problem_inputs
    from problems.generation import ict_person_problem

    exe = [sys.executable, "-m", "facebasis.cli"]
    out = {}
    print(f"cli: load average {os.getloadavg()[0]:.2f} (1 min) before the runs")
    with tempfile.TemporaryDirectory(prefix="facebasis-bench-cli-") as tmp:
        root = Path(tmp)
        pp = ict_person_problem(seed=0)
        p = pp.problem
        write_rig_folder(root / "template", p.template)
        write_mesh(root / "target.obj", p.target_neutral, p.template.faces)
        write_problem_inputs(root, p)  # examples/<name>.obj and weights.json, as `facebasis rig` takes them

        walls, cpus, _ = _run(exe[:1] + ["-c", "import facebasis.cli; facebasis.cli.build_parser()"], repeat)
        _line("import of the CLI + parser", walls, cpus, "0.5 s")
        out["import_s"] = statistics.median(walls)

        cmd = exe + ["transfer", "--template", root / "template", "--target", root / "target.obj",
                     "--out", root / "dt"]
        walls, cpus, _ = _run(cmd, repeat)
        _line(f"facebasis transfer ({p.template.n_shapes} shapes)", walls, cpus, "2.5 s")
        out["transfer_s"] = statistics.median(walls)
        got = load_rig_folder(root / "dt")
        ref = deformation_transfer(p.template, p.target_neutral)
        diff = np.abs(got.deltas - ref.deltas[[ref.names.index(n) for n in got.names]]).max()
        print(f"    outputs: largest difference to the in-process transfer {diff:.1e} cm (10 decimals in OBJ)")

        cmd = exe + ["rig", "--template", root / "template", "--target", root / "target.obj", "--examples",
                     root / "examples", "--weights", root / "weights.json", "--out", root / "rig", "--iterations", "10"]
        walls, cpus, stdout = _run(cmd, max(1, repeat // 2))
        _line(f"facebasis rig ({len(p.examples)} examples, 10 iterations)", walls, cpus, "6 s")
        out["rig_s"] = statistics.median(walls)
        print("    " + [s for s in stdout.splitlines() if s.startswith("generated")][-1])

        mesh = root / "template" / "neutral.obj"
        V, F = read_mesh(mesh)
        ms = {key: ([], []) for key in ("read", "read, f lines cached", "write", "write, f lines formatted")}
        for _ in range(20):  # "read": each read parses its f lines (the reader caches them for a rig's next shape)
            for key, call in (("read", lambda: (obj._FACE_CACHE.clear(), read_mesh(mesh))),
                              ("read, f lines cached", lambda: read_mesh(mesh)),
                              ("write", lambda: write_mesh(root / "w.obj", V, F)),  # f lines cached after the first
                              ("write, f lines formatted", lambda: (obj._FACE_BLOCKS.clear(), write_mesh(root / "w.obj", V, F)))):
                c0, t0 = time.process_time(), time.perf_counter()
                call()
                ms[key][0].append(1e3 * (time.perf_counter() - t0))
                ms[key][1].append(1e3 * (time.process_time() - c0))
        print(f"  OBJ of {len(V)} vertices, {len(F)} triangles: read median {statistics.median(ms['read'][0]):.1f} ms, "
              f"write median {statistics.median(ms['write'][0]):.1f} ms over 20  [target <= 10 ms each]")
        print("    " + "; ".join(f"{key} {statistics.median(w):.1f} ms (CPU {statistics.median(c):.1f})"
                                 for key, (w, c) in ms.items()))
        out["obj_read_ms"], out["obj_write_ms"] = statistics.median(ms["read"][0]), statistics.median(ms["write"][0])

        if facex:
            folder = Path(facex)
            target = folder / "identity003.obj"
            cmd = exe + ["transfer", "--template", folder, "--neutral", "generic_neutral_mesh.obj", "--exclude",
                         "identity*", "--target", target, "--out", root / "facex"]
            walls, cpus, stdout = _run(cmd, max(1, repeat // 2))
            _line("raw FaceXModel folder onto identity003", walls, cpus, "10 s")
            print("    " + stdout.strip().splitlines()[-1])
            out["facex_s"] = statistics.median(walls)
    print(f"  load average {os.getloadavg()[0]:.2f} (1 min) after the runs")
    return out
