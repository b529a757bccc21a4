"""Tests of calstudy.papers.binocular.experiments: trials, hold-out check, sweeps, defocus shift."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.estimators import binocular as bino
from calstudy.papers.binocular import experiments as ex
from calstudy.papers.binocular.scenario import load_scenario
from calstudy.papers.binocular.simulate import Imaging, World


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


def test_defocus_shift_grows_with_the_circle_of_confusion(scenario):
    table = ex.defocus_shift(scenario, [850.0, 750.0])
    assert table["coc_radius_px"].iloc[0] == 0.0
    assert table["fused_shift_px"].iloc[1] > 3 * table["fused_shift_px"].iloc[0]
    assert table["fused_rectified_shift_px"].iloc[1] < table["fused_shift_px"].iloc[1]


def test_one_trial_runs_and_is_seeded(scenario):
    a = ex.run_trial(scenario, np.random.default_rng(5))
    assert a["table2"].shape == (7, 2) and a["fig13"].shape == (10, 2)
    assert len(a["field"]) == 3
    assert np.all(np.abs(a["table2"] - a["standard"][:, None]) < 0.5)
    assert math.isfinite(a["fig13_standard"])
    # same seed, same numbers; skipping the field check (drawn last) changes nothing else
    b = ex.run_trial(scenario, np.random.default_rng(5), field=False)
    assert b["field"] == []
    for key in ("standard", "table2", "table3", "fig13"):
        np.testing.assert_array_equal(a[key], b[key])
    np.testing.assert_array_equal(a["handeye"]["updated"], b["handeye"]["updated"])


def test_holdout_modification_does_not_see_the_evaluated_target(scenario):
    pairs = bino.all_pairs(8)
    layout = scenario.layout
    standard = np.linalg.norm(layout[pairs[:, 0]] - layout[pairs[:, 1]], axis=1)
    world = World(None, None, np.zeros((6, 3)), pairs, standard)
    measured = layout.copy()
    measured[0] += 0.05 * (layout[0] - layout[6]) / np.linalg.norm(layout[0] - layout[6])
    measured = bino.with_virtual(measured[:6])
    held = ex.holdout_distances(measured, world)
    want = bino.distances_to_p7(layout)[:6]
    assert held[0, 1] - want[0] == pytest.approx(0.05, abs=1e-4)  # P1 kept its error
    full, _ = bino.modify_observed_error(measured, pairs, standard)
    assert abs(bino.distances_to_p7(full)[0] - want[0]) < 0.01  # the circular reading fixes it


def test_rendered_pipeline_without_noise_or_defocus(scenario):
    """Rendered, sharp, noise-free dots with a perfect sensor: distances to a few micrometres
    (pixel-level Canny edges limit a rendered centre to a few hundredths of a pixel)."""
    trial = ex.run_trial(
        scenario, np.random.default_rng(2), imaging=Imaging(noise=False, defocus=False)
    )
    err = trial["table2"] - trial["standard"][:, None]
    assert np.abs(err).max() < 0.01
    np.testing.assert_array_equal(trial["table2"][:, 0], trial["table2"][:, 1])


def test_calibration_sweep_rows_and_verdicts(scenario):
    from calstudy.claims import VERDICTS

    sweep = ex.calibration_sweep(scenario, 1, [0.0, 2.0], 2)
    assert sweep["calibration_scale"].tolist() == [0.0, 2.0]
    assert (sweep["n_trials"] == 2).all()
    # larger camera errors, larger distance errors; the modification fits them away
    assert sweep["t2_without"].iloc[1] > 2 * sweep["t2_without"].iloc[0]
    assert (sweep["t3_with"] < 0.2 * sweep["t3_without"]).all()
    for key in ("t2", "t3", "t3_holdout"):
        assert (sweep[f"{key}_ratio_low"] <= sweep[f"{key}_ratio"]).all()
        assert (sweep[f"{key}_ratio"] <= sweep[f"{key}_ratio_high"]).all()
    assert set(sweep["verdict_coc"]) | set(sweep["verdict_observed_error"]) <= set(VERDICTS)
    assert (sweep["verdict_observed_error"] != "not reproduced").all()
    with pytest.raises(CalibrationError, match="at least 2"):
        ex.calibration_sweep(scenario, 1, [1.0], 1)
