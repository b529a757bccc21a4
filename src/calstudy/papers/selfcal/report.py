"""Tables, figures and claim rows of the ``selfcal`` notebook, from the experiments' tables.

Everything here is computed from the trial rows of the experiments (and the scenario): the
route table, convergence and robot summaries, the basin and sweep tables, the figures (Figs. 5-7
of the paper, the routes, basin and sweeps) and the verdicts of the five claims by the v2 rule
with their null and oracle controls (:func:`selfcal_verdicts`). The tables of the example cell
(:func:`parameter_table`, :func:`measurement_table`) are the only ones drawn from one simulated
cell.
"""

from __future__ import annotations

import math
import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator  # noqa: E402

from calstudy.claims import (  # noqa: E402
    ClaimColumns,
    ClaimRow,
    Judged,
    claim_row,
    control_rows,
    judge_claim,
)
from calstudy.core.stats import median_and_spread, median_interval  # noqa: E402
from calstudy.papers.selfcal.experiments import (  # noqa: E402
    HISTORY_LENGTH,
    MAX_EVALUATIONS,
    METHODS,
    NULL,
    NULL_ROBOT_NOISE,
    NULL_ROBOT_NOMINAL,
    ONE_STEP,
    ORACLE,
    ROUTES,
)
from calstudy.papers.selfcal.scenario import Scenario  # noqa: E402
from calstudy.papers.selfcal.simulate import Station  # noqa: E402
from calstudy.selfcal.identify import Measurements  # noqa: E402
from calstudy.selfcal.model import (  # noqa: E402
    GROUPS,
    IS_LENGTH,
    PARAM_NAMES,
    ROBOT_NAMES,
    angle_wrap,
)

#: a paired ratio within this of 1 is a tie in ``one_step_better_share`` (the trial tables keep
#: 6 significant digits; a joint refit of the two-step result equals the one-step result)
RATIO_TIE = 1e-4

METRICS = ("val_mean_mm", "val_max_mm", "model_rms_mm", "robot_param_error", "robot_tol_error")

# ----------------------------------------------------------------------------------------------
# tables from the trial rows


def method_column(calib: pd.DataFrame, method: str, column: str) -> np.ndarray:
    """``column`` of ``method`` over the trials, in trial order (one value per trial)."""
    sub = calib[calib["method"] == method].sort_values("trial")
    return sub[column].to_numpy(float)


def best_route(calib: pd.DataFrame) -> str:
    """The sequential multi-step route (:data:`~calstudy.papers.selfcal.experiments.ROUTES`, no
    final joint refit) with the lowest median mean validation error over the trials."""
    medians = {r: float(np.median(method_column(calib, r, "val_mean_mm"))) for r in ROUTES}
    return min(medians, key=medians.get)


def route_table(calib: pd.DataFrame) -> pd.DataFrame:
    """Per method: median and 95 % CI of the median of each error, and the paired ratio of the
    one-step mean validation error to the method's (median, CI, share of trials below 1 by more
    than :data:`RATIO_TIE`)."""
    one = method_column(calib, ONE_STEP, "val_mean_mm")
    best = best_route(calib)
    rows = []
    for name in METHODS:
        row = {"method": name, "best_multi_step": name == best}
        n = 0
        for col in METRICS:
            values = method_column(calib, name, col)
            n = len(values)
            med, lo, hi = median_interval(values)
            row.update({f"{col}_median": med, f"{col}_ci_low": lo, f"{col}_ci_high": hi})
        ratio = one / method_column(calib, name, "val_mean_mm")
        med, lo, hi = median_interval(ratio)
        row.update(
            {
                "trials": n,
                "one_step_ratio_median": med,
                "one_step_ratio_ci_low": lo,
                "one_step_ratio_ci_high": hi,
                "one_step_better_share": float(np.mean(ratio < 1.0 - RATIO_TIE)),
            }
        )
        rows.append(row)
    return pd.DataFrame(rows)


