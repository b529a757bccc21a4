"""Reading TOML files: the parsed-table cache never hands out stale or shared tables."""

import os

import pytest

from calstudy import CalibrationError
from calstudy.core.schema import read_toml


def test_read_toml_rereads_an_edited_file_and_hands_out_copies(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text("[robot]\nname = 'a'\nreach_mm = 900.0\n")
    first = read_toml(path, "cell")
    first["robot"]["reach_mm"] = -1.0  # a caller changing its copy
    assert read_toml(path, "cell") == {"robot": {"name": "a", "reach_mm": 900.0}}
    path.write_text("[robot]\nname = 'b'\nreach_mm = 1200.0\n")
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert read_toml(path, "cell") == {"robot": {"name": "b", "reach_mm": 1200.0}}


def test_read_toml_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_toml(tmp_path / "missing.toml", "cell")
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\n")
    with pytest.raises(CalibrationError, match="bad.toml: not valid TOML"):
        read_toml(bad, "cell")
