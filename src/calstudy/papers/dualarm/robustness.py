"""The robustness map of the three ``dualarm`` claims (:mod:`calstudy.core.robustness`).

Every ``assumed`` and ``derived`` input of ``data/dualarm/scenario.toml`` with a range is
screened for the claims whose computation reads it (a derived input over the readings of the
paper's statements, :mod:`calstudy.papers.dualarm.derived`), and the two calibrated inputs (the
drift scale and the plate's circle noise) over their calibration's uncertainty. A point of the
map is a :func:`~calstudy.papers.dualarm.experiments.robustness_experiment` with the input set
by its dotted key (``overrides``, validated against the ledger) or, for a calibrated input, by
the factory's keyword; the claims are judged by :func:`judge_claims`, the one place that turns
trial rows into verdicts here.

Where the paper's own numbers put an input (:func:`paper_values`): each derived input at its
derivation from the stated accuracy; the per-point noise at the stated accuracy; the points a
scan has at the stated cameras' pixels over the visible cap of each sphere at the working
distance (:func:`calstudy.papers.dualarm.derived.cap_points`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import pandas as pd

from calstudy.core.robustness import (
    Input,
    MapSpec,
    calibrated_input,
    paper_spec,
    screened_inputs,
)
from calstudy.papers.dualarm import derived, experiments, report
from calstudy.papers.dualarm.scenario import load_scenario
from calstudy.papers.dualarm.schema import PublishedFile, Scenario

#: claim -> the part of the robustness trial that computes it
CLAIM_PARTS = {"dualarm.icp": "icp", "dualarm.global": "global", "dualarm.vs_circular": "global"}
#: inputs (dotted keys, or a prefix ending in ".") each part does not read: not screened for
#: its claims (a test checks that changing them leaves the part's rows as they are)
NOT_READ = {
    "icp": (
        "survey.",
        "circular_plate.",
        "global_test.placement_offsets_mm",
        "detection.marker_radius_mm",
        "detection.marker_sigma_mm",
        "detection.loss_rate",
        "detection.max_view_angle_deg",
        "design.",
        "plate_sigma_px",
    ),
    "global": ("icp.", "drift_scale"),
}
#: the provenance kinds whose ranged inputs the map screens
SCREENED_KINDS = ("assumed", "derived")
#: calibrated inputs are screened over their value +- this many standard uncertainties
CALIBRATION_SIGMAS = 2.0


def paper_values(scn: Scenario) -> dict[str, tuple[float, str]]:
    """Where the paper's stated instruments put some inputs: dotted key -> (value, how).

    Parameters
    ----------
    scn : Scenario
        The station (its statements, focal length, baseline, working distance, spheres and cap
        angle).

    Returns
    -------
    dict of str to (float, str)
        The derived inputs of :func:`calstudy.papers.dualarm.derived.derived_inputs`,
        ``sensor.point_sigma_mm`` (the stated accuracy) and ``sensor.points_per_scan`` (sphere
        B's cap; sphere A's in the text).
    """
    z = scn.sensor.working_distance_mm
    acc = scn.sensor.stated_accuracy_mm
    cap = {s: derived.cap_points(scn, r) for s, r in scn.spheres.radius.items()}
    out = {
        key: (entry["value"], f"derived: {entry['how']}")
        for key, entry in derived.derived_inputs(scn).items()
    }
    out["sensor.point_sigma_mm"] = (acc, f"the sensors' stated accuracy {acc:g} mm (sec. 4.1)")
    out["sensor.points_per_scan"] = (
        float(round(cap["B"])),
        f"pixels over the visible cap of sphere B at {z:g} mm ({cap['A']:.0f} for sphere A)",
    )
    return out


def default_caps(scn: Scenario) -> dict[str, float]:
    """The highest values screened by default: ``sensor.points_per_scan`` up to the count the
    stated cameras give on sphere B (one point per pixel of its visible cap); sphere A's, some
    six times more, costs minutes per ICP trial and is not screened.

    Parameters
    ----------
    scn : Scenario
        The station.

    Returns
    -------
    dict of str to float
        Dotted key -> cap.
    """
    cap = derived.cap_points(scn, scn.spheres.radius["B"])
    return {"sensor.points_per_scan": float(round(cap))}


def map_inputs(
    scn: Scenario,
    calibrated: Mapping[str, tuple[float, float]],
    caps: Mapping[str, float] | None = None,
) -> tuple[list[Input], list[str]]:
    """The inputs of the map: the ledger's assumed inputs with a range, the claims each is read
    by, where the paper puts it, and the calibrated inputs over their uncertainty.

    Parameters
    ----------
    scn : Scenario
        The station (its validated scenario file).
    calibrated : mapping of str to (float, float)
        Keyword of a calibrated input of the experiment (``drift_scale``, ``plate_sigma_px``)
        -> (value, standard uncertainty).
    caps : mapping of str to float, optional
        Dotted key -> the highest value screened when the top of its range costs too much to
        run (the summary says so).

    Returns
    -------
    (list of Input, list of str)
        The inputs and the ranged inputs not screened (with the reason).
    """
    extra = [
        calibrated_input(key, value, u, CALIBRATION_SIGMAS, bounds="half")
        for key, (value, u) in calibrated.items()
    ]
    not_read = {cid: NOT_READ[part] for cid, part in CLAIM_PARTS.items()}
    found, skipped = screened_inputs(
        scn,
        CLAIM_PARTS,
        not_read,
        kinds=SCREENED_KINDS,
        extra=extra,
    )
    paper = paper_values(scn)
    out = []
    for item in found:
        changes: dict = {}
        if item.key in paper:
            changes.update(paper=paper[item.key][0], paper_note=paper[item.key][1])
        if caps and item.key in caps and caps[item.key] < item.high:
            changes.update(
                high=float(caps[item.key]),
                paper_note=(
                    changes.get("paper_note", "") + f"; screened up to {caps[item.key]:g} "
                    f"of its range's {item.high:g} (cost)"
                ).lstrip("; "),
            )
        out.append(dataclasses.replace(item, **changes))
    return out, skipped


def judge_claims(trials: pd.DataFrame, published: PublishedFile) -> dict:
    """Each claim's verdict from the trial rows, as the notebook judges it: claim id ->
    :class:`~calstudy.core.verdicts.Verdict` (after the oracle gate)."""
    return {cid: v[0] for cid, v in report.dualarm_verdicts(trials, published).items()}


def map_spec(
    scenario_toml: str,
    published: PublishedFile,
    drift: tuple[float, float],
    plate: tuple[float, float],
    caps: Mapping[str, float] | None = None,
    only: Sequence[str] = (),
) -> MapSpec:
    """The :class:`~calstudy.core.robustness.MapSpec` of the three claims.

    Parameters
    ----------
    scenario_toml : str
        The scenario file ("" for the study's).
    published : PublishedFile
        The paper's numbers (for the verdicts).
    drift, plate : (float, float)
        The calibrated drift scale and plate circle noise (px), each with its standard
        uncertainty.
    caps : mapping of str to float, optional
        As for :func:`map_inputs`, over :func:`default_caps`.
    only : sequence of str, optional
        Screen only these inputs (dotted keys or keywords, a vector's components all); empty:
        every input of :func:`map_inputs`.

    Raises
    ------
    CalibrationError
        If ``only`` names an input the map does not screen.
    """
    base = {"drift_scale": drift[0], "plate_sigma_px": plate[0]}
    scn = load_scenario(scenario_toml or None)
    caps = {**default_caps(scn), **(caps or {})}
    screened = map_inputs(scn, {"drift_scale": drift, "plate_sigma_px": plate}, caps)

    def experiment(part: str, setting: Mapping, n_trials: int):
        keywords = {**base, **{k: v for k, v in setting.items() if "." not in k}}
        overrides = {k: v for k, v in setting.items() if "." in k} or None
        return experiments.robustness_experiment(
            scenario_toml, n_trials, section=part, overrides=overrides, **keywords
        )

    return paper_spec(
        CLAIM_PARTS,
        screened,
        experiment,
        lambda _, rows: report.claim_statistics(rows),
        lambda _, rows: judge_claims(rows, published),
        only=only,
        scenario="dualarm scenario",
    )
