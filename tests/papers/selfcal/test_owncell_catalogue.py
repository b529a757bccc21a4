"""Your own cell, case by case: each way a measured cell can mislead the identification is
refused or reported, never answered with a plausible wrong result.

The cells are drawn from the global model itself (the truth in the model class), so the counts
of identifiable parameters are known from theory: 30 with the sphere anywhere in the sensor's
field, 27 with a one-point sensor, 29 on an arm with three parallel axes (the model's DH link
between axes 3 and 4 fixes only d3 + d4).
"""

from __future__ import annotations

import math
import shutil
import warnings

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.errors import CalibrationWarning
from calstudy.core.geometry import euler_zyx_to_matrix, make_transform
from calstudy.models.kinematics import Link, Robot
from calstudy.models.robots import load_robot
from calstudy.models.urdf import robot_from_urdf
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.papers.selfcal.simulate import view_geometry
from calstudy.selfcal import design, measured
from calstudy.selfcal.identify import Measurements
from calstudy.selfcal.model import (
    IS_LENGTH,
    PARAM_NAMES,
    default_model,
    parameters_from_robot,
)
from calstudy.selfcal.planning import simulate_cell_rows, suggest_poses

NOISE = {"sensor_mm": 0.02, "repeatability_mm": 0.01, "tracker_mm": 0.005}
BASE = make_transform(euler_zyx_to_matrix(30.0, 0.0, 0.0), [1500.0, -800.0, -600.0])
SENSOR = make_transform(euler_zyx_to_matrix(90.0, -20.0, 0.0), [0.0, -80.0, 120.0])
SPHERES = np.array(
    [
        [1700.0, -700.0, 0.0],
        [1200.0, -300.0, 400.0],
        [1900.0, -1100.0, 500.0],
        [1400.0, -500.0, -300.0],
    ]
)
URDF_JOINT = """  <joint name="j{i}" type="revolute"><parent link="l{p}"/><child link="l{i}"/>
    <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
"""


def _urdf(joints, flange) -> str:
    """A URDF of six revolute joints ``(xyz m, rpy rad, axis)`` and a fixed flange frame."""
    links = "".join(f'  <link name="l{i}"/>\n' for i in range(8))
    body = "".join(
        URDF_JOINT.format(
            i=i + 1,
            p=i,
            xyz=" ".join(map(str, xyz)),
            rpy=" ".join(map(str, rpy)),
            axis=" ".join(map(str, axis)),
        )
        for i, (xyz, rpy, axis) in enumerate(joints)
    )
    fxyz, frpy = flange
    body += (
        '  <joint name="flange" type="fixed"><parent link="l6"/><child link="l7"/>'
        f'<origin xyz="{" ".join(map(str, fxyz))}" rpy="{" ".join(map(str, frpy))}"/></joint>\n'
    )
    return f'<?xml version="1.0"?>\n<robot name="test arm">\n{links}{body}</robot>\n'


HALF_PI = math.pi / 2
#: a UR-type arm (the layout of a UR5's URDF): axes 2, 3 and 4 parallel
UR_URDF = _urdf(
    [
        ((0, 0, 0.089159), (0, 0, 0), (0, 0, 1)),
        ((0, 0.13585, 0), (0, HALF_PI, 0), (0, 1, 0)),
        ((0, -0.1197, 0.425), (0, 0, 0), (0, 1, 0)),
        ((0, 0, 0.39225), (0, HALF_PI, 0), (0, 1, 0)),
        ((0, 0.093, 0), (0, 0, 0), (0, 0, 1)),
        ((0, 0, 0.09465), (0, 0, 0), (0, 1, 0)),
    ],
    ((0, 0.0823, 0), (0, 0, HALF_PI)),
)


def _ur_table() -> Robot:
    """The same UR-type arm as a DH table (UR5 numbers, mm)."""
    rows = [
        (0, 90, 89.159),
        (-425.0, 0, 0),
        (-392.25, 0, 0),
        (0, 90, 109.15),
        (0, -90, 94.65),
        (0, 0, 82.3),
    ]
    links = [Link("dh", a, math.radians(al), d, 0.0) for a, al, d in rows]
    return Robot("UR-type", links, [-math.pi] * 6, [math.pi] * 6)


