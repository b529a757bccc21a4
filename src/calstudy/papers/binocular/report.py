"""Tables, figures and claim rows of notebook 04 (binocular paper, Tables 2-5, Fig. 13).

Each table puts one trial of :func:`calstudy.papers.binocular.experiments.run_trial` (or the
Monte Carlo metrics) beside the published values of ``data/binocular/*.toml [published]``;
figures are drawn from those tables.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from calstudy.claims import verdict_vs_published
from calstudy.core.stats import median_and_spread
from calstudy.estimators import binocular as bino
from calstudy.papers.binocular.scenario import Scenario, paper_table, published

# ----------------------------------------------------------------------------------------------
# tables of one trial


def layout_table(scenario: Scenario) -> pd.DataFrame:
    """The solved calibrator layout (calibrator frame, mm) with each target's distance to P7,
    the Table 2 standard and the residual."""
    std = scenario.config["calibrator"]["standard"]["distance_mm"]
    d = bino.distances_to_p7(scenario.layout)
    rows = []
    for i, name in enumerate(bino.TARGET_NAMES):
        row = {"target": name, "x_mm": scenario.layout[i, 0], "y_mm": scenario.layout[i, 1]}
        row["z_mm"] = scenario.layout[i, 2]
        j = {6: None, 7: 6}.get(i, i)
        if j is None:
            row.update(distance_to_p7_mm=0.0, table2_mm=0.0, residual_mm=0.0)
        else:
            row.update(
                distance_to_p7_mm=d[j], table2_mm=std[j], residual_mm=scenario.layout_residual[j]
            )
        rows.append(row)
    return pd.DataFrame(rows)


def distance_table(trial: dict, which: str) -> pd.DataFrame:
    """Table 2 (``which="table2"``) or 3 of one trial beside the published one, mm."""
    cal = paper_table("calibrator")
    names = cal["standard"]["names"]
    pub = cal["published"]
    values = trial[which]
    return pd.DataFrame(
        {
            "pair": names,
            "standard_mm": trial["standard"],
            "without_mm": values[:, 0],
            "with_mm": values[:, 1],
            "error_without_mm": values[:, 0] - trial["standard"],
            "error_with_mm": values[:, 1] - trial["standard"],
            "published_standard_mm": cal["standard"]["distance_mm"],
            "published_without_mm": pub[f"{which}_control"],
            "published_with_mm": pub[f"{which}_experimental"],
        }
    )


def _matrix_rows(label: str, matrix) -> list[dict]:
    """The three rows of a ``(3, 4)`` or ``(4, 4)`` matrix as table rows ``c1``-``c4``."""
    return [
        {"matrix": label, "row": i + 1, **{f"c{j + 1}": matrix[i, j] for j in range(4)}}
        for i in range(3)
    ]


def handeye_table(trial: dict) -> pd.DataFrame:
    """Table 4: true, preliminary and updated ``sensor2flange`` (one trial) beside the published."""
    hand = trial["handeye"]
    pub = {k: np.array(published("station", f"table4_{k}")) for k in ("preliminary", "updated")}
    rows = []
    for label in ("true", "preliminary", "updated"):
        rows += _matrix_rows(label, hand[label])
    for label, m in pub.items():
        rows += _matrix_rows(f"published {label}", m)
    return pd.DataFrame(rows)


def fig13_table(trial: dict) -> pd.DataFrame:
    """Fig. 13: distance P7 to the base origin per validation pose, with both matrices."""
    f = trial["fig13"]
    std = trial["fig13_standard"]
    return pd.DataFrame(
        {
            "pose": np.arange(1, len(f) + 1),
            "standard_mm": std,
            "preliminary_mm": f[:, 0],
            "updated_mm": f[:, 1],
            "error_preliminary_mm": f[:, 0] - std,
            "error_updated_mm": f[:, 1] - std,
        }
    )


def field_table(trial: dict) -> pd.DataFrame:
    """Table 5 of one trial: each region's distances with both calibrations beside the published."""
    pre = published("station", "table5_preliminary")
    upd = published("station", "table5_updated")
    stds = paper_table("station")["field"]["standard_mm"]
    rows = []
    for k, f in enumerate(trial["field"]):
        for i, name in enumerate(f["names"]):
            rows.append(
                {
                    "region": f["region"],
                    "pair": name,
                    "standard_mm": f["standard"][i],
                    "preliminary_flange_mm": f["preliminary_flange"][i],
                    "updated_flange_mm": f["updated_flange"][i],
                    "preliminary_base_mm": f["preliminary_base"][i],
                    "updated_base_mm": f["updated_base"][i],
                    "published_standard_mm": stds[k][i],
                    "published_preliminary_mm": pre[k][i],
                    "published_updated_mm": upd[k][i],
                }
            )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# over the Monte Carlo trials


