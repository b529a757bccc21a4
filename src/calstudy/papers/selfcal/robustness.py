"""The robustness map of the five ``selfcal`` claims (:mod:`calstudy.core.robustness`).

Every ``assumed`` input of ``data/selfcal/scenario.toml`` with a range is screened for the
claims whose computation reads it. A point of the map is a
:func:`~calstudy.papers.selfcal.experiments.robustness_experiment` with the input set by its
dotted key (``overrides``, validated against the ledger); the five claims share one trial (the
calibration trial of the claims' experiment), so they form one trial group, and are judged by
:func:`judge_claims` through the report's own claim functions
(:func:`calstudy.papers.selfcal.report.selfcal_verdicts`).

The very poor start (``poor_start.*``) is read only by the convergence claim: the other four
claims' figures come from the identification from the good start, the routes and the controls,
and the very poor start draws from its own child stream (a test checks that changing it leaves
their figures as they are).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from calstudy.core.robustness import MapSpec, paper_spec, screened_inputs
from calstudy.papers.selfcal import experiments, report
from calstudy.papers.selfcal.scenario import Scenario, load_scenario

#: the trial group of the map: the five claims come from the same calibration trial
GROUP = "calibration"
#: claim -> the trial group that computes it
CLAIM_PARTS = {cid: GROUP for cid in report.CLAIMS}
#: inputs (dotted keys, or a prefix ending in ".") each claim's computation does not read: not
#: screened for that claim (a test checks that changing them leaves its statistic as it is)
NOT_READ = {cid: () if cid == "selfcal.convergence" else ("poor_start.",) for cid in report.CLAIMS}


def claim_statistics(calib: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each claim's figure per trial, as its verdict judges it: the claim's figure over its
    paired baseline for a ratio claim (``selfcal.robot_params``, ``selfcal.one_step``), the
    figure itself otherwise (:data:`calstudy.papers.selfcal.report.CLAIMS`).

    Parameters
    ----------
    calib : pandas.DataFrame
        Rows of :func:`~calstudy.papers.selfcal.experiments.calibration_trial` (one per method
        and trial).

    Returns
    -------
    dict of str to (n_trials,) ndarray
        Claim id -> its statistic per trial (units of :data:`report.UNITS`).
    """
    x = report.claim_samples(calib)
    return {
        cid: x[cols.figure] / x[cols.baseline] if cols.baseline else x[cols.figure]
        for cid, cols in report.CLAIMS.items()
    }


def judge_claims(calib: pd.DataFrame, scenario: Scenario) -> dict:
    """Each claim's verdict from the trial rows, as the notebook judges it: claim id ->
    :class:`~calstudy.core.verdicts.Verdict` (after the oracle gate).

    Parameters
    ----------
    calib : pandas.DataFrame
        Rows of the calibration trial.
    scenario : Scenario
        The scenario whose published figures and criteria the claims are judged against.
    """
    return {cid: v.claim for cid, v in report.selfcal_verdicts(calib, scenario).items()}


def map_spec(scenario_toml: str, only: Sequence[str] = ()) -> MapSpec:
    """The :class:`~calstudy.core.robustness.MapSpec` of the five claims: every ranged assumed
    input of the scenario, for the claims whose computation reads it.

    Parameters
    ----------
    scenario_toml : str
        The scenario file ("" for the study's).
    only : sequence of str, optional
        The inputs to screen (:func:`calstudy.core.robustness.paper_spec`, which refuses one the
        map does not screen); empty: every input.
    """
    scenario = load_scenario(scenario_toml or None)
    return paper_spec(
        CLAIM_PARTS,
        screened_inputs(scenario, CLAIM_PARTS, NOT_READ),
        lambda _, setting, n: experiments.robustness_experiment(
            scenario_toml, n, dict(setting) or None
        ),
        lambda _, rows: claim_statistics(rows),
        lambda _, rows: judge_claims(rows, scenario),
        only=only,
        scenario="selfcal scenario",
    )
