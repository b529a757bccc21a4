"""Tests of calstudy.models.targets and calstudy.models.sensors."""

import dataclasses

import cv2
import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import geometry as g
from calstudy.estimators.fitting import fit_homography, homography_to_pose
from calstudy.models.sensors import LineLaserSensor, PinholeCamera, stripe_offset_recommended
from calstudy.models.targets import HoleTarget, Sphere, circle_image_centres

CAMERA = PinholeCamera(fx=2000.0, fy=1990.0, cx=640.0, cy=512.0, width=1280, height=1024)


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def facing_pose(distance=400.0, tilt=(0.2, -0.1, 0.05)):
    """target2cam: the target's front face towards the camera, slightly tilted."""
    rot = g.rotvec_to_matrix(np.array(tilt)) @ np.diag([1.0, -1.0, -1.0])
    return g.make_transform(rot, [5.0, -3.0, distance])


# ----------------------------------------------------------------------------------------------
# targets


def test_sphere_defaults_and_checks():
    s = Sphere()
    assert s.radius_mm == 12.7
    np.testing.assert_array_equal(s.centre, np.zeros(3))
    with pytest.raises(CalibrationError, match="radius must be positive; got -1"):
        Sphere(radius_mm=-1.0)
    with pytest.raises(CalibrationError, match=r"centre has shape \(2,\)"):
        Sphere(centre=[1.0, 2.0])


def test_hole_target_nominal_geometry():
    t = HoleTarget()
    front, back = t.front_points(), t.back_points()
    assert front.shape == back.shape == (35, 3)
    np.testing.assert_allclose(front.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_array_equal(front[:, 2], 0.0)
    np.testing.assert_allclose(front[1] - front[0], [10.0, 0.0, 0.0])
    np.testing.assert_allclose(front[7] - front[0], [0.0, 10.0, 0.0])
    np.testing.assert_allclose(back[:, 1], -front[:, 1])
    b2f = g.check_transform("back2front", t.back2front())
    np.testing.assert_allclose(
        b2f[:3, :3], g.rotvec_to_matrix(np.array([np.pi, 0.0, 0.0])), atol=1e-15
    )
    np.testing.assert_allclose(g.apply(b2f, back), front + [0.0, 0.0, -8.0], atol=1e-12)
    np.testing.assert_allclose(t.front2back() @ b2f, np.eye(4), atol=1e-15)
    with pytest.raises(CalibrationError, match="pitch_mm must be positive; got 0"):
        HoleTarget(pitch_mm=0.0)


def test_hole_target_manufactured(rng):
    t = HoleTarget()
    m = t.manufactured(rng)
    error = m.front_points - t.front_points()
    assert np.abs(error).max() <= 0.05 and np.abs(error).max() > 0.01
    np.testing.assert_array_equal(error[:, 2], 0.0)
    np.testing.assert_array_equal(m.back_points[:, 2], 0.0)
    g.check_transform("back2front", m.back2front)
    np.testing.assert_allclose(m.back2front[:3, :3], t.back2front()[:3, :3])
    offset = m.back2front[:3, 3] - t.back2front()[:3, 3]
    assert np.abs(offset).max() <= 0.05 and offset[2] == 0.0
    # the same straight hole axis: each back centre is its front centre moved by one vector
    shift = g.apply(m.back2front, m.back_points) - m.front_points
    np.testing.assert_allclose(shift, np.tile(offset + [0.0, 0.0, -8.0], (35, 1)), atol=1e-12)
    again = t.manufactured(np.random.default_rng(7))
    np.testing.assert_array_equal(again.front_points, m.front_points)


# ----------------------------------------------------------------------------------------------
# pinhole camera


def test_camera_projection_matches_opencv(rng):
    pts = rng.uniform(-50, 50, (20, 3)) + [0.0, 0.0, 400.0]
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), CAMERA.K, None)
    np.testing.assert_allclose(CAMERA.project(pts), uv[:, 0, :], atol=1e-9)


def test_camera_observe_noise(rng):
    t = HoleTarget()
    pose = facing_pose()
    truth = CAMERA.observe(pose, t.front_points(), 0.0, rng)
    noisy = np.stack([CAMERA.observe(pose, t.front_points(), 0.2, rng) for _ in range(200)])
    assert np.std(noisy - truth) == pytest.approx(0.2, rel=0.05)
    h = fit_homography(t.front_points()[:, :2], truth)
    est = homography_to_pose(h, CAMERA.K)
    assert g.rotation_error(est, pose) < 1e-9 and g.translation_error(est, pose) < 1e-9


