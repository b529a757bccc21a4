"""The selfcal experiments: identifiability designs, trials, routes and factories."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy.core.montecarlo import trial_rng, trial_rows
from calstudy.papers.selfcal.experiments import (
    METHODS,
    ORACLE,
    TRUTH,
    basin_trial,
    calibration_experiment,
    calibration_trial,
    identifiability_designs,
    scenario_key,
)
from calstudy.papers.selfcal.routes import three_step_alternated, two_step
from calstudy.selfcal.model import SENSOR_NAMES, scaled_error


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


def test_trial_is_deterministic_and_has_every_method(scenario):
    a = calibration_trial(scenario, trial_rng(3, "calibration", {}, 1))
    b = calibration_trial(scenario, trial_rng(3, "calibration", {}, 1))
    assert [r["method"] for r in a] == list(METHODS)
    assert a == b


def test_oracle_is_the_truth_without_compliance(scenario):
    rows = calibration_trial(scenario, trial_rng(3, "calibration", {}, 2), compliance_scale=0.0)
    by = {r["method"]: r for r in rows}
    # noise-free identification of a cell in the model class recovers the true geometry
    assert by[ORACLE]["model_rms_mm"] < 1e-6
    assert by[TRUTH]["model_rms_mm"] < 1e-9
    assert by[ORACLE]["robot_param_error"] < 1e-6


def test_compliance_leaves_an_error_the_truth_cannot_remove(scenario):
    rows = calibration_trial(scenario, trial_rng(3, "calibration", {}, 2), compliance_scale=2.0)
    by = {r["method"]: r for r in rows}
    assert by[TRUTH]["model_rms_mm"] > 0.1  # the deflection under the payload, mm
    assert by[ORACLE]["model_rms_mm"] < by[TRUTH]["model_rms_mm"]  # partly absorbed


def test_alternation_moves_towards_the_two_step_solution(quiet, noise_free):
    station, meas, _ = noise_free
    robot = quiet.nominal_robot
    joint = two_step(meas, robot, station.nominal_params)
    one, _ = three_step_alternated(meas, robot, station.nominal_params, max_rounds=1)
    five, rounds = three_step_alternated(meas, robot, station.nominal_params, max_rounds=5)
    assert rounds == 5
    assert scaled_error(five, joint) < scaled_error(one, joint)
    # without noise or compliance the joint fit recovers the truth
    assert scaled_error(joint, station.true_params) < 1e-3


def test_basin_far_start_can_fail(scenario):
    out = [
        basin_trial(scenario, trial_rng(1, "basin", {"start_scale": 8.0}, t), 8.0) for t in (0, 2)
    ]
    assert not all(o["same_solution"] and o["iterations"] <= 4 for o in out)


def test_factory_rebuilds_the_same_rows():
    exp = calibration_experiment(n_trials=2)
    assert exp.scenario_key == scenario_key("")
    a = trial_rows(exp, 1, 0, 1)
    b = trial_rows(calibration_experiment(n_trials=2), 1, 0, 1)
    num = a.select_dtypes("number").to_numpy(float)
    np.testing.assert_array_equal(num, b.select_dtypes("number").to_numpy(float))


@pytest.mark.parametrize("scale", [0.0, 1.0])
def test_payload_deflection_is_zero_only_when_switched_off(scenario, scale):
    from calstudy.papers.selfcal.simulate import joint_deflection

    q = np.array([[0.2, 0.3, -0.1, 0.0, -0.8, 0.0]])
    d = joint_deflection(scenario, scenario.nominal_robot, q, scale)
    assert (np.abs(d).max() > 1e-5) == (scale > 0)
