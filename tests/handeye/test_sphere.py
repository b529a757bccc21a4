"""Fixed-sphere hand-eye (Eq. 6-14), its ML refinement, OpenCV baselines and Eq. 23."""

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.handeye import sphere, sphere_csv

SENSOR2FLANGE = geo.make_transform(
    geo.euler_zyx_to_matrix(10.0, 50.0, -5.0), np.array([-46.0, -4.5, 413.0])
)
X_B = np.array([1000.0, 350.0, 0.0])


def _poses(rng, n_trans=4, n_rot=6, axis=None):
    """Flange poses around the sphere: pure translations, then pose changes."""
    base_rot = geo.euler_zyx_to_matrix(20.0, 170.0, 5.0)
    base_pos = np.array([900.0, 300.0, 700.0])
    trans = geo.make_transform(
        np.broadcast_to(base_rot, (n_trans, 3, 3)), base_pos + rng.uniform(-15, 15, (n_trans, 3))
    )
    if axis is None:
        rv = rng.normal(size=(n_rot, 3))
        rv *= np.deg2rad(rng.uniform(10, 30, n_rot))[:, None] / np.linalg.norm(rv, axis=1)[:, None]
    else:
        rv = np.outer(np.deg2rad(np.linspace(-30, 30, n_rot)), axis)
    rot = geo.make_transform(
        base_rot @ geo.rotvec_to_matrix(rv), base_pos + rng.uniform(-15, 15, (n_rot, 3))
    )
    return trans, rot


def _centres(flange2base, sensor2flange=SENSOR2FLANGE, x_b=X_B):
    sensor2base = flange2base @ sensor2flange
    return np.einsum("nji,nj->ni", sensor2base[:, :3, :3], x_b - sensor2base[:, :3, 3])


def test_sphere_handeye_noise_free_exact():
    rng = np.random.default_rng(1)
    trans, rot = _poses(rng)
    est = he.sphere_handeye(trans, _centres(trans), rot, _centres(rot))
    assert geo.rotation_error(est.value, SENSOR2FLANGE) < 1e-9
    assert geo.translation_error(est.value, SENSOR2FLANGE) < 1e-9
    x_b = sphere.sphere_centre_in_base(rot, _centres(rot), est.value)
    np.testing.assert_allclose(x_b, X_B, atol=1e-9)


def test_uncentred_procrustes_needs_only_three_positions():
    rng = np.random.default_rng(2)
    trans, rot = _poses(rng, n_trans=3)
    r_f = sphere.rotation_from_translations(trans, _centres(trans), center=False)
    assert geo.rotation_error(r_f, SENSOR2FLANGE) < 1e-9
    with pytest.raises(CalibrationError, match="at least 4 positions; got 3"):
        sphere.rotation_from_translations(trans, _centres(trans), center=True)


def test_ml_refinement_noise_free_and_crb():
    rng = np.random.default_rng(3)
    trans, rot = _poses(rng)
    poses = np.concatenate([trans, rot])
    start = geo.perturb(SENSOR2FLANGE, 0.01, 2.0, rng)
    est = he.sphere_handeye_ml(poses, _centres(poses), 0.01, start)
    assert geo.rotation_error(est.value, SENSOR2FLANGE) < 1e-9
    assert geo.translation_error(est.value, SENSOR2FLANGE) < 1e-8
    np.testing.assert_allclose(est.params[6:], X_B, atol=1e-8)
    crb = he.sphere_handeye_crb(poses, _centres(poses), 0.01, SENSOR2FLANGE, X_B)
    # the rotation block is parametrised about different base rotations; compare the others
    keep = np.r_[0:3, 6:9]
    np.testing.assert_allclose(
        crb[np.ix_(keep, keep)], est.covariance[np.ix_(keep, keep)], rtol=1e-4
    )


