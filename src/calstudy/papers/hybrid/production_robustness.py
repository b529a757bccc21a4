"""The robustness map of notebook 02's three claims (:mod:`calstudy.core.robustness`).

Every ``assumed`` input of the production scenario (``data/hybrid/station.toml`` and
``data/hybrid/production.toml``) with a range is screened for the claims whose computation reads
it. A point of the map is a :func:`~calstudy.papers.hybrid.experiments.robustness_experiment`
with the input set by its dotted key (``overrides``, validated against the ledger); the three
claims share one trial (a station drawn, calibrated and run through the protocol, with its
robot-off and calibration-noise-floor stations), so they form one trial group, and are judged by
:func:`judge_claims` through the report's own claim function
(:func:`calstudy.papers.hybrid.report.production_verdicts`).

Two inputs are not read by two claims. The number of products in the offset
(``production.protocol.n_compensation``) and the drift before the follow-up
(``production.drift.sigma_mm``) act after the ten panels of Fig. 6, which decide
``hybrid.systematic``; and the correlation coefficient of Eq. 26 does not change when a constant
is added to a coordinate's readings, which is all an offset and a drift do, so neither moves
``hybrid.correlation`` (a test checks both).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from calstudy.core.robustness import MapSpec, paper_spec, screened_inputs
from calstudy.papers.hybrid import experiments, report
from calstudy.papers.hybrid.report_sweeps import deviation_statistics
from calstudy.papers.hybrid.scenario import load_scenario

#: the claims of notebook 02, in the order of its claims table
CLAIMS = ("hybrid.systematic", "hybrid.deviation", "hybrid.correlation")
#: the trial group of the map: the three claims come from the same production trial
GROUP = "production"
#: claim -> the trial group that computes it
CLAIM_PARTS = {cid: GROUP for cid in CLAIMS}
#: inputs (dotted keys, or a prefix ending in ".") each claim's computation does not read: not
#: screened for that claim
AFTER_FIG6 = ("production.protocol.n_compensation", "production.drift.sigma_mm")
NOT_READ = {
    "hybrid.systematic": AFTER_FIG6,
    "hybrid.deviation": (),
    "hybrid.correlation": AFTER_FIG6,
}


def claim_statistics(rows: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each claim's figure per trial, as its verdict judges it: the per-coordinate systematic
    size (mm), the shortfall of the deviation bins from the published ones and the Kolmogorov
    distance of the correlation bins to the published ones.

    Parameters
    ----------
    rows : pandas.DataFrame
        Rows of :func:`~calstudy.papers.hybrid.experiments.production_run` at one
        ``n_compensation`` (one per trial).

    Returns
    -------
    dict of str to (n_trials,) ndarray
        Claim id -> its statistic per trial.
    """
    return {
        "hybrid.systematic": rows["systematic_coord_median_mm"].to_numpy(float),
        "hybrid.deviation": deviation_statistics(rows)["deviation_shortfall"],
        "hybrid.correlation": report.correlation_statistics(rows)["r_distance"],
    }


def judge_claims(rows: pd.DataFrame) -> dict:
    """Each claim's verdict from the trial rows, as the notebook judges it: claim id ->
    :class:`~calstudy.core.verdicts.Verdict` (after its gates).

    Parameters
    ----------
    rows : pandas.DataFrame
        Rows of the production trial at one ``n_compensation``.
    """
    n = len(rows)
    return {cid: v.claim for cid, v in report.production_verdicts(rows, min_trials=n).items()}


def map_spec(scenario_toml: str, only: Sequence[str] = ()) -> MapSpec:
    """The :class:`~calstudy.core.robustness.MapSpec` of the three claims: every ranged assumed
    input of the production scenario, for the claims whose computation reads it.

    Parameters
    ----------
    scenario_toml : str
        The production file ("" for the study's).
    only : sequence of str, optional
        The inputs to screen (:func:`calstudy.core.robustness.paper_spec`, which refuses one the
        map does not screen); empty: every input.
    """
    return paper_spec(
        CLAIM_PARTS,
        screened_inputs(load_scenario(scenario_toml or None), CLAIMS, NOT_READ),
        lambda _, setting, n: experiments.robustness_experiment(
            scenario_toml, n, dict(setting) or None
        ),
        lambda _, rows: claim_statistics(rows),
        lambda _, rows: judge_claims(rows),
        only=only,
        scenario="hybrid production scenario",
    )
