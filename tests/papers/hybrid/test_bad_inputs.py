"""Bad hybrid files are refused with a CalibrationError naming the file, the key (or row and
column), the value and what is allowed: station.toml, production.toml, the hybrid and CMM tables
of notebook 02 and the fixed-sphere CSV of notebook 01."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.handeye import sphere_csv
from calstudy.papers.hybrid import (
    compensation,
    handeye_experiments,
    scenario,
    simulate,
)

STATION = data_path("hybrid", "station.toml").read_text()
PRODUCTION = data_path("hybrid", "production.toml").read_text()


def _broken(tmp_path, text, old, new, name):
    assert old in text, old
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


STATION_CASES = [
    ("non-rigid hand-eye", "0.647394, 0.01769", "0.747394, 0.01769",
     r"handeye\.matrix.*not orthonormal \(max \|R\^T R - I\| = 0\.1"),
    ("reflected hand-eye", "[-0.762019, -0.003901, 0.647543", "[0.762019, 0.003901, -0.647543",
     r"handeye\.matrix.*not orthonormal|reflection"),
    ("hand-eye last row", "[0.0, 0.0, 0.0, 1.0]", "[0.0, 0.0, 1.0, 1.0]",
     r"handeye\.matrix.*last row is \[0\.0, 0\.0, 1\.0, 1\.0\]"),
    ("hand-eye 3 x 4", "  [0.0, 0.0, 0.0, 1.0],\n]", "]", r"handeye\.matrix.*at least 4"),
    ("negative repeatability", "repeatability_mm = 0.06", "repeatability_mm = -0.06",
     r"robot\.repeatability_mm = -0\.06: must be >= 0"),
    ("stripe off the sphere", "stripe_offset_fraction = 0.25", "stripe_offset_fraction = 1.5",
     r"sensor\.stripe_offset_fraction = 1\.5: must be >= 0 and < 1"),
    ("zero standoff", "standoff_mm = 250.0", "standoff_mm = 0.0",
     r"sensor\.standoff_mm = 0\.0: must be > 0"),
    ("misspelt key", "standoff_mm = 250.0", "standof_mm = 250.0",
     r"sensor\.standoff_mm: missing \(required\); sensor\.standof_mm = 250\.0: unknown key"),
    ("missing table", "[sphere]\n", "[spheer]\n", r"sphere: missing \(required\)"),
    ("2-d sphere centre", "centre_mm = [1000.0, 350.0, 0.0]", "centre_mm = [1000.0, 350.0]",
     r"sphere\.centre_mm = \[1000\.0, 350\.0\]: .*at least 3"),
    ("nan sphere centre", "centre_mm = [1000.0, 350.0, 0.0]", "centre_mm = [nan, 350.0, 0.0]",
     r"sphere\.centre_mm #1 = nan: must be a finite number"),
    ("2 translations", "n_translations = 4", "n_translations = 2",
     r"calibration_moves\.n_translations = 2: must be >= 3"),
    ("fractional move count", "n_rotations = 6", "n_rotations = 6.5",
     r"calibration_moves\.n_rotations = 6\.5: is not an integer"),
    ("min tilt above range", "rotation_min_deg = 10.0", "rotation_min_deg = 40.0",
     r"rotation_min_deg = 40\.0 exceeds rotation_range_deg = 30\.0"),
    ("zero focal length", "fx = 3019.0", "fx = 0.0", r"cameras\.fx = 0\.0: must be > 0"),
    ("principal point outside", "cx = 640.0", "cx = 1640.0",
     r"principal point \(1640\.0, 512\.0\) lies outside the 1280 x 1024"),
    ("text for a number", "pixel_sigma = 0.1", 'pixel_sigma = "0.1 px"',
     r"cameras\.pixel_sigma = '0\.1 px': is not a number"),
    ("one tilt missing", "  [8.0, 8.0],\n]", "]", r"10 positions_mm but 9 tilts_deg"),
    ("collinear datums", "datum_C_plane_mm = [700.0, 1050.0, 0.0]",
     "datum_C_plane_mm = [700.0, 250.0, 0.0]", r"datums A, B and C are collinear"),
    ("negative panel size", "size_mm = [1500.0, 1200.0]", "size_mm = [1500.0, -1200.0]",
     r"workpiece\.size_mm #2 = -1200\.0: must be > 0"),
]


@pytest.mark.parametrize(
    "old, new, message", [c[1:] for c in STATION_CASES], ids=[c[0] for c in STATION_CASES]
)
def test_station_file(tmp_path, old, new, message):
    path = _broken(tmp_path, STATION, old, new, "station.toml")
    with pytest.raises(CalibrationError, match=r"station\.toml: .*" + message):
        scenario.load_station(path)


PRODUCTION_CASES = [
    ("2 products", "n_before = 10", "n_before = 2", r"protocol\.n_before = 2: must be >= 3"),
    ("max below n", "n_compensation_max = 20", "n_compensation_max = 5",
     r"n_compensation_max = 5 is below n_before = 10 or n_compensation = 10"),
    ("negative part sigma", "part_sigma_mm = 0.5", "part_sigma_mm = -0.5",
     r"variation\.part_sigma_mm = -0\.5: must be >= 0"),
    ("unknown key", "[cmm]\n", "[cmm]\nx = 1\n", r"cmm\.x = 1: unknown key"),
    ("infinite cmm sigma", "sigma_mm = 0.02", "sigma_mm = inf",
     r"cmm\.sigma_mm = inf: must be a finite"),
    ("negative sweep value", "drift_sigma_mm = [0.0,", "drift_sigma_mm = [-0.1,",
     r"sweep\.drift_sigma_mm #1 = -0\.1: must be >= 0"),
    ("ids and points differ", 'ids = ["S01", ', 'ids = [',
     r"9 ids, 10 kinds and 10 points \(3 datums \+ 7 others_xyz_mm\)"),
    ("zero view", 'id = "H01", kind = "hole", xyz_mm = [150, 200, 0], view = [0, 0, 1]',
     'id = "H01", kind = "hole", xyz_mm = [150, 200, 0], view = [0, 0, 0]',
     r"view of H01 is the zero vector"),
    ("feature without yaw", 'xyz_mm = [150, 450, 0], view = [0, 0, 1], yaw_deg = 0 }',
     'xyz_mm = [150, 450, 0], view = [0, 0, 1] }',
     r"flexible\.features #2\.yaw_deg: missing \(required\)"),
]


@pytest.mark.parametrize(
    "old, new, message", [c[1:] for c in PRODUCTION_CASES], ids=[c[0] for c in PRODUCTION_CASES]
)
def test_production_file(tmp_path, old, new, message):
    path = _broken(tmp_path, PRODUCTION, old, new, "production.toml")
    with pytest.raises(CalibrationError, match=r"production\.toml: .*" + message):
        scenario.load_scenario(path)


def test_missing_files_name_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "none.toml"))):
        scenario.load_station(tmp_path / "none.toml")
    with pytest.raises(FileNotFoundError, match="no such file"):
        scenario.load_production(tmp_path / "none.toml")


def test_the_shipped_files_pass():
    scenario.load_station()
    scenario.load_production()


# ---------------------------------------------------------------------------------------------
# the hybrid and CMM tables of notebook 02


def _tables(tmp_path, shift=1000.0):
    """Two small tables (4 points, 25 products) with coordinates of a panel (hundreds of mm)."""
    rng = np.random.default_rng(10)
    c = rng.normal(0, 0.5, (25, 4, 3)) + shift
    h = c + rng.normal(0, 0.1, c.shape) + 1.5
    run = {"compensation": (h[:10], c[:10]), "follow-up": (h[10:], c[10:])}
    ids = ["A", "B", "C", "D"]
    paths = {}
    for which, name in ((0, "hybrid"), (1, "cmm")):
        frame = compensation.measurements_frame(ids, run, which)
        paths[name] = tmp_path / f"{name}.csv"
        frame.to_csv(paths[name], index=False, float_format="%.6f")
    return paths, run


def _rewrite(path, edit):
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")


def _cell(lines, row, column, text):
    header = lines[0].split(",")
    cells = lines[row - 1].split(",")
    cells[header.index(column)] = text
    lines[row - 1] = ",".join(cells)
    return lines


def test_good_tables_read_as_written(tmp_path):
    paths, run = _tables(tmp_path)
    ids, got = compensation.read_measurements(paths["hybrid"], paths["cmm"])
    assert ids == ["A", "B", "C", "D"]
    np.testing.assert_allclose(got["follow-up"][1], run["follow-up"][1], atol=1e-6)


def test_cmm_in_metres_is_refused_with_the_suspicion(tmp_path):
    paths, _ = _tables(tmp_path)
    frame = compensation.read_table(paths["cmm"], "CMM")[0]
    frame[["x_mm", "y_mm", "z_mm"]] /= 1000.0
    frame.to_csv(paths["cmm"], index=False, float_format="%.9f")
    with pytest.raises(
        CalibrationError,
        match=r"cmm\.csv: the coordinates of the CMM table are all below 10 \(largest \|value\| "
        r"1\.00\d+\) while those of the hybrid table reach 100\d.*look like metres",
    ):
        compensation.read_measurements(paths["hybrid"], paths["cmm"])


def test_cmm_declared_in_metres_is_converted(tmp_path):
    paths, run = _tables(tmp_path)
    frame = compensation.read_table(paths["cmm"], "CMM")[0]
    frame[["x_mm", "y_mm", "z_mm"]] /= 1000.0
    frame = frame.rename(columns={"x_mm": "x_m", "y_mm": "y_m", "z_mm": "z_m"})
    frame.to_csv(paths["cmm"], index=False, float_format="%.9f")
    _, got = compensation.read_measurements(paths["hybrid"], paths["cmm"])
    np.testing.assert_allclose(got["compensation"][1], run["compensation"][1], atol=1e-5)


def test_small_mm_coordinates_may_be_declared(tmp_path):
    paths, _ = _tables(tmp_path)
    frame = compensation.read_table(paths["cmm"], "CMM")[0]
    frame[["x_mm", "y_mm", "z_mm"]] -= 1000.0
    frame.to_csv(paths["cmm"], index=False, float_format="%.6f")
    with pytest.raises(CalibrationError, match="look like metres"):
        compensation.read_measurements(paths["hybrid"], paths["cmm"])
    _rewrite(paths["cmm"], lambda lines: ["# units: mm", *lines])
    compensation.read_table(paths["cmm"], "CMM")  # declared: no suspicion
    assert compensation.read_table(paths["cmm"], "CMM")[1]


def test_byte_order_mark_and_semicolons_are_read(tmp_path):
    paths, run = _tables(tmp_path)
    text = paths["hybrid"].read_text().replace(",", ";").replace(".", ",")
    paths["hybrid"].write_text(text, encoding="utf-8-sig")
    # a decimal comma under ';' is named with its row and column
    with pytest.raises(CalibrationError, match=r"hybrid\.csv: row 2, column 'x_mm': '1\d+,\d+' "
                       r"is not a number \(decimal comma\? write 1\d+\.\d+\)"):
        compensation.read_measurements(paths["hybrid"], paths["cmm"])
    paths["hybrid"].write_text(text.replace(",", "."), encoding="utf-8-sig")
    _, got = compensation.read_measurements(paths["hybrid"], paths["cmm"])
    np.testing.assert_allclose(got["compensation"][0], run["compensation"][0], atol=1e-6)


TABLE_CASES = [
    ("decimal comma splits", lambda ls: _cell(ls, 3, "x_mm", "12,5"),
     r"hybrid\.csv: row 3 has 7 cells; the header has 6 \(a decimal comma such as 12,5"),
    ("quoted decimal comma", lambda ls: _cell(ls, 3, "y_mm", '"12,5"'),
     r"hybrid\.csv: row 3, column 'y_mm': '12,5' is not a number \(decimal comma\? write 12\.5\)"),
    ("nan coordinate", lambda ls: _cell(ls, 5, "z_mm", "nan"),
     r"hybrid\.csv: row 5, column 'z_mm': 'nan' is not finite"),
    ("empty cell", lambda ls: _cell(ls, 4, "x_mm", ""),
     r"hybrid\.csv: row 4, column 'x_mm': '' is not a number \(empty cell\)"),
    ("misspelt phase", lambda ls: _cell(ls, 6, "phase", "compensaton"),
     r"hybrid\.csv: row 6, column 'phase': 'compensaton' is not one of"),
    ("fractional product", lambda ls: _cell(ls, 7, "product", "1.5"),
     r"hybrid\.csv: row 7, column 'product': '1\.5' is not an integer"),
    ("missing column", lambda ls: [",".join(ln.split(",")[:5]) for ls_ in [ls] for ln in ls_],
     r"hybrid\.csv: missing column\(s\) z_mm"),
    ("repeated column", lambda ls: [ls[0].replace("z_mm", "x_mm"), *ls[1:]],
     r"hybrid\.csv: column\(s\) \['x_mm'\] given more than once"),
    ("header only", lambda ls: ls[:1], r"hybrid\.csv: no data rows"),
    ("mm and m columns", lambda ls: [ls[0].replace("z_mm", "z_m"), *ls[1:]],
     r"hybrid\.csv: coordinates in both mm and m columns"),
    ("duplicated point", lambda ls: [*ls, ls[1]],
     r"duplicated feature point in the hybrid table: point A appears 2 times in product 1"),
]


@pytest.mark.parametrize(
    "edit, message", [c[1:] for c in TABLE_CASES], ids=[c[0] for c in TABLE_CASES]
)
def test_hybrid_table(tmp_path, edit, message):
    paths, _ = _tables(tmp_path)
    _rewrite(paths["hybrid"], edit)
    with pytest.raises(CalibrationError, match=message):
        compensation.read_measurements(paths["hybrid"], paths["cmm"])


def test_missing_table_names_the_path(tmp_path):
    paths, _ = _tables(tmp_path)
    with pytest.raises(FileNotFoundError, match=r"nothing\.csv: no such file \(the CMM table\)"):
        compensation.read_measurements(paths["hybrid"], tmp_path / "nothing.csv")


# ---------------------------------------------------------------------------------------------
# the fixed-sphere CSV of notebook 01


@pytest.fixture(scope="module")
def sphere_files(tmp_path_factory):
    """A simulated station's measurements, and the same with the sphere moved by 5 mm (in the
    base frame) between the translation and the rotation series."""
    folder = tmp_path_factory.mktemp("sphere")
    rng = np.random.default_rng(11)
    station = simulate.make_station(rng)
    meas, _ = simulate.simulate_sphere_measurements(station, 4, 6, rng)
    good, moved = folder / "good.csv", folder / "moved.csv"
    sphere_csv.write_sphere_measurements(meas, good)
    rot = station.sensor2flange_true[:3, :3]
    centres = meas.centres.copy()
    for i in np.flatnonzero(meas.group == "rotation"):
        centres[i] += rot.T @ meas.flange2base[i, :3, :3].T @ np.array([5.0, 0.0, 0.0])
    sphere_csv.write_sphere_measurements(dataclasses.replace(meas, centres=centres), moved)
    return good, moved


def test_sphere_that_moved_is_refused_naming_the_ids(sphere_files):
    good, moved = sphere_files
    # the robot's pose error is part of a measured centre's scatter: 0.3 mm
    handeye_experiments.sphere_station_calibration(str(good), 0, 0.3)
    with pytest.raises(
        CalibrationError, match=r"chi2/dof = \d+(\.\d+)? .* disagree most: id \d+ \(RMS"
    ):
        handeye_experiments.sphere_station_calibration(str(moved), 0, 0.3)


def test_sphere_that_moved_may_be_flagged(sphere_files):
    _, moved = sphere_files
    with pytest.warns(UserWarning, match=r"disagree most: id \d+"):
        *_, ml, _ = handeye_experiments.sphere_station_calibration(
            str(moved), 0, 0.3, misfit="flag"
        )
    assert any("disagree most" in f for f in ml.flags)


PUBLISHED = data_path("hybrid", "published.toml").read_text()

PUBLISHED_CASES = [
    ("counts of the halves differ", "deviation_counts = [37, 82, 49, 6, 0]",
     "deviation_counts = [37, 82, 49, 6, 10]",
     r"table1: deviation_counts sum to 184, correlation_counts to 174"),
    ("share against its count", "deviation_percent = [21.26,", "deviation_percent = [12.26,",
     r"deviation_percent #1 = 12\.26 disagrees with its count: 37 of 174 is 21\.26 %"),
    ("headline share as a fraction", "within_0p3_percent = 96.55", "within_0p3_percent = 0.9655",
     r"within_0p3_percent = 0\.9655 disagrees with its count: 168 of 174"),
    ("edges not ascending", "deviation_edges_mm = [0.1, 0.2, 0.3, 0.5]",
     "deviation_edges_mm = [0.1, 0.3, 0.2, 0.5]",
     r"table1\.deviation_edges_mm = \[0\.1, 0\.3, 0\.2, 0\.5\]: the edges are not ascending"),
    ("correlation edges in percent", "correlation_edges = [0.6, 0.7, 0.8, 0.9]",
     "correlation_edges = [60, 70, 80, 90]", r"table1\.correlation_edges #1 = 60: must be <= 1"),
    ("range reversed", "range_mm = [2.0, 4.0]", "range_mm = [4.0, 2.0]",
     r"systematic\.range_mm = \[4\.0, 2\.0\]: \[4\.0, 2\.0\] is not \[low, high\]"),
    ("four counts", "deviation_counts = [37, 82, 49, 6, 0]", "deviation_counts = [37, 82, 49, 6]",
     r"table1\.deviation_counts = \[37, 82, 49, 6\]: must have at least 5 entries, not 4"),
    ("fractional count", "deviation_counts = [37, 82, 49, 6, 0]",
     "deviation_counts = [37, 82, 49.5, 6, 0]",
     r"table1\.deviation_counts #3 = 49\.5: is not an integer"),
    ("missing headline", "r_above_0p7_percent = 85.64\n", "",
     r"table1\.r_above_0p7_percent: missing \(required\)"),
    ("misspelt table", "[table1]", "[table_1]",
     r"table1: missing \(required\); table_1: unknown key"),
]


@pytest.mark.parametrize(
    "old, new, message", [c[1:] for c in PUBLISHED_CASES], ids=[c[0] for c in PUBLISHED_CASES]
)
def test_published_file(tmp_path, old, new, message):
    path = _broken(tmp_path, PUBLISHED, old, new, "published.toml")
    with pytest.raises(CalibrationError, match=r"published\.toml: .*" + message):
        scenario.load_published(path)
