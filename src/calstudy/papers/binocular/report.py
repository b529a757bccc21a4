"""Tables, figures and verdicts of notebook 04 (binocular paper, Tables 2-5, Fig. 13).

Every function reads the trial rows of :func:`calstudy.papers.binocular.experiments.
binocular_trial` (``trials``, one row per trial and sweep scale) or of ``field_trial``
(``field``), and the published values of ``data/binocular/*.toml [published]``; nothing here
simulates. The default scenario is the row with robot and calibration scale 1.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from calstudy.claims import (
    ClaimColumns,
    Judged,
    claim_row,
    control_rows,
    judge_claim,
    null_gate,
)
from calstudy.core.labels import claim_label
from calstudy.core.robustness import verdict_runs
from calstudy.core.stats import median_interval
from calstudy.core.verdicts import not_testable
from calstudy.estimators import binocular as bino
from calstudy.papers.binocular.scenario import Scenario, paper_table, published

#: Where each claim's figures sit in the trial rows (``binocular_trial``, ``field_trial``, with the
#: null columns of :func:`with_nulls`), with the error source each correction targets, named when
#: its oracle control is not significant; the rule is the register's. Each null runs the method
#: where its error source is absent (a broken method that improves anything would pass it).
CLAIMS = {
    "binocular.coc": ClaimColumns(
        "t2_with",
        baseline="t2_without",
        null="t2_null",
        oracle="t2_oracle",
        mechanism=(
            "a defocus error the rectification can act on (removing the defocus does not lower "
            "the RMSE here)"
        ),
    ),
    "binocular.observed_error": ClaimColumns(
        "t3_holdout_with",
        baseline="t3_holdout_without",
        null="t3_null",
        oracle="t3_holdout_exact",
        mechanism="an observed error of the 3-D points that the modification can see",
    ),
    "binocular.transformation": ClaimColumns(
        "fig13_updated",
        baseline="fig13_preliminary",
        null="fig13_null_scaled",
        oracle="fig13_true",
        mechanism="a hand-eye matrix error that dominates the Fig. 13 distances",
    ),
    "binocular.field": ClaimColumns("field_updated_base", baseline="field_preliminary_base"),
}

#: The null controls as paired ratios: ``(column, method in the null setting, its baseline)``;
#: :func:`with_nulls` scales each onto the claim's baseline, so that the null's effect (column /
#: claim baseline) is the method's ratio where its error source is absent.
NULLS = {
    "binocular.coc": ("t2_null", "t2_null_with", "t2_oracle"),
    "binocular.observed_error": ("t3_null", "t3_null_with", "t3_holdout_exact"),
    "binocular.transformation": ("fig13_null_scaled", "fig13_null", "fig13_true"),
}


def with_nulls(trials: pd.DataFrame) -> pd.DataFrame:
    """``trials`` with the null columns of :data:`NULLS`: the rectification on the views exposed
    without defocus (over the same views unrectified), the modification on the exact sphere
    centres (over them unmodified), the transformation update started from the true matrix (over
    the true matrix), each times the claim's baseline."""
    out = trials.copy()
    for claim, (column, with_, without) in NULLS.items():
        needs = (CLAIMS[claim].baseline, with_, without)
        if all(c in out for c in needs):  # a table of one experiment has its claim's alone
            out[column] = out[needs[0]] * out[with_] / out[without]
    return out


#: Where the paper's before/after RMSEs of each correction are (``published(*key)``).
PUBLISHED = {
    "binocular.coc": ("calibrator", "table2_rmse"),
    "binocular.observed_error": ("calibrator", "table3_rmse"),
    "binocular.transformation": ("station", "fig13_rmse"),
}


def _tiny(value: float) -> str:
    """A deviation for a note: below 1e-8 (finer than the 10 significant digits the trial rows
    are stored with) as ``< 1e-8``, so the note is the same from the rows in memory and on disk."""
    return "< 1e-8" if value < 1e-8 else f"{value:.1e}"


def default(trials: pd.DataFrame) -> pd.DataFrame:
    """The rows of the default scenario (robot and calibration error scale 1)."""
    sel = (trials["robot_scale"] == 1.0) & (trials["calibration_scale"] == 1.0)
    return trials[sel].sort_values("trial").reset_index(drop=True)


def _ratio(text_pub) -> tuple[float, str]:
    return text_pub[1] / text_pub[
        0
    ], f"{text_pub[1] / text_pub[0]:.3f} ({text_pub[1]:.3f}/{text_pub[0]:.3f} mm)"


