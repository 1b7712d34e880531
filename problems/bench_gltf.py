"""glTF export and OBJ layout writing, timed: ``python -m problems.bench_gltf [--repeat N]``.

* ``facebasis export`` of the ICT rig (53 expressions, 14,062 vertices; the built-in face when the
  ICT data is absent) as a whole process, and the glTF serialisation in process;
* the package's own GLB writer against pygltflib (the same document and buffer, given to
  ``pygltflib.GLTF2.from_dict`` and ``save_to_bytes``): time and size;
* OBJ output in a FaceXModel-like layout (``vt`` with a seam, ``vn``, ``usemtl``, groups, quads;
  14,400 vertices) against the plain writer, and the plain read, for one 14k-vertex mesh.

Everything is written into a temporary folder; the machine's load average is printed beside the
figures.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _best(fn, repeat):
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out), statistics.median(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")

    from facebasis.geometry import obj
    from facebasis.geometry.gltf import _finish, glb_bytes, gltf_document
    from facebasis.geometry.meshio import read_mesh, write_mesh
    from facebasis.geometry.objlayout import read_obj_layout
    from facebasis.geometry.rig import write_rig_folder
    from problems.ict import ict_available, ict_rig

    root = Path(tempfile.mkdtemp(prefix="bench_gltf_"))
    if ict_available():
        rig, what = ict_rig(), "ICT rig"
    else:
        from facebasis.defaults.face import default_template

        rig, what = default_template(), "built-in face (ICT data absent)"
    write_rig_folder(root / "rig", rig)
    print(f"{what}: {rig.n_shapes} shapes, {rig.n_vertices} vertices; load {os.getloadavg()[0]:.2f}")
    import resource

    def child(cmd):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.perf_counter() - t0, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime

    runs = [child([sys.executable, "-m", "facebasis.cli", "export", str(root / "rig"), "--out", str(root / "rig.glb")])
            for _ in range(args.repeat)]
    imp = min(child([sys.executable, "-c", "import facebasis.cli"]) for _ in range(args.repeat))
    print(f"facebasis export, whole process: wall {min(r[0] for r in runs):.3f} s best, "
          f"{statistics.median(r[0] for r in runs):.3f} s median; CPU {min(r[1] for r in runs):.3f} s best "
          f"(python + imports alone: wall {imp[0]:.3f} s, CPU {imp[1]:.3f} s)")
    best, med = _best(lambda: glb_bytes(rig), args.repeat)
    own = glb_bytes(rig)
    print(f"own GLB writer (document + normals + buffer): {best * 1e3:.0f} ms best, {med * 1e3:.0f} ms median, "
          f"{len(own) / 1e6:.2f} MB")
    try:
        import pygltflib
    except ImportError:
        print("pygltflib not installed: comparison skipped")
    else:
        doc, buf, _ = gltf_document(rig.neutral, rig.faces, rig.deltas, rig.names)
        full = _finish(doc, buf)

        def with_pygltflib():
            g = pygltflib.GLTF2.from_dict(dict(full, buffers=[{"byteLength": buf.offset}]))
            g.set_binary_blob(buf.binary())
            return b"".join(g.save_to_bytes())

        t_doc, _ = _best(lambda: gltf_document(rig.neutral, rig.faces, rig.deltas, rig.names), args.repeat)
        best_p, med_p = _best(with_pygltflib, args.repeat)
        size_p = len(with_pygltflib())
        print(f"pygltflib (from_dict + save_to_bytes of the same document): {(best_p + t_doc) * 1e3:.0f} ms best "
              f"incl. the document, {best_p * 1e3:.0f} ms of it pygltflib, {size_p / 1e6:.2f} MB "
              f"({size_p - len(own):+d} bytes)")
    # OBJ in a FaceXModel-like layout, 120 x 120 = 14,400 vertices
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from conftest import facex_like_obj, facex_like_positions  # noqa: E402

    V0 = facex_like_positions(120, 120)
    (root / "facex").mkdir()
    (root / "facex" / "face.obj").write_text(facex_like_obj(V0, 120, 120))
    layout = read_obj_layout(root / "facex" / "face.obj")
    V1 = V0 + 0.01
    b_lay, m_lay = _best(lambda: layout.obj_bytes(V1), args.repeat)
    Vp, Fp = read_mesh(root / "facex" / "face.obj")
    b_plain, m_plain = _best(lambda: obj.obj_bytes(Vp, Fp), args.repeat)
    t_layout_read, _ = _best(lambda: read_obj_layout(root / "facex" / "face.obj"), args.repeat)
    write_mesh(root / "plain.obj", rig.neutral, rig.faces)
    b_read, m_read = _best(lambda: read_mesh(root / "plain.obj"), args.repeat)
    b_write, m_write = _best(lambda: write_mesh(root / "plain_w.obj", rig.neutral, rig.faces), args.repeat)
    print(f"OBJ bytes in the template's layout (14,400 v, vt/vn/usemtl/quads): {b_lay * 1e3:.1f} ms best, "
          f"{m_lay * 1e3:.1f} ms median; plain writer of the same mesh {b_plain * 1e3:.1f} ms; reading the layout "
          f"once per template {t_layout_read * 1e3:.1f} ms")
    print(f"plain OBJ, {rig.n_vertices} vertices: read {b_read * 1e3:.1f} ms best ({m_read * 1e3:.1f} median), "
          f"write {b_write * 1e3:.1f} ms best ({m_write * 1e3:.1f} median)")
    print(f"load {os.getloadavg()[0]:.2f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
