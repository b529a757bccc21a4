"""The dual-arm chain: Tsai-Lenz, marker structure from motion, Eq. 11, RANSAC-PnP, weighted ICP
on the simulated station, bad inputs."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.estimators import sfm as mk
from calstudy.estimators.bundle import bundle_adjust
from calstudy.estimators.fitting import solve_pnp_ransac
from calstudy.estimators.stereo_views import make_view
from calstudy.papers.dualarm import experiments as ex
from calstudy.papers.dualarm import report
from calstudy.papers.dualarm import simulate as sim


def test_noise_free_base_to_base_is_exact(quiet):
    rng = np.random.default_rng(3)
    cam2flange, recon, ours = ex.coded_marker_chain(quiet, rng)
    b2b = {"coded markers": ours, "circular plate": ex.plate_base_to_base(quiet, cam2flange, rng)}
    for a in range(2):
        assert geo.rotation_error(cam2flange[a], quiet.calibration.cam2flange[a]) < 1e-9
        assert geo.translation_error(cam2flange[a], quiet.calibration.cam2flange[a]) < 1e-6
    assert recon.bundle.rms_px < 1e-6
    assert ex.marker_error(quiet, recon.bundle.points) < 1e-8
    for name, t in b2b.items():
        assert geo.translation_error(t, quiet.calibration.base2_to_base1) < 1e-6, name
        assert geo.rotation_error(t, quiet.calibration.base2_to_base1) < 1e-9, name


def test_noise_free_world_location_is_exact(quiet):
    rng = np.random.default_rng(4)
    cam2world = sim.view_poses(rng, quiet.markers.group_centre(1), 500.0, 1, 0.3)[0]
    view = sim.observe_markers(quiet, geo.invert(cam2world), rng)
    w2c = ex.locate_world(quiet, view, quiet.markers.xyz)
    assert geo.translation_error(geo.invert(w2c), cam2world) < 1e-8
    assert geo.rotation_error(w2c, geo.invert(cam2world)) < 1e-11


def test_tsai_recovers_the_hand_eye_of_table_a2(quiet):
    rng = np.random.default_rng(6)
    flange, plate2cam = ex.handeye_data(quiet, 2, rng)
    x = he.opencv_handeye(flange, plate2cam, "Tsai", he.MIN_PAIR_ROTATION)
    assert geo.rotation_error(x, quiet.calibration.cam2flange[1]) < 1e-9
    assert geo.translation_error(x, quiet.calibration.cam2flange[1]) < 1e-6


def test_tsai_needs_three_poses(quiet):
    rng = np.random.default_rng(7)
    flange, plate2cam = ex.handeye_data(quiet, 1, rng)
    with pytest.raises(CalibrationError, match="at least 3 poses.*got 2"):
        he.opencv_handeye(flange[:2], plate2cam[:2], "Tsai", he.MIN_PAIR_ROTATION)


def test_tsai_accepts_a_pair_without_rotation(quiet):
    """A move without rotation (valid data) is used, not refused: the hand-eye stays exact."""
    rng = np.random.default_rng(8)
    flange, plate2cam = ex.handeye_data(quiet, 1, rng)
    flange, plate2cam = flange.copy(), plate2cam.copy()
    # pose 3 = pose 2 moved by a pure translation of the flange
    shift = geo.make_transform(np.eye(3), [20.0, 0.0, 0.0])
    flange[3] = flange[2] @ shift
    c2f = quiet.calibration.cam2flange[0]
    plate2cam[3] = geo.invert(c2f) @ geo.invert(shift) @ c2f
    plate2cam[3] = plate2cam[3] @ plate2cam[2]
    x = he.opencv_handeye(flange, plate2cam, "Tsai", he.MIN_PAIR_ROTATION)
    assert geo.rotation_error(x, quiet.calibration.cam2flange[0]) < 1e-9
    assert geo.translation_error(x, quiet.calibration.cam2flange[0]) < 1e-6


def test_triangulation_matches_opencv(scenario):
    rng = np.random.default_rng(9)
    pts = rng.uniform([-80, -60, 420], [80, 60, 580], (20, 3))
    ul, ur = scenario.rig.project(pts)
    ul += rng.normal(0, 0.3, ul.shape)
    ur += rng.normal(0, 0.3, ur.shape)
    ours = scenario.rig.triangulate(ul, ur)
    pl = scenario.rig.left.K @ np.eye(4)[:3]
    pr = scenario.rig.right.K @ scenario.rig.left2right[:3]
    h = cv2.triangulatePoints(pl, pr, ul.T, ur.T)
    ref = (h[:3] / h[3]).T
    # the same linear solution, on pixels here and on normalised coordinates in the rig
    assert np.abs(ours - ref).max() < 1e-8
    exact = scenario.rig.triangulate(*scenario.rig.project(pts))
    np.testing.assert_allclose(exact, pts, atol=1e-8)


def test_disconnected_marker_graph_names_the_clusters(scenario):
    rng = np.random.default_rng(10)
    views = sim.survey_views(scenario, rng, bridges=False)
    with pytest.raises(CalibrationError, match=r"not connected: cluster \d+ \(centre image \d+\)"):
        ex.survey_markers(scenario, views)


def test_pnp_needs_four_markers(scenario):
    obj = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0]])
    uv = scenario.rig.left.project(obj + [0, 0, 500])
    with pytest.raises(CalibrationError, match="at least 4 markers; got 3"):
        mk.pnp_pose(obj, uv, scenario.rig.left)


def test_arm_without_four_markers_raises(quiet):
    view = make_view([0, 1, 2], np.zeros((3, 2)), np.zeros((3, 2)))
    data = [(np.eye(4)[None], [view]), (np.eye(4)[None], [view])]
    with pytest.raises(CalibrationError, match=r"at least 4 markers; arm 1's views show \[3\]"):
        ex.marker_base_to_base(quiet, quiet.calibration.cam2flange, quiet.markers.xyz, data)


def spliced(scn, rng):
    views = [v for v in sim.survey_views(scn, rng) if v.ids.size >= 4]
    w = mk.image_graph(views)
    clusters = [mk.reconstruct_cluster(scn.rig, views, c, m) for c, m in mk.cluster_images(w, 4)]
    w2c, pts = mk.splice_clusters(clusters)
    ref = next(iter(w2c))
    poses = np.stack([w2c[j] for j in range(len(views))])
    points = np.full((len(scn.markers.xyz), 3), np.nan)
    for i, p in pts.items():
        points[i] = p
    return views, poses, points, ref


def test_bundle_adjustment_jacobians_agree(scenario):
    """The analytic sparse Jacobian and finite differences on jac_sparsity reach one minimum
    (with the depth-dependent weights of Eq. 10)."""
    views, poses, points, ref = spliced(scenario, np.random.default_rng(11))
    kw = dict(fixed_view=ref, sigma_px=0.1, sigma_mm=0.1, depth_ref_mm=500.0)
    a = bundle_adjust(scenario.rig, views, poses, points, **kw)
    b = bundle_adjust(scenario.rig, views, poses, points, jacobian="sparse-fd", **kw)
    assert a.rms_px == pytest.approx(b.rms_px, rel=1e-5)
    np.testing.assert_allclose(a.points, b.points, atol=1e-4)
    assert a.rms_px < 0.2  # pixel noise 0.1 px per coordinate
    assert ex.marker_error(scenario, a.points) < ex.marker_error(scenario, points)


def test_survey_with_a_poor_pnp_start_converges(scenario):
    """In this survey the cluster centre is a bridge image at 1000 mm; from PnP's pose of image 1
    on those markers the adjustment stopped in a false minimum at 4.9 px. The rigid fit of the
    image's own triangulated markers gives a start in the right basin."""
    rng = np.random.default_rng(38)
    for arm in (1, 2):
        ex.handeye_data(scenario, arm, rng)
    views = sim.survey_views(scenario, rng)
    recon = ex.survey_markers(scenario, views)
    assert recon.bundle.rms_px < 0.2
    assert ex.marker_error(scenario, recon.bundle.points) < 0.1
    row = report.survey_table(scenario, views, recon).iloc[0]
    assert row["images"] == len(views) >= row["images used (>= 4 markers)"] > 0
    assert row["clusters"] == len(recon.clusters)
    assert row["RMS reprojection (px)"] == recon.bundle.rms_px


