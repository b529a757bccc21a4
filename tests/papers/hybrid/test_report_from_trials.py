"""Every table and verdict of notebooks 01 and 02 recomputed from the committed trial rows
(``results/<nb>/trials_*.csv``) with the report functions, against the committed files: numbers
to rtol 2e-5, text exactly. No simulation, so it runs in seconds.

The single-station tables of notebook 02 (the Lilliefors table, the measurements, Fig. 6 and the
station's Table 1) come from the run of trial 0, simulated again from its generator, not from
trial rows: ``tests/test_trials.py`` recomputes trials, this file only the reports."""


import pandas as pd
import pytest
from support import assert_same_table

from calstudy.claims import CONTROL_COLUMNS
from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import claims_table
from calstudy.papers.hybrid import report, report_sweeps
from calstudy.papers.hybrid.scenario import load_scenario

NB01 = RESULTS_DIR / "01_hybrid_global_calibration"
NB02 = RESULTS_DIR / "02_hybrid_production_compensation"


def _trials(folder, name):
    return pd.read_csv(folder / f"trials_{name}.csv", keep_default_na=False, na_values=[""])


def _compare(fresh: pd.DataFrame, path) -> None:
    assert_same_table(fresh, path)

def _claims_frame(rows):
    return claims_table(rows)


@pytest.mark.skipif(not (NB01 / "trials_handeye.csv").is_file(), reason="no committed trials")
def test_notebook01_tables_and_verdicts_from_trials():
    handeye = _trials(NB01, "handeye")
    stationary = _trials(NB01, "stationary")
    he_summary = report.summarise_errors(handeye, ["scenario", "method"])
    _compare(he_summary, NB01 / "handeye_summary.csv")
    _compare(report.handeye_figures(handeye), NB01 / "handeye_crb_ratios.csv")
    noise = _trials(NB01, "handeye_noise")
    _compare(
        report.summarise_errors(noise, ["sigma_point_mm", "method"]),
        NB01 / "handeye_noise_sweep.csv",
    )
    moves = _trials(NB01, "handeye_moves")
    _compare(report.summarise_errors(moves, ["n_rot", "method"]), NB01 / "handeye_moves_sweep.csv")
    errors = stationary[stationary["step"] == "stationary"]
    st_summary = report.summarise_errors(errors, ["scenario", "variant"])
    _compare(st_summary, NB01 / "stationary_summary.csv")
    _compare(
        report.summarise_rps(stationary[stationary["step"] == "rps"]), NB01 / "rps_summary.csv"
    )
    _compare(
        report.summarise_penalty_sweep(_trials(NB01, "rps_penalty")), NB01 / "rps_penalty_sweep.csv"
    )
    _compare(report.nominal_model_cost(he_summary, st_summary), NB01 / "nominal_model_cost.csv")
    _compare(
        report_sweeps.summarise_ranges(_trials(NB01, "handeye_ranges")),
        NB01 / "handeye_ranges_sweep.csv",
    )
    _compare(
        report_sweeps.summarise_handeye_sweep(noise, ["sigma_point_mm"]),
        NB01 / "handeye_noise_verdicts.csv",
    )
    _compare(
        report_sweeps.summarise_handeye_sweep(moves, ["n_rot"]), NB01 / "handeye_moves_verdicts.csv"
    )
    _compare(
        report_sweeps.summarise_stationary_sweep(_trials(NB01, "stationary_pixel"), "pixel_sigma"),
        NB01 / "stationary_pixel_sweep.csv",
    )
    claims, controls = report.calibration_claims(handeye, stationary, NB01.name)
    _compare(_claims_frame(claims), NB01 / "claims.csv")
    _compare(pd.DataFrame(controls)[list(CONTROL_COLUMNS)], NB01 / "controls.csv")


@pytest.mark.skipif(not (NB02 / "trials_production.csv").is_file(), reason="no committed trials")
def test_notebook02_tables_and_verdicts_from_trials():
    n = load_scenario().production.protocol.n_compensation
    production = _trials(NB02, "production")
    _compare(report.summarise_systematic(production, n), NB02 / "systematic_summary.csv")
    deviation, correlation = report.table1(production, n)
    _compare(deviation, NB02 / "table1_deviation.csv")
    _compare(correlation, NB02 / "table1_correlation.csv")
    _compare(report.headline_summary(production), NB02 / "compensation_n_sweep.csv")
    _compare(report.summarise_sweep(_trials(NB02, "sensitivity")), NB02 / "sensitivity.csv")
    _compare(
        report.summarise_robot_error_sweep(_trials(NB02, "robot_error")),
        NB02 / "robot_error_sweep.csv",
    )
    _compare(
        report_sweeps.deviation_distribution(production, n), NB02 / "deviation_distribution.csv"
    )
    _compare(report_sweeps.summarise_drift(_trials(NB02, "sensitivity")), NB02 / "drift_sweep.csv")
    claims, controls = report.production_claims(production, n, NB02.name)
    _compare(_claims_frame(claims), NB02 / "claims.csv")
    _compare(pd.DataFrame(controls)[list(CONTROL_COLUMNS)], NB02 / "controls.csv")
