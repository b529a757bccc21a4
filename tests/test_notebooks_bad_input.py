"""A notebook run with a broken user file stops at the first cell that reads it, with the
CalibrationError message that names the file and the problem (papermill, CI parameters)."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import papermill as pm
import pytest
from support import NOTEBOOK_DIR, REPRODUCIBLE_ENV, ci_parameters

from calstudy.core.paths import data_path
from calstudy.handeye import sphere_csv
from calstudy.papers.hybrid import simulate


def _run_broken(tmp_path, stem, params):
    notebook = NOTEBOOK_DIR / f"{stem}.ipynb"
    params = ci_parameters(stem) | params | {"results_dir": str(tmp_path / "out")}
    with pytest.raises(pm.PapermillExecutionError) as info:
        pm.execute_notebook(
            str(notebook),
            str(tmp_path / "out.ipynb"),
            parameters=params,
            cwd=str(notebook.parent),
            progress_bar=False,
        )
    err = info.value
    assert err.ename == "CalibrationError", (err.ename, err.evalue)
    return err


@pytest.fixture(autouse=True)
def _env(monkeypatch):
    for key, value in REPRODUCIBLE_ENV.items():
        monkeypatch.setenv(key, value)


def _text(path, old, new):
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


@pytest.mark.slow
def test_notebook01_stops_at_the_measurements_cell(tmp_path):
    """The sphere moved 5 mm between the translation and the rotation series: refused by the
    goodness-of-fit test, naming the ids that disagree most."""
    rng = np.random.default_rng(11)
    station = simulate.make_station(rng)
    meas, _ = simulate.simulate_sphere_measurements(station, 4, 6, rng)
    rot = station.sensor2flange_true[:3, :3]
    centres = meas.centres.copy()
    for i in np.flatnonzero(meas.group == "rotation"):
        centres[i] += rot.T @ meas.flange2base[i, :3, :3].T @ np.array([5.0, 0.0, 0.0])
    csv = tmp_path / "mine.csv"
    sphere_csv.write_sphere_measurements(dataclasses.replace(meas, centres=centres), csv)
    err = _run_broken(tmp_path, "01_hybrid_global_calibration", {"measurements_csv": str(csv)})
    assert "ML sphere hand-eye: whitened residual chi2/dof" in err.evalue
    assert "disagree most: id" in err.evalue
    assert "experiments.sphere_station_calibration(" in err.source


def test_notebook02_stops_at_the_tables_cell(tmp_path):
    hybrid, cmm = tmp_path / "hybrid.csv", tmp_path / "cmm.csv"
    header = "product,phase,point_id,x_mm,y_mm,z_mm\n"
    hybrid.write_text(header + "1,compensation,A,100.0,200.0,0.0\n")
    cmm.write_text(header.replace(",", ";") + "1;compensation;A;12,5;200.0;0.0\n")
    err = _run_broken(
        tmp_path,
        "02_hybrid_production_compensation",
        {"hybrid_csv": str(hybrid), "cmm_csv": str(cmm)},
    )
    assert "cmm.csv: row 2, column 'x_mm': '12,5' is not a number (decimal comma?" in err.evalue
    assert "compensation.station_data(" in err.source


def test_notebook03_stops_at_the_measurements_cell(tmp_path):
    folder = tmp_path / "cell"
    shutil.copytree(data_path("selfcal", "example_measurements"), folder)
    _text(folder / "cell.toml", "xyz_mm = [0.000, -80.000, 120.000]", "xyz_mm = [0.0, -80.0]")
    err = _run_broken(
        tmp_path, "03_selfcal_one_step_identification", {"measurements_dir": str(folder)}
    )
    assert "cell.toml: sensor.xyz_mm" in err.evalue and "at least 3" in err.evalue
    assert "cell = read_cell(measurements_dir)" in err.source


def test_notebook03_stops_at_the_scenario_cell(tmp_path):
    path = tmp_path / "my_cell.toml"
    path.write_text(data_path("selfcal", "scenario.toml").read_text())
    _text(path, "radius_mm = 25.0", "radius_mm = -25.0")
    err = _run_broken(tmp_path, "03_selfcal_one_step_identification", {"scenario_toml": str(path)})
    assert "my_cell.toml: spheres.radius_mm = -25.0: must be > 0" in err.evalue
    assert "load_scenario(scenario_toml" in err.source


def test_notebook04_stops_at_the_scenario_cell(tmp_path):
    """A scenario folder whose calibrator distances admit no layout (a layout solved anyway
    misses them by up to 84 mm): refused in the first cell that reads the folder, naming the
    distances."""
    folder = tmp_path / "my_cell"
    folder.mkdir()
    for name in ("sensor", "calibrator", "station"):
        shutil.copy(data_path("binocular", f"{name}.toml"), folder / f"{name}.toml")
    _text(folder / "calibrator.toml", "130.546, 64.765,", "130.546, 364.765,")
    err = _run_broken(tmp_path, "04_binocular_correction", {"scenario_dir": str(folder)})
    assert "calibrator.toml: standard.distance_mm = [" in err.evalue
    assert "P5P7 = 364.765 admit no layout" in err.evalue
    assert "load_scenario(scenario_dir" in err.source


def test_notebook05_stops_at_the_scenario_cell(tmp_path):
    path = tmp_path / "my_station.toml"
    path.write_text(data_path("dualarm", "scenario.toml").read_text())
    _text(path, "loss_rate = 0.1", "loss_rate = 1.5")
    err = _run_broken(tmp_path, "05_dualarm_global_calibration", {"scenario_toml": str(path)})
    assert "my_station.toml: detection.loss_rate = 1.5: must be >= 0 and < 1" in err.evalue
    assert "scenario.load_scenario(scenario_toml" in err.source


def test_notebook06_stops_at_the_pose_list_cell(tmp_path):
    """A pose list with a position that is not a number: refused with the row and column, in
    the cell that reads the pose list."""
    lines = data_path("handeye", "example_poses.csv").read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    header = lines[first].split(",")
    row = lines[first + 2].split(",")
    col = header.index("flange2base_x_mm")
    row[col] = row[col].replace(".", ";")  # not a number
    lines[first + 2] = ",".join(row)
    csv = tmp_path / "poses.csv"
    csv.write_text("\n".join(lines) + "\n")
    err = _run_broken(tmp_path, "06_handeye_your_cell", {"poses_csv": str(csv)})
    assert "poses.csv" in err.evalue and "flange2base_x_mm" in err.evalue
    assert "hc.calibrate_cell(" in err.source