def test_bundle_adjustment_rejects_bad_weights(scenario):
    views, poses, points, ref = spliced(scenario, np.random.default_rng(12))
    kw = dict(fixed_view=ref, sigma_px=0.1, sigma_mm=0.1, depth_ref_mm=0.0)
    with pytest.raises(CalibrationError, match=r"depth_ref_mm \(0.0\) must be > 0"):
        bundle_adjust(scenario.rig, views, poses, points, **kw)


def test_bundle_adjustment_divergence_raises(scenario):
    views, poses, points, ref = spliced(scenario, np.random.default_rng(12))
    bad = points + np.random.default_rng(0).normal(0, 150.0, points.shape)
    kw = dict(fixed_view=ref, sigma_px=0.1, sigma_mm=0.1, max_nfev=3)
    with pytest.raises(CalibrationError, match="bundle adjustment diverged: RMS reprojection"):
        bundle_adjust(scenario.rig, views, poses, bad, **kw)


def test_ransac_pnp_rejects_gross_errors(scenario):
    rng = np.random.default_rng(13)
    c2w = sim.view_poses(rng, [0.0, 0.0, 0.0], 500.0, 1, 0.6, axis=(0, 0.57, 0.82))[0]
    true = geo.invert(c2w)
    uv = scenario.rig.left.observe(true, scenario.handeye.plate_points, 0.0, rng)
    uv[::7] += 15.0
    est = solve_pnp_ransac(scenario.handeye.plate_points, uv, scenario.rig.left.K, 1.0)
    assert geo.translation_error(est, true) < 1e-6
    assert geo.rotation_error(est, true) < 1e-9


