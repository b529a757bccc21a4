"""The selfcal simulation: the scanned caps and their predicted centre covariance."""

from __future__ import annotations

import math

import numpy as np

from calstudy.estimators.fitting import fit_sphere
from calstudy.papers.selfcal.simulate import cap_centre_covariance, scan_cap


def test_cap_covariance_matches_monte_carlo():
    rng = np.random.default_rng(9)
    centre = np.array([20.0, -10.0, 300.0])
    fits = np.array(
        [
            fit_sphere(scan_cap(centre, 25.0, math.radians(60), 400, 0.05, rng))[0]
            for _ in range(400)
        ]
    )
    empirical = np.cov(fits.T)
    predicted = cap_centre_covariance(centre, 25.0, math.radians(60), 400, 0.05)
    np.testing.assert_allclose(np.diag(empirical), np.diag(predicted), rtol=0.3)
