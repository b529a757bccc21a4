"""The 95 % intervals and the joint 95 % region of the own-cell identification cover the truth 95 %
of the time over simulated cells, with the noise declared and without (the two residual variances
then estimated, the quantiles simulated)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import binom, chi2, f, norm, t

from calstudy import CalibrationError
from calstudy.core.errors import CalibrationWarning
from calstudy.core.schema import with_inputs
from calstudy.papers.selfcal.experiments import interval_coverage, probe_rows
from calstudy.papers.selfcal.simulate import draw_station, simulate
from calstudy.selfcal.measured import identify_measurements

N_CELLS = 200
#: 99.9 % of the counts of a binomial(N_CELLS, 0.95); the mean over the parameters of one cell
#: varies no more than one parameter's indicator, so the same bounds hold for the pooled count
LOW, HIGH = binom.interval(0.999, N_CELLS, 0.95)
NOISES = ["declared noise", "no noise declared"]


def _check(inside: np.ndarray, region: np.ndarray) -> None:
    assert LOW <= region.sum() <= HIGH, f"region covers {region.mean():.3f}"
    pooled = np.nanmean(inside, axis=1).sum()
    assert LOW <= pooled <= HIGH, f"intervals cover {pooled / N_CELLS:.3f}"


@pytest.fixture(scope="module")
def spheres(scenario):
    return interval_coverage(scenario, N_CELLS)


@pytest.mark.parametrize("noise", NOISES)
def test_6r_arm_with_spheres_covers_95_percent(spheres, noise):
    _check(*spheres[noise])


@pytest.fixture(scope="module")
def probe(scenario):
    return interval_coverage(scenario, N_CELLS, probe=True)


@pytest.mark.parametrize("noise", NOISES)
def test_one_point_probe_covers_95_percent(probe, noise):
    inside, region = probe[noise]
    assert np.isnan(inside).all(axis=0).sum() == 3  # the sensor rotations: not identified
    _check(inside, region)


@pytest.fixture(scope="module")
def cell(scenario):
    quiet = with_inputs(scenario, {"compliance.scale": 0.0})
    rng = np.random.default_rng([2026, 0])
    station = draw_station(quiet, rng)
    return station, simulate(quiet, station, station.spheres_base, 6, rng)


def test_declared_noise_uses_normal_and_chi_square_quantiles(cell, scenario):
    station, meas = cell
    sigma = scenario.repeatability.sigma_mm
    noise = {"sensor_mm": 0.0, "repeatability_mm": sigma, "tracker_mm": 0.0}
    fit = identify_measurements(meas, station.nominal_params, noise)
    std = np.sqrt(np.diag(fit.covariance))
    np.testing.assert_allclose(fit.half_widths(0.9), norm.ppf(0.95) * std, rtol=1e-12)
    assert fit.region_limit(0.95) == pytest.approx(chi2.ppf(0.95, 30), rel=1e-12)
    assert fit.in_region(fit.params) and not fit.in_region(fit.params + 10 * std)
    with pytest.raises(CalibrationError, match=r"params has shape \(29,\); expected \(30\)"):
        fit.in_region(fit.params[:-1])
    with pytest.raises(CalibrationError, match="level"):
        fit.half_widths(1.5)


def test_estimated_noise_widens_the_intervals_and_the_region(cell):
    station, meas = cell
    bare = replace(meas, cov=None, tracker_cov=None, C_true=None, Q_true=None)
    fit = identify_measurements(bare, station.nominal_params)
    std = np.sqrt(np.diag(fit.covariance))
    assert not fit.residual_errors.one_variance
    # the simulated quantiles scatter by a percent or two about their value: on the whole wider
    assert np.median(fit.half_widths() / std) > norm.ppf(0.975)
    assert fit.region_limit() > chi2.ppf(0.95, 30)
    for level in (0.0, 1.0, 1.5):
        with pytest.raises(CalibrationError, match=f"level is {level}; expected strictly between"):
            fit.half_widths(level)
        with pytest.raises(CalibrationError, match=f"level is {level}; expected strictly between"):
            fit.region_limit(level)


def test_one_point_probe_without_declared_noise_has_one_variance(cell, scenario):
    """Every pose its own tracker reading: nothing is shared, one variance is estimated and the
    intervals are Student's t with n - p degrees of freedom (exact for a linear model)."""
    station, meas = cell
    probe = probe_rows(scenario, station, meas, np.random.default_rng(1))
    bare = replace(probe, cov=None, tracker_cov=None, C_true=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        fit = identify_measurements(bare, station.nominal_params)
    n, p = 3 * len(bare), fit.n_identified
    assert p == 27
    std = np.sqrt(np.diag(fit.covariance))[fit.free]
    np.testing.assert_allclose(fit.half_widths()[fit.free], t.ppf(0.975, n - p) * std, rtol=1e-12)
    assert fit.region_limit() == pytest.approx(p * f.ppf(0.95, p, n - p), rel=1e-12)
    assert np.isnan(fit.half_widths()[~fit.free]).all()
