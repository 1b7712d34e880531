"""Command-line command of scan registration: register.

``register(subparsers)`` adds it to the ``facebasis`` command; the handler only parses, calls
:func:`facebasis.geometry.registerfiles.register_files` and prints.
"""

from __future__ import annotations

import dataclasses

from ..errors import InputError
from .common import Once, say
from .outputs import Outputs


def cmd_register(args) -> int:
    from ..geometry.registerfiles import register_files

    lm = args.landmarks
    if lm is not None and not (lm == ["auto"] or (len(lm) == 2 and "auto" not in lm)):
        raise InputError(f"--landmarks: expected 'auto' or SCAN_LM.json TEMPLATE_LM.json, found {' '.join(lm)}")
    det = None
    if args.detector is not None and lm != ["auto"]:
        raise InputError(f"--detector {args.detector}: expected together with --landmarks auto, found "
                         f"{'no --landmarks' if lm is None else '--landmarks with files'}")
    if args.identity_prior == "noise" and args.detail_prior == "off":   # the prior applies to the joint fit only
        raise InputError("--identity-prior noise: expected together with --detail-prior on (the noise-level prior "
                         "continues the fit of the modes and the detail field), found --detail-prior off")
    for dest, what in (("detail_modes", "the detail field's basis functions"), ("detail_basis", "the detail field's basis"),
                       ("detail_amplitude", "the detail field's deviation"),
                       ("detail_field_normals", "the detail field's directions"),
                       ("detail_amplitude_map", "the detail field's deviation over the skin")):
        value = getattr(args, dest)
        if value is not None and args.detail_prior == "off":  # options of the detail prior: never dropped silently
            raise InputError(f"--{dest.replace('_', '-')} {value}: expected together with --detail-prior on ({what}), "
                             "found --detail-prior off")
    if lm == ["auto"]:
        from ..capture.detect import available_detector, get_detector

        det = get_detector(args.detector or available_detector(), video=False)
    from ..geometry.detailprior import DetailPriorOptions
    from ..geometry.expressionregions import RegionOptions
    from ..geometry.registration import RegistrationOptions

    opts = RegistrationOptions(after_model=args.after_model or "normal",
                               **({} if args.expression_scan_pairs is None else
                                  {"expression_fit": dataclasses.replace(RegistrationOptions().expression_fit,
                                                                         scan_pairs=args.expression_scan_pairs)}),
                               **({} if args.expression_pairs_schedule is None else
                                  {"expression_pairs_schedule": args.expression_pairs_schedule}),
                               expression_regions=RegionOptions(
                                   count=RegionOptions.count if args.expression_regions is None else args.expression_regions),
                               detail=DetailPriorOptions(modes=0 if args.detail_prior == "off" else DetailPriorOptions.modes
                                                         if args.detail_modes is None else args.detail_modes,
                                                         noise_prior=args.identity_prior != "fixed",
                                                         basis=args.detail_basis or DetailPriorOptions.basis,
                                                         amplitude=_amplitude(args.detail_amplitude),
                                                         field_normals=args.detail_field_normals
                                                         or DetailPriorOptions.field_normals,
                                                         amplitude_map=args.detail_amplitude_map
                                                         or DetailPriorOptions.amplitude_map))
    s = register_files(args.scans, args.template, args.out, lm, args.neutral, opts, log=say(args.command), detector=det,
                       identity_basis=args.identity_basis, expression_basis=args.expression_basis,
                       expression_transfer=args.expression_transfer or "deformation")
    print(f"registered {len(s['scans'])} scan(s) in the template's topology -> {args.out}")
    return 0


def _amplitude(text):
    """``--detail-amplitude``'s value for :class:`DetailPriorOptions` (which checks it): the library's default,
    ``"auto"``, or a number (anything else is passed on as text and refused there in one line)."""
    from ..geometry.detailprior import DetailPriorOptions

    if text is None or text == "auto":
        return DetailPriorOptions.amplitude if text is None else text
    try:
        return float(text)
    except ValueError:
        return text


