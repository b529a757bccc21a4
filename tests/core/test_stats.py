"""Tests of calstudy.core.stats: median_and_spread (the one spread helper of the tables), the
checks the intervals share, and the Lilliefors test against statsmodels, by hand, and on bad
input. The order-statistic interval of the median is tested with the verdicts
(tests/core/test_verdicts.py)."""

from __future__ import annotations

import numpy as np
import pytest
from statsmodels.stats.diagnostic import lilliefors

from calstudy import CalibrationError
from calstudy.core.stats import (
    interval_level,
    lilliefors_test,
    lilliefors_tests,
    median_and_spread,
    median_interval,
    trial_values,
)


def test_median_and_central_95_percent_of_a_known_sample():
    x = np.arange(1001, dtype=float)  # quantiles of 0..1000 are exact under linear interpolation
    np.testing.assert_allclose(median_and_spread(x), (500.0, 25.0, 975.0), rtol=1e-12)
    np.testing.assert_allclose(median_and_spread(x[::-1]), (500.0, 25.0, 975.0), rtol=1e-12)


def test_single_value_and_bad_input():
    assert median_and_spread([2.5]) == (2.5, 2.5, 2.5)
    with pytest.raises(CalibrationError):
        median_and_spread([])
    with pytest.raises(CalibrationError):
        median_and_spread([1.0, np.nan])


def test_the_intervals_share_one_level_check_and_one_trial_check():
    assert interval_level(0.9) == 0.9
    for bad in (0.0, 1.0, float("nan"), -0.5):
        with pytest.raises(CalibrationError, match="expected strictly between 0 and 1"):
            interval_level(bad)
    with pytest.raises(CalibrationError, match="level is 'high'; expected a finite number"):
        interval_level("high")
    for fn in (median_and_spread, median_interval):
        with pytest.raises(CalibrationError, match="level is 1.5; expected strictly between"):
            fn(np.arange(10.0), level=1.5)
    np.testing.assert_array_equal(trial_values("x", [1, 2]), [1.0, 2.0])
    with pytest.raises(CalibrationError, match=r"x has shape \(2, 2\); expected \(N,\)"):
        trial_values("x", np.ones((2, 2)))
    with pytest.raises(CalibrationError, match="samples has shape \\(0,\\)"):
        median_interval([])


def test_lilliefors_matches_statsmodels():
    x = np.random.default_rng(1).normal(2.0, 0.3, 10)
    stat, p = lilliefors_test(x)
    ref = lilliefors(x, dist="norm", pvalmethod="table")
    assert stat == pytest.approx(ref[0]) and p == pytest.approx(ref[1])


def test_lilliefors_statistic_by_hand():
    x = np.array([-1.0, 0.0, 0.0, 1.0, 3.0])
    z = np.sort((x - x.mean()) / x.std(ddof=1))
    from scipy.stats import norm

    cdf = norm.cdf(z)
    n = x.size
    d = max((np.arange(1, n + 1) / n - cdf).max(), (cdf - np.arange(n) / n).max())
    assert lilliefors_test(x)[0] == pytest.approx(d)


def test_lilliefors_rejects_a_clearly_non_normal_sample():
    x = np.r_[np.zeros(15), np.ones(5) * 10] + np.linspace(0, 1e-3, 20)
    assert lilliefors_test(x)[1] < 0.01


def test_lilliefors_rejects_too_few_and_constant_samples():
    with pytest.raises(CalibrationError, match="Lilliefors test needs at least 4 samples"):
        lilliefors_test([0.1, 0.2, 0.4])
    with pytest.raises(CalibrationError, match="undefined for constant data"):
        lilliefors_test(np.full(10, 2.5))


def test_vectorised_lilliefors_matches_statsmodels_per_column():
    """Columns of 10 values (the hybrid paper's case) and of 40, normal and skewed: the
    statistics and p-values agree with statsmodels' per-column call to 1e-13, the interpolated
    p-values as well as the clipped ones (0.001, 0.99)."""
    rng = np.random.default_rng(3)
    for n in (10, 40):
        x = np.column_stack(
            [rng.normal(size=(n, 150)), rng.exponential(size=(n, 50)) ** 3, np.arange(n) ** 4]
        )
        stat, p = lilliefors_tests(x)
        ref = np.array([lilliefors(c, dist="norm", pvalmethod="table") for c in x.T])
        np.testing.assert_allclose(stat, ref[:, 0], rtol=0, atol=1e-13)
        np.testing.assert_allclose(p, ref[:, 1], rtol=0, atol=1e-13)
        assert p.min() == pytest.approx(0.001) and p.max() == pytest.approx(0.99)


def test_vectorised_lilliefors_rejects_bad_columns():
    with pytest.raises(CalibrationError, match="column 1 is constant"):
        lilliefors_tests(np.column_stack([np.arange(6.0), np.ones(6)]))
    with pytest.raises(CalibrationError, match="at least 4"):
        lilliefors_tests(np.ones((3, 2)))