def summarise_history(calib: pd.DataFrame) -> pd.DataFrame:
    """Per start and iteration: median and 5-95 % over trials of the mean position error (mm).

    A trial whose solver stopped earlier keeps its final value; failed runs are left out.
    """
    one = calib[calib["method"] == ONE_STEP].sort_values("trial")
    rows = []
    for start in ("good", "poor"):
        cols = [f"{start}_err_{i}" for i in range(HISTORY_LENGTH)]
        wide = one[cols].dropna().to_numpy(float)
        for it in range(HISTORY_LENGTH):
            med, lo, hi = median_and_spread(wide[:, it], level=0.90)
            rows.append(
                {"start": start, "iteration": it, "median_mm": med, "p5_mm": lo, "p95_mm": hi}
            )
    return pd.DataFrame(rows)


def convergence_summary(calib: pd.DataFrame) -> pd.DataFrame:
    """Counts over the trials: iterations from both starts, same solution, Jacobian rank."""
    one = calib[calib["method"] == ONE_STEP]
    rows = []
    for col in (
        "good_iterations",
        "poor_iterations",
        "poor_solver_iterations",
        "jacobian_rank",
        "jacobian_condition",
    ):
        x = one[col].to_numpy(float)
        rows.append(
            {
                "quantity": col,
                "min": x.min(),
                "median": np.median(x),
                "p95": np.percentile(x, 95),
                "max": x.max(),
            }
        )
    for col in ("poor_converged", "poor_same_solution"):
        x = one[col].astype(bool).to_numpy()
        rows.append(
            {
                "quantity": f"{col} (share)",
                "min": np.nan,
                "median": x.mean(),
                "p95": np.nan,
                "max": np.nan,
            }
        )
    return pd.DataFrame(rows)


def robot_example(calib: pd.DataFrame, trial: int = 0) -> pd.DataFrame:
    """One trial's 18 robot parameters: true, identified (paper, ML) minus nominal, std."""
    row = calib[(calib["method"] == ONE_STEP) & (calib["trial"] == trial)].iloc[0]
    return pd.DataFrame(
        [
            {
                "name": name,
                "unit": "mm" if IS_LENGTH[PARAM_NAMES.index(name)] else "deg",
                "true_minus_nominal": row[f"true_{name}"],
                "identified_minus_nominal": row[f"id_{name}"],
                "ml_identified_minus_nominal": row[f"ml_{name}"],
                "std": row[f"std_{name}"],
            }
            for name in ROBOT_NAMES
        ]
    )


def summarise_robot(calib: pd.DataFrame) -> pd.DataFrame:
    """Per robot parameter over trials: RMS manufacturing error, RMS identification errors, std."""
    one = calib[calib["method"] == ONE_STEP]
    rows = []
    for name in ROBOT_NAMES:
        true = one[f"true_{name}"].to_numpy(float)
        ident = one[f"id_{name}"].to_numpy(float)
        ml = one[f"ml_{name}"].to_numpy(float)
        rows.append(
            {
                "name": name,
                "unit": "mm" if IS_LENGTH[PARAM_NAMES.index(name)] else "deg",
                "rms_true_minus_nominal": float(np.sqrt(np.mean(true**2))),
                "rms_identified_minus_nominal": float(np.sqrt(np.mean(ident**2))),
                "rms_error_paper": float(np.sqrt(np.mean((ident - true) ** 2))),
                "rms_error_ml": float(np.sqrt(np.mean((ml - true) ** 2))),
                "mean_std": float(one[f"std_{name}"].mean()),
            }
        )
    return pd.DataFrame(rows)


def poor_start_iterations(one: pd.DataFrame) -> np.ndarray:
    """Per trial: iterations from the very poor start, :data:`MAX_EVALUATIONS` unless it
    reached the same solution as the good start."""
    same = one["poor_same_solution"].astype(bool).to_numpy()
    return np.where(same, one["poor_iterations"].to_numpy(float), float(MAX_EVALUATIONS))


