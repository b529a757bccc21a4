"""Time the pieces of notebook 02 (budget: the whole notebook in 90 s with default parameters
and n_jobs=2).

Prints the best of several repeats (wall clock) of one station drawn and calibrated, one run of
the paper's protocol on it (20 + 30 products x 58 points, the 3-2-1 frame of every panel), the
Table 1 analysis of that run, and the before-compensation analysis (168 Lilliefors tests, all
columns at once), beside the same 168 tests called one column at a time through statsmodels (the
loop it replaced), as a ratio measured in this run. The notebook's default run does 200
stations, 30 stations x 23 sweep values and 30 stations x 5 robot-error factors.
"""

from __future__ import annotations

import numpy as np
from timing import best_ms

from calstudy.core.stats import lilliefors_test, lilliefors_tests
from calstudy.papers.hybrid import compensation, experiments, simulate_production
from calstudy.papers.hybrid.scenario import load_scenario

BUDGET_S = 90.0
REPEATS = 5


def main() -> None:
    scenario = load_scenario()
    n_before = scenario.production.protocol.n_before
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
            lambda: compensation.before_compensation(run, n_before), REPEATS
        ),
    }
    before = compensation.before_compensation(run, n_before)
    cols = before["deviations"][:, ~before["fixed"]]
    loop = best_ms(lambda: [lilliefors_test(c) for c in cols.T], REPEATS)
    vec = best_ms(lambda: lilliefors_tests(cols), REPEATS)
    timings["168 Lilliefors tests, statsmodels one by one"] = loop
    timings["168 Lilliefors tests, vectorised"] = vec
    print(f"production: best of {REPEATS} (budget {BUDGET_S:g} s for the default notebook run)")
    for label, ms in timings.items():
        print(f"  {label:<55s} {ms:8.2f} ms")
    print(f"  vectorised Lilliefors speed-up (same run): {loop / vec:.0f}x")


if __name__ == "__main__":
    main()
