"""Plausibility of a hand-eye fit: instrument ranges, noise level, a break in the series.

Every calibration of :func:`calstudy.handeye.calibrate.calibrate_handeye` ends with
:func:`check_cell`, whatever the noise options: a fit can be exact on paper and still wrong
because the input was misread (rotations transposed, quaternions in another order, a unit
mix, rows shifted against each other, a target knocked halfway through). Three checks, each
cheap (linear in the pose count):

1. *Ranges*: the median camera-target distance lies in the camera's working range and the
   median flange distance from the robot base in the robot's reach (:class:`CellLimits`).
2. *Noise*: the noise level estimated robustly from the residuals (:func:`robust_sigmas`,
   median-based, so an outlier pose does not move it) is below what any instrument gives.
3. *Time order*: the target positions ``A_i X B_i`` implied by each pose do not step in the
   middle of the series (a target that moved, a mid-series re-mount): the largest two-sample
   statistic over every split point against its Bonferroni limit, and a step of at least
   :data:`MIN_STEP` times the per-pose scatter (taken from successive differences, which a
   single step does not inflate); series of :data:`BREAK_MIN_POSES` poses or more.

A failed check is diagnosed by :mod:`calstudy.handeye.diagnose` (only then).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.handeye.refine import pose_scale
from calstudy.handeye.robust import outlier_limit, robust_sigmas

#: false-alarm probability of the time-order break test over the whole series
BREAK_ALPHA = 1e-4
#: median of chi-square with 6 degrees of freedom (``scipy.stats.chi2.median(6)``)
CHI2_6_MEDIAN = 5.348120627447118
#: shorter series are not tested for a break (the scatter of a few successive differences, and
#: the estimate's own error seen through widely spread poses, would raise false alarms)
BREAK_MIN_POSES = 10
#: a break must also step by this many per-pose standard deviations
MIN_STEP = 5.0


@dataclass(frozen=True)
class CellLimits:
    """What a real cell can plausibly give; pass your own to the calibration's ``limits``.

    Attributes
    ----------
    camera_range_mm : (float, float)
        Median camera-target distance, mm (default 20 mm to 5 m).
    robot_reach_mm : (float, float)
        Median distance of the flange from the robot base, mm (default 50 mm to 5 m).
    max_sigma_rot_deg : float
        Largest plausible pose noise (camera and robot together), rotation per axis, deg
        (default 1 deg; a camera pose from a target is good to about 0.01-0.2 deg, a robot to
        about 0.01-0.05 deg).
    max_sigma_trans_fraction : float
        Largest plausible translation noise per axis, as a fraction of the camera-target
        distance (default 0.01: 5 mm at 500 mm; a target pose is good to about 0.1 % of its
        distance, a robot to about 1 mm).
    """

    camera_range_mm: tuple[float, float] = (20.0, 5000.0)
    robot_reach_mm: tuple[float, float] = (50.0, 5000.0)
    max_sigma_rot_deg: float = 1.0
    max_sigma_trans_fraction: float = 0.01

    def __post_init__(self):
        for name in ("camera_range_mm", "robot_reach_mm"):
            lo, hi = getattr(self, name)
            if not 0 <= lo < hi:
                raise CalibrationError(f"{name} must be (low, high) with 0 <= low < high")
        if not (self.max_sigma_rot_deg > 0 and self.max_sigma_trans_fraction > 0):
            raise CalibrationError("max_sigma_rot_deg and max_sigma_trans_fraction must be > 0")


@dataclass
class CellCheck:
    """The outcome of :func:`check_cell`.

    Attributes
    ----------
    camera_distance_mm, robot_distance_mm : float
        Median camera-target distance and median flange distance from the base, mm.
    sigma_rot_deg, sigma_trans_mm : float
        Noise level estimated robustly from the residuals, deg and mm per axis.
    noise_ratio : float
        The larger of the two noise levels over its plausible limit (above 1: implausible).
    break_after : int
        Row after which the implied target position steps most (-1 if it does not).
    break_step_mm : float
        Size of that step, mm, and ``break_sigma_mm`` the per-pose scatter.
    failures : list of str
        What failed, as sentences ("" none).
    diagnosis : list of (str, float)
        After a failure: the readings tried, best first, with their noise ratio.
    message : str
        The refusal (or warning) text, "" if the fit passed.
    """

    camera_distance_mm: float
    robot_distance_mm: float
    sigma_rot_deg: float
    sigma_trans_mm: float
    noise_ratio: float
    break_after: int = -1
    break_step_mm: float = 0.0
    break_sigma_mm: float = 0.0
    failures: list = field(default_factory=list)
    diagnosis: list = field(default_factory=list)
    message: str = ""


def noise_ratio(res: np.ndarray, scale_mm: float, limits: CellLimits) -> tuple[float, float, float]:
    """Robust noise level of per-pose residuals ``(N, 6)`` (deg, mm) and its ratio to the
    plausible limit of ``limits`` at the camera-target distance ``scale_mm``."""
    s_rot, s_trans = robust_sigmas(res)
    s_rot_deg = float(np.rad2deg(s_rot))
    ratio = max(
        s_rot_deg / limits.max_sigma_rot_deg,
        s_trans / (limits.max_sigma_trans_fraction * scale_mm),
    )
    return s_rot_deg, float(s_trans), float(ratio)


def range_failures(a: np.ndarray, b: np.ndarray, limits: CellLimits) -> tuple[float, float, list]:
    """Median camera-target and flange-base distances (mm) and the range failures, as
    sentences."""
    cam = float(np.median(np.linalg.norm(b[:, :3, 3], axis=1)))
    rob = float(np.median(np.linalg.norm(a[:, :3, 3], axis=1)))
    out = []
    lo, hi = limits.camera_range_mm
    if not lo <= cam <= hi:
        out.append(
            f"the median camera-target distance {cam:.4g} mm is outside the camera's working "
            f"range [{lo:g}, {hi:g}] mm"
        )
    lo, hi = limits.robot_reach_mm
    if not lo <= rob <= hi:
        out.append(
            f"the median flange distance from the robot base {rob:.4g} mm is outside the "
            f"robot's reach [{lo:g}, {hi:g}] mm"
        )
    return cam, rob, out


def series_break(a, b, x, scale_mm: float, weights=None) -> tuple[int, float, float, float]:
    """The largest step in time order of the implied target poses ``A_i X B_i``.

    Each pose gives the target in the robot base (position, and rotation times ``scale_mm``, so
    both are mm). With the per-pose scatter ``s`` from successive differences (median based),
    the two-sample statistic ``k (n - k) / n |m_1 - m_2|^2 / s^2`` of every split ``k`` is
    chi-square with 6 degrees of freedom under a steady target.

    Returns
    -------
    (int, float, float, float)
        Row after which the step is largest, the step (mm), the scatter ``s`` (mm) and the
        statistic's ratio to its Bonferroni limit at :data:`BREAK_ALPHA` (above 1: a break).
    """

    keep = np.ones(len(a), bool) if weights is None else np.asarray(weights) > 0
    idx = np.flatnonzero(keep)
    n = len(idx)
    if n < BREAK_MIN_POSES:
        return -1, 0.0, 0.0, 0.0
    zs = a[idx] @ x @ b[idx]
    rot = geo.so3_log(np.einsum("ji,njk->nik", zs[0, :3, :3], zs[:, :3, :3])) * scale_mm
    v = np.concatenate([zs[:, :3, 3], rot], 1)
    d2 = np.sum(np.diff(v, axis=0) ** 2, 1)
    # successive differences: 2 s^2 chi2(6) each; their median is not moved by one step
    s2 = max(float(np.median(d2) / (2.0 * CHI2_6_MEDIAN)), 1e-24)
    # an outlier pose differs from both neighbours in time, a break from one only: leave the
    # outliers out (the outlier flag reports them); the end poses are compared with the two
    # poses next to them
    lim = 2.0 * s2 * outlier_limit(1e-3)
    prev = np.concatenate([[np.sum((v[0] - v[2]) ** 2)], d2])
    nxt = np.concatenate([d2, [np.sum((v[-1] - v[-3]) ** 2)]])
    inl = np.minimum(prev, nxt) <= lim
    idx, v = idx[inl], v[inl]
    n = len(idx)
    if n < BREAK_MIN_POSES - 2:
        return -1, 0.0, float(np.sqrt(s2)), 0.0
    c = np.cumsum(v, axis=0)
    k = np.arange(1, n)
    m1 = c[:-1] / k[:, None]
    m2 = (c[-1] - c[:-1]) / (n - k)[:, None]
    step = np.sum((m1 - m2) ** 2, 1)
    stat = k * (n - k) / n * step / s2
    # splits near the ends rest on few poses: leave the outer two out
    stat[:2] = stat[-2:] = 0.0
    j = int(np.argmax(stat))
    limit = outlier_limit(BREAK_ALPHA / max(n - 5, 1))
    return int(idx[j]), float(np.sqrt(step[j])), float(np.sqrt(s2)), float(stat[j] / limit)


def check_cell(a, b, x, res, weights, limits: CellLimits, slack: float = 1.0) -> CellCheck:
    """Ranges, noise level and time order of a hand-eye fit.

    Parameters
    ----------
    a, b : (N, 4, 4) arrays
        Canonical robot and camera poses (mm).
    x : (4, 4) array
        The fitted ``X``.
    res : (N, 6) array
        Per-pose residuals ``[t (mm), rot (rad)]`` of the fit.
    weights : (N,) array
        Per-pose weights; poses of weight 0 are left out.
    limits : CellLimits
    slack : float
        Multiplies the noise limits (a closed-form start is checked with some, so that only a
        gross failure stops the calibration before its refinement).

    Returns
    -------
    CellCheck
        With ``failures`` as sentences (empty: the fit passed).
    """
    cam, rob, fails = range_failures(a, b, limits)
    scale = pose_scale(b)
    if weights is None:
        raise CalibrationError("check_cell needs the per-pose weights (an (N,) array); got None")
    keep = np.asarray(weights) > 0
    s_rot, s_trans, ratio = noise_ratio(res[keep], scale, limits)
    if ratio > slack:
        fails.append(
            f"the residuals imply a pose noise of {s_rot:.3g} deg and {s_trans:.3g} mm per "
            f"axis, beyond any instrument (limits {limits.max_sigma_rot_deg:g} deg and "
            f"{limits.max_sigma_trans_fraction * scale:.3g} mm at {scale:.4g} mm)"
        )
    row, step, sigma, brk = series_break(a, b, x, scale, keep)
    check = CellCheck(cam, rob, s_rot, s_trans, ratio, failures=fails)
    if brk > 1.0 and step > MIN_STEP * sigma:
        check.break_after, check.break_step_mm, check.break_sigma_mm = row, step, sigma
        fails.append(
            f"the target position implied by the poses steps by {step:.3g} mm after row {row} "
            f"(per-pose scatter {sigma:.3g} mm): the target moved, or the series breaks there"
        )
    return check