def _ml_residuals(poses, centres, cov, base_rot, x):
    """The ML problem written out here, independently of the library: predicted minus measured
    centre in the sensor frame, whitened by the inverse Cholesky factor of the (3, 3) centre
    covariance ``cov``, with ``x = [T_F, delta, X_B]`` and ``R_F = base_rot exp(delta)``."""
    s2f = geo.make_transform(base_rot @ geo.rotvec_to_matrix(x[3:6]), x[:3])
    whiten = np.linalg.inv(np.linalg.cholesky(cov))
    return ((_centres(poses, s2f, x[6:9]) - centres) @ whiten.T).ravel()


def test_ml_analytic_jacobian_matches_finite_differences():
    """The covariance of the ML fit is ``(J^T J)^-1`` of its analytic Jacobian at the solution;
    it must equal the one from central differences of the residuals written out above. The start
    is rotated far enough that the solution's correction ``delta`` is not small, so the chain
    rule through ``exp(delta)`` is exercised too."""
    rng = np.random.default_rng(4)
    trans, rot = _poses(rng)
    poses = np.concatenate([trans, rot])
    # correlated y-z noise, as the line-laser centre has
    cov = np.array([[1e-4, 0.0, 0.0], [0.0, 4e-4, -5e-4], [0.0, -5e-4, 9e-4]])
    centres = _centres(poses) + rng.multivariate_normal(np.zeros(3), cov, len(poses))
    start_rot = SENSOR2FLANGE[:3, :3] @ geo.rotvec_to_matrix(np.array([0.1, -0.2, 0.3]))
    start = geo.make_transform(start_rot, SENSOR2FLANGE[:3, 3] + [1.0, 2.0, 3.0])
    est = he.sphere_handeye_ml(poses, centres, cov, start, misfit="off")
    x = est.params
    assert np.linalg.norm(x[3:6]) > 0.3
    num = np.zeros((3 * len(poses), 9))
    for k in range(9):
        dx = np.zeros(9)
        dx[k] = 1e-6
        plus = _ml_residuals(poses, centres, cov, start_rot, x + dx)
        minus = _ml_residuals(poses, centres, cov, start_rot, x - dx)
        num[:, k] = (plus - minus) / 2e-6
    np.testing.assert_allclose(est.covariance, np.linalg.inv(num.T @ num), rtol=1e-4)


def test_ml_crb_matches_monte_carlo_spread():
    rng = np.random.default_rng(5)
    trans, rot = _poses(rng)
    poses = np.concatenate([trans, rot])
    clean = _centres(poses)
    sigma = 0.05
    errs = []
    for _ in range(300):
        noisy = clean + rng.normal(0, sigma, clean.shape)
        est = he.sphere_handeye_ml(poses, noisy, sigma, SENSOR2FLANGE)
        errs.append(est.params[:3] - SENSOR2FLANGE[:3, 3])
    crb = he.sphere_handeye_crb(poses, clean, sigma, SENSOR2FLANGE, X_B)
    mc_var = np.var(np.array(errs), axis=0)
    np.testing.assert_allclose(mc_var, np.diag(crb)[:3], rtol=0.3)


@pytest.mark.parametrize("method", list(he.OPENCV_METHODS))
def test_opencv_baselines_agree_noise_free(method):
    rng = np.random.default_rng(6)
    _, rot = _poses(rng, n_rot=8)
    target2base = geo.make_transform(geo.random_rotation(rng), X_B)
    target2sensor = geo.invert(rot @ SENSOR2FLANGE) @ target2base
    est = he.opencv_handeye(rot, target2sensor, method)
    assert geo.rotation_error(est, SENSOR2FLANGE) < 1e-6
    assert geo.translation_error(est, SENSOR2FLANGE) < 1e-4


def test_sphere_method_agrees_with_opencv_on_same_poses():
    rng = np.random.default_rng(7)
    trans, rot = _poses(rng)
    ours = he.sphere_handeye(trans, _centres(trans), rot, _centres(rot)).value
    target2base = geo.make_transform(geo.random_rotation(rng), X_B)
    poses = np.concatenate([trans, rot])
    t2s = geo.invert(poses @ SENSOR2FLANGE) @ target2base
    theirs = he.opencv_handeye(poses, t2s, "Park")
    assert geo.rotation_error(ours, theirs) < 1e-6
    assert geo.translation_error(ours, theirs) < 1e-4


