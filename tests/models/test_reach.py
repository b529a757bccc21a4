"""Tests of calstudy.models.reach: the strict reach bound of a serial robot."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.models.kinematics import IK_TOL, Link, Robot
from calstudy.models.reach import ReachBound, reach_bound
from calstudy.models.robots import load_robot, perturb_robot


@pytest.fixture(scope="module")
def kr16():
    return load_robot("kuka_kr16_2")


def _random_robot(seed: int, convention: str) -> Robot:
    """Any 6R arm: link lengths and offsets up to 500 mm, any twists, Hayati betas, a base and a
    tool off the identity."""
    rng = np.random.default_rng(seed)
    links = [
        Link(
            convention,
            rng.uniform(-500, 500),
            rng.uniform(-math.pi, math.pi),
            rng.uniform(-500, 500),
            rng.uniform(-math.pi, math.pi),
            rng.uniform(-0.3, 0.3),
        )
        for _ in range(6)
    ]
    base = geo.make_transform(geo.rotvec_to_matrix(rng.normal(size=3)), rng.uniform(-300, 300, 3))
    tool = geo.make_transform(geo.rotvec_to_matrix(rng.normal(size=3)), rng.uniform(-100, 100, 3))
    return Robot("test arm", links, np.full(6, -math.pi), np.full(6, math.pi), base, tool)


def _beyond(bound: ReachBound, pose: np.ndarray, excess: float) -> np.ndarray | None:
    """``pose`` translated so that its wrist point lies ``excess`` mm beyond the reach: moved
    along the ray from the nearest point of the shoulder circle, which stays the nearest while
    the ray leads away from the axis (a wrist point no nearer the axis than the circle; None for
    the others)."""
    w = pose[:3, :3] @ bound.wrist + pose[:3, 3]
    d = w - bound.centre
    h = d @ bound.axis
    radial = d - h * bound.axis
    if np.linalg.norm(radial) < bound.radius:
        return None
    nearest = bound.centre + bound.radius * radial / np.linalg.norm(radial)
    ray = (w - nearest) / np.linalg.norm(w - nearest)
    out = pose.copy()
    out[:3, 3] += (excess - bound.excess(pose)) * ray
    return out


def test_kr16_bound_is_the_stretched_arm(kr16):
    bound = reach_bound(kr16)
    np.testing.assert_allclose(bound.wrist, [0, 0, -158], atol=1e-12)  # the wrist centre
    np.testing.assert_allclose(bound.centre, [0, 0, 675], atol=1e-12)  # height of axis 2
    np.testing.assert_allclose(bound.axis, [0, 0, 1], atol=1e-15)
    assert bound.radius == pytest.approx(260.0, abs=1e-12)  # axis 2 in front of axis 1
    assert bound.reach == pytest.approx(680.0 + math.hypot(670.0, 35.0), abs=1e-9)
    # tight: the stretched arm (the wrist on the line of the upper arm) reaches it
    q3 = np.radians(np.linspace(-5, 5, 20001))
    excess = [bound.excess(kr16.fk([0.4, -0.7, x, 0.3, 0.8, -0.2])) for x in q3]
    assert -1e-6 < max(excess) <= 1e-9
    assert reach_bound(kr16) is bound  # once per robot
    assert bound.margin_mm() == pytest.approx(1e-3 + 2 * IK_TOL * 159.0, rel=1e-12)
    assert bound.margin_mm(1e-4) == pytest.approx(1e-3 + 2e-4 * 159.0001, rel=1e-12)


def test_default_tolerance_is_the_ik_default():
    assert IK_TOL == inspect.signature(Robot.ik).parameters["tol"].default


@given(
    seed=st.integers(0, 2**32 - 1),
    convention=st.sampled_from(["dh", "mdh"]),
    q=st.lists(st.floats(-2 * math.pi, 2 * math.pi), min_size=6, max_size=6),
)
@settings(max_examples=300, deadline=None)
def test_no_reachable_pose_is_refused(seed, convention, q):
    robot = _random_robot(seed, convention)
    bound = reach_bound(robot)
    pose = robot.fk(q)
    assert bound.excess(pose) <= 1e-9  # a theorem; rounding only
    assert not bound.unreachable(pose)


@given(
    seed=st.integers(0, 2**32 - 1),
    scale=st.floats(0.0, 20.0),
    q=st.lists(st.floats(-math.pi, math.pi), min_size=6, max_size=6),
)
@settings(max_examples=200, deadline=None)
def test_no_pose_of_a_drawn_kr16_is_refused(kr16, seed, scale, q):
    robot = perturb_robot(
        kr16, np.random.default_rng(seed), sigma_length_mm=0.5 * scale, sigma_angle_deg=0.05 * scale
    )
    assert reach_bound(robot).excess(robot.fk(q)) <= 1e-9


@given(
    seed=st.integers(0, 2**32 - 1),
    q=st.lists(st.floats(-math.pi, math.pi), min_size=6, max_size=6),
    excess=st.floats(0.002, 400.0),
    start=st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6),
)
@settings(max_examples=25, deadline=None)
def test_refused_poses_fail_in_the_solver(kr16, seed, q, excess, start):
    robot = perturb_robot(kr16, np.random.default_rng(seed))
    bound = reach_bound(robot)
    q = np.array(q)
    pose = _beyond(bound, robot.fk(q), excess)
    assume(pose is not None)
    assert bound.excess(pose) == pytest.approx(excess, abs=1e-6)
    assert bound.unreachable(pose)
    # from the configuration it was pushed out of, and from a start near it
    for q0 in (q, q + np.array(start)):
        with pytest.raises(CalibrationError, match="IK did not converge|outside the joint"):
            robot.ik(pose, q0)


def test_a_pose_just_inside_is_reached(kr16):
    # the bound is tight for the nominal table: ten micrometres inside, the solver reaches it
    bound = reach_bound(kr16)
    q = np.radians([10.0, -60.0, 20.0, 30.0, 40.0, 50.0])
    for inside in (0.01, 1.0):
        pose = _beyond(bound, kr16.fk(q), -inside)
        assert pose is not None
        assert not bound.unreachable(pose)
        np.testing.assert_allclose(kr16.fk(kr16.ik(pose, q)), pose, atol=1e-8)


def test_one_joint_is_never_refused():
    robot = Robot("one", [Link("dh", 100.0, 0.0, 0.0, 0.0)], [-math.pi], [math.pi])
    bound = reach_bound(robot)
    assert bound.excess(robot.fk([0.3])) == -math.inf
    far = geo.make_transform(np.eye(3), [1e4, 0.0, 0.0])
    assert not bound.unreachable(far)
