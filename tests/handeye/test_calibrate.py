"""Hand-eye calibration from pose lists: AX = XB and AX = ZB, ML, uncertainty, diagnostics."""

import numpy as np
import pytest
from support import HANDEYE_SIGMA_ROT as SIGMA_ROT
from support import HANDEYE_SIGMA_TRANS as SIGMA_TRANS
from support import handeye_cell as _cell

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp


def _errors(x, truth):
    return float(geo.rotation_error(x, truth)), float(geo.translation_error(x, truth))


# ----------------------------------------------------------------------------------------------
# exact recovery


@pytest.mark.parametrize("solver", [hp.calibrate_handeye, hp.calibrate_robot_world_handeye])
def test_noise_free_recovery(solver):
    cell = _cell(1, noise=False)
    res = solver(cell.flange2base, cell.target2camera)
    rot, trans = _errors(res.camera2flange, cell.camera2flange)
    assert rot < 1e-8 and trans < 1e-8
    rot, trans = _errors(res.target2base, cell.target2base)
    assert rot < 1e-8 and trans < 1e-8
    assert res.setup == "eye_in_hand" and res.camera2base is None and res.target2flange is None
    assert res.method.endswith("+ ML") and res.flagged == []


def test_noise_free_eye_to_hand():
    cell = _cell(2, noise=False)
    # a fixed camera (camera2base = X) and a target on the flange (target2flange = Z): the
    # flange poses are the inverses of the eye-in-hand cell's
    res = hp.calibrate_handeye(
        geo.invert(cell.flange2base), cell.target2camera, setup="eye_to_hand"
    )
    assert res.camera2flange is None and res.target2base is None
    assert max(_errors(res.camera2base, cell.camera2flange)) < 1e-8
    assert max(_errors(res.target2flange, cell.target2base)) < 1e-8
    assert res.camera2mount is res.camera2base and res.target2mount is res.target2flange


def test_reprojection_refinement_noise_free():
    cell = _cell(3, noise=False)
    pts = np.array([[x, y, 0.0] for x in range(-60, 61, 40) for y in range(-45, 46, 30)], float)
    k = np.array([[1200.0, 0.0, 640.0], [0.0, 1200.0, 480.0], [0.0, 0.0, 1.0]])
    cam = np.einsum("nij,mj->nmi", cell.target2camera[:, :3, :3], pts)
    cam += cell.target2camera[:, None, :3, 3]
    pixels = cam[..., :2] / cam[..., 2:] * 1200.0 + np.array([640.0, 480.0])
    noisy = geo.perturb(cell.target2camera, 2e-3, 0.5, np.random.default_rng(0))
    res = hp.calibrate_handeye(
        cell.flange2base,
        noisy,
        target_points=pts,
        pixels=pixels,
        camera_matrix=k,
        pixel_sigma=0.1,
    )
    assert "reprojection" in res.method
    assert max(_errors(res.camera2flange, cell.camera2flange)) < 1e-8


# ----------------------------------------------------------------------------------------------
# the refinement against closed forms; the noise level


def test_ml_beats_the_best_closed_form():
    """Median errors over 30 cells: ML translation well below the best closed form (about 2x in
    this scenario), rotation about as good (within 10 %: the rotation is the part the closed
    forms, on their 12 well-spread poses, already get close to the bound)."""
    ml, cf = [], []
    for seed in range(30):
        cell = _cell(100 + seed)
        res = hp.calibrate_handeye(
            cell.flange2base, cell.target2camera, sigma_rot=SIGMA_ROT, sigma_trans=SIGMA_TRANS
        )
        ml.append(_errors(res.camera2flange, cell.camera2flange))
        cf.append([_errors(c.x, cell.camera2flange) for c in res.closed_forms])
    ml_med = np.median(np.array(ml), axis=0)
    cf_med = np.median(np.array(cf), axis=0).min(axis=0)
    assert ml_med[1] < 0.6 * cf_med[1]
    assert ml_med[0] < 1.1 * cf_med[0]


def test_unknown_noise_is_estimated_and_covariance_scaled():
    cell = _cell(7, n=40)
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert res.covariance_basis.startswith("scaled by residual chi2")
    assert 0.7 < res.sigma_rot / SIGMA_ROT < 1.3 and 0.7 < res.sigma_trans / SIGMA_TRANS < 1.3
    given = hp.calibrate_handeye(
        cell.flange2base, cell.target2camera, sigma_rot=SIGMA_ROT, sigma_trans=SIGMA_TRANS
    )
    assert given.covariance_basis == "given noise level"
    ratio = res.std[3:6] / given.std[3:6]
    assert np.all((ratio > 0.6) & (ratio < 1.5))
    cov = res.point_covariance([0.0, 0.0, 500.0])
    assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)


# ----------------------------------------------------------------------------------------------
# outliers


def test_planted_outlier_is_flagged_and_robust_options_resist_it():
    cell = _cell(11, n=20, outlier=(68.0, 1.8))
    ids = np.arange(101, 121)
    plain = hp.calibrate_handeye(cell.flange2base, cell.target2camera, ids=ids)
    assert plain.flagged == [120]
    assert plain.outlier_score[-1] > 100 * np.median(plain.outlier_score)
    clean = _errors(
        hp.calibrate_handeye(cell.flange2base[:-1], cell.target2camera[:-1]).camera2flange,
        cell.camera2flange,
    )
    for robust in ("huber", "cauchy", "ransac"):
        res = hp.calibrate_handeye(
            cell.flange2base,
            cell.target2camera,
            ids=ids,
            robust=robust,
            rng=np.random.default_rng(0),
        )
        assert res.flagged == [120], robust
        assert res.weights[-1] < 0.05, robust
        rot, trans = _errors(res.camera2flange, cell.camera2flange)
        assert trans < 2 * clean[1] + 0.05, robust
    assert _errors(plain.camera2flange, cell.camera2flange)[1] > 2 * clean[1]
    with pytest.raises(CalibrationError, match="pass rng"):
        hp.calibrate_handeye(cell.flange2base, cell.target2camera, robust="ransac")


# ----------------------------------------------------------------------------------------------
# options


def test_unknown_method_and_options():
    cell = _cell(19)
    with pytest.raises(CalibrationError, match="unknown AX = XB method 'Shah'"):
        hp.calibrate_handeye(cell.flange2base, cell.target2camera, method="Shah")
    with pytest.raises(CalibrationError, match="unknown pose convention 'world2base'"):
        hp.calibrate_handeye(cell.flange2base, cell.target2camera, convention="world2base")
    with pytest.raises(CalibrationError, match="15 robot poses but 14 camera poses"):
        hp.calibrate_handeye(cell.flange2base, cell.target2camera[:-1])
    res = hp.calibrate_robot_world_handeye(cell.flange2base, cell.target2camera, method="Li")
    assert res.method == "Li + ML"
