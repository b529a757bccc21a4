"""The committed tables, claims and controls of notebook 05 recomputed from its committed trial
rows with the report functions (no simulation)."""

from __future__ import annotations

import pandas as pd
import pytest
from support import assert_same_table

from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import claims_table
from calstudy.papers.dualarm import report
from calstudy.papers.dualarm.scenario import load_published

FOLDER = RESULTS_DIR / "05_dualarm_global_calibration"

pytestmark = pytest.mark.skipif(
    not (FOLDER / "trials_station.csv").is_file(), reason="notebook 05 results not committed"
)


def _trials(name: str) -> pd.DataFrame:
    return pd.read_csv(FOLDER / f"trials_{name}.csv")


def _compare(fresh: pd.DataFrame, name: str) -> None:
    assert_same_table(fresh, FOLDER / f"{name}.csv")


def test_tables_recompute_from_the_trials():
    published = load_published()
    trials = _trials("station")
    targets = report.published_figures(published)
    _compare(
        report.calibration_table(
            _trials("drift_pilot"), "drift_scale", "before_mm", targets["icp_before"]
        ),
        "drift_calibration",
    )
    _compare(
        report.calibration_table(
            _trials("plate_pilot"), "plate_sigma_px", "plate_euclid_mm", targets["plate"]
        ),
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
