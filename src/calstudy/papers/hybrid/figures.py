"""Figures of the study, each drawn from a results table (never from raw simulation state)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

ERROR_COLUMNS = (
    ("rot_deg_rms", "RMS rotation error (deg)"),
    ("trans_mm_rms", "RMS translation error (mm)"),
)


def method_bars(summary: pd.DataFrame, group: str, hue: str, title: str):
    """Grouped bars of RMS rotation and translation errors (log scale), one panel each.

    ``summary`` comes from :func:`calstudy.papers.hybrid.station.summarise_errors` with columns
    ``group`` and
    ``hue`` among its keys.
    """
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), constrained_layout=True)
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
        ax.set_xticks(np.arange(len(groups)), groups, rotation=30, ha="right")
        ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return fig


def sweep_lines(summary: pd.DataFrame, x: str, xlabel: str, title: str, logx: bool = False):
    """RMS errors against a swept quantity, one line per method, rotation and translation."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), constrained_layout=True)
    for ax, (col, label) in zip(axes, ERROR_COLUMNS, strict=True):
        for method, sub in summary.groupby("method", sort=False):
            style = "k--" if method == "CRB" else "o-"
            ax.plot(sub[x], sub[col], style, label=method)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(label)
        ax.set_yscale("log")
        if logx:
            ax.set_xscale("log")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return fig


def per_sensor_bars(summary: pd.DataFrame, title: str):
    """RMS errors of each stationary sensor, one bar per variant."""
    return method_bars(
        summary.assign(sensor=summary["sensor"].astype(str)), "sensor", "variant", title
    )


def penalty_plot(sweep: pd.DataFrame, title: str):
    """Solver evaluations and orthogonality defect of the penalty LM against ``M``."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), constrained_layout=True)
    for start, sub in sweep.groupby("start", sort=False):
        axes[0].plot(sub["penalty"], sub["evaluations"], "o-", label=start)
        axes[1].plot(
            sub["penalty"], sub["orthogonality_defect"].clip(lower=1e-17), "o-", label=start
        )
    axes[0].set_ylabel("mean function evaluations")
    axes[1].set_ylabel("max |R^T R - I| (mean over trials)")
    axes[1].set_yscale("log")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("penalty factor M")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return fig
