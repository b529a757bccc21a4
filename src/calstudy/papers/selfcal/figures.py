"""Figures of the ``selfcal`` notebook, each drawn from one of its results tables."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

START_LABELS = {"good": "good initial estimate", "poor": "very poor initial estimate"}


def convergence(summary: pd.DataFrame, title: str):
    """Mean position error per LM iteration, median and 5-95 % band (Fig. 5 of the paper).

    ``summary`` comes from :func:`calstudy.papers.selfcal.selfcal.summarise_history`.
    """
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for start, sub in summary.groupby("start", sort=True):
        ax.plot(sub["iteration"], sub["median_mm"], "o-", label=START_LABELS.get(start, start))
        ax.fill_between(sub["iteration"], sub["p5_mm"], sub["p95_mm"], alpha=0.2)
    ax.set_yscale("log")
    ax.set_xlabel("LM iteration")
    ax.set_ylabel("mean position error (mm)")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    return fig


def robot_parameters(trial: pd.DataFrame, title: str):
    """Identified minus nominal robot parameters with their standard deviation (Fig. 6).

    ``trial`` holds one trial of the robot table (``name``, ``unit``, ``true_minus_nominal``,
    ``identified_minus_nominal``, ``std``); lengths and angles get one panel each.
    """
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for ax, unit in zip(axes, ("mm", "deg"), strict=True):
        sub = trial[trial["unit"] == unit]
        x = np.arange(len(sub))
        ax.bar(
            x,
            sub["identified_minus_nominal"],
            0.6,
            yerr=sub["std"],
            capsize=3,
            label="identified - nominal (+- 1 std)",
        )
        ax.plot(
            x,
            sub["true_minus_nominal"],
            "k_",
            markersize=14,
            mew=2,
            label="true - nominal (simulated)",
        )
        ax.set_xticks(x, sub["name"], rotation=45)
        ax.set_ylabel(f"difference ({unit})")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return fig


def residuals(validation: pd.DataFrame, requirement_mm: float, title: str):
    """Validation position errors per placement, x / y / z and norm, per method (Fig. 7)."""
    methods = list(dict.fromkeys(validation["method"]))
    fig, axes = plt.subplots(
        1, len(methods), figsize=(3.2 * len(methods), 3.8), sharey=True, constrained_layout=True
    )
    for ax, name in zip(np.atleast_1d(axes), methods, strict=True):
        sub = validation[validation["method"] == name]
        x = sub["placement"].to_numpy()
        for k, col in enumerate(("dx_mm", "dy_mm", "dz_mm")):
            ax.bar(x + (k - 1) * 0.25, sub[col], 0.25, label=col[1])
        ax.plot(x, sub["norm_mm"], "ko", ms=4, label="|error|")
        for sign in (1, -1):
            ax.axhline(sign * requirement_mm, color="r", ls="--", lw=1)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("validation placement")
        ax.grid(axis="y", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("position error (mm)")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.suptitle(title)
    return fig


def routes(summary: pd.DataFrame, requirement_mm: float, title: str):
    """Median and 95 % interval of the largest validation error per method (log scale)."""
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    y = np.arange(len(summary))
    med = summary["val_max_mm_median"].to_numpy()
    err = np.vstack([med - summary["val_max_mm_lo"], summary["val_max_mm_hi"] - med])
    ax.errorbar(med, y, xerr=err, fmt="o", capsize=4)
    ax.axvline(requirement_mm, color="r", ls="--", label=f"requirement {requirement_mm:g} mm")
    ax.set_yticks(y, summary["method"])
    ax.set_xscale("log")
    ax.set_xlabel("largest validation error of a calibration (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title)
    return fig


def singular_values(table: pd.DataFrame, title: str):
    """Singular values of the scaled identification Jacobian, one line per design."""
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    for design, sub in table.groupby("design", sort=False):
        ax.semilogy(sub["index"], sub["singular_value"], "o-", ms=4, label=design)
    ax.set_xlabel("index")
    ax.set_ylabel("singular value (mm per unit)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title)
    return fig


def noise_sweep(table: pd.DataFrame, requirement_mm: float, title: str):
    """Largest validation error against the common noise scale, per method."""
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    for name, sub in table.groupby("method", sort=False):
        ax.plot(sub["noise_scale"], sub["val_max_mm_median"], "o-", label=name)
        ax.fill_between(sub["noise_scale"], sub["val_max_mm_lo"], sub["val_max_mm_hi"], alpha=0.2)
    ax.axhline(requirement_mm, color="r", ls="--", label=f"requirement {requirement_mm:g} mm")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("noise scale (repeatability, scanner and tracker noise x)")
    ax.set_ylabel("largest validation error (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title)
    return fig