# ----------------------------------------------------------------------------------------------
# tables


def layout_table(scenario: Scenario) -> pd.DataFrame:
    """The solved calibrator layout (calibrator frame, mm) with each target's distance to P7,
    the Table 2 standard and the residual."""
    std = scenario.calibrator.standard.distance_mm
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


def distance_table(trials: pd.DataFrame, which: str) -> pd.DataFrame:
    """Table 2 (``which="table2"``: without / with rectification) or Table 3 (with rectification,
    without / with modification): per distance to P7, the median error over the default trials
    beside the paper's error (its value minus its CMM standard), mm."""
    cal = paper_table("calibrator")
    names = cal.standard.names
    std = np.array(cal.standard.distance_mm)
    pub = cal.published
    a, b = ("raw", "rect") if which == "table2" else ("rect", "mod")
    d = default(trials)
    return pd.DataFrame(
        {
            "pair": names,
            "median_error_without_mm": [float(d[f"err_{a}_{n}"].median()) for n in names],
            "median_error_with_mm": [float(d[f"err_{b}_{n}"].median()) for n in names],
            "rms_error_without_mm": [
                float(np.sqrt((d[f"err_{a}_{n}"] ** 2).mean())) for n in names
            ],
            "rms_error_with_mm": [float(np.sqrt((d[f"err_{b}_{n}"] ** 2).mean())) for n in names],
            "published_error_without_mm": np.array(getattr(pub, f"{which}_control")) - std,
            "published_error_with_mm": np.array(getattr(pub, f"{which}_experimental")) - std,
        }
    )


def handeye_table(trials: pd.DataFrame) -> pd.DataFrame:
    """Table 4 as errors: the preliminary and updated hand-eye matrix against the truth (median
    and 95 % interval over the default trials), beside the change the paper's update made to its
    translation (the text lost the rotation's signs, so only the translation is compared)."""
    d = default(trials)
    pre = np.array(published("station", "table4_preliminary"))
    upd = np.array(published("station", "table4_updated"))
    change = float(np.linalg.norm(upd[:, 3] - pre[:, 3]))
    rows = []
    for label in ("preliminary", "updated"):
        for what, col, unit in (
            ("rotation", f"rot_err_{label}_mrad", "mrad"),
            ("translation", f"trans_err_{label}_mm", "mm"),
        ):
            med, lo, hi = median_interval(d[col])
            rows.append(
                {
                    "matrix": label,
                    "error": what,
                    "unit": unit,
                    "median": med,
                    "ci_low": lo,
                    "ci_high": hi,
                }
            )
    rows.append(
        {
            "matrix": "published update - preliminary",
            "error": "translation change",
            "unit": "mm",
            "median": change,
            "ci_low": np.nan,
            "ci_high": np.nan,
        }
    )
    return pd.DataFrame(rows)


def field_table(field: pd.DataFrame) -> pd.DataFrame:
    """Table 5 per region: median RMSE over the field trials with each matrix, flange and base
    frame, beside the paper's RMSEs."""
    t5 = np.array(published("station", "table5_rmse"))
    regions = paper_table("station").field.regions
    rows = []
    for k, region in enumerate(regions):
        row = {"region": region}
        for label in ("preliminary", "updated"):
            for frame in ("flange", "base"):
                row[f"{label}_{frame}_mm"] = float(field[f"field{k + 1}_{label}_{frame}"].median())
        row["published_preliminary_mm"], row["published_updated_mm"] = t5[k]
        rows.append(row)
    return pd.DataFrame(rows)


def _summary_specs() -> list[tuple]:
    """``(step, trials column without, with, published [without, with])``."""
    t5 = list(np.array(published("station", "table5_rmse")).mean(0))
    nan2 = [np.nan, np.nan]
    return [
        (
            "Table 2: CoC rectification",
            "t2_without",
            "t2_with",
            published("calibrator", "table2_rmse"),
        ),
        ("Table 2 oracle: defocus switched off", "t2_without", "t2_oracle", nan2),
        (
            "Table 3: modification (paper's protocol, fitted distances)",
            "t3_without",
            "t3_with",
            published("calibrator", "table3_rmse"),
        ),
        (
            "Table 3, leave-one-target-out: P1-P6 to P7",
            "t3_holdout_without",
            "t3_holdout_with",
            nan2,
        ),
        ("Table 3 oracle: exact 3-D points", "t3_holdout_without", "t3_holdout_exact", nan2),
        ("Table 3: exact cameras", "t3_holdout_without", "t3_holdout_truecam", nan2),
        (
            "Fig. 13: transformation correction",
            "fig13_preliminary",
            "fig13_updated",
            published("station", "fig13_rmse"),
        ),
        ("Fig. 13 oracle: true hand-eye matrix", "fig13_preliminary", "fig13_true", nan2),
        ("Table 5: field, base frame", "field_preliminary_base", "field_updated_base", t5),
        ("Table 5: field, flange frame", "field_preliminary_flange", "field_updated_flange", t5),
    ]


