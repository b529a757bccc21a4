"""The dual-arm chain: Tsai-Lenz, marker structure from motion, Eq. 11, weighted ICP, bad inputs."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd
import pytest
from scipy.optimize import least_squares

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.estimators import icp
from calstudy.estimators import sfm as mk
from calstudy.estimators.fitting import fit_rigid
from calstudy.papers.dualarm import dualarm as da
from calstudy.papers.dualarm import report


@pytest.fixture(scope="module")
def scenario():
    return da.load_scenario()


@pytest.fixture(scope="module")
def quiet(scenario):
    return scenario.noise_free()


def sphere_cloud(rng, n=800, radius=25.0, centre=(10.0, -20.0, 300.0)):
    """A clean cap (upper half) of a sphere."""
    v = rng.normal(size=(4 * n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v = v[v[:, 2] > 0.2][:n]
    return np.asarray(centre) + radius * v


# ----------------------------------------------------------------------------------------------
# the station read from the data files


def test_scenario_holds_the_paper_tables(scenario):
    assert scenario.markers.shape == (14, 3)
    assert np.bincount(scenario.marker_group).tolist() == [8, 6]
    # Table A2, base-to-base as rotation vector and translation
    rv = geo.matrix_to_rotvec(scenario.base2_to_base1[:3, :3])
    np.testing.assert_allclose(rv, [-7.582e-3, -3.056e-3, -0.746], atol=1e-12)
    np.testing.assert_allclose(scenario.base2_to_base1[:3, 3], [807.320, -1339.438, 20.040])
    # the two world-to-base transforms agree with base2_to_base1
    np.testing.assert_allclose(
        scenario.world2base[0], scenario.base2_to_base1 @ scenario.world2base[1], atol=1e-9
    )
    assert scenario.rig.left.width == 1280 and scenario.rig.left.height == 1024
    assert scenario.sphere_radius["A"] == pytest.approx(50.807 / 2)


# ----------------------------------------------------------------------------------------------
# noise-free chain: exact


def test_noise_free_base_to_base_is_exact(quiet):
    rng = np.random.default_rng(3)
    cam2flange, recon, b2b = da.calibrate_station(quiet, rng)
    for a in range(2):
        assert geo.rotation_error(cam2flange[a], quiet.cam2flange[a]) < 1e-9
        assert geo.translation_error(cam2flange[a], quiet.cam2flange[a]) < 1e-6
    assert recon.bundle.rms_px < 1e-6
    assert da.marker_error(quiet, recon.bundle.points) < 1e-8
    for name, t in b2b.items():
        assert geo.translation_error(t, quiet.base2_to_base1) < 1e-6, name
        assert geo.rotation_error(t, quiet.base2_to_base1) < 1e-9, name


def test_noise_free_world_location_is_exact(quiet):
    rng = np.random.default_rng(4)
    cam2world = da.view_poses(rng, quiet.group_centre(1), 500.0, 1, 0.3)[0]
    view = da.observe_markers(quiet, geo.invert(cam2world), rng)
    w2c = da.locate_world(quiet, view, quiet.markers)
    assert geo.translation_error(geo.invert(w2c), cam2world) < 1e-8
    assert geo.rotation_error(w2c, geo.invert(cam2world)) < 1e-11


def test_base_to_base_is_eq11(quiet):
    """Eq. 11 with exact poses gives the true transform, for any number of poses per arm."""
    rng = np.random.default_rng(5)
    flange, w2c = [], []
    for arm in (1, 2):
        cam2world = da.view_poses(rng, quiet.group_centre(arm), 500.0, 2 + arm, 0.4)
        true, reported = da.arm_poses(quiet, arm, cam2world, rng, drift=False)
        np.testing.assert_allclose(true, reported, atol=1e-12)
        flange.append(reported)
        w2c.append(geo.invert(cam2world))
    t = da.base_to_base(
        flange[0], quiet.cam2flange[0], w2c[0], flange[1], quiet.cam2flange[1], w2c[1]
    )
    np.testing.assert_allclose(t, quiet.base2_to_base1, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# Tsai-Lenz


def test_tsai_recovers_the_hand_eye_of_table_a2(quiet):
    rng = np.random.default_rng(6)
    flange, plate2cam = da.simulate_handeye(quiet, 2, rng)
    x = da.tsai_handeye(flange, plate2cam)
    assert geo.rotation_error(x, quiet.cam2flange[1]) < 1e-9
    assert geo.translation_error(x, quiet.cam2flange[1]) < 1e-6


def test_tsai_needs_three_poses(quiet):
    rng = np.random.default_rng(7)
    flange, plate2cam = da.simulate_handeye(quiet, 1, rng)
    with pytest.raises(CalibrationError, match="at least 3 poses.*got 2"):
        da.tsai_handeye(flange[:2], plate2cam[:2])


def test_tsai_rejects_a_pair_without_rotation(quiet):
    rng = np.random.default_rng(8)
    flange, plate2cam = da.simulate_handeye(quiet, 1, rng)
    flange, plate2cam = flange.copy(), plate2cam.copy()
    # pose 3 = pose 2 moved by a pure translation of the flange
    shift = geo.make_transform(np.eye(3), [20.0, 0.0, 0.0])
    flange[3] = flange[2] @ shift
    plate2cam[3] = geo.invert(quiet.cam2flange[0]) @ geo.invert(shift) @ quiet.cam2flange[0]
    plate2cam[3] = plate2cam[3] @ plate2cam[2]
    with pytest.raises(CalibrationError, match=r"poses 2 and 3 differ by a rotation of 0 deg"):
        da.tsai_handeye(flange, plate2cam)


# ----------------------------------------------------------------------------------------------
# markers: triangulation, graph, clustering, PnP, splice, bundle adjustment


def test_triangulation_matches_opencv(scenario):
    rng = np.random.default_rng(9)
    pts = rng.uniform([-80, -60, 420], [80, 60, 580], (20, 3))
    ul, ur = scenario.rig.project(pts)
    ul += rng.normal(0, 0.3, ul.shape)
    ur += rng.normal(0, 0.3, ur.shape)
    ours = mk.triangulate(scenario.rig, ul, ur)
    pl = scenario.rig.left.K @ np.eye(4)[:3]
    pr = scenario.rig.right.K @ scenario.rig.left2right[:3]
    h = cv2.triangulatePoints(pl, pr, ul.T, ur.T)
    ref = (h[:3] / h[3]).T
    # both are linear (DLT-type) solutions; they differ only at the noise level of the pixels
    assert np.abs(ours - ref).max() < 0.05
    exact = mk.triangulate(scenario.rig, *scenario.rig.project(pts))
    np.testing.assert_allclose(exact, pts, atol=1e-8)


def test_image_graph_and_clusters():
    views = [
        mk.make_view([0, 1, 2, 3, 4], np.zeros((5, 2)), np.zeros((5, 2))),
        mk.make_view([2, 3, 4, 5, 6], np.zeros((5, 2)), np.zeros((5, 2))),
        mk.make_view([3, 4, 5, 6, 7, 8], np.zeros((6, 2)), np.zeros((6, 2))),
        mk.make_view([9, 10, 11, 12], np.zeros((4, 2)), np.zeros((4, 2))),
    ]
    w = mk.image_graph(views)
    assert w.tolist() == [[0, 3, 2, 0], [3, 0, 4, 0], [2, 4, 0, 0], [0, 0, 0, 0]]
    clusters = mk.cluster_images(w, alpha=3)
    # view 1 covers 0, 1, 2; view 3 stands alone
    assert clusters == [(1, [0, 1, 2]), (3, [3])]


def test_disconnected_marker_graph_names_the_clusters(scenario):
    rng = np.random.default_rng(10)
    views = da.survey_views(scenario, rng, bridges=False)
    with pytest.raises(CalibrationError, match=r"not connected: cluster \d+ \(centre image \d+\)"):
        da.survey_markers(scenario, views)


def test_pnp_needs_four_markers(scenario):
    obj = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0]])
    uv = scenario.rig.left.project(obj + [0, 0, 500])
    with pytest.raises(CalibrationError, match="at least 4 markers; got 3"):
        mk.pnp_pose(obj, uv, scenario.rig.left)


def test_arm_without_four_markers_raises(quiet):
    view = mk.make_view([0, 1, 2], np.zeros((3, 2)), np.zeros((3, 2)))
    data = [(np.eye(4)[None], [view]), (np.eye(4)[None], [view])]
    with pytest.raises(CalibrationError, match=r"at least 4 markers; arm 1's views show \[3\]"):
        da.marker_base_to_base(quiet, quiet.cam2flange, quiet.markers, data)


def spliced(scn, rng):
    views = [v for v in da.survey_views(scn, rng) if v.ids.size >= 4]
    w = mk.image_graph(views)
    clusters = [mk.reconstruct_cluster(scn.rig, views, c, m) for c, m in mk.cluster_images(w, 4)]
    w2c, pts = mk.splice_clusters(clusters)
    ref = next(iter(w2c))
    poses = np.stack([w2c[j] for j in range(len(views))])
    points = np.full((len(scn.markers), 3), np.nan)
    for i, p in pts.items():
        points[i] = p
    return views, poses, points, ref


def test_bundle_adjustment_jacobians_agree(scenario):
    """The analytic sparse Jacobian and finite differences on jac_sparsity reach one minimum
    (with the depth-dependent weights of Eq. 10)."""
    views, poses, points, ref = spliced(scenario, np.random.default_rng(11))
    kw = dict(fixed_view=ref, sigma_px=0.1, sigma_mm=0.1, depth_ref_mm=500.0)
    a = mk.bundle_adjust(scenario.rig, views, poses, points, **kw)
    b = mk.bundle_adjust(scenario.rig, views, poses, points, jacobian="sparse-fd", **kw)
    assert a.rms_px == pytest.approx(b.rms_px, rel=1e-5)
    np.testing.assert_allclose(a.points, b.points, atol=1e-4)
    assert a.rms_px < 0.2  # pixel noise 0.1 px per coordinate
    assert da.marker_error(scenario, a.points) < da.marker_error(scenario, points)


def test_survey_with_a_poor_pnp_start_converges(scenario):
    """In this survey the cluster centre is a bridge image at 1000 mm; from PnP's pose of image 1
    on those markers the adjustment stopped in a false minimum at 4.9 px. The rigid fit of the
    image's own triangulated markers gives a start in the right basin."""
    rng = np.random.default_rng(38)
    for arm in (1, 2):
        da.simulate_handeye(scenario, arm, rng)
    views = da.survey_views(scenario, rng)
    recon = da.survey_markers(scenario, views)
    assert recon.bundle.rms_px < 0.2
    assert da.marker_error(scenario, recon.bundle.points) < 0.1
    row = report.survey_table(scenario, views, recon).iloc[0]
    assert row["images"] == len(views) >= row["images used (>= 4 markers)"] > 0
    assert row["clusters"] == len(recon.clusters)
    assert row["RMS reprojection (px)"] == recon.bundle.rms_px