def basin_table(basin: pd.DataFrame, bound: float) -> pd.DataFrame:
    """Per start scale: trials, share converged, share reaching the good start's solution, the
    iterations (median, 95th percentile) of those that did, and the share that did within
    ``bound`` iterations (the published count)."""
    rows = []
    for scale, sub in basin.groupby("start_scale", sort=True):
        same = sub["same_solution"].astype(bool).to_numpy()
        it = sub["iterations"].to_numpy(float)[same]
        rows.append(
            {
                "start_scale": scale,
                "trials": len(sub),
                "converged_share": float(sub["converged"].astype(bool).mean()),
                "same_solution_share": float(same.mean()),
                "iterations_median": float(np.median(it)) if it.size else np.nan,
                "iterations_p95": float(np.percentile(it, 95)) if it.size else np.nan,
                "within_published_share": float(
                    np.mean(same & (sub["iterations"].to_numpy(float) <= bound))
                ),
            }
        )
    return pd.DataFrame(rows)


def parameter_table(station: Station) -> pd.DataFrame:
    """The 30 parameters: name, group, unit, good initial estimate and true value (mm, deg)."""
    conv = np.where(IS_LENGTH, 1.0, 180.0 / math.pi)
    return pd.DataFrame(
        {
            "name": PARAM_NAMES,
            "group": GROUPS,
            "unit": np.where(IS_LENGTH, "mm", "deg"),
            "initial": station.nominal_params * conv,
            "true": station.true_params * conv,
            "true_minus_initial": angle_wrap(station.true_params - station.nominal_params) * conv,
        }
    )


def measurement_table(meas: Measurements) -> pd.DataFrame:
    """One row per measurement: sphere, joint angles (deg), fitted centre ``C`` and ``P^n``."""
    q = np.degrees(meas.Q)
    return pd.DataFrame(
        {
            "sphere": meas.sphere + 1,
            **{f"q{j + 1}_deg": q[:, j] for j in range(6)},
            "cx_mm": meas.C[:, 0],
            "cy_mm": meas.C[:, 1],
            "cz_mm": meas.C[:, 2],
            "px_mm": meas.P_ref[:, 0],
            "py_mm": meas.P_ref[:, 1],
            "pz_mm": meas.P_ref[:, 2],
        }
    )


# ----------------------------------------------------------------------------------------------
# claims (v2 rule)

UNITS = {
    "selfcal.identification": "model error / CRB",
    "selfcal.convergence": "iterations",
    "selfcal.robot_params": "ratio",
    "selfcal.residual": "mm",
    "selfcal.one_step": "ratio",
}


#: Where each claim's figures sit in the table of :func:`claim_samples`; the rule is the
#: register's.
CLAIMS = {
    "selfcal.identification": ClaimColumns(
        "model_over_crb",
        null="null_model_over_crb",
        oracle="oracle_model_over_crb",
        mechanism="the geometric errors of robot, sensor mounting and base",
    ),
    "selfcal.convergence": ClaimColumns("poor_start_iterations"),
    "selfcal.robot_params": ClaimColumns(
        "robot_tol_error",
        baseline="null_robot_tol_error",
        null="noise_robot_tol_error",
        oracle="oracle_robot_tol_error",
        mechanism="manufacturing errors of the robot",
    ),
    "selfcal.residual": ClaimColumns(
        "val_max_mm",
        null="robot_nominal_val_max_mm",
        oracle="oracle_val_max_mm",
        mechanism="geometric errors that identification can correct",
    ),
    "selfcal.one_step": ClaimColumns(
        "val_mean_mm",
        baseline="best_route_val_mean_mm",
        null="null_val_mean_mm",
        oracle="oracle_val_mean_mm",
        mechanism="error propagation between calibration steps",
    ),
}


#: the methods whose figures :func:`claim_samples` carries, by column prefix
SAMPLE_METHODS = {
    "": ONE_STEP,
    "null_": NULL,
    "robot_nominal_": NULL_ROBOT_NOMINAL,
    "noise_": NULL_ROBOT_NOISE,
    "oracle_": ORACLE,
}


