"""The simulated dual-arm station: camera and robot poses consistent with the true transforms."""

from __future__ import annotations

import numpy as np

from calstudy.core import geometry as geo
from calstudy.estimators import handeye as he
from calstudy.papers.dualarm import simulate as sim


def test_base_to_base_is_eq11(quiet):
    """Eq. 11 with exact poses gives the true transform, for any number of poses per arm."""
    rng = np.random.default_rng(5)
    flange, w2c = [], []
    for arm in (1, 2):
        cam2world = sim.view_poses(rng, quiet.group_centre(arm), 500.0, 2 + arm, 0.4)
        true, reported = sim.arm_poses(quiet, arm, cam2world, rng, drift=False)
        np.testing.assert_allclose(true, reported, atol=1e-12)
        flange.append(reported)
        w2c.append(geo.invert(cam2world))
    t = he.base_to_base(
        flange[0], quiet.cam2flange[0], w2c[0], flange[1], quiet.cam2flange[1], w2c[1]
    )
    np.testing.assert_allclose(t, quiet.base2_to_base1, atol=1e-9)
