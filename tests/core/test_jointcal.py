"""Tests of calstudy.core.jointcal: joint calibration of a nuisance input to several baselines."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.jointcal import Baseline, joint_calibration, joint_calibration_rows, rmse_spread

GRID = [1.0, 2.0, 4.0, 8.0, 16.0]


def figures(x: float, n: int = 50) -> dict:
    """Two figures that fall and rise as a power of the input, the same in every trial."""
    return {"falls": np.full(n, 0.1 / x), "rises": np.full(n, 0.01 * x)}


def test_two_consistent_baselines_identify_the_input():
    fit = joint_calibration(
        figures, GRID, [Baseline("falls", 0.025, 0.1), Baseline("rises", 0.04, 0.1)]
    )
    assert fit.value == pytest.approx(4.0, rel=2e-3)
    assert fit.identified and not fit.at_edge
    assert fit.met() == ["falls", "rises"]
    np.testing.assert_allclose(fit.agreement["ratio"], 1.0, rtol=3e-3)


def test_conflicting_baselines_meet_in_the_weighted_middle_and_are_not_identified():
    # alone, 'falls' wants x = 4 and 'rises' x = 8; equal spreads and slopes +-1 in logs put the
    # fit at the geometric mean, sqrt(32), with standard uncertainty x s / sqrt(2) in ln x
    spread = 0.05
    fit = joint_calibration(
        figures, GRID, [Baseline("falls", 0.025, spread), Baseline("rises", 0.08, spread)]
    )
    assert fit.value == pytest.approx(math.sqrt(32.0), rel=3e-3)
    assert fit.uncertainty == pytest.approx(fit.value * spread / math.sqrt(2.0), rel=0.15)
    assert not fit.identified and fit.met() == []
    assert fit.agreement["met_alone"].all()
    np.testing.assert_allclose(fit.agreement["alone"], [4.0, 8.0], rtol=3e-3)
    # a wider tolerance (larger spread of the paper's figures) meets both at the same fit
    wide = joint_calibration(
        figures, GRID, [Baseline("falls", 0.025, 0.3), Baseline("rises", 0.08, 0.3)]
    )
    assert wide.value == pytest.approx(fit.value, rel=3e-3) and wide.identified
    # unequal spreads: weights 1 / s^2, ln x = (400 ln 4 + 25 ln 8) / 425
    tight = joint_calibration(
        figures, GRID, [Baseline("falls", 0.025, 0.05), Baseline("rises", 0.08, 0.2)]
    )
    assert tight.value == pytest.approx(4.0 * 2.0 ** (25.0 / 425.0), rel=3e-3)
    # each row carries its baseline's spread, and the tolerance is its coverage of spreads
    assert tight.agreement["spread"].tolist() == [0.05, 0.2]
    np.testing.assert_allclose(tight.agreement["tolerance"], np.expm1([0.1, 0.4]))


def test_a_baseline_beyond_the_range_pins_the_fit_to_its_end():
    fit = joint_calibration(figures, GRID, [Baseline("rises", 0.5, 0.1)])
    assert fit.at_edge and fit.value == pytest.approx(16.0)
    assert not fit.identified and not fit.agreement["met_alone"].iloc[0]


def test_monte_carlo_noise_of_the_medians_widens_the_uncertainty():
    rng = np.random.default_rng(3)
    noise = {x: rng.normal(1.0, 0.3, 40) for x in GRID}

    def noisy(x):
        return {"falls": 0.1 / x * noise[x]}

    base = [Baseline("falls", 0.025, 0.01)]
    exact = joint_calibration(lambda x: {"falls": np.full(40, 0.1 / x)}, GRID, base)
    fit = joint_calibration(noisy, GRID, base)
    assert fit.uncertainty > 3 * exact.uncertainty


def test_rmse_spread():
    assert rmse_spread(8) == pytest.approx(0.25)
    with pytest.raises(CalibrationError, match="an RMSE of 0 errors"):
        rmse_spread(0)


def test_bad_inputs_are_named():
    ok = [Baseline("falls", 0.025, 0.1)]
    with pytest.raises(CalibrationError, match=r"grid of the input is \[4\.0\]"):
        joint_calibration(figures, [4.0], ok)
    with pytest.raises(CalibrationError, match=r"grid of the input is \[-1\.0, 2\.0\]"):
        joint_calibration(figures, [-1.0, 2.0], ok)
    with pytest.raises(CalibrationError, match="no baseline figure"):
        joint_calibration(figures, GRID, [])
    with pytest.raises(CalibrationError, match=r"gives no 'missing' at 1"):
        joint_calibration(figures, GRID, [Baseline("missing", 1.0, 0.1)])
    with pytest.raises(CalibrationError, match=r"baseline 'x': spread is 0.0; need > 0"):
        Baseline("x", 1.0, 0.0)
    with pytest.raises(CalibrationError, match=r"baseline 'falls' at 1: median -0\.1"):
        joint_calibration(lambda x: {"falls": np.full(8, -0.1)}, GRID, ok)


def test_the_rows_of_a_sweep_give_the_same_fit_as_its_figures():
    noise = np.exp(np.random.default_rng(3).normal(0.0, 0.2, 12))
    rows = pd.DataFrame(
        [
            {"x": x, "trial": t, "falls": 0.1 / x * noise[t], "rises": 0.01 * x * noise[-1 - t]}
            for x in GRID
            for t in range(12)
        ]
    ).sample(frac=1.0, random_state=0)  # any row order

    def own(x: float) -> dict:
        return {"falls": 0.1 / x * noise, "rises": 0.01 * x * noise[::-1]}

    base = [Baseline("falls", 0.025, 0.1), Baseline("rises", 0.05, 0.1)]
    fit, ref = joint_calibration_rows(rows, "x", base), joint_calibration(own, GRID, base)
    assert (fit.value, fit.uncertainty) == (ref.value, ref.uncertainty)
    pd.testing.assert_frame_equal(fit.agreement, ref.agreement)
    with pytest.raises(CalibrationError, match=r"the sweep rows have no column 'f'"):
        joint_calibration_rows(rows, "f", base)
    with pytest.raises(CalibrationError, match=r"gives no 'rises' at 1"):
        joint_calibration_rows(rows.drop(columns="rises"), "x", base)
