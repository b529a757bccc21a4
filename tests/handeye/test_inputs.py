"""Input handling of hand-eye calibration: conventions, units, SO(3) re-projection, motions."""

import numpy as np
import pytest
from support import handeye_cell as _cell

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp

# ----------------------------------------------------------------------------------------------
# conventions and units


def test_convention_check_catches_inverted_robot_poses():
    cell = _cell(8)
    base2gripper = geo.invert(cell.flange2base)
    match = r"implausible .*Likely causes: the data fit with 1\. the robot poses inverted"
    with pytest.raises(CalibrationError, match=match):
        hp.calibrate_handeye(base2gripper, cell.target2camera)
    res = hp.calibrate_handeye(base2gripper, cell.target2camera, convention="base2gripper")
    assert np.rad2deg(geo.rotation_error(res.camera2flange, cell.camera2flange)) < 0.1


def test_convention_check_catches_inverted_camera_poses():
    cell = _cell(9)
    camera2target = geo.invert(cell.target2camera)
    match = r"Likely causes: the data fit with 1\. the camera poses inverted"
    with pytest.raises(CalibrationError, match=match):
        hp.calibrate_robot_world_handeye(cell.flange2base, camera2target)
    res = hp.calibrate_handeye(cell.flange2base, camera2target, convention="camera2target")
    assert np.rad2deg(geo.rotation_error(res.camera2flange, cell.camera2flange)) < 0.1


def test_convention_check_catches_metres_against_millimetres():
    cell = _cell(10)
    robot_m = cell.flange2base.copy()
    robot_m[:, :3, 3] /= 1000.0
    match = r"outside the robot's reach .*1\. the robot translations x1000 \(robot in m"
    with pytest.raises(CalibrationError, match=match):
        hp.calibrate_handeye(robot_m, cell.target2camera)
    with pytest.warns(UserWarning, match="robot translations x1000"):
        hp.calibrate_handeye(robot_m, cell.target2camera, check_convention="warn")
    res = hp.calibrate_handeye(robot_m, cell.target2camera, robot_unit="m")
    assert geo.translation_error(res.camera2flange, cell.camera2flange) < 1.0


# ----------------------------------------------------------------------------------------------
# near-orthonormal input


def test_rounded_rotations_are_reprojected_and_reported():
    cell = _cell(12, round_rotations=6)
    with pytest.raises(CalibrationError, match="re-project them to SO.3."):
        he.opencv_handeye(cell.flange2base, cell.target2camera, "Park")
    assert np.all(
        np.isfinite(he.opencv_handeye(cell.flange2base, cell.target2camera, "Park", tol=1e-5))
    )
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert 1e-8 < res.prepared.max_correction < 1e-5
    assert np.rad2deg(geo.rotation_error(res.camera2flange, cell.camera2flange)) < 0.1


def test_rotation_beyond_tolerance_is_refused_naming_the_pose():
    cell = _cell(13)
    bad = cell.target2camera.copy()
    bad[4, :3, :3] *= 1.001  # a scale error of 1e-3: max |R^T R - I| about 2e-3
    msg = r"camera rotation of pose 4 .*max \|R\^T R - I\| = 0.002 exceeds"
    with pytest.raises(CalibrationError, match=msg):
        hp.calibrate_handeye(cell.flange2base, bad)
    res = hp.calibrate_handeye(cell.flange2base, bad, ortho_tol=3e-3)
    assert res.prepared.worst_pose == 4


def test_reflection_is_refused():
    cell = _cell(14)
    bad = cell.flange2base.copy()
    bad[2, :3, 0] *= -1
    with pytest.raises(CalibrationError, match="pose 2 .*reflection"):
        hp.calibrate_handeye(bad, cell.target2camera)


# ----------------------------------------------------------------------------------------------
# degenerate motions


def test_pure_translations_are_refused():
    cell = _cell(15)
    a = cell.flange2base.copy()
    a[:, :3, :3] = a[0, :3, :3]
    b = geo.invert(a @ cell.camera2flange) @ cell.target2base
    with pytest.raises(
        CalibrationError,
        match=r"no pair of the 15 poses rotates by 2 deg or more \(largest 0 deg\): pure transl",
    ):
        hp.calibrate_handeye(a, b)


def test_rotations_about_one_axis_are_refused():
    cell = _cell(16, noise=False)
    angles = np.deg2rad(np.linspace(-40, 40, 10))
    a = cell.flange2base[0] @ geo.make_transform(
        geo.rotvec_to_matrix(np.outer(angles, [0.0, 0.0, 1.0])), np.zeros(3)
    )
    b = geo.perturb(
        geo.invert(a @ cell.camera2flange) @ cell.target2base,
        1e-3,
        0.2,
        np.random.default_rng(0),
    )
    with pytest.raises(
        CalibrationError,
        match=r"motions of the 10 poses turn about one axis \(axes within 0 deg, minimum 2 deg\)",
    ):
        hp.calibrate_robot_world_handeye(a, b)


def test_duplicate_poses_only_are_refused():
    cell = _cell(17)
    a = np.concatenate([cell.flange2base[:2]] * 5)
    b = np.concatenate([cell.target2camera[:2]] * 5)
    with pytest.raises(CalibrationError, match="10 poses are duplicates of only 2 distinct"):
        hp.calibrate_handeye(a, b)
    with pytest.raises(CalibrationError, match="at least 3 poses; got 2"):
        hp.calibrate_handeye(cell.flange2base[:2], cell.target2camera[:2])
