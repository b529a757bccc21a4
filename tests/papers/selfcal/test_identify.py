"""The selfcal identification: recovery, convergence, ML weights, three-step route, bad inputs."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.schema import with_inputs
from calstudy.papers.selfcal.routes import (
    hand_eye,
    three_step,
    three_step_alternated,
    three_step_reordered,
    two_step,
)
from calstudy.papers.selfcal.simulate import draw_station, poor_start, scan_cap, simulate
from calstudy.selfcal.identify import (
    Measurements,
    check_sphere_layout,
    covariance,
    fit_sphere_cap,
    identify,
)
from calstudy.selfcal.model import (
    GlobalModel,
    angle_wrap,
    parameters_from_robot,
    scaled_error,
)


def test_noise_free_identification_recovers_the_truth(noise_free):
    station, meas, val = noise_free
    assert len(meas) == 24
    fit = identify(meas, station.nominal_params)
    # all 30 are identifiable here (rank 30, test below), so the whole vector is recovered
    error = angle_wrap(fit.params - station.true_params)
    assert np.abs(error).max() < 1e-8
    residual = GlobalModel().points(fit.params, val.Q, val.C) - val.P_ref
    assert np.linalg.norm(residual, axis=1).max() < 1e-6
    assert fit.mean_error_mm[0] > 1.0 and fit.mean_error_mm[-1] < 1e-8


def test_very_poor_start_converges_to_the_same_solution(scenario, noise_free):
    station, meas, _ = noise_free
    start = poor_start(scenario, station, np.random.default_rng(6))
    assert scaled_error(start, station.true_params) > 50.0
    fit = identify(meas, start)
    assert np.abs(angle_wrap(fit.params - station.true_params)).max() < 1e-8
    assert fit.iterations_to() <= 6


def test_weighted_identification_is_unbiased_with_noise(scenario):
    scenario = with_inputs(scenario, {"compliance.scale": 0.0})  # noise only: model exact
    rng = np.random.default_rng(7)
    station = draw_station(scenario, rng)
    meas = simulate(scenario, station, station.spheres_base, 6, rng)
    ml = identify(meas, station.nominal_params, weighted=True)
    z = angle_wrap(ml.params - station.true_params) / ml.estimate.std
    assert 0.5 < np.sqrt(np.mean(z**2)) < 1.5  # errors of the size of the stated std


def test_three_step_is_exact_for_a_nominal_robot(quiet):
    """With no manufacturing error and no noise nothing propagates: three steps are exact."""
    rng = np.random.default_rng(8)
    station = draw_station(quiet, rng)
    exact = parameters_from_robot(quiet.nominal_robot, station.part2base, station.sensor2flange)
    station = replace(station, true_params=exact)
    meas = simulate(quiet, station, station.spheres_base, 6, rng)
    for route in (three_step, three_step_reordered, two_step):
        params = route(meas, quiet.nominal_robot, station.nominal_params)
        points = GlobalModel().points(params, meas.Q, meas.C)
        assert np.linalg.norm(points - meas.P_ref, axis=1).max() < 1e-6, route.__name__


def test_measurement_covariance_matches_monte_carlo(scenario):
    """Residuals at the truth scatter as :func:`covariance` says, the shared tracker error included.

    A tracker made noisy enough to dominate shows the correlation between two views of a sphere.
    """
    # the covariance describes the noise; the unmodelled compliance is switched off here
    noisy_tracker = with_inputs(
        scenario, {"tracker.u0_mm": 0.5, "tracker.u1_mm_per_m": 0.0, "compliance.scale": 0.0}
    )
    rng = np.random.default_rng(14)
    station = draw_station(noisy_tracker, rng)
    model = GlobalModel()
    residuals, predicted = [], []
    for _ in range(100):
        meas = simulate(noisy_tracker, station, station.spheres_base[:1], 2, rng)
        points = model.points(station.true_params, meas.Q, meas.C)
        residuals.append((points - meas.P_ref).ravel())
        predicted.append(covariance(meas))
    r = np.array(residuals)
    assert np.mean(predicted, axis=0)[0, 3] > 0.02  # views 1 and 2 share the tracker's x error
    np.testing.assert_allclose(r.T @ r / len(r), np.mean(predicted, axis=0), atol=0.008)


def test_too_few_measurements_raise(noise_free):
    station, meas, _ = noise_free
    few = Measurements(*(getattr(meas, f.name)[:9] for f in fields(meas)))
    with pytest.raises(CalibrationError, match="9 sphere-centre measurements give 27 equations"):
        identify(few, station.nominal_params)


def test_non_finite_measurements_raise(noise_free):
    station, meas, _ = noise_free
    C = meas.C.copy()
    C[3, 1] = np.nan
    with pytest.raises(CalibrationError, match=r"measurements C holds a non-finite value"):
        identify(replace(meas, C=C), station.nominal_params)


def test_collinear_spheres_raise():
    line = np.outer(np.arange(4), [300.0, 200.0, 100.0]) + [1000.0, 0.0, 0.0]
    with pytest.raises(CalibrationError, match="collinear"):
        check_sphere_layout(line, 25.0)


def test_coincident_spheres_raise():
    centres = np.array([[0, 0, 0], [500, 0, 0], [0, 500, 0], [10, 10, 0]], float)
    with pytest.raises(CalibrationError, match="spheres 0 and 3 coincide"):
        check_sphere_layout(centres, 25.0)


def test_sphere_fit_needs_four_points(scenario):
    with pytest.raises(CalibrationError, match="at least 4"):
        fit_sphere_cap(np.eye(3), scenario.scanner.max_fit_condition)


def test_sphere_fit_rejects_coplanar_points(scenario):
    rng = np.random.default_rng(10)
    flat = np.column_stack([rng.uniform(-5, 5, (50, 2)), np.zeros(50)])
    with pytest.raises(CalibrationError, match="coplanar"):
        fit_sphere_cap(flat, scenario.scanner.max_fit_condition)


def test_small_cap_raises_with_condition_number(scenario):
    rng = np.random.default_rng(11)
    cap = scan_cap([0, 0, 300.0], 25.0, math.radians(5), 400, 0.02, rng)
    with pytest.raises(CalibrationError, match=r"too small to fix the radius: condition number \d"):
        fit_sphere_cap(cap, scenario.scanner.max_fit_condition)
    wide = scan_cap([0, 0, 300.0], 25.0, math.radians(60), 400, 0.02, rng)
    centre, radius, cond = fit_sphere_cap(wide, scenario.scanner.max_fit_condition)
    assert cond < 5 and abs(radius - 25.0) < 0.05


def test_lm_that_does_not_converge_raises(scenario, noise_free):
    station, meas, _ = noise_free
    start = poor_start(scenario, station, np.random.default_rng(12))
    with pytest.raises(CalibrationError, match=r"did not converge after \d+ iterations \(cost"):
        identify(meas, start, max_evaluations=2)


def test_ml_weights_need_noise(noise_free):
    station, meas, _ = noise_free
    with pytest.raises(CalibrationError, match="not positive definite"):
        identify(meas, station.nominal_params, weighted=True)


def test_routes_given_the_hand_eye_fit_are_the_routes_that_fit_it(scenario):
    """Handing the three-step routes one shared hand-eye fit changes none of their results."""
    rng = np.random.default_rng(8)
    station = draw_station(scenario, rng)
    meas = simulate(scenario, station, station.spheres_base, 6, rng)
    start, robot = station.nominal_params, scenario.nominal_robot
    first = hand_eye(meas, robot, start)
    assert three_step(meas, robot, start, first=first).tobytes() == (
        three_step(meas, robot, start).tobytes()
    )
    assert three_step_reordered(meas, robot, start, first=first).tobytes() == (
        three_step_reordered(meas, robot, start).tobytes()
    )
    shared, rounds = three_step_alternated(meas, robot, start, max_rounds=3, first=first)
    alone, rounds_alone = three_step_alternated(meas, robot, start, max_rounds=3)
    assert (shared.tobytes(), rounds) == (alone.tobytes(), rounds_alone)
    # a different first step does change the route: the argument is used
    moved = (first[0] + 1e-3, first[1])
    assert not np.array_equal(
        three_step(meas, robot, start, first=moved), three_step(meas, robot, start)
    )
