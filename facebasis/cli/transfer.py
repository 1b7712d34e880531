"""``facebasis transfer``: deformation transfer of a template rig onto a target neutral (Sumner and
Popovic 2004), optionally with the virtual-edge energy or exact contact."""

from __future__ import annotations

import sys
import time

from .common import add_rig_folder_args, add_virtual_edge_args, check_virtual_edge_args, virtual_edges_for, warn_rig_folder
from .exact_contact import add_contact_args, check_contact_target, contact_request, contact_verdict, write_contact
from .outputs import Outputs


def cmd_transfer(args) -> int:
    from ..atomic import atomic_directory
    from ..geometry.rig import load_rig_folder, load_target_neutral, write_shapes
    from ..geometry.transfer import DeformationTransfer

    contact = contact_request(args)
    virtual_mode = check_virtual_edge_args(args)
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    warn_rig_folder(template)
    target = load_target_neutral(args.target, template)
    if contact is not None:  # names, size and the target's own intersections, before any solving (as rig does)
        check_contact_target(contact, template, target, args.target)
    ve = virtual_edges_for(args, template)
    t0 = time.perf_counter()
    dt = DeformationTransfer(template, target, virtual_edges=ve, virtual_weight=args.virtual_weight,
                             virtual_mode=virtual_mode)
    found = None
    if contact is not None:
        from ..contact.exact import contact_transfer

        found = contact_transfer(template, target, exclude=list(contact.exclude), transfer=dt,
                                 allow_target_pairs=contact.allow_target_pairs)
        result = found.rig
    else:
        result = dt.transfer()
    seconds = time.perf_counter() - t0
    with atomic_directory(args.out) as stage:
        missing = write_shapes(stage, result, layout=template.layout)
        if found is not None:
            write_contact(stage, found)
    print(f"transferred {result.n_shapes} shapes onto {args.target} in {seconds:.3f} s -> {args.out}")
    if missing:
        print(f"note: the template names {', '.join(missing)}, not found beside {args.template}: not copied",
              file=sys.stderr)
    if found is not None:
        print(found.table())
        return contact_verdict(found, "transferred", list(contact.exclude))
    return 0


def edges_file(args) -> list:
    """``--virtual-edges EDGES.json`` (without a file the edges are detected: nothing read)."""
    return [] if args.virtual_edges in (None, "detect") else [args.virtual_edges]


def register(sub) -> None:
    """Add ``transfer`` to the ``facebasis`` parser."""
    p = sub.add_parser("transfer", help="deformation transfer of a template rig onto a target neutral")
    add_rig_folder_args(p)
    p.add_argument("--target", required=True, help="target neutral mesh (.obj/.ply), template topology")
    p.add_argument("--out", required=True, help="output folder: <shape>.obj for every template shape")
    add_virtual_edge_args(p)
    add_contact_args(p, "exact contact: the least-squares transfer subject to no triangle pair intersecting that "
                        "does not intersect in the target neutral or in the template shape; checked exactly after "
                        "every solve (exit status 1 if a shape keeps a new pair)",
                     "with --contact: shapes left as plain transfer, e.g. correctives meant to press layers "
                     "together (several after one flag or repeated)")
    p.set_defaults(func=cmd_transfer, outputs=Outputs(writes=(("out", "folder", "--out"),),
                                                     reads=("template", "target"), derived=edges_file))
