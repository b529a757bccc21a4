"""Scenarios that cannot exist are refused before any simulation, in well under a second, with a
CalibrationError naming the input and the number."""

from __future__ import annotations

import re
import shutil
import time

import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.papers.binocular.scenario import load_scenario as load_binocular
from calstudy.papers.dualarm.scenario import load_scenario as load_dualarm
from calstudy.papers.hybrid.scenario import load_production, load_station
from calstudy.papers.selfcal.scenario import load_scenario as load_selfcal


def _folder(tmp_path, paper, name, old, new):
    for f in data_path(paper).glob("*.toml"):
        shutil.copy(f, tmp_path / f.name)
    path = tmp_path / name
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    return path


CASES = [
    (
        "selfcal scanner inside the sphere",
        "selfcal", "scenario.toml", "standoff_mm = 300.0", "standoff_mm = 10.0",
        lambda folder, path: load_selfcal(path),
        r"scanner\.standoff_mm = 10\.0: .*within the sphere's radius",
    ),
    (
        "dualarm stand 5 m below the base",
        "dualarm", "scenario.toml", "stand_height_mm = 100.0", "stand_height_mm = -5000.0",
        lambda folder, path: load_dualarm(path),
        r"global_test\.stand_height_mm = -5000\.0: sphere A .* lies \d+ mm from the base of arm",
    ),
    (
        "dualarm baseline 5000 mm at 500 mm",
        "dualarm", "scenario.toml", "baseline_mm = 200.0", "baseline_mm = 5000.0",
        lambda folder, path: load_dualarm(path),
        r"stereo\.baseline_mm = 5000\.0: .*converge at 84\.3 deg",
    ),
    (
        "dualarm point noise 1e6 mm",
        "dualarm", "scenario.toml", "point_sigma_mm = 0.03", "point_sigma_mm = 1e6",
        lambda folder, path: load_dualarm(path),
        r"sensor\.point_sigma_mm = 1000000\.0: must be >= 0 and <= 1\.0",
    ),
    (
        "hybrid stationary sensor above the panel",
        "hybrid", "station.toml", "[1400.0, -250.0, -250.0]", "[1400.0, -250.0, 250.0]",
        lambda folder, path: load_station(path),
        r"stationary\.positions_mm #1 z = 250\.0: the sensor sits at or above the panel",
    ),
    (
        "hybrid sensor looking down",
        "hybrid", "station.toml", "[5.0, 0.0],", "[175.0, 0.0],",
        lambda folder, path: load_station(path),
        r"stationary\.tilts_deg #2 = \[175\.0, 0\.0\]: the sensor looks sideways or down",
    ),
    (
        "hybrid 1e9 compensation products",
        "hybrid", "production.toml", "n_compensation_max = 20", "n_compensation_max = 1000000000",
        lambda folder, path: load_production(path),
        r"protocol\.n_compensation_max = 1000000000: must be >= 3 and <= 1000",
    ),
    (
        "binocular station 8.5 m from the calibrator",
        "binocular", "station.toml", "observation_distance_mm = 850.0",
        "observation_distance_mm = 8500.0",
        lambda folder, path: load_binocular(folder),
        r"poses\.observation_distance_mm = 8500\.0: every view of the calibrator .* beyond its "
        r"reach",
    ),
]


@pytest.mark.parametrize(
    "paper, name, old, new, load, message", [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_impossible_scenario_refused_fast(tmp_path, paper, name, old, new, load, message):
    path = _folder(tmp_path, paper, name, old, new)
    start = time.perf_counter()
    with pytest.raises(CalibrationError, match=message):
        load(tmp_path, path)
    assert time.perf_counter() - start < 1.0


def _user(path, *keys):
    """Mark ``keys`` of the file ``path`` as the user's own (no ledger range applies)."""
    text = path.read_text()
    for key in keys:
        mine = f'provenance.{key} = {{ kind = "user" }}'
        text = re.sub(rf"provenance\.{key} = {{.*}}", mine, text)
    path.write_text(text)


def test_selfcal_envelope_out_of_reach(tmp_path):
    """A user's sphere envelope 3.1-3.9 m in front of the M-710iC/50 (reach about 2 m)."""
    path = _folder(
        tmp_path, "selfcal", "scenario.toml", "[1100.0, -900.0, 0.0]", "[3100.0, -900.0, 0.0]"
    )
    path.write_text(path.read_text().replace("[1900.0, 900.0, 1200.0]", "[3900.0, 900.0, 1200.0]"))
    _user(path, "envelope_min_mm", "envelope_max_mm")
    start = time.perf_counter()
    with pytest.raises(
        CalibrationError,
        match=r"spheres\.envelope_min_mm = \[3100\.0, -900\.0, 0\.0\], envelope_max_mm = "
        r"\[3900\.0, 900\.0, 1200\.0\]: .* at least \d+ mm beyond its reach",
    ):
        load_selfcal(path)
    assert time.perf_counter() - start < 1.0


def test_hybrid_sensor_inside_the_sphere(tmp_path):
    path = _folder(tmp_path, "hybrid", "station.toml", "standoff_mm = 250.0", "standoff_mm = 5.0")
    _user(path, "standoff_mm")
    start = time.perf_counter()
    with pytest.raises(
        CalibrationError, match=r"sensor\.standoff_mm = 5\.0: not beyond the sphere's radius"
    ):
        load_station(path)
    assert time.perf_counter() - start < 1.0


def test_dualarm_camera_inside_the_sphere(tmp_path):
    path = _folder(
        tmp_path, "dualarm", "scenario.toml", "working_distance_mm = 500.0",
        "working_distance_mm = 20.0",
    )
    _user(path, "working_distance_mm")
    start = time.perf_counter()
    with pytest.raises(
        CalibrationError,
        match=r"sensor\.working_distance_mm = 20\.0: not beyond the radius of the spheres it "
        r"scans \(25\.4035 mm",
    ):
        load_dualarm(path)
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize(
    "paper, load",
    [
        ("selfcal", lambda: load_selfcal()),
        ("dualarm", lambda: load_dualarm()),
        ("hybrid", lambda: (load_station(), load_production())),
        ("binocular", lambda: load_binocular()),
    ],
)
def test_the_papers_scenarios_are_plausible(paper, load):
    load()
