"""The experiments: exact recovery on a noise-free station, what the nominal model costs, the
Cramer-Rao bound, determinism, the user's CSV, and the sweep of the robot's errors."""

import dataclasses

import numpy as np
import pandas as pd
import pytest
from support import ideal_station

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.core import montecarlo
from calstudy.handeye import sphere_csv
from calstudy.papers.hybrid import experiments, handeye_experiments, scenario, simulate


def test_noise_free_station_recovers_everything_exactly():
    s, rng = ideal_station()
    meas, _ = simulate.simulate_sphere_measurements(s, 4, 6, rng)
    s2f = he.sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    assert geo.rotation_error(s2f, s.sensor2flange_true) < 1e-9
    assert geo.translation_error(s2f, s.sensor2flange_true) < 1e-7
    rows = experiments.stationary_trial(s, s2f, rng)
    calibrations = [r for r in rows if r["variant"] != "design pose"]
    worst_rot = max(r["rotation_error_deg"] for r in calibrations)
    worst_trans = max(r["translation_error_mm"] for r in calibrations)
    assert worst_rot < 1e-6 and worst_trans < 1e-6
    # the sensors sit off their design pose by the mounting error, which only a calibration finds
    design = [r["field_error_mm"] for r in rows if r["variant"] == "design pose"]
    assert len(design) == 10 and min(design) > 0.05
    calibrated = np.array([r["estimate"] for r in rows if r["variant"] == "homography"])
    s = dataclasses.replace(s, datum_sigma=0.0)
    for r in experiments.rps_trial(s, calibrated, rng, penalties=(1.0, 1e4)):
        assert r["frame_error_mm"] < 1e-6


def test_systematic_error_disappears_when_true_and_nominal_robots_coincide():
    """Noise-free, the whole chain is exact with a perfect robot and mm-wrong with a real one."""
    errors = {}
    for robot_errors in (False, True):
        s, rng = ideal_station(seed=3, robot_errors=robot_errors)
        meas, _ = simulate.simulate_sphere_measurements(s, 4, 6, rng)
        s2f = he.sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
        rows = experiments.stationary_trial(s, s2f, rng)
        errors[robot_errors] = max(r["field_error_mm"] for r in rows if r["variant"] == "pnp")
    assert errors[False] < 1e-6
    assert errors[True] > 0.1


def test_trials_are_deterministic_per_seed_and_reject_unknown_scenarios():
    exp = handeye_experiments.handeye_noise_experiment([0.02], n_trials=2)
    a = montecarlo.run(exp, 2, n_jobs=1, progress=False)
    b = montecarlo.run(exp, 2, n_jobs=1, progress=False)
    c = montecarlo.run(exp, 3, n_jobs=1, progress=False)
    assert a.equals(b)
    assert not a.equals(c)
    with pytest.raises(CalibrationError, match="unknown scenario 'lab'"):
        handeye_experiments.handeye_run(
            {"n_trans": 4, "n_rot": 6, "baselines": False}, rng(1), "lab"
        )


def rng(seed):
    return np.random.default_rng(seed)


def test_calibrate_from_user_csv(tmp_path):
    s, rng = ideal_station(seed=4)
    meas, _ = simulate.simulate_sphere_measurements(s, 4, 6, rng)
    path = tmp_path / "mine.csv"
    sphere_csv.write_sphere_measurements(meas, path)
    source, _, paper, ml, table = handeye_experiments.sphere_station_calibration(
        str(path), 0, [0.01, 0.02, 0.01]
    )
    assert source.startswith(f"user measurements from {path}")
    assert "truth" not in table
    assert geo.translation_error(paper.value, s.sensor2flange_true) < 1e-6
    assert geo.translation_error(ml.value, s.sensor2flange_true) < 1e-6