def test_camera_back_side_view_chain(rng):
    """The back camera sees the back face: chain through the nominal back2front."""
    t = HoleTarget()
    front2cam = facing_pose(tilt=(np.pi, 0.0, 0.0))  # turned over: back face to the camera
    back2cam = front2cam @ t.back2front()
    uv = CAMERA.observe(back2cam, t.back_points(), 0.0, rng)
    est = homography_to_pose(fit_homography(t.back_points()[:, :2], uv), CAMERA.K)
    assert g.rotation_error(est, back2cam) < 1e-9
    assert g.translation_error(est @ t.front2back(), front2cam) < 1e-9


def test_camera_errors(rng):
    pts = np.array([[0, 0, 100.0], [1, 0, 100], [0, 1, 100], [0, 0, -120.0], [0, 0, -5.0]])
    with pytest.raises(CalibrationError, match=r"target behind the camera: point 3 at z = -120.0"):
        CAMERA.project(pts)
    with pytest.raises(CalibrationError, match=r"shape \(5, 2\)"):
        CAMERA.project(pts[:, :2])
    wide = HoleTarget(rows=3, cols=3, pitch_mm=400.0)
    with pytest.raises(
        CalibrationError,
        match=r"8 of 9 points fall outside the 1280 x 1024 image \(points 0, 1, 2, 3, 5",
    ):
        CAMERA.observe(facing_pose(tilt=(0, 0, 0)), wide.front_points(), 0.1, rng)
    uv = CAMERA.observe(facing_pose(), wide.front_points(), 0.1, rng, require_in_image=False)
    assert uv.shape == (9, 2)
    with pytest.raises(CalibrationError, match="sigma_px must be >= 0; got -1"):
        CAMERA.observe(facing_pose(), wide.front_points(), -1.0, rng)
    with pytest.raises(CalibrationError, match="focal lengths must be positive"):
        PinholeCamera(fx=0.0, fy=1.0, cx=0.0, cy=0.0, width=10, height=10)


# ----------------------------------------------------------------------------------------------
# line-laser sensor


R = 12.7


def centres_in_view(rng, n):
    y = rng.uniform(0.15, 0.85, n) * R
    return np.column_stack([rng.uniform(-20, 20, n), y, rng.uniform(120, 250, n)])


def test_line_laser_noise_free_exact(rng):
    exact = LineLaserSensor(sigma_point_mm=0.0)
    c = centres_in_view(rng, 50)
    np.testing.assert_allclose(exact.measure_sphere_centre(c, R, rng), c, atol=1e-9)
    np.testing.assert_allclose(exact.measure_sphere_centre(c[3], R, rng), c[3], atol=1e-9)
    mirrored = c * [1.0, -1.0, 1.0]
    lower = LineLaserSensor(sigma_point_mm=0.0, side=-1)
    np.testing.assert_allclose(lower.measure_sphere_centre(mirrored, R, rng), mirrored, atol=1e-9)
    through_centre = np.array([1.0, 0.0, 150.0])
    np.testing.assert_allclose(exact.measure_sphere_centre(through_centre, R, rng), through_centre)


def test_line_laser_noise_unbiased(rng):
    sensor = LineLaserSensor()
    c = np.array([4.0, stripe_offset_recommended(R), 180.0])
    shots = sensor.measure_sphere_centre(np.tile(c, (4000, 1)), R, rng)
    std = shots.std(axis=0, ddof=1)
    assert np.all(std > 0) and np.all(std < 0.1)
    standard_error = std / np.sqrt(len(shots))
    assert np.all(np.abs(shots.mean(axis=0) - c) < 4 * standard_error)
    repeat = sensor.centre_std(c, R, rng, n_shots=2000)
    np.testing.assert_allclose(repeat, std, rtol=0.1)
    # the stripe near a great circle fixes y worst (dy = -(r / y) dr)
    assert std[1] > std[0] and std[1] > std[2]


def test_line_laser_kasa_bias_is_small_but_real(rng):
    """The plain Kasa fit is biased on the visible arc: a tenth of the per-shot scatter."""
    c = np.array([4.0, stripe_offset_recommended(R), 180.0])
    shots = LineLaserSensor(circle_fit="kasa").measure_sphere_centre(np.tile(c, (4000, 1)), R, rng)
    bias, std = shots.mean(axis=0) - c, shots.std(axis=0, ddof=1)
    assert np.all(np.abs(bias) < 0.15 * std)
    assert abs(bias[1]) > 4 * std[1] / np.sqrt(len(shots))  # y comes out too large


def test_stripe_offset_recommended():
    assert stripe_offset_recommended(12.7) == pytest.approx(3.175)
    with pytest.raises(CalibrationError, match="radius must be positive"):
        stripe_offset_recommended(0.0)


