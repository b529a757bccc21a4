"""Coverage of the 95 % intervals of ``measured.identify_cell`` over simulated cells.

Each cell is drawn as in the calibration experiment of notebook 03 (the paper's scenario with
the joint compliance off, so that the truth lies in the model class): 24 calibration views of 4
spheres, the scanner's cap fits, the robot's repeatability and the tracker's reading of each
sphere, shared by all views of it; and the same poses read as a tracker reflector on the flange
(one-point probe, 27 parameters). Each cell is identified twice, with its noise declared
(maximum likelihood, covariance from the declared noise, normal and chi-square quantiles) and
without (least squares, covariance from the residual variances, quantiles of the studentised
errors simulated with the variance ratio drawn from its restricted likelihood), by
``experiments.interval_coverage``. The script counts how
often the truth lies within each parameter's 95 % interval and within the 95 % region of all the
identified parameters, each with a 95 % Monte Carlo interval: Clopper-Pearson for the region (one
per cell) and for each parameter (the three lowest and the three highest are printed), a
bootstrap over cells for the intervals pooled over the parameters (the parameters of one cell
are not independent).

    .venv/bin/python benchmarks/coverage_selfcal_owncell.py [n_cells]   # default 400
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.stats import binomtest, bootstrap

from calstudy.papers.selfcal.experiments import interval_coverage
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.selfcal.model import PARAM_NAMES


def _pooled(inside: np.ndarray) -> tuple[float, float, float]:
    """Coverage over all identified parameters and cells, with a bootstrap interval over cells."""
    per_cell = np.nanmean(inside, axis=1)
    ci = bootstrap(
        (per_cell,), np.mean, n_resamples=4000, method="percentile", rng=np.random.default_rng(0)
    ).confidence_interval
    return float(per_cell.mean()), float(ci.low), float(ci.high)


def main(n_cells: int = 400) -> None:
    scenario = load_scenario()
    for probe in (False, True):
        start = time.perf_counter()
        result = interval_coverage(scenario, n_cells, probe=probe)
        seconds = time.perf_counter() - start
        what = "one-point probe" if probe else "6R arm, 4 spheres"
        print(f"{what}: {n_cells} cells, {seconds:.0f} s")
        for name, (inside, region) in result.items():
            pooled, lo, hi = _pooled(inside)
            identified = ~np.isnan(inside).all(axis=0)
            per_param = np.nanmean(inside[:, identified], axis=0)
            ci = binomtest(int(region.sum()), len(region)).proportion_ci(0.95)
            print(
                f"  {name:>17}: the 95 % intervals cover {100 * pooled:.1f} % "
                f"[{100 * lo:.1f}, {100 * hi:.1f}] over all parameters (per parameter "
                f"{100 * per_param.min():.1f}-{100 * per_param.max():.1f} %); the 95 % region of "
                f"all {per_param.size} covers {100 * region.mean():.1f} % "
                f"[{100 * ci.low:.1f}, {100 * ci.high:.1f}]"
            )
            names = np.array(PARAM_NAMES)[identified]
            for k in np.argsort(per_param)[[0, 1, 2, -3, -2, -1]]:
                hits = int(np.nansum(inside[:, identified][:, k]))
                ci = binomtest(hits, n_cells).proportion_ci(0.95)
                print(
                    f"{'':>21}{names[k]:>7}: {100 * per_param[k]:.1f} % "
                    f"[{100 * ci.low:.1f}, {100 * ci.high:.1f}]"
                )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 400)
