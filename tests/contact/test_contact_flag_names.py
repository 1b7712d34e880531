"""Contact's errors name the library's parameters; the command line writes its flags (#25 item 5)."""

import pytest
from conftest import grid_sheet

from facebasis.cli import main
from facebasis.cli.common import flags_of
from facebasis.contact.penetration import parse_region
from facebasis.errors import InputError
from facebasis.geometry.meshio import write_mesh


def test_region_names_the_parameter_and_the_commands_their_flag(tmp_path, capsys):
    with pytest.raises(InputError, match=r"^region: expected START:END vertex indices, found '9:x'$"):
        parse_region("9:x", 30)
    with pytest.raises(InputError, match=r"^region: expected 0 <= START < END <= 30, found 5:2$") as ei:
        parse_region("5:2", 30)
    assert str(ei.value.renamed(flags_of("penetration"))) == "--region: expected 0 <= START < END <= 30, found 5:2"
    V, F = grid_sheet()
    write_mesh(tmp_path / "m.obj", V, F)
    assert main(["virtual-edges", str(tmp_path / "m.obj"), "--region", "9:x", "--out", str(tmp_path / "e.json")]) == 2
    assert capsys.readouterr().err == "error: --region: expected START:END vertex indices, found '9:x'\n"
    assert main(["penetration", str(tmp_path / "m.obj"), "--region", "5:2"]) == 2
    assert capsys.readouterr().err == f"error: --region: expected 0 <= START < END <= {len(V)}, found 5:2\n"