def test_line_laser_errors(rng):
    sensor = LineLaserSensor()
    with pytest.raises(
        CalibrationError, match=r"laser plane misses the sphere: \|y\| = 26.0 mm >= radius 25.0"
    ):
        sensor.measure_sphere_centre([0.0, 26.0, 150.0], 25.0, rng)
    with pytest.raises(CalibrationError, match=r"misses the sphere: \|y\| = 25.0 mm"):
        sensor.measure_sphere_centre([0.0, 25.0, 150.0], 25.0, rng)  # grazing
    with pytest.raises(CalibrationError, match=r"behind the sensor: z = -150.0 mm at shot 1"):
        sensor.measure_sphere_centre([[0.0, 5.0, 150.0], [0.0, 5.0, -150.0]], 25.0, rng)
    with pytest.raises(CalibrationError, match=r"wrong side of the laser plane: y = -5.00 mm"):
        sensor.measure_sphere_centre([0.0, -5.0, 150.0], 25.0, rng)
    with pytest.raises(CalibrationError, match="sensor is inside the sphere"):
        sensor.measure_sphere_centre([0.0, 5.0, 10.0], 25.0, rng)
    with pytest.raises(CalibrationError, match=r"fitted stripe radius .* > sphere radius 25.0"):
        sensor.measure_sphere_centre(np.tile([0.0, 0.001, 150.0], (50, 1)), 25.0, rng)
    with pytest.raises(CalibrationError, match=r"centres_sensor has shape \(4,\)"):
        sensor.measure_sphere_centre([0.0, 1.0, 2.0, 3.0], 25.0, rng)
    with pytest.raises(CalibrationError, match="non-finite"):
        sensor.measure_sphere_centre([0.0, np.nan, 150.0], 25.0, rng)
    with pytest.raises(CalibrationError, match=r"empty \(0 sphere centres\)"):
        sensor.measure_sphere_centre(np.zeros((0, 3)), 25.0, rng)
    with pytest.raises(CalibrationError, match="side must be"):
        LineLaserSensor(side=0)


def test_camera_with_distortion_projects_like_opencv_and_undistorts_back():
    dist = (-0.18, 0.038, -1.2e-4, -2.1e-3)
    cam = dataclasses.replace(CAMERA, dist=dist)
    assert cam.distorted and not CAMERA.distorted
    p = np.array([[40.0, -30.0, 400.0], [-60.0, 20.0, 500.0]])
    want, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), CAMERA.K, np.array(dist))
    np.testing.assert_allclose(cam.project(p), want.reshape(-1, 2), atol=1e-9)
    np.testing.assert_allclose(cam.normalise(cam.project(p)), p[:, :2] / p[:, 2:], atol=1e-12)
    np.testing.assert_allclose(CAMERA.normalise(CAMERA.project(p)), p[:, :2] / p[:, 2:], atol=1e-12)
    with pytest.raises(CalibrationError, match="distortion"):
        PinholeCamera(fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=10, height=10, dist=(0.1, 0.2))


def test_line_laser_centre_covariance_matches_repeated_shots(rng):
    """The linearised covariance (strong y-z correlation) against 20,000 simulated shots."""
    sensor = LineLaserSensor()
    c = np.array([4.0, stripe_offset_recommended(R), 180.0])
    shots = sensor.measure_sphere_centre(np.tile(c, (20000, 1)), R, rng)
    empirical, model = np.cov(shots.T), sensor.centre_covariance(c, R)
    np.testing.assert_allclose(np.diag(model), np.diag(empirical), rtol=0.05)
    corr = model[1, 2] / np.sqrt(model[1, 1] * model[2, 2])
    corr_emp = empirical[1, 2] / np.sqrt(empirical[1, 1] * empirical[2, 2])
    assert corr < -0.9 and abs(corr - corr_emp) < 0.02
    batch = sensor.centre_covariance(np.tile(c, (2, 1)), R)
    np.testing.assert_allclose(batch[1], model)


# ------------------------------------------------------------- the image of a circular target


def _outline_centre(k, centre, normal, radius):
    """Centre of the conic fitted (algebraically, exact for exact points) to the projected
    outline of the circle: an independent route to the image ellipse's centre."""
    from calstudy.core import geometry as geo

    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    e1 = np.cross(n, [0.3, 0.9, 0.1])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    pts = centre + radius * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)
    uv = geo.apply(np.eye(4), pts) @ k.T
    x, y = (uv[:, :2] / uv[:, 2:]).T
    m = np.column_stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    a, b, c, d, e, _ = np.linalg.svd(m)[2][-1]
    return -np.linalg.solve([[a, b / 2], [b / 2, c]], [d / 2, e / 2])


