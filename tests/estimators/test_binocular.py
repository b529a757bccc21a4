"""Tests of calstudy.estimators.binocular: triangulation (Eq. 1), calibrator layout, observed-error
modification (Eq. 23-25) and the hand-eye checks (Eq. 13)."""

from __future__ import annotations

import numpy as np
import pytest
from support import binocular_rig

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.core.schema import read_toml
from calstudy.estimators import binocular as bino


@pytest.fixture(scope="module")
def sensor():
    return binocular_rig()


@pytest.fixture(scope="module")
def calibrator():
    """The calibrator table of ``data/binocular/calibrator.toml`` (Table 2)."""
    return read_toml(data_path("binocular", "calibrator.toml"), "calibrator")


def test_calibrator_layout_matches_table2(calibrator):
    pts, residual = bino.solve_calibrator_layout(
        calibrator["standard"]["distance_mm"], calibrator["standard"]["start_angle_deg"]
    )
    assert np.abs(residual).max() < 1e-9
    np.testing.assert_allclose(pts[6], pts[[1, 2, 4]].mean(0), atol=1e-12)
    np.testing.assert_allclose(pts[7], pts[[0, 3, 5]].mean(0), atol=1e-12)


def test_rays_that_do_not_intersect(sensor):
    p = np.array([[0.0, 0.0, 850.0], [30.0, 10.0, 860.0]])
    uv_l, uv_r = sensor.project(p)
    uv_r[1, 1] += 40.0  # 40 px of vertical disparity: about 3 mm of ray gap
    with pytest.raises(CalibrationError, match="miss each other"):
        bino.triangulate(sensor, uv_l, uv_r, tol_mm=0.5)


def test_modification_removes_distance_errors(calibrator):
    pts, _ = bino.solve_calibrator_layout(
        calibrator["standard"]["distance_mm"], calibrator["standard"]["start_angle_deg"]
    )
    rng = np.random.default_rng(0)
    measured = bino.with_virtual(pts[:6] + rng.normal(0, 0.02, (6, 3)))
    pairs = bino.all_pairs(8)
    standard = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    modified, _ = bino.modify_observed_error(measured, pairs, standard)
    before = bino.distances_to_p7(measured) - bino.distances_to_p7(pts)
    after = bino.distances_to_p7(modified) - bino.distances_to_p7(pts)
    assert np.abs(after).max() < 0.05 * np.abs(before).max()


def test_modification_keeps_p7_and_p8_the_centroids(calibrator):
    pts, _ = bino.solve_calibrator_layout(
        calibrator["standard"]["distance_mm"], calibrator["standard"]["start_angle_deg"]
    )
    rng = np.random.default_rng(2)
    measured = bino.with_virtual(pts[:6] + rng.normal(0, 0.05, (6, 3)))
    pairs = bino.all_pairs(8)
    standard = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    w = bino.virtual_weights()
    np.testing.assert_allclose(w @ measured[:6], measured, atol=1e-12)
    modified, delta = bino.modify_observed_error(measured, pairs, standard, combine=w)
    # the virtual targets move with their three SBRs: still exactly their centroids
    np.testing.assert_allclose(modified, bino.with_virtual(modified[:6]), atol=1e-9)
    np.testing.assert_allclose(delta, w @ delta[:6], atol=1e-12)
    before = bino.distances_to_p7(measured) - bino.distances_to_p7(pts)
    after = bino.distances_to_p7(modified) - bino.distances_to_p7(pts)
    assert np.abs(after).max() < 0.05 * np.abs(before).max()
    # every point free is the identity combination
    same, _ = bino.modify_observed_error(measured, pairs, standard, combine=np.eye(8))
    np.testing.assert_allclose(same, bino.modify_observed_error(measured, pairs, standard)[0])
    with pytest.raises(CalibrationError, match="combine must be"):
        bino.modify_observed_error(measured, pairs, standard, combine=np.eye(6))


def test_modification_needs_eight_distances():
    pts = np.random.default_rng(1).normal(0, 50, (8, 3))
    pairs = bino.all_pairs(8)[:7]
    with pytest.raises(CalibrationError, match="at least 8"):
        bino.modify_observed_error(pts, pairs, np.ones(7))


def test_axx_b_needs_two_rotation_axes():
    rot = geo.rotvec_to_matrix(np.array([[0, 0, a] for a in (0.0, 0.2, 0.4, 0.6)]))
    poses = geo.make_transform(rot, np.arange(12.0).reshape(4, 3))
    targets = geo.invert(poses)  # any target poses: the check comes first
    with pytest.raises(CalibrationError, match="turn about one axis"):
        bino.preliminary_handeye(poses, targets)
    still = geo.make_transform(np.eye(3)[None].repeat(3, 0), np.eye(3))
    with pytest.raises(CalibrationError, match="no pair of the 3 poses rotates"):
        bino.preliminary_handeye(still, geo.invert(still))


def test_batched_modification_and_triangulation_equal_one_by_one(calibrator, sensor):
    pts, _ = bino.solve_calibrator_layout(
        calibrator["standard"]["distance_mm"], calibrator["standard"]["start_angle_deg"]
    )
    rng = np.random.default_rng(1)
    sets = bino.with_virtual(pts[:6] + rng.normal(0, 0.02, (4, 6, 3)))
    pairs = bino.all_pairs(8)
    standard = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    w = bino.virtual_weights()
    for combine in (None, w):
        got, delta = bino.modify_observed_errors(sets, pairs, standard, combine=combine)
        for s, g, d in zip(sets, got, delta, strict=True):
            one, one_delta = bino.modify_observed_error(s, pairs, standard, combine=combine)
            np.testing.assert_array_equal(g, one)
            np.testing.assert_array_equal(d, one_delta)
    with pytest.raises(CalibrationError, match="standard distance #3 is -1 mm"):
        bad = np.tile(standard, (4, 1))
        bad[2, 2] = -1.0
        bino.modify_observed_errors(sets, np.tile(pairs, (4, 1, 1)), bad)
    world = sets[:, :6] + np.array([0.0, 0.0, 850.0])
    uv = np.array([sensor.project(p) for p in world])  # (4, 2 cameras, 6, 2)
    uv += rng.normal(0, 0.05, uv.shape)
    got = bino.triangulate_sets(sensor, uv[:, 0], uv[:, 1], 0.5)
    for g, u in zip(got, uv, strict=True):
        np.testing.assert_array_equal(g, bino.triangulate(sensor, u[0], u[1], 0.5))
    uv[2, 1, 4, 1] += 40.0  # the third set's fifth point misses
    with pytest.raises(CalibrationError, match="rays of point 4 miss each other"):
        bino.triangulate_sets(sensor, uv[:, 0], uv[:, 1], 0.5)