def _cell(robot, rng, n=40, sigma=0.02, declared=False, probe=False, Q=None, sphere=None):
    """Nominal parameters, truth and measurements of a cell drawn from the global model."""
    model = default_model()
    nominal = parameters_from_robot(robot, BASE, SENSOR)
    truth = nominal + np.where(
        IS_LENGTH, rng.normal(0, 0.5, 30), np.radians(rng.normal(0, 0.05, 30))
    )
    Q = rng.uniform(-2.0, 2.0, (n, 6)) if Q is None else Q
    sphere = np.arange(len(Q)) % 4 if sphere is None else sphere
    if probe:  # one point of the sensor frame: the tracker reads where it is
        C = np.tile([0.0, 0.0, 300.0], (len(Q), 1))
        P_ref = model.points(truth, Q, C) + rng.normal(0, sigma, C.shape)
        C = C + rng.normal(0, sigma, C.shape)  # the reading of the point is noisy too
    else:
        poses = model.sensor2part(truth, Q)
        P_ref = SPHERES[sphere]
        C = np.einsum("mji,mj->mi", poses[:, :3, :3], P_ref - poses[:, :3, 3])
        C = C + rng.normal(0, sigma, C.shape)
    cov = tracker = None
    if declared:
        t2 = NOISE["tracker_mm"] ** 2
        own = NOISE["sensor_mm"] ** 2 + NOISE["repeatability_mm"] ** 2
        cov = np.tile((own + t2) * np.eye(3), (len(Q), 1, 1))
        tracker = np.tile(t2 * np.eye(3), (len(Q), 1, 1))
    meas = Measurements(Q, C, P_ref, sphere, cov=cov, tracker_cov=tracker)
    return nominal, truth, meas


def _quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        return fn(*args, **kwargs)


@pytest.fixture(scope="module")
def fanuc():
    return load_robot("fanuc_m710ic_50")


@pytest.fixture(scope="module", params=["table", "urdf"])
def arm(request, fanuc, tmp_path_factory):
    """The FANUC of the paper from its table and from a URDF of it."""
    if request.param == "table":
        return fanuc
    path = tmp_path_factory.mktemp("urdf") / "fanuc.urdf"
    path.write_text(_table_as_urdf(fanuc))
    return robot_from_urdf(path, flange="l7")


# ---------------------------------------------------------------------------------------------
# outliers


def test_two_rows_off_by_2_mm_are_flagged_with_declared_noise(fanuc):
    nominal, truth, meas = _cell(fanuc, np.random.default_rng(1), n=24, declared=True)
    meas.C[5] += [2.0, 0.0, 0.0]
    meas.C[17] += [0.0, -1.2, 1.6]
    fit = measured.identify_measurements(meas, nominal, NOISE)
    assert set(np.flatnonzero(fit.outliers)) == {5, 17}
    kept = fit.residuals.loc[~fit.outliers, "normalised"]
    assert kept.max() < measured.CHI2_3_999
    assert np.abs(fit.params - truth)[IS_LENGTH].max() < 0.5


def test_declared_noise_far_too_small_is_refused(fanuc):
    nominal, _, meas = _cell(fanuc, np.random.default_rng(2), n=24, sigma=0.2, declared=True)
    with pytest.raises(CalibrationError, match="declared noise is too small"):
        measured.identify_measurements(meas, nominal, NOISE)


# ---------------------------------------------------------------------------------------------
# identifiable-parameter counts


