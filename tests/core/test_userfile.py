"""One reader under every user file: the four readers (pose lists, fixed-sphere CSVs, the hybrid
tables, a self-calibration cell) accept a spreadsheet's export (byte-order mark, ``;``) with the
same numbers, refuse a decimal comma naming file, row and column, and raise FileNotFoundError
for a missing file."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest
from support import ideal_station

from calstudy import CalibrationError
from calstudy.core import userfile
from calstudy.core.paths import data_path
from calstudy.handeye import read_pose_list, read_sphere_measurements, write_sphere_measurements
from calstudy.papers.hybrid import compensation, simulate
from calstudy.selfcal import measured


def _pose_list(tmp_path):
    path = tmp_path / "poses.csv"
    shutil.copy(data_path("handeye", "example_poses.csv"), path)
    return path, lambda: read_pose_list(path).robot


def _spheres(tmp_path):
    station, rng = ideal_station()
    meas, _ = simulate.simulate_sphere_measurements(station, 4, 6, rng)
    path = tmp_path / "spheres.csv"
    write_sphere_measurements(meas, path)
    return path, lambda: read_sphere_measurements(path).centres


def _hybrid(tmp_path):
    rng = np.random.default_rng(10)
    c = rng.normal(0, 0.5, (25, 4, 3)) + 1000.0
    h = c + rng.normal(0, 0.1, c.shape) + 1.5
    run = {"compensation": (h[:10], c[:10]), "follow-up": (h[10:], c[10:])}
    paths = {}
    for which, name in ((0, "hybrid"), (1, "cmm")):
        paths[name] = tmp_path / f"{name}.csv"
        compensation.measurements_frame(["A", "B", "C", "D"], run, which).to_csv(
            paths[name], index=False, float_format="%.6f"
        )
    return paths["hybrid"], lambda: compensation.read_measurements(
        paths["hybrid"], paths["cmm"]
    )[1]["compensation"][0]


def _selfcal(tmp_path):
    folder = tmp_path / "cell"
    shutil.copytree(data_path("selfcal", "example_measurements"), folder)
    return folder / measured.SPHERES_FILE, lambda: measured.read_cell(folder).spheres


READERS = {"pose list": _pose_list, "sphere CSV": _spheres, "hybrid": _hybrid, "selfcal": _selfcal}


def _content(lines: list[str]) -> list[int]:
    """Indices of the lines that are neither blank nor comments (a byte-order mark aside)."""
    stripped = [ln.strip("\ufeff \t") for ln in lines]
    return [i for i, ln in enumerate(stripped) if ln and not ln.startswith("#")]


def _decimal_cell(lines: list[str], sep: str) -> tuple[int, str, str]:
    """Line index, column name and text of the first decimal number of the first data row."""
    h, k = _content(lines)[:2]
    header = lines[h].lstrip("\ufeff")
    cells = lines[k].split(sep)
    j = next(j for j, c in enumerate(cells) if re.fullmatch(r"-?\d+\.\d+", c.strip()))
    return k, header.split(sep)[j].strip(), cells[j].strip()


@pytest.mark.parametrize("reader", READERS)
def test_spreadsheet_export_reads_the_same_numbers(tmp_path, reader):
    path, read = READERS[reader](tmp_path)
    plain = read()
    text = path.read_text()
    path.write_text("\ufeff" + text.replace(",", ";"), encoding="utf-8")
    np.testing.assert_array_equal(read(), plain)


@pytest.mark.parametrize("reader", READERS)
def test_decimal_comma_is_refused_naming_file_row_and_column(tmp_path, reader):
    path, read = READERS[reader](tmp_path)
    lines = ("\ufeff" + path.read_text().replace(",", ";")).splitlines()
    k, column, text = _decimal_cell(lines, ";")
    comma = text.replace(".", ",")
    lines[k] = lines[k].replace(text, comma, 1)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    message = (
        f"{re.escape(path.name)}: row {k + 1}, column '{column}': '{comma}' is not a number "
        rf"\(decimal comma\? write {re.escape(text)}\)"
    )
    with pytest.raises(CalibrationError, match=message):
        read()


@pytest.mark.parametrize("reader", READERS)
def test_decimal_comma_in_a_comma_file_is_named_as_the_cause(tmp_path, reader):
    path, read = READERS[reader](tmp_path)
    lines = path.read_text().splitlines()
    k, _, text = _decimal_cell(lines, ",")
    lines[k] = lines[k].replace(text, text.replace(".", ","), 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(CalibrationError, match=rf"row {k + 1} has \d+ cells; .*decimal comma"):
        read()


@pytest.mark.parametrize("reader", READERS)
def test_missing_file_is_file_not_found(tmp_path, reader):
    path, read = READERS[reader](tmp_path)
    path.unlink()
    with pytest.raises(FileNotFoundError, match=re.escape(path.name)):
        read()


def test_self_calibration_cell_without_its_description_is_file_not_found(tmp_path):
    _, read = _selfcal(tmp_path)
    (tmp_path / "cell" / measured.CELL_FILE).unlink()
    with pytest.raises(FileNotFoundError, match=measured.CELL_FILE):
        read()


def test_one_unit_table():
    """Every reader converts with the same factors: a length in any unit the table lists, an
    angle in degrees or radians."""
    assert userfile.LENGTH_UNITS == {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
    assert userfile.ANGLE_UNITS["deg"] * 180.0 == pytest.approx(np.pi, rel=1e-15)
    with pytest.raises(CalibrationError, match=r"f.csv: row 3, column 'x': '1,5' .*write 1.5"):
        userfile.parse_number("f.csv", 3, "x", "1,5")
