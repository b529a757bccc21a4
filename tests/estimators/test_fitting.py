"""Tests of calstudy.estimators.fitting: exact on noise-free data, agreeing with scipy and OpenCV,
and
raising CalibrationError on degenerate input."""

import cv2
import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from calstudy import CalibrationError
from calstudy.core import geometry as g
from calstudy.core.circles import fit_circle_2d, fit_circles_2d_batch
from calstudy.estimators.fitting import (
    fit_homography,
    fit_rigid,
    fit_rotation,
    fit_sphere,
    homography_to_pose,
    solve_pnp,
    solve_pnp_ransac,
)

K = np.array([[2000.0, 0.0, 640.0], [0.0, 1990.0, 512.0], [0.0, 0.0, 1.0]])


@pytest.fixture
def rng():
    return np.random.default_rng(20240611)


def grid_points(rows=5, cols=7, pitch=10.0):
    col, row = np.meshgrid(np.arange(cols), np.arange(rows))
    x = (col.ravel() - (cols - 1) / 2) * pitch
    y = (row.ravel() - (rows - 1) / 2) * pitch
    return np.column_stack([x, y, np.zeros(x.size)])


def project(pose, points, k=K):
    q = g.apply(pose, points) @ k.T
    return q[:, :2] / q[:, 2:]


def random_view(rng, behind=False):
    """A target2cam with the target 300-500 mm in front, tilted up to 40 deg from facing the
    camera (front face towards the camera, or its back face if ``behind``)."""
    tilt = g.rotvec_to_matrix(rng.normal(0.0, 0.35, 3))
    facing = np.diag([1.0, -1.0, -1.0]) if not behind else np.eye(3)
    t = [rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(300, 500)]
    return g.make_transform(tilt @ facing, t)


# ----------------------------------------------------------------------------------------------
# fit_rotation, fit_rigid


def test_fit_rotation_exact(rng):
    r = g.random_rotation(rng)
    v = rng.normal(0, 50, (6, 3))
    np.testing.assert_allclose(fit_rotation(v, v @ r.T), r, atol=1e-12)
    np.testing.assert_allclose(fit_rotation(v, v @ r.T + [5.0, -3.0, 2.0]), r, atol=1e-12)
    np.testing.assert_allclose(fit_rotation(v, v @ r.T, center=False), r, atol=1e-12)


@pytest.mark.parametrize("center", [True, False])
def test_fit_rotation_matches_scipy_align_vectors(rng, center):
    r = g.random_rotation(rng)
    v = rng.normal(0, 50, (8, 3))
    w = v @ r.T + rng.normal(0, 0.5, v.shape)
    a, b = (v - v.mean(0), w - w.mean(0)) if center else (v, w)
    ref, _ = Rotation.align_vectors(b, a)
    assert g.rotation_error(fit_rotation(v, w, center=center), ref.as_matrix()) < 1e-9


def test_fit_rotation_is_proper_on_planar_noisy_data(rng):
    v = np.column_stack([rng.normal(0, 50, (4, 2)), np.zeros(4)])
    w = v * [1.0, 1.0, -1.0] + rng.normal(0, 0.1, v.shape)
    assert np.linalg.det(fit_rotation(v, w)) == pytest.approx(1.0)


def test_fit_rotation_collinear_raises():
    d = np.array([[1.0, 2.0, 3.0]])
    v = np.array([[0.0], [10.0], [25.0], [40.0]]) * d
    with pytest.raises(CalibrationError, match=r"difference vectors are collinear \(singular"):
        fit_rotation(v, v)
    with pytest.raises(CalibrationError, match="collinear"):  # 2 vectors, centred: one line
        fit_rotation(np.eye(3)[:2], np.eye(3)[:2])
    with pytest.raises(CalibrationError, match="at least 2 vectors; got 1"):
        fit_rotation(np.ones((1, 3)), np.ones((1, 3)))


def test_fit_rotation_bad_input():
    v = np.eye(3)
    with pytest.raises(CalibrationError, match=r"shape \(3, 2\); expected \(N, 3\)"):
        fit_rotation(v[:, :2], v[:, :2])
    with pytest.raises(CalibrationError, match="3 rows but v_to has 2"):
        fit_rotation(v, v[:2])
    bad = v.copy()
    bad[1, 2] = np.nan
    with pytest.raises(CalibrationError, match=r"non-finite value \(nan\) at index \(1, 2\)"):
        fit_rotation(v, bad)