# --------------------------------------------------------------------------- bad input


def test_pure_translations_only_leave_t_undefined():
    rng = np.random.default_rng(8)
    trans, _ = _poses(rng, n_trans=6)
    r_f = sphere.rotation_from_translations(trans, _centres(trans))
    with pytest.raises(
        CalibrationError, match="T_F is undefined: the 6 moves are pure translations"
    ):
        sphere.translation_from_rotations(trans, _centres(trans), r_f)


def test_rotations_about_one_axis_are_rank_deficient():
    rng = np.random.default_rng(9)
    trans, rot = _poses(rng, axis=np.array([0.0, 0.0, 1.0]))
    with pytest.raises(CalibrationError, match=r"parallel \(condition number [0-9.e+]+\)"):
        he.sphere_handeye(trans, _centres(trans), rot, _centres(rot))


def test_collinear_translations_rejected():
    rng = np.random.default_rng(10)
    trans, _ = _poses(rng)
    trans[:, :3, 3] = trans[0, :3, 3] + np.outer(np.arange(4.0), [1.0, 2.0, 0.5])
    with pytest.raises(CalibrationError, match="fewer than 3 non-collinear translations"):
        sphere.rotation_from_translations(trans, _centres(trans))


def test_translations_with_rotation_rejected():
    rng = np.random.default_rng(11)
    trans, rot = _poses(rng)
    trans[2] = rot[0]
    with pytest.raises(CalibrationError, match="not pure translations: orientation of move 2"):
        sphere.rotation_from_translations(trans, _centres(trans))


def test_non_finite_and_shapes_and_rotations():
    rng = np.random.default_rng(12)
    trans, rot = _poses(rng)
    centres = _centres(trans)
    centres[1, 2] = np.nan
    with pytest.raises(CalibrationError, match=r"non-finite value \(nan\) at index \(1, 2\)"):
        sphere.rotation_from_translations(trans, centres)
    with pytest.raises(CalibrationError, match=r"shape \(4, 2\); expected \(4, 3\)"):
        sphere.rotation_from_translations(trans, _centres(trans)[:, :2])
    bad = trans.copy()
    bad[0, :3, :3] *= 1.01
    with pytest.raises(CalibrationError, match="not orthonormal"):
        sphere.rotation_from_translations(bad, _centres(trans))
    with pytest.raises(CalibrationError, match="unknown hand-eye method 'Foo'"):
        he.opencv_handeye(rot, rot, "Foo")
    with pytest.raises(CalibrationError, match="at least 3 poses; got 2"):
        he.opencv_handeye(rot[:2], rot[:2], "Tsai")


# --------------------------------------------------------------------------- user CSV


def _measurements(rng):
    trans, rot = _poses(rng)
    poses = np.concatenate([trans, rot])
    return sphere_csv.SphereMeasurements(
        ids=np.arange(len(poses)),
        group=np.array(["translation"] * len(trans) + ["rotation"] * len(rot)),
        flange2base=poses,
        centres=_centres(poses),
    )


def test_csv_round_trip_calibrates(tmp_path):
    meas = _measurements(np.random.default_rng(14))
    path = tmp_path / "m.csv"
    sphere_csv.write_sphere_measurements(meas, path)
    back = sphere_csv.read_sphere_measurements(path)
    np.testing.assert_allclose(back.flange2base, meas.flange2base, atol=1e-9)
    est = he.sphere_handeye(*back.select("translation"), *back.select("rotation"))
    assert geo.translation_error(est.value, SENSOR2FLANGE) < 1e-6


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("sy", "sy_mm", 1), "missing column"),
        (lambda t: _cell(t, 3, 9, "abc"), r"row 3, column 'sx': 'abc' is not a number"),
        (lambda t: _cell(t, 4, 5, ""), r"row 4, column 'z': '' is not a number"),
        (lambda t: _cell(t, 2, 7, "inf"), r"row 2, column 'b': 'inf' is not finite"),
        (lambda t: _cell(t, 5, 2, "spin"), r"row 5, column 'group': 'spin' is not one of"),
        (lambda t: _cell(t, 6, 1, "0"), "id 0 appears more than once"),
    ],
)
def test_malformed_csv_names_row_and_column(tmp_path, edit, message):
    meas = _measurements(np.random.default_rng(15))
    path = tmp_path / "m.csv"
    sphere_csv.write_sphere_measurements(meas, path)
    path.write_text(edit(path.read_text()))
    with pytest.raises(CalibrationError, match=message):
        sphere_csv.read_sphere_measurements(path)


