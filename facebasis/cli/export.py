"""``facebasis export`` (a rig folder as glTF 2.0) and ``facebasis verify`` (re-certify the stored
weights of a ``facebasis rig`` output folder)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from .common import add_rig_folder_args, describe_pairs, warn_rig_folder
from .outputs import READS_ONLY, Outputs


def cmd_verify(args) -> int:
    from ..errors import InputError
    from ..rigging.examples import parse_pairs
    from ..rigging.verify import verify_run

    if not 0 <= args.tolerance < float("inf"):
        raise InputError(f"--tolerance: expected a relative gap >= 0, found {args.tolerance}")
    report = verify_run(args.run_dir, tolerance=args.tolerance, check_pairs=parse_pairs(args.exclusive))
    print(f"{report.run_dir}: {len(report.examples)} examples, lambda {report.lam:g}, tolerance {report.tolerance:g} "
          "(relative objective gap of the stored weights to the certified global optimum)")
    print(f"exclusive pairs of the run: {describe_pairs(report.pairs, len(report.pairs))}")
    print(report.table())
    bad = [e.name for e in report.examples if not e.ok]
    if report.checked:
        print("pairs named with --exclusive (largest |x_a x_b| of the stored weights over all examples):")
        for chk in report.checked:
            flag = "ok" if chk.ok else "BREACHED"
            print(f"  {chk.a}:{chk.b}  {chk.max_product:.3g}  at {chk.worst_example}  "
                  f"({'a constraint of the run' if chk.in_run else 'not a constraint of the run'})  {flag}")
        breached = [f"{c.a}:{c.b}" for c in report.checked if not c.ok]
        if breached:
            print(f"NOT EXCLUSIVE: the stored weights breach {len(breached)} pair(s) named with --exclusive "
                  f"({', '.join(breached)})", file=sys.stderr)
    else:
        breached = []
    if bad:  # said as well when a named pair is breached: both verdicts, one exit status
        print(f"NOT OPTIMAL: {len(bad)} of {len(report.examples)} stored answers ({', '.join(bad)})", file=sys.stderr)
    if bad or breached:
        return 1
    print(f"all {len(report.examples)} stored answers are certified optimal")
    return 0


def _gltf_buffer(args) -> list:
    """``export --out X.gltf`` also writes ``X.bin`` beside it."""
    out = Path(args.out)
    return [(str(out.with_suffix(".bin")), "file", "--out (its .bin)")] if out.suffix.lower() == ".gltf" else []


def cmd_export(args) -> int:
    from ..errors import InputError
    from ..geometry.gltf import check_gltf_path, unit_scale, write_glb
    from ..geometry.rig import load_rig_folder

    if args.template is not None and args.rig is not None:
        raise InputError(f"export: expected the rig folder once, found {args.rig} and --template {args.template}")
    folder = args.rig if args.rig is not None else args.template
    if folder is None:
        raise InputError("export: expected a rig folder (RIG_DIR or --template), found none")
    unit_scale(args.unit)
    check_gltf_path(args.out, "--out")
    rig = load_rig_folder(folder, args.neutral, args.exclude)
    warn_rig_folder(rig)
    t0 = time.perf_counter()
    out = write_glb(rig, args.out, unit=args.unit)
    layout = rig.layout
    what = ("" if layout is None else
            f", UVs {'yes' if layout.uv is not None else 'no'}, {max(len(layout.material_names), 1)} material(s)")
    print(f"{rig.n_shapes} morph targets, {rig.n_vertices} vertices{what}, {args.unit} -> metres, written in "
          f"{time.perf_counter() - t0:.3f} s -> {out}")
    return 0


def register(sub) -> None:
    """Add ``export`` and ``verify`` to the ``facebasis`` parser."""
    p = sub.add_parser("export", help="a rig folder as glTF 2.0 (.glb or .gltf) with one morph target per shape")
    p.add_argument("rig", nargs="?", default=None,
                   help="rig folder (neutral + one mesh per blendshape), e.g. a facebasis rig output")
    add_rig_folder_args(p, template="optional", template_metavar="RIG_DIR",
                        template_help="the rig folder, spelled as transfer spells it")
    p.add_argument("--unit", default="cm", metavar="cm|m|mm",
                   help="the rig's length unit (default cm: ICT-FaceKit and the built-in face); glTF is written in "
                        "metres and the unit recorded in asset.extras")
    p.add_argument("--out", required=True,
                   help="output .glb (binary glTF) or .gltf (JSON, with OUT.bin and the textures beside it); the "
                        "folder must exist")
    p.set_defaults(func=cmd_export, outputs=Outputs(writes=(("out", "file", "--out"),), reads=("rig", "template"),
                                                    also=_gltf_buffer))

    p = sub.add_parser("verify", help="certify the stored weights of a facebasis rig output folder")
    p.add_argument("run_dir", help="output folder of facebasis rig (with inputs.json)")
    p.add_argument("--tolerance", type=float, default=1e-6,
                   help="largest relative objective gap accepted (default 1e-6); exit status 1 beyond it")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="also report the largest product x_a x_b of the stored weights over these pairs "
                        "(several after one flag or repeated); exit status 1 if any exceeds 1e-8")
    p.set_defaults(func=cmd_verify, outputs=READS_ONLY)