def test_icp_experiment_lowers_the_errors(scenario):
    rows = ex.icp_rows(scenario, scenario.calibration.cam2flange, np.random.default_rng(17))
    df = pd.DataFrame(rows)
    assert len(df) == 2 * 2 * (scenario.icp.n_views - 1)
    assert df["after_mm"].mean() < 0.5 * df["before_mm"].mean()
    # the oracle (true poses and hand-eye) leaves only the sphere-fit noise
    assert df["oracle_mm"].mean() < 0.2 * df["after_mm"].mean()


def test_the_global_test_floor_lies_far_below_the_claim(scenario):
    """With every calibrated transform true, the Tables 1-2 test measures a
    few hundredths of a millimetre, far below the claimed 0.100 mm."""
    rng = np.random.default_rng(21)
    rows = pd.DataFrame(ex.global_rows(scenario, scenario.calibration.cam2flange, {}, rng))
    assert (rows["method"] == "true calibration").all() and len(rows) == 9
    assert rows["euclid_mm"].mean() < 0.03


def test_split_survey_error_keeps_one_part_each(scenario):
    """The error budget's split of a survey: the ``link`` part has exact group shapes, the
    ``shape`` part an exact link; together they account for the reconstruction."""
    rng = np.random.default_rng(31)
    recon = ex.survey_markers(scenario, sim.survey_views(scenario, rng))
    pts = recon.bundle.points
    split = ex.split_survey_error(scenario, pts)
    assert ex.link_error_deg(scenario, pts) > 1e-3
    assert ex.link_error_deg(scenario, split["shape"]) < 1e-9
    np.testing.assert_allclose(
        ex.link_error_deg(scenario, split["link"]), ex.link_error_deg(scenario, pts), rtol=1e-9
    )
    for g in (0, 1):
        m = scenario.markers.group_index == g
        names = [n for n, keep in zip(scenario.markers.names, m, strict=True) if keep]
        sub = scenario.replace(
            {"markers.names": names, "markers.xyz_mm": scenario.markers.xyz[m].tolist()}
        )
        assert ex.marker_error(sub, split["link"][m]) < 1e-9
        np.testing.assert_allclose(
            ex.marker_error(sub, split["shape"][m]), ex.marker_error(sub, pts[m]), rtol=1e-9
        )


