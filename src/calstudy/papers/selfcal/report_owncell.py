"""Tables and figures of your own cell and of the pose-selection study.

- :func:`pose_selection_table`, :func:`pose_selection_sentence` and
  :func:`pose_selection_figure`: optimised against random poses
  of the same number, from the rows of
  :func:`calstudy.papers.selfcal.experiments.pose_selection_experiment`;
- :func:`residuals_figure` and :func:`validation_figure`: the per-measurement residuals with the
  outliers and the held-out errors before and after against the requirement.
"""

from __future__ import annotations

import textwrap

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from calstudy.core.stats import median_interval  # noqa: E402
from calstudy.papers.selfcal.experiments import OPTIMISED, RANDOM  # noqa: E402
from calstudy.papers.selfcal.report import legend_outside  # noqa: E402

#: columns of the pose-selection rows compared between the two selections
SELECTION_METRICS = {
    "param_error": "parameter error (mm, angles at 1 m)",
    "val_rms_mm": "validation error, RMS (mm)",
    "model_rms_mm": "model error, RMS (mm)",
}


def _ratio(opt: pd.DataFrame, rnd: pd.DataFrame, column: str) -> np.ndarray:
    """Per trial: random over optimised (both converged), paired by trial."""
    both = (
        opt.set_index("trial")[column]
        .to_frame("o")
        .join(rnd.set_index("trial")[column].to_frame("r"), how="inner")
    )
    both = both.dropna()
    return (both["r"] / both["o"]).to_numpy(float)


def pose_selection_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Per number of poses: medians of each selection and the paired ratio random / optimised.

    ``*_ratio_median`` above 1 means the optimised poses did better; ``*_ratio_ci_low/high`` is
    the order-statistic 95 % interval of that median (:func:`median_interval`).
    """
    out = []
    for n, group in rows.groupby("n_poses"):
        opt = group[group["selection"] == OPTIMISED]
        rnd = group[group["selection"] == RANDOM]
        row = {
            "n_poses": int(n),
            "trials": int(len(opt)),
            "optimised_converged": int(opt["converged"].sum()),
            "random_converged": int(rnd["converged"].sum()),
            "optimised_min_sv_median": float(opt["min_sv"].median()),
            "random_min_sv_median": float(rnd["min_sv"].median()),
        }
        for col in SELECTION_METRICS:
            row[f"optimised_{col}_median"] = float(opt[col].median())
            row[f"random_{col}_median"] = float(rnd[col].median())
            ratio = _ratio(opt, rnd, col)
            med, lo, hi = median_interval(ratio) if len(ratio) >= 6 else (np.nan,) * 3
            row |= {
                f"{col}_ratio_median": med,
                f"{col}_ratio_ci_low": lo,
                f"{col}_ratio_ci_high": hi,
            }
        out.append(row)
    return pd.DataFrame(out)


def pose_selection_sentence(table: pd.DataFrame) -> str:
    """Per number of poses, the paired ratios random over optimised (median [95 % interval]) of
    the validation RMS and of the parameter error, from :func:`pose_selection_table`."""
    parts = [
        f"{int(row.n_poses)} poses: validation {row.val_rms_mm_ratio_median:.3g} "
        f"[{row.val_rms_mm_ratio_ci_low:.3g}, {row.val_rms_mm_ratio_ci_high:.3g}], parameters "
        f"{row.param_error_ratio_median:.3g} [{row.param_error_ratio_ci_low:.3g}, "
        f"{row.param_error_ratio_ci_high:.3g}]"
        for row in table.itertuples()
    ]
    counts = sorted({int(n) for n in table["trials"]})
    return "; ".join(parts) + f" (N = {', '.join(str(n) for n in counts)})"


def pose_selection_figure(rows: pd.DataFrame, title: str):
    """Error against the number of poses, optimised and random: median and quartiles; one
    panel per error, stacked for the book's column, the legend beside the data."""
    fig, axes = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True, constrained_layout=True)
    for ax, col in zip(axes, ("param_error", "val_rms_mm"), strict=True):
        for name, style in ((OPTIMISED, "o-"), (RANDOM, "s--")):
            sel = rows[rows["selection"] == name].groupby("n_poses")[col]
            q = sel.quantile([0.25, 0.5, 0.75]).unstack()
            ax.plot(q.index, q[0.5], style, label=f"{name}, median")
            ax.fill_between(q.index, q[0.25], q[0.75], alpha=0.2, label=f"{name}, quartiles")
        ax.set_ylabel(textwrap.fill(SELECTION_METRICS[col], 24))
        ax.grid(alpha=0.3)
        legend_outside(ax)
    sizes = sorted(rows["n_poses"].unique())
    axes[-1].set_xticks(sizes, [str(int(n)) for n in sizes])
    axes[-1].set_xlabel("measuring poses N")
    fig.suptitle(f"{title} ({rows['trial'].nunique()} trials)")
    return fig