def test_bundle_adjustment_rejects_bad_weights(scenario):
    views, poses, points, ref = spliced(scenario, np.random.default_rng(12))
    with pytest.raises(CalibrationError, match=r"depth_ref_mm \(0.0\) must be > 0"):
        mk.bundle_adjust(
            scenario.rig,
            views,
            poses,
            points,
            fixed_view=ref,
            sigma_px=0.1,
            sigma_mm=0.1,
            depth_ref_mm=0.0,
        )


def test_bundle_adjustment_divergence_raises(scenario):
    views, poses, points, ref = spliced(scenario, np.random.default_rng(12))
    bad = points + np.random.default_rng(0).normal(0, 150.0, points.shape)
    with pytest.raises(CalibrationError, match="bundle adjustment diverged: RMS reprojection"):
        mk.bundle_adjust(
            scenario.rig,
            views,
            poses,
            bad,
            fixed_view=ref,
            sigma_px=0.1,
            sigma_mm=0.1,
            max_nfev=3,
        )


def test_ransac_pnp_rejects_gross_errors(scenario):
    rng = np.random.default_rng(13)
    c2w = da.view_poses(rng, [0.0, 0.0, 0.0], 500.0, 1, 0.6, axis=(0, 0.57, 0.82))[0]
    true = geo.invert(c2w)
    uv = scenario.rig.left.observe(true, scenario.plate_points, 0.0, rng)
    uv[::7] += 15.0
    est = da.ransac_pnp(scenario.plate_points, uv, scenario.rig.left, 1.0)
    assert geo.translation_error(est, true) < 1e-6
    assert geo.rotation_error(est, true) < 1e-9