def _summary_specs() -> list[tuple]:
    """``(step, metric without, metric with, published [without, with] RMSE)`` per step."""
    t5 = list(np.array(published("station", "table5_rmse")).mean(0))
    return [
        (
            "Table 2: CoC rectification",
            "t2_without",
            "t2_with",
            published("calibrator", "table2_rmse"),
        ),
        (
            "Table 3: observed-error modification",
            "t3_without",
            "t3_with",
            published("calibrator", "table3_rmse"),
        ),
        ("Table 3, hold-out: P1-P6 to P7", "t3_holdout_without", "t3_holdout_with", [math.nan] * 2),
        (
            "Fig. 13: transformation correction",
            "fig13_preliminary",
            "fig13_updated",
            published("station", "fig13_rmse"),
        ),
        ("Table 5: field, base frame", "field_preliminary_base", "field_updated_base", t5),
        ("Table 5: field, flange frame", "field_preliminary_flange", "field_updated_flange", t5),
    ]


def rmse_summary(metrics: pd.DataFrame) -> pd.DataFrame:
    """RMSE without/with each step: median and 95 % interval over trials, beside the paper."""
    rows = []
    for label, a, b, pub in _summary_specs():
        if a not in metrics:
            continue
        ratio, lo, hi = median_and_spread(metrics[b] / metrics[a])
        rows.append(
            {
                "step": label,
                "published_without_mm": pub[0],
                "published_with_mm": pub[1],
                "published_ratio": pub[1] / pub[0],
                "without_mm": float(metrics[a].median()),
                "with_mm": float(metrics[b].median()),
                "ratio": ratio,
                "ratio_low": lo,
                "ratio_high": hi,
            }
        )
    return pd.DataFrame(rows)


def claim_rows(metrics: pd.DataFrame, notebook: str) -> list:
    """The four claim rows; each verdict is computed from the per-trial RMSE ratios."""
    t5 = np.array(published("station", "table5_rmse"))
    specs = [
        ("binocular.coc", "t2_without", "t2_with", published("calibrator", "table2_rmse")),
        (
            "binocular.observed_error",
            "t3_without",
            "t3_with",
            published("calibrator", "table3_rmse"),
        ),
        (
            "binocular.transformation",
            "fig13_preliminary",
            "fig13_updated",
            published("station", "fig13_rmse"),
        ),
        ("binocular.field", "field_preliminary_base", "field_updated_base", None),
    ]
    rows = []
    for claim, a, b, pub in specs:
        if pub is None:
            ratio = float(np.mean(t5[:, 1] / t5[:, 0]))
            text = f"{ratio:.3f} (mean of " + ", ".join(f"{y:.3f}/{x:.3f}" for x, y in t5) + " mm)"
        else:
            ratio = pub[1] / pub[0]
            text = f"{ratio:.3f} ({pub[1]:.3f}/{pub[0]:.3f} mm)"
        v = verdict_vs_published(
            ratio, metrics[b].to_numpy(), metrics[a].to_numpy(), kind="ratio", direction="lower"
        )
        rows.append(v.row(claim, text, "ratio", notebook))
    return rows


# ----------------------------------------------------------------------------------------------
# figures