def rmse_summary(trials: pd.DataFrame, field: pd.DataFrame) -> pd.DataFrame:
    """RMSE without/with each step: medians over trials and the median ratio with its
    order-statistic 95 % interval, beside the paper's figures."""
    d = default(trials)
    rows = []
    for label, a, b, pub in _summary_specs():
        src = d if a in d else field
        med, lo, hi = median_interval(src[b] / src[a])
        rows.append(
            {
                "step": label,
                "n": len(src),
                "published_without_mm": pub[0],
                "published_with_mm": pub[1],
                "published_ratio": pub[1] / pub[0],
                "without_mm": float(src[a].median()),
                "with_mm": float(src[b].median()),
                "ratio": med,
                "ratio_low": lo,
                "ratio_high": hi,
            }
        )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# verdicts


def judge_correction(trials: pd.DataFrame, claim: str):
    """Claim, null and oracle control of one correction on the same trials (v2 rule 8), the
    claim's verdict after the oracle gate; a claim whose null control passes is ``not
    testable`` (the test cannot tell the method from one that improves anything)."""
    pub = published(*PUBLISHED[claim])
    return null_gate(
        judge_claim(claim, with_nulls(trials), CLAIMS[claim], published=pub[1] / pub[0])
    )


def _with_note(v, extra: str):
    return dataclasses.replace(v, note=f"{v.note}; {extra}")


def alternative_text(claim: str, label: str, trials: pd.DataFrame) -> str:
    """The verdict of ``claim`` on the default rows of ``trials`` (another mechanism,
    ``label``), in words for a note."""
    v, null, oracle = judge_correction(default(trials), claim)
    figure = (
        f"ratio {v.effect_median:.3g} [{v.effect_low:.3g}, {v.effect_high:.3g}]"
        if np.isfinite(v.effect_median)
        else f"oracle ratio {oracle.effect_median:.3g}, null ratio {null.effect_median:.3g}"
    )
    return f"under {label}: {v.verdict}, {figure}"


def verdicts(trials: pd.DataFrame, field: pd.DataFrame, alternatives: dict | None = None) -> dict:
    """Claim id to ``(verdict, null control, oracle control)`` (controls None where the claim
    has none), by the v2 rule from the default trials. ``alternatives`` maps a label (another
    defocus mechanism, its calibration) to its trials; each claim's note then gives its verdict
    under each (:func:`alternative_text`)."""
    d = default(trials)
    out = _verdicts(d, field)
    for claim in ("binocular.coc", "binocular.observed_error", "binocular.transformation"):
        for label, alt in (alternatives or {}).items():
            v, null, oracle = out[claim]
            out[claim] = Judged(_with_note(v, alternative_text(claim, label, alt)), null, oracle)
    return out


def _verdicts(d: pd.DataFrame, field: pd.DataFrame) -> dict:
    out = {}
    out["binocular.coc"] = judge_correction(d, "binocular.coc")
    claim, null, oracle = judge_correction(d, "binocular.observed_error")
    circ, lo, hi = median_interval(d["t3_with"] / d["t3_without"])
    out["binocular.observed_error"] = Judged(
        _with_note(
            claim,
            f"judged leave-one-target-out; the paper's protocol (scored on the distances the "
            f"modification is fitted to) gives ratio {circ:.3g} [{lo:.3g}, {hi:.3g}]",
        ),
        null,
        oracle,
    )
    claim, null, oracle = judge_correction(d, "binocular.transformation")
    he = {c: float(d[c].median()) for c in d if c.startswith(("rot_err", "trans_err"))}
    below = float((d["fig13_updated"] < d["fig13_true"]).mean())
    out["binocular.transformation"] = Judged(
        _with_note(
            claim,
            "hand-eye error itself, preliminary -> updated: rotation "
            f"{he['rot_err_preliminary_mrad']:.3g} -> {he['rot_err_updated_mrad']:.3g} mrad, "
            f"translation {he['trans_err_preliminary_mm']:.3g} -> "
            f"{he['trans_err_updated_mm']:.3g} mm (medians); the updated matrix scores below "
            f"the true one in {below:.0%} of the trials, so the true-matrix oracle is "
            + ("not a floor when the sensor is biased" if below > 0 else "a floor in this run"),
        ),
        null,
        oracle,
    )
    flange = field["field_updated_flange"] / field["field_preliminary_flange"]
    deviation = _tiny(float((flange - 1).abs().max()))
    base = judge_claim("binocular.field", field, CLAIMS["binocular.field"]).claim
    out["binocular.field"] = Judged(
        not_testable(
            "identical by construction: a rigid change of the hand-eye matrix preserves every "
            "distance between points it maps (flange-frame ratio "
            f"{float(flange.median()):.6f}, max |ratio - 1| {deviation}; "
            f"base-frame ratio {base.median:.5f} [{base.ci_low:.5f}, {base.ci_high:.5f}]); "
            f"N={len(field)}",
            kind="ratio",
            n=len(field),
        )
    )
    return out