def test_robot_error_sweep_scales_the_systematic_error_of_the_same_stations():
    sc = scenario.load_scenario()
    setup = {"scenario": sc, "scales": [0.0, 1.0, 2.0]}
    sweep = pd.DataFrame(experiments.robot_error_run(setup, rng(5)))
    assert sweep["robot_error_scale"].tolist() == [0.0, 1.0, 2.0]
    # the same station, its robot errors scaled: the systematic error grows with the factor
    # and the raw share within +-0.3 mm falls; the compensated share hardly moves
    assert (np.diff(sweep["systematic_median_mm"]) > 0).all()
    assert (np.diff(sweep["systematic_coord_median_mm"]) > 0).all()
    assert (np.diff(sweep["within_0p3_uncompensated"]) < 0).all()
    assert np.ptp(sweep["within_0p3"]) <= 2.0


def test_move_ranges_bound_the_pure_translations_and_refuse_a_stripe_across_the_centre():
    s, _ = ideal_station(seed=5)
    ref = s.sphere_reference_pose()
    for span, across in ((5.0, 0.5), (60.0, 3.0)):
        st = handeye_experiments.with_move_ranges(s, span, across)
        q_t, _ = st.sphere_moves(40, 2, rng(6))
        shifts = s.nominal.fk_many(q_t)[:, :3, 3] - s.nominal.fk_many(q_t[:1])[:, :3, 3]
        in_sensor = shifts @ ref[:3, :3]  # base -> sensor axes (the reference orientation)
        assert np.all(np.abs(in_sensor) <= np.array([span, across, span]) + 1e-6)
        assert np.abs(in_sensor[:, 0]).max() > 0.5 * span  # the range is used, not ignored
    # across the laser plane beyond the stripe offset (R/4 = 3.2 mm) the centre changes side
    st = handeye_experiments.with_move_ranges(s, None, 12.0)
    with pytest.raises(CalibrationError, match="wrong side of the laser plane"):
        for seed in range(20):
            simulate.simulate_sphere_measurements(st, 4, 2, rng(seed))
    with pytest.raises(CalibrationError, match="unknown move range 'rotation_range_deg'"):
        handeye_experiments.handeye_ranges_experiment([15.0], [2.0]).trial(
            {"n_trans": 4, "n_rot": 6, "baselines": False}, rng(1), "rotation_range_deg", 3.0
        )


def test_mounting_error_has_the_stated_tolerance_as_three_sigma():
    st = scenario.load_station().stationary
    design = np.repeat(st.design[None], 400, axis=0)
    mounted = simulate._mount_stationary(design, st, rng(4))
    shift = (mounted[..., :3, 3] - design[..., :3, 3]).reshape(-1, 3)
    turn = np.rad2deg(geo.rotation_error(mounted.reshape(-1, 4, 4), design.reshape(-1, 4, 4)))
    np.testing.assert_allclose(shift.std(axis=0), st.mounting_tolerance_mm / 3, rtol=0.05)
    # the angle of a rotation vector with N(0, s^2) per axis has RMS s * sqrt(3)
    rms = np.sqrt(np.mean(turn**2))
    assert rms == pytest.approx(st.mounting_tolerance_deg / 3 * np.sqrt(3), rel=0.05)


def test_stationary_chain_noise_free_exact():
    rng = np.random.default_rng(13)
    sensor2flange = geo.make_transform(
        geo.euler_zyx_to_matrix(10.0, 50.0, -5.0), np.array([-46.0, -4.5, 413.0])
    )
    flange2base = geo.make_transform(geo.random_rotation(rng), rng.uniform(-900, 900, 3))
    front2sensor = geo.make_transform(geo.rotvec_to_matrix([np.pi, 0, 0]), [0, 0, 250.0])
    back2front = geo.make_transform(geo.rotvec_to_matrix([np.pi, 0, 0]), [0, 0, -8.0])
    statcam2base = geo.make_transform(geo.random_rotation(rng), rng.uniform(-900, 900, 3))
    front2base = flange2base @ sensor2flange @ front2sensor
    back2statcam = geo.invert(statcam2base) @ front2base @ back2front
    est = experiments.stationary_sensor_to_base(
        flange2base, sensor2flange, front2sensor, back2statcam, back2front
    )
    assert geo.rotation_error(est, statcam2base) < 1e-9
    assert geo.translation_error(est, statcam2base) < 1e-9
