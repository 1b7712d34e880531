"""Registering scan files: a scan or a folder of one person's scans onto a template, written atomically.

The file side of :mod:`.registration`: reads and checks every input (scans, landmarks, the
template's identity and expression bases) before any work, registers the neutral first and the
other scans from it, and writes ``<stem>.obj`` and ``<stem>.json`` per scan and ``summary.json``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError, NamedText, parameter_error
from ..jsonio import read_json
from .registration import Registration, RegistrationOptions, check_landmarks


def read_landmarks(path: str | os.PathLike):
    """Read a landmark JSON file: a list of vertex indices or of [x, y, z] points, or an object
    ``{"landmarks": [...]}``, or (scan landmarks of a folder) an object mapping scan stems to lists."""
    path = Path(path)
    data = read_json(path, "a JSON list of vertex indices or [x, y, z] points", what="landmarks")
    if isinstance(data, dict) and "landmarks" in data:
        data = data["landmarks"]
    if isinstance(data, dict):
        return {str(k): v for k, v in data.items()}
    if not isinstance(data, list):
        raise InputError(f"landmarks {path}: expected a list of indices or points, found {type(data).__name__}")
    try:
        return np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"landmarks {path}: expected a list of indices or [x, y, z] points, found ragged or "
                         f"non-numeric entries") from exc


#: the run's own file in the output folder: a scan of this stem would have its report overwritten
SUMMARY_STEM = "summary"


def _scan_files(scan_or_dir: Path) -> list[Path]:
    from .meshio import MESH_SUFFIXES

    if scan_or_dir.is_dir():
        named = sorted(p for p in scan_or_dir.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
        broken = [p for p in named if p.is_symlink() and not p.exists()]
        if broken:
            raise InputError(f"scans {scan_or_dir}: expected readable scan files, found symbolic link(s) leading nowhere: "
                             + ", ".join(f"{p.name} -> {os.readlink(p)}" for p in broken[:3]))
        files = [p for p in named if p.is_file()]
        if not files:
            raise InputError(f"scans {scan_or_dir}: expected .obj or .ply files in the folder, found none")
        stems = [p.stem for p in files]
        dup = sorted({s for s in stems if stems.count(s) > 1})
        if dup:
            raise InputError(f"scans {scan_or_dir}: expected one file per name, found {dup[0]} twice (.obj and .ply)")
    elif not scan_or_dir.exists():
        raise InputError(f"scans {scan_or_dir}: expected a scan file or a folder of scans, found no such path")
    else:
        files = [scan_or_dir]
    clash = [p for p in files if p.stem.casefold() == SUMMARY_STEM]
    if clash:
        raise InputError(f"scans {scan_or_dir}: expected scan names other than '{SUMMARY_STEM}' (the run writes "
                         f"{SUMMARY_STEM}.json, which would overwrite the report {clash[0].stem}.json of this scan), "
                         f"found {clash[0].name}; rename the scan")
    return files


def _bases(template: Path, T_V, T_F, identity_basis, expression_basis, log):
    """The identity and expression bases of a run (read and checked before any work).

    ``identity_basis`` / ``expression_basis``: a folder, ``"none"``, or None (auto: ICT-FaceKit's
    FaceXModel layout beside the template, :func:`.shapemodel.template_bases`).
    """
    from .shapemodel import basis_files, read_shape_basis, template_bases

    auto_i, auto_e = template_bases(template, T_V) if None in (identity_basis, expression_basis) else ([], [])
    out = []
    for given, auto, what, pattern in ((identity_basis, auto_i, "identity_basis", "*"),
                                       (expression_basis, auto_e, "expression_basis", "*")):
        if given is not None and str(given) == "none":
            out.append(None)
            continue
        if given is not None:
            files, src = basis_files(given, pattern, "{" + what + "}"), str(given)
        elif auto:
            files, src = auto, str(template.parent)
            log(NamedText(f"{what.replace('_', ' ')}: {len(files)} meshes found beside the template in {src} "
                          f"(FaceXModel layout: identity*.obj; pass {{{what}}} none to register without it)",
                          {what: what}))
        else:
            out.append(None)
            continue
        out.append(read_shape_basis(files, T_V, T_F, str(template), source=src))
    return out


def _landmark_inputs(landmarks, detector, src: Path, files: list, T_V):
    """The landmarks of a run, read and checked: ``(template landmarks, scan landmarks, detector, auto)``;
    the scan landmarks are a list, an object mapping scan names to lists, or ``"auto"``."""
    t_lm = s_lm = det = None
    auto = isinstance(landmarks, str) or (isinstance(landmarks, (list, tuple)) and list(landmarks) == ["auto"])
    if detector is not None and not auto:
        raise InputError(f"detector: expected together with landmarks 'auto', found "
                         f"{'no landmarks' if landmarks is None else 'landmark files'}")
    if auto:
        if str(landmarks if isinstance(landmarks, str) else landmarks[0]) != "auto":
            raise parameter_error("landmarks", "'auto' or SCAN_LM.json TEMPLATE_LM.json", repr(landmarks))
        if detector is None:
            raise InputError(what="{landmarks} auto", expected="a 2D face detector ({detector})", found="none",
                             params={"landmarks": "landmarks", "detector": "detector"})
        det, s_lm = detector, "auto"
    elif landmarks is not None:
        s_path, t_path = landmarks
        t_lm = read_landmarks(t_path)
        if isinstance(t_lm, dict):
            raise InputError(f"template landmarks {t_path}: expected a list of template vertex indices, found an object")
        s_lm = read_landmarks(s_path)
        if src.is_dir() and not isinstance(s_lm, dict):
            raise InputError(f"scan landmarks {s_path}: expected an object mapping scan names to landmark lists "
                             f"when registering a folder, found a list")
        if not src.is_dir() and isinstance(s_lm, dict):
            s_lm = s_lm.get(files[0].stem, s_lm.get(files[0].name))
            if s_lm is None:
                raise InputError(f"scan landmarks {s_path}: expected an entry for {files[0].stem}, found none")
        if len(t_lm) != (len(s_lm) if not isinstance(s_lm, dict) else len(t_lm)):
            raise InputError(f"scan landmarks {s_path} and template landmarks {t_path}: expected the same number "
                             f"of landmarks, found {len(s_lm)} and {len(t_lm)}")
        check_landmarks(t_lm, None, len(T_V), None, f"template landmarks {t_path}")
    return t_lm, s_lm, det, auto


def register_files(scan_or_dir, template, out, landmarks=None, neutral: str | None = None,
                   options: RegistrationOptions | None = None, log=None, identity_basis=None,
                   expression_basis=None, detector=None, expression_transfer: str = "deformation") -> dict:
    """Register a scan, or a folder of one person's scans, and write the results to ``out``.

    Parameters
    ----------
    scan_or_dir : an OBJ/PLY scan, or a folder of them; in a folder the scan named ``neutral``
        (``neutral.obj``/``.ply``, or ``neutral``'s stem) is registered first from the template and
        the others from the registered neutral
    template : the template neutral (OBJ/PLY)
    out : output folder: ``<stem>.obj`` (template topology) and ``<stem>.json`` (report) per scan,
        and ``summary.json``; written atomically (all or nothing)
    landmarks : ``(SCAN_LM.json, TEMPLATE_LM.json)`` or None; for a folder, SCAN_LM.json maps scan
        stems to landmark lists (scans it does not name get none); or ``"auto"``: found on every scan
        and on the template by a 2D detector on front renders (:mod:`.scanlandmarks`)
    detector : with ``"auto"``: a 2D face detector object with ``detect(image) -> (68, 2) | None``
        (:func:`facebasis.capture.detect.get_detector`; the command line makes it from ``--detector``)
    expression_transfer : how the expression basis is carried to the person's registered neutral:
        ``"deformation"`` (deformation transfer) or ``"linear"`` (the template's displacements, as
        ICT-FaceKit defines its expressions: identity-independent deltas)
    neutral : the neutral scan's file name or stem in a folder (default ``neutral``)
    identity_basis : folder of identity meshes in the template's topology (the neutral is fitted in
        their space first), ``"none"``, or None: ``identity*.obj`` beside the template if any
    expression_basis : folder of the template's expressions in its topology (each other scan is
        fitted as the registered neutral plus their transfer first), ``"none"``, or None: the other
        meshes of the template's vertex count beside ``identity*.obj``

    Every input is read and checked before any registration starts.

    Returns
    -------
    summary : dict with one report per scan, in registration order
    """
    from ..atomic import atomic_directory, atomic_write_bytes, atomic_write_json
    from .meshio import read_mesh, write_mesh
    from .objlayout import copy_side_files, read_obj_layout

    log = log or (lambda *a: None)
    if expression_transfer not in ("deformation", "linear"):
        raise parameter_error("expression_transfer", "'deformation' or 'linear'", repr(expression_transfer))
    src = Path(scan_or_dir)
    files = _scan_files(src)
    T_V, T_F = read_mesh(template)
    layout = read_obj_layout(template)  # UVs, materials, polygons of an OBJ template, kept in the outputs
    t_lm, s_lm, det, auto = _landmark_inputs(landmarks, detector, src, files, T_V)
    ident, expr = _bases(Path(template), T_V, T_F, identity_basis, expression_basis, log)
    reg = Registration(T_V, T_F, options, t_lm, name=str(template), identity=ident, expressions=expr,
                       detector=det)
    order = files
    if src.is_dir() and len(files) > 1:
        want = neutral or "neutral"
        hit = [p for p in files if p.name == want or p.stem == want]
        if not hit:
            raise InputError(what=f"scans {src}", expected=f"a neutral scan named '{want}' (.obj/.ply) to register "
                             f"first", found=f"{', '.join(p.name for p in files[:6])}{' ...' if len(files) > 6 else ''}",
                             note="; name it with {neutral}", params={"neutral": "neutral"})
        order = hit + [p for p in files if p is not hit[0]]
    elif neutral is not None and not src.is_dir():
        raise InputError(what=f"{{neutral}} {neutral}", expected="a folder of scans", found=f"the single file {src}",
                         params={"neutral": "neutral"})
    scans = []
    for p in order:  # read and check every scan before any work
        V, F = read_mesh(p)
        lm = s_lm.get(p.stem, s_lm.get(p.name)) if isinstance(s_lm, dict) else s_lm
        if lm is not None and not auto:
            if len(lm) != len(t_lm):
                raise InputError(f"scan landmarks for {p.name} and template landmarks: expected the same number of "
                                 f"landmarks, found {len(lm)} and {len(t_lm)}")
        V, F, _ = reg.check_scan(V, F, str(p), None if auto else lm)
        scans.append((p, V, F, lm))
    summary = {"template": str(template), "scans": []}
    with atomic_directory(out) as stage:
        start = E = None
        for k, (p, V, F, lm) in enumerate(scans):
            res = reg.register(V, F, lm, start=start, name=str(p), expressions=E)
            if k == 0 and len(scans) > 1:
                start = res.vertices
                E = reg.person_expressions(start, expression_transfer) if expr is not None else None
            if layout is not None and layout.matches(len(res.vertices), reg.F):
                atomic_write_bytes(stage / f"{p.stem}.obj", layout.obj_bytes(res.vertices))
            else:
                write_mesh(stage / f"{p.stem}.obj", res.vertices, reg.F)
            rep = {"scan": str(p), "scan_vertices": int(len(V)), "template": str(template),
                   "started_from": "template" if (k == 0 or len(scans) == 1) else f"{scans[0][0].stem}.obj",
                   **res.report()}
            atomic_write_json(stage / f"{p.stem}.json", rep)
            summary["scans"].append(rep)
            r = rep["residual"] or {}
            log(f"{p.name}: residual median {r.get('median', float('nan')):.4g}, p95 {r.get('p95', float('nan')):.4g}, "
                f"max {r.get('max', float('nan')):.4g}; {rep['no_surface_vertices']} vertices found no scan surface; "
                f"{rep['iterations']} iterations, {rep['seconds']:.1f} s" + _model_line(rep))
            _log_checks(log, p.name, rep, res.rigid_check, auto)
        copy_side_files(layout, stage)
        atomic_write_json(stage / "summary.json", summary)
    return summary


def _log_checks(log, name: str, rep: dict, check, auto: bool) -> None:
    """A scan's extra lines: a doubtful rigid pose (never silent, issue #27), landmarks found on the scan."""
    if check is not None and check.doubtful:
        log(f"{name}: warning: {check.warning()}")
    if auto:
        le = rep["landmark_error"]
        log(f"{name}: landmarks found on the scan and the template: {rep['landmarks_found']}, used (within "
            f"2 edge lengths of the fitted mesh): {rep['landmarks_used']}"
            + (f"; residual after registration mean {le['mean']:.4g}, max {le['max']:.4g}" if le else ""))


def _model_line(rep: dict) -> str:
    """The identity or expression fit's part of a scan's printed line."""
    for kind in ("identity", "expressions"):
        if kind in rep:
            m = rep[kind]
            top = sorted(m["coefficients"].items(), key=lambda kv: -abs(kv[1]))[:3]
            d = m.get("detail_field")
            return (f"; {kind} fit: {len(m['coefficients'])} {'modes' if kind == 'identity' else 'weights > 0'}, "
                    f"rms {m['rms_point_to_plane_template_units']:.3g}, largest "
                    + ", ".join(f"{k} {v:.2f}" for k, v in top)
                    + ("" if d is None else f"; detail field sd {d['sd_template_units']:.3g} ("
                       + (f"auto: evidence, noise {d['noise_template_units']:.3g})" if d["noise_template_units"]
                          else "from the amplitude)")))
    return ""
