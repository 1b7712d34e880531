"""Write the ICT data as the files the command line takes, to reproduce the benchmarks by hand.

``python -m problems.export_ict OUT_DIR [--seed 0] [--train 20] [--scale 1]``

writes, from ``../shared/data/ict/ict_face.npz`` (never into this repository: OUT_DIR must lie
outside it):

* ``template/``      ICT's neutral and its 53 expressions as a rig folder (``neutral.obj`` + one
  OBJ per expression);
* ``target.obj``     a seeded random identity (the benchmarks' target neutral; ``--scale 3`` gives
  the penetration benchmark's exaggerated identity);
* ``person/``        the person case of ``python -m problems.bench rig``: ``examples/`` (training
  expressions), ``weights.json`` (rough weights), ``heldout/`` (held-out expressions) and
  ``truth/`` (the person's true rig, a rig folder);
* ``landmarks68.json``  ICT's 68 landmark vertex indices (for ``facebasis retarget``);
* ``commands.txt``   the command lines that run on these files.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def export(out: Path, seed: int = 0, n_train: int = 20, scale: float = 1.0) -> list[str]:
    from facebasis.atomic import atomic_directory, atomic_write_json
    from facebasis.errors import InputError
    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import write_rig_folder
    from facebasis.rigging.runs import write_problem_inputs
    from problems.generation import ICT_EXCLUSIVE, ict_person_problem
    from problems.ict import _load, ict_random_identity, ict_rig

    out = Path(out).absolute()
    if out == REPO or REPO in out.parents:
        raise InputError(f"OUT_DIR {out}: expected a folder outside the repository (ICT data is never stored "
                         f"in it), found one inside {REPO}")
    rig = ict_rig()
    _, target = ict_random_identity(seed, scale)
    pp = ict_person_problem(seed=seed, n_train=n_train)
    with atomic_directory(out) as stage:
        write_rig_folder(stage / "template", rig)
        write_mesh(stage / "target.obj", target, rig.faces)
        write_problem_inputs(stage / "person", pp.problem)
        for i, T in enumerate(pp.heldout):  # (h, n, 3)
            write_mesh(stage / "person" / "heldout" / f"heldout{i:02d}.obj", T, rig.faces)
        write_rig_folder(stage / "person" / "truth", pp.truth)
        write_mesh(stage / "person" / "target.obj", pp.problem.target_neutral, rig.faces)
        atomic_write_json(stage / "landmarks68.json", [int(i) for i in _load()["landmarks68"]])
        pairs = " ".join(f"{a}:{b}" for a, b in ICT_EXCLUSIVE)
        commands = [
            f"facebasis transfer --template {out}/template --target {out}/target.obj --out {out}/transfer",
            f"facebasis rig --template {out}/template --target {out}/person/target.obj "
            f"--examples {out}/person/examples --weights {out}/person/weights.json --exclusive {pairs} "
            f"--out {out}/rig",
            f"facebasis verify {out}/rig",
            f"facebasis report {out}/rig",
            f"facebasis virtual-edges {out}/template/neutral.obj --out {out}/edges.json",
            f"facebasis transfer --template {out}/template --target {out}/target.obj --virtual-edges "
            f"{out}/edges.json --out {out}/transfer_ve",
            f"facebasis penetration {out}/transfer_ve/jawOpen.obj --reference {out}/template/jawOpen.obj "
            f"--reference {out}/target.obj --rest {out}/target.obj",
            f"facebasis retarget CAPTURE_DIR --rig {out}/template --landmarks {out}/landmarks68.json "
            f"--exclusive {pairs} --out {out}/retarget",
        ]
        (stage / "commands.txt").write_text("\n".join(commands) + "\n")
    return commands


def main(argv=None) -> int:
    from facebasis.errors import FacebasisError

    parser = argparse.ArgumentParser(prog="python -m problems.export_ict", description=__doc__.splitlines()[0])
    parser.add_argument("out", help="output folder, outside the repository")
    parser.add_argument("--seed", type=int, default=0, help="identity and person-case seed (default 0)")
    parser.add_argument("--train", type=int, default=20, help="training expressions (default 20)")
    parser.add_argument("--scale", type=float, default=1.0, help="identity scale of target.obj (default 1)")
    args = parser.parse_args(argv)
    try:
        commands = export(Path(args.out), args.seed, args.train, args.scale)
    except FacebasisError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}; commands that run on it ({args.out}/commands.txt):")
    print("\n".join(commands))
    return 0


if __name__ == "__main__":
    sys.exit(main())