def result_text(claim) -> str:
    """A claim row's figure for the chapter: median ratio, interval and replication rate, or,
    without a figure (not testable), why not."""
    if claim.reproduced is None or not np.isfinite(claim.reproduced):
        return f"no figure is judged (oracle control {claim.oracle_control or 'absent'})"
    return (
        f"median ratio {claim.reproduced:.3g} [{claim.ci_low:.3g}, {claim.ci_high:.3g}], "
        f"replication rate {claim.replication_rate:.2f}, N={claim.n}"
    )


def fig13_text(trials: pd.DataFrame) -> str:
    """Fig. 13 and the hand-eye error of the default trials beside the paper's Fig. 13, as a
    sentence (medians)."""
    d = default(trials)
    pub = published("station", "fig13_rmse")
    return (
        f"The preliminary matrix gives a Fig. 13 RMSE of {d['fig13_preliminary'].median():.3g} mm "
        f"(the paper: {pub[0]:.3g} mm), the updated one {d['fig13_updated'].median():.3g} mm "
        f"(the paper: {pub[1]:.3g} mm); the hand-eye error itself goes from "
        f"{d['rot_err_preliminary_mrad'].median():.3g} to {d['rot_err_updated_mrad'].median():.3g} "
        f"mrad in rotation and from {d['trans_err_preliminary_mm'].median():.3g} to "
        f"{d['trans_err_updated_mm'].median():.3g} mm in translation."
    )


def _published_text(claim: str) -> str:
    if claim == "binocular.field":
        t5 = np.array(published("station", "table5_rmse"))
        ratio = float(np.mean(t5[:, 1] / t5[:, 0]))
        return f"{ratio:.3f} (mean of " + ", ".join(f"{y:.3f}/{x:.3f}" for x, y in t5) + " mm)"
    return _ratio(published(*PUBLISHED[claim]))[1]


def claim_rows(
    trials: pd.DataFrame,
    field: pd.DataFrame,
    notebook: str,
    alternatives: dict | None = None,
):
    """The four claim rows and the control rows (``controls.csv``); ``alternatives`` (see
    :func:`verdicts`) adds each other mechanism's verdict to the notes."""
    claims, controls = [], []
    for claim, judged in verdicts(trials, field, alternatives).items():
        published_text = _published_text(claim)
        claims.append(
            claim_row(claim, judged, published=published_text, unit="ratio", notebook=notebook)
        )
        controls += control_rows(claim, judged, refuse_passing_null=False)
    return claims, controls


# ----------------------------------------------------------------------------------------------
# sweeps


def sweep_table(trials: pd.DataFrame, sweep: str) -> pd.DataFrame:
    """Medians per scale of the robot sweep (``sweep="robot"``, calibration scale 1) or of the
    camera calibration sweep (``"calibration"``, robot scale 1), with the verdict of the claims
    the swept errors drive (coc, observed_error; transformation) at each scale."""
    key, other = ("robot_scale", "calibration_scale")
    if sweep == "calibration":
        key, other = other, key
    sel = trials[trials[other] == 1.0]
    rows = []
    for scale, d in sel.groupby(key, sort=True):
        d = d.sort_values("trial")
        row = {key: float(scale), "n": len(d)}
        cols = [c for c in d if c.startswith(("t2_", "t3_", "fig13_", "rot_", "trans_"))]
        row.update({c: float(d[c].median()) for c in cols})
        specs = (
            ["binocular.transformation"]
            if sweep == "robot"
            else ["binocular.coc", "binocular.observed_error"]
        )
        for claim in specs:
            v, _, oracle = judge_correction(d, claim)
            name = claim.split(".")[1]
            cols = CLAIMS[claim]
            row[f"{name}_ratio"] = float((d[cols.figure] / d[cols.baseline]).median())
            row[f"{name}_oracle_ratio"] = oracle.effect_median
            row[f"verdict_{name}"] = v.verdict
        rows.append(row)
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# figures


