"""Time the pieces of notebook 02 (budget: the whole notebook in 90 s with default parameters).

Prints the best of several repeats (wall clock) of one station drawn and calibrated, one run of
the paper's protocol on it (20 + 30 products x 58 points, the 3-2-1 frame of every panel), the
Table 1 analysis of that run, and the before-compensation analysis (168 Lilliefors tests). The
notebook's default run does 100 stations, then 23 sweep values x 40 stations of protocol runs.
"""

from __future__ import annotations

import numpy as np
from timing import best_ms

from calstudy.papers.hybrid import compensation, experiments, simulate_production
from calstudy.papers.hybrid.scenario import load_scenario

BUDGET_S = 90.0
REPEATS = 5


def main() -> None:
    scenario = load_scenario()
    rng = np.random.default_rng(0)
    # the first call also writes the robot program (IK, cached)
    ps = experiments.calibrated_station(rng)
    run = simulate_production.simulate_run(ps, scenario, rng)
    timings = {
        "station drawn and calibrated (sphere + homography)": best_ms(
            lambda: experiments.calibrated_station(np.random.default_rng(1)), REPEATS
        ),
        "protocol run, 50 products x 58 points": best_ms(
            lambda: simulate_production.simulate_run(ps, scenario, np.random.default_rng(2)),
            REPEATS,
        ),
        "Table 1 analysis of one run": best_ms(lambda: compensation.analyse_run(run, 10), REPEATS),
        "before compensation, 168 Lilliefors tests": best_ms(
            lambda: compensation.before_compensation(run, scenario.n_before), REPEATS
        ),
    }
    print(f"production: best of {REPEATS} (budget {BUDGET_S:g} s for the default notebook run)")
    for label, ms in timings.items():
        print(f"  {label:<55s} {ms:8.2f} ms")


if __name__ == "__main__":
    main()
