"""Tests of calstudy.core.stats.median_and_spread, the one spread helper of the tables."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.stats import median_and_spread


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
