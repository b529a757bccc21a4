"""Coverage of the 95 % intervals of ``measured.identify_measurements`` over simulated cells.

Each cell is drawn as in the calibration experiment of notebook 03 (the paper's scenario with
the joint compliance off, so that the truth lies in the model class): 24 calibration views of 4
spheres, the scanner's cap fits, the robot's repeatability and the tracker's reading of each
sphere, shared by all views of it. The cell is identified twice, with its noise declared
(maximum likelihood, covariance from the declared noise) and without (least squares, covariance
estimated from the residuals), and the script counts how often the truth lies within the 95 %
interval of each parameter and within the 95 % ellipsoid of all 30.

    .venv/bin/python benchmarks/coverage_selfcal_owncell.py [n_cells]   # default 200
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from calstudy.core.errors import CalibrationWarning
from calstudy.core.schema import with_inputs
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.papers.selfcal.simulate import draw_station, simulate
from calstudy.selfcal import measured
from calstudy.selfcal.model import N_PARAMS, angle_wrap

Z95 = 1.959964
ELLIPSOID95 = float(chi2.ppf(0.95, N_PARAMS))


def _noise(scenario) -> dict:
    """The cell's declared noise (only used for the rejection scale; the weights are the
    simulated covariance of each measurement)."""
    repeatability = scenario.repeatability.sigma_mm
    return {"sensor_mm": 0.0, "repeatability_mm": repeatability, "tracker_mm": 0.0}


def _scores(fit, truth) -> tuple[np.ndarray, bool]:
    d = angle_wrap(fit.params - truth)
    std = np.sqrt(np.diag(fit.covariance))
    inside = np.abs(d) <= Z95 * std
    ellipsoid = float(d @ np.linalg.solve(fit.covariance, d)) <= ELLIPSOID95
    return inside, ellipsoid


def main(n_cells: int = 200) -> None:
    scenario = with_inputs(load_scenario(), {"compliance.scale": 0.0})
    rows = {"declared noise": [], "no noise declared": []}
    start = time.perf_counter()
    for i in range(n_cells):
        rng = np.random.default_rng([2026, i])
        station = draw_station(scenario, rng)
        views = scenario.protocol.views_per_sphere
        meas = simulate(scenario, station, station.spheres_base, views, rng)
        bare = replace(meas, cov=None, tracker_cov=None, C_true=None, Q_true=None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CalibrationWarning)
            declared = measured.identify_measurements(
                meas, station.nominal_params, _noise(scenario)
            )
            plain = measured.identify_measurements(bare, station.nominal_params)
        rows["declared noise"].append(_scores(declared, station.true_params))
        rows["no noise declared"].append(_scores(plain, station.true_params))
    seconds = time.perf_counter() - start
    print(f"{n_cells} cells, {seconds:.0f} s")
    for name, scores in rows.items():
        inside = np.array([s[0] for s in scores])  # (cells, 30)
        ellipsoid = np.array([s[1] for s in scores])
        per_param = inside.mean(axis=0)
        print(
            f"{name:>18}: the 95 % intervals cover {100 * inside.mean():.1f} % over all "
            f"parameters (per parameter {100 * per_param.min():.1f}-{100 * per_param.max():.1f} "
            f"%); the 95 % ellipsoid of all {N_PARAMS} covers {100 * ellipsoid.mean():.1f} %"
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
