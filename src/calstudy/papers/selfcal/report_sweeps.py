"""The sweeps of the ``selfcal`` notebook: what the verdicts do when an assumption moves.

From the trial rows of the calibration experiment and of a sweep of the same trial (joint
compliance under the payload, or all noise scaled): :func:`sweep_table` (the figures behind the
five claims per sweep value), :func:`sweep_verdicts` (the five verdicts by the v2 rule, with
their controls, at every sweep value), :func:`sweep_sentences` (what the sweep does to each
verdict, as text for the chapter), :func:`verdict_grid` (the verdicts as a compact table),
:func:`sweep_figure`; and in words for the chapter: :func:`basin_sentence` (the basin of
convergence), :func:`route_sentence` and :func:`best_route_sentence` (the route comparison),
:func:`ml_sentence` (the paper's LM against maximum likelihood) and :func:`rank_sentence`.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from calstudy.papers.selfcal.experiments import (  # noqa: E402
    NULL,
    ONE_STEP,
    ONE_STEP_ML,
    ORACLE,
    ROUTES,
)
from calstudy.papers.selfcal.report import (  # noqa: E402
    UNITS,
    best_route,
    legend_outside,
    method_column,
    poor_start_iterations,
    selfcal_verdicts,
)
from calstudy.papers.selfcal.scenario import Scenario  # noqa: E402


def _with_own_point(calib: pd.DataFrame, sweep: pd.DataFrame, key: str, own: float):
    """The calibration trials as the sweep point ``own`` beside the sweep's trials."""
    own_rows = pd.concat([calib, pd.Series(own, index=calib.index, name=key)], axis=1)
    return pd.concat([own_rows, sweep], ignore_index=True)


def sweep_table(calib: pd.DataFrame, sweep: pd.DataFrame, key: str, own: float) -> pd.DataFrame:
    """Per value of the sweep ``key`` (the calibration experiment is the point ``own``) the
    figures of the five claims: the one-step largest validation error (median, 95th percentile,
    and the ideal identification's 95th percentile), the one-step mean validation error over the
    best multi-step route's (median), the model error over its Cramer-Rao prediction (median,
    95th percentile), the iterations from the very poor start (median, 95th percentile; a start
    that does not reach the good start's solution counts as the evaluation budget) and the
    robot-parameter error over the manufacturing error (median, 95th percentile)."""
    rows = []
    for value, sub in _with_own_point(calib, sweep, key, own).groupby(key, sort=True):
        best = best_route(sub)
        one_max = method_column(sub, ONE_STEP, "val_max_mm")
        ratio = method_column(sub, ONE_STEP, "val_mean_mm") / method_column(
            sub, best, "val_mean_mm"
        )
        crb = method_column(sub, ONE_STEP, "model_rms_mm") / method_column(
            sub, ONE_STEP, "crb_model_rms_mm"
        )
        one = sub[sub["method"] == ONE_STEP].sort_values("trial")
        iterations = poor_start_iterations(one)
        robot = method_column(sub, ONE_STEP, "robot_param_error") / method_column(
            sub, NULL, "robot_param_error"
        )
        rows.append(
            {
                key: value,
                "trials": len(one_max),
                "one_step_val_max_median_mm": float(np.median(one_max)),
                "one_step_val_max_p95_mm": float(np.percentile(one_max, 95)),
                "oracle_val_max_p95_mm": float(
                    np.percentile(method_column(sub, ORACLE, "val_max_mm"), 95)
                ),
                "best_route": best,
                "best_route_val_mean_median_mm": float(
                    np.median(method_column(sub, best, "val_mean_mm"))
                ),
                "one_step_over_best_route_median": float(np.median(ratio)),
                "model_error_over_crb_median": float(np.median(crb)),
                "model_error_over_crb_p95": float(np.percentile(crb, 95)),
                "poor_start_iterations_median": float(np.median(iterations)),
                "poor_start_iterations_p95": float(np.percentile(iterations, 95)),
                "robot_param_ratio_median": float(np.median(robot)),
                "robot_param_ratio_p95": float(np.percentile(robot, 95)),
            }
        )
    return pd.DataFrame(rows)


