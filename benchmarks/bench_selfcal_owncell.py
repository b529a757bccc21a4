"""Time your-own-cell selfcal steps: identification on measured data (budget 10 ms) and pose
selection from 5,000 candidates for N = 24 (budget 5 s).

Prints the best of several repeats (wall clock) of
``calstudy.selfcal.identify.identify`` and ``measured.identify_measurements`` on the 24
calibration rows of ``data/selfcal/example_measurements`` (the latter with its outlier
rejection: three fits), and of ``design.candidate_jacobians`` plus ``design.select_poses`` on
5,000 candidate poses: 50 planned views of each of 4 spheres, each turned about joint 6 in 25
steps (planning 5,000 views by inverse kinematics is not part of the selection).
"""

from __future__ import annotations

import math

import numpy as np
from timing import best_seconds

from calstudy.core.paths import data_path
from calstudy.papers.selfcal.experiments import example_station
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.papers.selfcal.simulate import view_geometry
from calstudy.selfcal import design, measured
from calstudy.selfcal.identify import identify
from calstudy.selfcal.planning import candidate_views

IDENTIFY_BUDGET_MS = 10.0
SELECT_BUDGET_S = 5.0


def _candidates(scenario, station):
    q, sphere = candidate_views(
        scenario.nominal_robot,
        scenario.sensor.design,
        view_geometry(scenario),
        station.spheres_base,
        50,
        np.random.default_rng(0),
    )
    turns = np.linspace(-math.pi, math.pi, 25, endpoint=False)
    q = np.repeat(q, 25, axis=0)
    q[:, 5] += np.tile(turns, len(q) // 25)
    return q, np.repeat(sphere, 25)


def main() -> None:
    cell = measured.read_cell(data_path("selfcal", "example_measurements"))
    kept = measured.identify_measurements(cell.calibration, cell.start)
    clean = measured.subset(cell.calibration, ~kept.outliers)
    ident = best_seconds(lambda: identify(cell.calibration, cell.start), 20) * 1e3
    ident_clean = best_seconds(lambda: identify(clean, cell.start), 20) * 1e3
    robust = (
        best_seconds(lambda: measured.identify_measurements(cell.calibration, cell.start), 10)
        * 1e3
    )
    scenario = load_scenario()
    station, _ = example_station(scenario, 1)
    q, sphere = _candidates(scenario, station)

    def select():
        blocks, _ = design.candidate_jacobians(
            station.nominal_params, q, station.spheres_part, sphere
        )
        return design.select_poses(blocks, 24)

    sel = best_seconds(select, 3)
    rows = {
        f"identify, {len(cell.calibration)} rows (2 outliers in)": f"{ident:8.2f} ms  (budget 10)",
        f"identify, {len(clean)} rows (outliers out)": f"{ident_clean:8.2f} ms  (budget 10)",
        f"identify_measurements with rejection ({kept.rounds} fits)": f"{robust:8.2f} ms",
        "pose selection, 5,000 candidates, N = 24": f"{sel:8.2f} s   (budget 5)",
    }
    print(f"selfcal own cell: {len(cell.calibration)} calibration rows, {len(q)} candidates")
    for label, text in rows.items():
        print(f"  {label:<45s} {text}")


if __name__ == "__main__":
    main()
