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