def _spans_decades(values) -> bool:
    v = np.asarray(values, float)
    v = v[v > 0]
    return v.size > 0 and v.max() / v.min() > 10.0


def residuals_figure(residuals: pd.DataFrame, sigma_mm: float, threshold: float, title: str):
    """Residual ``|e|`` per calibration measurement, outliers marked, with the rejection line
    (log axis only when the residuals span more than a decade, as outliers make them)."""
    fig, ax = plt.subplots(figsize=(7.5, 3.5), constrained_layout=True)
    ok = ~residuals["outlier"].to_numpy(bool)
    x = np.arange(len(residuals))
    ax.bar(x[ok], residuals["error_mm"][ok], color="tab:blue", label="kept")
    if (~ok).any():
        ax.bar(x[~ok], residuals["error_mm"][~ok], color="tab:red", label="outlier")
    line = sigma_mm * np.sqrt(threshold)
    ax.axhline(line, ls="--", color="k", label="rejection threshold")
    if _spans_decades([*residuals["error_mm"], line]):
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    step = max(1, len(x) // 25)
    ax.set_xticks(x[::step], residuals["pose"].astype(str)[::step])
    return _finish(fig, ax, "pose", "|P - P_ref| (mm)", title)


def validation_figure(table: pd.DataFrame, requirement_mm: float, title: str):
    """Held-out position errors before and after calibration, against the requirement (log
    axis: the errors before and after differ by decades)."""
    fig, ax = plt.subplots(figsize=(7.5, 3.5), constrained_layout=True)
    x = np.arange(len(table))
    ax.bar(x - 0.2, table["before_mm"], 0.4, label="before (nominal)")
    ax.bar(x + 0.2, table["after_mm"], 0.4, label="after (identified)")
    ax.axhline(requirement_mm, ls="--", color="k", label=f"requirement {requirement_mm:g} mm")
    if _spans_decades([*table["before_mm"], *table["after_mm"], requirement_mm]):
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xticks(x, [str(i + 1) for i in x])
    return _finish(fig, ax, "held-out measurement", "position error (mm)", title)


def _finish(fig, ax, xlabel: str, ylabel: str, title: str):
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    legend_outside(ax)
    return fig


def planned_vs_random_table(random: dict) -> pd.DataFrame:
    """The planned poses against random ones for a user's cell, predicted and measured: one row
    each with the median ratio random / planned and its 95 % interval, from the ``random`` dict
    of :func:`calstudy.selfcal.planning.suggest_poses`."""
    stats = ("median", "ci_low", "ci_high")
    return pd.DataFrame(
        [
            {
                "comparison": f"predicted parameter spread ({random['draws']} choices)",
                **{k: random[f"ratio_{k}"] for k in stats},
            },
            {
                "comparison": f"measured held-out RMS error ({random['replications']} "
                "re-measurements)",
                **{k: random[f"measured_ratio_{k}"] for k in stats},
            },
        ]
    )


def measured_selection_sentence(random: dict) -> str:
    """One sentence on the measured comparison of planned and random poses
    (:func:`calstudy.selfcal.planning.measured_selection_errors`)."""
    lo, hi = random["measured_ratio_ci_low"], random["measured_ratio_ci_high"]
    verdict = (
        "the planned poses measure better than random ones"
        if lo > 1.0
        else "random poses measure better than the planned ones"
        if hi < 1.0
        else "the replications cannot tell the planned poses from random ones"
    )
    failed = random["failed_planned"] + random["failed_random"]
    return (
        f"Over {random['replications']} simulated re-measurements of your cell (its identified "
        f"parameters as the truth, {random['noise_sigma_mm']:.3g} mm noise per axis), the RMS "
        f"error at the held-out placements was {random['planned_rms_mm']:.3g} mm with the "
        f"planned poses and {random['random_rms_mm']:.3g} mm with random ones (medians); the "
        f"ratio random / planned has median {random['measured_ratio_median']:.3g} with 95 % "
        f"interval [{lo:.3g}, {hi:.3g}]: {verdict}"
        + (f" ({failed} identifications failed and were left out)." if failed else ".")
    )
