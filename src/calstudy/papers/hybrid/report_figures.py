"""The hybrid study's figures, each drawn from a results table (never from raw simulation state).

Notebook 01: errors by method, against noise and move count, per stationary sensor, and the
per-trial hand-eye ratio over the swept move ranges. Notebook 02: Fig. 6 of the paper, the
Table 1 headline shares against the number of products in the offset, against each assumption
and against the size of the robot's manufacturing errors. Published values are read from
``data/hybrid/published.toml``.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy.stats import norm  # noqa: E402

from calstudy.core.errors import CalibrationError  # noqa: E402
from calstudy.papers.hybrid.scenario import (  # noqa: E402
    AXES,
    SWEEP_LABELS,
    Scenario,
    load_published,
)

#: axis label of the sweep of the robot's manufacturing errors
ROBOT_ERROR_LABEL = "factor on the robot's kinematic tolerances"

#: rows of the error summaries not drawn: the oracle control's errors are rounding (1e-10), which
#: would stretch a log axis over ten decades; they are in the tables
NOT_DRAWN = ("oracle control",)

ERROR_COLUMNS = (
    ("rot_deg_rms", "RMS rotation error (deg)"),
    ("trans_mm_rms", "RMS translation error (mm)"),
)


#: width of a figure in the book's column (inches at the 120 dpi of ``write_figure``)
COLUMN_IN = 7.2


def _legend_below(fig, ax, ncol: int = 3) -> None:
    """The legend of ``ax`` under the figure, outside the data."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=8, frameon=False)


def _plain_ticks(ax, values) -> None:
    """Ticks at ``values`` labelled in plain numbers (no 10^x notation), no minor ticks."""
    ax.set_xticks(list(values), [f"{v:g}" for v in values])
    ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())


