"""One table of examples for every command, shown at the end of its ``--help`` page, and the
command reference of the documentation, generated from the parsers.

:data:`EXAMPLES` maps a command to ``(command line, what it does)`` pairs. Most run as they stand on
the folder ``facebasis demo`` writes (``facebasis-demo/``), so a new user can paste them; the rest
name the files they need. :func:`apply_examples` adds them to the parsers where the parser is built
(:func:`facebasis.cli.build_parser`), so the per-command modules need not carry them, and
``tests/cli/test_cli_examples.py`` parses every example with the real parser (an example whose
option is renamed or removed fails there).

:func:`reference_markdown` writes the command reference page of the documentation from the same
parser at build time: a new option or command appears there without editing a page.
"""

from __future__ import annotations

import argparse

#: the folder ``facebasis demo`` writes, which most examples read
DEMO = "facebasis-demo"

#: command -> ((command line, what it does), ...)
EXAMPLES: dict[str, tuple[tuple[str, str], ...]] = {
    "demo": (
        ("facebasis demo", "the whole job on the built-in face, into ./facebasis-demo/"),
        ("facebasis demo --quick --out demo-quick", "a shorter run (fewer iterations and frames) into ./demo-quick/"),
    ),
    "transfer": (
        (f"facebasis transfer --template {DEMO}/template --target {DEMO}/person_neutral.obj --out my_transfer",
         "every shape of the template rig onto the person's neutral"),
        (f"facebasis transfer --template {DEMO}/template --target {DEMO}/person_neutral.obj --virtual-edges "
         "--contact --out my_contact", "the same, with virtual edges and exact contact (no new intersections)"),
        ("facebasis transfer --template FaceXModel --neutral generic_neutral_mesh.obj --exclude 'identity*' "
         "--target identity003.obj --out ict_transfer", "ICT-FaceKit's folder as it ships"),
    ),
    "rig": (
        (f"facebasis rig --template {DEMO}/template --target {DEMO}/person_neutral.obj "
         f"--examples {DEMO}/rig_inputs/examples --weights {DEMO}/rig_inputs/weights.json "
         "--exclusive mouthLeft:mouthRight --out my_rig",
         "example-based generation from the demo's training expressions and rough weights"),
        (f"facebasis rig --template {DEMO}/template --target {DEMO}/person_neutral.obj "
         f"--examples {DEMO}/rig_inputs/examples --weights {DEMO}/rig_inputs/weights.json --alpha auto "
         "--ipopt every --out my_rig_cv", "alpha chosen by cross-validation, IPOPT run at every step (its answer seeds the certified solver)"),
        ("facebasis rig --resume my_rig --examples more/ --weights more.json --out my_rig2",
         "add training expressions to a finished run"),
    ),
    "export": (
        (f"facebasis export {DEMO}/rig --out rig.glb", "the generated rig as glTF 2.0 with one morph target per shape"),
        ("facebasis export FaceXModel --neutral generic_neutral_mesh.obj --exclude 'identity*' --unit cm "
         "--out ict.gltf", "a rig folder as it ships, as .gltf + .bin"),
    ),
    "verify": (
        (f"facebasis verify {DEMO}/rig", "re-certify the stored weights of a rig run (exit 1 if one is off)"),
        (f"facebasis verify {DEMO}/rig --exclusive mouthLeft:mouthRight --tolerance 1e-8",
         "and report the largest product of a pair of weights"),
    ),
    "virtual-edges": (
        (f"facebasis virtual-edges {DEMO}/template/neutral.obj --out edges.json --figure edges.png",
         "detect thin multi-layer regions (lips, lids) and draw the edges"),
    ),
    "penetration": (
        (f"facebasis penetration my_transfer/jawOpen.obj --reference {DEMO}/person_neutral.obj "
         f"--reference {DEMO}/template/jawOpen.obj --rest {DEMO}/person_neutral.obj",
         "new intersecting triangle pairs, split into layer crossings and local folds"),
    ),
    "capture": (
        (f"facebasis capture {DEMO}/video/frames --landmarks {DEMO}/video/first.pts --out my_capture",
         "track the demo's generated video from its first frame's landmarks"),
        ("facebasis capture take.mp4 --detector mediapipe --max-frames 300 --out take_capture",
         "a video, landmarks from MediaPipe (pip install '.[mediapipe]' from a clone, "
         "'facebasis[mediapipe]' from PyPI)"),
    ),
    "landmarks": (
        ("facebasis landmarks take.mp4 --detector dlib --out first.pts",
         "the 68 landmarks of frame 0 as an editable .pts (pip install '.[detect]' from a clone, "
         "'facebasis[detect]' from PyPI)"),
    ),
    "animate2d": (
        (f"facebasis animate2d {DEMO}/capture --out my_cartoon", "the built-in cartoon face, animated by a capture"),
        (f"facebasis animate2d {DEMO}/capture --image face.png --landmarks face.pts --head follow --out my_cartoon",
         "your own image with its 68 landmarks, moving with the head"),
    ),
    "animate3d": (
        (f"facebasis animate3d {DEMO}/capture --out my_mesh_animation", "the built-in face mesh, driven by a capture"),
        (f"facebasis animate3d {DEMO}/capture --mesh {DEMO}/rig --landmarks indices.json --out my_mesh_animation",
         "a rig folder's neutral, with the mesh indices of the 68 landmarks"),
    ),
    "retarget": (
        (f"facebasis retarget {DEMO}/capture --out my_weights", "per-frame weights and head pose on the built-in rig"),
        ("facebasis retarget take_capture --rig ict/template --landmarks ict/landmarks68.json "
         "--exclusive mouthLeft:mouthRight --smooth 0.05 --out take_weights", "an ICT rig, one exclusive pair"),
    ),
    "report": (
        (f"facebasis report {DEMO}/rig", "figures and tables of a rig run, into facebasis-demo/rig/report/"),
        ("facebasis report results.csv --out figures --formats png", "figures of a sweep's results table"),
    ),
    "sweep": (
        ("facebasis sweep --problem default --study alpha,noise --seeds 0,1 --out results.csv",
         "two studies on the built-in face, on a local Dask cluster"),
    ),
    "register": (
        (f"facebasis register scan.ply --template {DEMO}/template/neutral.obj --out registered",
         "a scan (any topology) into the template's topology"),
        (f"facebasis register scans/ --template {DEMO}/template/neutral.obj --landmarks scan_lm.json tmpl_lm.json "
         "--neutral neutral --out registered", "a folder: its neutral first, then each expression"),
    ),
}


