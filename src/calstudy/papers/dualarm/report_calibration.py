"""The two nuisance inputs of notebook 05, each calibrated jointly to the paper's baseline figures
(:func:`calstudy.core.jointcal.joint_calibration`, rule 14 of the verdict rule).

* The drift scale of the multi-view scans, to the four before-ICP errors of Section 4.1 at once
  (arm 1 and 2, spheres A and B: one baseline per arm-sphere pair), from the rows of
  :func:`~calstudy.papers.dualarm.experiments.drift_experiment`.
* The circle-centre noise of the circular plate, to Table 3's plate error, from the rows of
  :func:`~calstudy.papers.dualarm.experiments.plate_experiment`.

The value that feeds the experiments is the joint fit rounded to the decade of its standard
uncertainty (:func:`fed_value`), so that another machine draws the same numbers. Nothing here
simulates. Millimetres; the plate noise in pixels.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.jointcal import Baseline, JointFit, joint_calibration_rows
from calstudy.core.stats import round_to_uncertainty
from calstudy.papers.dualarm.schema import PublishedFile

#: the column of the plate pilot that Table 3's plate row is calibrated to
PLATE_COLUMN = "plate_euclid_mm"


def pair_column(arm: int, sphere: str) -> str:
    """The drift pilot's column of one arm-sphere pair's before-ICP error (mm)."""
    return f"before_{int(arm)}{sphere}_mm"


def trial_spreads(pilot: pd.DataFrame, x: str, column: str) -> pd.Series:
    """The study's own spread of one experiment's figure: per value of ``x``, the standard
    deviation over the pilot's trials of the log of ``column``.

    Parameters
    ----------
    pilot : pandas.DataFrame
        Pilot rows: ``x`` and ``column`` (> 0), several trials per value of ``x``.
    x, column : str
        The input's column and the figure's.

    Returns
    -------
    pandas.Series
        Indexed by the values of ``x``, ascending.
    """
    return pilot.groupby(x)[column].agg(lambda v: float(np.std(np.log(v.to_numpy(float)), ddof=1)))


def pilot_spread(pilot: pd.DataFrame, x: str, column: str) -> float:
    """A baseline's relative spread: the median over the grid of :func:`trial_spreads`.

    A paper figure is one run of the station, and the study's model says how much one run's
    figure scatters: the pilot's trials are such runs. Both calibrations take this rule, for
    every baseline alike. A count of averaged errors would understate it: the errors behind one
    figure share what one run draws once (the drift walk of a scan, the plate's one hand-eye and
    base calibration), so they are not independent, and the study's own trials carry that
    sharing.

    Parameters
    ----------
    pilot : pandas.DataFrame
        Pilot rows: ``x`` and ``column`` (> 0).
    x, column : str
        The input's column and the figure's.

    Returns
    -------
    float

    Raises
    ------
    CalibrationError
        If a column is missing or the spread is not positive (fewer than two trials per value).
    """
    for key in (x, column):
        if key not in pilot:
            raise CalibrationError(
                f"the pilot rows have no column {key!r} (they have {list(pilot)})"
            )
    spread = float(trial_spreads(pilot, x, column).median())
    if not spread > 0:
        raise CalibrationError(f"{column}: the pilot's spread over trials is {spread}; need > 0")
    return spread


def drift_baselines(published: PublishedFile, pilot: pd.DataFrame) -> list[Baseline]:
    """The four before-ICP errors of Section 4.1 (``published.icp``), one baseline per arm and
    sphere.

    Each is the mean, over the later views of one multi-view scan, of the distance of that
    view's fitted sphere centre from the first view's (sec. 4.1: "the fitted spherical center
    coordinates of the first group ... were used as a reference"). Its spread is the pilot's
    own (:func:`pilot_spread`): the distances of one scan share its drift, a random walk from
    the first view, so their count does not say how one scan's figure scatters.

    Parameters
    ----------
    published : PublishedFile
        The paper's numbers.
    pilot : pandas.DataFrame
        Rows of :func:`~calstudy.papers.dualarm.experiments.drift_experiment`.

    Returns
    -------
    list of Baseline
        Named by :func:`pair_column`, in the order of ``published.icp.rows``.

    Raises
    ------
    CalibrationError
        As :func:`pilot_spread`.
    """
    out = []
    for arm, sphere, before, _ in published.icp.rows:
        name = pair_column(arm, sphere)
        out.append(Baseline(name, float(before), pilot_spread(pilot, "drift_scale", name)))
    return out


def plate_baselines(published: PublishedFile, pilot: pd.DataFrame) -> list[Baseline]:
    """Table 3's circular-plate error (sphere A, mean Euclidean centre error) as one baseline.

    The paper fits sphere A's centre "across all motion poses" of the arms (sec. 4.2) without
    their number; the errors it averages all rest on one plate calibration, so its figure
    scatters as one run of the station's: the pilot's own spread (:func:`pilot_spread`, as
    :func:`drift_baselines`).

    Parameters
    ----------
    published : PublishedFile
        The paper's numbers.
    pilot : pandas.DataFrame
        Rows of :func:`~calstudy.papers.dualarm.experiments.plate_experiment`.

    Returns
    -------
    list of Baseline
        One, named :data:`PLATE_COLUMN`.

    Raises
    ------
    CalibrationError
        As :func:`pilot_spread`.
    """
    t3 = dict(zip(published.table3.methods, published.table3.rows, strict=True))
    spread = pilot_spread(pilot, "plate_sigma_px", PLATE_COLUMN)
    return [Baseline(PLATE_COLUMN, float(t3["circular plate"][3]), spread)]


def drift_fit(pilot: pd.DataFrame, published: PublishedFile) -> JointFit:
    """The drift scale calibrated to the four before-ICP errors at once (:func:`drift_baselines`).

    Parameters
    ----------
    pilot : pandas.DataFrame
        Rows of :func:`~calstudy.papers.dualarm.experiments.drift_experiment`: ``drift_scale``,
        ``trial`` and one :func:`pair_column` per arm-sphere pair (mm), the same trials at every
        scale.
    published : PublishedFile
        The paper's numbers.

    Returns
    -------
    JointFit
        The fitted scale, its standard uncertainty, and per pair whether it is met.

    Raises
    ------
    CalibrationError
        If a column is missing, the grid has fewer than two scales or fewer than six trials per
        scale (the median's interval), or an error is not positive.
    """
    return joint_calibration_rows(pilot, "drift_scale", drift_baselines(published, pilot))


def plate_fit(pilot: pd.DataFrame, published: PublishedFile) -> JointFit:
    """The plate's circle-centre noise (px) calibrated to Table 3's plate error
    (:func:`plate_baselines`).

    Parameters
    ----------
    pilot : pandas.DataFrame
        Rows of :func:`~calstudy.papers.dualarm.experiments.plate_experiment`:
        ``plate_sigma_px``, ``trial`` and :data:`PLATE_COLUMN` (mm).
    published : PublishedFile
        The paper's numbers.

    Returns
    -------
    JointFit

    Raises
    ------
    CalibrationError
        As :func:`drift_fit`.
    """
    return joint_calibration_rows(pilot, "plate_sigma_px", plate_baselines(published, pilot))


def fed_value(fit: JointFit, name: str) -> float:
    """The calibrated value that feeds the experiments: the joint fit rounded to the decade of
    its standard uncertainty (:func:`calstudy.core.stats.round_to_uncertainty`), the same on
    every machine.

    Parameters
    ----------
    fit : JointFit
        A joint calibration.
    name : str
        The input's name, for the message.

    Returns
    -------
    float

    Raises
    ------
    CalibrationError
        If the fit lies at an end of its grid (the figures pull beyond the swept range) or has
        no positive uncertainty.
    """
    grid = sorted(fit.grid["value"].unique())
    if fit.at_edge:
        raise CalibrationError(
            f"{name}: the joint fit {fit.value:.4g} lies at an end of the swept "
            f"{grid[0]:g}-{grid[-1]:g}; widen the sweep"
        )
    if not fit.uncertainty > 0:
        raise CalibrationError(f"{name}: the joint fit has uncertainty {fit.uncertainty}")
    return round_to_uncertainty(fit.value, fit.uncertainty)


def calibration_table(fit: JointFit, pilot: pd.DataFrame, x: str) -> pd.DataFrame:
    """The calibration of one input from its :class:`JointFit`, long.

    Parameters
    ----------
    fit : JointFit
        The joint calibration of the input.
    pilot : pandas.DataFrame
        The pilot rows it was fitted on (``x``, ``trial`` and one column per baseline).
    x : str
        The input's column.

    Returns
    -------
    pandas.DataFrame
        Rows ``point`` ``grid``: per value of ``x`` and baseline, the median over trials with
        its 95 % interval, ``n`` trials, the paper's value and ``trial_spread`` (the standard
        deviation over trials of the log figure: the simulation's own spread of one
        experiment's figure, beside the baseline's assumed ``spread``). Rows ``joint fit``: per
        baseline, ``x`` the value fed to the experiments (:func:`fed_value`), ``fit`` and
        ``fit_u`` the unrounded fit and its standard uncertainty, the median there, its
        ``ratio`` to the paper's value, the relative ``tolerance`` and its ``coverage`` in
        spreads, whether it is ``met``
        jointly, the value that meets it best ``alone`` and whether any value of the range
        does (``met_alone``), and whether the input is ``identified`` (every baseline met).

    Raises
    ------
    CalibrationError
        As :func:`fed_value`.
    """
    g = fit.grid.rename(columns={"value": x}).assign(point="grid")
    g["paper"] = g["baseline"].map(fit.agreement.set_index("baseline")["target"])
    spreads = {b: trial_spreads(pilot, x, b) for b in g["baseline"].unique()}
    g["trial_spread"] = [spreads[b][v] for v, b in g[[x, "baseline"]].itertuples(index=False)]
    a = fit.agreement.assign(
        point="joint fit",
        fit=fit.value,
        fit_u=fit.uncertainty,
        identified=fit.identified,
        **{x: fed_value(fit, x)},
    ).rename(columns={"target": "paper"})
    out = pd.concat([g, a], ignore_index=True)
    columns = ["point", x, "baseline", "paper", "median", "ci_low", "ci_high", "n"]
    columns += ["trial_spread", "spread", "coverage", "ratio", "tolerance", "met", "alone"]
    columns += ["met_alone"]
    return out[[*columns, "fit", "fit_u", "identified"]]


def _pair_label(name: str) -> str:
    key = name.removeprefix("before_").removesuffix("_mm")
    return f"arm {key[0]} sphere {key[1:]}"


def _span(values, fmt: str) -> str:
    lo, hi = format(min(values), fmt), format(max(values), fmt)
    return lo if lo == hi else f"{lo}-{hi}"


def coverage(table: pd.DataFrame) -> float:
    """The tolerance of a :func:`calibration_table` in spreads: a figure is met within this many
    standard deviations of its log (the baselines' coverage, the same for all)."""
    return float(table.loc[table["point"] == "joint fit", "coverage"].max())


def _spreads(table: pd.DataFrame) -> str:
    fit = table[table["point"] == "joint fit"]
    return (
        f"a figure is met within a factor {_span(1 + fit['tolerance'], '.2f')} of the paper's "
        f"({coverage(table):g} standard deviations of the log of one run's figure, "
        f"{_span(fit['spread'], '.2f')}: its spread over the pilot's trials)"
    )


def _order(rows: pd.DataFrame, column: str) -> str:
    return " < ".join(_pair_label(b) for b in rows.sort_values(column, kind="stable")["baseline"])


def _discrimination(fit: pd.DataFrame) -> str:
    spread = float(fit["paper"].max() / fit["paper"].min())
    allowed = float(1 + fit["tolerance"].min())
    paper, simulated = _order(fit, "paper"), _order(fit, "median")
    order = (
        f"the simulation puts them in the paper's order, {paper}"
        if paper == simulated
        else f"the simulation orders them {simulated}, the paper {paper}"
    )
    if spread <= allowed:
        return (
            f" The paper's four figures lie within a factor {spread:.2f} of one another, inside "
            f"even the narrowest tolerance, a factor {allowed:.2f}: they cannot tell the pairs "
            "apart within one experiment's scatter, so a drift met by all four says only that "
            "one drift scale is consistent with them, not that the study's model reproduces "
            f"their order ({order})."
        )
    return (
        f" The paper's four figures span a factor {spread:.2f}, beyond the narrowest "
        f"tolerance, a factor {allowed:.2f}, so one experiment's scatter does not cover all "
        f"their differences ({order})."
    )


def drift_text(table: pd.DataFrame) -> str:
    """The drift's joint calibration in sentences from :func:`calibration_table`: the fed scale
    and its uncertainty, each pair's median against the paper's and whether it is met, the
    scale that meets each pair best alone, the tolerance, the judgement (rule 14), and what the
    paper's four figures can tell apart: the ratio of the largest to the smallest against the
    tolerance factor, and the simulated order of the pairs against the paper's."""
    fit = table[table["point"] == "joint fit"]
    first = fit.iloc[0]
    pairs = "; ".join(
        f"{_pair_label(r.baseline)} {r.median:.3f} mm against {r.paper:.3f} mm"
        + ("" if r.met else " (not met)")
        for r in fit.itertuples()
    )
    alone = ", ".join(f"{r.alone:.2g}" for r in fit.itertuples())
    text = (
        f"One drift scale fitted to the four before-ICP errors at once, "
        f"{first['drift_scale']:g} (fit {first['fit']:.3g}, standard uncertainty "
        f"{first['fit_u']:.2g}), gives {pairs}; {_spreads(table)}. Each pair alone would take "
        f"{alone} in that order. "
    )
    if first["identified"]:
        text += "All four are met at once: one drift scale is consistent with the four figures."
    else:
        missed = [_pair_label(b) for b in fit.loc[~fit["met"].astype(bool), "baseline"]]
        text += (
            f"The joint scale does not meet {', '.join(missed)}: the paper's four figures do not "
            "identify one drift of the study's model. The joint fit is kept, and the robustness "
            "map carries its uncertainty."
        )
    return text + _discrimination(fit)


def plate_text(table: pd.DataFrame) -> str:
    """The plate's calibration in one sentence from :func:`calibration_table`."""
    r = table[table["point"] == "joint fit"].iloc[0]
    met = "met" if r["met"] else "not met"
    return (
        f"The plate's circle centres get {r['plate_sigma_px']:g} px of noise (fit "
        f"{r['fit']:.3g}, standard uncertainty {r['fit_u']:.2g} px): its route's median error "
        f"at the fit is {r['median']:.3f} mm against Table 3's {r['paper']:.3f} mm, {met}; "
        f"{_spreads(table)}."
    )


def drift_figure(table: pd.DataFrame):
    """The four pairs' median before-ICP errors (95 % intervals) against the drift scale, each
    with the paper's value as a dashed line of its colour, and the joint fit with its standard
    uncertainty as a band."""
    import matplotlib.pyplot as plt

    grid = table[table["point"] == "grid"]
    fit = table[table["point"] == "joint fit"].iloc[0]
    fig, ax = plt.subplots(figsize=(5.8, 3.8))
    for k, (name, rows) in enumerate(grid.groupby("baseline", sort=False)):
        colour = f"C{k}"
        x = rows["drift_scale"].to_numpy(float)
        ax.plot(x, rows["median"], marker="o", color=colour, label=_pair_label(name))
        ax.fill_between(x, rows["ci_low"], rows["ci_high"], color=colour, alpha=0.15)
        ax.axhline(float(rows["paper"].iloc[0]), color=colour, ls="--", lw=1)
    ax.axvspan(fit["fit"] - fit["fit_u"], fit["fit"] + fit["fit_u"], color="0.85", zorder=0)
    ax.axvline(fit["drift_scale"], color="0.3", lw=1, label="joint fit (fed value)")
    ax.set_xlabel("drift scale (x the step of scenario.toml)")
    ax.set_ylabel("before-ICP centre-distance error (mm)")
    ax.set_title("Drift: four pairs (lines), the paper's values (dashed)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
