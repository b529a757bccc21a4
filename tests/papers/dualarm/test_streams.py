"""The station trials of notebook 05 do not change with the last bit of a calibrated value.

The plate's circle-centre noise is calibrated to a baseline figure of the paper (rule 11) and
enters the station experiment as its sweep point; another machine computes it with other last
bits. The trial's random streams are keyed by (seed, experiment, trial) alone, so both values
draw the same numbers and the rows agree to the stated tolerances.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from calstudy.core.montecarlo import trial_rows
from calstudy.io.tolerance import TRIAL_RTOL, compare_tables
from calstudy.papers.dualarm import experiments, report


def test_one_ulp_of_the_calibrated_plate_noise_leaves_the_station_rows():
    value = 0.7164706571379741  # a calibrated value as another machine computed it
    rows = {}
    for v in (value, np.nextafter(value, 1.0)):
        exp = experiments.station_experiment(n_trials=1, plate_sigma_px=float(v))
        rows[v] = trial_rows(exp, 1, 0, 0).drop(columns="plate_sigma_px")
    a, b = rows.values()
    assert not compare_tables(b, a, TRIAL_RTOL)
    glob = report.part(a, "global")
    assert len(glob) and (glob["euclid_mm"] > 0).all()


def test_calibrated_value_is_rounded_to_its_uncertainty():
    rng = np.random.default_rng(0)
    pilot = pd.DataFrame(
        [{"s": s, "y": 0.5 * s + rng.normal(0.0, 0.05)} for s in (0.3, 0.6, 1.0) for _ in range(30)]
    )
    value = report.calibrated_value(pilot, "s", "y", 0.36)
    nudged = pilot.assign(y=pilot["y"] * (1.0 + 1e-13))
    assert report.calibrated_value(nudged, "s", "y", 0.36) == value
    # the standard error of a mean of 30 draws of sd 0.05 is ~0.009 in y, ~0.02 in s
    assert value == round(value, 2)
    assert abs(value - 0.72) < 0.1
