"""The simulated station: the robot's manufacturing errors drawn at a scale of its tolerances."""

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.core.montecarlo import streams
from calstudy.models import robots
from calstudy.models.reach import reach_bound
from calstudy.papers.hybrid import simulate


def test_robot_error_scale_multiplies_the_drawn_link_errors():
    nominal = simulate.make_station(np.random.default_rng(14), robot_errors=False).true.parameters()
    errors = {
        scale: simulate.make_station(
            np.random.default_rng(14), robot_error_scale=scale
        ).true.parameters()
        - nominal
        for scale in (0.0, 1.0, 2.0)
    }
    assert np.all(errors[0.0] == 0.0)  # the nominal robot: no kinematic model error
    assert np.abs(errors[1.0]).max() > 0.1
    np.testing.assert_allclose(errors[2.0], 2.0 * errors[1.0], atol=1e-12)
    # the default is the robot of the tolerances file, draw for draw (notebook 01 unchanged)
    names = ("robot", "target", "stationary mounts", "workpiece")  # the station's streams
    robot_draws = streams(np.random.default_rng(14), *names)[0]
    default = robots.perturb_robot(robots.load_robot("kuka_kr16_2"), robot_draws)
    assert (errors[1.0] + nominal).tobytes() == default.parameters().tobytes()
    with pytest.raises(CalibrationError, match="robot_error_scale is -1.0"):
        simulate.make_station(np.random.default_rng(14), robot_error_scale=-1.0)


def _tilted_flange_poses(station, n, rng):
    """Flange poses of the true robot tilted about the sphere centre, drawn as the calibration
    moves draw them (random axis, angle within the station's rotation range)."""
    cfg = station.config.calibration_moves
    ref = station.sphere_reference_pose()
    about = geo.make_transform(np.eye(3), station.sphere.centre)
    poses = []
    for _ in range(n):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = np.deg2rad(rng.uniform(cfg.rotation_min_deg, cfg.rotation_range_deg))
        turn = about @ geo.make_transform(geo.rotvec_to_matrix(axis * angle), np.zeros(3))
        poses.append(turn @ geo.invert(about) @ ref @ geo.invert(station.sensor2flange_true))
    return poses


_REFUSED = (
    r"out of reach of the KUKA KR 16-2: its wrist point lies \d+\.\d mm beyond the arm's reach"
)


def test_poses_beyond_reach_are_refused_as_the_solver_would():
    station = simulate.make_station(np.random.default_rng(3))
    robot = station.true
    bound = reach_bound(robot)
    ref = station.sphere_reference_pose() @ geo.invert(station.sensor2flange_true)
    q_ref = station.solve_ik(robot, ref)
    failed = refused = 0
    for pose in _tilted_flange_poses(station, 120, np.random.default_rng(4)):
        try:  # the solver alone, from the reference configuration (as the moves are taught)
            robot.ik(pose, q_ref)
            reached = True
        except CalibrationError:
            reached = False
        failed += not reached
        if bound.unreachable(pose):
            refused += 1
            assert not reached  # never refuse a pose the solver reaches
            with pytest.raises(CalibrationError, match=_REFUSED):
                station.solve_ik(robot, pose, q_ref, only_q0=True)
        elif reached:
            np.testing.assert_allclose(
                station.solve_ik(robot, pose, q_ref, only_q0=True), robot.ik(pose, q_ref)
            )
    # the failures are mostly poses out of reach: the bound spares their searches
    assert failed >= 10
    assert refused >= 0.75 * failed


def test_a_refused_pose_costs_no_search(monkeypatch):
    station = simulate.make_station(np.random.default_rng(3))
    robot = station.true
    calls = []
    solve = robot.ik
    monkeypatch.setattr(robot, "ik", lambda *a, **k: calls.append(1) or solve(*a, **k))
    far = geo.make_transform(np.eye(3), [2500.0, 0.0, 700.0])  # wrist 2 m from the shoulder
    with pytest.raises(CalibrationError, match="out of reach of the KUKA KR 16-2"):
        station.solve_ik(robot, far)
    assert calls == []
    near = robot.fk(np.radians([0.0, -45.0, 100.0, 0.0, 45.0, 0.0]))
    np.testing.assert_allclose(robot.fk(station.solve_ik(robot, near)), near, atol=1e-8)
    assert calls
