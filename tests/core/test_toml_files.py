"""Reading a scenario file (core.paths.scenario_file, core.schema.read_toml): errors naming the
file and what it holds."""

from __future__ import annotations

import pytest

from calstudy import CalibrationError
from calstudy.core.paths import DATA_DIR, scenario_file
from calstudy.core.schema import read_toml


def test_reads_a_shipped_scenario_and_its_keys():
    path = scenario_file("selfcal", "scenario.toml")
    assert path == DATA_DIR / "selfcal" / "scenario.toml"
    table = read_toml(path, "selfcal scenario")
    assert isinstance(table["robot"], str)


def test_missing_file_names_path_and_purpose(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.toml: no such file \(the robot table\)"):
        read_toml(tmp_path / "nope.toml", "robot table")
    with pytest.raises(FileNotFoundError, match=r"data/selfcal/missing\.toml"):
        scenario_file("selfcal", "missing.toml")


def test_malformed_toml_gives_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("a = 1\nb = [1, 2\n")
    with pytest.raises(CalibrationError, match=r"bad\.toml: not valid TOML \(Unclosed array"):
        read_toml(bad, "scenario")