def shift_figure(table: pd.DataFrame, scenario: Scenario):
    """Detected-centre shift against depth, without and with rectification."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for label, name in (("fused", "fused exposures"), ("blur_only", "blur only")):
        ax.plot(table["depth_mm"], table[f"{label}_shift_px"], "o-", label=f"{name}")
        ax.plot(
            table["depth_mm"],
            table[f"{label}_rectified_shift_px"],
            "s--",
            label=f"{name}, rectified",
        )
    ax2 = ax.twinx()
    ax2.plot(table["depth_mm"], table["coc_radius_px"], "k:")
    ax2.set_ylabel("circle-of-confusion radius, dotted (px)")
    focus = scenario.config["sensor"]["optics"]["focus_distance_mm"]
    ax.set_xlabel(f"dot depth (mm); focused at {focus:g} mm")
    ax.set_ylabel("centre shift (px)")
    ax.set_title("Defocus shift of a detected dot centre (noise-free)")
    ax.legend(loc="upper center", fontsize=8)
    fig.tight_layout()
    return fig


def fig13_figure(table: pd.DataFrame):
    """Fig. 13 equivalent: error of the P7-to-base distance per validation pose."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    x = table["pose"].to_numpy()
    ax.bar(x - 0.2, table["error_preliminary_mm"].abs(), 0.4, label="preliminary (AX = XB)")
    ax.bar(x + 0.2, table["error_updated_mm"].abs(), 0.4, label="updated (Eq. 14-22)")
    ax.set_xticks(x)
    ax.set_xlabel("validation pose")
    ax.set_ylabel("|distance error| (mm)")
    ax.set_title("Distance from P7 to the base origin (one trial)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def summary_figure(summary: pd.DataFrame):
    """RMSE ratio (with / without) per step: median and 95 % interval, and the published ratio."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.2, 3.6))
    y = np.arange(len(summary))
    err = [summary["ratio"] - summary["ratio_low"], summary["ratio_high"] - summary["ratio"]]
    ax.errorbar(summary["ratio"], y, xerr=err, fmt="o", label="simulation (median, 95 %)")
    ax.plot(summary["published_ratio"], y, "r*", markersize=10, label="paper")
    ax.axvline(1.0, color="grey", lw=0.8)
    ax.set_yticks(y, summary["step"], fontsize=8)
    ax.set_xlabel("RMSE with / without the step")
    ax.invert_yaxis()
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return fig


def sweep_figure(
    sweep: pd.DataFrame,
    x: str = "robot_scale",
    series=(("fig13_preliminary", "preliminary"), ("fig13_updated", "updated")),
    paper=None,
    xlabel: str = "robot error scale (x tolerances of the robot's file)",
    ylabel: str = "Fig. 13 RMSE (mm, median)",
):
    """Median RMSEs of a sweep against the swept scale ``x``, with the paper's values.

    ``series`` pairs a column of ``sweep`` with its label; ``paper`` pairs each published value
    with its label (drawn dotted in the colour of the series at the same position). The defaults
    draw Fig. 13 against the robot error scale
    (:func:`calstudy.papers.binocular.experiments.robot_sweep`).
    """
    import matplotlib.pyplot as plt

    if paper is None:
        fig13 = published("station", "fig13_rmse")
        paper = ((fig13[0], "paper, preliminary"), (fig13[1], "paper, updated"))
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for col, label in series:
        ax.plot(sweep[x], sweep[col], "o-", label=label)
    for i, (value, label) in enumerate(paper):
        ax.axhline(value, color=f"C{i}", ls=":", label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def robot_sweep_figure(sweep: pd.DataFrame, scenario: Scenario):
    """Fig. 13 RMSEs against the robot error scale (``experiments.robot_sweep``) of
    ``scenario``'s robot."""
    model = scenario.config["station"]["robot"]["model"]
    return sweep_figure(sweep, xlabel=f"robot error scale (x tolerances of {model}.toml)")


def calibration_sweep_figure(sweep: pd.DataFrame):
    """Tables 2 and 3 RMSE against the scale of the cameras' calibration errors
    (``experiments.calibration_sweep``), with the paper's 0.049, 0.041 and 0.034 mm."""
    t2 = published("calibrator", "table2_rmse")
    t3 = published("calibrator", "table3_rmse")
    return sweep_figure(
        sweep,
        x="calibration_scale",
        series=(
            ("t2_without", "Table 2, without rectification"),
            ("t2_with", "Table 2, with rectification (= Table 3, without)"),
            ("t3_with", "Table 3, with modification"),
            ("t3_holdout_with", "hold-out P1-P6, with modification"),
        ),
        paper=(
            (t2[0], "paper, without rectification"),
            (t2[1], "paper, with rectification"),
            (t3[1], "paper, with modification"),
        ),
        xlabel="camera calibration error scale (x sensor.toml [calibration_uncertainty])",
        ylabel="RMSE of distances to P7 (mm, median)",
    )
