"""Rigid-transform helpers of calstudy.core.geometry."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import geometry as geo


def test_mean_transform_of_equal_and_nearby_transforms():
    rng = np.random.default_rng(1)
    t = geo.make_transform(geo.random_rotation(rng), rng.uniform(-100, 100, 3))
    np.testing.assert_allclose(geo.mean_transform(np.stack([t, t, t])), t, atol=1e-12)
    # two rotations +-a about one axis average to the middle one; translations to their mean
    a = geo.make_transform(geo.rotvec_to_matrix([0.0, 0.0, 0.1]), [1.0, 0.0, 0.0])
    b = geo.make_transform(geo.rotvec_to_matrix([0.0, 0.0, -0.1]), [3.0, 2.0, 0.0])
    np.testing.assert_allclose(
        geo.mean_transform(np.stack([a, b])),
        geo.make_transform(np.eye(3), [2.0, 1.0, 0.0]),
        atol=1e-12,
    )


def test_mean_transform_rejects_non_rigid():
    bad = np.tile(np.eye(4), (2, 1, 1))
    bad[1, 0, 0] = 2.0
    with pytest.raises(CalibrationError, match="not orthonormal"):
        geo.mean_transform(bad)