def shift_figure(table: pd.DataFrame, scenario: Scenario):
    """Radial centre shift against depth for each tilt, without and with rectification."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.6, 3.8))
    for i, (tilt, d) in enumerate(table.groupby("tilt_deg", sort=True)):
        ax.plot(d["depth_mm"], d["radial_shift_px"], "o-", color=f"C{i}", label=f"tilt {tilt:g}°")
        ax.plot(
            d["depth_mm"],
            d["rectified_radial_shift_px"],
            "s--",
            color=f"C{i}",
            label=f"tilt {tilt:g}°, rectified",
        )
    ax.axhline(0.0, color="grey", lw=0.8)
    opt = scenario.sensor.optics
    ax.set_xlabel(f"dot depth (mm); focused at {opt.focus_distance_mm:g} mm, f/{opt.f_number:.2g}")
    ax.set_ylabel("centre shift along the field (px)")
    ax.set_title("Defocus shift of a detected dot centre, 15° off axis (noise-free)", fontsize=10)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    fig.tight_layout()
    return fig


def summary_figure(summary: pd.DataFrame):
    """RMSE ratio (with / without) per step: median and 95 % interval, and the published ratio."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.2, 4.2))
    y = np.arange(len(summary))
    err = [summary["ratio"] - summary["ratio_low"], summary["ratio_high"] - summary["ratio"]]
    ax.errorbar(summary["ratio"], y, xerr=err, fmt="o", label="simulation (median, 95 % CI)")
    ax.plot(summary["published_ratio"], y, "r*", markersize=10, label="paper")
    ax.axvline(1.0, color="grey", lw=0.8)
    ax.set_yticks(y, summary["step"], fontsize=8)
    ax.set_xlabel("RMSE with / without the step")
    ax.invert_yaxis()
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2)
    fig.tight_layout()
    return fig


def sweep_figure(sweep: pd.DataFrame, x: str, series, paper, xlabel: str, ylabel: str):
    """Median RMSEs of a sweep against the swept scale ``x``, with the paper's values dotted."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.6, 3.6))
    for col, label in series:
        ax.plot(sweep[x], sweep[col], "o-", label=label)
    for i, (value, label) in enumerate(paper):
        ax.axhline(value, color=f"C{i}", ls=":", label=label)
    ax.set_xlabel(xlabel, fontsize=9)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    fig.tight_layout()
    return fig


def robot_sweep_figure(sweep: pd.DataFrame, scenario: Scenario):
    """Fig. 13 RMSEs against the robot error scale."""
    model = scenario.station.robot.model
    fig13 = published("station", "fig13_rmse")
    curves = (
        ("fig13_preliminary", "preliminary"),
        ("fig13_updated", "updated"),
        ("fig13_true", "true hand-eye (oracle)"),
    )
    paper = ((fig13[0], "paper, preliminary"), (fig13[1], "paper, updated"))
    xlabel = f"robot error scale (x tolerances of {model}.toml)"
    return sweep_figure(sweep, "robot_scale", curves, paper, xlabel, "Fig. 13 RMSE (mm, median)")


def calibration_sweep_figure(sweep: pd.DataFrame):
    """Tables 2 and 3 RMSEs against the scale of the cameras' calibration errors."""
    t2 = published("calibrator", "table2_rmse")
    t3 = published("calibrator", "table3_rmse")
    return sweep_figure(
        sweep,
        "calibration_scale",
        (
            ("t2_without", "Table 2, without rectification"),
            ("t2_with", "Table 2, with rectification"),
            ("t3_with", "Table 3, with modification (fitted distances)"),
            ("t3_holdout_with", "leave-one-target-out, with modification"),
        ),
        (
            (t2[0], "paper, without rectification"),
            (t2[1], "paper, with rectification"),
            (t3[1], "paper, with modification"),
        ),
        "camera calibration error scale (x sensor.toml [calibration_uncertainty])",
        "RMSE of distances to P7 (mm, median)",
    )


