"""The selfcal global model: Eq. 2, the chain against the DH robot, the Jacobian, bad tables."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.geometry import make_transform, random_rotation
from calstudy.models.kinematics import Link
from calstudy.models.robots import perturb_robot
from calstudy.selfcal.model import (
    GlobalModel,
    parameters_from_robot,
    params_to_pose,
    pose_to_params,
)


def random_pose(rng, scale_mm=500.0):
    return make_transform(random_rotation(rng), rng.uniform(-scale_mm, scale_mm, 3))


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
    robot = perturb_robot(scenario.nominal_robot, rng)
    vec = robot.parameters()
    vec[7] = 0.0  # d2: Eq. 2 has none
    robot = robot.with_parameters(vec)
    part2base, sensor2flange = random_pose(rng, 3000.0), random_pose(rng, 200.0)
    params = parameters_from_robot(robot, part2base, sensor2flange)
    assert params.shape == (30,)
    Q = robot.random_configurations(rng, 20)
    expected = part2base @ robot.fk_many(Q) @ sensor2flange
    np.testing.assert_allclose(GlobalModel().sensor2part(params, Q), expected, atol=1e-9)


def test_joint6_turns_about_the_z_axis_of_frame5(scenario):
    """Our reading of 5HS: turning joint 6 rotates the sensor about the joint-6 axis (frame 5 z)."""
    rng = np.random.default_rng(2)
    params = parameters_from_robot(scenario.nominal_robot, np.eye(4), random_pose(rng, 200.0))
    q = scenario.nominal_robot.random_configurations(rng, 1)
    q2 = q.copy()
    q2[0, 5] += 0.7
    model = GlobalModel()
    a, b = model.sensor2part(params, np.vstack([q, q2]))
    frame5 = scenario.nominal_robot.fk(q[0]) @ np.linalg.inv(
        scenario.nominal_robot.links[5].split()[1]
    )
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
    params = parameters_from_robot(
        scenario.nominal_robot, random_pose(rng), random_pose(rng, 200.0)
    )
    Q = scenario.nominal_robot.random_configurations(rng, 4)
    C = rng.normal(0.0, 100.0, (4, 3))
    model = GlobalModel()
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
    np.testing.assert_allclose(params_to_pose(pose_to_params(pose)), pose, atol=1e-12)


@pytest.mark.parametrize(
    ("index", "value", "match"),
    [(7, 2.0, "link 2 of Eq. 2 has no offset d"), (14, 0.01, "beta is only modelled on link 2")],
)
def test_tables_outside_the_model_raise(scenario, index, value, match):
    vec = scenario.nominal_robot.parameters()
    vec[index] = value
    with pytest.raises(CalibrationError, match=match):
        parameters_from_robot(scenario.nominal_robot.with_parameters(vec), np.eye(4), np.eye(4))


def test_points_and_jacobian_keep_the_last_answer_read_only(scenario):
    rng = np.random.default_rng(4)
    params = parameters_from_robot(
        scenario.nominal_robot, random_pose(rng), random_pose(rng, 200.0)
    )
    Q = scenario.nominal_robot.random_configurations(rng, 3)
    C = rng.normal(0.0, 100.0, (3, 3))
    model = GlobalModel()
    points, jac = model.points_and_jacobian(params, Q, C)
    again = model.points_and_jacobian(params.copy(), Q.copy(), C.copy())
    assert again[0] is points and again[1] is jac  # the same inputs: the kept answer
    with pytest.raises(ValueError, match="read-only"):
        jac[0, 0] = 1.0
    fresh = GlobalModel().points_and_jacobian(params, Q, C)
    assert fresh[1].tobytes() == jac.tobytes()  # what a new computation gives, to the bit
    moved = model.points_and_jacobian(params, Q, C + 1.0)  # another input: computed afresh
    assert not np.array_equal(moved[0], points)
