"""The selfcal scenario: the paper's numbers from data/selfcal/scenario.toml and loader errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from calstudy import CalibrationError
from calstudy.core.paths import data_path
from calstudy.papers.selfcal.scenario import load_scenario


def test_published_and_protocol_numbers_come_from_the_file(scenario):
    assert scenario.protocol.requirement_mm == 0.42  # Section 5.2
    assert scenario.published.convergence_iterations == 4  # Section 5.2, Fig. 5
    protocol = scenario.protocol
    assert (scenario.spheres.count, protocol.views_per_sphere, protocol.validation_placements) == (
        4,
        6,
        10,
    )
    assert scenario.scanner.max_fit_condition == 15.0
    assert scenario.scanner.roll_deg == 90.0
    assert math.isclose(scenario.scanner.cap_half_angle_deg, 60.0)


def test_missing_key_names_file_and_key(tmp_path: Path):
    text = data_path("selfcal", "scenario.toml").read_text()
    broken = tmp_path / "cell.toml"
    broken.write_text(text.replace("max_fit_condition = 15.0\n", ""))
    with pytest.raises(
        CalibrationError, match=r"cell\.toml: scanner\.max_fit_condition: missing \(required\)"
    ):
        load_scenario(broken)


def test_missing_file_and_bad_toml_raise(tmp_path: Path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_scenario(tmp_path / "absent.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("robot = \n")
    with pytest.raises(CalibrationError, match="not valid TOML"):
        load_scenario(bad)


def test_empty_path_means_the_papers_file(scenario):
    """The notebook passes ``scenario_toml or None``; an empty string also means the default."""
    default = load_scenario("")
    assert default.nominal_robot.name == scenario.nominal_robot.name
    assert default.protocol.requirement_mm == scenario.protocol.requirement_mm
