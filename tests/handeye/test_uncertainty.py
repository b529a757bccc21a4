"""Honest uncertainty of the hand-eye calibration (errors in variables, F regions, the flag
below 6 poses) and the plan of poses before measuring. The full measurements are
``benchmarks/bench_handeye_coverage.py`` and ``benchmarks/bench_handeye_plan.py``."""

import warnings

import numpy as np
import pytest
from scipy.stats import chi2, f
from support import handeye_cell as _cell

from calstudy import CalibrationError, CalibrationWarning
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp
from calstudy.handeye import plan as hplan
from calstudy.handeye import simulate as hs
from calstudy.io import handeye_report as hc


def test_region_limit_is_chi2_with_a_given_noise_and_f_with_an_estimated_one():
    cell = _cell(50, n=12)
    est = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert est.dof == 3 * 12 - 6
    assert est.region_limit(0.95) == pytest.approx(6 * f.ppf(0.95, 6, 30), rel=1e-10)
    given = hp.calibrate_handeye(
        cell.flange2base, cell.target2camera, sigma_rot=1e-3, sigma_trans=0.2
    )
    assert given.dof == np.inf and given.robot_sigma_rot == 0.0
    assert given.region_limit(0.95) == pytest.approx(chi2.ppf(0.95, 6), rel=1e-10)


def test_fewer_than_6_poses_are_flagged():
    cell = _cell(51, n=5)
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert not res.covariance_trusted
    assert any("covariance cannot be trusted" in n for n in res.notes)
    assert hp.calibrate_handeye(*_pair(_cell(51, n=6))).covariance_trusted


def _pair(cell):
    return cell.flange2base, cell.target2camera


def _robot_cell(seed: int, n: int):
    """A cell whose robot poses carry a uniform error twice the size of a typical robot's
    (0.04 deg and 0.2 mm per axis RMS): not the Gaussian the estimator assumes."""
    rng = np.random.default_rng(seed)
    cell = hs.simulate_cell(rng, n, 1e-3, 0.2)
    d = rng.uniform(-1, 1, (n, 6)) * np.sqrt(3.0) * np.r_[[np.deg2rad(0.04)] * 3, [0.2] * 3]
    a = cell.flange2base @ geo.make_transform(geo.rotvec_to_matrix(d[:, :3]), d[:, 3:])
    return a, cell.target2camera, cell.camera2flange


@pytest.mark.slow
@pytest.mark.parametrize("n", [6, 12])
def test_the_95_percent_region_covers_the_truth_with_robot_error(n):
    inside = []
    for s in range(150):
        a, b, truth = _robot_cell(9000 + 100 * n + s, n)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CalibrationWarning)
            try:
                res = hp.calibrate_handeye(a, b)
            except CalibrationError:
                continue
        inside.append(res.camera_distance(truth) <= res.region_limit(0.95))
    assert len(inside) >= 145
    assert 0.88 <= np.mean(inside) <= 0.99


# ----------------------------------------------------------------------------------------------
# the plan


def test_plan_beats_random_choices_in_its_prediction():
    pool = hs.simulate_cell(np.random.default_rng(52), 120, 0.0, 0.0, max_tilt_deg=40.0)
    x, z, point = pool.camera2flange, pool.target2base, np.array([0.0, 0.0, 500.0])
    plan = hplan.plan_poses(pool.flange2base, x, z, 8, 1e-3, 0.2, point)
    assert len(set(plan.chosen)) == 8
    infos = hplan.pose_information(pool.flange2base, x, z, 1e-3, 0.2)
    pj = hplan.point_jacobian(x, point)
    rng = np.random.default_rng(0)
    random = [
        hplan.point_rms(infos[rng.choice(120, 8, replace=False)].sum(0), pj) for _ in range(200)
    ]
    assert plan.predicted_rms_mm < np.min(random)
    assert plan.predicted_rms_mm == pytest.approx(plan.predicted_curve_mm[-1], rel=1e-3)
    with pytest.raises(CalibrationError, match="n_poses must be between 3 and the 120"):
        hplan.plan_poses(pool.flange2base, x, z, 2, 1e-3, 0.2, point)


@pytest.mark.slow
def test_planned_poses_beat_random_ones_by_monte_carlo():
    """40 cells at 6 poses: the planned poses' RMS tool-point error is below the random ones'
    and near its prediction."""
    point = np.array([0.0, 0.0, 500.0])
    planned, random, predicted = [], [], []
    for s in range(40):
        rng = np.random.default_rng(8000 + s)
        pool = hs.simulate_cell(rng, 100, 0.0, 0.0, max_tilt_deg=40.0)
        x, z = pool.camera2flange, pool.target2base
        plan = hplan.plan_poses(pool.flange2base, x, z, 6, 1e-3, 0.2, point)
        errs = []
        for pick in (plan.chosen, rng.choice(100, 6, replace=False)):
            a = pool.flange2base[pick]
            b = geo.perturb(geo.invert(a @ x) @ z, 1e-3, 0.2, rng)
            try:
                fit = hp.calibrate_handeye(a, b, sigma_rot=1e-3, sigma_trans=0.2)
            except CalibrationError:
                errs.append(np.nan)
                continue
            errs.append(np.linalg.norm(geo.apply(fit.camera2flange, point) - geo.apply(x, point)))
        planned.append(errs[0])
        random.append(errs[1])
        predicted.append(plan.predicted_rms_mm)
    p, r = np.array(planned), np.array(random)
    ok = np.isfinite(p) & np.isfinite(r)
    assert np.all(np.isfinite(p))
    rms_p, rms_r = np.sqrt(np.mean(p[ok] ** 2)), np.sqrt(np.mean(r[ok] ** 2))
    assert rms_p < 0.8 * rms_r
    assert 0.7 < rms_p / np.sqrt(np.mean(np.square(predicted))) < 1.3


def test_notebook_plan_table():
    cell = _cell(53, n=16)
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    table = hc.plan_table(res, [0.0, 0.0, 500.0], pose_counts=(6, 10, 40))
    assert list(table.n_poses) == [6, 10]
    assert np.all(table.planned_rms_mm < table.random_median_rms_mm)
    assert np.all(table.all_poses_rms_mm <= table.planned_rms_mm)
