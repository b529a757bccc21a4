"""The simulated dual-arm station: camera and robot poses consistent with the true transforms."""

from __future__ import annotations

import numpy as np

from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.papers.dualarm import experiments as ex
from calstudy.papers.dualarm import simulate as sim


def test_base_to_base_is_eq11(quiet):
    """Eq. 11 with exact poses gives the true transform, for any number of poses per arm."""
    rng = np.random.default_rng(5)
    flange, w2c = [], []
    for arm in (1, 2):
        cam2world = sim.view_poses(rng, quiet.markers.group_centre(arm), 500.0, 2 + arm, 0.4)
        true, reported = sim.arm_poses(quiet, arm, cam2world, rng, drift=False)
        np.testing.assert_allclose(true, reported, atol=1e-12)
        flange.append(reported)
        w2c.append(geo.invert(cam2world))
    t = ex.base_to_base(
        flange[0],
        quiet.calibration.cam2flange[0],
        w2c[0],
        flange[1],
        quiet.calibration.cam2flange[1],
        w2c[1],
    )
    np.testing.assert_allclose(t, quiet.calibration.base2_to_base1, atol=1e-9)


def test_handeye_views_rotate_enough_but_never_near_half_a_turn(scenario):
    """The practitioner's views: every hand-eye pose set passes the rotation diversity check,
    and no pair of poses rotates near 180 deg (where a random roll puts some)."""
    largest = []
    for seed in range(10):
        flange, _ = sim.handeye_images(scenario, 1 + seed % 2, np.random.default_rng(seed))
        he.check_rotation_diversity(flange, he.MIN_PAIR_ROTATION)
        i, j = np.triu_indices(len(flange), 1)
        rel = np.swapaxes(flange[i, :3, :3], 1, 2) @ flange[j, :3, :3]
        largest.append(np.degrees(geo.rotation_angle(rel)).max())
    assert 60.0 < max(largest) < 150.0
    random_roll = scenario.replace({"handeye.roll_deg": 180.0})  # any turn
    flange, _ = sim.handeye_images(random_roll, 1, np.random.default_rng(0))
    i, j = np.triu_indices(len(flange), 1)
    rel = np.swapaxes(flange[i, :3, :3], 1, 2) @ flange[j, :3, :3]
    assert np.degrees(geo.rotation_angle(rel)).max() > 150.0
