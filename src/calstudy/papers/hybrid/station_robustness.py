"""The robustness map of the three claims of notebook 01 (:mod:`calstudy.core.robustness`).

Every ``assumed`` input of ``data/hybrid/station.toml`` with a range is screened for the claims
whose computation reads it. A point of the map is a :func:`robustness_experiment` with the
inputs set by their dotted keys (``overrides``, validated against the ledger), in the
sensor-noise-only scenario of the verdicts. Two trial groups: the hand-eye trial
(:func:`~calstudy.papers.hybrid.handeye_experiments.handeye_run`, without the AX = XB baselines,
which no verdict reads) computes ``hybrid.handeye``; the station trial
(:func:`~calstudy.papers.hybrid.experiments.stationary_run`) computes ``hybrid.stationary`` and
``hybrid.rps``. Each group is judged by the report's own claim functions
(:func:`~calstudy.papers.hybrid.report.handeye_judged`, ``stationary_judged``, ``rps_judged``).

What a claim does not read (:data:`NOT_READ`, a test checks it): the hand-eye trial draws the
target, the stationary mounts and the panel from their own streams and never looks at them, and
in the sensor-noise-only scenario the robot is the nominal one without repeatability; the
stationary claim judges the chains with the true hand-eye and flange pose (images only), so the
sphere, the laser stripe and the calibration moves do not reach it. ``hybrid.rps`` is not
testable whatever the inputs (six equations in six unknowns: the penalty and the SO(3) solution
coincide); its statistic, the penalty solution's frame error over the SO(3) solution's, is 1 by
construction, and it is screened on the inputs of the frame (``workpiece.*``) that set its
datums: a robust *not testable* over their range says that no input there makes it testable.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import Experiment
from calstudy.core.robustness import MapSpec, paper_spec, screened_inputs
from calstudy.papers.hybrid import experiments, handeye_experiments, report
from calstudy.papers.hybrid.scenario import load_station

#: claim -> the trial group that computes it
CLAIM_PARTS = {
    "hybrid.handeye": "handeye",
    "hybrid.stationary": "stationary",
    "hybrid.rps": "stationary",
}
#: inputs (dotted keys, or a prefix ending in ".") each claim's computation does not read: not
#: screened for that claim (a test checks that changing them leaves its statistic as it is)
NOT_READ = {
    "hybrid.handeye": ("robot.", "cameras.", "target.", "stationary.", "workpiece."),
    "hybrid.stationary": (
        "robot.",
        "sphere.",
        "calibration_moves.",
        "workpiece.",
        "sensor.sigma_point_mm",
        "sensor.n_points",
        "sensor.arc_half_angle_deg",
        "sensor.centre_floor_mm",
        "sensor.correlation_scale",
    ),
    # 1 by construction whatever it reads; screened on the frame's own inputs
    "hybrid.rps": (
        "robot.",
        "sensor.",
        "sphere.",
        "calibration_moves.",
        "cameras.",
        "target.",
        "stationary.",
    ),
}


def robustness_experiment(group: str, n_trials: int = 10, overrides: dict | None = None):
    """One point of the map: the trial of ``group`` (``"handeye"`` or ``"stationary"``) in the
    sensor-noise-only scenario, with ``overrides`` (dotted keys of ``station.toml``, validated
    against their ledger ranges). The name is the same at every point, so every point runs the
    same trials (paired seeds); the setup, the cache's fingerprint, holds the overrides.

    Raises
    ------
    CalibrationError
        If ``group`` is neither, or an override names no input or leaves its range.
    """
    overrides = dict(overrides or {})
    handeye_experiments.station_config(overrides)  # refused here, before any trial runs
    extra = {"overrides": json.loads(json.dumps(overrides))} if overrides else {}
    point = ({"scenario": report.VERDICT_SCENARIO},)
    if group == "handeye":
        # the hand-eye trial's setup (handeye_experiments.handeye_setup), no baselines
        setup = {**handeye_experiments.handeye_setup(False), **extra}
        trial = handeye_experiments.handeye_run
    elif group == "stationary":
        setup, trial = {"version": 4, **extra}, experiments.stationary_run
    else:
        raise CalibrationError(f"unknown trial group {group!r}; use 'handeye' or 'stationary'")
    return Experiment(f"robustness_{group}", trial, setup, n_trials, point)


def claim_statistics(group: str, rows: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each claim's statistic per trial, as its verdict judges it: the paper's hand-eye error
    over the bound (the larger of rotation and translation), the homography chain's RMS field
    error over the PnP chain's (images only; the verdict pools them), the penalty solution's
    frame error over the SO(3) solution's.

    Parameters
    ----------
    group : str
        ``"handeye"`` or ``"stationary"``.
    rows : pandas.DataFrame
        The group's trial rows.

    Returns
    -------
    dict of str to (n_trials,) ndarray
        Claim id -> its statistic per trial.
    """
    if group == "handeye":
        return {"hybrid.handeye": report.handeye_figures(rows)["sphere"].to_numpy(float)}
    ratios = report.stationary_figures(rows)
    rps = rows[rows["step"] == "rps"]
    frame = rps.pivot_table(index="trial", columns="solver", values="frame_error_mm")
    penalty = [c for c in frame.columns if str(c).startswith("penalty")]
    return {
        "hybrid.stationary": ratios["ratio"].to_numpy(float),
        "hybrid.rps": (frame[penalty[0]] / frame["SO(3)"]).to_numpy(float),
    }


def judge_claims(group: str, rows: pd.DataFrame) -> dict:
    """Each claim's verdict from the group's trial rows, as the notebook judges it: claim id ->
    :class:`~calstudy.core.verdicts.Verdict` (after the oracle gate)."""
    n = int(rows["trial"].nunique())
    if group == "handeye":
        return {"hybrid.handeye": report.handeye_judged(rows, min_trials=n).claim}
    return {
        "hybrid.stationary": report.stationary_judged(rows, min_trials=n).claim,
        "hybrid.rps": report.rps_judged(rows).claim,
    }


def map_spec(only: Sequence[str] = ()) -> MapSpec:
    """The :class:`~calstudy.core.robustness.MapSpec` of the three claims: every ranged assumed
    input of ``data/hybrid/station.toml`` (the file the trials read), for the claims whose
    computation reads it.

    Parameters
    ----------
    only : sequence of str, optional
        The inputs to screen (:func:`calstudy.core.robustness.paper_spec`, which refuses one the
        map does not screen); empty: every input.
    """
    return paper_spec(
        CLAIM_PARTS,
        screened_inputs(load_station(), CLAIM_PARTS, NOT_READ),
        lambda group, setting, n: robustness_experiment(group, n, dict(setting) or None),
        claim_statistics,
        judge_claims,
        only=only,
        scenario="hybrid station",
    )