# ----------------------------------------------------------------------------------------------
# weighted ICP


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


# ----------------------------------------------------------------------------------------------
# the experiments on the noisy station


def test_icp_experiment_lowers_the_errors(scenario):
    df = da.icp_experiment(scenario, scenario.cam2flange, np.random.default_rng(17))
    assert len(df) == 2 * 2 * (scenario.icp_views - 1)
    assert df["after_mm"].mean() < df["before_mm"].mean()


# ----------------------------------------------------------------------------------------------
# tables and verdicts


def fake_trials(n=6, after=0.15, ours=0.100, circ=0.556):
    rng = np.random.default_rng(18)
    icp_rows = [
        {"arm": a, "sphere": s, "view": v, "trial": t, "before_mm": b, "after_mm": b * after}
        for t in range(n)
        for a in (1, 2)
        for s in ("A", "B")
        for v in (1, 2)
        for b in [1.0 + 0.1 * rng.random()]
    ]
    glob = [
        {
            "method": m,
            "group": g,
            "pose": k,
            "trial": t,
            "dx_mm": e / 2,
            "dy_mm": e / 2,
            "dz_mm": e / 2,
            "euclid_mm": e,
            "euclid_truth_mm": e,
        }
        for t in range(n)
        for m, base in (("coded markers", ours), ("circular plate", circ))
        for g in (1, 2, 3)
        for k in (1, 2, 3)
        for e in [base * (1 + 0.05 * rng.standard_normal())]
    ]
    return {"icp": pd.DataFrame(icp_rows), "global": pd.DataFrame(glob)}


def test_claims_reproduce_the_published_numbers_when_the_data_do():
    published = report.load_published()
    rows = report.dualarm_claims(fake_trials(), published, "nb")
    assert [r.id for r in rows] == ["dualarm.icp", "dualarm.global", "dualarm.vs_circular"]
    assert [r.verdict for r in rows] == ["reproduced"] * 3
    assert rows[2].reproduced == pytest.approx(0.18, rel=0.1)
    worse = report.dualarm_claims(fake_trials(after=1.2, ours=0.9), published, "nb")
    assert [r.verdict for r in worse] == ["not reproduced", "direction only", "not reproduced"]
    assert "not testable" in worse[2].note


def test_table3_marks_the_instruments_not_testable():
    t3 = report.table3(fake_trials()["global"], report.load_published())
    assert t3["testable"].tolist() == ["not testable", "not testable", "yes", "yes"]
    assert t3.loc[t3["method"] == "circular plate", "published_euclid_mm"].item() == 0.556
    assert np.isnan(t3.loc[0, "euclid_mm"])
