"""Binocular sensor, circle-of-confusion rectification and hand-eye update (notebook 04)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators import binocular as bino
from calstudy.models import optics as coc
from calstudy.papers.binocular import binocular_sim as bsim


@pytest.fixture(scope="module")
def scenario():
    return bsim.load_scenario()


@pytest.fixture(scope="module")
def sensor():
    return bino.StereoSensor.from_table()


def disk_image(size=41, radius=9.0, centre=(20.3, 19.6), blur=0.0):
    yy, xx = np.mgrid[0:size, 0:size]
    d = np.hypot(xx - centre[0], yy - centre[1])
    img = np.clip(radius + 0.5 - d, 0, 1).astype(np.float32) * 0.8 + 0.1
    return coc.defocus(img, blur) if blur else img


def exact_views(scenario, n=6, seed=3):
    """Calibrator views of the nominal station: flange poses and exact sensor-frame points."""
    rng = np.random.default_rng(seed)
    _, flange = bsim.viewpoints(scenario, scenario.calibrator2base, n, rng)
    pts = geo.apply(scenario.calibrator2base, scenario.layout[:6])
    sensor2base = flange @ scenario.sensor2flange
    return flange, np.array([geo.apply(geo.invert(s), pts) for s in sensor2base])


# ----------------------------------------------------------------------------------------------
# circle of confusion


def test_coc_radius_zero_at_focus_and_far_field_limit():
    assert coc.coc_radius_mm(850.0, 850.0, 55.5, 8.0) == 0.0
    # Eq. 5 is the limit of Eq. 4 for d >> f: ratio (d_A - f) / d_A
    near = coc.coc_radius_mm(900.0, 850.0, 55.5, 8.0)
    far = coc.coc_radius_far_mm(900.0, 850.0, 55.5, 8.0)
    assert far / near == pytest.approx((850.0 - 55.5) / 850.0, rel=1e-12)
    # textbook value: |dB - dA| f^2 / (dB (dA - f) N) is the blur diameter
    assert 2 * near == pytest.approx(50 * 55.5**2 / (900 * 794.5 * 8), rel=1e-12)
    with pytest.raises(CalibrationError, match="exceed the focal length"):
        coc.coc_radius_mm(40.0, 850.0, 55.5, 8.0)


def test_vectorised_rectification_equals_flowchart_loop():
    img = disk_image(size=23, radius=6.0, centre=(11.2, 10.7), blur=1.5)
    fast = coc.rectify_coc(img, 1.5)
    slow = coc.rectify_coc_reference(img, 1.5)
    inner = (slice(6, -6), slice(6, -6))  # away from the border handling
    # cv2.remap quantises sub-pixel positions to 1/32 px: up to |gradient| / 64 apart
    np.testing.assert_allclose(fast[inner], slow[inner], atol=5e-3)
    assert np.abs(fast[inner] - slow[inner]).mean() < 1e-3
    assert np.abs(fast - img).max() > 0.01  # it does change the image


def test_rectification_sharpens_and_keeps_a_symmetric_centre():
    # a dot centred on a pixel corner: the image is symmetric, so the centre must stay exactly
    blurred = disk_image(centre=(20.5, 19.5), blur=2.5)
    rect = coc.rectify_coc(blurred, 2.5)
    grad = lambda a: np.abs(np.diff(a[20])).max()  # noqa: E731
    assert grad(rect) > 1.3 * grad(blurred)
    np.testing.assert_allclose(coc.detect_centre(rect), [20.5, 19.5], atol=1e-5)


def test_rectification_does_not_depend_on_the_strip_height():
    img = disk_image(size=41, blur=2.0)
    np.testing.assert_array_equal(coc.rectify_coc(img, 2.0, 5), coc.rectify_coc(img, 2.0, 1000))


def test_rectification_rejects_a_tiny_radius_and_nan_pixels():
    with pytest.raises(CalibrationError, match="below 1/3 px"):
        coc.rectify_coc(disk_image(), 0.2)
    img = disk_image()
    img[3, 4] = np.nan
    with pytest.raises(CalibrationError, match="NaN or inf pixels"):
        coc.rectify_coc(img, 2.0)
    with pytest.raises(CalibrationError, match="not finite"):
        coc.coc_radius_px(np.nan, 850.0, 55.5, 8.0, 0.0046)


def test_render_and_detect_recover_the_projected_centre(sensor):
    k, dist = sensor.k_left, sensor.dist_left
    centre = np.array([60.0, -40.0, 850.0])
    normal = -centre / np.linalg.norm(centre)  # facing the camera
    uv, _ = cv2.projectPoints(centre[None], np.zeros(3), np.zeros(3), k, dist)
    uv = uv.reshape(2)
    origin, shape = coc.roi_around(uv, 2.5 * k[0, 0] / 850.0, 10, sensor.width, sensor.height)
    img = coc.render_dot(k, dist, centre, normal, 2.5, origin, shape)
    np.testing.assert_allclose(coc.detect_centre(img, origin), uv, atol=0.05)


def test_fusion_of_equal_images_is_the_image_and_checks_shapes():
    img = (disk_image() * 255).astype(np.uint8)
    np.testing.assert_allclose(coc.fuse_exposures([img, img]), img / 255.0, atol=1e-6)
    with pytest.raises(CalibrationError, match="one shape"):
        coc.fuse_exposures([img, img[:-1]])


def test_dot_not_found():
    with pytest.raises(CalibrationError, match="no dot found"):
        coc.detect_centre(np.full((30, 30), 0.4, np.float32), origin=(100, 200))


def test_dot_touching_the_roi_border():
    img = disk_image(size=41, radius=9.0, centre=(5.0, 20.0))
    with pytest.raises(CalibrationError, match="touches the border"):
        coc.detect_centre(img)


def test_dot_touching_the_image_border(sensor):
    with pytest.raises(CalibrationError, match="touches the border of the 7904 x 6004 image"):
        coc.roi_around([7890.0, 3000.0], 30.0, 10.0, sensor.width, sensor.height)


def test_ellipse_from_too_few_edge_points():
    img = disk_image(size=21, radius=1.2, centre=(10.0, 10.0))
    with pytest.raises(CalibrationError, match="edge points"):
        coc.detect_centre(img, min_points=20)


# ----------------------------------------------------------------------------------------------
# calibrator and stereo geometry


def test_calibrator_layout_matches_table2():
    cal = bino.load_toml("calibrator")
    pts, residual = bino.solve_calibrator_layout(
        cal["standard"]["distance_mm"], cal["standard"]["start_angle_deg"]
    )
    assert np.abs(residual).max() < 1e-9
    np.testing.assert_allclose(pts[6], pts[[1, 2, 4]].mean(0), atol=1e-12)
    np.testing.assert_allclose(pts[7], pts[[0, 3, 5]].mean(0), atol=1e-12)


def test_noise_free_pipeline_returns_the_standard_distances(scenario, sensor):
    """Exact sub-pixel centres through distortion, undistortion and triangulation: 1e-6 mm."""
    _, points = exact_views(scenario)
    want = bino.distances_to_p7(scenario.layout)
    for p in points:
        uv_l, uv_r = sensor.project(p)
        got = bino.distances_to_p7(bino.with_virtual(sensor.triangulate(uv_l, uv_r)))
        np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


def test_projection_matches_opencv_round_trip(sensor):
    p = np.array([[10.0, 20.0, 800.0], [-50.0, 5.0, 900.0]])
    uv_l, uv_r = sensor.project(p)
    np.testing.assert_allclose(sensor.normalise(uv_l, "left"), p[:, :2] / p[:, 2:], atol=1e-12)
    p_r = geo.apply(sensor.left2right, p)  # p_right = R p_left + t
    np.testing.assert_allclose(sensor.normalise(uv_r, "right"), p_r[:, :2] / p_r[:, 2:], atol=1e-12)
    with pytest.raises(CalibrationError, match="camera side"):
        sensor.normalise(uv_l, "Left")


def test_rays_that_do_not_intersect(sensor):
    p = np.array([[0.0, 0.0, 850.0], [30.0, 10.0, 860.0]])
    uv_l, uv_r = sensor.project(p)
    uv_r[1, 1] += 40.0  # 40 px of vertical disparity: about 3 mm of ray gap
    with pytest.raises(CalibrationError, match="miss each other"):
        sensor.triangulate(uv_l, uv_r, tol_mm=0.5)


# ----------------------------------------------------------------------------------------------
# observed-error modification (Eq. 23-25)


def test_modification_removes_distance_errors():
    cal = bino.load_toml("calibrator")
    pts, _ = bino.solve_calibrator_layout(
        cal["standard"]["distance_mm"], cal["standard"]["start_angle_deg"]
    )
    rng = np.random.default_rng(0)
    measured = bino.with_virtual(pts[:6] + rng.normal(0, 0.02, (6, 3)))
    pairs = bino.all_pairs(8)
    standard = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    modified, _ = bino.modify_observed_error(measured, pairs, standard)
    before = bino.distances_to_p7(measured) - bino.distances_to_p7(pts)
    after = bino.distances_to_p7(modified) - bino.distances_to_p7(pts)
    assert np.abs(after).max() < 0.05 * np.abs(before).max()


def test_modification_needs_eight_distances():
    pts = np.random.default_rng(1).normal(0, 50, (8, 3))
    pairs = bino.all_pairs(8)[:7]
    with pytest.raises(CalibrationError, match="at least 8"):
        bino.modify_observed_error(pts, pairs, np.ones(7))


# ----------------------------------------------------------------------------------------------
# hand-eye (Eq. 13-22)


def test_axx_b_needs_two_rotation_axes():
    rot = geo.rotvec_to_matrix(np.array([[0, 0, a] for a in (0.0, 0.2, 0.4, 0.6)]))
    poses = geo.make_transform(rot, np.arange(12.0).reshape(4, 3))
    targets = geo.invert(poses)  # any target poses: the check comes first
    with pytest.raises(CalibrationError, match="parallel"):
        bino.preliminary_handeye(poses, targets)
    with pytest.raises(CalibrationError, match="at least 2 rotations"):
        bino.check_rotation_axes(geo.make_transform(np.eye(3)[None].repeat(3, 0), np.eye(3)))


def test_noise_free_handeye_to_1e9(scenario):
    flange, points = exact_views(scenario)
    poses = np.array([bino.calibrator_pose(scenario.layout[:6], p) for p in points])
    pre = bino.preliminary_handeye(flange, poses)
    assert geo.rotation_error(pre, scenario.sensor2flange) < 1e-9
    assert geo.translation_error(pre, scenario.sensor2flange) < 1e-9
    pts8 = bino.with_virtual(points)
    upd, d_eta = bino.correct_transformation(flange, pre, pts8, pts8)
    assert np.abs(d_eta).max() < 1e-9
    assert geo.rotation_error(upd, scenario.sensor2flange) < 1e-9
    assert geo.translation_error(upd, scenario.sensor2flange) < 1e-9


def test_correction_uses_the_observed_error_terms(scenario):
    """Eq. 21 with measured points off by observed errors and modified points exact: the
    ``R dX`` terms must cancel those errors, so a wrong matrix is still recovered."""
    flange, points = exact_views(scenario)
    wrong = scenario.sensor2flange @ geo.exp6(np.array([0.3, -0.2, 0.4, 2e-4, -1e-4, 3e-4]))
    exact = bino.with_virtual(points)
    measured = exact + np.random.default_rng(4).normal(0.0, 0.05, exact.shape)
    upd, _ = bino.correct_transformation(flange, wrong, measured, exact)
    assert geo.translation_error(upd, scenario.sensor2flange) < 1e-3
    assert geo.rotation_error(upd, scenario.sensor2flange) < 1e-6
    # without the modification the same errors leave the matrix visibly off
    off, _ = bino.correct_transformation(flange, wrong, measured, measured)
    assert geo.translation_error(off, scenario.sensor2flange) > 10 * geo.translation_error(
        upd, scenario.sensor2flange
    )


def test_correction_recovers_a_perturbed_matrix(scenario):
    flange, points = exact_views(scenario)
    wrong = scenario.sensor2flange @ geo.exp6(np.array([0.3, -0.2, 0.4, 2e-4, -1e-4, 3e-4]))
    pts8 = bino.with_virtual(points)
    upd, _ = bino.correct_transformation(flange, wrong, pts8, pts8)
    assert geo.translation_error(upd, scenario.sensor2flange) < 1e-3
    assert geo.rotation_error(upd, scenario.sensor2flange) < 1e-6


# ----------------------------------------------------------------------------------------------
# the simulated station


def test_defocus_shift_grows_with_the_circle_of_confusion(scenario):
    table = bsim.defocus_shift(scenario, [850.0, 750.0])
    assert table["coc_radius_px"].iloc[0] == 0.0
    assert table["fused_shift_px"].iloc[1] > 3 * table["fused_shift_px"].iloc[0]
    assert table["fused_rectified_shift_px"].iloc[1] < table["fused_shift_px"].iloc[1]


def test_one_trial_runs_and_is_seeded(scenario):
    a = bsim.run_trial(scenario, np.random.default_rng(5))
    assert a["table2"].shape == (7, 2) and a["fig13"].shape == (10, 2)
    assert len(a["field"]) == 3
    assert np.all(np.abs(a["table2"] - a["standard"][:, None]) < 0.5)
    assert math.isfinite(a["fig13_standard"])
    # same seed, same numbers; skipping the field check (drawn last) changes nothing else
    b = bsim.run_trial(scenario, np.random.default_rng(5), field=False)
    assert b["field"] == []
    for key in ("standard", "table2", "table3", "fig13"):
        np.testing.assert_array_equal(a[key], b[key])
    np.testing.assert_array_equal(a["handeye"]["updated"], b["handeye"]["updated"])


def test_holdout_modification_does_not_see_the_evaluated_target(scenario):
    pairs = bino.all_pairs(8)
    layout = scenario.layout
    standard = np.linalg.norm(layout[pairs[:, 0]] - layout[pairs[:, 1]], axis=1)
    world = bsim.World(None, None, np.zeros((6, 3)), pairs, standard)
    measured = layout.copy()
    measured[0] += 0.05 * (layout[0] - layout[6]) / np.linalg.norm(layout[0] - layout[6])
    measured = bino.with_virtual(measured[:6])
    held = bsim.holdout_distances(measured, world)
    want = bino.distances_to_p7(layout)[:6]
    assert held[0, 1] - want[0] == pytest.approx(0.05, abs=1e-4)  # P1 kept its error
    full, _ = bino.modify_observed_error(measured, pairs, standard)
    assert abs(bino.distances_to_p7(full)[0] - want[0]) < 0.01  # the circular reading fixes it


def test_rendered_pipeline_without_noise_or_defocus(scenario):
    """Rendered, sharp, noise-free dots with a perfect sensor: distances to a few micrometres
    (pixel-level Canny edges limit a rendered centre to a few hundredths of a pixel)."""
    trial = bsim.run_trial(
        scenario, np.random.default_rng(2), imaging=bsim.Imaging(noise=False, defocus=False)
    )
    err = trial["table2"] - trial["standard"][:, None]
    assert np.abs(err).max() < 0.01
    np.testing.assert_array_equal(trial["table2"][:, 0], trial["table2"][:, 1])


def test_load_scenario_from_own_directory(tmp_path):
    import shutil

    from calstudy.core.paths import data_path

    for name in ("sensor", "calibrator", "station"):
        shutil.copy(data_path("binocular", f"{name}.toml"), tmp_path / f"{name}.toml")
    station = tmp_path / "station.toml"
    station.write_text(station.read_text().replace("p7_height_mm = 600.0", "p7_height_mm = 650.0"))
    default, own = bsim.load_scenario(), bsim.load_scenario(tmp_path)
    assert np.array_equal(own.layout, default.layout)
    assert own.calibrator2base[2, 3] == pytest.approx(default.calibrator2base[2, 3] + 50.0)
    (tmp_path / "calibrator.toml").unlink()
    with pytest.raises(CalibrationError, match=r"calibrator\.toml: no such file"):
        bsim.load_scenario(tmp_path)


# ----------------------------------------------------------------------------------------------
# sweep of the cameras' calibration errors


def test_calibration_scale_scales_the_camera_errors_only(scenario):
    def world(scale):
        return bsim.draw_world(scenario, np.random.default_rng(4), calibration_scale=scale)

    zero, one, two = world(0.0), world(1.0), world(2.0)
    nominal = scenario.sensor

    def errors(sensor):
        out = {n: getattr(sensor, n) - getattr(nominal, n) for n in ("k_left", "dist_left")}
        out |= {n: getattr(sensor, n) - getattr(nominal, n) for n in ("k_right", "dist_right")}
        out["translation"] = sensor.translation - nominal.translation
        out["rotation"] = geo.matrix_to_rotvec(sensor.rotation @ nominal.rotation.T)
        return out

    e0, e1, e2 = errors(zero.sensor), errors(one.sensor), errors(two.sensor)
    for name in e1:
        assert np.abs(e0[name]).max() == 0.0  # scale 0: the cameras of Table 1
        assert np.abs(e1[name]).max() > 0
        np.testing.assert_allclose(e2[name], 2 * e1[name], rtol=1e-6, atol=1e-12)
    # the same draws at every scale: the rest of the world does not change
    q = np.radians([10.0, -40.0, 30.0, 5.0, 50.0, -20.0])
    for other in (zero, two):
        np.testing.assert_array_equal(other.robot.fk(q), one.robot.fk(q))
        np.testing.assert_array_equal(other.dot_offsets, one.dot_offsets)
        np.testing.assert_array_equal(other.standard_mm, one.standard_mm)
    with pytest.raises(CalibrationError, match="calibration_scale"):
        world(-1.0)


def test_calibration_sweep_rows_and_verdicts(scenario):
    from calstudy.claims import VERDICTS

    sweep = bsim.calibration_sweep(scenario, 1, [0.0, 2.0], 2)
    assert sweep["calibration_scale"].tolist() == [0.0, 2.0]
    assert (sweep["n_trials"] == 2).all()
    # larger camera errors, larger distance errors; the modification fits them away
    assert sweep["t2_without"].iloc[1] > 2 * sweep["t2_without"].iloc[0]
    assert (sweep["t3_with"] < 0.2 * sweep["t3_without"]).all()
    for key in ("t2", "t3", "t3_holdout"):
        assert (sweep[f"{key}_ratio_low"] <= sweep[f"{key}_ratio"]).all()
        assert (sweep[f"{key}_ratio"] <= sweep[f"{key}_ratio_high"]).all()
    assert set(sweep["verdict_coc"]) | set(sweep["verdict_observed_error"]) <= set(VERDICTS)
    assert (sweep["verdict_observed_error"] != "not reproduced").all()
    with pytest.raises(CalibrationError, match="at least 2"):
        bsim.calibration_sweep(scenario, 1, [1.0], 1)
