"""Bad selfcal files are refused with a CalibrationError naming the file, the key, the value and
what is allowed: scenario.toml (notebook 03's scenario_toml) and a measurement folder's cell.toml
(notebook 03's measurements_dir)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.selfcal import measured

SCENARIO = data_path("selfcal", "scenario.toml").read_text()

SCENARIO_CASES = [
    (
        "negative sphere radius",
        "radius_mm = 25.0",
        "radius_mm = -25.0",
        r"spheres\.radius_mm = -25\.0: must be > 0",
    ),
    (
        "no views",
        "views_per_sphere = 6",
        "views_per_sphere = 0",
        r"protocol\.views_per_sphere = 0: must be >= 1",
    ),
    ("two spheres", "count = 4", "count = 2", r"spheres\.count = 2: must be >= 3"),
    (
        "envelope upside down",
        "envelope_max_mm = [1900.0, 900.0, 1200.0]",
        "envelope_max_mm = [1900.0, -1000.0, 1200.0]",
        r"envelope_min_mm \[1100\.0, -900\.0, 0\.0\] is not below envelope_max_mm",
    ),
    (
        "separation beyond the envelope",
        "min_separation_mm = 500.0",
        "min_separation_mm = 5000.0",
        r"min_separation_mm = 5000\.0 is not below the envelope's diagonal 2306\.5 mm: no two",
    ),
    (
        "3 points per cap",
        "points_per_cap = 400",
        "points_per_cap = 3",
        r"scanner\.points_per_cap = 3: must be >= 4",
    ),
    (
        "cap beyond a hemisphere",
        "cap_half_angle_deg = 60.0",
        "cap_half_angle_deg = 120.0",
        r"scanner\.cap_half_angle_deg = 120\.0: must be > 0 and <= 90",
    ),
    (
        "negative noise",
        "sigma_point_mm = 0.02",
        "sigma_point_mm = -0.02",
        r"scanner\.sigma_point_mm = -0\.02: must be >= 0",
    ),
    (
        "nan repeatability",
        "sigma_mm = 0.0233",
        "sigma_mm = nan",
        r"repeatability\.sigma_mm = nan: must be a finite number",
    ),
    (
        "five stiffnesses",
        "[2.0e6, 2.0e6, 1.0e6, 2.0e5, 2.0e5, 1.0e5]",
        "[2.0e6, 2.0e6, 1.0e6, 2.0e5, 2.0e5]",
        r"compliance\.stiffness_nm_per_rad = .*at least 6",
    ),
    (
        "zero stiffness",
        "[2.0e6, 2.0e6, 1.0e6, 2.0e5, 2.0e5, 1.0e5]",
        "[2.0e6, 2.0e6, 0.0, 2.0e5, 2.0e5, 1.0e5]",
        r"compliance\.stiffness_nm_per_rad #3 = 0\.0: must be > 0",
    ),
    (
        "fractional count",
        "validation_placements = 10",
        "validation_placements = 10.5",
        r"protocol\.validation_placements = 10\.5: is not an integer",
    ),
    (
        "crb multiple below 1",
        "crb_multiple = 2.0",
        "crb_multiple = 0.5",
        r"protocol\.crb_multiple = 0\.5: must be >= 1",
    ),
    (
        "2-d base position",
        "rough_xyz_mm = [2500.0, -1200.0, -900.0]",
        "rough_xyz_mm = [2500.0, -1200.0]",
        r"base\.rough_xyz_mm = .*at least 3",
    ),
    (
        "misspelt key",
        "field_mm = 40.0",
        "feild_mm = 40.0",
        r"scanner\.field_mm: missing \(required\); scanner\.feild_mm = 40\.0: unknown key",
    ),
    ("missing table", "[tracker]\n", "[trackr]\n", r"tracker: missing \(required\)"),
    (
        "text for a number",
        "coverage = 2.0",
        'coverage = "k=2"',
        r"tracker\.coverage = 'k=2': is not a number",
    ),
]


@pytest.mark.parametrize(
    "old, new, message", [c[1:] for c in SCENARIO_CASES], ids=[c[0] for c in SCENARIO_CASES]
)
def test_scenario_file(tmp_path, old, new, message):
    assert old in SCENARIO, old
    path = tmp_path / "my_cell.toml"
    path.write_text(SCENARIO.replace(old, new, 1))
    with pytest.raises(CalibrationError, match=r"my_cell\.toml: .*" + message):
        load_scenario(path)


def test_robot_file_that_does_not_exist_names_it(tmp_path):
    path = tmp_path / "my_cell.toml"
    path.write_text(SCENARIO.replace('robot = "fanuc_m710ic_50"', 'robot = "fanuc_m710"'))
    with pytest.raises(FileNotFoundError, match=r"fanuc_m710.*fanuc_m710ic_50"):
        load_scenario(path)


# ---------------------------------------------------------------------------------------------
# cell.toml of a measurement folder


@pytest.fixture
def folder(tmp_path):
    out = tmp_path / "cell"
    shutil.copytree(data_path("selfcal", "example_measurements"), out)
    return out


CELL_CASES = [
    (
        "base with 2 numbers",
        "xyz_mm = [2500.000, -1200.000, -900.000]",
        "xyz_mm = [2500.000, -1200.000]",
        r"base\.xyz_mm = .*at least 3",
    ),
    (
        "angle out of range",
        "zyx_deg = [90.0000, -20.0000, 0.0000]",
        "zyx_deg = [90.0000, -2000.0000, 0.0000]",
        r"sensor\.zyx_deg #2 = -2000\.0: must be >= -360",
    ),
    (
        "negative noise",
        "# no [noise] table",
        "[noise]\nsensor_mm = -0.02\nrepeatability_mm = 0.02\ntracker_mm = 0.01\n#",
        r"noise\.sensor_mm = -0\.02: must be >= 0",
    ),
    (
        "noise key missing",
        "# no [noise] table",
        "[noise]\nsensor_mm = 0.02\nrepeatability_mm = 0.02\n#",
        r"noise\.tracker_mm: missing",
    ),
    (
        "unknown table",
        "[sensor]",
        "[sensors]",
        r"sensor: missing \(required\); sensors: unknown key",
    ),
]


@pytest.mark.parametrize(
    "old, new, message", [c[1:] for c in CELL_CASES], ids=[c[0] for c in CELL_CASES]
)
def test_cell_file(folder, old, new, message):
    path = folder / measured.CELL_FILE
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(CalibrationError, match=r"cell\.toml: .*" + message):
        measured.read_cell(folder)


def test_cell_robot_file_that_does_not_exist(folder):
    path = folder / measured.CELL_FILE
    path.write_text(path.read_text().replace("fanuc_m710ic_50.toml", "my_robot.toml"))
    with pytest.raises(CalibrationError, match=r"robot file .*my_robot\.toml does not exist"):
        measured.read_cell(folder)


def _rewrite_columns(path, first, count, convert):
    """Apply ``convert`` to ``count`` columns of every data row of a CSV, from column ``first``."""
    lines = path.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    k = lines[head].split(",").index(first)
    for i in range(head + 1, len(lines)):
        cells = lines[i].split(",")
        cells[k : k + count] = [convert(float(c)) for c in cells[k : k + count]]
        lines[i] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


UNIT_CASES = [
    ("joints in radians", measured.MEASUREMENTS_FILE, "q1_deg", 6, np.radians,
     r"measurements\.csv: every joint angle of the 34 poses lies within \+-pi .*"
     r"q1_deg \.\.\. q6_deg: radians\?"),
    ("sphere readings in metres", measured.SPHERES_FILE, "x_mm", 3, lambda v: v / 1000,
     r"spheres\.csv: the 14 sphere placements lie within \d\.\d{3} mm of each other .*metres"),
    ("sensor centres in metres", measured.MEASUREMENTS_FILE, "cx_mm", 3, lambda v: v / 1000,
     r"measurements\.csv: every sensor centre lies within 0\.3\d+ mm of the sensor origin"),
]


@pytest.mark.parametrize(
    "name, first, count, convert, message",
    [c[1:] for c in UNIT_CASES],
    ids=[c[0] for c in UNIT_CASES],
)
def test_units_the_values_contradict(folder, name, first, count, convert, message):
    """Declared units that the values contradict (a plausible cell otherwise)."""
    _rewrite_columns(folder / name, first, count, lambda v: f"{convert(v):.6f}")
    with pytest.raises(CalibrationError, match=message):
        measured.read_cell(folder)


def test_example_folder_reads(folder):
    cell = measured.read_cell(folder)
    assert len(cell.calibration) > 0
