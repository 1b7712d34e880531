import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from facebasis.geometry.rig import Rig
from problems.ict import ict_available  # the repository root is on sys.path: pytest's `pythonpath` (pyproject.toml)


def parser_refuses(main, argv, capsys, *needles):
    """The command line refuses ``argv`` while parsing (argparse: exit 2), naming every one of ``needles``
    on stderr."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and all(n in err for n in needles), err


def check_detail_choice_flag(main, tmp_path, capsys, monkeypatch, flag: str, field: str, bad: str, values: tuple):
    """A ``register`` choice flag of the detail prior (``flag``, :class:`DetailPriorOptions`'s ``field``): a bad value
    and a repeat refused while parsing, refused without the detail prior (one line, no output), and each of ``values``
    (the first the default) reaching the registration's options, the CLI's default being the library's."""
    import facebasis.geometry.registerfiles as rf
    from facebasis.geometry.detailprior import DetailPriorOptions

    out = tmp_path / "o"
    base = ["register", str(tmp_path / "s.obj"), "--template", str(tmp_path / "t.obj"), "--out", str(out)]
    parser_refuses(main, base + [flag, bad], capsys, flag, f"invalid choice: '{bad}'")
    parser_refuses(main, base + [flag, values[0], flag, values[-1]], capsys, flag)
    assert main(base + [flag, values[-1], "--detail-prior", "off", "--identity-prior", "fixed"]) == 2
    err = capsys.readouterr().err
    assert f"{flag} {values[-1]}: expected together with --detail-prior on" in err and err.count("\n") == 1
    assert not out.exists()
    seen = {}
    monkeypatch.setattr(rf, "register_files", lambda *a, **k: seen.setdefault("opts", a[5]) and {"scans": []})
    for given, how in [([], values[0])] + [([flag, v], v) for v in values[1:]]:
        seen.clear()
        assert main(base + given) == 0
        assert seen["opts"].detail == DetailPriorOptions(**{field: how})
    assert getattr(DetailPriorOptions(), field) == values[0]  # the CLI's default is the library's


def grid_sheet(nx=6, ny=5, z=0.0, size=1.0):
    """A flat triangulated sheet in the plane z, (V, F)."""
    xs, ys = np.meshgrid(np.linspace(0, size, nx), np.linspace(0, size * 0.8, ny), indexing="xy")
    V = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)], 1)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def bumpy_sheet(nx=8, ny=7, seed=0):
    V, F = grid_sheet(nx, ny)
    rng = np.random.default_rng(seed)
    V = V.copy()
    V[:, 2] = 0.2 * np.sin(3 * V[:, 0]) * np.cos(2 * V[:, 1]) + 0.01 * rng.standard_normal(len(V))
    return V, F


@pytest.fixture
def sheet():
    return bumpy_sheet()


requires_ict = pytest.mark.skipif(not ict_available(), reason="ICT data not found at ../shared/data/ict")


def write_rig_inputs(root, pp, n_iterations=None):
    """Write a person problem as `facebasis rig` inputs under ``root``: ``template/`` (rig folder),
    ``target.obj``, ``examples/<name>.obj`` and ``weights.json`` (rough weights by shape name)."""
    import json

    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import write_rig_folder

    p = pp.problem
    write_rig_folder(root / "template", p.template)
    write_mesh(root / "target.obj", p.target_neutral, p.template.faces)
    (root / "examples").mkdir()
    for name, T in zip(p.example_names, p.examples):
        write_mesh(root / "examples" / f"{name}.obj", T, p.template.faces)
    weights = {n: {s: float(v) for s, v in zip(p.template.names, row) if v > 0}
               for n, row in zip(p.example_names, p.initial_weights)}
    (root / "weights.json").write_text(json.dumps(weights))
    return root


def write_mp4(path, frames, crf=None):
    """Frames (n, H, W, 3) uint8 as an H.264 mp4 with its index up front (``faststart``), so that a file cut
    short still decodes its first frames (PyAV, independent of the package's own writers)."""
    import av

    frames = np.asarray(frames)
    with av.open(str(path), "w", options={"movflags": "faststart"}) as c:
        s = c.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = frames.shape[2], frames.shape[1], "yuv420p"
        if crf is not None:
            s.options = {"crf": str(crf)}
        for f in frames:
            for pk in s.encode(av.VideoFrame.from_ndarray(f, format="rgb24")):
                c.mux(pk)
        for pk in s.encode():
            c.mux(pk)
    return Path(path)


