"""Tests of calstudy.estimators.shared_error: the REML variances against statsmodels' MixedLM,
the exact answers of one variance, the sandwich against the true variances, the simulated
quantiles against a known answer and by their coverage, and bad input."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import statsmodels.api as sm
from scipy import stats

from calstudy import CalibrationError
from calstudy.estimators.shared_error import best_ratio, best_ratios, shared_error_fit


def _problem(rng, n_groups=10, per_group=8, p=4, own=0.02, shared=0.03):
    """Residuals of a least-squares fit whose errors share one error per group."""
    n = n_groups * per_group
    groups = np.repeat(np.arange(n_groups), per_group)
    jac = np.column_stack([np.ones(n), rng.normal(size=(n, p - 1))])
    e = rng.normal(0.0, own, n) + rng.normal(0.0, shared, n_groups)[groups]
    r = e - jac @ np.linalg.lstsq(jac, e, rcond=None)[0]
    return jac, r, groups


def test_reml_variances_match_statsmodels_mixedlm():
    rng = np.random.default_rng(1)
    for _ in range(3):
        jac, r, groups = _problem(rng)
        fit = shared_error_fit(jac, r, groups)
        assert fit.variances[1] > 0.1 * fit.variances[0]  # an interior optimum
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = sm.MixedLM(r, jac, groups=groups).fit(reml=True)
        np.testing.assert_allclose(
            fit.variances, [ref.scale, np.asarray(ref.cov_re)[0, 0]], rtol=2e-3
        )


def test_one_variance_gives_the_textbook_answers():
    """No group of two: s^2 = r^T r / (n - p), covariance s^2 (J^T J)^-1, n - p degrees of
    freedom for every direction and for the joint region."""
    rng = np.random.default_rng(2)
    jac, r, _ = _problem(rng)
    n, p = jac.shape
    fit = shared_error_fit(jac, r, np.arange(n))
    s2 = r @ r / (n - p)
    np.testing.assert_allclose(fit.variances, [s2, 0.0], rtol=1e-12)
    np.testing.assert_allclose(fit.covariance, s2 * np.linalg.inv(jac.T @ jac), rtol=1e-10)
    assert fit.one_variance and fit.dof == n - p
    t = stats.t.ppf(0.975, n - p)
    np.testing.assert_allclose(fit.interval_quantiles(0.95), t, rtol=1e-12)
    np.testing.assert_allclose(fit.interval_quantiles(0.95, rng.normal(size=(3, p))), t)
    assert fit.region_quantile(0.9) == pytest.approx(p * stats.f.ppf(0.9, p, n - p), rel=1e-12)


def test_sandwich_recovers_the_covariance_of_the_true_variances():
    rng = np.random.default_rng(3)
    n_groups, per_group, p = 12, 6, 4
    own, shared = 0.02, 0.015
    groups = np.repeat(np.arange(n_groups), per_group)
    jac = np.column_stack([np.ones(len(groups)), rng.normal(size=(len(groups), p - 1))])
    same = (groups[:, None] == groups[None, :]).astype(float)
    a = np.linalg.inv(jac.T @ jac)
    truth = a @ jac.T @ (own**2 * np.eye(len(groups)) + shared**2 * same) @ jac @ a
    estimates = []
    for _ in range(60):
        e = rng.normal(0, own, len(groups)) + rng.normal(0, shared, n_groups)[groups]
        estimates.append(shared_error_fit(jac, e - jac @ (a @ jac.T @ e), groups).covariance)
    ratio = np.diag(np.mean(estimates, axis=0)) / np.diag(truth)
    assert np.all(np.abs(ratio - 1.0) < 0.25)
    # the entries of a group are not independent: s^2 (J^T J)^-1 is far too small for the
    # column every entry shares
    assert truth[0, 0] > 2.0 * (own**2 + shared**2) * a[0, 0]


def test_balanced_one_way_layout_gives_the_anova_answers():
    """The mean of g groups of k: REML is the ANOVA estimate (within and between mean squares);
    when the shared variance dominates, the mean studentised by the between mean square is
    Student's t with g - 1 degrees of freedom, and the simulated quantile finds it."""
    rng = np.random.default_rng(4)
    g, k = 6, 8
    groups = np.repeat(np.arange(g), k)
    for _ in range(3):
        e = rng.normal(0.0, 0.02, g * k) + rng.normal(0.0, 0.3, g)[groups]
        r = e - e.mean()
        fit = shared_error_fit(np.ones((g * k, 1)), r, groups)
        means = np.array([r[groups == i].mean() for i in range(g)])
        within = np.sum((r - means[groups]) ** 2) / (g * (k - 1))
        between = k * np.sum(means**2) / (g - 1)
        assert between > within  # an interior optimum
        np.testing.assert_allclose(fit.variances, [within, (between - within) / k], rtol=1e-6)
        assert not fit.one_variance
        for level in (0.9, 0.95):
            assert fit.interval_quantiles(level)[0] == pytest.approx(
                stats.t.ppf(0.5 + level / 2, g - 1), rel=0.05
            )
        # one parameter: the region is the interval squared (up to the quantiles' interpolation)
        q = fit.interval_quantiles(0.95)[0]
        assert fit.region_quantile(0.95) == pytest.approx(q**2, rel=1e-4)