def test_scanner_on_a_6r_arm_identifies_30(arm):
    nominal, truth, meas = _cell(arm, np.random.default_rng(3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", CalibrationWarning)
        fit = measured.identify_measurements(meas, nominal)
    assert fit.n_identified == 30 and not fit.notes
    assert (fit.identifiability["status"] == measured.IDENTIFIED).all()


@pytest.mark.parametrize("declared", [False, True])
def test_one_point_probe_identifies_27_and_names_the_sensor_rotations(arm, declared):
    nominal, truth, meas = _cell(arm, np.random.default_rng(4), probe=True, declared=declared)
    with pytest.warns(CalibrationWarning, match="identify 27 parameters"):
        fit = measured.identify_measurements(meas, nominal, NOISE if declared else None)
    assert fit.n_identified == 27
    assert fit.notes[0].startswith("at the start: the poses identify 27")
    table = fit.identifiability.set_index("name")
    lost = set(table.index[table["status"] == measured.NOT_IDENTIFIABLE])
    assert len(lost) == 3 and lost <= {"x1", "y1", "z1", "gamma1", "phi1", "eps1"}
    report = measured.parameter_report(fit, nominal).set_index("name")
    assert report.loc[sorted(lost), "std"].isna().all()
    assert (report.loc[sorted(lost), "change"] == 0).all()
    # the probe point itself (where it sits on the flange) is what the poses fix
    model = default_model()
    tip = model.sensor2part(fit.params, meas.Q[:5])[:, :3] @ [0, 0, 300.0, 1]
    true_tip = model.sensor2part(truth, meas.Q[:5])[:, :3] @ [0, 0, 300.0, 1]
    assert np.abs(tip - true_tip).max() < 0.1
    # the guidance: hold the sensor rotations yourself, and nothing more is lost or warned of
    with warnings.catch_warnings():
        warnings.simplefilter("error", CalibrationWarning)
        held = measured.identify_measurements(
            meas, nominal, NOISE if declared else None, fixed=["gamma1", "phi1", "eps1"]
        )
    assert held.n_identified == 27 and not held.notes
    tip = model.sensor2part(held.params, meas.Q[:5])[:, :3] @ [0, 0, 300.0, 1]
    assert np.abs(tip - true_tip).max() < 0.1


@pytest.mark.parametrize("source", ["table", "urdf"])
def test_ur_type_arm_identifies_29_with_d4_fixed(tmp_path, source):
    if source == "urdf":
        (tmp_path / "ur.urdf").write_text(UR_URDF)
        robot = robot_from_urdf(tmp_path / "ur.urdf", flange="l7")
    else:
        robot = _ur_table()
    nominal, truth, meas = _cell(robot, np.random.default_rng(5))
    with pytest.warns(CalibrationWarning, match="axes 3 and 4 of the nominal robot are parallel"):
        fit = measured.identify_measurements(meas, nominal)
    assert fit.n_identified == 29
    lost = fit.identifiability.set_index("name")
    lost = lost[lost["status"] == measured.NOT_IDENTIFIABLE]
    assert list(lost.index) in (["d3"], ["d4"])
    assert "d3" in lost["combination"].iloc[0] and "d4" in lost["combination"].iloc[0]
    i3, i4 = PARAM_NAMES.index("d3"), PARAM_NAMES.index("d4")
    assert abs((fit.params[i3] + fit.params[i4]) - (truth[i3] + truth[i4])) < 0.05
    assert np.abs(fit.params - truth)[IS_LENGTH].max() < 5.0  # no length at metres


# ---------------------------------------------------------------------------------------------
# rank-deficient pose sets


def test_one_pose_repeated_is_refused(fanuc):
    rng = np.random.default_rng(6)
    Q = np.tile(rng.uniform(-2, 2, 6), (24, 1))
    nominal, _, meas = _cell(fanuc, rng, Q=Q, sphere=np.zeros(24, int))
    with pytest.raises(CalibrationError, match=r"identify 3 of the 30 .*poses repeated"):
        measured.identify_measurements(meas, nominal)


def test_only_joint_6_moving_is_refused(fanuc):
    rng = np.random.default_rng(7)
    Q = np.tile(rng.uniform(-2, 2, 6), (24, 1))
    Q[:, 5] = np.linspace(-2.5, 2.5, 24)
    nominal, _, meas = _cell(fanuc, rng, Q=Q, sphere=np.zeros(24, int))
    with pytest.raises(CalibrationError, match="one joint moving"):
        measured.identify_measurements(meas, nominal)


def test_one_sphere_reports_the_base_rotation_not_identified(fanuc):
    nominal, _, meas = _cell(fanuc, np.random.default_rng(8), sphere=np.zeros(40, int))
    with pytest.warns(CalibrationWarning, match="identify 27 parameters"):
        fit = measured.identify_measurements(meas, nominal)
    report = measured.parameter_report(fit, nominal).set_index("name")
    lost = report[report["status"] == measured.NOT_IDENTIFIABLE]
    assert set(lost.index) == {"gamma2", "phi2", "eps2"}
    assert lost["std"].isna().all()
    assert np.isfinite(report.loc[report["status"] == measured.IDENTIFIED, "std"]).all()


# ---------------------------------------------------------------------------------------------
# fixed parameters


def test_parameters_fixed_on_request_stay_at_the_start(fanuc):
    nominal, truth, meas = _cell(fanuc, np.random.default_rng(9))
    fit = measured.identify_measurements(meas, nominal, fixed=["a2", "alpha3"])
    for name in ("a2", "alpha3"):
        i = PARAM_NAMES.index(name)
        assert fit.params[i] == nominal[i] and not fit.free[i]
        assert fit.identifiability.loc[i, "status"] == measured.FIXED_BY_YOU
        assert np.all(fit.covariance[i] == 0.0)
    assert fit.n_identified == 28
    with pytest.raises(CalibrationError, match="fixed parameter 'a7' is not one of"):
        measured.identify_measurements(meas, nominal, fixed=["a7"])


# ---------------------------------------------------------------------------------------------
# the sensor-frame columns


@pytest.mark.parametrize(
    ("order", "signs", "cause"),
    [((1, 0, 2), (1, 1, 1), "cy as cx, cx as cy"), ((0, 1, 2), (1, 1, -1), "-cz as cz")],
)
def test_swapped_or_negated_columns_are_refused_with_the_cause(fanuc, order, signs, cause):
    nominal, _, meas = _cell(fanuc, np.random.default_rng(10))
    meas.C[:] = meas.C[:, order] * np.array(signs)
    with pytest.raises(CalibrationError, match=f"look swapped or negated: read with {cause} "):
        measured.identify_measurements(meas, nominal)


def test_candidate_blocks_non_finite_or_zero_are_refused():
    blocks = np.random.default_rng(0).normal(size=(20, 3, 30))
    blocks[4, 1, 7] = np.nan
    with pytest.raises(CalibrationError, match="candidate block 4 .* non-finite"):
        design.select_poses(blocks, 12)
    blocks[4] = 0.0
    with pytest.raises(CalibrationError, match="candidate block 4 .* all zero"):
        design.select_poses(blocks, 12)


# ---------------------------------------------------------------------------------------------
# robots from URDF


def _table_as_urdf(robot: Robot) -> str:
    """A URDF of a DH table: each joint placed by the previous link's constant part."""
    import pinocchio as pin

    joints, carry = [], robot.base
    for link in robot.links:
        pre, post = link.split()
        t = carry @ pre
        joints.append((tuple(t[:3, 3] / 1000.0), tuple(pin.rpy.matrixToRpy(t[:3, :3])), (0, 0, 1)))
        carry = post
    t = carry @ robot.tool
    return _urdf(joints, (tuple(t[:3, 3] / 1000.0), tuple(pin.rpy.matrixToRpy(t[:3, :3]))))


def test_urdf_of_a_table_gives_the_same_robot_and_parameters(tmp_path, fanuc):
    (tmp_path / "arm.urdf").write_text(_table_as_urdf(fanuc))
    robot = robot_from_urdf(tmp_path / "arm.urdf", flange="l7")
    Q = np.random.default_rng(11).uniform(-2, 2, (10, 6))
    np.testing.assert_allclose(robot.fk_many(Q), fanuc.fk_many(Q), atol=1e-6)
    model = default_model()
    from_urdf = parameters_from_robot(robot, BASE, SENSOR)
    from_table = parameters_from_robot(fanuc, BASE, SENSOR)
    np.testing.assert_allclose(
        model.sensor2part(from_urdf, Q), model.sensor2part(from_table, Q), atol=1e-6
    )


def test_urdf_with_a_prismatic_joint_is_refused(tmp_path):
    text = UR_URDF.replace('name="j3" type="revolute"', 'name="j3" type="prismatic"')
    (tmp_path / "bad.urdf").write_text(text)
    with pytest.raises(CalibrationError, match="revolute joints of one degree of freedom"):
        robot_from_urdf(tmp_path / "bad.urdf")
    with pytest.raises(CalibrationError, match="no frame 'tool9'"):
        (tmp_path / "ur.urdf").write_text(UR_URDF)
        robot_from_urdf(tmp_path / "ur.urdf", flange="tool9")


# ---------------------------------------------------------------------------------------------
# 6-D pose readings (a camera on the flange)


def test_one_target_read_in_6d_identifies_all_30(fanuc):
    rng = np.random.default_rng(12)
    model = default_model()
    nominal = parameters_from_robot(fanuc, BASE, SENSOR)
    truth = nominal + np.where(
        IS_LENGTH, rng.normal(0, 0.5, 30), np.radians(rng.normal(0, 0.05, 30))
    )
    Q = rng.uniform(-2.0, 2.0, (15, 6))
    target2part = make_transform(euler_zyx_to_matrix(10.0, 5.0, -3.0), SPHERES[0])[None]
    sensor2part = model.sensor2part(truth, Q)
    target2sensor = np.linalg.inv(sensor2part) @ target2part[0]
    meas = measured.measurements_from_poses(Q, target2sensor, target2part, np.zeros(15, int))
    meas.C[:] += rng.normal(0, 0.01, meas.C.shape)
    assert len(meas) == 60 and set(meas.sphere) == {0, 1, 2, 3}
    fit = measured.identify_measurements(meas, nominal)
    assert fit.n_identified == 30 and not fit.notes
    assert np.abs(fit.params - truth)[IS_LENGTH].max() < 0.2
    # the same robot poses seeing only the target's origin (one sphere) lose the base rotation
    origin = measured.subset(meas, np.arange(0, 60, 4))
    assert _quiet(measured.identify_measurements, origin, nominal).n_identified == 27
    with pytest.raises(CalibrationError, match="target indices must be integers in 0..0"):
        measured.measurements_from_poses(Q, target2sensor, target2part, np.ones(15, int))


# ---------------------------------------------------------------------------------------------
# poses planned for your sensor


def _example_cell(tmp_path, sensor_lines: str = ""):
    from calstudy.core.paths import data_path

    folder = tmp_path / "cell"
    shutil.copytree(data_path("selfcal", "example_measurements"), folder)
    text = (folder / measured.CELL_FILE).read_text()
    marker = "zyx_deg = [90.0000, -20.0000, 0.0000]\n"
    assert marker in text
    (folder / measured.CELL_FILE).write_text(text.replace(marker, marker + sensor_lines, 1))
    return measured.read_cell(folder)


def test_planning_uses_your_sensor_and_is_compared_with_your_poses(tmp_path):
    scenario = load_scenario()
    own = _example_cell(tmp_path, "standoff_mm = 150.0\nfield_mm = 20.0\ndepth_mm = 20.0\n")
    assert own.sensor_geometry == {"standoff_mm": 150.0, "field_mm": 20.0, "depth_mm": 20.0}
    suggested, compare, random = suggest_poses(
        own, 15, np.random.default_rng(1), view_geometry(scenario)
    )
    assert random["standoff_mm"] == 150.0 and len(suggested) == len(own.calibration) == 24
    # the candidates really stand at 150 mm: the spheres lie near the sensor's z = 150 mm
    model = default_model()
    q = np.radians(suggested[[f"q{i}_deg" for i in range(1, 7)]].to_numpy())
    spheres = own.spheres[[list(own.sphere_ids).index(s) for s in suggested["sphere"]]]
    poses = model.sensor2part(own.start, q)
    local = np.einsum("mji,mj->mi", poses[:, :3, :3], spheres - poses[:, :3, 3])
    assert np.abs(local[:, 2] - 150.0).max() < 25.0
    # planned for a worse sensor than the one that measured, the selection is not better
    yours, selected = compare.set_index("poses").loc[["yours", "selected"], "predicted_std"]
    assert compare["better"].tolist() == [False, bool(selected < yours)]
    assert random["ratio_ci_low"] > 1.0  # planned beats random selections of the same number
    with pytest.raises(CalibrationError, match="25 poses asked for from 24 candidates"):
        suggest_poses(own, 6, np.random.default_rng(1), view_geometry(scenario), n_poses=25)
    with pytest.raises(CalibrationError, match="standoff_mm = -1.0 must be a positive"):
        suggest_poses(
            own, 6, np.random.default_rng(1), view_geometry(scenario), standoff_mm=-1.0
        )


def _example_fit():
    from calstudy.core.paths import data_path

    own = measured.read_cell(data_path("selfcal", "example_measurements"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        return own, measured.identify_measurements(own.calibration, own.start, own.noise)


def test_planned_poses_beat_random_ones_measured_on_your_cell():
    scenario = load_scenario()
    own, fit = _example_fit()

    def measured_comparison(seed):
        return suggest_poses(
            own, 15, np.random.default_rng(seed), view_geometry(scenario), truth=fit,
            replications=50,
        )[2]

    first = measured_comparison(1)
    assert first["replications"] == 50 and first["noise_sigma_mm"] == fit.sigma_mm
    assert first["failed_planned"] == first["failed_random"] == 0
    # the identified model at the held-out rows: within a few noise sigmas of the truth
    assert 0.0 < first["planned_rms_mm"] < 3 * fit.sigma_mm
    assert first["planned_rms_mm"] < first["random_rms_mm"]
    assert first["measured_ratio_ci_low"] > 1.0  # planned poses measure better than random
    assert measured_comparison(1) == first  # deterministic for a seed
    assert measured_comparison(2)["measured_ratio_median"] != first["measured_ratio_median"]
    # the simulated rows put each centre where the truth puts it, plus the noise asked for
    q, sphere = own.calibration.Q, own.calibration.sphere
    rows = simulate_cell_rows(
        fit.params, q, sphere, own.spheres, 0.5, True, np.random.default_rng(3)
    )
    model = default_model()
    assert np.allclose(model.points(fit.params, q, rows.C_true), rows.P_ref, atol=1e-9)
    assert 0.35 < np.std(rows.C - rows.C_true) < 0.65 and rows.cov.shape == (len(q), 3, 3)


@pytest.mark.parametrize("replications", [1, 5])
def test_measured_comparison_refuses_too_few_replications(replications):
    own, fit = _example_fit()
    with pytest.raises(CalibrationError, match=f"replications = {replications}: at least 6"):
        suggest_poses(
            own, 15, np.random.default_rng(1), view_geometry(load_scenario()), truth=fit,
            replications=replications,
        )


# ---------------------------------------------------------------------------------------------
# the covariance without declared noise


def test_shared_error_covariance_recovers_the_sandwich_of_the_true_variances():
    rng = np.random.default_rng(13)
    m, p, k = 96, 5, 8  # views, parameters, spheres
    sphere = np.arange(m) % k
    # three columns move every view alike (a translation), as the base position does
    jac = np.column_stack([np.tile(np.eye(3), (m, 1)), rng.normal(size=(3 * m, p - 3))])
    var_e, var_t = 0.02**2, 0.015**2
    same = np.kron((sphere[:, None] == sphere[None, :]).astype(float), np.eye(3))
    v = var_e * np.eye(3 * m) + var_t * same
    info_inv = np.linalg.inv(jac.T @ jac)
    truth = info_inv @ jac.T @ v @ jac @ info_inv
    estimates = []
    for _ in range(40):
        noise = rng.normal(0, 0.02, 3 * m) + rng.normal(0, 0.015, (k, 3))[sphere].ravel()
        r = noise - jac @ (info_inv @ jac.T @ noise)
        estimates.append(measured.shared_error_covariance(jac, r, sphere).covariance)
    ratio = np.diag(np.mean(estimates, axis=0)) / np.diag(truth)
    assert np.all(np.abs(ratio - 1.0) < 0.3)
    # the views of one sphere are not independent: s^2 (J^T J)^-1 is far too small
    assert np.all(np.diag(truth)[:3] > 3.0 * (var_e + var_t) * np.diag(info_inv)[:3])


def test_a_cell_folder_may_name_a_urdf(tmp_path, fanuc):
    from calstudy.core.paths import data_path

    folder = tmp_path / "cell"
    shutil.copytree(data_path("selfcal", "example_measurements"), folder)
    (folder / "arm.urdf").write_text(_table_as_urdf(fanuc))
    text = (folder / measured.CELL_FILE).read_text()
    old = 'robot = "fanuc_m710ic_50.toml"'
    assert old in text
    (folder / measured.CELL_FILE).write_text(
        text.replace(old, 'robot = "arm.urdf"\nflange = "l7"', 1)
    )
    from_urdf = measured.read_cell(folder)
    from_table = measured.read_cell(data_path("selfcal", "example_measurements"))
    model = default_model()
    Q = from_table.calibration.Q
    np.testing.assert_allclose(
        model.sensor2part(from_urdf.start, Q), model.sensor2part(from_table.start, Q), atol=1e-6
    )
    (folder / measured.CELL_FILE).write_text(text.replace(old, 'robot = "gone.urdf"', 1))
    with pytest.raises(CalibrationError, match="gone.urdf does not exist"):
        measured.read_cell(folder)


def test_noise_aware_rank_drops_a_direction_the_noise_hides():
    rng = np.random.default_rng(14)
    jac = rng.normal(size=(60, 4)) * 10.0
    jac = np.column_stack([jac, jac[:, 0] + 1e-4 * rng.normal(size=60)])  # nearly column 0
    names, length = ("a", "b", "c", "d", "e"), np.ones(5, bool)
    assert design.base_parameters(jac, names, length).rank == 5  # round-off: all 5
    # the direction a - e moves the points by ~1e-3 mm per mm: at 0.05 mm of noise its
    # standard deviation is ~50 mm, beyond the 10 mm limit
    noisy = design.base_parameters(jac, names, length, sigma_mm=0.05)
    assert noisy.rank == 4 and len(noisy.unidentified) == 1
    assert {"a", "e"} <= set(noisy.unidentified[0].split())
    assert design.base_parameters(jac, names, length, sigma_mm=1e-6).rank == 5
    with pytest.raises(CalibrationError, match="sigma_mm = -1.0 must be positive"):
        design.base_parameters(jac, names, length, sigma_mm=-1.0)
