"""The committed tables, claims and controls of notebook 05 recomputed from its committed trial
rows with the report functions (no simulation)."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from support import assert_same_table

from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import claims_table
from calstudy.papers.dualarm import report, report_calibration
from calstudy.papers.dualarm.scenario import load_published

FOLDER = RESULTS_DIR / "05_dualarm_global_calibration"

pytestmark = pytest.mark.skipif(
    not (FOLDER / "trials_station.csv").is_file(), reason="notebook 05 results not committed"
)


def _trials(name: str) -> pd.DataFrame:
    return pd.read_csv(FOLDER / f"trials_{name}.csv")


def _compare(fresh: pd.DataFrame, name: str) -> None:
    assert_same_table(fresh, FOLDER / f"{name}.csv")


def _fits():
    published = load_published()
    drift, plate = _trials("drift_pilot"), _trials("plate_pilot")
    return (
        (report_calibration.drift_fit(drift, published), drift, "drift_scale"),
        (report_calibration.plate_fit(plate, published), plate, "plate_sigma_px"),
    )


def test_the_stored_calibrated_values_are_the_ones_the_code_computes():
    """The calibrated values the station trials ran with (run.json) are the joint fits of the
    committed pilot rows, rounded as fed; the station rows carry the plate noise too."""
    stored = json.loads((FOLDER / "run.json").read_text())["parameters"]
    for fit, _, x in _fits():
        assert stored[x] == report_calibration.fed_value(fit, x), x
    station = _trials("station")
    assert set(station["plate_sigma_px"]) == {stored["plate_sigma_px"]}


def test_tables_recompute_from_the_trials():
    published = load_published()
    trials = _trials("station")
    (drift, drift_pilot, _), (plate, plate_pilot, _) = _fits()
    _compare(
        report_calibration.calibration_table(drift, drift_pilot, "drift_scale"),
        "drift_calibration",
    )
    _compare(
        report_calibration.calibration_table(plate, plate_pilot, "plate_sigma_px"),
        "plate_calibration",
    )
    _compare(report.calibration_summary(trials), "calibration_summary")
    _compare(report.icp_summary(report.part(trials, "icp"), published), "icp_summary")
    glob = report.part(trials, "global")
    _compare(report.table1(glob, published), "table1_axis_errors")
    _compare(report.table2(glob, published), "table2_euclidean_errors")
    _compare(report.table3(glob, published), "table3_methods")


def test_claims_and_controls_recompute_from_the_trials():
    claims, controls = report.dualarm_claims(_trials("station"), load_published(), FOLDER.name)
    _compare(claims_table(claims), "claims")
    _compare(pd.DataFrame(controls), "controls")
