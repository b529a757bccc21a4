"""The committed results of notebook 04 follow from its committed trial rows: every table and the
claims and controls are recomputed by the report functions (no simulation) and compared."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from support import assert_same_table

from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import read_claims
from calstudy.papers.binocular import report
from calstudy.papers.binocular.scenario import published

STEM = "04_binocular_correction"
OUT = RESULTS_DIR / STEM


@pytest.fixture(scope="module")
def frames():
    if not (OUT / "trials_binocular.csv").is_file():
        pytest.skip("results/04_binocular_correction has not been regenerated with the engine yet")
    return pd.read_csv(OUT / "trials_binocular.csv"), pd.read_csv(OUT / "trials_field.csv")


def _same(got: pd.DataFrame, name: str) -> None:
    assert_same_table(got, OUT / f"{name}.csv")


def test_tables(frames):
    trials, field = frames
    _same(report.distance_table(trials, "table2"), "table2")
    _same(report.distance_table(trials, "table3"), "table3")
    _same(report.handeye_table(trials), "table4")
    _same(report.field_table(field), "table5")
    _same(report.rmse_summary(trials, field), "rmse_summary")
    _same(report.sweep_table(trials, "robot"), "robot_sweep")
    _same(report.sweep_table(trials, "calibration"), "calibration_sweep")


def test_claims_and_controls(frames):
    trials, field = frames
    claims, controls = report.claim_rows(trials, field, STEM)
    want = read_claims(OUT / "claims.csv")
    got = pd.DataFrame([c.__dict__ for c in claims])
    assert got["verdict"].tolist() == want["verdict"].tolist()
    assert got["note"].tolist() == want["note"].fillna("").tolist()
    for col in ("reproduced", "ci_low", "ci_high", "replication_rate"):
        pd.testing.assert_series_equal(got[col], want[col], rtol=2e-5, check_dtype=False)
    _same(pd.DataFrame(controls), "controls")


def test_optics_sweeps_and_the_calibrated_f_number():
    if not (OUT / "trials_optics_sweep.csv").is_file():
        pytest.skip("results/04_binocular_correction has no optics sweeps yet")
    fsweep = pd.read_csv(OUT / "trials_fnumber_sweep.csv")
    osweep = pd.read_csv(OUT / "trials_optics_sweep.csv")
    fnumber = report.optics_sweep_table(fsweep, "f_number")
    _same(fnumber, "fnumber_sweep")
    _same(report.optics_sweep_table(osweep, "focus_distance_mm"), "focus_distance_sweep")
    _same(report.optics_sweep_table(osweep, "dot_diameter_mm"), "dot_diameter_sweep")
    assert (fnumber["n"] >= 30).all()
    run = json.loads((OUT / "run.json").read_text())["parameters"]
    target = published("calibrator", "table2_rmse")[0]
    calibrated = report.calibrated_f_number(fnumber, target)
    assert run["f_number"] == (calibrated if calibrated is not None else 8.0)
