"""Tests of calstudy.core.stats: median_and_spread (the one spread helper of the tables) and the
Lilliefors test against statsmodels, by hand, and on bad input."""

from __future__ import annotations

import numpy as np
import pytest
from statsmodels.stats.diagnostic import lilliefors

from calstudy import CalibrationError
from calstudy.core.stats import lilliefors_test, median_and_spread


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
