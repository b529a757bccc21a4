"""Tests of calstudy.papers.binocular.simulate: the noise-free station returns the truth through
the paper's estimators; the random world scales as documented."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators import binocular as bino
from calstudy.estimators.fitting import fit_rigid
from calstudy.papers.binocular import simulate as sim
from calstudy.papers.binocular.scenario import load_scenario


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


def exact_views(scenario, n=6, seed=3):
    """Calibrator views of the nominal station: flange poses and exact sensor-frame points."""
    rng = np.random.default_rng(seed)
    _, flange = sim.viewpoints(scenario, scenario.calibrator2base, n, rng)
    pts = geo.apply(scenario.calibrator2base, scenario.layout[:6])
    sensor2base = flange @ scenario.sensor2flange
    return flange, np.array([geo.apply(geo.invert(s), pts) for s in sensor2base])


def test_noise_free_pipeline_returns_the_standard_distances(scenario):
    """Exact sub-pixel centres through distortion, undistortion and triangulation: 1e-6 mm."""
    sensor = scenario.rig
    _, points = exact_views(scenario)
    want = bino.distances_to_p7(scenario.layout)
    for p in points:
        uv_l, uv_r = sensor.project(p)
        got = bino.distances_to_p7(bino.with_virtual(bino.triangulate(sensor, uv_l, uv_r)))
        np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


def test_noise_free_handeye_to_1e9(scenario):
    flange, points = exact_views(scenario)
    poses = np.array([fit_rigid(scenario.layout[:6], p) for p in points])
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


def test_calibration_scale_scales_the_camera_errors_only(scenario):
    world = sim.draw_world(scenario, np.random.default_rng(4))
    zero, one, two = (world.model(scenario, s) for s in (0.0, 1.0, 2.0))
    nominal = scenario.rig

    def errors(sensor):
        out = {}
        for side in ("left", "right"):
            cam, ref = sensor.camera(side), nominal.camera(side)
            out[f"k_{side}"] = cam.K - ref.K
            out[f"dist_{side}"] = cam.dist_coeffs - ref.dist_coeffs
        out["translation"] = sensor.translation - nominal.translation
        out["rotation"] = geo.matrix_to_rotvec(sensor.rotation @ nominal.rotation.T)
        return out

    e0, e1, e2 = errors(zero), errors(one), errors(two)
    for name in e1:
        assert np.abs(e0[name]).max() == 0.0  # scale 0: the cameras of Table 1
        assert np.abs(e1[name]).max() > 0
        np.testing.assert_allclose(e2[name], 2 * e1[name], rtol=1e-6, atol=1e-12)
    # the robot's errors scale the same way, from the same draws
    q = np.radians([10.0, -40.0, 30.0, 5.0, 50.0, -20.0])
    nom = scenario.robot.fk(q)
    d1 = world.robot(scenario, 1.0).fk(q) - nom
    d2 = world.robot(scenario, 2.0).fk(q) - nom
    assert np.abs(d1).max() > 0
    np.testing.assert_allclose(d2[:3, 3], 2 * d1[:3, 3], rtol=0.02, atol=1e-3)
    np.testing.assert_allclose(world.robot(scenario, 0.0).fk(q), nom, atol=1e-9)
    with pytest.raises(CalibrationError, match="calibration scale"):
        world.model(scenario, -1.0)


def _ray_traced_spot(scenario, point_cam, n=401):
    """Independent thin-lens ray trace of one camera-frame object point: every ray through a
    uniform grid on the entrance pupil (radius f / 2F at the lens) that passes the rim (radius R,
    L in front of the pupil) is followed to the sensor (at the lens-to-sensor distance
    ``fx * pitch``). Returns the landing points minus the chief ray's, in image px (u along the
    camera's x, v along y: the sensor image is inverted), and the geometric blur radius, px."""
    opt = scenario.sensor.optics
    pitch = scenario.sensor.image.pixel_pitch_mm
    f = scenario.focal_mm
    a = f / (2.0 * opt.f_number)
    v = scenario.rig.left.fx * pitch
    x, y, z = point_cam
    g = np.linspace(-a, a, n)
    px, py = np.meshgrid(g, g)
    inside = px**2 + py**2 <= a**2
    lam = opt.rim_distance_mm / z  # the ray from the point to the pupil at the rim's plane
    rim_x, rim_y = px + (x - px) * lam, py + (y - py) * lam
    passes = inside & (rim_x**2 + rim_y**2 <= opt.rim_radius_mm ** 2)
    v_img = 1.0 / (1.0 / f - 1.0 / z)  # where the point is imaged sharply
    land_x = px + (-x * v_img / z - px) * v / v_img
    land_y = py + (-y * v_img / z - py) * v / v_img
    offsets = -np.column_stack([land_x[passes] + x * v / z, land_y[passes] + y * v / z]) / pitch
    return offsets, a * abs(1.0 - v / v_img) / pitch


