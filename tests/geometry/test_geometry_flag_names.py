"""Geometry's errors and hints name the library's parameters; the command line writes its flags (#25 item 5)."""

import pytest
from conftest import facex_like_folder, grid_sheet

from facebasis.cli import main
from facebasis.cli.common import flags_of
from facebasis.errors import InputError, RigError, renamed_text
from facebasis.geometry.gltf import unit_scale
from facebasis.geometry.meshio import read_mesh, write_mesh
from facebasis.geometry.registerfiles import _bases, register_files
from facebasis.geometry.rig import load_rig_folder


def test_rig_folder_names_neutral_and_exclude(tmp_path, capsys):
    V, F = grid_sheet()
    (tmp_path / "rig").mkdir()
    write_mesh(tmp_path / "rig" / "smile.obj", V, F)
    write_mesh(tmp_path / "target.obj", V, F)
    with pytest.raises(RigError, match=r"^rig folder .*rig: expected the neutral 'neutral.obj', found no such file "
                                       r"\(mesh files there: \['smile.obj'\]\); name it with neutral$"):
        load_rig_folder(tmp_path / "rig")
    for command in (["transfer", "--template", str(tmp_path / "rig"), "--target", str(tmp_path / "target.obj")],
                    ["export", str(tmp_path / "rig")]):
        out = str(tmp_path / ("o.glb" if command[0] == "export" else "o"))
        assert main([*command, "--out", out]) == 2
        assert capsys.readouterr().err.endswith("(mesh files there: ['smile.obj']); name it with --neutral\n")
    write_mesh(tmp_path / "rig" / "neutral.obj", V, F)
    with pytest.raises(RigError, match=r"expected every exclude pattern to match a mesh file, found none for 'x\*'"):
        load_rig_folder(tmp_path / "rig", exclude=["x*"])
    assert main(["export", str(tmp_path / "rig"), "--exclude", "x*", "--out", str(tmp_path / "o.glb")]) == 2
    assert "expected every --exclude pattern to match a mesh file, found none for 'x*'" in capsys.readouterr().err


def test_unit_names_the_parameter_or_the_caller_s_label():
    with pytest.raises(InputError, match=r"^unit: expected one of m, cm, mm \(the source unit\), found 'inch'$") as ei:
        unit_scale("inch")
    assert str(ei.value.renamed(flags_of("export"))).startswith("--unit: expected one of m, cm, mm")
    with pytest.raises(InputError, match=r"^source unit: expected one of"):
        unit_scale("inch", "source unit")


def test_registration_names_neutral_and_its_bases_hint(tmp_path, capsys):
    V, F = grid_sheet()
    write_mesh(tmp_path / "t.obj", V, F)
    write_mesh(tmp_path / "scan.obj", V, F)
    with pytest.raises(InputError, match=r"^neutral n: expected a folder of scans, found the single file .*scan.obj$"):
        register_files(tmp_path / "scan.obj", tmp_path / "t.obj", tmp_path / "o", neutral="n")
    assert main(["register", str(tmp_path / "scan.obj"), "--template", str(tmp_path / "t.obj"), "--neutral", "n",
                 "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.startswith("error: --neutral n: expected a folder of scans, found the single file ")
    folder, _, _ = facex_like_folder(tmp_path / "facex")
    T_V, T_F = read_mesh(folder / "generic_neutral_mesh.obj")
    said = []
    _bases(folder / "generic_neutral_mesh.obj", T_V, T_F, None, "none", said.append)
    assert len(said) == 1 and said[0].startswith("identity basis: 2 meshes found beside the template in ")
    assert said[0].endswith("(FaceXModel layout: identity*.obj; pass identity_basis none to register without it)")
    assert renamed_text(said[0], flags_of("register")).endswith("pass --identity-basis none to register without it)")
    assert not (tmp_path / "o").exists()