def _png_bytes(w=4, h=4):
    """A tiny RGB PNG (a texture for the FaceXModel-like folder)."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray((np.arange(w * h * 3).reshape(h, w, 3) * 7 % 255).astype(np.uint8)).save(buf, "PNG")
    return buf.getvalue()


def facex_like_obj(V, nx=12, ny=10, normals=True):
    """OBJ text laid out as ICT-FaceKit's FaceXModel files are: a header comment, ``mtllib``, the
    ``v`` lines, ``vt`` lines with a UV seam (more ``vt`` than ``v``), one ``vn`` per vertex, then
    groups with ``usemtl`` and smoothing groups over quads, a row of triangles and one hexagon,
    ``f v/vt/vn`` references (``f v/vt`` without ``normals``, as ICT-FaceKit's own files). ``V`` (nx * ny, 3)."""
    idx = np.arange(nx * ny).reshape(ny, nx)
    seam = nx // 2  # faces right of this column use a second copy of the seam column's vt
    uv = [(j / (nx - 1), i / (ny - 1)) for i in range(ny) for j in range(nx)]
    seam_vt = {i: len(uv) + i for i in range(ny)}
    uv += [(seam / (nx - 1) + 0.01, i / (ny - 1)) for i in range(ny)]
    vt_of = lambda i, j, right: seam_vt[i] if (j == seam and right) else idx[i, j]  # noqa: E731
    lines = ["# FaceXModel-like test mesh", "mtllib face.mtl"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in V]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
    lines += ["vn 0.000000 0.000000 1.000000"] * len(V) if normals else []

    def ref(i, j, right):
        return f"{idx[i, j] + 1}/{vt_of(i, j, right) + 1}" + (f"/{idx[i, j] + 1}" if normals else "")

    for i in range(ny - 1):
        if i == 0:
            lines += ["g mouth", "usemtl lips", "s 1"]
        if i == 3:
            lines += ["g head", "usemtl skin", "s off"]
        j = 0
        while j < nx - 1:
            right = j >= seam
            if i == ny - 2:  # the last row: triangles
                lines.append("f " + " ".join(ref(a, b, right) for a, b in ((i, j), (i, j + 1), (i + 1, j + 1))))
                lines.append("f " + " ".join(ref(a, b, right) for a, b in ((i, j), (i + 1, j + 1), (i + 1, j))))
            elif i == 4 and j == 2:  # one hexagon over two cells
                lines.append("f " + " ".join(ref(a, b, right) for a, b in ((i, j + 1), (i, j + 2), (i + 1, j + 2),
                                                                          (i + 1, j + 1), (i + 1, j), (i, j))))
                j += 1
            else:
                lines.append("f " + " ".join(ref(a, b, right) for a, b in ((i, j), (i, j + 1), (i + 1, j + 1),
                                                                          (i + 1, j))))
            j += 1
    return "\n".join(lines) + "\n"


def facex_like_positions(nx=12, ny=10):
    """A half-cylinder 'head' about 20 cm tall and 16 cm wide (centimetres, as ICT)."""
    th = np.linspace(-np.pi / 2, np.pi / 2, nx)
    y = np.linspace(-10.0, 10.0, ny)
    T, Y = np.meshgrid(th, y)
    return np.stack([8.0 * np.sin(T).ravel(), Y.ravel(), 8.0 * np.cos(T).ravel() + 0.3 * np.sin(Y).ravel()], 1)


def facex_like_folder(root, nx=12, ny=10, identities=2, normals=True):
    """A folder laid out like ICT-FaceKit's FaceXModel: ``generic_neutral_mesh.obj``, expressions
    (``jawOpen``, ``mouthSmile_L``, ``browInnerUp``), ``identity000.obj`` ... , ``face.mtl`` naming
    ``skin.png`` (a real PNG) for ``map_Kd``. Returns (folder, neutral positions, {name: positions})."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    V0 = facex_like_positions(nx, ny)
    rows = np.repeat(np.arange(ny), nx)
    cols = np.tile(np.arange(nx), ny)
    shapes = {
        "jawOpen": V0 + np.c_[0 * rows, -1.5 * (rows < 4) * (4 - rows) / 4, 0 * rows],
        "mouthSmile_L": V0 + np.c_[0.8 * (rows < 4) * (cols > nx // 2), 0.5 * (rows < 4) * (cols > nx // 2), 0 * rows],
        "browInnerUp": V0 + np.c_[0 * rows, 0.6 * (rows > ny - 4) * np.exp(-((cols - nx / 2) / 2) ** 2), 0 * rows],
    }
    for k in range(identities):
        shapes[f"identity{k:03d}"] = V0 * (1.0 + 0.05 * (k + 1))
    (root / "generic_neutral_mesh.obj").write_text(facex_like_obj(V0, nx, ny, normals))
    for name, V in shapes.items():
        (root / f"{name}.obj").write_text(facex_like_obj(V, nx, ny, normals))
    (root / "face.mtl").write_text("# materials\nnewmtl skin\nKd 0.8 0.6 0.5\nmap_Kd skin.png\n\n"
                                   "newmtl lips\nKd 0.7 0.3 0.3\nd 1.0\n")
    (root / "skin.png").write_bytes(_png_bytes())
    return root, V0, shapes


def swallow_signal_inside_ipopt(monkeypatch, signum):
    """Make every IPOPT solve of the weight step raise ``signum`` and swallow the interrupt, as CasADi
    does with an interrupt inside IPOPT (it reports a status instead); the run must stop all the same."""
    import signal

    from facebasis.rigging import weights

    real_init = weights.WeightSolver.__init__

    def init(self, *a, **k):
        real_init(self, *a, **k)
        solver = self._solver

        def swallowing(**args):
            try:
                signal.raise_signal(signum)
            except KeyboardInterrupt:
                pass
            return solver(**args)

        self._solver = swallowing

    monkeypatch.setattr(weights.WeightSolver, "__init__", init)


def _validator_dir():
    """A folder whose node_modules holds the npm package gltf-validator, or None."""
    if shutil.which("node") is None:
        return None
    for base in filter(None, [os.environ.get("FACEBASIS_GLTF_VALIDATOR"), "/tmp/gltfv", str(Path.home())]):
        if (Path(base) / "node_modules" / "gltf-validator").is_dir():
            return Path(base)
    return None


def gltf_validate(path):
    """The Khronos glTF-Validator's issues for ``path`` (.glb, or .gltf with its files beside it); the
    test skips where the npm package is not installed."""
    base = _validator_dir()
    if base is None:
        pytest.skip("npm package gltf-validator not installed (set FACEBASIS_GLTF_VALIDATOR to its folder)")
    # a .gltf's buffer and images are read beside it
    script = ("const v=require('gltf-validator');const fs=require('fs');const p=require('path');"
              f"const f={json.dumps(str(path))};"
              "const ext=(u)=>new Promise((ok,no)=>{try{ok(new Uint8Array(fs.readFileSync(p.join(p.dirname(f),"
              "decodeURIComponent(u)))));}catch(e){no(e.toString());}});"
              "v.validateBytes(new Uint8Array(fs.readFileSync(f)),{uri:f,externalResourceFunction:ext})"
              ".then(r=>{console.log(JSON.stringify(r.issues));}).catch(e=>{console.error(e);process.exit(3);});")
    out = subprocess.run(["node", "-e", script], cwd=base, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def two_sheets(gap=0.6, push=0.5, bottom_len=1.5):
    """A long top sheet (x in [0, 4]) above a short bottom sheet (x in [0, bottom_len]) at distance
    ``gap``; the template shape pushes the top sheet down by ``push`` (still along its long borders,
    which anchor it). Returns the template rig."""
    Vt, Ft = grid_sheet(21, 7, z=gap, size=4.0)
    Vb, Fb = grid_sheet(9, 7, z=0.0, size=bottom_len)
    Vb[:, 1] *= 4.0 / bottom_len  # same width as the top sheet
    Vb[:, :2] += (0.05, 0.0)
    Vt[:, 2] += 0.01 * np.sin(3.0 * Vt[:, 0] + 1.0) * np.cos(2.0 * Vt[:, 1])  # not coplanar: fast exact tests
    Vb[:, 2] += 0.01 * np.cos(2.0 * Vb[:, 0]) * np.sin(3.0 * Vb[:, 1] + 0.5)
    V = np.concatenate([Vt, Vb])
    F = np.concatenate([Ft, Fb + len(Vt)])
    d = np.zeros_like(V)
    y = Vt[:, 1] / Vt[:, 1].max()
    d[: len(Vt), 2] = -push * np.sin(np.pi * y) ** 2
    return Rig(V, F, ("push", "still"), np.stack([d, np.zeros_like(d)]))


def stretched(V, sx=1.1, gap=0.3):
    """The target neutral: stretched along x, the top sheet lowered to ``gap`` above the bottom one."""
    W = V.copy()
    W[:, 0] *= sx
    W[W[:, 2] > 0.1, 2] += gap - 0.6
    return W


def capture_cli_inputs(tmp_path, frames=3, size=(96, 96)):
    """A generated sequence written as a PNG folder with its frame-0 landmarks: ``(seq, folder, base)``,
    ``base`` the ``capture`` command line tracking it (no overlay, no progress bar) without ``--out``."""
    import cv2

    from facebasis.capture.landmarks import format_pts
    from facebasis.capture.synthetic import synthetic_sequence

    seq = synthetic_sequence(frames, size=size)
    d = tmp_path / "frames"
    d.mkdir()
    for i, f in enumerate(seq.frames):
        cv2.imwrite(str(d / f"f{i:03d}.png"), f[..., ::-1])
    (tmp_path / "first.pts").write_text(format_pts(seq.landmarks[0]))
    return seq, d, ["capture", str(d), "--landmarks", str(tmp_path / "first.pts"), "--no-overlay", "--no-progress"]