# ----------------------------------------------------------------------------------------------
# optics sweeps

#: The optics sweeps: trial column, label, unit.
OPTICS = (
    ("f_number", "F-number", ""),
    ("focus_distance_mm", "focused distance", "mm"),
    ("dot_diameter_mm", "dot diameter", "mm"),
)


def optics_sweep_table(sweep: pd.DataFrame, key: str) -> pd.DataFrame:
    """Per value of ``key`` (the other optics at their default): N, median RMSEs of Table 2
    without/with rectification and without defocus, the claim's ratio and its oracle's, and the
    verdict of ``binocular.coc`` by the v2 rule (with the oracle gate) at that point."""
    others = [k for k, _, _ in OPTICS if k != key]
    sel = sweep
    for k in others:
        if k in sel:
            sel = sel[sel[k] == 0.0]
    rows = []
    for value, d in sel.groupby(key, sort=True):
        if key != "f_number" and value == 0.0:
            continue
        d = d.sort_values("trial")
        v, _, oracle = judge_correction(d, "binocular.coc")
        rows.append(
            {
                key: float(value),
                "n": len(d),
                "t2_without_mm": float(d["t2_without"].median()),
                "t2_with_mm": float(d["t2_with"].median()),
                "t2_oracle_mm": float(d["t2_oracle"].median()),
                "coc_ratio": float((d["t2_with"] / d["t2_without"]).median()),
                "oracle_ratio": oracle.effect_median,
                "verdict_coc": v.verdict,
            }
        )
    return pd.DataFrame(rows)


def loglog_crossing(x, y, goal: float) -> float | None:
    """``x`` at which ``y`` meets ``goal`` by log-log interpolation between the first bracketing
    pair of points (in the order given); None if no pair brackets it."""
    lx, ly, lg = np.log(np.asarray(x)), np.log(np.asarray(y)), math.log(goal)
    for i in range(len(lx) - 1):
        lo, hi = sorted((ly[i], ly[i + 1]))
        if lo <= lg <= hi and ly[i] != ly[i + 1]:
            w = (lg - ly[i]) / (ly[i + 1] - ly[i])
            return float(math.exp(lx[i] + w * (lx[i + 1] - lx[i])))
    return None


def sweep_verdict_sentence(table: pd.DataFrame, key: str, claim: str, label: str, unit: str) -> str:
    """One sentence: the verdict of ``claim`` along a sweep (column ``key`` of ``table``, verdicts
    in ``verdict_<name>``) and where it changes; the claim is named in words
    (:data:`calstudy.core.labels.CLAIM_LABELS`)."""
    vals = table[key].to_numpy()
    verdicts = table[f"verdict_{claim.split('.')[1]}"].tolist()
    words = f"the {claim_label(claim)} claim"

    def fmt(x):
        if key == "f_number":
            return f"f/{x:g}"
        return f"{x:g}{unit}" if unit == "x" else f"{x:g} {unit}"

    if len(set(verdicts)) == 1:
        return (
            f"Over the {label} sweep ({fmt(vals[0])} to {fmt(vals[-1])}) {words} stays "
            f"{verdicts[0]}."
        )
    parts = [  # one part per run of equal verdicts, with its values
        f"{verdict} at {fmt(xs[0])}" + ("" if len(xs) == 1 else f" to {fmt(xs[-1])}")
        for verdict, xs in verdict_runs(vals, verdicts)
    ]
    return f"Along the {label} sweep {words} is " + ", ".join(parts) + "."


def optics_sweep_figure(tables: dict, target_mm: float):
    """Median Table 2 RMSE without / with rectification and without defocus against each optics
    input (one panel each), with the paper's baseline dotted."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(OPTICS), figsize=(7.8, 3.0), sharey=True)
    for ax, (key, label, unit) in zip(axes, OPTICS, strict=True):
        t = tables[key]
        for col, name, style in (
            ("t2_without_mm", "without rectification", "o-"),
            ("t2_with_mm", "with rectification", "s--"),
            ("t2_oracle_mm", "defocus off (oracle)", "^:"),
        ):
            ax.plot(t[key], t[col], style, label=name)
        ax.axhline(target_mm, color="k", ls=":", lw=0.8, label="paper, without rectification")
        ax.set_xlabel(f"{label} ({unit})" if unit else label, fontsize=9)
        ax.tick_params(labelsize=8)
    axes[0].set_ylabel("Table 2 RMSE (mm, median)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=7, bbox_to_anchor=(0.5, 0.0))
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return fig