def epilog(command: str) -> str | None:
    """The ``examples:`` block of a command's ``--help`` page (None without examples)."""
    rows = EXAMPLES.get(command)
    if not rows:
        return None
    lines = ["examples:"]
    for line, what in rows:
        lines += [f"  # {what}", f"  {line}"]
    return "\n".join(lines)


def _keeping_epilog(base: type) -> type:
    """``base`` formatter that wraps descriptions as before but prints an ``examples:`` epilog as written."""

    class Formatter(base):
        def _fill_text(self, text, width, indent):
            if text.startswith("examples:"):
                return "".join(indent + line for line in text.splitlines(keepends=True))
            return super()._fill_text(text, width, indent)

    Formatter.__name__ = f"Examples{base.__name__}"
    return Formatter


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The command parsers of the top-level parser, by name, in ``--help`` order."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def apply_examples(parser: argparse.ArgumentParser) -> None:
    """Add each command's :data:`EXAMPLES` to its ``--help`` page (its epilog)."""
    for name, command in subcommands(parser).items():
        text = epilog(name)
        if text is None:
            continue
        command.epilog = text if not command.epilog else f"{command.epilog}\n\n{text}"
        command.formatter_class = _keeping_epilog(command.formatter_class)


def reference_markdown(parser: argparse.ArgumentParser) -> str:
    """The command reference page: for every command its summary, an options table and its whole
    ``--help`` page (usage, options, examples), all read from ``parser``
    (:func:`facebasis.cli.build_parser`'s) at call time."""
    commands = subcommands(parser)
    out = ["# Command reference", "",
           "Generated from the command line's own parsers when the documentation is built "
           "(`facebasis.cli.examples.reference_markdown`): every option of every command is here as "
           "`facebasis COMMAND --help` prints it. Exit status: 0 done, 2 an error (one `error:` line), "
           "128 + the signal's number when interrupted (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP); "
           "`facebasis verify` exits 1 when a stored answer is off.", "",
           "| command | what it does |", "|---|---|"]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {a.dest: a.help for a in sub._choices_actions}
    out += [f"| [`{name}`](#{name}) | {helps.get(name, '')} |" for name in commands]
    out += ["", "```text", _with_width(parser.format_help), "```", ""]
    for name, command in commands.items():
        out += [f"## {name}", "", (command.description or helps.get(name, "")).split("\n\n")[0].replace("\n", " "), ""]
        rows = []
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            flags = ", ".join(f"`{s}`" for s in action.option_strings) or f"`{action.metavar or action.dest}`"
            default = "" if action.default in (None, False, argparse.SUPPRESS) or action.required else f"`{action.default}`"
            text = (action.help or "").replace("|", "\\|").replace("\n", " ")
            text = text.replace("%(default)s", str(action.default)).replace("%%", "%")
            rows.append(f"| {flags} | {'yes' if action.required or not action.option_strings else ''} | "
                        f"{default} | {text} |")
        if rows:
            out += ["| option | required | default | meaning |", "|---|---|---|---|", *rows, ""]
        out += ["??? note \"`facebasis " + name + " --help`\"", "", "    ```text"]
        out += ["    " + line if line else "" for line in _with_width(command.format_help).splitlines()]
        out += ["    ```", ""]
    return "\n".join(out)


def _with_width(fmt, columns: int = 88) -> str:
    """``fmt()`` at a fixed terminal width (the page does not depend on the builder's terminal)."""
    import os

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(columns)
    try:
        return fmt().rstrip()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


__all__ = ["EXAMPLES", "apply_examples", "epilog", "reference_markdown", "subcommands"]
