"""The selfcal experiments: identifiability designs, trials and the Monte Carlo loop."""

from __future__ import annotations

import pytest

from calstudy import CalibrationError
from calstudy.papers.selfcal.experiments import identifiability_designs, monte_carlo, run_trial
from calstudy.papers.selfcal.model import SENSOR_NAMES


def test_identifiability_scanner_full_rank_one_point_rank_27(scenario, noise_free):
    station, meas, _ = noise_free
    out = identifiability_designs(scenario, meas, station.true_params)
    summary = out["summary"].set_index("design")
    ranks = summary["rank"].tolist()
    assert ranks == [30, 27]
    null = set(summary["null_space_parameters"].iloc[1].split())
    assert null <= set(SENSOR_NAMES) and {"gamma1", "phi1", "eps1"} <= null
    params = out["parameters"]
    one_point = params[params["design"] == "one sensor point"]
    assert set(one_point.loc[~one_point["identifiable"], "name"]) == set(SENSOR_NAMES)


def test_trial_is_deterministic(scenario):
    a = run_trial(scenario, 3, 1)
    b = run_trial(scenario, 3, 1)
    assert a["methods"] == b["methods"] and a["history"] == b["history"]


def test_monte_carlo_needs_two_trials(scenario):
    with pytest.raises(CalibrationError, match="at least 2 trials"):
        monte_carlo(scenario, 1, 1)
