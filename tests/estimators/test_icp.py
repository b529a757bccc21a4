"""Weighted point-to-point ICP (dualarm Eq. 4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.estimators import icp
from calstudy.estimators.fitting import fit_rigid


def sphere_cloud(rng, n=800, radius=25.0, centre=(10.0, -20.0, 300.0)):
    """A clean cap (upper half) of a sphere."""
    v = rng.normal(size=(4 * n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v = v[v[:, 2] > 0.2][:n]
    return np.asarray(centre) + radius * v


def test_icp_recovers_an_injected_drift_exactly():
    rng = np.random.default_rng(14)
    cloud = sphere_cloud(rng)
    drift = geo.perturb(np.eye(4), np.deg2rad(0.05), 0.3, rng)
    moved = geo.apply(geo.invert(drift), cloud)
    res = icp.weighted_icp(moved, cloud)
    assert res.converged
    assert geo.rotation_error(res.transform, drift) < 1e-12
    assert geo.translation_error(res.transform, drift) < 1e-9


def test_icp_solves_the_weighted_problem_of_eq4():
    """Sparse points (nearest neighbours are the true pairs) moved and perturbed: the ICP
    minimises Eq. 4 over those pairs, as scipy's least squares does; with z weight 1 it is the
    Kabsch fit."""
    rng = np.random.default_rng(15)
    ref = rng.uniform(-50, 50, (200, 3)) + [0.0, 0.0, 400.0]
    drift = geo.perturb(np.eye(4), np.deg2rad(0.05), 0.3, rng)
    moving = geo.apply(geo.invert(drift), ref) + rng.normal(0, 0.03, ref.shape)
    w = np.sqrt([1.0, 1.0, 20.0])

    def weighted(x):
        t = geo.make_transform(geo.rotvec_to_matrix(x[:3]), x[3:])
        return ((geo.apply(t, moving) - ref) * w).ravel()

    x = least_squares(weighted, np.zeros(6), xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    best = geo.make_transform(geo.rotvec_to_matrix(x[:3]), x[3:])
    res = icp.weighted_icp(moving, ref, z_threshold_mm=np.inf, tol=1e-10)
    assert res.converged and res.pairs == len(ref)
    np.testing.assert_allclose(res.transform, best, atol=1e-8)
    kabsch = icp.weighted_icp(moving, ref, z_weight=1.0, z_threshold_mm=np.inf, tol=1e-10)
    np.testing.assert_allclose(kabsch.transform, fit_rigid(moving, ref), atol=1e-8)
    # the weight does enter: the two fits differ by more than their tolerance
    assert np.abs(kabsch.transform - res.transform).max() > 1e-5


def test_icp_rejects_empty_clouds():
    with pytest.raises(CalibrationError, match=r"moving cloud is empty \(0 points\)"):
        icp.weighted_icp(np.zeros((0, 3)), np.ones((10, 3)))
    with pytest.raises(CalibrationError, match=r"reference cloud is empty"):
        icp.weighted_icp(np.ones((10, 3)), np.zeros((0, 3)))


def test_icp_rejects_clouds_that_do_not_overlap():
    rng = np.random.default_rng(16)
    cloud = sphere_cloud(rng)
    with pytest.raises(
        CalibrationError, match=r"do not overlap: 0 of 800 points.*closest 1\d\d mm"
    ):
        icp.weighted_icp(cloud + [150.0, 0, 0], cloud + [0, 0, 0.0])
