"""The simulated station: the robot's manufacturing errors drawn at a scale of its tolerances."""

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.models import robots
from calstudy.papers.hybrid import simulate


def test_robot_error_scale_multiplies_the_drawn_link_errors():
    nominal = simulate.make_station(np.random.default_rng(14), robot_errors=False).true.parameters()
    errors = {
        scale: simulate.make_station(
            np.random.default_rng(14), robot_error_scale=scale
        ).true.parameters()
        - nominal
        for scale in (0.0, 1.0, 2.0)
    }
    assert np.all(errors[0.0] == 0.0)  # the nominal robot: no kinematic model error
    assert np.abs(errors[1.0]).max() > 0.1
    np.testing.assert_allclose(errors[2.0], 2.0 * errors[1.0], atol=1e-12)
    # the default is the robot of the tolerances file, draw for draw (notebook 01 unchanged)
    default = robots.perturb_robot(robots.load_robot("kuka_kr16_2"), np.random.default_rng(14))
    assert (errors[1.0] + nominal).tobytes() == default.parameters().tobytes()
    with pytest.raises(CalibrationError, match="robot_error_scale is -1.0"):
        simulate.make_station(np.random.default_rng(14), robot_error_scale=-1.0)
