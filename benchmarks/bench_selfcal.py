"""Time one selfcal identification: 24 sphere-centre measurements, 30 parameters (budget 50 ms).

Prints the best of several repeats (wall clock) of ``calstudy.papers.selfcal.selfcal.identify``
from the good
initial estimate and from the very poor one, and of one model evaluation with its Jacobian.
"""

from __future__ import annotations

import numpy as np
from timing import best_ms

from calstudy.papers.selfcal import selfcal as sc

BUDGET_MS = 50.0
REPEATS = 20


def main() -> None:
    scenario = sc.load_scenario()
    station, meas = sc.example_station(scenario, 1)
    poor = sc.poor_start(scenario, station, np.random.default_rng(0))
    good_fit = sc.identify(meas, station.nominal_params)
    poor_fit = sc.identify(meas, poor)
    model = sc.GlobalModel()
    timings = {
        f"identification, good start ({good_fit.iterations} iterations)": best_ms(
            lambda: sc.identify(meas, station.nominal_params), REPEATS
        ),
        f"identification, very poor start ({poor_fit.iterations} iterations)": best_ms(
            lambda: sc.identify(meas, poor), REPEATS
        ),
        "points and 72 x 30 Jacobian (one evaluation)": best_ms(
            lambda: model.points_and_jacobian(station.nominal_params, meas.Q, meas.C), REPEATS
        ),
    }
    print(f"selfcal: {len(meas)} measurements, {sc.N_PARAMS} parameters, best of {REPEATS}")
    for label, ms in timings.items():
        print(f"  {label:<55s} {ms:8.2f} ms   (budget {BUDGET_MS:g} ms per identification)")


if __name__ == "__main__":
    main()