@pytest.mark.parametrize("depth", [780.0, 940.0])
@pytest.mark.parametrize(
    ("f_number", "field_deg", "cut"),
    [(8.0, 6.0, False), (8.0, 10.0, False), (4.0, 6.0, False), (4.0, 14.0, True)],
)
def test_blur_spot_agrees_with_a_thin_lens_ray_trace(scenario, depth, f_number, field_deg, cut):
    """The CoC radius (Eq. 4, px) is the ray-traced blur radius, and the centroid of the rim-cut
    spot (:func:`blur_spots`, :func:`calstudy.models.optics.defocus_kernel`) is the ray trace's:
    within 15 % where the rim cuts the pupil (outwards for a nearer point, inwards for a farther
    one), and nil (< 0.02 px) where the rim clears it. A wrong spot inversion, rim side or
    depth, or a rim that cuts the Gaussian's tail, fails here (the perspective factor of the
    rim's footprint, a 4 % effect here, is checked in the optics tests)."""
    from calstudy.models import optics

    sc = scenario.replace({"sensor.optics.f_number": f_number})
    field = math.tan(math.radians(field_deg)) * np.array([0.8, 0.6])
    point = depth * np.array([field[0], field[1], 1.0])
    offsets, radius = _ray_traced_spot(sc, point)
    deltas, sides, rims = sim.blur_spots(sc, point)
    assert deltas[0] == pytest.approx(radius, rel=1e-9)
    traced = offsets.mean(axis=0)
    k = optics.defocus_kernel(float(deltas[0]), float(sides[0]), rims[0, :2], float(rims[0, 2]))
    h = k.shape[0] // 2
    jj, ii = np.mgrid[-h : h + 1, -h : h + 1]
    model = np.array([(k * ii).sum(), (k * jj).sum()])
    if not cut:  # the rim clears the pupil: no shift in the trace nor in the model
        assert np.linalg.norm(traced) < 1e-9
        assert np.linalg.norm(model) < 0.02
        return
    assert np.linalg.norm(traced) > 0.1 * radius  # the rim does cut the spot
    assert np.linalg.norm(model - traced) < 0.15 * np.linalg.norm(traced)
    outward = traced @ field
    assert (outward > 0) == (depth < sc.sensor.optics.focus_distance_mm)


def test_world_builds_each_robot_once_and_replace_starts_afresh(scenario):
    world = sim.draw_world(scenario, np.random.default_rng(4))
    q = np.radians([10.0, -40.0, 30.0, 5.0, 50.0, -20.0])
    one = world.robot(scenario, 1.0)
    assert world.robot(scenario, 1.0) is one and world.robot(scenario, 2.0) is not one
    fresh = dataclasses.replace(world)  # the same seeds: equal robots, built again
    assert fresh.robot(scenario, 1.0) is not one
    np.testing.assert_array_equal(fresh.robot(scenario, 1.0).fk(q), one.fk(q))
    other = dataclasses.replace(world, robot_seed=world.robot_seed + 1)
    assert np.abs(other.robot(scenario, 1.0).fk(q) - one.fk(q)).max() > 1e-6
