"""The hybrid study's tables and claim rows, computed from the experiments' trial tables.

Notebook 01: summaries of the hand-eye, stationary-sensor and 3-2-1 errors, the cost of the
nominal robot model, and the claims ``hybrid.handeye``, ``hybrid.stationary``, ``hybrid.rps``.
Notebook 02: the feature and assumption tables, the Lilliefors table, both halves of Table 1
beside the published ones, the summaries of the sweeps, and the claims ``hybrid.systematic``,
``hybrid.deviation``, ``hybrid.correlation``. The figures are in
:mod:`calstudy.papers.hybrid.report_figures`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from calstudy.claims import verdict_vs_ml, verdict_vs_published
from calstudy.core.errors import CalibrationError
from calstudy.core.stats import median_and_spread
from calstudy.papers.hybrid.compensation import analyse_run
from calstudy.papers.hybrid.scenario import (
    AXES,
    Features,
    Scenario,
    load_published,
    load_station,
)

#: label of the correlation bin of the coordinates fixed by the frame (r undefined there)
UNDEFINED_BIN = "undefined (fixed by the frame)"


# ---------------------------------------------------------------------------------------------
# notebook 01: the station's calibration


def summarise_errors(df, by: list[str]):
    """RMS, median and 95th percentile of the rotation and translation errors per group."""

    def stats(g):
        out = {}
        for col, short in (
            ("rotation_error_deg", "rot_deg"),
            ("translation_error_mm", "trans_mm"),
            ("field_error_mm", "field_mm"),
        ):
            if col not in g:
                continue
            v = g[col].to_numpy()
            out[f"{short}_rms"] = float(np.sqrt(np.mean(v**2)))
            out[f"{short}_median"] = float(np.median(v))
            out[f"{short}_p95"] = float(np.percentile(v, 95))
        out["trials"] = len(g)
        return pd.Series(out)

    return df.groupby(by, sort=False).apply(stats, include_groups=False).reset_index()


def nominal_model_cost(handeye_summary, stationary_summary):
    """RMS errors of each step in both scenarios and their ratio (station / sensor noise only)."""
    rows = []
    pairs = [
        ("hand-eye", handeye_summary, "method", ["sphere", "ML"]),
        ("stationary sensors", stationary_summary, "variant", ["homography", "pnp"]),
    ]
    for step, summary, key, methods in pairs:
        for method in methods:
            sub = summary[summary[key] == method].set_index("scenario")
            for col, unit in (("rot_deg_rms", "deg"), ("trans_mm_rms", "mm")):
                noise = float(sub.loc["sensor noise only", col])
                full = float(sub.loc["station", col])
                rows.append(
                    {
                        "step": step,
                        "method": method,
                        "error": f"RMS {col[:3]}. ({unit})",
                        "sensor_noise_only": noise,
                        "station": full,
                        "ratio": full / noise,
                    }
                )
    return pd.DataFrame(rows)


#: the scenario the verdicts are computed in (see the notebook: ML is ML only for its noise model)
VERDICT_SCENARIO = "sensor noise only"


def _paired(df, key, method, reference, column, scenario):
    sub = df[df["scenario"] == scenario]
    idx = ["trial"] + (["sensor"] if "sensor" in sub.columns else [])
    a = sub[sub[key] == method].set_index(idx)[column]
    b = sub[sub[key] == reference].set_index(idx)[column]
    return a.to_numpy(), b.reindex(a.index).to_numpy()


def _combined_verdict(pairs, works: bool, rng, label: str):
    """The worse (larger-ratio) of the rotation and translation verdicts of a comparison."""
    verdicts = [(name, verdict_vs_ml(m, r, works, rng=rng)) for name, (m, r) in pairs.items()]
    name, worst = max(verdicts, key=lambda v: v[1].reproduced)
    others = "; ".join(f"{n} ratio {v.reproduced:.2f}" for n, v in verdicts)
    return replace(worst, note=f"{label}: {others} (figure: {name})")


def hybrid_claims(handeye, stationary, rps, seed: int, notebook: str):
    """Claim rows ``hybrid.handeye``, ``hybrid.stationary``, ``hybrid.rps`` computed from the runs.

    Each compares the paper's method with the maximum-likelihood (or constrained) estimate on the
    same data in :data:`VERDICT_SCENARIO`, by :func:`calstudy.claims.verdict_vs_ml`; the method
    "works" when every trial returned a finite estimate.
    """
    rng = np.random.default_rng([seed, 7])
    sc = VERDICT_SCENARIO
    rows = []
    he_pairs = {
        c.split("_")[0]: _paired(handeye, "method", "sphere", "ML", c, sc)
        for c in ("rotation_error_deg", "translation_error_mm")
    }
    works = all(np.all(np.isfinite(v)) for pair in he_pairs.values() for v in pair)
    v = _combined_verdict(he_pairs, works, rng, "sphere method / ML, sensor noise only")
    rows.append(v.row("hybrid.handeye", "", "RMS ratio", notebook))
    st_pairs = {
        c.split("_")[0]: _paired(stationary, "variant", "homography", "pnp", c, sc)
        for c in ("rotation_error_deg", "translation_error_mm", "field_error_mm")
    }
    works = all(np.all(np.isfinite(v)) for pair in st_pairs.values() for v in pair)
    v = _combined_verdict(st_pairs, works, rng, "homography chain / PnP chain, sensor noise only")
    rows.append(v.row("hybrid.stationary", "", "RMS ratio", notebook))
    sub = rps[rps["scenario"] == sc]
    pen = sub[sub["solver"].str.startswith("penalty")].set_index("trial")["frame_error_mm"]
    so3 = sub[sub["solver"] == "SO(3)"].set_index("trial")["frame_error_mm"].reindex(pen.index)
    works = bool(np.all(np.isfinite(pen.to_numpy())))
    v = _combined_verdict(
        {"frame": (pen.to_numpy(), so3.to_numpy())},
        works,
        rng,
        "penalty LM / SO(3), sensor noise only",
    )
    rows.append(v.row("hybrid.rps", "", "RMS ratio", notebook))
    return rows


def summarise_rps(rps):
    """RMS frame and rotation errors of each 3-2-1 solver per scenario (from :func:`rps_trial`)."""
    return (
        rps.groupby(["scenario", "solver"], sort=False)
        .agg(
            frame_error_rms_mm=("frame_error_mm", lambda v: float(np.sqrt(np.mean(v**2)))),
            rotation_error_rms_deg=("rotation_error_deg", lambda v: float(np.sqrt(np.mean(v**2)))),
            orthogonality_defect_max=("orthogonality_defect", "max"),
            trials=("trial", "count"),
        )
        .reset_index()
    )


def summarise_penalty_sweep(sweep):
    """Per start and penalty ``M``: converged share, mean evaluations and orthogonality defect,
    and the largest difference from the SO(3) solution (from :func:`rps_penalty_sweep`)."""
    return (
        sweep.groupby(["start", "penalty"], sort=False)
        .agg(
            converged_share=("converged", "mean"),
            evaluations=("evaluations", "mean"),
            orthogonality_defect=("orthogonality_defect", "mean"),
            excess_over_so3_max_mm=("excess_over_so3_mm", lambda v: float(np.abs(v).max())),
        )
        .reset_index()
    )


# ---------------------------------------------------------------------------------------------
# notebook 02: the station in production


def features_table(features: Features) -> pd.DataFrame:
    """The features as a table: id, kind, sensor, CAD x, y, z (mm), coordinates fixed by the
    frame."""
    return pd.DataFrame(
        {
            "point_id": features.ids,
            "kind": features.kinds,
            "sensor": ["flexible" if s == 0 else f"stationary {s}" for s in features.sensor],
            "x_mm": features.cad[:, 0],
            "y_mm": features.cad[:, 1],
            "z_mm": features.cad[:, 2],
            "fixed_by_frame": [
                ", ".join(a for a, f in zip(AXES, row, strict=True) if f) for row in features.fixed
            ],
        }
    )


def assumptions_table(scenario: Scenario) -> pd.DataFrame:
    """The production assumptions of a scenario with where each comes from."""
    size_mm = load_station()["workpiece"]["size_mm"]
    rows = [
        ("part_sigma_mm", scenario.part_sigma_mm, "assumption: +-2 mm tolerance (4.3), Cp 1.33"),
        ("feature_sigma_mm", scenario.feature_sigma_mm, "assumption: line-laser feature noise"),
        ("repeatability_mm", scenario.repeatability_mm, "paper 4.1: +-0.06 mm"),
        ("drift_sigma_mm", scenario.drift_sigma_mm, "assumption: residual drift over a month"),
        ("cmm_sigma_mm", scenario.cmm_sigma_mm, "assumption: CMM probing of sheet metal"),
        ("n_before", scenario.n_before, "paper 4.3: 10 panels (Fig. 6)"),
        ("n_compensation", scenario.n_compensation, "paper 4.3: usually 10-20 products"),
        ("n_follow_up", scenario.n_follow_up, "paper 4.3: 30 products over a month"),
        ("panel_mm", " x ".join(f"{v:g}" for v in size_mm), "paper 4.1"),
    ]
    return pd.DataFrame(rows, columns=["assumption", "value", "source"]).astype({"value": str})


def before_table(ids, before: dict, level: float = 0.05) -> pd.DataFrame:
    """Per coordinate: mean and std of the deviation (mm), the Lilliefors statistic and p-value,
    whether normality is rejected at ``level``, the t-test p-value of a zero mean."""
    n_f = len(ids)
    fixed = before["fixed"].ravel()
    p = before["lilliefors_p"].ravel()
    return pd.DataFrame(
        {
            "point_id": np.repeat(np.asarray(ids, dtype=object), 3),
            "axis": np.tile(AXES, n_f),
            "mean_mm": before["mean"].ravel(),
            "std_mm": before["std"].ravel(),
            "lilliefors_stat": before["lilliefors_stat"].ravel(),
            "lilliefors_p": p,
            "normality": np.where(
                fixed, "fixed by the frame", np.where(p < level, "rejected", "not rejected")
            ),
            "mean_zero_p": before["t_test_p"].ravel(),
        }
    )


def summarise_systematic(systematic: pd.DataFrame) -> pd.DataFrame:
    """Median and 95 % interval over trials of each before-compensation figure."""
    rows = []
    for col in systematic.columns.drop("trial"):
        med, lo, hi = median_and_spread(systematic[col])
        rows.append({"figure": col, "median": med, "ci_low": lo, "ci_high": hi})
    return pd.DataFrame(rows)


def _n_vectors(sub: pd.DataFrame) -> int:
    """Number of deviation coordinates of the trials in ``sub`` (174 for the paper's 58 points)."""
    n = sub["n_vectors"].to_numpy(int)
    if n.size == 0 or np.any(n != n[0]):
        raise CalibrationError(f"trials disagree on the number of coordinates: {sorted(set(n))}")
    return int(n[0])


def _published_halves() -> tuple:
    """Both halves of the published Table 1: (half, bin labels, counts, shares %); the
    correlation half with the row of the coordinates fixed by the frame (none published)."""
    pub = load_published()
    return (
        ("deviation", pub.deviation_bins, pub.deviation_counts, pub.deviation_percent),
        (
            "correlation",
            pub.correlation_bins + (UNDEFINED_BIN,),
            pub.correlation_counts + (0,),
            pub.correlation_percent + (0.0,),
        ),
    )


def table1(trials: pd.DataFrame, n_compensation: int) -> tuple:
    """Table 1, both halves, over the trials at ``n_compensation``: per bin the median count,
    the median share (%) with its 95 % interval over trials, and the published count and share.

    The correlation half has one more row, the coordinates where ``r`` is undefined (fixed by
    the frame); its shares are of all coordinates (174 for the paper's 58 points).
    """
    sub = trials[trials["n_compensation"] == n_compensation]
    n_vectors = _n_vectors(sub)
    halves = []
    for prefix, labels, counts, percent in _published_halves():
        rows = []
        columns = [f"{prefix}_bin{k}" for k in range(5)]
        values = [sub[c].to_numpy(float) for c in columns]
        if prefix == "correlation":
            values.append(sub["n_fixed"].to_numpy(float))
        for label, v, pc, pp in zip(labels, values, counts, percent, strict=True):
            med, lo, hi = median_and_spread(100.0 * v / n_vectors)
            rows.append(
                {
                    "bin": label,
                    "count_median": float(np.median(v)),
                    "percent_median": med,
                    "percent_ci_low": lo,
                    "percent_ci_high": hi,
                    "published_count": pc,
                    "published_percent": pp,
                }
            )
        halves.append(pd.DataFrame(rows))
    return halves[0], halves[1]


def headline_summary(trials: pd.DataFrame) -> pd.DataFrame:
    """Per ``n``: median and 95 % interval of the two headline shares and of the share within
    +-0.3 mm before compensation and of all single readings."""
    rows = []
    for n, sub in trials.groupby("n_compensation", sort=True):
        row = {"n_compensation": int(n)}
        for col in ("within_0p3", "r_above_0p7", "within_0p3_uncompensated", "single_within_0p3"):
            row[col], row[f"{col}_low"], row[f"{col}_high"] = median_and_spread(sub[col])
        rows.append(row)
    return pd.DataFrame(rows)


def summarise_sweep(sweep: pd.DataFrame) -> pd.DataFrame:
    """Median and 95 % interval of the two headline shares per assumption and value."""
    rows = []
    for (name, value), sub in sweep.groupby(["parameter", "value"], sort=False):
        row = {"parameter": name, "value": value}
        for col in ("within_0p3", "r_above_0p7"):
            row[col], row[f"{col}_low"], row[f"{col}_high"] = median_and_spread(sub[col])
        rows.append(row)
    return pd.DataFrame(rows)


def summarise_robot_error_sweep(
    sweep: pd.DataFrame, n_compensation: int, notebook: str
) -> pd.DataFrame:
    """Per factor on the robot's tolerances (from :func:`robot_error_sweep`): the systematic size
    and the two headline shares, each with its 95 % interval over stations and the verdict of its
    claim computed by :func:`production_claims` on that factor's stations alone, and the median
    share within +-0.3 mm of the same products uncompensated."""
    rows = []
    for scale, sub in sweep.groupby("robot_error_scale", sort=False):
        claims = production_claims(sub, sub, n_compensation, notebook)
        row = {"robot_error_scale": scale, "stations": len(sub)}
        for claim, col in zip(
            claims, ("systematic_median_mm", "within_0p3", "r_above_0p7"), strict=True
        ):
            row |= {col: claim.reproduced, f"{col}_low": claim.ci_low, f"{col}_high": claim.ci_high}
            row[f"{claim.id.split('.')[1]}_verdict"] = claim.verdict
        row["within_0p3_uncompensated"] = float(np.median(sub["within_0p3_uncompensated"]))
        rows.append(row)
    return pd.DataFrame(rows)


def station_table1(run: dict, n_compensation: int) -> pd.DataFrame:
    """Table 1 of one station beside the published one: half, bin, count, share (%)."""
    a = analyse_run(run, n_compensation)
    n_vec = a["n_vectors"]
    counts = {
        "deviation": a["deviation_counts"],
        "correlation": np.r_[a["correlation_counts"], a["n_fixed"]],
    }
    rows = []
    for half, labels, pub_c, pub_p in _published_halves():
        for label, c, pc, pp in zip(labels, counts[half], pub_c, pub_p, strict=True):
            rows.append(
                {
                    "half": half,
                    "bin": label,
                    "count": int(c),
                    "percent": 100.0 * c / n_vec,
                    "published_count": pc,
                    "published_percent": pp,
                }
            )
    return pd.DataFrame(rows)


def production_claims(
    systematic: pd.DataFrame, trials: pd.DataFrame, n_compensation: int, notebook: str
):
    """Claim rows ``hybrid.systematic``, ``hybrid.deviation``, ``hybrid.correlation``.

    * systematic: median over points of the size of the mean deviation before compensation
      (per trial) against the middle of the published 2-4 mm (value, factor 1.5); its effect is
      the excess over the median panel-to-panel scatter of the same trial (a size is never
      below 0, so 0 cannot stand for no effect: an error that is not systematic has a mean no
      larger than its scatter); the Lilliefors non-rejection rate and the share of significantly
      non-zero means in the note.
    * deviation: share within +-0.3 mm after compensation against 96.55 % (10 pp), its effect
      the gain over the same products uncompensated (paired per trial).
    * correlation: share of r > 0.7 (of the coordinates where r is defined) against 85.64 %
      (10 pp), no effect 0 % (unrelated readings almost never reach r > 0.7 over 30 products).

    The published numbers come from ``data/hybrid/published.toml``.
    """
    sub = trials[trials["n_compensation"] == n_compensation]
    pub = load_published()
    return [
        _systematic_claim(systematic, pub.systematic_mm, notebook),
        _deviation_claim(sub, pub.within_0p3_percent, n_compensation, notebook),
        _correlation_claim(sub, pub.r_above_0p7_percent, notebook),
    ]


def _systematic_claim(systematic: pd.DataFrame, published_mm, notebook: str):
    lo_pub, hi_pub = published_mm
    size = systematic["systematic_median_mm"].to_numpy()
    scatter = systematic["scatter_median_mm"].to_numpy()
    v = verdict_vs_published(
        (lo_pub + hi_pub) / 2.0, size, scatter, kind="value", direction="higher"
    )
    lf = np.median(systematic["lilliefors_not_rejected"])
    nz = np.median(systematic["mean_nonzero"])
    v = replace(
        v,
        note=f"{v.note}; effect = size minus panel-to-panel scatter; Lilliefors does not reject "
        f"normality for {lf:.3g} % of the coordinates, mean significantly non-zero for "
        f"{nz:.3g} % (medians over trials)",
    )
    return v.row("hybrid.systematic", f"{lo_pub:g}-{hi_pub:g}", "mm", notebook)


def _deviation_claim(sub: pd.DataFrame, published: float, n_compensation: int, notebook: str):
    within, raw = sub["within_0p3"].to_numpy(), sub["within_0p3_uncompensated"].to_numpy()
    v = verdict_vs_published(published, within, raw, kind="percent", direction="higher")
    v = replace(
        v,
        note=f"offset from {n_compensation} products; {v.note}; beyond 0.5 mm: "
        f"{np.median(sub['beyond_0p5']):.3g} % (published 0)",
    )
    return v.row("hybrid.deviation", f"{published}", "%", notebook)


def _correlation_claim(sub: pd.DataFrame, published: float, notebook: str):
    r_above = sub["r_above_0p7"].to_numpy()
    v = verdict_vs_published(published, r_above, 0.0, kind="percent", direction="higher")
    v = replace(
        v,
        note=f"{v.note}; share of the {_n_vectors(sub) - int(np.median(sub['n_fixed']))} "
        "coordinates where r is defined",
    )
    return v.row("hybrid.correlation", f"{published}", "%", notebook)