def test_circle_image_centre_is_the_centre_of_the_projected_outline():
    from calstudy.core import geometry as geo
    from calstudy.models.targets import circle_centre_bias, circle_image_centres

    k = np.array([[2000.0, 0.0, 639.5], [0.0, 2000.0, 511.5], [0.0, 0.0, 1.0]])
    rng = np.random.default_rng(5)
    centres = rng.uniform([-80, -60, 400], [80, 60, 900], (6, 3))
    normals = geo.rotvec_to_matrix(rng.normal(0, 0.5, (6, 3))) @ [0.0, 0.0, -1.0]
    ours = circle_image_centres(k, centres, normals, 5.0)
    for c, n, o in zip(centres, normals, ours, strict=True):
        np.testing.assert_allclose(o, _outline_centre(k, c, n, 5.0), atol=1e-6)
    bias = circle_centre_bias(k, centres, normals, 5.0)
    assert np.all(np.linalg.norm(bias, axis=1) > 1e-3)  # a tilted circle is biased
    # the bias grows with the square of the radius (to first order) ...
    ratio = np.linalg.norm(circle_centre_bias(k, centres, normals, 2.5), axis=1) / np.linalg.norm(
        bias, axis=1
    )
    np.testing.assert_allclose(ratio, 0.25, rtol=0.02)
    # ... and vanishes for a circle facing the camera on its optical axis, or of radius 0
    facing = circle_centre_bias(k, [[0.0, 0.0, 500.0]], [[0.0, 0.0, -1.0]], 5.0)
    np.testing.assert_allclose(facing, 0.0, atol=1e-9)
    assert not np.any(circle_centre_bias(k, centres, normals, 0.0))


@pytest.mark.parametrize(
    ("centre", "normal", "radius", "match"),
    [
        ([0.0, 0.0, 500.0], [0.0, 0.0, 0.0], 5.0, "circle normal 0 is zero"),
        ([0.0, 0.0, -500.0], [0.0, 0.0, 1.0], 5.0, r"reaches depth -500 mm"),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0], 5.0, r"reaches depth -2 mm"),
        ([0.0, 0.0, 500.0], [1.0, 0.0, 0.0], 5.0, "seen edge-on"),
        ([0.0, float("nan"), 500.0], [0.0, 0.0, 1.0], 5.0, "circle centres holds a non-finite"),
        ([0.0, 0.0, 500.0], [0.0, 0.0, 1.0], -1.0, r"radius -1.0 mm must be finite and >= 0"),
    ],
)
def test_circle_image_refuses_circles_it_cannot_image(centre, normal, radius, match):
    k = np.array([[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]])
    with pytest.raises(CalibrationError, match=match):
        circle_image_centres(k, [centre], [normal], radius)


def test_circle_image_refuses_mismatched_shapes():
    k = np.eye(3)
    with pytest.raises(CalibrationError, match=r"must both be \(N, 3\)"):
        circle_image_centres(k, [[0.0, 0.0, 500.0]], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], 5.0)
    with pytest.raises(CalibrationError, match="camera matrix"):
        circle_image_centres(np.eye(4), [[0.0, 0.0, 500.0]], [[0.0, 0.0, 1.0]], 5.0)


def test_line_laser_noise_beyond_the_stripe_matches_its_covariance(rng):
    """A centre-noise floor and a weaker y-(x, z) correlation: 20,000 shots against the
    covariance the ML and the bound use; the correlation is scaled, the y variance kept."""
    c = np.array([4.0, stripe_offset_recommended(R), 180.0])
    plain = LineLaserSensor().centre_covariance(c, R)
    sensor = LineLaserSensor(centre_floor_mm=0.004, correlation_scale=0.5)
    shots = sensor.measure_sphere_centre(np.tile(c, (20000, 1)), R, rng)
    empirical, model = np.cov(shots.T), sensor.centre_covariance(c, R)
    np.testing.assert_allclose(np.diag(model), np.diag(plain) + 0.004**2)
    np.testing.assert_allclose(np.diag(model), np.diag(empirical), rtol=0.05)
    np.testing.assert_allclose(model[1, 2], 0.5 * plain[1, 2])
    assert abs(model[1, 2] - empirical[1, 2]) < 0.05 * np.sqrt(model[1, 1] * model[2, 2])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"centre_floor_mm": -0.01}, r"centre_floor_mm must be >= 0; got -0.01"),
        ({"correlation_scale": 1.5}, r"correlation_scale must be in \[0, 1\]; got 1.5"),
    ],
)
def test_line_laser_noise_beyond_the_stripe_refuses_bad_values(kwargs, match):
    with pytest.raises(CalibrationError, match=match):
        LineLaserSensor(**kwargs)