def _cell(text: str, row: int, col: int, value: str) -> str:
    lines = text.splitlines()
    cells = lines[row - 1].split(",")
    cells[col - 1] = value
    lines[row - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------- dualarm: Tsai check, Eq. 11


def test_tsai_takes_poses_with_equal_orientations():
    """Tsai-Lenz uses every pair of poses: a move without rotation among rotating ones is valid
    data, accepted by the diversity check and solved exactly."""
    rng = np.random.default_rng(21)
    _, rot = _poses(rng, n_rot=6)
    rot = rot.copy()
    rot[4] = rot[3] @ geo.make_transform(np.eye(3), [20.0, 0.0, 0.0])  # a pure translation
    target2base = geo.make_transform(geo.random_rotation(rng), X_B)
    target2sensor = geo.invert(rot @ SENSOR2FLANGE) @ target2base
    est = he.opencv_handeye(rot, target2sensor, "Tsai", he.MIN_PAIR_ROTATION)
    assert geo.rotation_error(est, SENSOR2FLANGE) < 1e-6
    assert geo.translation_error(est, SENSOR2FLANGE) < 1e-3


def test_tsai_diversity_check_refuses_one_axis_and_no_rotation():
    rng = np.random.default_rng(23)
    target2base = geo.make_transform(geo.random_rotation(rng), X_B)
    trans, one_axis = _poses(rng, n_rot=6, axis=np.array([0.0, 0.0, 1.0]))
    for flange, match in (
        (one_axis, r"6 poses turn about one axis \(axes within 0 deg"),
        (trans, r"no pair of the 4 poses rotates by 0.5 deg or more \(largest 0 deg\)"),
    ):
        target2sensor = geo.invert(flange @ SENSOR2FLANGE) @ target2base
        with pytest.raises(CalibrationError, match=match):
            he.opencv_handeye(flange, target2sensor, "Tsai", he.MIN_PAIR_ROTATION)
    # two axes 1 deg apart pass the check; 0.2 deg apart do not
    base = geo.euler_zyx_to_matrix(20.0, 170.0, 5.0)
    for tilt, ok in ((1.0, True), (0.2, False)):
        axis2 = geo.rotvec_to_matrix([np.deg2rad(tilt), 0.0, 0.0]) @ [0.0, 0.0, 1.0]
        rv = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3], list(0.3 * axis2)])
        flange = geo.make_transform(base @ geo.rotvec_to_matrix(rv), rng.uniform(-15, 15, (3, 3)))
        if ok:
            he.check_rotation_diversity(flange, he.MIN_PAIR_ROTATION)
        else:
            with pytest.raises(CalibrationError, match="turn about one axis"):
                he.check_rotation_diversity(flange, he.MIN_PAIR_ROTATION)


def test_rotation_check_refuses_bad_shapes_and_angles():
    flange = np.repeat(np.eye(4)[None], 2, axis=0)
    with pytest.raises(CalibrationError, match=r"shape \(2, 4, 4\).*N >= 3"):
        he.check_rotation_diversity(flange, he.MIN_PAIR_ROTATION)
    with pytest.raises(CalibrationError, match=r"shape \(4, 4\)"):
        he.check_rotation_diversity(np.eye(4), he.MIN_PAIR_ROTATION)
    with pytest.raises(CalibrationError, match="min_rotation must be a positive angle"):
        he.check_rotation_diversity(np.repeat(np.eye(4)[None], 3, axis=0), 0.0)
