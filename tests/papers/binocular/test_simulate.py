"""Tests of calstudy.papers.binocular.simulate: the noise-free station returns the truth through
the paper's estimators; the random world scales as documented."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators import binocular as bino
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
    sensor = scenario.sensor
    _, points = exact_views(scenario)
    want = bino.distances_to_p7(scenario.layout)
    for p in points:
        uv_l, uv_r = sensor.project(p)
        got = bino.distances_to_p7(bino.with_virtual(bino.triangulate(sensor, uv_l, uv_r)))
        np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


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


def test_calibration_scale_scales_the_camera_errors_only(scenario):
    world = sim.draw_world(scenario, np.random.default_rng(4))
    zero, one, two = (world.model(scenario, s) for s in (0.0, 1.0, 2.0))
    nominal = scenario.sensor

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
