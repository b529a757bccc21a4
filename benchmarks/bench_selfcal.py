"""Time one selfcal identification: 24 sphere-centre measurements, 30 parameters (budget 10 ms).

Prints the best of several repeats (wall clock) of ``calstudy.selfcal.identify.identify``
from the good initial estimate and from the very poor one, and of one model evaluation with its
Jacobian.
"""

from __future__ import annotations

import numpy as np
from timing import best_ms

from calstudy.papers.selfcal.experiments import example_station
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.papers.selfcal.simulate import poor_start
from calstudy.selfcal.identify import identify
from calstudy.selfcal.model import N_PARAMS, GlobalModel

BUDGET_MS = 10.0
REPEATS = 20


def main() -> None:
    scenario = load_scenario()
    station, meas = example_station(scenario, 1)
    poor = poor_start(scenario, station, np.random.default_rng(0))
    # the example cell of the calibration experiment (trial 0 of seed 1)
    good_fit = identify(meas, station.nominal_params)
    poor_fit = identify(meas, poor)
    model = GlobalModel()
    timings = {
        f"identification, good start ({good_fit.iterations} iterations)": best_ms(
            lambda: identify(meas, station.nominal_params), REPEATS
        ),
        f"identification, very poor start ({poor_fit.iterations} iterations)": best_ms(
            lambda: identify(meas, poor), REPEATS
        ),
        "points and 72 x 30 Jacobian (one evaluation)": best_ms(
            lambda: model.points_and_jacobian(station.nominal_params, meas.Q, meas.C), REPEATS
        ),
    }
    print(f"selfcal: {len(meas)} measurements, {N_PARAMS} parameters, best of {REPEATS}")
    for label, ms in timings.items():
        budget = "" if label.startswith("points") else f"   (budget {BUDGET_MS:g} ms)"
        print(f"  {label:<55s} {ms:8.2f} ms{budget}")


if __name__ == "__main__":
    main()
