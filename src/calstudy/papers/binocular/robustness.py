"""The robustness map of the four ``binocular`` claims (:mod:`calstudy.core.robustness`).

Every ``assumed`` input of ``data/binocular/*.toml`` with a range, and every ``calibrated`` one
over its calibration's uncertainty (its ledger range when no calibration is given), is screened
for the claims whose computation reads it (:func:`calstudy.core.robustness.ledger_inputs`: a new
ledger entry is screened without a change here). A point of the map is a
:func:`robustness_experiment` with the inputs set by their dotted keys (``overrides``, validated
against the ledger) and the calibrated values applied at every point.

The three claims of the calibration chain (``binocular.coc``, ``binocular.observed_error``,
``binocular.transformation``) share one trial of
:func:`~calstudy.papers.binocular.experiments.binocular_trial` at the default errors (group
``chain``): the images are rendered once for the three. They do not read where the field
regions lie (``station.field.*``: a test checks that changing it leaves their statistics as
they are). ``binocular.field`` is a trial of
:func:`~calstudy.papers.binocular.experiments.field_trial` (group ``field``); its verdict is *not
testable* by construction at every station (a rigid change of the hand-eye matrix preserves
every distance between the points it maps, so the flange-frame ratio the verdict rests on is 1
whatever the inputs), so it is screened only over the inputs its own trial alone reads
(``station.field.*``), a check that the construction holds where the regions lie.

Each claim is judged as :func:`calstudy.papers.binocular.report.verdicts` judges it: the claim
and its controls by :func:`calstudy.claims.judge_claim` with the report's columns
(:data:`calstudy.papers.binocular.report.CLAIMS`) and published ratios, gated by the oracle.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import Experiment
from calstudy.core.robustness import (
    Input,
    MapSpec,
    calibrated_input,
    ledger_inputs,
    paper_spec,
    screened_inputs,
)
from calstudy.core.verdicts import not_testable
from calstudy.papers.binocular import experiments, report
from calstudy.papers.binocular.scenario import load_scenario

#: claim -> the trial group that computes it (claims of a group share their trials)
CLAIM_PARTS = {
    "binocular.coc": "chain",
    "binocular.observed_error": "chain",
    "binocular.transformation": "chain",
    "binocular.field": "field",
}
#: the trial of each group
GROUP_TRIALS = {"chain": experiments.binocular_trial, "field": experiments.field_trial}
#: inputs (dotted keys, or a prefix ending in ".") each claim's computation does not read: not
#: screened for that claim (a test checks that changing them leaves its statistic as it is)
NOT_READ = {
    "binocular.coc": ("station.field.",),
    "binocular.observed_error": ("station.field.",),
    "binocular.transformation": ("station.field.",),
}
#: claims screened only over these inputs: the field check's verdict is not testable by
#: construction whatever the station (module docstring), so it is screened over the inputs of
#: its regions alone (a test checks that another input leaves its statistic at 1)
ONLY_READ = {"binocular.field": ("station.field.",)}
#: inputs read only under one defocus mechanism (``sensor.optics.mechanism``): not screened when
#: the scenario runs another
MECHANISM_INPUTS = {"rim": ("sensor.optics.rim_radius_mm", "sensor.optics.rim_distance_mm")}
#: calibrated inputs are screened over their value +- this many standard uncertainties
CALIBRATION_SIGMAS = 2.0


def robustness_trial(setup: experiments.Setup, rng, group: str):
    """One trial of a robustness map: the rows of ``group`` (:data:`GROUP_TRIALS`) on the
    setup's station; the trial draws from the children of ``rng`` as the notebook's own trials
    do, so every point of a map draws the same world, poses and noise."""
    if group not in GROUP_TRIALS:
        raise CalibrationError(f"group {group!r} is not one of {sorted(GROUP_TRIALS)}")
    return GROUP_TRIALS[group](setup, rng)


def robustness_experiment(
    scenario_dir: str = "",
    n_trials: int = 10,
    overrides: dict | None = None,
    group: str = "chain",
) -> Experiment:
    """One point of a robustness map: :func:`robustness_trial` of ``group`` at the default
    errors (robot and calibration error scale 1), on the station of ``scenario_dir`` with
    ``overrides`` (dotted keys of its files, read before they are validated and checked against
    their ledger ranges). The name is the same at every point, so every point runs the same
    trials (paired seeds); the cache's key is the validated station's, so a point whose
    overrides the files already hold shares the trials of the point without them.

    Parameters
    ----------
    scenario_dir : str
        A scenario folder ("" for ``data/binocular``).
    n_trials : int
        Trials, at least 1.
    overrides : dict, optional
        Dotted key -> value (``{"sensor.optics.f_number": 4.0}``).
    group : str
        ``"chain"`` (Tables 2-3, Fig. 13) or ``"field"`` (Table 5).

    Raises
    ------
    CalibrationError
        If ``group`` is unknown, ``n_trials`` below 1, or an override names no input or lies
        outside its range.
    """
    if group not in GROUP_TRIALS:
        raise CalibrationError(f"group {group!r} is not one of {sorted(GROUP_TRIALS)}")
    if n_trials < 1:
        raise CalibrationError(f"n_trials is {n_trials}; need at least 1")
    setup = experiments.Setup(load_scenario(scenario_dir or None, overrides), (1.0,), (1.0,))
    return Experiment(
        "robustness",
        robustness_trial,
        setup,
        int(n_trials),
        ({"group": group},),
        scenario_key=experiments.scenario_key(setup),
    )


def map_inputs(
    scenario_dir: str, calibrated: Mapping[str, tuple[float, float | None]] | None = None
) -> tuple[list[Input], list[str]]:
    """The inputs of the map: the ledger's assumed and calibrated inputs with a range, each with
    the claims whose computation reads it; a calibrated input over its value +-
    :data:`CALIBRATION_SIGMAS` standard uncertainties (within its ledger range) when
    ``calibrated`` gives them (the value is then where the paper's baseline figures put it,
    :attr:`~calstudy.core.robustness.Input.paper`), over its ledger range otherwise.

    Parameters
    ----------
    scenario_dir : str
        The scenario folder ("" for the study's).
    calibrated : mapping of str to (float, float or None), optional
        Dotted key of a calibrated input -> (its calibrated value, standard uncertainty; None:
        unknown, its ledger range is screened around the value).

    Returns
    -------
    (list of Input, list of str)
        The inputs and the ranged inputs not screened (with the reason).

    Raises
    ------
    CalibrationError
        If ``calibrated`` names an input the ledger does not mark calibrated with a range, or a
        value outside its ledger range.
    """
    calibrated = dict(calibrated or {})
    scenario = load_scenario(scenario_dir or None)
    mechanism = scenario.sensor.optics.mechanism
    unused = {
        key: f"read only under the {other} mechanism (the scenario runs {mechanism})"
        for other, keys in MECHANISM_INPUTS.items()
        if other != mechanism
        for key in keys
    }
    found, skipped = screened_inputs(
        scenario,
        CLAIM_PARTS,
        NOT_READ,
        kinds=("assumed", "calibrated"),
        only_read=ONLY_READ,
        unused=unused,
    )
    known = {item.key for item in ledger_inputs(scenario, ("calibrated",))[0]}
    unknown = sorted(set(calibrated) - known)
    if unknown:
        raise CalibrationError(
            f"calibrated inputs {unknown} are not calibrated inputs with a range in the ledger "
            f"of the binocular scenario (those are {sorted(known)})"
        )
    return [
        calibrated_input(item, *calibrated.get(item.key, (item.base, None)), CALIBRATION_SIGMAS)
        if item.kind == "calibrated"
        else item
        for item in found
    ], skipped


def claim_statistics(group: str, rows: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each claim's figure per trial, as its verdict judges it: the ratio with / without the
    correction of the chain's claims (:data:`calstudy.papers.binocular.report.CLAIMS`); for the
    field check, the flange-frame ratio updated / preliminary its not-testable verdict rests on.

    Parameters
    ----------
    group : str
        ``"chain"`` or ``"field"``.
    rows : pandas.DataFrame
        The group's trial rows (one per trial at the default errors).

    Returns
    -------
    dict of str to (n_trials,) ndarray
        Claim id -> its ratio per trial, in trial order.
    """
    d = rows.sort_values("trial")
    if group == "field":
        ratio = d["field_updated_flange"] / d["field_preliminary_flange"]
        return {"binocular.field": ratio.to_numpy(float)}
    d = report.default(rows)
    return {
        cid: (d[report.CLAIMS[cid].figure] / d[report.CLAIMS[cid].baseline]).to_numpy(float)
        for cid, part in CLAIM_PARTS.items()
        if part == group
    }


def judge_claims(group: str, rows: pd.DataFrame) -> dict:
    """The verdicts of the claims of ``group`` from its trial rows, as
    :func:`calstudy.papers.binocular.report.verdicts` judges them: claim id ->
    :class:`~calstudy.core.verdicts.Verdict` (after the oracle gate).

    Parameters
    ----------
    group : str
        ``"chain"`` or ``"field"``.
    rows : pandas.DataFrame
        The group's trial rows.
    """
    if group == "field":
        deviation = float(np.abs(claim_statistics(group, rows)["binocular.field"] - 1).max())
        return {
            "binocular.field": not_testable(
                "identical by construction: a rigid change of the hand-eye matrix preserves "
                f"every distance between points it maps (max |flange ratio - 1| {deviation:.1e})",
                kind="ratio",
                n=len(rows),
            )
        }
    d = report.default(rows)
    return {
        cid: report.judge_correction(d, cid).claim
        for cid, part in CLAIM_PARTS.items()
        if part == group
    }


def map_spec(
    scenario_dir: str,
    calibrated: Mapping[str, tuple[float, float | None]] | None = None,
    only: Sequence[str] = (),
) -> MapSpec:
    """The :class:`~calstudy.core.robustness.MapSpec` of the four claims.

    Parameters
    ----------
    scenario_dir : str
        The scenario folder ("" for the study's).
    calibrated : mapping of str to (float, float or None), optional
        As for :func:`map_inputs`; the values are applied at every point of the map.
    only : sequence of str, optional
        Screen only these inputs (dotted keys, a vector's components all); empty: every input
        of :func:`map_inputs`.

    Raises
    ------
    CalibrationError
        If ``only`` names an input the map does not screen, and as :func:`map_inputs`.
    """
    base = {key: float(value) for key, (value, _) in (calibrated or {}).items()}
    return paper_spec(
        CLAIM_PARTS,
        map_inputs(scenario_dir, calibrated),
        lambda group, setting, n: robustness_experiment(
            scenario_dir, n, {**base, **setting} or None, group
        ),
        claim_statistics,
        judge_claims,
        only=only,
        scenario="binocular scenario",
    )