def test_fit_rigid_exact(rng):
    pose = g.make_transform(g.random_rotation(rng), rng.normal(0, 100, 3))
    p = rng.normal(0, 30, (5, 3))
    est = fit_rigid(p, g.apply(pose, p))
    assert g.rotation_error(est, pose) < 1e-12
    assert g.translation_error(est, pose) < 1e-9


def test_fit_rigid_degenerate():
    p = np.outer(np.arange(4.0), [1.0, 1.0, 0.0])
    with pytest.raises(CalibrationError, match=r"the 4 p_from points are collinear"):
        fit_rigid(p, p)
    with pytest.raises(CalibrationError, match="at least 3 points; got 2"):
        fit_rigid(p[:2], p[:2])


# ----------------------------------------------------------------------------------------------
# circles and spheres


def test_fit_circle_exact_on_short_arc(rng):
    centre, radius = np.array([12.0, -340.0]), 9.5
    a = np.linspace(-0.5, 0.3, 7)
    pts = centre + radius * np.column_stack([np.cos(a), np.sin(a)])
    for method in ("kasa", "geometric"):
        c, r = fit_circle_2d(pts, method)
        np.testing.assert_allclose(c, centre, atol=1e-9)
        assert r == pytest.approx(radius, abs=1e-9)


@pytest.mark.parametrize("method", ["kasa", "geometric"])
def test_fit_circles_batch_matches_single(rng, method):
    a = rng.uniform(0, 2 * np.pi, (4, 20))
    pts = 10 * np.stack([np.cos(a), np.sin(a)], axis=2) + rng.normal(0, 0.5, (4, 20, 2))
    centres, radii = fit_circles_2d_batch(pts, method)
    for i in range(4):
        c, r = fit_circle_2d(pts[i], method)
        np.testing.assert_allclose(centres[i], c, atol=1e-12)
        assert radii[i] == pytest.approx(r, abs=1e-12)


def test_fit_circle_kasa_matches_lstsq_and_geometric_matches_scipy(rng):
    a = np.linspace(-1.2, 1.2, 60)
    pts = [3.0, 140.0] + 12.3 * np.column_stack([np.cos(a), np.sin(a)])
    pts = pts + rng.normal(0.0, 0.05, pts.shape)
    design = np.column_stack([2 * pts, np.ones(len(pts))])
    sol, *_ = np.linalg.lstsq(design, (pts**2).sum(axis=1), rcond=None)
    c, r = fit_circle_2d(pts)
    np.testing.assert_allclose(c, sol[:2], atol=1e-9)
    assert r == pytest.approx(np.sqrt(sol[2] + sol[:2] @ sol[:2]), abs=1e-9)

    def dist(x):
        return np.linalg.norm(pts - x[:2], axis=1) - x[2]

    def jac(x):
        d = pts - x[:2]
        return np.column_stack([-d / np.linalg.norm(d, axis=1, keepdims=True), -np.ones(len(d))])

    ref = least_squares(
        dist, np.append(c, r), jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15
    ).x
    c_geo, r_geo = fit_circle_2d(pts, method="geometric")
    np.testing.assert_allclose(c_geo, ref[:2], atol=1e-9)
    assert r_geo == pytest.approx(ref[2], abs=1e-9)
    assert np.abs(c_geo - c).max() > 1e-4  # the refinement did move the Kasa answer
    with pytest.raises(CalibrationError, match="method must be one of"):
        fit_circle_2d(pts, method="pratt")


