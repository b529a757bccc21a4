"""The noise model's assumed parts (a centre-noise floor, the strength of the line laser's y-z
correlation) reach the hand-eye trial through station.toml's ledger, and at their values in the
file leave the trial's rows as they were."""

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import trial_rng
from calstudy.papers.hybrid import handeye_experiments as he


def _rows(parameter=None, value=None):
    setup = he.handeye_setup(False)
    rng = trial_rng(3, "handeye_noise_model", {}, 0)
    if parameter is None:
        return pd.DataFrame(he.handeye_run(setup, rng)).set_index("method")
    return pd.DataFrame(he.handeye_input_run(setup, rng, parameter, value)).set_index("method")


def test_file_values_leave_the_trial_as_it_was_and_other_values_move_it():
    plain = _rows()
    for key, value in (("sensor.centre_floor_mm", 0.0), ("sensor.correlation_scale", 1.0)):
        pd.testing.assert_frame_equal(_rows(key, value), plain)
    floor = _rows("sensor.centre_floor_mm", 0.02)
    weaker = _rows("sensor.correlation_scale", 0.5)
    for moved in (floor, weaker):
        assert not np.isclose(moved.loc["sphere", "rotation_error_deg"],
                              plain.loc["sphere", "rotation_error_deg"])
        # the bound follows the noise model: the floor adds information loss
    assert floor.loc["CRB", "rotation_error_deg"] > plain.loc["CRB", "rotation_error_deg"]
    # the noise-free oracle does not see the noise model
    assert floor.loc["oracle control", "rotation_error_deg"] < 1e-6


def test_values_outside_the_ledger_range_are_refused():
    with pytest.raises(CalibrationError, match=r"correlation_scale = 0.3: outside its plausible"):
        _rows("sensor.correlation_scale", 0.3)
    with pytest.raises(CalibrationError, match="no values of sensor.centre_floor_mm"):
        he.handeye_noise_model_experiment(centre_floors_mm=())
