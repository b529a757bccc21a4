"""Weighted point-to-point ICP (dualarm Eq. 4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.estimators import icp
from calstudy.estimators.fitting import fit_rigid, fit_sphere


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


def test_normal_equations_from_moments_match_the_dense_jacobian():
    """The 6 x 6 normal equations built from the 3 x 3 moments give the step of the explicit
    (N, 3, 6) Jacobian of Eq. 4."""
    rng = np.random.default_rng(17)
    p = rng.normal(size=(300, 3)) * [20.0, 30.0, 10.0] + [5.0, -3.0, 400.0]
    q = geo.apply(geo.perturb(np.eye(4), 0.01, 0.5, rng), p) + rng.normal(0, 0.05, p.shape)
    w = np.array([1.0, 1.0, 20.0])
    x = p - p.mean(axis=0)
    jac = np.zeros((len(p), 3, 6))
    jac[:, 0, 1], jac[:, 0, 2] = x[:, 2], -x[:, 1]
    jac[:, 1, 0], jac[:, 1, 2] = -x[:, 2], x[:, 0]
    jac[:, 2, 0], jac[:, 2, 1] = x[:, 1], -x[:, 0]
    jac[:, :, 3:] = np.eye(3)
    jac *= np.sqrt(w)[None, :, None]
    flat = jac.reshape(-1, 6)
    delta = -np.linalg.solve(flat.T @ flat, flat.T @ ((p - q) * np.sqrt(w)).ravel())
    rot = geo.rotvec_to_matrix(delta[:3])
    c = p.mean(axis=0)
    dense = geo.make_transform(rot, c - rot @ c + delta[3:])
    step, size = icp._weighted_rigid_step(p, q, w)
    np.testing.assert_allclose(step, dense, atol=1e-12)
    assert size > 1.0  # a 0.5 mm offset is far above 0.05 mm noise over 300 pairs


def test_stop_below_noise_ends_the_slide_but_not_a_real_correction():
    """Two differently sampled noisy caps of one sphere, 0.4 mm apart: stopping once the update
    is below its standard error takes fewer correspondence updates than the tolerance, and the
    sphere centre of the result is as good (the slide it cuts short is about the centre)."""
    rng = np.random.default_rng(18)
    centre = np.array([10.0, -20.0, 300.0])
    ref = sphere_cloud(rng, n=1000, centre=centre) + rng.normal(0, 0.03, (1000, 3))
    drift = geo.perturb(np.eye(4), np.deg2rad(0.02), 0.4, rng)
    moving = geo.apply(drift, sphere_cloud(rng, n=1000, centre=centre))
    moving += rng.normal(0, 0.03, moving.shape)
    full = icp.weighted_icp(moving, ref)
    fast = icp.weighted_icp(moving, ref, stop_below_noise=True)
    assert fast.converged and fast.iterations < full.iterations
    before = np.linalg.norm(fit_sphere(moving)[0] - centre)
    errs = [
        np.linalg.norm(fit_sphere(geo.apply(r.transform, moving))[0] - centre) for r in (full, fast)
    ]
    assert before > 0.2
    assert max(errs) < 0.25 * before
    # noise-free true pairs: the noise test never ends a real correction early
    exact = sphere_cloud(rng)
    res = icp.weighted_icp(geo.apply(geo.invert(drift), exact), exact, stop_below_noise=True)
    assert geo.translation_error(res.transform, drift) < 1e-9


def test_icp_refuses_bad_settings():
    cloud = sphere_cloud(np.random.default_rng(19))
    with pytest.raises(CalibrationError, match=r"z_weight -1.*must be > 0"):
        icp.weighted_icp(cloud, cloud, z_weight=-1.0)


def test_shift_shortcut_agrees_with_mapping_the_cloud():
    """The stop test decides from the step's translation at the pairs' centroid when it can;
    its answer is the one of mapping every point, on both sides of the tolerance."""
    rng = np.random.default_rng(20)
    cloud = sphere_cloud(rng) + [0.0, 0.0, 500.0]
    for scale in (1e-9, 3e-8, 1e-7, 5e-7, 1e-6, 2e-6, 1e-5, 1e-3):
        for _ in range(20):
            step = geo.perturb(np.eye(4), scale * 1e-3, scale, rng)
            keep = rng.random(len(cloud)) < 0.7
            direct = float(np.abs(geo.apply(step, cloud) - cloud).max()) < 1e-6
            assert icp._moves_less_than(step, cloud, cloud[keep], 1e-6) == direct


def test_kept_pairs_are_those_of_a_fresh_query():
    """The nearest neighbours kept between updates (the tree asked again only where they may
    have changed) are, update after update, those of a fresh query of the whole cloud: small
    steps, large jumps, points leaving and re-entering the pairing distance."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(21)
    ref = sphere_cloud(rng, n=1000)
    cloud = sphere_cloud(rng, n=1000)
    tree = cKDTree(ref)
    pairs = icp._Pairs(tree, ref, 2.0, 1)
    requeried = 0
    for k, (angle, shift) in enumerate([(0.0, 0.0)] + [(1e-4, 0.02)] * 20 + [(0.05, 3.0)] * 3):
        cloud = geo.apply(geo.perturb(np.eye(4), angle, shift, rng), cloud)
        at_before = None if pairs.at is None else pairs.at.copy()
        paired, idx = pairs.update(cloud)
        dist, fresh = tree.query(cloud, distance_upper_bound=2.0)
        np.testing.assert_array_equal(idx, fresh)
        np.testing.assert_array_equal(paired, np.isfinite(dist))
        if at_before is not None and k <= 20:
            requeried += int(np.any(pairs.at != at_before, axis=1).sum())
    assert not paired.all()  # the jumps took points out of reach
    assert requeried < 0.5 * 20 * len(cloud)  # small steps: most pairs kept without a query
