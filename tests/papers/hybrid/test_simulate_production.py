"""Panels measured on the simulated station and the CMM: exact without robot error and noise,
a repeatable millimetre deviation with it, and the paper's layout."""

import dataclasses

import numpy as np
from support import ideal_station

from calstudy.core.schema import with_inputs
from calstudy.papers.hybrid import (
    compensation,
    experiments,
    scenario,
    simulate_production,
)


def _noise_free(robot_errors: bool):
    # notebook 01's noise-free station: no sensor, pixel or robot noise, a perfectly made target
    s, rng = ideal_station(seed=8, robot_errors=robot_errors)
    s = dataclasses.replace(s, datum_sigma=0.0)
    zero = ("production.sensors.feature_sigma_mm", "station.robot.repeatability_mm")
    zero += ("production.drift.sigma_mm", "production.cmm.sigma_mm")
    sc = with_inputs(scenario.load_scenario(), dict.fromkeys(zero, 0.0))
    return experiments.calibrate(s, rng), sc, rng


def test_systematic_error_disappears_when_true_and_nominal_robots_coincide():
    ps, sc, rng = _noise_free(robot_errors=False)
    hybrid, cmm = simulate_production.simulate_products(ps, sc, 5, rng)
    assert np.abs(hybrid - cmm).max() < 1e-5


def test_robot_model_error_gives_a_repeatable_millimetre_deviation():
    ps, sc, rng = _noise_free(robot_errors=True)
    hybrid, cmm = simulate_production.simulate_products(ps, sc, 5, rng)
    d = hybrid - cmm
    assert np.median(np.linalg.norm(d.mean(axis=0), axis=1)) > 0.5
    # repeatable: without noise, the panels differ only by their variation and clamping
    assert np.abs(d - d.mean(axis=0)).max() < 0.02 * np.abs(d).max()


def test_simulated_run_has_the_paper_layout_and_frame_fixed_coordinates():
    rng = np.random.default_rng(9)
    ps = experiments.calibrated_station(rng)
    sc = scenario.load_scenario()
    run = simulate_production.simulate_run(ps, sc, rng)
    assert run["compensation"][0].shape == (sc.production.protocol.n_compensation_max, 58, 3)
    assert run["follow-up"][1].shape == (sc.production.protocol.n_follow_up, 58, 3)
    h = np.concatenate([run[p][0] for p in scenario.PHASES])
    c = np.concatenate([run[p][1] for p in scenario.PHASES])
    np.testing.assert_array_equal(compensation.frame_fixed(h, c), ps.features.fixed)
    # each program pose puts its feature near the middle of the sensor's field
    p = simulate_production.sensor_pose_check(ps)
    assert np.abs(p[:, :2]).max() < 20.0 and np.abs(p[:, 2] - 250.0).max() < 20.0


def test_the_taught_program_follows_the_stand_off():
    # the program is kept by what its inverse kinematics reads: a station with another stand-off
    # gets its own program, whatever stations the process taught before (a trial's rows must not
    # depend on which trials its worker ran first)
    s, _ = ideal_station(seed=8)
    features = scenario.panel_features(scenario.load_production(), s.config)
    taught = simulate_production.teach_program(s, features)
    moved = dataclasses.replace(s, standoff=s.standoff - 20.0)
    q = simulate_production.teach_program(moved, features)
    assert np.abs(q - taught).max() > 1e-3
    simulate_production._PROGRAM_CACHE.clear()  # and a fresh station: no IK memo either
    fresh = simulate_production.teach_program(dataclasses.replace(moved), features)
    np.testing.assert_array_equal(fresh, q)
    assert not fresh.flags.writeable
    # every taught sensor pose moves 20 mm (along its axis, to stay 20 mm nearer the part)
    sensor = np.array([s.nominal.fk(qi) @ s.sensor2flange_true for qi in taught])
    sensor_moved = np.array([s.nominal.fk(qi) @ s.sensor2flange_true for qi in q])
    gap = np.linalg.norm(sensor[:, :3, 3] - sensor_moved[:, :3, 3], axis=1)
    np.testing.assert_allclose(gap, 20.0, atol=1e-6)
