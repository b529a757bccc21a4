"""Planned against random robot poses for a hand-eye calibration, by Monte Carlo.

Each cell draws 200 candidate flange poses (:func:`calstudy.handeye.simulate.simulate_cell`:
a camera 500 mm from the target, tilted up to 40 deg, rolled up to 45 deg), chooses N of them by
:func:`calstudy.handeye.plan.plan_poses` (nominal X and Z: the truth, camera noise
1e-3 rad and 0.2 mm, tool point 500 mm along the optical axis) and N at random, simulates the
camera's measurements of both sets, calibrates (:func:`calibrate_handeye`, noise estimated) and
measures the tool point's error (a random set the calibration refuses, rotating about one axis,
is left out with its cell and counted). Reported per N: RMS error of planned and random poses, their
ratio with a 95 % bootstrap interval (goal: below 1, the interval excluding 1), and the plan's
predicted RMS error (goal: within 20 % of the planned poses' simulated one). Seeds fixed.
"""

from __future__ import annotations

import sys
import warnings

import numpy as np

from calstudy import CalibrationError, CalibrationWarning
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp
from calstudy.handeye import plan as hplan
from calstudy.handeye import simulate as hs

CELLS = 200
POSE_COUNTS = (6, 10, 20)
CANDIDATES = 200
SIGMA_ROT, SIGMA_TRANS = 1e-3, 0.2
TOOL_POINT = np.array([0.0, 0.0, 500.0])


def tool_error(a, x, z, rng) -> float:
    """Tool-point error (mm) of a calibration from flange poses ``a`` with simulated camera
    measurements."""
    b = geo.perturb(geo.invert(a @ x) @ z, SIGMA_ROT, SIGMA_TRANS, rng)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CalibrationWarning)
            res = hp.calibrate_handeye(a, b)
    except CalibrationError:  # degenerate motions (random poses about one axis): refused
        return np.nan
    moved = geo.apply(res.camera2flange, TOOL_POINT) - geo.apply(x, TOOL_POINT)
    return float(np.linalg.norm(moved))


def cell(n: int, seed: int) -> tuple[float, float, float]:
    """Planned and random tool-point errors (mm) and the plan's prediction for one cell."""
    rng = np.random.default_rng(seed)
    pool = hs.simulate_cell(rng, CANDIDATES, 0.0, 0.0, max_tilt_deg=40.0)
    x, z = pool.camera2flange, pool.target2base
    plan = hplan.plan_poses(pool.flange2base, x, z, n, SIGMA_ROT, SIGMA_TRANS, TOOL_POINT)
    pick = rng.choice(CANDIDATES, n, replace=False)
    planned = tool_error(pool.flange2base[plan.chosen], x, z, rng)
    random = tool_error(pool.flange2base[pick], x, z, rng)
    return planned, random, plan.predicted_rms_mm


def bootstrap_ratio(p: np.ndarray, r: np.ndarray, rng, draws: int = 2000):
    """RMS(p) / RMS(r) and its 95 % percentile bootstrap interval (cells resampled)."""
    idx = rng.integers(0, len(p), (draws, len(p)))
    ratios = np.sqrt(np.mean(p[idx] ** 2, 1) / np.mean(r[idx] ** 2, 1))
    return np.sqrt(np.mean(p**2) / np.mean(r**2)), *np.quantile(ratios, [0.025, 0.975])


def main(cells: int = CELLS) -> None:
    print(f"planned against random poses, {cells} cells per count, {CANDIDATES} candidates")
    print(
        f"  {'poses':>5s} {'planned RMS':>12s} {'random RMS':>11s} {'ratio [95 % CI]':>22s}"
        f" {'predicted':>10s}"
    )
    for n in POSE_COUNTS:
        out = np.array([cell(n, 7000 * n + s) for s in range(cells)])
        refused = np.isnan(out).any(axis=1)
        out = out[~refused]
        ratio, lo, hi = bootstrap_ratio(out[:, 0], out[:, 1], np.random.default_rng(n))
        rms = np.sqrt(np.mean(out**2, axis=0))
        print(
            f"  {n:5d} {rms[0]:9.3f} mm {rms[1]:8.3f} mm {ratio:8.3f} [{lo:.3f}, {hi:.3f}]"
            f" {rms[2]:7.3f} mm"
            + (f"   ({int(refused.sum())} cells refused)" if refused.any() else ""),
            flush=True,
        )


if __name__ == "__main__":
    main(cells=int(sys.argv[1]) if len(sys.argv) > 1 else CELLS)