def register(subparsers) -> None:
    """Add ``register`` to an argparse sub-parser collection."""
    p = subparsers.add_parser(
        "register", help="lay the template's topology onto 3D face scans (non-rigid ICP)",
        description="Align the template neutral to each scan (similarity from landmarks, else a search over "
                    "orientations and trimmed ICP with scale), then deform it onto the scan with non-rigid ICP and "
                    "a stiffness schedule. Writes OUT/<scan>.obj in the template's topology and OUT/<scan>.json "
                    "(residual distance to the scan, iterations, landmark error, vertices without scan surface). "
                    "With a folder, the neutral scan is registered first and the other scans start from it.")
    p.add_argument("scans", metavar="SCAN_OR_DIR", help="scan (.obj/.ply, any topology) or folder of one person's scans")
    p.add_argument("--template", required=True, metavar="TEMPLATE_NEUTRAL.obj", help="template neutral mesh")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--landmarks", nargs="+", default=None, action=Once, metavar="auto | SCAN_LM.json TEMPLATE_LM.json",
                   help="scan landmarks (vertex indices or [x, y, z] points; for a folder an object mapping scan "
                        "names to such lists) and the template's landmark vertex indices, in the same order; or "
                        "'auto': found on each scan and on the template by a face detector on a front render "
                        "(the template looks along +z, y up), lifted onto the surface; the number found and their "
                        "residual are reported per scan")
    p.add_argument("--expression-transfer", default=None, action=Once, choices=("deformation", "linear"),
                   help="how the expression basis is carried onto the person's registered neutral: deformation "
                        "transfer (default) or the template's displacements as they are (ICT-FaceKit's own convention)")
    p.add_argument("--after-model", default=None, action=Once, choices=("nricp", "normal", "nricp+normal"),
                   help="the stage after the identity or expression fit: offsets along the fitted model's normals "
                        "only (default; cannot slide along the skin: a person's detail outside the identity space "
                        "without moving correspondence), free non-rigid ICP, or both in this order; without a basis "
                        "the non-rigid ICP runs as always")
    p.add_argument("--expression-regions", default=None, type=int, action=Once, metavar="N",
                   help="after the expression fit, one weight per expression in each of N soft regions placed over "
                        "the expressions' supports (a person's expression whose strength varies over the face, e.g. "
                        "a jaw opening further on one side); default 48; 0: whole expressions only")
    p.add_argument("--expression-scan-pairs", default=None, type=int, action=Once, metavar="N",
                   help="the expression fit also pairs N scan vertices with their nearest model vertex (default "
                        "5000): a model part over a hole of the scan then meets the scan points it should cover "
                        "(an opened mouth was fitted as lips closed over the mouth hole); 0: model-to-scan pairs only")
    p.add_argument("--expression-pairs-schedule", default=None, action=Once, choices=("after", "joint"),
                   help="when those scan pairs join the expression fit: after (default) a fit without them, continued "
                        "with them, keeping the one that leaves less of the scan unexplained (the pairs from the first "
                        "round rolled a lip in or half closed the lips on scans the fit without them got right); "
                        "joint: from the first round")
    p.add_argument("--detail-prior", default=None, action=Once, choices=("on", "off"),
                   help="the identity fit also fits a smooth field along the normals beside the modes (default on): "
                        "what the identity space cannot express is left to that field instead of sliding the "
                        "fitted points along the skin; 'off': the modes alone")
    p.add_argument("--detail-modes", default=None, type=int, action=Once, metavar="N",
                   help="basis functions carrying the detail field (default 300; more take more of a person's detail "
                        "outside the identity space, at more cost per neutral scan)")
    p.add_argument("--detail-basis", default=None, action=Once, choices=("kernel", "spectral"),
                   help="the detail field's basis: 'kernel' (default), the leading functions of a squared-exponential "
                        "covariance in 3D at inducing points about 1.1 cm apart on ICT (Nystrom; 300 hold 96%% of its "
                        "variance at the median vertex, 1.5 s CPU once per template); 'spectral', the template's first Laplace-Beltrami "
                        "eigenfunctions (the previous field, with --detail-modes 150; the joint fit still pairs every skin vertex "
                        "for 20 rounds, the former fit paired 5000 for 40; 150 hold 82%% of the variance on average, "
                        "300 cost 10 s)")
    p.add_argument("--detail-amplitude", default=None, action=Once, metavar="auto|A",
                   help="the detail field's pointwise deviation: 'auto' (default) chooses it per neutral scan, with "
                        "the scan's noise level, by the evidence (marginal likelihood) of the joint fit linearised at "
                        "the modes-only fit (a person within the identity space gets almost no field); a positive number "
                        "A: A x the RMS normal offset the modes-only fit leaves (2: the previous default; also what "
                        "'auto' uses with --identity-prior fixed, and where the evidence cannot be evaluated: the "
                        "report's detail_field.chosen_by says which)")
    p.add_argument("--detail-field-normals", default=None, action=Once, choices=("person", "template"),
                   help="the directions the detail field displaces along: 'person' (default), the normals of the "
                        "person's fitted identity modes (the modes-only fit's, then the joint fit's once it has converged); "
                        "'template', the template's normals (the previous field: where the person's surface is tilted "
                        "against the template's, the field's tangential part slides the points)")
    p.add_argument("--detail-amplitude-map", default=None, action=Once, choices=("field", "residual", "uniform"),
                   help="the detail field's deviation over the skin: 'field' (default), larger where the identity "
                        "modes alone leave residuals, then where the fitted field is (a few rounds more), so the modes "
                        "neither share the detail there nor slide the points elsewhere; 'residual', the first step "
                        "alone; 'uniform', the same deviation everywhere (the previous field)")
    p.add_argument("--identity-prior", default=None, action=Once, choices=("noise", "fixed"),
                   help="the coefficients' prior of the identity fit with the detail prior: 'noise' (default) "
                        "continues the fit with the prior at the noise level of the scan's residual (a fixed strong "
                        "prior shrinks the coefficients, and the points slide along the skin where the surface "
                        "cannot tell, e.g. the back of the head); 'fixed': the fixed prior throughout")
    p.add_argument("--detector", default=None, action=Once, choices=("dlib", "mediapipe"),
                   help="the 2D detector of --landmarks auto (default: the installed one)")
    p.add_argument("--neutral", default=None, metavar="NAME",
                   help="the neutral scan's file name or stem inside the folder (default: neutral)")
    p.add_argument("--identity-basis", default=None, action=Once, metavar="DIR",
                   help="folder of identity meshes in the template's topology (e.g. ICT-FaceKit's identity*.obj): the "
                        "neutral scan is fitted in their space first, then refined non-rigidly; default: identity*.obj "
                        "beside the template if any; 'none' to register without")
    p.add_argument("--expression-basis", default=None, action=Once, metavar="DIR",
                   help="folder of the template's expressions in its topology: each other scan is fitted as the "
                        "registered neutral plus their transfer (weights in [0, 1.5]) first; default: the other meshes "
                        "of the template's vertex count beside identity*.obj; 'none' to register without")
    p.set_defaults(func=cmd_register, outputs=Outputs(writes=(("out", "folder", "--out"),),
                                                     reads=("scans", "template", "landmarks", "identity_basis",
                                                            "expression_basis")))