def sweep_verdicts(
    calib: pd.DataFrame, sweep: pd.DataFrame, key: str, own: float, scenario: Scenario
) -> pd.DataFrame:
    """The five verdicts by the v2 rule (:func:`calstudy.papers.selfcal.report.selfcal_verdicts`)
    at every value of the sweep ``key``, each point judged on its own trials (the calibration
    experiment is the point ``own``). One row per (value, claim): N, median and its 95 %
    interval, the 95th percentile (bound claims), replication rate, verdict and the verdicts of
    the null and oracle controls (empty where the claim has none)."""
    rows = []
    for value, sub in _with_own_point(calib, sweep, key, own).groupby(key, sort=True):
        for cid, (v, null, oracle) in selfcal_verdicts(sub, scenario).items():
            rows.append(
                {
                    key: value,
                    "claim": cid,
                    "unit": UNITS[cid],
                    "n": v.n,
                    "median": v.median,
                    "ci_low": v.ci_low,
                    "ci_high": v.ci_high,
                    "p95": v.p95,
                    "replication_rate": v.replication_rate,
                    "verdict": v.verdict,
                    "null_control": null.verdict if null is not None else "",
                    "oracle_control": oracle.verdict if oracle is not None else "",
                }
            )
    return pd.DataFrame(rows)


def _figure_text(row) -> str:
    """``"0.929 [0.865, 1.06]"``, or ``"no figure"`` where the verdict has none (not testable)."""
    if not np.isfinite(row["median"]):
        return "no figure"
    return f"{row['median']:.3g} [{row['ci_low']:.3g}, {row['ci_high']:.3g}]"


def verdict_grid(verdicts: pd.DataFrame, key: str) -> pd.DataFrame:
    """The rows of :func:`sweep_verdicts` as a compact table: one row per claim, one column per
    sweep value, each cell the verdict with its median and 95 % interval."""
    cells = verdicts.assign(
        value=[f"{row['verdict']}: {_figure_text(row)}" for _, row in verdicts.iterrows()]
    )
    grid = cells.pivot(index="claim", columns=key, values="value")
    grid = grid.reindex(list(dict.fromkeys(verdicts["claim"])))
    grid.columns = [f"{key.replace('_', ' ')} {value:g}" for value in grid.columns]
    return grid.reset_index()


def _join(values: list[str]) -> str:
    return values[0] if len(values) == 1 else ", ".join(values[:-1]) + " and " + values[-1]


def _by_verdict(points: pd.DataFrame, key: str, column: str) -> str:
    """``"reproduced at every scale swept"`` or ``"reproduced at 0 and 1, direction only at 4"``."""
    groups: dict[str, list[str]] = {}
    for value, verdict in zip(points[key], points[column], strict=True):
        groups.setdefault(str(verdict), []).append(f"{value:g}")
    if len(groups) == 1:
        return f"{next(iter(groups))} at every scale swept"
    return ", ".join(f"{verdict} at {_join(values)}" for verdict, values in groups.items())


def sweep_sentences(verdicts: pd.DataFrame, key: str) -> dict[str, str]:
    """Per claim, one sentence saying what the sweep does to its verdict, from the rows of
    :func:`sweep_verdicts`: the verdict at each scale, the median (and for a bound the 95th
    percentile) at the smallest and the largest scale, the trials per point and the controls."""
    out = {}
    for cid, points in verdicts.groupby("claim", sort=False):
        points = points.sort_values(key)
        first, last = points.iloc[0], points.iloc[-1]
        unit = first["unit"]
        text = (
            f"{_by_verdict(points, key, 'verdict')}; median {_figure_text(first)} at "
            f"{first[key]:g} and {_figure_text(last)} at {last[key]:g} ({unit})"
        )
        if np.isfinite(first["p95"]) and np.isfinite(last["p95"]):
            text += f", 95th percentile {first['p95']:.3g} and {last['p95']:.3g}"
        counts = sorted({int(n) for n in points["n"]})
        text += f"; N = {_join([str(n) for n in counts])} per point"
        if points["null_control"].fillna("").astype(str).str.len().all():
            text += (
                f"; null control {_by_verdict(points, key, 'null_control')}, oracle control "
                f"{_by_verdict(points, key, 'oracle_control')}"
            )
        out[cid] = text
    return out


def route_sentence(routes: pd.DataFrame) -> str:
    """The one-step mean validation error over each multi-step route's, median [95 % interval],
    from :func:`calstudy.papers.selfcal.report.route_table`."""
    parts = [
        f"{row.method} {row.one_step_ratio_median:.3g} "
        f"[{row.one_step_ratio_ci_low:.3g}, {row.one_step_ratio_ci_high:.3g}]"
        for row in routes.itertuples()
        if row.method in ROUTES
    ]
    return "; ".join(parts) + f" (N = {int(routes['trials'].iloc[0])})"


def ml_sentence(routes: pd.DataFrame) -> str:
    """The paper's unweighted LM against maximum likelihood on the same trials, from
    :func:`calstudy.papers.selfcal.report.route_table`: the median of the paired ratio of their
    mean validation errors with its 95 % interval, and the two model errors."""
    by = routes.set_index("method")
    ml, one = by.loc[ONE_STEP_ML], by.loc[ONE_STEP]
    return (
        f"one-step over one-step ML {ml['one_step_ratio_median']:.3g} "
        f"[{ml['one_step_ratio_ci_low']:.3g}, {ml['one_step_ratio_ci_high']:.3g}]; median model "
        f"error {one['model_rms_mm_median']:.3g} mm against {ml['model_rms_mm_median']:.3g} mm "
        f"(N = {int(one['trials'])})"
    )


