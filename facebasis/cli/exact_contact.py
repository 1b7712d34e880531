"""The exact-contact flags of ``facebasis transfer`` and ``facebasis rig``, declared once: parsing
them, checking the target before any solving, writing ``contact.json`` and saying the verdict."""

from __future__ import annotations

import sys
from dataclasses import dataclass

from .common import once


@dataclass(frozen=True)
class ContactRequest:
    """What ``--contact`` asks for: the shapes left as they are and whether the target neutral's own
    intersections are kept (the default) or refused (``--contact-strict``)."""

    exclude: tuple[str, ...]
    allow_target_pairs: bool


def add_contact_args(p, contact_help: str, exclude_help: str) -> None:
    """``--contact``, ``--contact-exclude``, ``--contact-strict``, ``--contact-allow-target-pairs``;
    the two help texts say what contact does in the command."""
    p.add_argument("--contact", action="store_true", help=contact_help)
    p.add_argument("--contact-exclude", action="extend", nargs="+", default=[], metavar="SHAPE", help=exclude_help)
    p.add_argument("--contact-strict", action="store_true",
                   help="with --contact: refuse a target neutral that intersects itself where the template does not "
                        "(by default those pairs are kept as they are, said in one line, and no new pair appears)")
    p.add_argument("--contact-allow-target-pairs", action="store_true",
                   help="with --contact: keep the target neutral's own intersections (the default now; the flag "
                        "is kept for older scripts)")


def contact_flags_given(args) -> list[str]:
    """The contact flags given (``--contact`` first)."""
    return [flag for flag, v in (("--contact", args.contact), ("--contact-exclude", args.contact_exclude),
                                 ("--contact-strict", args.contact_strict),
                                 ("--contact-allow-target-pairs", args.contact_allow_target_pairs)) if v]


def contact_request(args) -> ContactRequest | None:
    """The contact flags checked (the others need ``--contact``; names given twice kept once), or None
    without ``--contact``."""
    from ..errors import InputError

    given = contact_flags_given(args)[1 if args.contact else 0:]
    if not args.contact and given:
        raise InputError(f"{', '.join(given)}: expected --contact as well, found none")
    if args.contact_strict and args.contact_allow_target_pairs:
        raise InputError("--contact-strict: expected it or --contact-allow-target-pairs, found both (strict refuses "
                         "the target's own intersections, the other keeps them)")
    exclude = once(args.contact_exclude, "--contact-exclude")
    # the target's own intersections are kept by default
    return ContactRequest(tuple(exclude), not args.contact_strict) if args.contact else None


def check_contact_target(request: ContactRequest, template, target, target_name) -> None:
    """Names, size and the target neutral's own intersections, before any solving; those are kept as
    they are (one line says how many and where) unless ``--contact-strict`` refuses the target."""
    from ..contact.exact import check_contact_inputs, describe_target_pairs

    own = check_contact_inputs(template, target, list(request.exclude), request.allow_target_pairs,
                               what="--contact", exclude_what="--contact-exclude", target_what=str(target_name))
    if len(own):
        print(f"contact: the target neutral {target_name} intersects itself beyond the template neutral in "
              f"{describe_target_pairs(own, target, template.faces)}: kept as they are, no new pair is allowed "
              "(--contact-strict refuses such a target)", file=sys.stderr)


def write_contact(stage, contact) -> None:
    """``contact.json``: the exact check's verdict and the per-shape table, kept with the shapes."""
    import json

    (stage / "contact.json").write_text(json.dumps(contact.record(), indent=1))


def contact_verdict(contact, what: str, excluded) -> int:
    """Say what the exact check found after the contact solve; 1 if a shape keeps a new pair."""
    if not contact.ok:
        bad = [s.name for s in contact.shapes if not s.excluded and s.new_pairs_left]
        print(f"CONTACT NOT MET: {len(bad)} shape(s) keep new intersecting pairs after the exact check "
              f"({', '.join(bad)}); they are written as solved", file=sys.stderr)
        return 1
    retreated = [f"{s.name} ({s.retreated} vertices, {100 * s.retreat_loss:.1f}% of its delta)"
                 for s in contact.shapes if not s.excluded and s.retreated]
    if retreated:  # intersection-free, but less of the shape: the user should see it
        print(f"exact contact: the solve-and-check rounds left pairs in {len(retreated)} shape(s); they were "
              f"pulled back towards the target neutral around those pairs: {', '.join(retreated)}", file=sys.stderr)
    print(f"exact check: no {what} shape has a triangle pair intersecting that does not intersect in the "
          "target neutral or in the template shape" + (f" (excluded: {', '.join(excluded)})" if excluded else ""))
    return 0
