"""Tests of calstudy.core.config: one way to read a scenario file, errors naming file and key."""

from __future__ import annotations

import pytest

from calstudy import CalibrationError
from calstudy.core.config import read_toml, require, scenario_file
from calstudy.core.paths import DATA_DIR


def test_reads_a_shipped_scenario_and_its_keys():
    path = scenario_file("selfcal", "scenario.toml")
    assert path == DATA_DIR / "selfcal" / "scenario.toml"
    table = read_toml(path, "selfcal scenario")
    assert isinstance(require(table, "robot", path), str)


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


def test_require_names_the_first_missing_part_of_the_key():
    table = {"sensor": {"noise": {"sigma_mm": 0.02}}}
    assert require(table, "sensor.noise.sigma_mm", "s.toml") == 0.02
    with pytest.raises(CalibrationError, match=r"s\.toml: missing key 'sensor\.pose'"):
        require(table, "sensor.pose.x", "s.toml")
    with pytest.raises(CalibrationError, match=r"missing key 'sensor\.noise\.sigma_mm\.x'"):
        require(table, "sensor.noise.sigma_mm.x", "s.toml")
