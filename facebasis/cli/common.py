"""Argument helpers shared by several command groups."""

from __future__ import annotations

import argparse


#: the command line's name for every library parameter a structured error names
#: (:meth:`facebasis.errors.FacebasisError.renamed`): the library says what it knows, the CLI maps
#: its fields to the flags the user typed
FLAGS = {"iterations": "--iterations", "alpha": "--alpha", "lam": "--lambda", "support": "--support",
         "cv_folds": "--cv-folds", "cv_grid": "--cv-grid", "cv_candidates": "--cv-candidates",
         "virtual_weight": "--virtual-weight", "virtual_mode": "--virtual-mode", "virtual_edges": "--virtual-edges",
         "ipopt": "--ipopt", "unobserved": "--unobserved", "exclusive": "--exclusive", "run_dir": "--resume",
         "template": "--template", "target": "--target", "more_examples": "--examples", "more_weights": "--weights",
         "contact": "--contact", "landmarks": "--landmarks", "detector": "--detector", "image": "--image",
         "mesh": "--mesh", "rig": "--rig", "neutral": "--neutral", "exclude": "--exclude", "unit": "--unit",
         "head": "--head", "ridge": "--ridge", "identity": "--identity", "first_frame_neutral": "--first-frame-neutral",
         "region": "--region", "max_frames": "--max-frames", "fps": "--fps", "identity_basis": "--identity-basis",
         "expression_basis": "--expression-basis", "expression_transfer": "--expression-transfer",
         "amplitude": "--amplitude", "jaw": "--jaw", "expression_regions": "--expression-regions", "detail_modes": "--detail-modes",
         "detail_basis": "--detail-basis", "detail_amplitude": "--detail-amplitude",
         "detail_field_normals": "--detail-field-normals", "detail_amplitude_map": "--detail-amplitude-map",
         "expression_scan_pairs": "--expression-scan-pairs", "expression_pairs_schedule": "--expression-pairs-schedule",
         "rest_anchor": "--rest-anchor", "focal": "--focal", "noise_model": "--noise-model",
         "point_noise": "--point-noise", "gaze": "--gaze",
         "rest_depth": "--rest-depth"}

#: a command whose flag for a library parameter is not :data:`FLAGS`'s (``landmarks``' ``--frame`` is
#: :func:`facebasis.capture.video.read_frame`'s ``index``)
COMMAND_FLAGS = {"landmarks": {"index": "--frame"}}


def flags_of(command: str | None) -> dict:
    """{library parameter: flag} of one command: :data:`FLAGS` with the command's own names over it."""
    return {**FLAGS, **COMMAND_FLAGS.get(command, {})}


def add_rig_folder_args(p: argparse.ArgumentParser, *, template: str | None = "required",
                        template_help: str = "template rig folder (neutral + one mesh per blendshape)",
                        template_metavar: str | None = None, where: str = "the rig folder",
                        exclude_note: str = "") -> None:
    """The arguments of a rig folder, declared once for every command that reads one: ``--template``
    (``template`` "required", "optional" or None for a command that names the folder otherwise),
    ``--neutral`` (the neutral's file name inside ``where``) and ``--exclude`` (globs of files to
    ignore; ``exclude_note`` ends its help)."""
    if template is not None:
        p.add_argument("--template", required=template == "required", default=None, metavar=template_metavar,
                       help=template_help)
    p.add_argument("--neutral", default="neutral.obj",
                   help=f"file name of the neutral inside {where} (default neutral.obj)")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB",
                   help="ignore rig-folder files matching this glob (repeatable), e.g. 'identity*'" + exclude_note)


def say(command: str | None):
    """``print`` for a library's ``log``: a hint or warning that names library parameters
    (:class:`facebasis.errors.NamedText`) is printed with the command's flags."""
    from ..errors import renamed_text

    names = flags_of(command)
    return lambda text, *a, **k: print(renamed_text(text, names), *a, **k)


def warn_rig_folder(rig) -> None:
    """One line on stderr for a rig folder that looks as it ships (identity modes, many shapes)."""
    import sys

    from ..errors import renamed_text
    from ..geometry.rig import rig_folder_warning

    warning = rig_folder_warning(rig)
    if warning:
        print(renamed_text(warning, FLAGS), file=sys.stderr)


def once(values, flag: str) -> list:
    """``values`` in order with repeats dropped, saying so (a repeated flag value is kept once)."""
    import sys

    out = list(dict.fromkeys(values))
    if len(out) < len(values):
        repeated = sorted({str(v) for v in values if values.count(v) > 1})
        print(f"note: {flag} {', '.join(repeated)} given more than once: used once", file=sys.stderr)
    return out


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


def check_virtual_edge_args(args, allowed_without_edges: bool = False) -> str:
    """``--virtual-weight`` / ``--virtual-mode`` shape the virtual-edge energy, so they are refused
    without ``--virtual-edges`` (before any work) instead of being ignored, unless
    ``allowed_without_edges`` (a resumed run refuses them itself). Returns the mode (its default
    when not given); the namespace is not changed."""
    from ..contact.virtual_edges import VIRTUAL_MODES
    from ..errors import InputError

    given = [flag for flag, v in (("--virtual-weight", args.virtual_weight), ("--virtual-mode", args.virtual_mode))
             if v is not None]
    if given and args.virtual_edges is None and not allowed_without_edges:
        raise InputError(f"{', '.join(given)}: expected --virtual-edges as well, found none")
    w = args.virtual_weight
    if w is not None and not (0.0 < w < float("inf")):  # before the meshes are read and the edges detected
        raise InputError(f"--virtual-weight: expected a positive number, found {w:g}")
    return VIRTUAL_MODES[0] if args.virtual_mode is None else args.virtual_mode


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
    never a silent overwrite of the first. It takes no default (a default would read as the option
    given once already): declare ``default=None`` and apply the default after parsing."""

    def __init__(self, option_strings, dest, default=None, **kwargs):
        if default is not None:
            raise ValueError(f"{'/'.join(option_strings)}: a Once option cannot have a default (found {default!r}): "
                             "given once, it would be refused as given twice")
        super().__init__(option_strings, dest, default=None, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest, None) is not None:
            parser.error(f"argument {option_string}: expected once, found it given twice "
                         f"(keeping only the last would drop {getattr(namespace, self.dest)})")
        setattr(namespace, self.dest, values)
