"""Every table, claim and control of notebook 03 recomputed from its committed trial rows.

No simulation: the report functions read ``results/03_*/trials_*.csv`` and the scenario, and
must give the committed tables (numbers to rtol 2e-5, text exactly).
"""

from __future__ import annotations

import pandas as pd
import pytest
from support import assert_same_table

from calstudy.claims import CONTROL_COLUMNS
from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import claims_table
from calstudy.papers.selfcal import report, report_sweeps
from calstudy.papers.selfcal.scenario import load_scenario

STEM = "03_selfcal_one_step_identification"
OUT = RESULTS_DIR / STEM

pytestmark = pytest.mark.skipif(
    not (OUT / "trials_calibration.csv").is_file(), reason="no committed trials"
)


def _trials(name: str) -> pd.DataFrame:
    return pd.read_csv(OUT / f"trials_{name}.csv")


def _compare(fresh: pd.DataFrame, name: str) -> None:
    assert_same_table(fresh, OUT / f"{name}.csv")


@pytest.fixture(scope="module")
def calib():
    return _trials("calibration")


def test_tables(calib):
    sc = load_scenario()
    _compare(report.route_table(calib), "routes")
    _compare(report.summarise_history(calib), "convergence_summary")
    _compare(report.convergence_summary(calib), "convergence_counts")
    _compare(report.robot_example(calib), "robot_parameters_example")
    _compare(report.summarise_robot(calib), "robot_parameters_summary")
    _compare(report.basin_table(_trials("basin"), sc.published.convergence_iterations), "basin")
    compliance = _trials("compliance_sweep")
    own = sc.compliance.scale
    _compare(
        report_sweeps.sweep_table(calib, compliance, "compliance_scale", own), "compliance_sweep"
    )
    _compare(
        report_sweeps.sweep_verdicts(calib, compliance, "compliance_scale", own, sc),
        "compliance_verdicts",
    )
    arm, arm_own = _trials("arm_weight_sweep"), sc.compliance.arm_weight_fraction
    key = "arm_weight_fraction"
    _compare(report_sweeps.sweep_table(calib, arm, key, arm_own), "arm_weight_sweep")
    _compare(report_sweeps.sweep_verdicts(calib, arm, key, arm_own, sc), "arm_weight_verdicts")
    noise = _trials("noise_sweep")
    _compare(report_sweeps.sweep_table(calib, noise, "noise_scale", 1.0), "noise_sweep")
    _compare(report_sweeps.sweep_verdicts(calib, noise, "noise_scale", 1.0, sc), "noise_verdicts")


def test_compliance_sweep_judges_all_five_claims_at_every_scale(calib):
    """Every compliance scale of the scenario has >= 30 trials and a verdict for each claim;
    at the scenario's own scale the verdicts are those of claims.csv."""
    sc = load_scenario()
    table = report_sweeps.sweep_verdicts(
        calib, _trials("compliance_sweep"), "compliance_scale", sc.compliance.scale, sc
    )
    assert sorted(set(table["compliance_scale"])) == sorted(sc.compliance.sweep_scales)
    assert (table.groupby("compliance_scale")["claim"].nunique() == 5).all()
    assert (table["n"] >= 30).all()
    own = table[table["compliance_scale"] == sc.compliance.scale].set_index("claim")
    claims = pd.read_csv(OUT / "claims.csv").set_index("id")
    assert own["verdict"].to_dict() == claims["verdict"].to_dict()
    comparisons = table[table["null_control"] != ""]
    assert set(comparisons["claim"]) == {
        "selfcal.identification",
        "selfcal.robot_params",
        "selfcal.residual",
        "selfcal.one_step",
    }
    assert (comparisons["null_control"] == "not reproduced").all()


def _conditions(calib, sc):
    """The conditions stated beside the verdicts, from the committed sweep trials."""
    basin = report.basin_table(_trials("basin"), sc.published.convergence_iterations)
    compliance = report_sweeps.sweep_verdicts(
        calib, _trials("compliance_sweep"), "compliance_scale", sc.compliance.scale, sc
    )
    arm = report_sweeps.sweep_verdicts(
        calib,
        _trials("arm_weight_sweep"),
        "arm_weight_fraction",
        sc.compliance.arm_weight_fraction,
        sc,
    )
    return report_sweeps.claim_conditions(sc, basin, compliance, arm)


def test_claims_and_controls(calib):
    sc = load_scenario()
    verdicts = report.selfcal_verdicts(calib, sc)
    rows = report.claim_rows(verdicts, sc, STEM, _conditions(calib, sc))
    claims = claims_table(rows)
    _compare(claims, "claims")
    controls = pd.DataFrame(report.controls_rows(verdicts), columns=list(CONTROL_COLUMNS))
    _compare(controls, "controls")


def test_every_null_control_fails(calib):
    verdicts = report.selfcal_verdicts(calib, load_scenario())
    for cid, (_, null, _) in verdicts.items():
        if null is not None:
            assert null.verdict == "not reproduced", cid


def test_arm_weight_sweep_covers_its_range(calib):
    """Every share of the arm's weight in the scenario's sweep has >= 30 trials and a verdict
    for each claim; the share's range in the ledger is covered end to end."""
    sc = load_scenario()
    key = "arm_weight_fraction"
    table = report_sweeps.sweep_verdicts(
        calib, _trials("arm_weight_sweep"), key, sc.compliance.arm_weight_fraction, sc
    )
    assert sorted(set(table[key])) == sorted(sc.compliance.arm_weight_sweep)
    assert min(table[key]) == 0.0 and max(table[key]) == 1.0
    assert (table.groupby(key)["claim"].nunique() == 5).all()
    assert (table["n"] >= 30).all()
