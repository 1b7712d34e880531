"""python -m problems.reproduce: every file under reports/ belongs to one entry (a new figure without an
entry fails here), --list names each entry's command, data and script, and entries whose data is
absent are skipped with one line instead of failing."""

import pytest

from problems import reproduce


def test_every_report_file_has_exactly_one_entry_or_is_a_note():
    files = reproduce.report_files()
    assert len(files) > 50
    orphans = [p for p in files if not reproduce.is_note(p) and not reproduce.owners(p)]
    assert not orphans, f"files under reports/ with no entry in problems/reproduce.py: {orphans}"
    doubles = {p: [r.id for r in reproduce.owners(p)] for p in files if len(reproduce.owners(p)) > 1}
    assert not doubles, doubles
    notes = [p for p in files if reproduce.is_note(p)]
    assert all(p.endswith(".md") for p in notes), notes  # only prose is written by hand


def test_every_folder_of_reports_is_covered():
    folders = {p.relative_to(reproduce.REPORTS).parts[0] for p in reproduce.REPORTS.iterdir() if p.is_dir()}
    covered = {f.split("/")[0] for r in reproduce.RECIPES for f in r.files}
    assert folders <= covered, sorted(folders - covered)
    files = reproduce.report_files()
    for r in reproduce.RECIPES:  # every entry either runs or says how its files were made
        assert r.commands or r.archived, r.id
        if any(r in reproduce.owners(p) for p in files):  # (an entry may name a branch's files before they land)
            assert r.script and (reproduce.REPO / r.script).is_file(), (r.id, r.script)


def test_a_new_file_without_an_entry_is_reported(tmp_path, monkeypatch):
    (tmp_path / "default").mkdir()
    (tmp_path / "default" / "alpha_sweep.png").write_bytes(b"png")
    (tmp_path / "newstudy").mkdir()
    (tmp_path / "newstudy" / "figure.png").write_bytes(b"png")
    files = reproduce.report_files(tmp_path)
    assert files == ["default/alpha_sweep.png", "newstudy/figure.png"]
    assert [p for p in files if not reproduce.owners(p)] == ["newstudy/figure.png"]


def test_list_names_command_data_and_script(capsys):
    assert reproduce.main(["--list"]) == 0
    out = capsys.readouterr().out
    assert "default: " in out and "command: python -m problems.reports --data default" in out
    assert "data:    ict" in out and "script:  problems/bench_contact.py" in out and "archived:" in out
    assert reproduce.main(["--list", "--files"]) == 0
    listing = capsys.readouterr().out
    assert "NO ENTRY" not in listing and "reports" not in listing.split("\t")[0]


def test_needs_data_entries_skip_cleanly_without_the_data(monkeypatch, capsys):
    import problems.ict as ict

    monkeypatch.setattr(ict, "ict_available", lambda: False)
    monkeypatch.setattr(reproduce, "SHARED", reproduce.REPO / "no-such-shared")
    assert reproduce.main(["contact", "cartoon-warp", "capture-gt-before"]) == 0
    out = capsys.readouterr().out
    assert "contact: skipped: needs the ICT data" in out
    assert "cartoon-warp: skipped: needs " in out and "the shared clips" in out
    assert "capture-gt-before: archived" in out


def test_dry_run_and_bad_ids(capsys):
    assert reproduce.main(["default", "--dry-run"]) == 0
    assert "problems.reports --data default" in capsys.readouterr().out
    assert reproduce.main(["no-such-figure"]) == 2
    assert "unknown entry no-such-figure; expected one of: all, default" in capsys.readouterr().err


def test_run_executes_the_commands_with_their_placeholders(tmp_path, monkeypatch, capsys):
    target = tmp_path / "made.txt"
    recipe = reproduce.Recipe("tiny", "a test entry", ("tiny/*",),
                              ("{python} -c \"import sys; print(sys.version_info[0])\" > {tmp}/v.txt",
                               f"cp {{tmp}}/v.txt {target}"), script="problems/reproduce.py")
    monkeypatch.setattr(reproduce, "RECIPES", reproduce.RECIPES + (recipe,))
    assert reproduce.main(["tiny"]) == 0
    assert target.read_text().strip() == "3" and "tiny: ran" in capsys.readouterr().out
    failing = reproduce.Recipe("bad", "fails", ("bad/*",), ("exit 3",), script="problems/reproduce.py")
    monkeypatch.setattr(reproduce, "RECIPES", reproduce.RECIPES + (failing,))
    with pytest.raises(SystemExit, match="reproduce bad: `exit 3` exited with status 3"):
        reproduce.main(["bad"])