def method_bars(summary: pd.DataFrame, group: str, hue: str, title: str):
    """Grouped bars of RMS rotation and translation errors, one panel each, on a log axis (the
    methods span decades, from the bound to the null control); legend under the panels.

    ``summary`` comes from :func:`calstudy.papers.hybrid.report.summarise_errors` with columns
    ``group`` and ``hue`` among its keys.
    """
    fig, axes = plt.subplots(1, 2, figsize=(COLUMN_IN, 3.9), layout="constrained")
    summary = summary[~summary[group].isin(NOT_DRAWN)]
    groups = list(dict.fromkeys(summary[group]))
    hues = list(dict.fromkeys(summary[hue]))
    width = 0.8 / len(hues)
    for ax, (col, label) in zip(axes, ERROR_COLUMNS, strict=True):
        for j, h in enumerate(hues):
            sub = summary[summary[hue] == h].set_index(group).reindex(groups)
            ax.bar(
                np.arange(len(groups)) + (j - (len(hues) - 1) / 2) * width,
                sub[col],
                width,
                label=str(h),
            )
        ax.set_xticks(np.arange(len(groups)), groups, rotation=35, ha="right", fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    _legend_below(fig, axes[0])
    fig.suptitle(title, fontsize=11)
    return fig


def sweep_lines(summary: pd.DataFrame, x: str, xlabel: str, title: str, logx: bool = False):
    """RMS errors against a swept quantity, one line per method, rotation and translation;
    ticks at the swept values in plain numbers, legend under the panels."""
    fig, axes = plt.subplots(1, 2, figsize=(COLUMN_IN, 3.6), layout="constrained")
    values = sorted(summary[x].unique())
    summary = summary[~summary["method"].isin(NOT_DRAWN + ("null control",))]
    for ax, (col, label) in zip(axes, ERROR_COLUMNS, strict=True):
        for method, sub in summary.groupby("method", sort=False):
            style = "k--" if method == "CRB" else "o-"
            ax.plot(sub[x], sub[col], style, label=method)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(label)
        ax.set_yscale("log")
        if logx:
            ax.set_xscale("log")
        _plain_ticks(ax, values)
        ax.tick_params(axis="x", labelrotation=45, labelsize=8)
        ax.grid(alpha=0.3)
    _legend_below(fig, axes[0], ncol=4)
    fig.suptitle(title, fontsize=11)
    return fig


def per_sensor_points(summary: pd.DataFrame, title: str):
    """RMS field-centre error of each stationary sensor, one marker per variant, on a log axis
    (the variants span decades: an exact target to the uncalibrated design pose); legend under
    the panel."""
    fig, ax = plt.subplots(figsize=(COLUMN_IN, 3.8), layout="constrained")
    variants = list(dict.fromkeys(summary["variant"]))
    markers = "osD^v<>p"
    for j, variant in enumerate(variants):
        sub = summary[summary["variant"] == variant]
        ax.plot(
            sub["sensor"] + (j - (len(variants) - 1) / 2) * 0.08,
            sub["field_mm_rms"],
            markers[j % len(markers)],
            label=variant,
        )
    ax.set_yscale("log")
    ax.set_xticks(sorted(summary["sensor"].unique()))
    ax.set_xlabel("stationary sensor")
    ax.set_ylabel("RMS field-centre error (mm)")
    ax.grid(alpha=0.3)
    _legend_below(fig, ax, ncol=3)
    fig.suptitle(title, fontsize=11)
    return fig


def ratio_boxes(ratios: pd.DataFrame, bound: float, labels: dict, defaults: dict):
    """Per-trial distribution of the hand-eye ratio (paper's method / CRB RMS) at every value
    of each swept move range (columns ``parameter, value, sphere``), one panel per range; the
    bound of the criterion dashed, the default value's box filled."""
    names = list(dict.fromkeys(ratios["parameter"]))
    fig, axes = plt.subplots(
        1, len(names), figsize=(COLUMN_IN, 3.6), layout="constrained", squeeze=False
    )
    for ax, name in zip(axes[0], names, strict=True):
        sub = ratios[ratios["parameter"] == name]
        values = sorted(sub["value"].unique())
        data = [sub.loc[sub["value"] == v, "sphere"].to_numpy() for v in values]
        boxes = ax.boxplot(
            data, whis=(5, 95), showfliers=True, patch_artist=True, medianprops={"color": "k"}
        )
        for v, patch in zip(values, boxes["boxes"], strict=True):
            patch.set_facecolor("0.8" if np.isclose(v, defaults[name]) else "white")
        ax.set_xticks(np.arange(1, len(values) + 1), [f"{v:g}" for v in values])
        ax.axhline(bound, color="k", ls="--", lw=1)
        ax.set_yscale("log")
        ax.set_xlabel(labels[name])
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("per-trial error / CRB RMS")
    fig.suptitle(
        f"Hand-eye ratio per trial (whiskers 5-95 %; dashed: bound {bound:g}; grey: default)",
        fontsize=10,
    )
    return fig


def fig6_figure(deviations, ids, point_id: str):
    """Fig. 6 of the paper for one point: (a) the deviations of each panel along x, y, z;
    (b) the normal densities fitted to them.

    ``deviations`` is ``(n, F, 3)`` in mm (``before_compensation(...)["deviations"]``), its
    points in the order of ``ids``; ``point_id`` names the point shown.
    """
    ids = list(ids)
    if point_id not in ids:
        raise CalibrationError(
            f"featured point {point_id!r} is not among the {len(ids)} feature points "
            f"(first ones: {ids[:5]})"
        )
    d = np.asarray(deviations, dtype=float)[:, ids.index(point_id)]
    fig, (ax_a, ax_b) = plt.subplots(1, 2, figsize=(COLUMN_IN, 3.6), layout="constrained")
    panels = np.arange(1, d.shape[0] + 1)
    for k, axis in enumerate(AXES):
        ax_a.plot(panels, d[:, k], "o-", label=axis)
        mu, sd = d[:, k].mean(), d[:, k].std(ddof=1)
        grid = np.linspace(mu - 4 * sd, mu + 4 * sd, 200)
        ax_b.plot(grid, norm.pdf(grid, mu, sd), label=f"{axis}: mean {mu:.2f}, sd {sd:.3f} mm")
        ax_b.plot(d[:, k], np.zeros(d.shape[0]), "|", color=ax_b.lines[-1].get_color(), ms=12)
    ax_a.axhline(0.0, color="k", lw=0.8)
    ax_a.set_xlabel("panel")
    ax_a.set_ylabel("hybrid - CMM (mm)")
    ax_a.set_title(f"(a) deviations of point {point_id}, {d.shape[0]} panels")
    ax_a.legend(fontsize=8)
    ax_b.set_xlabel("hybrid - CMM (mm)")
    ax_b.set_ylabel("fitted normal density (1/mm)")
    ax_b.set_title("(b) normal fits")
    ax_b.legend(fontsize=8)
    for ax in (ax_a, ax_b):
        ax.grid(alpha=0.3)
    return fig


def n_sweep_figure(summary: pd.DataFrame):
    """The two headline shares against the number of products in the offset (Eq. 24)."""
    fig, ax = plt.subplots(figsize=(COLUMN_IN, 3.6), constrained_layout=True)
    _headline_shares(ax, summary["n_compensation"], summary)
    ax.set_xlabel("products in the offset estimate (n of Eq. 24)")
    ax.set_ylabel("share of the vectors (%)")
    ax.set_title("Table 1 headline shares against n (median, 95 % interval over stations)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _headline_shares(ax, x, summary: pd.DataFrame) -> None:
    """Both headline shares of ``summary`` against ``x`` with their 95 % intervals, the published
    values dashed."""
    published = load_published()
    for col, label, pub in (
        ("within_0p3", "within +-0.3 mm", published.table1.within_0p3_percent),
        ("r_above_0p7", "r > 0.7", published.table1.r_above_0p7_percent),
    ):
        line = ax.plot(x, summary[col], "o-", label=label)[0]
        ax.fill_between(x, summary[f"{col}_low"], summary[f"{col}_high"], alpha=0.2)
        ax.axhline(pub, color=line.get_color(), ls="--", lw=1, label=f"published {pub} %")


def sensitivity_figure(summary: pd.DataFrame, scenario: Scenario):
    """A grid of panels (two per row), one per swept assumption: both headline shares, the
    published values dashed, the default value dotted; legend under the grid."""
    names = list(dict.fromkeys(summary["parameter"]))
    n_rows = (len(names) + 1) // 2
    fig, axes = plt.subplots(
        n_rows, 2, figsize=(COLUMN_IN, 2.7 * n_rows + 0.9), squeeze=False, sharey=True
    )
    fig.set_layout_engine("constrained")
    for ax, name in zip(axes.ravel(), names, strict=False):
        sub = summary[summary["parameter"] == name]
        _headline_shares(ax, sub["value"], sub)
        ax.axvline(scenario.swept(name), color="k", ls=":", lw=1)
        ax.set_xlabel(SWEEP_LABELS[name], fontsize=9)
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(names) :]:
        ax.set_visible(False)
    for row in axes:
        row[0].set_ylabel("share of the vectors (%)")
    _legend_below(fig, axes[0][0], ncol=2)
    fig.suptitle("Table 1 headline shares as each assumption moves (dotted: default)", fontsize=10)
    return fig


def robot_error_figure(summary: pd.DataFrame, default: float = 1.0):
    """The sweep of the robot's manufacturing errors (:func:`summarise_robot_error_sweep`):
    (a) the systematic size before compensation against the published 2-4 mm, each factor
    labelled with its ``hybrid.systematic`` verdict; (b) the two headline shares after
    compensation, and the share within +-0.3 mm of the same products uncompensated ("raw").
    The default factor is dotted."""
    fig, (ax_a, ax_b) = plt.subplots(2, 1, figsize=(COLUMN_IN, 7.0), constrained_layout=True)
    x = summary["robot_error_scale"]
    lo, hi = load_published().systematic.range_mm
    mid = (lo + hi) / 2.0
    ax_a.axhspan(lo, hi, color="0.85", label=f"published {lo:g}-{hi:g} mm")
    # the magnitude band of the verdict: the middle of the range within the register's factor 1.5
    for k, edge in enumerate((mid / 1.5, mid * 1.5)):
        label = f"verdict band {mid / 1.5:g}-{mid * 1.5:g} mm" if k == 0 else None
        ax_a.axhline(edge, color="0.4", ls="--", lw=1, label=label)
    ax_a.plot(x, summary["systematic_median_mm"], "s--", color="0.5", label="3-D reading")
    y = summary["systematic_coord_median_mm"]
    ax_a.plot(x, y, "o-", label="per coordinate (judged), median over stations")
    ax_a.fill_between(
        x,
        summary["systematic_coord_median_mm_low"],
        summary["systematic_coord_median_mm_high"],
        alpha=0.2,
    )
    for xi, yi, verdict in zip(x, y, summary["systematic_verdict"], strict=True):
        ax_a.annotate(
            verdict, (xi, yi), textcoords="offset points", xytext=(-6, 8), fontsize=7, rotation=30
        )
    ax_a.set_ylabel("systematic size before compensation (mm)")
    ax_a.set_title("(a) hybrid.systematic (95 % interval over stations)")
    ax_a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _headline_shares(ax_b, x, summary)
    ax_b.plot(
        x, summary["within_0p3_uncompensated"], "s:", color="0.4", label="within +-0.3 mm, raw"
    )
    ax_b.set_ylim(-3, 103)
    ax_b.set_ylabel("share of the vectors (%)")
    ax_b.set_title("(b) Table 1 headline shares after compensation")
    ax_b.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    for ax in (ax_a, ax_b):
        _plain_ticks(ax, sorted(x.unique()))
        ax.axvline(default, color="k", ls=":", lw=1)
        ax.set_xlabel(ROBOT_ERROR_LABEL)
        ax.grid(alpha=0.3)
    return fig
