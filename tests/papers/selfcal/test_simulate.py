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


def test_roll_is_scipys_rotation_to_the_bit():
    """The view's roll about the optical axis, built directly, is the transform of
    euler_zyx_to_matrix (scipy) byte for byte, signed zeros included."""
    from calstudy.core.geometry import euler_zyx_to_matrix, make_transform
    from calstudy.selfcal.planning import _roll

    rng = np.random.default_rng(4)
    special = [0.0, -0.0, 45.0, -45.0, 90.0, -90.0, 180.0, -180.0, 270.0, 1e-300, -1e-300]
    for deg in [*special, *rng.uniform(-90, 90, 3000), *rng.uniform(-720, 720, 1000)]:
        expected = make_transform(euler_zyx_to_matrix(deg, 0, 0), np.zeros(3))
        assert _roll(deg).tobytes() == expected.tobytes(), deg


def test_cap_covariance_is_the_same_for_every_view_direction_up_to_rotation():
    """The cached local covariance turned into each view's frame: the covariance of a cap seen
    along z, rotated, is the covariance of the rotated cap."""
    along_z = cap_centre_covariance([0.0, 0.0, 300.0], 25.0, math.radians(60), 400, 0.05)
    tilted_centre = np.array([120.0, -80.0, 250.0])
    tilted = cap_centre_covariance(tilted_centre, 25.0, math.radians(60), 400, 0.05)
    np.testing.assert_allclose(np.linalg.eigvalsh(tilted), np.linalg.eigvalsh(along_z), rtol=1e-12)
    axis = tilted_centre / np.linalg.norm(tilted_centre)
    # the cap's axis is a principal direction with the along-z variance of z
    np.testing.assert_allclose(axis @ tilted @ axis, along_z[2, 2], rtol=1e-12)
