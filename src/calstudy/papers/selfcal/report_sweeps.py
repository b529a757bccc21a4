"""The sweeps of the ``selfcal`` notebook: what the verdicts do when an assumption moves.

From the trial rows of the calibration experiment and of a sweep of the same trial (joint
compliance under the payload, or all noise scaled): :func:`sweep_table` (the figures behind the
five claims per sweep value), :func:`sweep_verdicts` (the five verdicts by the v2 rule, with
their controls, at every sweep value), :func:`sweep_sentences` (what the sweep does to each
verdict, as text for the chapter), :func:`verdict_grid` (the verdicts as a compact table),
:func:`sweep_figure`; and in words for the chapter: :func:`condition_sentence` (up to which
value of a sweep a verdict holds) and :func:`claim_conditions` (the conditions stated beside the
verdicts), :func:`basin_sentence` and :func:`basin_condition` (the basin
of convergence, and up to which start error the published count holds),
:func:`route_sentence`, :func:`best_route_sentence` and :func:`refit_sentence` (the route
comparison, and what a refit of the two-step result on all equations does),
:func:`robot_reading_sentence` (the paper's reading of Fig. 6 against the truth),
:func:`control_sentence` (what a control came out as), :func:`ml_sentence` (the paper's LM
against maximum likelihood) and :func:`rank_sentence`.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from calstudy.claims import Judged  # noqa: E402
from calstudy.core.errors import CalibrationError  # noqa: E402
from calstudy.core.robustness import verdict_runs  # noqa: E402
from calstudy.papers.selfcal.experiments import (  # noqa: E402
    NULL,
    NULL_ROBOT_NOISE,
    ONE_STEP,
    ONE_STEP_ML,
    ORACLE,
    REFITS,
    ROUTES,
    TOLERANCE_CLASS_SIGMAS,
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
        robot = method_column(sub, ONE_STEP, "robot_tol_error") / method_column(
            sub, NULL, "robot_tol_error"
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


def _by_label(values, labels, swept: str = "scale", at: str = "") -> str:
    """The swept values grouped by their label (a verdict, a route): ``"reproduced at every
    scale swept"`` or ``"reproduced at 0 and 1, direction only at 4"`` (``at`` before the
    values)."""
    groups: dict[str, list[str]] = {}
    for value, label in zip(values, labels, strict=True):
        groups.setdefault(str(label), []).append(f"{value:g}")
    if len(groups) == 1:
        return f"{next(iter(groups))} at every {swept} swept"
    return ", ".join(f"{label} at {at}{_join(values)}" for label, values in groups.items())


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
            f"{_by_label(points[key], points['verdict'])}; median {_figure_text(first)} at "
            f"{first[key]:g} and {_figure_text(last)} at {last[key]:g} ({unit})"
        )
        if np.isfinite(first["p95"]) and np.isfinite(last["p95"]):
            text += f", 95th percentile {first['p95']:.3g} and {last['p95']:.3g}"
        counts = sorted({int(n) for n in points["n"]})
        text += f"; N = {_join([str(n) for n in counts])} per point"
        if points["null_control"].fillna("").astype(str).str.len().all():
            text += (
                f"; null control {_by_label(points[key], points['null_control'])}, oracle control "
                f"{_by_label(points[key], points['oracle_control'])}"
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
    swept = key.replace("_", " ")
    return _by_label(table[key], table["best_route"], swept, f"{swept} ")


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


def condition_sentence(verdicts: pd.DataFrame, key: str, claim: str, own: float, label: str):
    """Up to which value of the sweep ``key`` the verdict of ``claim`` at the scenario's own
    value ``own`` holds, from the rows of :func:`sweep_verdicts`.

    ``"holds up to compliance scale 2 (reproduced at 0, 1 and 2); not reproduced at 4"``, or
    ``"holds at every compliance scale swept, up to 4 (reproduced)"``; ``label`` names the
    swept input. Points below ``own`` with another verdict are named too.

    Raises
    ------
    CalibrationError
        If the rows have no point at ``own`` for ``claim``
        (:func:`calstudy.core.robustness.verdict_runs` for empty rows).
    """
    points = verdicts[verdicts["claim"] == claim].sort_values(key)
    runs = verdict_runs(points[key].tolist(), points["verdict"].tolist())
    at = [i for i, (_, values) in enumerate(runs) if own in values]
    if not at:
        raise CalibrationError(f"{claim}: the sweep of {key} has no point at {own:g}")
    i = at[0]
    verdict, values = runs[i]
    listed = _join([f"{v:g}" for v in values])
    if len(runs) == 1:
        return f"holds at every {label} swept, up to {values[-1]:g} ({verdict})"
    text = f"holds up to {label} {values[-1]:g} ({verdict} at {listed})"
    if i + 1 < len(runs):
        after = runs[i + 1]
        text += f"; {after[0]} at {_join([f'{v:g}' for v in after[1]])}"
        text += "".join(
            f", {v} at {_join([f'{x:g}' for x in vals])}" for v, vals in runs[i + 2 :]
        )
    if i > 0:
        before = "; ".join(
            f"{v} at {_join([f'{x:g}' for x in vals])}" for v, vals in runs[:i]
        )
        text += f"; below it {before}"
    return text


def basin_condition(table: pd.DataFrame, bound: float, scenario: Scenario, share=0.95) -> str:
    """Up to which start error the published count holds, from
    :func:`calstudy.papers.selfcal.report.basin_table`: the largest start scale up to which at
    least ``share`` of the trials at every scale reach the good start's solution within
    ``bound`` iterations (the v2 rule for a bound: its 95th percentile meets it), with that
    start's offsets in mm and degrees, and the share at the next scale swept.

    ``scenario.poor_start`` gives the offsets of scale 1.
    """
    table = table.sort_values("start_scale")
    ok = (table["within_published_share"] >= share).to_numpy()
    n = int(np.argmin(ok)) if not ok.all() else len(ok)
    counts = _join([str(c) for c in sorted({int(t) for t in table["trials"]})])
    tail = f" (N = {counts} per start scale)"
    if n == 0:
        first = table.iloc[0]
        return (
            f"within {bound:g} iterations in fewer than {share:.0%} of trials at every start "
            f"scale swept, from {first['start_scale']:g} ({first['within_published_share']:.0%})"
            + tail
        )
    last = table.iloc[n - 1]
    p, s = scenario.poor_start, float(last["start_scale"])
    text = (
        f"within {bound:g} iterations in at least {share:.0%} of trials up to a start error of "
        f"{s:g} x the scenario's very poor start (base {s * p.base_mm:g} mm and "
        f"{s * p.base_deg:g} deg, sensor {s * p.sensor_mm:g} mm and {s * p.sensor_deg:g} deg, "
        f"robot lengths {s * p.robot_length_mm:g} mm and angles {s * p.robot_angle_deg:g} deg "
        "off)"
    )
    if n < len(table):
        nxt = table.iloc[n]
        text += (
            f"; at {nxt['start_scale']:g} x in {nxt['within_published_share']:.0%}"
            f", {nxt['same_solution_share']:.0%} reaching the same solution at all"
        )
    else:
        text += ", the farthest swept"
    return text + tail


#: the claims whose verdicts the compliance and arm-weight sweeps condition
SWEPT_CLAIMS = (
    "selfcal.identification",
    "selfcal.robot_params",
    "selfcal.residual",
    "selfcal.one_step",
)


def claim_conditions(
    scenario: Scenario,
    basin: pd.DataFrame,
    compliance_verdicts: pd.DataFrame,
    arm_verdicts: pd.DataFrame,
) -> dict[str, str]:
    """The condition stated beside each verdict in ``claims.csv``: for the convergence claim the
    start error up to which it holds (:func:`basin_condition` of the basin table), for the
    others the size of the unmodelled joint compliance and the share of the arm's own weight up
    to which they hold (:func:`condition_sentence` of the two sweeps' verdicts)."""
    out = {
        "selfcal.convergence": basin_condition(
            basin, scenario.published.convergence_iterations, scenario
        )
    }
    c = scenario.compliance
    for cid in SWEPT_CLAIMS:
        payload = condition_sentence(
            compliance_verdicts, "compliance_scale", cid, c.scale, "compliance scale"
        )
        arm = condition_sentence(
            arm_verdicts,
            "arm_weight_fraction",
            cid,
            c.arm_weight_fraction,
            "share of the arm's weight",
        )
        out[cid] = f"unmodelled joint compliance: {payload}; arm's own weight: {arm}"
    return out


def refit_sentence(calib: pd.DataFrame) -> str:
    """What refitting the two-step result on all equations does, from the trial rows: the
    largest scaled parameter step that refitting the base alone makes, the largest distance of
    the full joint refit from the one-step result, and the median distance of the two-step
    result from the one-step result (mm, angles as mm at 1 m) with the median paired ratio of
    their mean validation errors."""
    base, full = REFITS
    two = ROUTES[-1]
    moved = method_column(calib, base, "step_from_two_step")
    to_one = method_column(calib, full, "step_from_one_step")
    apart = method_column(calib, two, "step_from_one_step")
    ratio = method_column(calib, base, "val_mean_mm") / method_column(calib, two, "val_mean_mm")
    return (
        f"re-fitting the base on all equations moves the two-step result by at most "
        f"{moved.max():.2g} mm (mean validation error ratio {np.median(ratio):.6g} median), a "
        f"full joint refit from it lands within {to_one.max():.2g} mm of the one-step result, "
        f"and the two-step result lies {np.median(apart):.3g} mm (median) from it "
        f"(parameter distances, angles as mm at 1 m; N = {moved.size})"
    )


def robot_reading_sentence(calib: pd.DataFrame) -> str:
    """The paper's reading of Fig. 6 (every identified robot change within
    :data:`~calstudy.papers.selfcal.experiments.TOLERANCE_CLASS_SIGMAS` standard deviations of the
    tolerance class) for the one-step route and for the null that reports the nominal robot
    plus noise of the tolerance class: the share of trials where it holds; and the study's
    reading, identified against true change (RMS in tolerance units, median)."""
    k = TOLERANCE_CLASS_SIGMAS
    parts = []
    for name, method in (("one-step", ONE_STEP), ("nominal plus noise", NULL_ROBOT_NOISE)):
        within = np.mean(method_column(calib, method, "robot_change_max_sigmas") <= k)
        error = np.median(method_column(calib, method, "robot_tol_error"))
        parts.append((name, within, error))
    manufacturing = np.median(method_column(calib, NULL, "robot_tol_error"))
    text = "; ".join(f"{n} {w:.0%}" for n, w, _ in parts)
    errors = ", ".join(f"{n} {e:.3g}" for n, _, e in parts)
    return (
        f"every identified change within {k:g} tolerance standard deviations of nominal: {text} "
        f"of trials; identified against true change, RMS in tolerance units (median): "
        f"{errors}, the manufacturing error itself {manufacturing:.3g} "
        f"(N = {calib['trial'].nunique()})"
    )


def control_sentence(judged: Judged, which: str = "null") -> str:
    """What a control came out as: ``"median 1.9 [1.7, 2.1], not reproduced"``."""
    v = judged.null if which == "null" else judged.oracle
    if v is None:
        return "no control"
    return f"median {v.median:.3g} [{v.ci_low:.3g}, {v.ci_high:.3g}], {v.verdict}"


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
