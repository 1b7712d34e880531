"""facebasis.jsonio.read_json: one set of messages for every JSON input."""

import pytest

from facebasis.errors import InputError
from facebasis.jsonio import read_json


def test_reads_value(tmp_path):
    p = tmp_path / "a.json"
    p.write_text('{"x": [1, 2]}')
    assert read_json(p, "an object") == {"x": [1, 2]}


def test_missing_file_names_path_and_label(tmp_path):
    with pytest.raises(InputError, match=r"landmarks .*nope\.json: expected a list, found no such file"):
        read_json(tmp_path / "nope.json", "a list", what="landmarks")


def test_folder(tmp_path):
    with pytest.raises(InputError, match=r": expected a list, found a folder"):
        read_json(tmp_path, "a list")


def test_invalid_json(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(InputError, match=r"bad\.json: expected a list, found invalid JSON \(Expecting"):
        read_json(p, "a list")


def test_binary_bytes(tmp_path):
    p = tmp_path / "bin.json"
    p.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match=r"bin\.json: expected a list, found unreadable bytes"):
        read_json(p, "a list")
