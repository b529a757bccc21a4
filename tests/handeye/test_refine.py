"""Hand-eye residuals, closed forms and refinement: Jacobian, Cramer-Rao bound, refusals."""

import numpy as np
import pytest
from support import HANDEYE_SIGMA_ROT as SIGMA_ROT
from support import HANDEYE_SIGMA_TRANS as SIGMA_TRANS
from support import handeye_cell as _cell

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp
from calstudy.handeye import inputs as hi
from calstudy.handeye import refine as hr

# ----------------------------------------------------------------------------------------------
# the refinement: Jacobian, Cramer-Rao bound


def test_analytic_jacobian_matches_finite_differences():
    cell = _cell(4)
    prep = hi.prepare_poses(cell.flange2base, cell.target2camera)
    x = cell.camera2flange @ geo.pose_from_vector([1.0, -2.0, 3.0, 0.01, -0.02, 0.03])
    prob = hr.PoseProblem.build(prep.a, prep.b, x, cell.target2base, 1e-3, 0.2, np.ones(15))
    p = prob.x0(x, cell.target2base) + np.random.default_rng(0).normal(0, 0.05, 12)
    num = np.zeros((90, 12))
    for k in range(12):
        e = np.zeros(12)
        e[k] = 1e-6
        num[:, k] = (prob.residuals(p + e) - prob.residuals(p - e)) / 2e-6
    np.testing.assert_allclose(prob.jacobian(p), num, atol=1e-5 * np.abs(num).max())


def test_monte_carlo_covariance_of_ml_matches_crb():
    """Sample covariance of 600 ML estimates against (J^T J)^-1 at the truth: the trace of each
    3 x 3 block (rotation and translation of X and of Z) within 10 %."""
    cell = _cell(5, noise=False)
    prep = hi.prepare_poses(cell.flange2base, cell.target2camera)
    x_t, z_t = cell.camera2flange, cell.target2base
    crb = hr.handeye_crb(prep.a, prep.b, x_t, z_t, SIGMA_ROT, SIGMA_TRANS)
    rng = np.random.default_rng(6)
    errs = []
    for _ in range(600):
        b = geo.perturb(prep.b, SIGMA_ROT, SIGMA_TRANS, rng)
        x0 = he.opencv_handeye(prep.a, b, "Park")
        est = hr.refine_ml(prep.a, b, x0, hr.target_in_world(prep.a, b, x0), 1e-3, 0.2)
        x, z = est.value
        errs.append(
            np.concatenate(
                [
                    geo.matrix_to_rotvec(x_t[:3, :3].T @ x[:3, :3]),
                    x[:3, 3] - x_t[:3, 3],
                    geo.matrix_to_rotvec(z_t[:3, :3].T @ z[:3, :3]),
                    z[:3, 3] - z_t[:3, 3],
                ]
            )
        )
    errs = np.array(errs)
    sample = errs.T @ errs / len(errs)  # about the truth: includes any bias
    for blk in range(4):
        s = slice(3 * blk, 3 * blk + 3)
        ratio = np.trace(sample[s, s]) / np.trace(crb[s, s])
        assert abs(ratio - 1.0) < 0.10, f"block {blk}: MC / CRB = {ratio:.3f}"
    # the covariance the estimator reports (given sigma) is the bound at its estimate
    ratio = np.trace(est.covariance[:3, :3]) / np.trace(crb[:3, :3])
    assert abs(ratio - 1.0) < 0.05


# ----------------------------------------------------------------------------------------------
# closed forms far off the data are refused


def test_inconsistent_closed_form_is_refused(monkeypatch):
    cell = _cell(18)
    real = he.opencv_handeye
    wrong = geo.make_transform(geo.rotvec_to_matrix([0.0, np.deg2rad(27.0), 0.0]), [2300.0, 0, 0])

    def broken(a, b, method, tol=geo.ORTHONORMAL_TOL):
        x = real(a, b, method, tol)
        return x @ wrong if method == "Daniilidis" else x

    monkeypatch.setattr(hr, "opencv_handeye", broken)
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    daniilidis = next(c for c in res.closed_forms if c.method == "Daniilidis")
    assert daniilidis.refused.startswith("inconsistent with the data")
    assert not res.method.startswith("Daniilidis")
    with pytest.raises(CalibrationError, match="OpenCV Daniilidis result refused"):
        hp.calibrate_handeye(cell.flange2base, cell.target2camera, method="Daniilidis")


# ----------------------------------------------------------------------------------------------
# errors in variables: the robot's rotation error


def test_robot_error_map_is_the_first_order_change_of_the_residuals():
    from calstudy.handeye.refine import pose_residuals, robot_error_map

    cell = _cell(31, n=8, noise=False)
    a, x, z = cell.flange2base, cell.camera2flange, cell.target2base
    delta = np.array([2e-6, -1e-6, 3e-6])
    moved = a @ geo.make_transform(geo.rotvec_to_matrix(np.tile(delta, (8, 1))), np.zeros(3))
    # the camera saw the moved flange; the residual against the reported one
    b_seen = geo.invert(moved @ x) @ z
    change = pose_residuals(a, b_seen, x, z)
    g_t, g_r = robot_error_map(a, x, z)
    np.testing.assert_allclose(change[:, :3], g_t @ delta, rtol=0, atol=1e-8)  # of 1e-3
    np.testing.assert_allclose(change[:, 3:], g_r @ delta, rtol=0, atol=1e-11)  # of 4e-6


def test_eiv_sigmas_separate_the_robot_from_the_camera():
    from calstudy.handeye import calibrate as hp

    rng = np.random.default_rng(5)
    cell = _cell(32, n=300)
    rho = np.deg2rad(0.05)
    a = geo.perturb(cell.flange2base, rho, 0.0, rng)
    res = hp.calibrate_handeye(a, cell.target2camera)
    assert 0.8 < res.robot_sigma_rot / rho < 1.2
    assert 0.8 < res.sigma_rot / 1e-3 < 1.2 and 0.8 < res.sigma_trans / 0.2 < 1.25
    clean = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert clean.robot_sigma_rot < 0.3 * rho


def test_closed_forms_start_from_a_fixed_number_of_well_spread_poses():
    from calstudy.handeye.refine import START_POSES, spread_subset

    cell = _cell(33, n=300)
    sub = spread_subset(cell.flange2base)
    assert len(sub) == START_POSES == 12 and len(np.unique(sub)) == 12
    rot = cell.flange2base[:, :3, :3]
    angles = geo.rotation_angle(np.swapaxes(rot[:, None], -1, -2) @ rot[None])
    # the chosen poses span nearly the largest rotation between any two of the 300
    assert angles[np.ix_(sub, sub)].max() > 0.9 * angles.max()
    np.testing.assert_array_equal(spread_subset(cell.flange2base[:10]), np.arange(10))