def test_fit_circle_degenerate():
    with pytest.raises(CalibrationError, match=r"the 3 points are collinear \(singular values"):
        fit_circle_2d([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    with pytest.raises(CalibrationError, match="at least 3 points; got 2"):
        fit_circle_2d([[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(CalibrationError, match="non-finite"):
        fit_circle_2d([[0.0, 0.0], [1.0, np.inf], [2.0, 0.0]])


def test_fit_sphere_exact(rng):
    centre, radius = np.array([800.0, -120.0, 450.0]), 12.7
    d = rng.normal(size=(30, 3))
    d[:, 2] = np.abs(d[:, 2])  # a hemisphere, as a sensor sees it
    pts = centre + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    c, r, cond = fit_sphere(pts)
    np.testing.assert_allclose(c, centre, atol=1e-9)
    assert r == pytest.approx(radius, abs=1e-9)
    assert 1.0 <= cond < 100.0


def test_fit_sphere_coplanar_raises(rng):
    a = rng.uniform(0, 2 * np.pi, 12)
    pts = np.column_stack([10 * np.cos(a), 10 * np.sin(a), np.full(12, 5.0)])
    with pytest.raises(CalibrationError, match=r"the 12 points are coplanar \(condition number"):
        fit_sphere(pts)
    with pytest.raises(CalibrationError, match="at least 4 points; got 3"):
        fit_sphere(pts[:3])
    with pytest.raises(CalibrationError, match=r"shape \(12, 2\)"):
        fit_sphere(pts[:, :2])


# ----------------------------------------------------------------------------------------------
# homography and pose


@pytest.mark.parametrize("behind", [False, True])
def test_homography_chain_exact(rng, behind):
    pts = grid_points()
    for _ in range(3):
        pose = random_view(rng, behind=behind)
        h = fit_homography(pts[:, :2], project(pose, pts))
        h_true = K @ pose[:3][:, [0, 1, 3]]
        np.testing.assert_allclose(h, h_true / h_true[2, 2], rtol=1e-10, atol=1e-12)
        est = homography_to_pose(h, K)
        assert g.rotation_error(est, pose) < 1e-9
        assert g.translation_error(est, pose) < 1e-9


def test_homography_from_four_corners_exact(rng):
    corners = grid_points()[[0, 6, 28, 34]]
    pose = random_view(rng)
    est = homography_to_pose(fit_homography(corners[:, :2], project(pose, corners)), K)
    assert g.rotation_error(est, pose) < 1e-9
    assert g.translation_error(est, pose) < 1e-9


def test_homography_to_pose_sign_rule_any_scale(rng):
    pose = random_view(rng)
    h = K @ pose[:3][:, [0, 1, 3]]
    for scale in (1.0, -1.0, 1e-3, -250.0):
        est = homography_to_pose(scale * h, K)
        assert est[2, 3] > 0
        assert g.rotation_error(est, pose) < 1e-12
        assert g.translation_error(est, pose) < 1e-9


@pytest.mark.parametrize("behind", [False, True])
def test_homography_pose_agrees_with_solvepnp_noise_free(rng, behind):
    pts = grid_points()
    for _ in range(3):
        pose = random_view(rng, behind=behind)
        uv = project(pose, pts)
        est = homography_to_pose(fit_homography(pts[:, :2], uv), K)
        pnp = solve_pnp(pts, uv, K)
        assert g.rotation_error(est, pnp) < 1e-9
        assert g.translation_error(est, pnp) < 1e-7
        assert est[2, 3] > 0


def test_homography_pose_close_to_solvepnp_with_noise(rng):
    """0.1 px noise, 40 views of the 5 x 7 grid (front and back): both poses are close to the
    truth; PnP, the maximum-likelihood pose, is the better of the two, as it must be."""
    pts = grid_points()
    err = {"h": [], "pnp": []}
    for i in range(40):
        pose = random_view(rng, behind=i % 2 == 1)
        uv = project(pose, pts) + rng.normal(0.0, 0.1, (len(pts), 2))
        est = homography_to_pose(fit_homography(pts[:, :2], uv), K)
        assert est[2, 3] > 0
        for name, value in (("h", est), ("pnp", solve_pnp(pts, uv, K))):
            err[name].append([g.rotation_error(value, pose), g.translation_error(value, pose)])
    rms = {name: np.sqrt(np.mean(np.square(e), axis=0)) for name, e in err.items()}
    assert rms["h"][0] < 0.01 and rms["h"][1] < 1.5  # rad, mm
    assert rms["pnp"][0] < 0.005 and rms["pnp"][1] < 0.3
    assert np.all(rms["pnp"] <= rms["h"])


def test_solve_pnp_matches_cv2_projection(rng):
    pts = grid_points()
    pose = random_view(rng)
    rvec = cv2.Rodrigues(pose[:3, :3])[0]
    uv, _ = cv2.projectPoints(pts, rvec, pose[:3, 3], K, None)
    est = solve_pnp(pts, uv[:, 0, :], K)
    assert g.rotation_error(est, pose) < 1e-12
    assert g.translation_error(est, pose) < 1e-9


def test_fit_homography_degenerate(rng):
    pts = grid_points()
    uv = project(random_view(rng), pts)
    with pytest.raises(CalibrationError, match="homography needs at least 4 points; got 3"):
        fit_homography(pts[:3, :2], uv[:3])
    row = pts[:5, :2]  # the first row of the grid: 5 points on a line
    with pytest.raises(CalibrationError, match=r"the 5 points are collinear \(singular values"):
        fit_homography(row, uv[:5])
    with pytest.raises(CalibrationError, match="35 rows but image_uv has 34"):
        fit_homography(pts[:, :2], uv[:-1])
    bad = uv.copy()
    bad[4, 0] = np.nan
    with pytest.raises(CalibrationError, match="image_uv holds a non-finite value"):
        fit_homography(pts[:, :2], bad)


def test_homography_to_pose_bad_input():
    h = K @ np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 400]])
    lower = K.copy()
    lower[2, 0] = 0.1
    with pytest.raises(CalibrationError, match="K is not upper triangular"):
        homography_to_pose(h, lower)
    singular = K.copy()
    singular[1, 1] = 0.0
    with pytest.raises(CalibrationError, match="not an invertible camera matrix"):
        homography_to_pose(h, singular)
    with pytest.raises(CalibrationError, match="H holds a non-finite value"):
        homography_to_pose(np.full((3, 3), np.nan), K)
    with pytest.raises(CalibrationError, match=r"H has shape \(2, 3\)"):
        homography_to_pose(h[:2], K)


def test_solve_pnp_bad_input(rng):
    pts = grid_points()
    uv = project(random_view(rng), pts)
    with pytest.raises(CalibrationError, match="at least 4 points; got 3"):
        solve_pnp(pts[:3], uv[:3], K)
    cloud = rng.normal(0, 30, (5, 3)) + [0, 0, 400]
    with pytest.raises(CalibrationError, match="non-planar object points need at least 6"):
        solve_pnp(cloud - [0, 0, 400], project(np.eye(4), cloud), K)
    skewed = K.copy()
    skewed[0, 1] = 0.5
    with pytest.raises(CalibrationError, match="no skew"):
        solve_pnp(pts, uv, skewed)


def test_solve_pnp_ransac_rejects_gross_errors(rng):
    """An oblique plate with every seventh centre 15 px off: the pose is exact on the rest."""
    pts = grid_points(7, 9, 20.0)
    for _ in range(5):
        pose = random_view(rng)
        uv = project(pose, pts)
        uv[::7] += 15.0
        est = solve_pnp_ransac(pts, uv, K, 1.0)
        assert g.translation_error(est, pose) < 1e-6
        assert g.rotation_error(est, pose) < 1e-9


def test_solve_pnp_ransac_bad_input():
    pts = grid_points(2, 2)
    with pytest.raises(CalibrationError, match="at least 4 points; got 3"):
        solve_pnp_ransac(pts[:3], np.zeros((3, 2)), K, 1.0)
    with pytest.raises(CalibrationError, match=r"image_uv has shape \(3, 2\); expected \(4, 2\)"):
        solve_pnp_ransac(pts, np.zeros((3, 2)), K, 1.0)


def test_homography_data_check_is_the_textbook_dlt_matrix():
    from calstudy.estimators.fitting import check_homography_data

    rng = np.random.default_rng(8)
    xy = rng.uniform(-50.0, 50.0, (20, 2))
    for _ in range(2):  # the second call reuses the plane's part of the matrix
        uv = xy @ rng.normal(size=(2, 2)) + rng.normal(0.0, 0.1, xy.shape) + 300.0

        def normalise(p):
            q = p - p.mean(axis=0)
            return q * (np.sqrt(2.0) / np.sqrt((q**2).sum(axis=1).mean()))

        a, b = normalise(xy), normalise(uv)
        ah, zero = np.column_stack([a, np.ones(len(a))]), np.zeros((len(a), 3))
        dlt = np.vstack(
            [np.hstack([ah, zero, -b[:, :1] * ah]), np.hstack([zero, ah, -b[:, 1:] * ah])]
        )
        s = np.linalg.svd(dlt, compute_uv=False)
        assert check_homography_data(xy, uv) == s[7] / s[0]