def test_intervals_and_region_cover_with_few_groups():
    """Four groups of six, the shared variance a quarter of the own one: each parameter's 95 %
    interval and the joint 95 % region hold the truth 95 % of the time (99.9 % binomial bounds).
    Satterthwaite's degrees of freedom at the estimate fail here (the intercept's interval
    over-covers): the shared variance is often estimated at zero, and the intercept's degrees of
    freedom then drop to a few."""
    rng = np.random.default_rng(6)
    n_groups, per_group, p, trials = 4, 6, 3, 800
    groups = np.repeat(np.arange(n_groups), per_group)
    jac = np.column_stack([np.ones(len(groups)), rng.normal(size=(len(groups), p - 1))])
    inside, region = [], []
    for _ in range(trials):
        e = rng.normal(0.0, 1.0, len(groups)) + rng.normal(0.0, 0.5, n_groups)[groups]
        x = np.linalg.lstsq(jac, e, rcond=None)[0]  # the error of the estimate (truth zero)
        fit = shared_error_fit(jac, e - jac @ x, groups)
        std = np.sqrt(np.diag(fit.covariance))
        inside.append(np.abs(x) <= fit.interval_quantiles(0.95) * std)
        region.append(x @ np.linalg.solve(fit.covariance, x) <= fit.region_quantile(0.95))
    low, high = stats.binom.interval(0.999, trials, 0.95)
    counts = np.sum(inside, axis=0)
    assert np.all((low <= counts) & (counts <= high)), counts
    assert low <= np.sum(region) <= high, np.sum(region)


def test_ratios_of_the_draws_match_the_one_fit_search():
    """The vectorised REML search of the simulation finds the ratio of the scalar one."""
    rng = np.random.default_rng(7)
    g = np.concatenate([rng.uniform(0.0, 6.0, 8), np.zeros(30)])
    w2 = (rng.normal(size=(300, 38)) * np.sqrt(1.0 + rng.uniform(0.0, 3.0, (300, 1)) * g)) ** 2
    many = best_ratios(w2, g)
    one = np.array([best_ratio(row, g) for row in w2])
    assert 0 < np.sum(one == 0.0) < len(one)  # both the boundary and interior optima
    np.testing.assert_array_equal(many == 0.0, one == 0.0)
    np.testing.assert_allclose(many, one, rtol=1e-3)


@pytest.mark.parametrize(
    ("shape", "message"),
    [
        ((5, 5), "5 residuals for 5 parameters leave no degrees of freedom"),
        ((8, 3), "not of full column rank"),
    ],
)
def test_refuses_what_it_cannot_estimate(shape, message):
    rng = np.random.default_rng(5)
    jac = rng.normal(size=shape)
    if shape[0] > shape[1]:
        jac[:, 2] = jac[:, 0]
    with pytest.raises(CalibrationError, match=message):
        shared_error_fit(jac, rng.normal(size=shape[0]), np.arange(shape[0]) // 2)


def test_refuses_shapes_that_disagree_and_non_finite_values():
    jac = np.ones((6, 2))
    with pytest.raises(CalibrationError, match=r"residuals \(5,\)"):
        shared_error_fit(jac, np.zeros(5), np.zeros(6))
    with pytest.raises(CalibrationError, match="non-finite"):
        shared_error_fit(jac, np.array([0, 1, 2, 3, 4, math.nan]), np.zeros(6))
    fit = shared_error_fit(np.eye(6)[:, :2], np.arange(6.0), np.arange(6))
    with pytest.raises(CalibrationError, match="directions have 3 columns; the fit has 2"):
        fit.interval_quantiles(0.95, np.ones((1, 3)))
