"""Bad dualarm scenario files (notebook 05's scenario_toml) are refused with a CalibrationError
naming the file, the key, the value and what is allowed."""

from __future__ import annotations

import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.papers.dualarm.scenario import load_published, load_scenario

SCENARIO = data_path("dualarm", "scenario.toml").read_text()

CASES = [
    ("loss rate above 1", "loss_rate = 0.1", "loss_rate = 1.5",
     r"detection\.loss_rate = 1\.5: must be >= 0 and < 1"),
    ("every marker lost", "loss_rate = 0.1", "loss_rate = 1.0",
     r"detection\.loss_rate = 1\.0: must be >= 0 and < 1"),
    ("negative points per scan", "points_per_scan = 1000", "points_per_scan = -500",
     r"sensor\.points_per_scan = -500: must be >= 4"),
    ("negative sphere diameter", "diameter_a_mm = 50.807", "diameter_a_mm = -50.807",
     r"spheres\.diameter_a_mm = -50\.807: must be > 0"),
    ("incidence beyond 90", "max_incidence_deg = 70.0", "max_incidence_deg = 170.0",
     r"sensor\.max_incidence_deg = 170\.0: must be > 0 and <= 90"),
    ("zero focal length", "fx_px = 2000.0", "fx_px = 0.0", r"camera\.fx_px = 0\.0: must be > 0"),
    ("principal point outside", "cx_px = 639.5", "cx_px = -5.0",
     r"principal point \(-5\.0, 511\.5\) lies outside the 1280 x 1024 px image"),
    ("marker without position", "  [196.881, -26.520, 8.204],\n", "",
     r"14 names but 13 xyz_mm; one each"),
    ("marker in no group", '"5817-C",\n]', '"5818-C",\n]',
     r"markers \['5818-C'\] belong to no group"),
    ("repeated marker", '"5817-17", "5817-5"', '"5817-17", "5817-17"',
     r"marker names repeated: \['5817-17'\]"),
    ("2 hand-eye poses", "n_poses = 10", "n_poses = 2", r"handeye\.n_poses = 2: must be >= 3"),
    ("offsets and groups differ", "placement_offsets_mm = [-120.0, 0.0, 120.0]",
     "placement_offsets_mm = [-120.0, 0.0]", r"2 placement_offsets_mm for n_groups = 3"),
    ("outlier range reversed", "outlier_px = [5.0, 20.0]", "outlier_px = [20.0, 5.0]",
     r"circular_plate\.outlier_px = \[20\.0, 5\.0\]: \[20\.0, 5\.0\] is not \[low, high\]"),
    ("outlier rate above 1", "outlier_rate = 0.05", "outlier_rate = 5",
     r"circular_plate\.outlier_rate = 5: must be >= 0 and <= 1"),
    ("rotation vector of 2", "cam2flange_1_rotvec = [0.133, 0.139, -1.568]",
     "cam2flange_1_rotvec = [0.133, 0.139]", r"calibration\.cam2flange_1_rotvec = .*at least 3"),
    ("rotation vector in degrees", "cam2flange_1_rotvec = [0.133, 0.139, -1.568]",
     "cam2flange_1_rotvec = [7.6, 8.0, -89.8]",
     r"calibration\.cam2flange_1_rotvec #3 = -89\.8: must be >= -7"),
    ("negative drift", "drift_step_sigma_mm = 0.05", "drift_step_sigma_mm = -0.05",
     r"robot\.drift_step_sigma_mm = -0\.05: must be >= 0"),
    ("fractional iterations", "max_iterations = 200", "max_iterations = 200.5",
     r"icp\.max_iterations = 200\.5: is not an integer"),
    ("misspelt key", "baseline_mm = 200.0", "base_line_mm = 200.0",
     r"stereo\.baseline_mm: missing \(required\); stereo\.base_line_mm = 200\.0: unknown key"),
    ("missing key", "loss_rate = 0.1\n", "", r"detection\.loss_rate: missing \(required\)"),
    ("quoted number", "baseline_mm = 200.0", 'baseline_mm = "200.0"',
     r"stereo\.baseline_mm = '200\.0': is not a number"),
    ("true for a count", "n_poses = 10", "n_poses = true",
     r"handeye\.n_poses = True: is not an integer"),
]


@pytest.mark.parametrize("old, new, message", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_scenario_file(tmp_path, old, new, message):
    assert old in SCENARIO, old
    path = tmp_path / "my_station.toml"
    path.write_text(SCENARIO.replace(old, new, 1))
    with pytest.raises(CalibrationError, match=r"my_station\.toml: .*" + message):
        load_scenario(path)


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"absent\.toml: no such file"):
        load_scenario(tmp_path / "absent.toml")


PUBLISHED = data_path("dualarm", "published.toml").read_text()

PUBLISHED_CASES = [
    ("arm 3", '[1, "A", 0.471, 0.076]', '[3, "A", 0.471, 0.076]',
     r"icp\.rows #1 #1 = 3: must be <= 2"),
    ("sphere C", '[1, "A", 0.471, 0.076]', '[1, "C", 0.471, 0.076]',
     r"icp\.rows #1 #2 = 'C': is not one of 'A' or 'B'"),
    ("arm-sphere pair twice", '[1, "B", 0.352, 0.088]', '[1, "A", 0.352, 0.088]',
     r"icp\.rows: arm-sphere pairs repeated: \[\(1, 'A'\)\]"),
    ("negative error", "[1, 0.022, 0.036, 0.040]", "[1, -0.022, 0.036, 0.040]",
     r"table1\.rows #1 #2 = -0\.022: must be >= 0"),
    ("group twice", "[2, 0.073, 0.029, 0.062]", "[1, 0.073, 0.029, 0.062]",
     r"table1\.rows: groups repeated: \[1\]"),
    ("short row", "[2, 0.097, 0.147, 0.092]", "[2, 0.097, 0.147]", r"table2\.rows #2 #4: missing"),
    ("missing overall", "overall = 0.100\n", "", r"table2\.overall: missing \(required\)"),
    ("methods and rows differ", '"coded markers"]', '"coded markers", "ICP"]',
     r"table3: 5 methods but 4 rows; one each"),
    ("nan error", "[0.044, 0.028, 0.069, 0.100]", "[0.044, 0.028, 0.069, nan]",
     r"table3\.rows #4 #4 = nan: must be a finite number"),
    ("target not a text", "drift_target =", "drift_target = 0.492\nx =",
     r"nuisance_targets\.drift_target = 0\.492: is not a text"),
]


@pytest.mark.parametrize(
    "old, new, message", [c[1:] for c in PUBLISHED_CASES], ids=[c[0] for c in PUBLISHED_CASES]
)
def test_published_file(tmp_path, old, new, message):
    assert old in PUBLISHED, old
    path = tmp_path / "published.toml"
    path.write_text(PUBLISHED.replace(old, new, 1))
    with pytest.raises(CalibrationError, match=r"published\.toml: .*" + message):
        load_published(path)
