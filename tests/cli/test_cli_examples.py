"""Every --help page ends with examples that parse with the real parser, and the documentation's
command reference is generated from the parsers (a new option appears without editing a page)."""

import shlex

import pytest

from facebasis.cli import build_parser, main
from facebasis.cli import examples as ex


def test_every_command_has_examples_that_parse():
    parser = build_parser()
    commands = ex.subcommands(parser)
    assert set(commands) <= set(ex.EXAMPLES), sorted(set(commands) - set(ex.EXAMPLES))
    assert set(ex.EXAMPLES) <= set(commands), sorted(set(ex.EXAMPLES) - set(commands))  # no stale command
    for name, rows in ex.EXAMPLES.items():
        assert rows, name
        for line, what in rows:
            argv = shlex.split(line)
            assert argv[0] == "facebasis" and argv[1] == name and what
            args = parser.parse_args(argv[1:])  # exits (SystemExit) on an unknown or misspelt option
            assert args.command == name


def test_help_pages_end_with_their_examples_as_written(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["transfer", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    examples = out.split("examples:\n", 1)[1]
    first, what = ex.EXAMPLES["transfer"][0]
    assert f"  # {what}\n  {first}\n" in examples  # not re-wrapped
    assert "deformation transfer" in out.split("examples:")[0].lower()


def test_version_flag(capsys):
    from facebasis import __version__

    with pytest.raises(SystemExit) as exc:
        main(["-V"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"facebasis {__version__}"


def test_command_reference_is_generated_from_the_parsers(monkeypatch):
    page = ex.reference_markdown(build_parser())
    for name in ex.subcommands(build_parser()):
        assert f"\n## {name}\n" in page
    assert "`--ipopt`" in page and "`--virtual-edges`" in page and "examples:" in page
    # a new option of a command shows up on the page with nothing else edited
    from facebasis.cli import rigging

    register = rigging.register

    def register_with_new_option(sub):
        register(sub)
        sub.choices["verify"].add_argument("--brand-new-option", metavar="X", help="an option added in a test")

    monkeypatch.setattr(rigging, "register", register_with_new_option)
    page = ex.reference_markdown(build_parser())
    section = page.split("\n## verify\n", 1)[1].split("\n## ", 1)[0]
    assert "| `--brand-new-option` |  |  | an option added in a test |" in section
    assert "--brand-new-option X" in section  # in the --help page too
