"""Coverage of the hand-eye calibration's reported 95 % region of ``camera2flange`` against the
truth, with the noise level not given (the default): 200 cells per pose count, each cell its own
simulated eye-in-hand cell (:func:`calstudy.handeye.simulate.simulate_cell`, camera noise
1e-3 rad and 0.2 mm per axis).

Robot error of the cells (the estimator models a Gaussian robot rotation error of unknown size,
errors in variables, and folds a robot translation error into the camera's):

- ``none``: robot poses exact;
- ``gauss``: Gaussian, 0.02 deg and 0.1 mm per axis (the model's form);
- ``uniform 2x``: uniform, twice those standard deviations (another distribution and size);
- ``laplace 4x``: Laplace, four times the rotation error (heavy tails, a larger share).

Goal: coverage within 90-98 % at every pose count from 6 up. Fewer than 6 poses are flagged
(``HandEyeResult.covariance_trusted``); their coverage is printed for reference. Seeds are fixed:
cell ``s`` of pose count ``n`` draws from ``default_rng(1000 n + s)``.
"""

from __future__ import annotations

import sys
import warnings

import numpy as np

from calstudy import CalibrationError, CalibrationWarning
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp
from calstudy.handeye import simulate as hs

CELLS = 200
POSE_COUNTS = (5, 6, 8, 10, 15, 30)
ROBOT_ROT_DEG, ROBOT_TRANS_MM = 0.02, 0.1


def _robot_error(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, 6)`` robot errors ``[rotation (rad), translation (mm)]`` per axis."""
    scale = np.r_[np.full(3, np.deg2rad(ROBOT_ROT_DEG)), np.full(3, ROBOT_TRANS_MM)]
    if kind == "none":
        return np.zeros((n, 6))
    if kind == "gauss":
        return rng.normal(size=(n, 6)) * scale
    if kind == "uniform 2x":
        return rng.uniform(-1, 1, (n, 6)) * np.sqrt(3.0) * 2.0 * scale
    if kind == "laplace 4x":
        return rng.laplace(size=(n, 6)) / np.sqrt(2.0) * scale * np.r_[4, 4, 4, 1, 1, 1]
    raise ValueError(kind)


def covered(kind: str, n: int, seed: int) -> bool | None:
    """Whether the reported 95 % region of one cell covers the truth (None: refused)."""
    rng = np.random.default_rng(seed)
    cell = hs.simulate_cell(rng, n, 1e-3, 0.2)
    d = _robot_error(kind, n, rng)
    a = cell.flange2base @ geo.make_transform(geo.rotvec_to_matrix(d[:, :3]), d[:, 3:])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CalibrationWarning)
            res = hp.calibrate_handeye(a, cell.target2camera)
    except CalibrationError:
        return None
    return res.camera_distance(cell.camera2flange) <= res.region_limit(0.95)


def main(kinds=("none", "gauss", "uniform 2x", "laplace 4x"), cells: int = CELLS) -> None:
    print(f"coverage of the reported 95 % region of camera2flange, {cells} cells per count")
    print(f"  {'poses':>5s} " + " ".join(f"{k:>12s}" for k in kinds))
    for n in POSE_COUNTS:
        row = []
        for kind in kinds:
            out = [covered(kind, n, 1000 * n + s) for s in range(cells)]
            ok = [o for o in out if o is not None]
            refused = len(out) - len(ok)
            row.append(f"{np.mean(ok):12.3f}" + (f" ({refused} refused)" if refused else ""))
        flag = "   (flagged: fewer than 6 poses)" if n < hp.MIN_TRUSTED_POSES else ""
        print(f"  {n:5d} " + " ".join(row) + flag, flush=True)


if __name__ == "__main__":
    main(cells=int(sys.argv[1]) if len(sys.argv) > 1 else CELLS)
