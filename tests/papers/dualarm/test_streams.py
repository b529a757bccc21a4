"""The station trials of notebook 05 do not change with the last bit of a calibrated value.

The plate's circle-centre noise is calibrated to a baseline figure of the paper (rules 11 and
14) and enters the station experiment as its sweep point; another machine computes it with other
last bits (the value fed onwards is rounded to its uncertainty, and even unrounded it would draw
the same numbers). The trial's random streams are keyed by (seed, experiment, trial) alone, so
both values draw the same numbers and the rows agree to the stated tolerances.
"""

from __future__ import annotations

import numpy as np

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
