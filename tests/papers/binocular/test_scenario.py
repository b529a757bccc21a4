"""Tests of calstudy.papers.binocular.scenario: the station and the published numbers."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.papers.binocular import scenario as scn


def copy_scenario(folder):
    for name in scn.TABLES:
        shutil.copy(data_path("binocular", f"{name}.toml"), folder / f"{name}.toml")


def test_load_scenario_from_own_directory(tmp_path):
    copy_scenario(tmp_path)
    station = tmp_path / "station.toml"
    station.write_text(station.read_text().replace("p7_height_mm = 600.0", "p7_height_mm = 650.0"))
    default, own = scn.load_scenario(), scn.load_scenario(tmp_path)
    assert np.array_equal(own.layout, default.layout)
    assert own.calibrator2base[2, 3] == pytest.approx(default.calibrator2base[2, 3] + 50.0)
    (tmp_path / "calibrator.toml").unlink()
    with pytest.raises(FileNotFoundError, match=r"calibrator\.toml: no such file"):
        scn.load_scenario(tmp_path)


def test_missing_key_names_the_file_and_the_key(tmp_path):
    copy_scenario(tmp_path)
    station = tmp_path / "station.toml"
    station.write_text(station.read_text().replace('model = "kuka_kr210"', ""))
    message = r"station\.toml: robot\.model: missing \(required\)"
    with pytest.raises(CalibrationError, match=message):
        scn.load_scenario(tmp_path)


def test_scenario_derived_values():
    s = scn.load_scenario()
    v = 12058.0 * 0.0046  # lens-to-sensor distance; thin lens focused at 850 mm
    assert s.focal_mm == pytest.approx(v * 850.0 / (v + 850.0))
    assert s.dot_radius_mm == 2.5
    assert s.coc_radius_px(850.0) == 0.0
    assert s.detection == {"low": 0.25, "high": 0.5, "min_points": 20}
    p7 = s.calibrator2base[:3, 3]
    assert np.linalg.norm(p7) == pytest.approx(2342.949)


def test_published_numbers_come_from_data():
    assert scn.published("station", "fig13_rmse") == [0.192, 0.080]
    assert scn.published("calibrator", "table2_rmse") == [0.049, 0.041]
    with pytest.raises(
        CalibrationError, match=r"binocular/station\.toml: no value 'published\.nothing'"
    ):
        scn.published("station", "nothing")


def test_overrides_name_the_file_first_and_are_validated():
    s = scn.load_scenario(
        overrides={"sensor.optics.f_number": 5.6, "calibrator.sbr.dot_diameter_mm": 4.0}
    )
    assert s.sensor.optics.f_number == 5.6 and s.dot_radius_mm == 2.0
    with pytest.raises(
        CalibrationError,
        match=r"sensor\.toml: optics\.f_number = 1\.4: outside its plausible range",
    ):
        scn.load_scenario(overrides={"sensor.optics.f_number": 1.4})
    rim = scn.load_scenario(overrides={"sensor.optics.mechanism": "rim"})
    assert rim.sensor.optics.mechanism == "rim"
    assert scn.load_scenario().sensor.optics.mechanism == "gaussian"  # the paper's Eq. 7
    bad = r"optics\.mechanism = \"cat's eye\": is not one of 'gaussian' or 'rim'"
    with pytest.raises(CalibrationError, match=bad):
        scn.load_scenario(overrides={"sensor.optics.mechanism": "cat's eye"})
    for key in ("optics.f_number", "sensor.optics.f_numbr", "sensor"):
        with pytest.raises(CalibrationError, match=rf"override '{key}': '[^']*' names no input"):
            scn.load_scenario(overrides={key: 5.6})