def test_normal_equation_lm_reaches_the_trust_region_minimum(scenario):
    """The bundle adjustment's Levenberg-Marquardt on the normal equations and scipy's trust
    region on the dense Jacobian end at one minimum: the same cost to rounding, the markers to
    well below their noise, in far fewer seconds' worth of evaluations."""
    views, poses, points, ref = spliced(scenario, np.random.default_rng(11))
    kw = dict(fixed_view=ref, sigma_px=0.1, sigma_mm=0.1, depth_ref_mm=500.0)
    a = bundle_adjust(scenario.rig, views, poses, points, **kw)
    b = bundle_adjust(scenario.rig, views, poses, points, jacobian="analytic-dense", **kw)
    assert a.rms_px == pytest.approx(b.rms_px, rel=1e-9)
    assert a.rms_mm == pytest.approx(b.rms_mm, rel=1e-6)
    np.testing.assert_allclose(a.points, b.points, atol=1e-4)
    assert a.nfev <= 10
    with pytest.raises(CalibrationError, match="expected 'analytic', 'analytic-dense' or"):
        bundle_adjust(scenario.rig, views, poses, points, jacobian="numeric", **kw)


def test_camera_pose_refinement_matches_finite_differences(scenario):
    """The view's pose refined with the analytic Jacobian is the minimum that MINPACK reaches
    with finite differences on the same residuals of Eq. 9-10."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    from calstudy.estimators import bundle as bd

    rng = np.random.default_rng(21)
    cam2world = sim.view_poses(rng, scenario.markers.group_centre(1), 500.0, 1, 0.3)[0]
    view = sim.observe_markers(scenario, geo.invert(cam2world), rng)
    start = geo.perturb(geo.invert(cam2world), 0.01, 2.0, rng)
    kw = dict(sigma_px=0.1, sigma_mm=0.05, depth_ref_mm=500.0)
    got = bd.refine_camera_pose(scenario.rig, view, scenario.markers.xyz, start, **kw)
    vi, mi, ul, ur, pc = bd._observations(scenario.rig, [view])
    so = bd._euclid_sigma(pc, 0.05, 500.0)[:, None]

    def fun(x):
        rot = Rotation.from_rotvec(x[None, :3]).as_matrix()
        rp, eu = bd._residual_blocks(scenario.rig, rot, x[None, 3:], scenario.markers.xyz, vi, mi,
                                     ul, ur, pc)
        return np.concatenate([rp.ravel() / 0.1, (eu / so).ravel()])

    x0 = np.concatenate([geo.matrix_to_rotvec(start[:3, :3]), start[:3, 3]])
    x = least_squares(fun, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    fd = geo.make_transform(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:])
    assert geo.rotation_error(got, fd) < 1e-7
    assert geo.translation_error(got, fd) < 1e-4
    # the start was off by far more than that
    assert geo.translation_error(start, fd) > 0.5


def test_base_to_base_chains_two_robots():
    """Eq. 11: two robots whose cameras see one world frame give the transform between their
    bases, for any number of poses per robot; unequal pose counts are rejected."""
    rng = np.random.default_rng(22)
    def pose(n, scale):
        return geo.make_transform(geo.random_rotation(rng, n), rng.uniform(-scale, scale, (n, 3)))

    world2base, cam2flange = pose(2, 900.0), pose(2, 100.0)
    args = []
    for a, n in ((0, 3), (1, 5)):
        flange2base = pose(n, 900.0)
        world2cam = geo.invert(flange2base @ cam2flange[a]) @ world2base[a]
        args += [flange2base, cam2flange[a], world2cam]
    truth = world2base[0] @ geo.invert(world2base[1])
    np.testing.assert_allclose(ex.base_to_base(*args), truth, atol=1e-9)
    args[2] = args[2][:2]
    with pytest.raises(CalibrationError, match="3 flange poses but 2 camera poses"):
        ex.base_to_base(*args)
