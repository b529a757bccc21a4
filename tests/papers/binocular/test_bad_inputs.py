# ruff: noqa: E501  (the catalogue is a table: one case per line)
"""Bad binocular scenario folders (notebook 04's scenario_dir) are refused with a
CalibrationError naming the file, the key, the value and what is allowed: sensor.toml,
calibrator.toml and station.toml, with their [published] tables."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.core.schema import read_toml, validate
from calstudy.estimators.binocular import layout_problem, solve_calibrator_layout
from calstudy.papers.binocular import scenario as scn
from calstudy.papers.binocular.schema import CalibratorFile, StationFile

TEXT = {name: data_path("binocular", f"{name}.toml").read_text() for name in scn.TABLES}
NAMES = ["P1P7", "P2P7", "P3P7", "P4P7", "P5P7", "P6P7", "P8P7"]
DISTANCES = [162.085, 58.853, 55.181, 130.546, 64.765, 178.467, 43.745]

# (id, file, old text, new text, message after "<file>.toml: ")
CASES = [
    # sensor.toml
    ("pixel pitch in um", "sensor", "pixel_pitch_mm = 0.0046", "pixel_pitch_mm = 4.6",
     r"image\.pixel_pitch_mm = 4\.6: must be > 0 and <= 0\.05"),
    ("zero image width", "sensor", "width = 7904", "width = 0", r"image\.width = 0: must be >= 1"),
    ("fractional image height", "sensor", "height = 6004", "height = 6004.5",
     r"image\.height = 6004\.5: is not an integer"),
    ("negative focal length", "sensor", "fx = 12058.0", "fx = -12058.0", r"left\.fx = -12058\.0: must be > 0"),
    ("principal point outside", "sensor", "cx = 3951.7", "cx = 9951.7",
     r"right: principal point \(9951\.7, 3002\.0\) lies outside the 7904 x 6004 px image"),
    ("nan principal point", "sensor", "cy = 3005.7", "cy = nan", r"left\.cy = nan: must be a finite number"),
    ("k1 in percent", "sensor", "dist = [-0.1820,", "dist = [-18.20,", r"left\.dist = .*k1 = -18\.2 \(entry #1\): must be within \+-10"),
    ("tangential distortion too large", "sensor", "-1.3870e-4, 6.1797e-4]", "-1.3870e-4, 0.61797]",
     r"right\.dist = .*p2 = 0\.61797 \(entry #4\): must be within \+-0\.1"),
    ("three distortion coefficients", "sensor", "dist = [-0.1820, 0.0382, -1.2323e-4, -2.086e-3]",
     "dist = [-0.1820, 0.0382, -1.2323e-4]", r"left\.dist = .*3 coefficients; OpenCV takes"),
    ("extrinsic not a rotation", "sensor", "[0.8542, 2.1609e-4, 0.5199]", "[0.9542, 2.1609e-4, 0.5199]",
     r"extrinsic\.rotation: left2right is not a rotation: .*max \|R\^T R - I\| = 0\.181, allowed 0\.002"),
    ("extrinsic a reflection", "sensor", "[-0.0018, 1.0, 0.0025]", "[0.0018, -1.0, -0.0025]",
     r"extrinsic\.rotation: left2right is not a rotation: its rotation is a reflection"),
    ("extrinsic 2 x 3", "sensor", "  [-0.5199, -0.0031, 0.8542],\n", "",
     r"extrinsic\.rotation.*must have at least 3 entries, not 2"),
    ("zero baseline", "sensor", "translation_mm = [-343.8618, 2.0126, 86.4411]", "translation_mm = [0.0, 0.0, 0.0]",
     r"extrinsic\.translation_mm = \[0\.0, 0\.0, 0\.0\]: the cameras coincide"),
    ("f-number zero", "sensor", "f_number = 8.0", "f_number = 0.0", r"optics\.f_number = 0\.0: must be >= 0\.5 and <= 128"),
    ("misspelt optics key", "sensor", "f_number = 8.0", "f_nmber = 8.0",
     r"optics\.f_number: missing \(required\); optics\.f_nmber = 8\.0: unknown key"),
    ("negative focus distance", "sensor", "focus_distance_mm = 850.0", "focus_distance_mm = -850.0",
     r"optics\.focus_distance_mm = -850\.0: must be > 0"),
    ("negative lens rim", "sensor", "rim_radius_mm = 12.0", "rim_radius_mm = -12.0",
     r"optics\.rim_radius_mm = -12\.0: must be > 0"),
    ("lens rim in metres", "sensor", "rim_distance_mm = 40.0", "rim_distance_mm = 4000.0",
     r"optics\.rim_distance_mm = 4000\.0: must be >= -1000 and <= 1000"),
    ("no lens rim", "sensor", "rim_radius_mm = 12.0\n", "",
     r"optics\.rim_radius_mm: missing \(required\)"),
    ("no exposure time", "sensor", "times_ms = [100.0, 70.0]", "times_ms = []",
     r"exposure\.times_ms = \[\]: must have at least 1 entries, not 0"),
    ("32-bit output", "sensor", "bits = 8", "bits = 32", r"exposure\.bits = 32: must be >= 1 and <= 16"),
    ("background at full scale", "sensor", "background_at_100ms = 0.06", "background_at_100ms = 1.5",
     r"exposure\.background_at_100ms = 1\.5: must be >= 0 and < 1"),
    ("dot darker than background", "sensor", "dot_peak_at_100ms = 1.3", "dot_peak_at_100ms = 0.05",
     r"exposure: dot_peak_at_100ms = 0\.05 is not above background_at_100ms = 0\.06"),
    ("zero electrons per DN", "sensor", "electrons_per_dn = 40.0", "electrons_per_dn = 0.0",
     r"noise\.electrons_per_dn = 0\.0: must be > 0"),
    ("negative calibration sigma", "sensor", "focal_px = 0.5", "focal_px = -0.5",
     r"calibration_uncertainty\.focal_px = -0\.5: must be >= 0"),
    ("extrinsic sigma in degrees", "sensor", "extrinsic_rotation_rad = 5.0e-6", "extrinsic_rotation_rad = 5.0",
     r"calibration_uncertainty\.extrinsic_rotation_rad = 5\.0: must be >= 0 and <= 0\.001"),
    ("canny thresholds reversed", "sensor", "canny_low = 0.25", "canny_low = 0.75",
     r"detection: canny_low = 0\.75 is not below canny_high = 0\.5"),
    ("4 edge points", "sensor", "min_edge_points = 20", "min_edge_points = 4",
     r"detection\.min_edge_points = 4: must be >= 5"),
    ("text for a number", "sensor", "ray_tolerance_mm = 1.0", 'ray_tolerance_mm = "1.0 mm"',
     r"detection\.ray_tolerance_mm = '1\.0 mm': is not a number"),
    ("missing table", "sensor", "[noise]", "[nois]", r"noise: missing \(required\); nois\b.*unknown key"),
    ("source not text", "sensor", 'paper = "binocular:', 'paper = 2023\nx = "binocular:',
     r"source\.paper = 2023: is not a text"),
    # calibrator.toml
    ("P2 P3 P5 admit no triangle", "calibrator", "130.546, 64.765,", "130.546, 200.0,",
     r"standard\.distance_mm = \[.*200\.0, 178\.467, 43\.745\]: P2P7 = 58\.853, P3P7 = 55\.181, P5P7 = 200 admit no layout: .*\(P5P7 = 200 > 114\.034\)"),
    ("P8 too far", "calibrator", "178.467, 43.745]", "178.467, 200.0]",
     r"standard\.distance_mm = \[.*\]: P8P7 = 200 with P1P7 = 162\.085, P4P7 = 130\.546, P6P7 = 178\.467 admit no layout: .*between 0 and 157\.033"),
    ("negative distance", "calibrator", "distance_mm = [162.085,", "distance_mm = [-162.085,",
     r"standard\.distance_mm #1 = -162\.085: must be > 0"),
    ("six distances", "calibrator", "178.467, 43.745]", "178.467]",
     r"standard\.distance_mm = .*must have at least 7 entries, not 6"),
    ("start angles that miss", "calibrator", "start_angle_deg = [0.0, 60.0, 180.0, 120.0, 300.0, 240.0]",
     "start_angle_deg = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]",
     r"standard\.start_angle_deg = \[0\.0, .*misses P1P7 by -59\.6 mm"),
    ("start angle beyond a turn", "calibrator", "start_angle_deg = [0.0, 60.0,", "start_angle_deg = [0.0, 600.0,",
     r"standard\.start_angle_deg #2 = 600\.0: must be <= 360"),
    ("negative CMM sigma", "calibrator", "sigma_um = 0.9", "sigma_um = -0.9", r"cmm\.sigma_um = -0\.9: must be >= 0"),
    ("zero dot diameter", "calibrator", "dot_diameter_mm = 5.0", "dot_diameter_mm = 0.0",
     r"sbr\.dot_diameter_mm = 0\.0: must be > 0"),
    ("published row short", "calibrator", "table2_rmse = [0.049, 0.041]", "table2_rmse = [0.049]",
     r"published\.table2_rmse = \[0\.049\]: must have at least 2 entries, not 1"),
    ("published unknown key", "calibrator", "table3_rmse = [0.041, 0.034]", "table3_rmse = [0.041, 0.034]\ntable3_rsme = [0.041, 0.034]",
     r"published\.table3_rsme = .*unknown key"),
    # station.toml
    ("hand-eye not a rotation", "station", "[-0.0078, 1.0, 0.0046, 78.6841]", "[-0.0078, 0.1, 0.0046, 78.6841]",
     r"handeye\.matrix: its 3 x 3 block is not a rotation: .*max \|R\^T R - I\| = 0\.99"),
    ("hand-eye last row", "station", "[0.0, 0.0, 0.0, 1.0]", "[0.0, 0.0, 1.0, 1.0]",
     r"handeye\.matrix: the last row is \[0\.0, 0\.0, 1\.0, 1\.0\]"),
    ("P7 above its distance", "station", "p7_height_mm = 600.0", "p7_height_mm = 2600.0",
     r"calibrator: \|p7_height_mm\| = 2600\.0 is not below p7_distance_mm = 2342\.949"),
    ("plate tilt 90", "station", "plate_tilt_deg = 20.0", "plate_tilt_deg = 90.0",
     r"calibrator\.plate_tilt_deg = 90\.0: must be > -90 and < 90"),
    ("2 calibration poses", "station", "n_calibration = 6", "n_calibration = 2",
     r"poses\.n_calibration = 2: must be >= 3"),
    ("no validation pose", "station", "n_validation = 10", "n_validation = 0",
     r"poses\.n_validation = 0: must be >= 1"),
    ("cone 90", "station", "cone_deg = 20.0", "cone_deg = 90.0", r"poses\.cone_deg = 90\.0: must be >= 0 and < 90"),
    ("spread beyond distance", "station", "distance_spread_mm = 40.0", "distance_spread_mm = 900.0",
     r"poses: distance_spread_mm = 900\.0 is not below observation_distance_mm = 850\.0"),
    ("empty robot model", "station", 'model = "kuka_kr210"', 'model = ""', r"robot\.model = '': String should have at least 1"),
    ("negative tracker sigma", "station", "sigma_um = 15.0", "sigma_um = -15.0", r"laser_tracker\.sigma_um = -15\.0: must be >= 0"),
    ("regions and distances differ", "station", 'regions = ["Region 1", "Region 2", "Region 3"]', 'regions = ["Region 1", "Region 2"]',
     r"field: 2 regions but 3 names, 3 standard_mm, 3 centres_mm; one per region"),
    ("region faces its own centre", "station", "faces_point_mm = [800.0, 0.0, 1400.0]", "faces_point_mm = [2100.0, 0.0, 300.0]",
     r"field: faces_point_mm is the centre of Region 2"),
    ("field distance zero", "station", "[58.224, 54.532,", "[0.0, 54.532,", r"field\.standard_mm #1 #1 = 0\.0: must be > 0"),
    ("published rmse of one", "station", "fig13_rmse = [0.192, 0.080]", "fig13_rmse = [0.192]",
     r"published\.fig13_rmse = \[0\.192\]: must have at least 2 entries, not 1"),
    ("published table 5 regions differ", "station", "table5_rmse = [[0.064, 0.055], [0.063, 0.054], [0.063, 0.055]]",
     "table5_rmse = [[0.064, 0.055], [0.063, 0.054]]", r"published: 3 table5_preliminary but 2 table5_rmse; one row per region"),
    ("missing key", "station", 'model = "kuka_kr210"', "", r"robot\.model: missing \(required\)"),
    # strict values and unit suspicions
    ("quoted number in a matrix", "station", "[0.9734, 0.0066, 0.2289, 188.2993]", '["0.9734", 0.0066, 0.2289, 188.2993]',
     r"handeye\.matrix #1 #1 = '0\.9734': is not a number"),
    ("true for a count", "sensor", "bits = 8", "bits = true", r"exposure\.bits = True: is not an integer"),
    ("6.0 for a count", "station", "n_calibration = 6", "n_calibration = 6.0", r"poses\.n_calibration = 6\.0: is not an integer"),
    ("baseline in metres", "sensor", "translation_mm = [-343.8618, 2.0126, 86.4411]", "translation_mm = [-0.3438618, 0.0020126, 0.0864411]",
     r"extrinsic\.translation_mm = .*the baseline's largest coordinate is 0\.343862 mm, below 10 mm: metres\?"),
    ("hand-eye translation in metres", "station",
     "188.2993],\n  [0.2289, 0.0062, -0.9734, 28.2481],\n  [-0.0078, 1.0, 0.0046, 78.6841]",
     "0.1882993],\n  [0.2289, 0.0062, -0.9734, 0.0282481],\n  [-0.0078, 1.0, 0.0046, 0.0786841]",
     r"handeye\.matrix: its translation's largest coordinate is 0\.188299 mm, below 10 mm: metres\?"),
    ("distances in metres", "calibrator", "distance_mm = [162.085, 58.853, 55.181, 130.546, 64.765, 178.467, 43.745]",
     "distance_mm = [0.162085, 0.058853, 0.055181, 0.130546, 0.064765, 0.178467, 0.043745]",
     r"standard\.distance_mm: the largest distance is 0\.178467 mm, below 10 mm: metres\?"),
    ("observation distance in metres", "station", "observation_distance_mm = 850.0", "observation_distance_mm = 0.85",
     r"poses\.observation_distance_mm = 0\.85: must be >= 10"),
    ("focus inside the focal length", "sensor", "focus_distance_mm = 850.0", "focus_distance_mm = 50.0",
     r"optics\.focus_distance_mm = 50\.0 is not beyond the lens-to-sensor distance 55\.47 mm"),
    ("distance names repeated", "calibrator", 'names = ["P1P7", "P2P7"', 'names = ["P1P7", "P1P7"',
     r"standard\.names = .*distance names repeated: \['P1P7'\]"),
    ("region names repeated", "station", 'regions = ["Region 1", "Region 2", "Region 3"]', 'regions = ["Region 1", "Region 1", "Region 3"]',
     r"field\.regions = .*region names repeated: \['Region 1'\]"),
]


def _folder(tmp_path, name, old, new):
    for table in scn.TABLES:
        text = TEXT[table]
        if table == name:
            assert old in text, old
            text = text.replace(old, new, 1)
        (tmp_path / f"{table}.toml").write_text(text)
    return tmp_path


@pytest.mark.parametrize("name, old, new, message", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_scenario_folder(tmp_path, name, old, new, message):
    folder = _folder(tmp_path, name, old, new)
    with pytest.raises(CalibrationError, match=rf"{name}\.toml: .*" + message):
        scn.load_scenario(folder)


def test_a_missing_file_names_it(tmp_path):
    folder = _folder(tmp_path, "sensor", "", "")
    (folder / "sensor.toml").unlink()
    with pytest.raises(FileNotFoundError, match=r"sensor\.toml: no such file \(the binocular sensor table\)"):
        scn.load_scenario(folder)


def test_a_file_for_the_folder(tmp_path):
    path = tmp_path / "sensor.toml"
    path.write_text(TEXT["sensor"])
    with pytest.raises(NotADirectoryError, match=r"sensor\.toml: not a folder; a scenario folder holds"):
        scn.load_scenario(path)


def test_a_robot_that_does_not_exist(tmp_path):
    folder = _folder(tmp_path, "station", 'model = "kuka_kr210"', 'model = "kuka_kr2100"')
    with pytest.raises(FileNotFoundError, match=r"kuka_kr2100"):
        scn.load_scenario(folder)


def test_the_layout_rule_is_exact():
    """The closed-form rule agrees with the solver: distances on the boundary of what admits a
    layout are accepted and solved to ~0 residual; just beyond it they are refused (the solver
    alone would leave a residual of the size of the excess)."""
    d = np.array(DISTANCES)
    start = [0.0, 60.0, 180.0, 120.0, 300.0, 240.0]
    # P5P7 exactly the sum of P2P7 and P3P7: a degenerate (flat) triangle, still a layout
    flat = d.copy()
    flat[4] = d[1] + d[2]
    assert layout_problem(flat, NAMES) == ""
    _, residual = solve_calibrator_layout(flat, start)
    assert np.abs(residual).max() < 1e-6
    beyond = flat.copy()
    beyond[4] += 1.0
    assert "P5P7 = 115.034 > 114.034" in layout_problem(beyond, NAMES)
    with pytest.raises(CalibrationError, match=r"P5P7 = 115\.034 admit no layout"):
        solve_calibrator_layout(beyond, start)
    # P8P7 at its largest, (P1P7 + P4P7 + P6P7) / 3, is reachable; beyond it is not
    top = d.copy()
    top[6] = (d[0] + d[3] + d[5]) / 3
    assert layout_problem(top, NAMES) == ""
    top[6] += 0.5
    assert "admit no layout" in layout_problem(top, NAMES)


def test_published_tables_are_checked():
    """The files of data/binocular pass, [published] included; paper_table checks them too."""
    for model, name in ((CalibratorFile, "calibrator"), (StationFile, "station")):
        scn.paper_table(name)
        path = data_path("binocular", f"{name}.toml")
        parsed = validate(model, read_toml(path, name), name)  # with the ledger's entries
        assert parsed.published is not None
    with pytest.raises(CalibrationError, match=r"no binocular table 'stations'"):
        scn.paper_table("stations")


def test_own_folder_without_published_tables(tmp_path):
    """A folder describing your own cell needs no [published] table."""
    for table in scn.TABLES:
        text = TEXT[table]
        cut = text.find("\n[published]")
        (tmp_path / f"{table}.toml").write_text(text if cut < 0 else text[:cut])
    own = scn.load_scenario(tmp_path)
    assert np.array_equal(own.layout, scn.load_scenario().layout)
    shutil.rmtree(tmp_path)
