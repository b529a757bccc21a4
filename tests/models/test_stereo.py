"""Tests of calstudy.models.stereo: the one stereo rig of the binocular and dualarm papers."""

from __future__ import annotations

import numpy as np
import pytest
from support import binocular_rig

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig, stereo_rig

CAMERA = PinholeCamera(fx=2000.0, fy=1990.0, cx=640.0, cy=512.0, width=1280, height=1024)


@pytest.fixture(scope="module")
def sensor():
    return binocular_rig()


def test_projection_matches_opencv_round_trip(sensor):
    p = np.array([[10.0, 20.0, 800.0], [-50.0, 5.0, 900.0]])
    uv_l, uv_r = sensor.project(p)
    np.testing.assert_allclose(sensor.normalise(uv_l, "left"), p[:, :2] / p[:, 2:], atol=1e-12)
    p_r = geo.apply(sensor.left2right, p)  # p_right = R p_left + t
    np.testing.assert_allclose(sensor.normalise(uv_r, "right"), p_r[:, :2] / p_r[:, 2:], atol=1e-12)
    with pytest.raises(CalibrationError, match="camera side"):
        sensor.normalise(uv_l, "Left")


def test_table_rig_keeps_the_extrinsic_and_its_inverse(sensor):
    np.testing.assert_array_equal(sensor.left2right[:3, :3], sensor.rotation)
    np.testing.assert_array_equal(sensor.left2right[:3, 3], sensor.translation)
    np.testing.assert_allclose(sensor.right2left @ sensor.left2right, np.eye(4), atol=1e-12)
    assert sensor.left.distorted and sensor.right.distorted
    assert (sensor.left.width, sensor.left.height) == (7904, 6004)
    # the right camera sits to the right of the left one (+x) and both see 850 mm ahead
    assert sensor.right2left[0, 3] > 300.0
    aim = sensor.aim_point(850.0)
    assert np.linalg.norm(aim - 0.5 * sensor.right2left[:3, 3]) == pytest.approx(850.0)


def test_converging_rig_of_two_equal_cameras():
    rig = stereo_rig(CAMERA, 200.0, 1000.0)
    np.testing.assert_array_equal(rig.left2right, geo.invert(rig.right2left))
    uv_l, uv_r = rig.project(np.array([[0.0, 0.0, 1000.0]]))
    np.testing.assert_allclose(uv_l, [[640.0, 512.0]], atol=1e-9)
    np.testing.assert_allclose(uv_r, [[640.0, 512.0]], atol=1e-9)  # both aimed at the point
    with pytest.raises(CalibrationError, match="must be > 0"):
        stereo_rig(CAMERA, 0.0, 1000.0)


def test_rig_refuses_transforms_that_are_not_inverse():
    r2l = geo.make_transform(np.eye(3), [100.0, 0.0, 0.0])
    with pytest.raises(CalibrationError, match="not inverse"):
        StereoRig(CAMERA, CAMERA, r2l, r2l)
    with pytest.raises(CalibrationError, match="right2left"):
        StereoRig(CAMERA, CAMERA, np.eye(3))


def test_perturbed_rig_is_seeded_and_scales_with_the_sigmas(sensor):
    sigmas = {
        "focal_px": 0.5,
        "principal_point_px": 0.5,
        "k1": 2e-4,
        "extrinsic_rotation_rad": 5e-6,
        "extrinsic_translation_mm": 0.01,
    }
    a = sensor.perturbed(sigmas, np.random.default_rng(3))
    b = sensor.perturbed(sigmas, np.random.default_rng(3))
    np.testing.assert_array_equal(a.left2right, b.left2right)
    assert a.left == b.left and a.right == b.right
    assert a.left.dist[1:] == sensor.left.dist[1:] and a.left.dist[0] != sensor.left.dist[0]
    zero = sensor.perturbed(dict.fromkeys(sigmas, 0.0), np.random.default_rng(3))
    assert zero.left == sensor.left and zero.right == sensor.right
    np.testing.assert_array_equal(zero.left2right, sensor.left2right)
