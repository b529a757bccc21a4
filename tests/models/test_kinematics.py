"""Tests of calstudy.models.kinematics: link matrices, the KR 16-2 table, Jacobian, IK,
perturbations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import paths
from calstudy.models.kinematics import Link, Robot
from calstudy.models.robots import load_robot, perturb_robot, pose_errors

# ----------------------------------------------------------------------------------------------
# an independent reference: elementary matrices written out by hand


def rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def ry(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def tx(x):
    out = np.eye(4)
    out[0, 3] = x
    return out


def tz(z):
    out = np.eye(4)
    out[2, 3] = z
    return out


def dh_product(table, q):
    """Rz(q+theta) Tz(d) Tx(a) Rx(alpha) Ry(beta) for rows (a, alpha, d, theta, beta)."""
    out = np.eye(4)
    for (a, alpha, d, theta, beta), qi in zip(table, q, strict=True):
        out = out @ rz(qi + theta) @ tz(d) @ tx(a) @ rx(alpha) @ ry(beta)
    return out


def mdh_product(table, q):
    """Rx(alpha_{i-1}) Tx(a_{i-1}) Ry(beta_{i-1}) Rz(q+theta) Tz(d) for the same row layout."""
    out = np.eye(4)
    for (a, alpha, d, theta, beta), qi in zip(table, q, strict=True):
        out = out @ rx(alpha) @ tx(a) @ ry(beta) @ rz(qi + theta) @ tz(d)
    return out


def random_table(rng, n=6):
    return np.column_stack(
        [
            rng.uniform(-500, 500, n),
            rng.uniform(-math.pi, math.pi, n),
            rng.uniform(-500, 500, n),
            rng.uniform(-math.pi, math.pi, n),
            rng.uniform(-0.3, 0.3, n),
        ]
    )


def robot_from_table(convention, table, **kwargs):
    links = [Link(convention, *row) for row in table]
    n = len(links)
    return Robot("test arm", links, np.full(n, -math.pi), np.full(n, math.pi), **kwargs)


@pytest.fixture(scope="module")
def kr16():
    return load_robot("kuka_kr16_2")


# ----------------------------------------------------------------------------------------------
# forward kinematics


@pytest.mark.parametrize(("convention", "product"), [("dh", dh_product), ("mdh", mdh_product)])
def test_fk_equals_product_of_link_matrices(convention, product):
    rng = np.random.default_rng(1)
    table = random_table(rng)
    robot = robot_from_table(convention, table)
    for q in rng.uniform(-math.pi, math.pi, (20, 6)):
        np.testing.assert_allclose(robot.fk(q), product(table, q), rtol=0, atol=1e-9)


def test_fk_applies_base_and_tool():
    rng = np.random.default_rng(2)
    table = random_table(rng)
    base = rz(0.3) @ tx(120.0) @ ry(-0.2) @ tz(40.0)
    tool = rx(0.1) @ tz(95.0)
    robot = robot_from_table("dh", table, base=base, tool=tool)
    q = rng.uniform(-1, 1, 6)
    np.testing.assert_allclose(robot.fk(q), base @ dh_product(table, q) @ tool, atol=1e-9)


def test_fk_many_matches_fk_and_results_are_not_overwritten(kr16):
    rng = np.random.default_rng(3)
    Q = kr16.random_configurations(rng, 5)
    first = kr16.fk(Q[0])
    poses = kr16.fk_many(Q)
    np.testing.assert_array_equal(poses[0], first)
    for q, pose in zip(Q, poses, strict=True):
        np.testing.assert_allclose(kr16.fk(q), pose, atol=1e-12)
    np.testing.assert_array_equal(kr16.fk(Q[0]), first)


def test_hayati_link_matches_selfcal_eq2():
    # The selfcal paper's Eq. 2 written out: DH with d = 0 and a rotation beta about y.
    a, alpha, theta, beta, q = 680.0, 0.02, 0.1, -0.03, 0.7
    t, ca, sa, cb, sb = q + theta, math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
    ct, st = math.cos(t), math.sin(t)
    eq2 = np.array(
        [
            [ct * cb - st * sa * sb, -st * ca, ct * sb + st * sa * cb, a * ct],
            [st * cb + ct * sa * sb, ct * ca, st * sb - ct * sa * cb, a * st],
            [-ca * sb, sa, ca * cb, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    np.testing.assert_allclose(Link("dh", a, alpha, 0.0, theta, beta).transform(q), eq2, atol=1e-12)


# ----------------------------------------------------------------------------------------------
# DH and MDH describe the same arm


def test_planar_two_link_by_hand():
    l1, l2 = 300.0, 200.0
    dh = Robot("planar", [Link("dh", l1, 0, 0, 0), Link("dh", l2, 0, 0, 0)], [-3, -3], [3, 3])
    # Craig: row 1 has a0 = 0, row 2 has a1 = l1; frame 2 sits on joint 2, so the tip is a tool.
    mdh = Robot(
        "planar", [Link("mdh", 0, 0, 0, 0), Link("mdh", l1, 0, 0, 0)], [-3, -3], [3, 3], tool=tx(l2)
    )
    for q1, q2 in [(0.0, 0.0), (0.4, -1.1), (2.5, 0.9)]:
        tip = [
            l1 * math.cos(q1) + l2 * math.cos(q1 + q2),
            l1 * math.sin(q1) + l2 * math.sin(q1 + q2),
        ]
        for robot in (dh, mdh):
            pose = robot.fk([q1, q2])
            np.testing.assert_allclose(pose[:3, 3], [*tip, 0.0], atol=1e-9)
            np.testing.assert_allclose(pose[:3, :3], rz(q1 + q2)[:3, :3], atol=1e-12)


def test_mdh_table_equivalent_to_dh_table_gives_same_flange(kr16):
    # Shift the (a, alpha, beta) columns down one row; the last DH triple becomes the tool.
    dh = kr16.parameters().reshape(6, 5)
    mdh = dh.copy()
    mdh[:, [0, 1, 4]] = np.vstack([np.zeros(3), dh[:-1][:, [0, 1, 4]]])
    a, alpha, beta = dh[-1, [0, 1, 4]]
    robot = Robot(
        "mdh KR 16-2",
        [Link("mdh", *row) for row in mdh],
        kr16.qmin,
        kr16.qmax,
        tool=tx(a) @ rx(alpha) @ ry(beta),
    )
    assert robot.parameter_names()[:5] == ["a0", "alpha0", "d1", "theta1", "beta0"]
    rng = np.random.default_rng(4)
    Q = kr16.random_configurations(rng, 50)
    np.testing.assert_allclose(robot.fk_many(Q), kr16.fk_many(Q), rtol=0, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# the KUKA KR 16-2 table reproduces the dimension drawing


def wrist_centre(robot, q):
    pose = robot.fk(q)
    return pose[:3, 3] - 158.0 * pose[:3, 2]


def test_kr16_zero_configuration(kr16):
    pose = kr16.fk(np.zeros(6))
    # Mechanical zero: arm stretched forward, axis-4 line 35 mm above axis 2.
    np.testing.assert_allclose(pose[:3, 3], [260 + 680 + 670 + 158, 0, 675 + 35], atol=1e-9)
    np.testing.assert_allclose(pose[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(wrist_centre(kr16, np.zeros(6)), [1610, 0, 710], atol=1e-9)


def test_kr16_home_configuration(kr16):
    home = np.radians([0, -90, 90, 0, 0, 0])
    np.testing.assert_allclose(wrist_centre(kr16, home), [260 + 670, 0, 675 + 680 + 35], atol=1e-9)


def test_kr16_reach_to_wrist_centre(kr16):
    axis2 = np.array([260.0, 0.0, 675.0])
    q3 = np.radians(np.linspace(-20, 20, 40001))
    dist = [np.linalg.norm(wrist_centre(kr16, [0, 0, x, 0, 0, 0]) - axis2) for x in q3]
    assert round(260 + max(dist)) == 1611


def test_kr16_limits_and_tolerances(kr16):
    np.testing.assert_allclose(np.degrees(kr16.qmin), [-185, -155, -130, -350, -130, -350])
    np.testing.assert_allclose(np.degrees(kr16.qmax), [185, 35, 154, 350, 130, 350])
    assert kr16.tolerances == {"sigma_length_mm": 0.5, "sigma_angle_deg": 0.05}
    assert kr16.name == "KUKA KR 16-2"
    assert [link.parallel for link in kr16.links] == [False, True, False, False, False, False]


# ----------------------------------------------------------------------------------------------
# Jacobian and inverse kinematics


def skew_vector(m):
    return np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / 2.0


def test_jacobian_matches_finite_differences(kr16):
    rng = np.random.default_rng(5)
    h = 1e-6
    for q in kr16.random_configurations(rng, 10):
        jac = kr16.jacobian(q)
        assert jac.shape == (6, 6)
        pose = kr16.fk(q)
        for j in range(6):
            dq = np.zeros(6)
            dq[j] = h
            plus, minus = kr16.fk(q + dq), kr16.fk(q - dq)
            dpos = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
            omega = skew_vector((plus[:3, :3] - minus[:3, :3]) / (2 * h) @ pose[:3, :3].T)
            np.testing.assert_allclose(jac[:3, j], dpos, atol=1e-5)
            np.testing.assert_allclose(jac[3:, j], omega, atol=1e-8)


def test_ik_recovers_pose(kr16):
    rng = np.random.default_rng(6)
    for q in kr16.random_configurations(rng, 20):
        target = kr16.fk(q)
        q0 = q + rng.normal(0, 0.1, 6)
        solution = kr16.ik(target, q0)
        np.testing.assert_allclose(kr16.fk(solution), target, rtol=0, atol=1e-9)
        assert np.all(solution >= kr16.qmin) and np.all(solution <= kr16.qmax)


def test_ik_shifts_angles_by_full_turns_into_limits(kr16):
    q = np.radians([10, -60, 40, 20, 30, 40])
    solution = kr16.ik(kr16.fk(q), q + [2 * math.pi, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(solution, q, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# parameters and perturbations


def test_parameters_round_trip(kr16):
    p = kr16.parameters()
    assert p.shape == (30,)
    names = kr16.parameter_names()
    assert names[:6] == ["a1", "alpha1", "d1", "theta1", "beta1", "a2"]
    assert names[-1] == "beta6" and len(names) == 30
    assert p[names.index("d1")] == 675.0 and p[names.index("a2")] == 680.0
    assert kr16.parameter_is_length().sum() == 12
    copy = kr16.with_parameters(p)
    np.testing.assert_array_equal(copy.parameters(), p)
    q = np.radians([5, -70, 80, 10, 20, 30])
    np.testing.assert_array_equal(copy.fk(q), kr16.fk(q))
    moved = kr16.with_parameters(p + np.eye(30)[names.index("d6")] * 10.0)
    np.testing.assert_allclose(moved.fk(np.zeros(6))[:3, 3], [1778, 0, 710], atol=1e-9)


def test_perturbed_robot_has_millimetre_errors(kr16):
    rng = np.random.default_rng(7)
    true = perturb_robot(kr16, rng)
    Q = kr16.random_configurations(rng, 500)
    position, rotation = pose_errors(kr16, true, Q)
    rms = float(np.sqrt(np.mean(position**2)))
    assert 0.5 < rms < 5.0, rms
    assert 0.0 < np.degrees(np.sqrt(np.mean(rotation**2))) < 1.0
    delta = (true.parameters() - kr16.parameters()).reshape(6, 5)
    # beta moves only on the link between the parallel axes 2 and 3
    assert np.flatnonzero(delta[:, 4]).tolist() == [1]
    assert np.all(delta[:, :4] != 0)


def test_perturbation_is_seeded_and_zero_sigma_is_exact(kr16):
    a = perturb_robot(kr16, np.random.default_rng(8))
    b = perturb_robot(kr16, np.random.default_rng(8))
    np.testing.assert_array_equal(a.parameters(), b.parameters())
    same = perturb_robot(kr16, np.random.default_rng(8), sigma_length_mm=0, sigma_angle_deg=0)
    Q = kr16.random_configurations(np.random.default_rng(9), 50)
    position, rotation = pose_errors(kr16, same, Q)
    assert position.max() == 0.0 and rotation.max() < 1e-7
    np.testing.assert_array_equal(same.parameters(), kr16.parameters())


def test_random_configurations_stay_inside_shrunk_limits(kr16):
    Q = kr16.random_configurations(np.random.default_rng(10), 2000, margin=0.1)
    assert Q.shape == (2000, 6)
    assert np.all(Q >= kr16.qmin + 0.1) and np.all(Q <= kr16.qmax - 0.1)


# ----------------------------------------------------------------------------------------------
# bad input


def test_wrong_number_of_joint_angles(kr16):
    with pytest.raises(CalibrationError, match=r"q has 5 values; the KUKA KR 16-2 has 6 joints"):
        kr16.fk(np.zeros(5))
    with pytest.raises(CalibrationError, match=r"q has 7 values"):
        kr16.jacobian(np.zeros(7))
    with pytest.raises(CalibrationError, match=r"Q has shape \(4, 5\)"):
        kr16.fk_many(np.zeros((4, 5)))


def test_non_finite_joint_angles(kr16):
    with pytest.raises(CalibrationError, match=r"q holds a non-finite value \(nan\) at joint 3"):
        kr16.fk([0, 0, np.nan, 0, 0, 0])
    Q = np.zeros((3, 6))
    Q[2, 5] = np.inf
    with pytest.raises(CalibrationError, match=r"non-finite value \(inf\) at row 2, joint 6"):
        kr16.fk_many(Q)


def test_unknown_convention_and_bad_tables():
    with pytest.raises(CalibrationError, match=r"unknown link convention 'craig'"):
        Link("craig", 1.0, 0.0, 0.0, 0.0)
    with pytest.raises(CalibrationError, match=r"link parameter d is not finite \(nan\)"):
        Link("dh", 1.0, 0.0, float("nan"), 0.0)
    with pytest.raises(CalibrationError, match=r"mixes link conventions \['dh', 'mdh'\]"):
        Robot("mixed", [Link("dh", 1, 0, 0, 0), Link("mdh", 1, 0, 0, 0)], [-1, -1], [1, 1])
    with pytest.raises(CalibrationError, match=r"joint 2 of the arm has an empty range"):
        Robot("arm", [Link("dh", 1, 0, 0, 0), Link("dh", 1, 0, 0, 0)], [-1, 1], [1, 1])


def test_missing_robot_file():
    with pytest.raises(FileNotFoundError, match=r"data/robots/no_such_robot.toml"):
        load_robot("no_such_robot")


def test_robot_file_with_missing_key(tmp_path, monkeypatch):
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "bad.toml").write_text(
        '[[link]]\nconvention = "dh"\na_mm = 1.0\nalpha_deg = 0.0\nd_mm = 0.0\n'
    )
    monkeypatch.setattr(paths, "DATA_DIR", tmp_path)
    with pytest.raises(CalibrationError, match=r"bad.toml: link #1.theta_deg: missing"):
        load_robot("bad")


def test_ik_does_not_converge(kr16):
    q = np.radians([10, -60, 40, 20, 30, 40])
    with pytest.raises(
        CalibrationError, match=r"IK did not converge after 2 iterations \(residual"
    ):
        kr16.ik(kr16.fk(q), q + 0.5, max_iter=2)
    unreachable = kr16.fk(q)
    unreachable[0, 3] += 5000.0
    with pytest.raises(CalibrationError, match=r"IK did not converge after \d+ iterations"):
        kr16.ik(unreachable, q)


def test_ik_solution_outside_limits(kr16):
    q = np.radians([0, 60, 40, 20, 30, 40])  # A2 stops at +35 deg
    with pytest.raises(CalibrationError, match=r"outside the joint limits: joint 2 at 60.00 deg"):
        kr16.ik(kr16.fk(q), q)


def test_ik_rejects_bad_target(kr16):
    with pytest.raises(CalibrationError, match=r"flange2base has shape \(3, 3\)"):
        kr16.ik(np.eye(3), np.zeros(6))


def test_bad_parameters_sigmas_and_margins(kr16):
    with pytest.raises(
        CalibrationError, match=r"shape \(29,\); the KUKA KR 16-2 has 30 parameters"
    ):
        kr16.with_parameters(np.zeros(29))
    bad = kr16.parameters()
    bad[7] = np.nan
    with pytest.raises(CalibrationError, match=r"non-finite value \(nan\) at d2"):
        kr16.with_parameters(bad)
    with pytest.raises(CalibrationError, match=r"sigma_length_mm must be finite and >= 0 \(got -1"):
        perturb_robot(kr16, np.random.default_rng(0), sigma_length_mm=-1.0)
    with pytest.raises(CalibrationError, match=r"rng must be a numpy.random.Generator \(got int\)"):
        perturb_robot(kr16, 0)
    with pytest.raises(CalibrationError, match=r"margin 100.0 deg leaves no range for joint 2"):
        kr16.random_configurations(np.random.default_rng(0), 3, margin=math.radians(100))
    plain = Robot("arm", [Link("dh", 1, 0, 0, 0)], [-1], [1])
    with pytest.raises(CalibrationError, match=r"no tolerances table; pass sigma_length_mm"):
        perturb_robot(plain, np.random.default_rng(0))
    with pytest.raises(CalibrationError, match=r"the robots have 6 and 1 joints"):
        pose_errors(kr16, plain, np.zeros((2, 6)))


def test_ik_singular_normal_equations_raise_calibration_error(kr16, monkeypatch):
    q = np.array([0.3, -0.8, 0.9, 0.2, 0.6, -0.4])
    target = kr16.fk(q)

    solve = np.linalg.solve

    def singular(a, b):
        return solve(np.zeros_like(a), b)  # what a singular system raises

    monkeypatch.setattr(np.linalg, "solve", singular)
    with pytest.raises(CalibrationError, match="IK did not converge after 1 iterations"):
        kr16.ik(target, q + 0.1)
