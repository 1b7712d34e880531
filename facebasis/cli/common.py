"""Argument helpers shared by several command groups."""

from __future__ import annotations

import argparse


def add_rig_folder_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--template", required=True, help="template rig folder (neutral + one mesh per blendshape)")
    p.add_argument("--neutral", default="neutral.obj",
                   help="file name of the neutral inside the rig folder (default neutral.obj)")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB",
                   help="ignore rig-folder files matching this glob (repeatable), e.g. 'identity*'")


def virtual_edges_for(args, template):
    """``--virtual-edges [EDGES.json]``: read the file, or detect on the template's neutral."""
    if args.virtual_edges is None:
        return None
    from ..contact.virtual_edges import VirtualEdges, detect_virtual_edges

    if args.virtual_edges == "detect":
        ve = detect_virtual_edges(template.neutral, template.faces, name=f"template {template.source}")
        print(f"virtual edges: {len(ve)} detected on the template neutral in {ve.seconds:.2f} s")
        return ve
    ve = VirtualEdges.read(args.virtual_edges, template.n_vertices)
    print(f"virtual edges: {len(ve)} from {args.virtual_edges}")
    return ve


def check_virtual_edge_args(args) -> None:
    """``--virtual-weight`` / ``--virtual-mode`` shape the virtual-edge energy, so they are refused
    without ``--virtual-edges`` (before any work) instead of being ignored; fills the mode's default.
    A resumed run (``rig --resume``) refuses them itself."""
    from ..contact.virtual_edges import VIRTUAL_MODES
    from ..errors import InputError

    given = [flag for flag, v in (("--virtual-weight", args.virtual_weight), ("--virtual-mode", args.virtual_mode))
             if v is not None]
    if given and args.virtual_edges is None and getattr(args, "resume", None) is None:
        raise InputError(f"{', '.join(given)}: expected --virtual-edges as well, found none")
    w = args.virtual_weight
    if w is not None and not (0.0 < w < float("inf")):  # before the meshes are read and the edges detected
        raise InputError(f"--virtual-weight: expected a positive number, found {w:g}")
    if args.virtual_mode is None:
        args.virtual_mode = VIRTUAL_MODES[0]


def add_virtual_edge_args(p: argparse.ArgumentParser) -> None:
    from ..contact.virtual_edges import DEFAULT_VIRTUAL_WEIGHT, VIRTUAL_MODES

    p.add_argument("--virtual-edges", nargs="?", const="detect", default=None, metavar="EDGES.json",
                   help="add the virtual-edge energy against penetration (Li et al. 2023); without a file the "
                        "edges are detected on the template neutral with the default parameters")
    p.add_argument("--virtual-weight", type=float, default=None,
                   help=f"weight of the virtual-edge energy (default {DEFAULT_VIRTUAL_WEIGHT:g})")
    p.add_argument("--virtual-mode", choices=VIRTUAL_MODES, default=None,
                   help="virtual-edge targets: the template's gap motion scaled down to a thinner target "
                        "gap (proportional, default) or the local gradient only (gradient)")


def pair_of_floats(text: str, name: str) -> tuple[float, float]:
    from ..errors import InputError

    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise InputError(f"{name}: expected two numbers FIRST,LAST, found {text!r}") from exc
    if len(vals) == 1:
        vals = vals * 2
    if len(vals) != 2:
        raise InputError(f"{name}: expected two numbers FIRST,LAST, found {text!r}")
    return vals[0], vals[1]


def describe_pairs(pairs, given: int) -> str:
    """``"3 exclusive pairs: a:b, c:d, e:f"`` (and how many repeats of a pair were merged)."""
    text = f"{len(pairs)} exclusive pairs" + (": " + ", ".join(f"{a}:{b}" for a, b in pairs) if pairs else "")
    if given > len(pairs):
        text += f" ({given - len(pairs)} repeated pair(s) merged)"
    return text


class Once(argparse.Action):
    """An option that takes several values once (e.g. a pair of files); given twice it is an error,
    never a silent overwrite of the first."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest, None) is not None:
            parser.error(f"argument {option_string}: expected once, found it given twice "
                         f"(keeping only the last would drop {getattr(namespace, self.dest)})")
        setattr(namespace, self.dest, values)