def rank_sentence(calib: pd.DataFrame, n_params: int) -> str:
    """How many trials' identification Jacobians have full rank ``n_params``."""
    ranks = calib.loc[calib["method"] == ONE_STEP, "jacobian_rank"].to_numpy(int)
    return f"rank {n_params} in {int(np.sum(ranks == n_params))} of {ranks.size} trials"


def best_route_sentence(table: pd.DataFrame, key: str) -> str:
    """Which route is the best at each value of a sweep, from :func:`sweep_table`."""
    groups: dict[str, list[str]] = {}
    for value, route in zip(table[key], table["best_route"], strict=True):
        groups.setdefault(str(route), []).append(f"{value:g}")
    if len(groups) == 1:
        return f"{next(iter(groups))} at every {key.replace('_', ' ')} swept"
    return ", ".join(
        f"{route} at {key.replace('_', ' ')} {_join(values)}" for route, values in groups.items()
    )


def basin_sentence(table: pd.DataFrame, bound: float) -> str:
    """The basin of convergence in words, from :func:`calstudy.papers.selfcal.report.basin_table`:
    per start scale the share of trials reaching the good start's solution and the share doing
    so within ``bound`` iterations."""
    parts = [
        f"{row.start_scale:g} x: {row.same_solution_share:.0%} reach it, "
        f"{row.within_published_share:.0%} within {bound:g} iterations"
        for row in table.itertuples()
    ]
    counts = sorted({int(n) for n in table["trials"]})
    return "; ".join(parts) + f" (N = {_join([str(n) for n in counts])} per start scale)"


def sweep_figure(table: pd.DataFrame, key: str, scenario: Scenario, title: str, xlabel: str):
    """The figures of the five claims against a swept input (``table`` from
    :func:`sweep_table`): largest validation error against the requirement, the ratios to the
    best route and to the Cramer-Rao prediction against their bounds, the iterations from the
    very poor start against the published 4, and the robot-parameter error ratio. Four panels
    stacked for the book's column, legends to the right of the data."""
    fig, axes = plt.subplots(4, 1, figsize=(7.5, 9.5), sharex=True, constrained_layout=True)
    x = table[key]
    ax = axes[0]
    ax.plot(x, table["one_step_val_max_median_mm"], "o-", label="one-step, median")
    ax.plot(x, table["one_step_val_max_p95_mm"], "s--", label="one-step, 95th pct.")
    ax.plot(x, table["oracle_val_max_p95_mm"], "^:", label="ideal identification,\n95th pct.")
    req = scenario.protocol.requirement_mm
    ax.axhline(req, color="r", ls="--", label=f"requirement {req:g} mm")
    ax.set_ylim(0.0, 1.1 * max(req, float(table["one_step_val_max_p95_mm"].max())))
    ax.set_ylabel("largest validation\nerror (mm)")
    ax = axes[1]
    best = "one-step / best route,\nmedian"
    ax.plot(x, table["one_step_over_best_route_median"], "o-", label=best)
    ax.plot(x, table["model_error_over_crb_median"], "s--", label="model error / CRB,\nmedian")
    ax.plot(x, table["model_error_over_crb_p95"], "d:", label="model error / CRB,\n95th pct.")
    crb = scenario.protocol.crb_multiple
    ax.axhline(crb, color="r", ls="--", label=f"bound {crb:g}")
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_ylabel("ratio")
    ax = axes[2]
    ax.plot(x, table["poor_start_iterations_median"], "o-", label="median")
    ax.plot(x, table["poor_start_iterations_p95"], "s--", label="95th pct.")
    bound = scenario.published.convergence_iterations
    ax.axhline(bound, color="r", ls="--", label=f"published {bound:g}")
    ax.set_ylim(0.0, 1.25 * max(bound, float(table["poor_start_iterations_p95"].max())))
    ax.set_ylabel("iterations from the\nvery poor start")
    ax = axes[3]
    ax.plot(x, table["robot_param_ratio_median"], "o-", label="median")
    ax.plot(x, table["robot_param_ratio_p95"], "s--", label="95th pct.")
    ax.axhline(1.0, color="0.5", lw=0.8, label="nothing identified")
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("robot-parameter error /\nmanufacturing error")
    ax.set_xlabel(xlabel)
    ax.set_xticks(list(x))
    for ax in axes:
        ax.grid(alpha=0.3)
        legend_outside(ax)
    fig.suptitle(title)
    return fig