def claim_samples(calib: pd.DataFrame) -> dict[str, np.ndarray]:
    """The per-trial figures of the five claims (one value per trial, in trial order): the
    one-step route's (no prefix), nothing identified (``null_``), base and sensor identified
    with the robot nominal (``robot_nominal_``), the same with the robot nominal plus noise of
    its tolerance class (``noise_``), the noise-free identification (``oracle_``), the model
    error over its Cramer-Rao prediction, the iterations from the very poor start and the best
    multi-step route's mean validation error."""
    one = calib[calib["method"] == ONE_STEP].sort_values("trial")
    crb = one["crb_model_rms_mm"].to_numpy(float)
    out = {"poor_start_iterations": poor_start_iterations(one)}
    for prefix, method in SAMPLE_METHODS.items():
        metrics = ("model_rms_mm", "robot_tol_error", "val_max_mm", "val_mean_mm")
        for metric in metrics:
            out[prefix + metric] = method_column(calib, method, metric)
        out[prefix + "model_over_crb"] = out[prefix + "model_rms_mm"] / crb
    out["best_route_val_mean_mm"] = method_column(calib, best_route(calib), "val_mean_mm")
    return out


def selfcal_verdicts(calib: pd.DataFrame, scenario: Scenario) -> dict[str, Judged]:
    """Verdicts by the v2 rule from the calibration trials: claim id ->
    :class:`calstudy.claims.Judged` (claim after the oracle gate, null and oracle control; the
    controls None where the claim has none, convergence)."""
    x = claim_samples(calib)
    references = {
        "selfcal.identification": scenario.protocol.crb_multiple,
        "selfcal.convergence": float(scenario.published.convergence_iterations),
        "selfcal.residual": scenario.protocol.requirement_mm,
    }
    return {
        cid: judge_claim(cid, x, columns, reference=references.get(cid))
        for cid, columns in CLAIMS.items()
    }


def claim_rows(
    verdicts: dict, scenario: Scenario, notebook: str, conditions: dict | None = None
) -> list[ClaimRow]:
    """The five rows of ``claims.csv``; ``conditions`` (claim id -> text, e.g. from
    :func:`calstudy.papers.selfcal.report_sweeps.condition_sentence`) is appended to the
    verdict's note: the condition under which it holds, stated beside it."""
    conditions = conditions or {}
    published = {
        "selfcal.convergence": f"{scenario.published.convergence_iterations:g}",
        "selfcal.residual": f"{scenario.protocol.requirement_mm:g}",
        "selfcal.identification": f"{scenario.protocol.crb_multiple:g}",
    }
    return [
        claim_row(
            cid,
            judged,
            published=published.get(cid, ""),
            unit=UNITS[cid],
            notebook=notebook,
            note="; ".join(filter(None, (judged.claim.note, conditions.get(cid, "")))),
        )
        for cid, judged in verdicts.items()
    ]


def controls_rows(verdicts: dict) -> list[dict]:
    """The rows of ``controls.csv`` (claims with controls only)."""
    return [row for cid, judged in verdicts.items() for row in control_rows(cid, judged)]


# ----------------------------------------------------------------------------------------------
# figures


START_LABELS = {"good": "good initial estimate", "poor": "very poor initial estimate"}


def legend_outside(ax, fontsize=8, width=24):
    """The axes' legend to the right of the data, outside the plotting area, its labels
    wrapped at ``width`` characters."""
    handles, labels = ax.get_legend_handles_labels()
    labels = [textwrap.fill(label, width) for label in labels]
    ax.legend(
        handles,
        labels,
        fontsize=fontsize,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        frameon=False,
    )


def _finish(fig, ax, title: str, xlabel: str, ylabel: str | None = None):
    """Axis labels, grid, legend (outside the data) and title."""
    ax.set_xlabel(xlabel)
    if ylabel is not None:
        ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    legend_outside(ax)
    ax.set_title(title)
    return fig


def convergence_figure(summary: pd.DataFrame, title: str):
    """Mean position error per LM iteration, median and 5-95 % band (Fig. 5 of the paper).

    ``summary`` comes from :func:`summarise_history`.
    """
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for start, sub in summary.groupby("start", sort=True):
        ax.plot(sub["iteration"], sub["median_mm"], "o-", label=START_LABELS.get(start, start))
        ax.fill_between(sub["iteration"], sub["p5_mm"], sub["p95_mm"], alpha=0.2)
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    return _finish(fig, ax, title, "LM iteration", "mean position error (mm)")


