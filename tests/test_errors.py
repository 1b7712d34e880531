"""Structured errors: the library names its parameters, an application writes them by its own names."""

import pytest

from facebasis.errors import FacebasisError, InputError, SolverError, parameter_error


def test_fields_compose_the_message_and_renaming_rewrites_only_the_named_parameters():
    err = InputError(what="{run_dir} runs/a", expected="{template} and {target} (recorded: none)",
                     found="only {template} {other}", params={"run_dir": "run_dir", "template": "template",
                                                             "target": "target"})
    assert str(err) == "run_dir runs/a: expected template and target (recorded: none), found only template {other}"
    flags = err.renamed({"run_dir": "--resume", "template": "--template", "target": "--target", "x": "--x"})
    assert isinstance(flags, InputError) and flags is not err
    assert str(flags) == ("--resume runs/a: expected --template and --target (recorded: none), found only "
                          "--template {other}")
    assert (flags.what, flags.expected, flags.found) == (err.what, err.expected, err.found)
    assert str(err).startswith("run_dir")  # the original is unchanged


def test_parameter_error_and_errors_without_fields():
    err = parameter_error("lam", "values >= 0", (-1.0, 2.0), label="lambda")
    assert isinstance(err, InputError) and str(err) == "lambda: expected values >= 0, found (-1.0, 2.0)"
    assert str(err.renamed({"lam": "--lambda"})) == "--lambda: expected values >= 0, found (-1.0, 2.0)"
    plain = FacebasisError("x.obj: expected a mesh, found nothing")
    assert plain.renamed({"x": "--x"}) is plain
    solver = SolverError("IPOPT failed", "Maximum_Iterations_Exceeded")
    assert solver.renamed({"x": "--x"}) is solver and solver.status == "Maximum_Iterations_Exceeded"


def test_library_options_name_their_fields_and_the_cli_its_flags(tmp_path, capsys):
    from facebasis.cli import main
    from facebasis.rigging.problem import GenerationOptions

    with pytest.raises(InputError, match=r"^cv_folds: expected >= 2, found 1$") as ei:
        GenerationOptions(cv_folds=1)
    assert ei.value.params == {"cv_folds": "cv_folds"}
    code = main(["rig", "--template", "t", "--target", "t.obj", "--examples", "e", "--weights", "w.json",
                 "--out", str(tmp_path / "o"), "--alpha", "auto", "--cv-folds", "1"])
    assert code == 2 and "error: --cv-folds: expected >= 2, found 1" in capsys.readouterr().err


def test_templates_and_named_text_rename_only_their_parameters():
    from facebasis.errors import NamedText, RigError, named_params, renamed_text

    err = RigError("rig folder r: expected the neutral 'n.obj', found no such file; name it with {neutral} {x}",
                   params={"neutral": "neutral"})
    assert str(err).endswith("name it with neutral {x}") and err.what is None
    assert str(err.renamed({"neutral": "--neutral", "x": "--x"})).endswith("name it with --neutral {x}")
    assert err.renamed({"other": "--other"}) is err
    text = NamedText("hint: {identity} auto or {identity} rig")
    assert text == "hint: identity auto or identity rig" and isinstance(text, str)
    assert renamed_text(text, {"identity": "--identity"}) == "hint: --identity auto or --identity rig"
    assert renamed_text("plain {identity}", {"identity": "--identity"}) == "plain {identity}"
    assert named_params("{unit} of {mesh}", None) == {"unit": "unit", "mesh": "mesh"}


# --- no library message names a command-line flag ------------------------------------------------------------------

#: (module, function) whose flag-naming text stays, with the reason
FLAG_TEXT_ALLOWED = {
    # the output rule's module is not changed here; every caller (cli/outputs, atomic_directory) passes its label
    ("facebasis/atomic.py", "check_output"),
    # the hint is chosen only when the caller's label is a flag (the CLI passes what="--contact")
    ("facebasis/contact/exact.py", "check_size"),
    # names the Python keyword and the flag side by side on purpose (one message for both callers)
    ("facebasis/contact/exact.py", "check_target_neutral"),
}
LOGGERS = {"warn", "log", "_log", "print", "NamedText", "say"}


def _flag_texts(path):
    """(function, text) of every string naming a ``--flag`` inside a raise, a warning or log call, or
    a parameter's default value, in one module."""
    import ast
    import re

    flag = re.compile(r"(?<![\w-])--[a-z]")
    tree = ast.parse(path.read_text())
    found = []

    def strings(node):
        return [n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)]

    def visit(node, func):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            func = node.name
            found.extend((func, s) for d in node.args.defaults + node.args.kw_defaults if d is not None
                         for s in strings(d) if flag.search(s))
        hit = isinstance(node, ast.Raise) or (
            isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) in LOGGERS)
        if hit:
            found.extend((func, s) for s in strings(node) if flag.search(s))
            return
        for child in ast.iter_child_nodes(node):
            visit(child, func)

    visit(tree, None)
    return found


def test_no_library_message_names_a_command_line_flag():
    """The library says its parameters' names ({name} placeholders, facebasis.errors); facebasis/cli/
    maps them to flags. A new message naming a flag outside cli/ fails here."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    bad = [(str(p.relative_to(root)), func, text) for p in sorted((root / "facebasis").rglob("*.py"))
           if "cli" not in p.relative_to(root / "facebasis").parts[:1]
           for func, text in _flag_texts(p) if (str(p.relative_to(root)), func) not in FLAG_TEXT_ALLOWED]
    assert not bad, bad
    stale = [(m, f) for m, f in FLAG_TEXT_ALLOWED if f not in {func for func, _ in _flag_texts(root / m)}]
    assert not stale, f"allowed but no longer naming a flag: {stale}"


def test_the_flag_check_sees_a_raise_a_log_and_a_default(tmp_path):
    p = tmp_path / "m.py"
    p.write_text('def f(x, what="--x"):\n    log(f"use --y")\n    raise ValueError(f"--z: {x}")\n'
                 'def g():\n    return "--not-a-message"\n')
    assert [t for _, t in _flag_texts(p)] == ["--x", "use --y", "--z: "]


def test_every_flag_the_cli_maps_to_is_an_option_of_a_command():
    """FLAGS and the per-command overrides stay in step with the parsers (a renamed option fails here);
    main() writes every command's errors through them (flags_of(command))."""
    import argparse

    from facebasis.cli import build_parser
    from facebasis.cli.common import COMMAND_FLAGS, FLAGS, flags_of

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    options = {name: {s for a in p._actions for s in a.option_strings} for name, p in sub.choices.items()}
    assert not [f for f in FLAGS.values() if not any(f in o for o in options.values())]
    assert all(flag in options[command] for command, names in COMMAND_FLAGS.items() for flag in names.values())
    for command in options:
        assert set(flags_of(command)) >= set(FLAGS)
    assert flags_of("landmarks")["index"] == "--frame" and flags_of("rig")["lam"] == "--lambda"
