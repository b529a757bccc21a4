"""The selfcal global model, its identification, identifiability and bad inputs."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.geometry import make_transform, random_rotation
from calstudy.estimators.fitting import fit_sphere
from calstudy.models.kinematics import Link, perturb_robot
from calstudy.papers.selfcal import selfcal as sc


@pytest.fixture(scope="module")
def scenario():
    return sc.load_scenario()


@pytest.fixture(scope="module")
def quiet(scenario):
    """The scenario without any noise: scanner, repeatability and tracker exact."""
    return scenario.with_(sigma_point_mm=0.0, repeatability_mm=0.0, tracker=(0.0, 0.0, 2.0))


def random_pose(rng, scale_mm=500.0):
    return make_transform(random_rotation(rng), rng.uniform(-scale_mm, scale_mm, 3))


# ----------------------------------------------------------------------------------------------
# the model


def test_hayati_link_is_eq2():
    rng = np.random.default_rng(0)
    a, alpha, theta, beta, q = 870.0, *rng.uniform(-0.5, 0.5, 4)
    t = theta + q
    ct, st, ca, sa, cb, sb = (
        math.cos(t),
        math.sin(t),
        math.cos(alpha),
        math.sin(alpha),
        math.cos(beta),
        math.sin(beta),
    )
    eq2 = np.array(
        [
            [ct * cb - st * sa * sb, -st * ca, ct * sb + st * sa * cb, a * ct],
            [st * cb + ct * sa * sb, ct * ca, st * sb - ct * sa * cb, a * st],
            [-ca * sb, sa, ca * cb, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    link = Link("dh", a=a, alpha=alpha, d=0.0, theta=theta, beta=beta, parallel=True)
    np.testing.assert_allclose(link.transform(q), eq2, atol=1e-12)


def test_global_model_reproduces_the_dh_chain(scenario):
    rng = np.random.default_rng(1)
    robot = perturb_robot(scenario.robot, rng)
    vec = robot.parameters()
    vec[7] = 0.0  # d2: Eq. 2 has none
    robot = robot.with_parameters(vec)
    part2base, sensor2flange = random_pose(rng, 3000.0), random_pose(rng, 200.0)
    params = sc.parameters_from_robot(robot, part2base, sensor2flange)
    assert params.shape == (30,)
    Q = robot.random_configurations(rng, 20)
    expected = part2base @ robot.fk_many(Q) @ sensor2flange
    np.testing.assert_allclose(sc.GlobalModel().sensor2part(params, Q), expected, atol=1e-9)


def test_joint6_turns_about_the_z_axis_of_frame5(scenario):
    """Our reading of 5HS: turning joint 6 rotates the sensor about the joint-6 axis (frame 5 z)."""
    rng = np.random.default_rng(2)
    params = sc.parameters_from_robot(scenario.robot, np.eye(4), random_pose(rng, 200.0))
    q = scenario.robot.random_configurations(rng, 1)
    q2 = q.copy()
    q2[0, 5] += 0.7
    model = sc.GlobalModel()
    a, b = model.sensor2part(params, np.vstack([q, q2]))
    frame5 = scenario.robot.fk(q[0]) @ np.linalg.inv(scenario.robot.links[5].split()[1])
    relative = np.linalg.inv(frame5) @ b @ np.linalg.inv(a) @ frame5
    expected = make_transform(
        np.array(
            [[math.cos(0.7), -math.sin(0.7), 0], [math.sin(0.7), math.cos(0.7), 0], [0, 0, 1]]
        ),
        np.zeros(3),
    )
    np.testing.assert_allclose(relative, expected, atol=1e-9)


def test_jacobian_matches_finite_differences(scenario):
    rng = np.random.default_rng(3)
    params = sc.parameters_from_robot(scenario.robot, random_pose(rng), random_pose(rng, 200.0))
    Q = scenario.robot.random_configurations(rng, 4)
    C = rng.normal(0.0, 100.0, (4, 3))
    model = sc.GlobalModel()
    points, jac = model.points_and_jacobian(params, Q, C)
    np.testing.assert_allclose(points, model.points(params, Q, C), atol=1e-9)
    h = 1e-6
    numeric = np.column_stack(
        [
            (model.points(params + h * e, Q, C) - model.points(params - h * e, Q, C)).ravel()
            / (2 * h)
            for e in np.eye(30)
        ]
    )
    np.testing.assert_allclose(jac, numeric, rtol=1e-6, atol=1e-4)


def test_pose_parameters_round_trip():
    rng = np.random.default_rng(4)
    pose = random_pose(rng)
    np.testing.assert_allclose(sc.params_to_pose(sc.pose_to_params(pose)), pose, atol=1e-12)


@pytest.mark.parametrize(
    ("index", "value", "match"),
    [(7, 2.0, "link 2 of Eq. 2 has no offset d"), (14, 0.01, "beta is only modelled on link 2")],
)
def test_tables_outside_the_model_raise(scenario, index, value, match):
    vec = scenario.robot.parameters()
    vec[index] = value
    with pytest.raises(CalibrationError, match=match):
        sc.parameters_from_robot(scenario.robot.with_parameters(vec), np.eye(4), np.eye(4))


# ----------------------------------------------------------------------------------------------
# identification


@pytest.fixture(scope="module")
def noise_free(quiet):
    rng = np.random.default_rng(5)
    station = sc.draw_station(quiet, rng)
    meas = sc.simulate(quiet, station, station.spheres_base, 6, rng)
    val = sc.simulate(quiet, station, sc.draw_placements(quiet, 10, rng), 1, rng)
    return station, meas, val


def test_noise_free_identification_recovers_the_truth(noise_free):
    station, meas, val = noise_free
    assert len(meas) == 24
    fit = sc.identify(meas, station.nominal_params)
    # all 30 are identifiable here (rank 30, test below), so the whole vector is recovered
    error = sc._angle_wrap(fit.params - station.true_params)
    assert np.abs(error).max() < 1e-8
    residual = sc.GlobalModel().points(fit.params, val.Q, val.C) - val.P_ref
    assert np.linalg.norm(residual, axis=1).max() < 1e-6
    assert fit.mean_error_mm[0] > 1.0 and fit.mean_error_mm[-1] < 1e-8


def test_very_poor_start_converges_to_the_same_solution(scenario, noise_free):
    station, meas, _ = noise_free
    start = sc.poor_start(scenario, station, np.random.default_rng(6))
    assert sc._scaled_error(start, station.true_params) > 50.0
    fit = sc.identify(meas, start)
    assert np.abs(sc._angle_wrap(fit.params - station.true_params)).max() < 1e-8
    assert fit.iterations_to() <= 6


def test_weighted_identification_is_unbiased_with_noise(scenario):
    rng = np.random.default_rng(7)
    station = sc.draw_station(scenario, rng)
    meas = sc.simulate(scenario, station, station.spheres_base, 6, rng)
    ml = sc.identify(meas, station.nominal_params, weighted=True)
    z = sc._angle_wrap(ml.params - station.true_params) / ml.estimate.std
    assert 0.5 < np.sqrt(np.mean(z**2)) < 1.5  # errors of the size of the stated std


def test_three_step_is_exact_for_a_nominal_robot(quiet):
    """With no manufacturing error and no noise nothing propagates: three steps are exact."""
    rng = np.random.default_rng(8)
    station = sc.draw_station(quiet, rng)
    exact = sc.parameters_from_robot(quiet.robot, station.part2base, station.sensor2flange)
    station = replace(station, true_params=exact)
    meas = sc.simulate(quiet, station, station.spheres_base, 6, rng)
    params = sc.three_step(meas, quiet.robot, station.nominal_params)
    points = sc.GlobalModel().points(params, meas.Q, meas.C)
    assert np.linalg.norm(points - meas.P_ref, axis=1).max() < 1e-6


def test_identifiability_scanner_full_rank_one_point_rank_27(scenario, noise_free):
    station, meas, _ = noise_free
    out = sc.identifiability_designs(scenario, meas, station.true_params)
    summary = out["summary"].set_index("design")
    ranks = summary["rank"].tolist()
    assert ranks == [30, 27]
    null = set(summary["null_space_parameters"].iloc[1].split())
    assert null <= set(sc.SENSOR_NAMES) and {"gamma1", "phi1", "eps1"} <= null
    params = out["parameters"]
    one_point = params[params["design"] == "one sensor point"]
    assert set(one_point.loc[~one_point["identifiable"], "name"]) == set(sc.SENSOR_NAMES)


def test_cap_covariance_matches_monte_carlo():
    rng = np.random.default_rng(9)
    centre = np.array([20.0, -10.0, 300.0])
    fits = np.array(
        [
            fit_sphere(sc.scan_cap(centre, 25.0, math.radians(60), 400, 0.05, rng))[0]
            for _ in range(400)
        ]
    )
    empirical = np.cov(fits.T)
    predicted = sc.cap_centre_covariance(centre, 25.0, math.radians(60), 400, 0.05)
    np.testing.assert_allclose(np.diag(empirical), np.diag(predicted), rtol=0.3)


def test_measurement_covariance_matches_monte_carlo(scenario):
    """Residuals at the truth scatter as :func:`covariance` says, the shared tracker error included.

    A tracker made noisy enough to dominate shows the correlation between two views of a sphere.
    """
    noisy_tracker = scenario.with_(tracker=(0.5, 0.0, 2.0))
    rng = np.random.default_rng(14)
    station = sc.draw_station(noisy_tracker, rng)
    model = sc.GlobalModel()
    residuals, predicted = [], []
    for _ in range(100):
        meas = sc.simulate(noisy_tracker, station, station.spheres_base[:1], 2, rng)
        points = model.points(station.true_params, meas.Q, meas.C)
        residuals.append((points - meas.P_ref).ravel())
        predicted.append(sc.covariance(meas))
    r = np.array(residuals)
    assert np.mean(predicted, axis=0)[0, 3] > 0.02  # views 1 and 2 share the tracker's x error
    np.testing.assert_allclose(r.T @ r / len(r), np.mean(predicted, axis=0), atol=0.008)


def test_trial_is_deterministic(scenario):
    a = sc.run_trial(scenario, 3, 1)
    b = sc.run_trial(scenario, 3, 1)
    assert a["methods"] == b["methods"] and a["history"] == b["history"]


# ----------------------------------------------------------------------------------------------
# bad input


def test_too_few_measurements_raise(noise_free):
    station, meas, _ = noise_free
    few = sc.Measurements(*(getattr(meas, f.name)[:9] for f in fields(meas)))
    with pytest.raises(CalibrationError, match="9 sphere-centre measurements give 27 equations"):
        sc.identify(few, station.nominal_params)


def test_non_finite_measurements_raise(noise_free):
    station, meas, _ = noise_free
    C = meas.C.copy()
    C[3, 1] = np.nan
    with pytest.raises(CalibrationError, match=r"measurements C holds a non-finite value"):
        sc.identify(replace(meas, C=C), station.nominal_params)


def test_collinear_spheres_raise():
    line = np.outer(np.arange(4), [300.0, 200.0, 100.0]) + [1000.0, 0.0, 0.0]
    with pytest.raises(CalibrationError, match="collinear"):
        sc.check_sphere_layout(line, 25.0)


def test_coincident_spheres_raise():
    centres = np.array([[0, 0, 0], [500, 0, 0], [0, 500, 0], [10, 10, 0]], float)
    with pytest.raises(CalibrationError, match="spheres 0 and 3 coincide"):
        sc.check_sphere_layout(centres, 25.0)


def test_sphere_fit_needs_four_points():
    with pytest.raises(CalibrationError, match="at least 4"):
        sc.fit_sphere_cap(np.eye(3))


def test_sphere_fit_rejects_coplanar_points():
    rng = np.random.default_rng(10)
    flat = np.column_stack([rng.uniform(-5, 5, (50, 2)), np.zeros(50)])
    with pytest.raises(CalibrationError, match="coplanar"):
        sc.fit_sphere_cap(flat)


def test_small_cap_raises_with_condition_number():
    rng = np.random.default_rng(11)
    cap = sc.scan_cap([0, 0, 300.0], 25.0, math.radians(5), 400, 0.02, rng)
    with pytest.raises(CalibrationError, match=r"too small to fix the radius: condition number \d"):
        sc.fit_sphere_cap(cap)
    wide = sc.scan_cap([0, 0, 300.0], 25.0, math.radians(60), 400, 0.02, rng)
    centre, radius, cond = sc.fit_sphere_cap(wide)
    assert cond < 5 and abs(radius - 25.0) < 0.05


def test_lm_that_does_not_converge_raises(scenario, noise_free):
    station, meas, _ = noise_free
    start = sc.poor_start(scenario, station, np.random.default_rng(12))
    with pytest.raises(CalibrationError, match=r"did not converge after \d+ iterations \(cost"):
        sc.identify(meas, start, max_evaluations=2)


def test_monte_carlo_needs_two_trials(scenario):
    with pytest.raises(CalibrationError, match="at least 2 trials"):
        sc.monte_carlo(scenario, 1, 1)


def test_ml_weights_need_noise(noise_free):
    station, meas, _ = noise_free
    with pytest.raises(CalibrationError, match="not positive definite"):
        sc.identify(meas, station.nominal_params, weighted=True)