def robot_parameters_figure(trial: pd.DataFrame, title: str):
    """Identified minus nominal robot parameters with their standard deviation (Fig. 6).

    ``trial`` holds one trial of the robot table (``name``, ``unit``, ``true_minus_nominal``,
    ``identified_minus_nominal``, ``std``); lengths and angles get one panel each, stacked.
    """
    fig, axes = plt.subplots(2, 1, figsize=(7.5, 6), constrained_layout=True)
    for ax, unit in zip(axes, ("mm", "deg"), strict=True):
        sub = trial[trial["unit"] == unit]
        x = np.arange(len(sub))
        ax.bar(
            x,
            sub["identified_minus_nominal"],
            0.6,
            yerr=sub["std"],
            capsize=3,
            label="identified (± 1 std)",
        )
        ax.plot(
            x,
            sub["true_minus_nominal"],
            "k_",
            markersize=14,
            mew=2,
            label="true (simulated)",
        )
        ax.set_xticks(x, sub["name"], rotation=45)
        ax.set_ylabel(f"minus nominal ({unit})")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.grid(axis="y", alpha=0.3)
        legend_outside(ax)
    fig.suptitle(title)
    return fig


def residuals_figure(calib: pd.DataFrame, requirement_mm: float, title: str):
    """Largest validation error per calibration (Fig. 7 over all trials): one-step, the best
    multi-step route and the ideal identification, against the requirement."""
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    names = (ONE_STEP, best_route(calib), ORACLE)
    values = [method_column(calib, name, "val_max_mm") for name in names]
    bins = np.linspace(0.0, max(requirement_mm, *(v.max() for v in values)) * 1.05, 40)
    for name, v in zip(names, values, strict=True):
        ax.hist(v, bins=bins, histtype="step", lw=1.5, label=name)
    ax.axvline(requirement_mm, color="r", ls="--", label=f"requirement {requirement_mm:g} mm")
    return _finish(fig, ax, title, "largest validation error of a calibration (mm)", "trials")


def routes_figure(table: pd.DataFrame, requirement_mm: float, title: str):
    """Median and its 95 % CI of the mean validation error per method (log scale);
    ``table`` from :func:`route_table`."""
    sub = table[table["method"] != NULL]
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    y = np.arange(len(sub))
    med = sub["val_mean_mm_median"].to_numpy()
    err = np.vstack([med - sub["val_mean_mm_ci_low"], sub["val_mean_mm_ci_high"] - med])
    ax.errorbar(med, y, xerr=err, fmt="o", capsize=4, label="median, 95 % CI")
    ax.axvline(requirement_mm, color="r", ls="--", label=f"requirement {requirement_mm:g} mm")
    ax.set_yticks(y, [textwrap.fill(m, 24) for m in sub["method"]])
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    return _finish(fig, ax, title, "mean validation error of a calibration (mm)")


def basin_figure(table: pd.DataFrame, bound: float, title: str):
    """Share of trials reaching the good start's solution (and within ``bound`` iterations)
    against the start distance; ``table`` from :func:`basin_table`."""
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    x = table["start_scale"]
    ax.plot(x, table["same_solution_share"], "o-", label="reaches the same\nsolution")
    ax.plot(x, table["within_published_share"], "s--", label=f"... within {bound:g}\niterations")
    ax.set_ylim(-0.05, 1.05)
    ax.set_xticks(list(x), [f"{v:g}" for v in x])
    xlabel = "start distance (multiples of the scenario's very poor start)"
    return _finish(fig, ax, title, xlabel, "share of trials")


def singular_values_figure(table: pd.DataFrame, title: str):
    """Singular values of the scaled identification Jacobian, one line per design."""
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    for design, sub in table.groupby("design", sort=False):
        ax.semilogy(sub["index"], sub["singular_value"], "o-", ms=4, label=design)
    return _finish(fig, ax, title, "index", "singular value (mm per unit)")
