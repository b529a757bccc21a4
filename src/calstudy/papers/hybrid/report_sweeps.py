"""The hybrid study's sweeps and distributions: where each verdict changes.

Notebook 01: the per-trial distribution of the hand-eye ratio (the paper's method over the
Cramer-Rao RMS of the same poses) and its sweep over the ranges of the pure translations, with
the ``hybrid.handeye`` verdict per value. Notebook 02: the whole deviation distribution of Table 1
against the published one (Kolmogorov and chi-square distances), the sweep of the drift between
compensation and follow-up with the ``hybrid.deviation`` verdict per value, and the sentence that
says where a swept verdict changes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import chi2

from calstudy.claims import (
    ClaimColumns,
    judge_along,
    judge_claim,
    verdict_or_none,
    verdict_text,
)
from calstudy.core.errors import CalibrationError
from calstudy.core.labels import plain
from calstudy.core.robustness import verdict_changes
from calstudy.core.stats import median_and_spread, rms_ratio_interval
from calstudy.papers.hybrid.compensation import shortfall_bound, shortfall_distance
from calstudy.papers.hybrid.scenario import load_published

#: "works" criterion of hybrid.handeye (stated, not fitted): the larger of the rotation and
#: translation errors, each divided by the Cramer-Rao RMS of the same poses, at most this
CRB_MULTIPLE = 3.0

#: Where each claim's figures sit in the per-trial tables of the two notebooks: notebook 01's
#: :func:`handeye_ratios` and :func:`stationary_ratios`, notebook 02's trial table
#: (``trial_summary``); the rule is the register's.
CLAIMS = {
    "hybrid.handeye": ClaimColumns(
        "sphere",
        null="null control",
        oracle="oracle control",
        mechanism="sensor noise on the sphere centres",
    ),
    "hybrid.stationary": ClaimColumns(
        "images only, homography",
        baseline="images only, pnp",
        null="design pose",
        oracle="exact target, homography",
        oracle_baseline="exact target, pnp",
        mechanism="an error of the homography that the ML PnP avoids",
        pooled=True,
    ),
    "hybrid.systematic": ClaimColumns(
        "systematic_coord_median_mm", baseline="systematic_coord_floor_mm"
    ),
    "hybrid.deviation": ClaimColumns(
        "deviation_shortfall",
        null="deviation_shortfall_null",
        oracle="deviation_shortfall_oracle",
        mechanism="a systematic error that an offset can remove",
    ),
    "hybrid.correlation": ClaimColumns("r_distance"),
}
#: quantiles of the per-trial hand-eye ratio reported
RATIO_QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)


def handeye_ratios(trials: pd.DataFrame, keys=()) -> pd.DataFrame:
    """Per trial (and per value of ``keys``): each method's rotation and translation errors over
    the trial's Cramer-Rao RMS; ``<method>`` the larger of the two ratios (the claim's figure
    for ``sphere``)."""
    keys = list(keys)
    index = keys + ["trial"]
    rot = trials.pivot_table(index=index, columns="method", values="rotation_error_deg")
    trans = trials.pivot_table(index=index, columns="method", values="translation_error_mm")
    out = pd.DataFrame(index=rot.index)
    for m in rot.columns.drop(["CRB", "CRB translations", "weighted rotation"], errors="ignore"):
        out[m] = np.maximum(rot[m] / rot["CRB"], trans[m] / trans["CRB"])
    return out.reset_index()


def ratio_distribution(ratios: pd.DataFrame, column: str = "sphere", keys=()) -> pd.DataFrame:
    """Quantiles of the per-trial ratio ``column`` (per value of ``keys``), the largest one and
    the share of trials within :data:`calstudy.papers.hybrid.report.CRB_MULTIPLE`."""
    groups = ratios.groupby(list(keys), sort=False) if keys else [((), ratios)]
    rows = []
    for key, sub in groups:
        v = sub[column].to_numpy(float)
        row = dict(zip(keys, key if isinstance(key, tuple) else (key,), strict=True))
        row["trials"] = len(v)
        row |= {f"q{int(round(100 * q)):02d}": float(np.quantile(v, q)) for q in RATIO_QUANTILES}
        row["max"] = float(v.max())
        row[f"within_{CRB_MULTIPLE:g}x_pct"] = 100.0 * float(np.mean(v <= CRB_MULTIPLE))
        rows.append(row)
    return pd.DataFrame(rows)


def summarise_handeye_sweep(trials: pd.DataFrame, keys) -> pd.DataFrame:
    """A hand-eye sweep (sensor noise only): per value of ``keys`` the median hand-eye ratio with
    its 95 % confidence interval, the 95th percentile, the ML's median ratio and the
    ``hybrid.handeye`` verdict by its rule on that value's trials."""
    keys = list(keys)
    rows = []
    for key, sub, judged in _bound_points(handeye_ratios(trials, keys), keys, "hybrid.handeye"):
        row = dict(zip(keys, key if isinstance(key, tuple) else (key,), strict=True))
        extra = {"ml_median_ratio": float(np.median(sub["ML"]))}
        rows.append(row | _bound_summary(sub["sphere"], judged, extra))
    return pd.DataFrame(rows)


def pattern_sentence(summary: pd.DataFrame) -> str:
    """One sentence from :func:`summarise_handeye_sweep` over ``translation_pattern``: the
    median hand-eye ratio with its interval, the 95th percentile and the verdict with the pure
    translations on the designed pattern and drawn at random."""
    rows = summary.set_index("translation_pattern")
    missing = {"designed", "random"} - set(rows.index)
    if missing:
        raise CalibrationError(f"the pattern sweep lacks {sorted(missing)}")

    def text(name):
        r = rows.loc[name]
        interval = (
            "" if np.isnan(r["ci_low"]) else f" ({r['ci_low']:.3g}-{r['ci_high']:.3g})"
        )
        return (
            f"median ratio {r['median_ratio']:.3g}{interval}, 95th percentile "
            f"{r['p95_ratio']:.3g}, {r['verdict']}"
        )

    return (
        f"with the pure translations on a designed pattern (each move along a new direction, "
        f"the full ranges): {text('designed')}; drawn at random: {text('random')}"
    )


def _bound_points(ratios: pd.DataFrame, by, claim_id: str) -> list:
    """:func:`calstudy.claims.judge_along` on the claim's figure alone (its bound:
    :data:`CRB_MULTIPLE` or :data:`ML_MULTIPLE`)."""
    bound = {"hybrid.handeye": CRB_MULTIPLE, "hybrid.stationary": ML_MULTIPLE}[claim_id]
    c = CLAIMS[claim_id]
    figure = ClaimColumns(c.figure, baseline=c.baseline if c.pooled else "", pooled=c.pooled)
    return judge_along(ratios, by, claim_id, figure, reference=bound)


def _bound_summary(ratios: pd.Series, judged, extra: dict) -> dict:
    """The columns of a sweep point judged by a bound on ``ratios`` (its trials): count, median
    with its 95 % confidence interval, 95th percentile, ``extra`` and the verdict (``judged``,
    None for too few trials)."""
    v = None if judged is None else judged.claim
    return {
        "trials": len(ratios),
        "median_ratio": float(np.median(ratios)),
        "ci_low": np.nan if v is None else v.ci_low,
        "ci_high": np.nan if v is None else v.ci_high,
        "p95_ratio": float(np.quantile(ratios, 0.95)),
        **extra,
        "verdict": verdict_text(judged),
    }


def summarise_ranges(trials: pd.DataFrame) -> pd.DataFrame:
    """The move-range sweep (``handeye_ranges_experiment``): :func:`summarise_handeye_sweep` per
    range and value (mm)."""
    out = summarise_handeye_sweep(trials, ["parameter", "value"])
    return out.rename(columns={"value": "value_mm"})


def summarise_noise_model(trials: pd.DataFrame) -> pd.DataFrame:
    """The noise-model sweep (``handeye_noise_model_experiment``): per input and value the
    columns of :func:`summarise_handeye_sweep`, the RMS rotation error of the paper's
    unweighted SVD over a covariance-weighted fit of the same pure translations
    (``svd_over_weighted``, what weighting the centres gains), and the null control (the
    design mounting) judged by the claim's rule there (``null_median_ratio``,
    ``null_verdict``): where doing nothing meets the criterion, the test cannot fail."""
    keys = ["parameter", "value"]
    out = summarise_handeye_sweep(trials, keys)
    nulls = judge_along(
        handeye_ratios(trials, keys),
        keys,
        "hybrid.handeye",
        ClaimColumns("null control"),
        reference=CRB_MULTIPLE,
    )
    out["null_median_ratio"] = [float(np.median(sub["null control"])) for _, sub, _ in nulls]
    out["null_verdict"] = [verdict_text(j) for _, _, j in nulls]
    rot = trials.pivot_table(
        index=["parameter", "value", "trial"], columns="method", values="rotation_error_deg"
    )
    gain = rot.groupby(level=["parameter", "value"], sort=False).apply(
        lambda g: float(np.sqrt(np.mean(g["sphere"] ** 2) / np.mean(g["weighted rotation"] ** 2)))
    )
    index = pd.MultiIndex.from_frame(out[keys])
    return out.assign(svd_over_weighted=gain.reindex(index).to_numpy())


#: "works" criterion of hybrid.stationary (the study's: the paper states no accuracy for the
#: stationary sensors): the homography chain's RMS field error, pooled over the trials, at most
#: this multiple of the PnP chain's (maximum likelihood for the pixel noise) on the same images
ML_MULTIPLE = 1.5


def stationary_ratios(stationary: pd.DataFrame, keys=()) -> pd.DataFrame:
    """Per trial (and value of ``keys``): the RMS field error over the ten sensors of each
    variant (one column per variant, mm: the claim's columns of :data:`CLAIMS`), and the
    per-trial ratios homography / PnP (images only, ``ratio``; the same with the calibrated
    hand-eye and reported poses, ``ratio_full_chain``), shown as distributions, not judged."""
    wide = _rms_per_trial(stationary, keys)
    wide["ratio"] = wide["images only, homography"] / wide["images only, pnp"]
    wide["ratio_full_chain"] = wide["homography"] / wide["pnp"]
    return wide.reset_index()


def _rms_per_trial(stationary: pd.DataFrame, keys=()) -> pd.DataFrame:
    """Per trial (and value of ``keys``, the index): the RMS field error over the sensors of
    each variant (one column per variant, mm)."""
    sub = stationary[stationary["step"] == "stationary"]
    rms = sub.groupby(list(keys) + ["trial", "variant"])["field_error_mm"].apply(
        lambda v: float(np.sqrt(np.mean(v**2)))
    )
    return rms.unstack("variant")


def summarise_stationary_sweep(stationary: pd.DataFrame, key: str) -> pd.DataFrame:
    """A stationary-sensor sweep: per value of ``key`` the claim's pooled RMS ratio (homography
    over PnP chain, images only) with its 95 % confidence interval, the same for the oracle
    (exact target), the 95th percentile of the per-trial ratio (shown, not judged) and the
    ``hybrid.stationary`` verdict by its rule on that value's trials."""
    rows = []
    ratios = stationary_ratios(stationary, [key])
    c = CLAIMS["hybrid.stationary"]
    for value, sub, judged in _bound_points(ratios, key, "hybrid.stationary"):
        v = None if judged is None else judged.claim
        oracle_ratio = np.sqrt(
            np.mean(sub["exact target, homography"] ** 2) / np.mean(sub["exact target, pnp"] ** 2)
        )
        rows.append(
            {
                key: float(value),
                "trials": len(sub),
                "rms_ratio": float(
                    np.sqrt(np.mean(sub[c.figure] ** 2) / np.mean(sub[c.baseline] ** 2))
                ),
                "ci_low": np.nan if v is None else v.ci_low,
                "ci_high": np.nan if v is None else v.ci_high,
                "per_trial_p95": float(np.quantile(sub["ratio"], 0.95)),
                "oracle_rms_ratio": float(oracle_ratio),
                "verdict": verdict_text(judged),
            }
        )
    return pd.DataFrame(rows)


def station_against_design(stationary: pd.DataFrame) -> dict:
    """The station scenario: the calibrated homography chain (calibrated hand-eye, reported
    flange poses of the nominal robot) against the uncalibrated design pose, the RMS field
    error over the ten sensors pooled over trials. Returns the RMS ratio calibrated / design
    with its 95 % interval (``station_design_ratio``, ``_low``, ``_high``) and the sentence
    that says which is better (``station_design_sentence``)."""
    wide = _rms_per_trial(stationary[stationary["scenario"] == "station"])
    ratio, lo, hi = rms_ratio_interval(wide["homography"], wide["design pose"])
    if lo > 1.0:
        finding = "the uncalibrated design pose is better than the calibrated chain"
    elif hi < 1.0:
        finding = "the calibrated chain is better than the uncalibrated design pose"
    else:
        finding = "the calibrated chain and the design pose cannot be told apart"
    sentence = (
        f"in the station scenario {finding}: the calibrated chain's RMS field error is "
        f"{ratio:.3g} times the design pose's (95 % interval {lo:.3g}-{hi:.3g}, "
        f"{len(wide)} stations)"
    )
    return {
        "station_design_ratio": ratio,
        "station_design_low": lo,
        "station_design_high": hi,
        "station_design_sentence": sentence,
    }


def where_verdict_changes(values, verdicts, default, what: str, unit: str = "") -> str:
    """One sentence: the verdict at the default value of a swept assumption and the values
    between which it changes (``values`` ascending, one verdict each). Claim ids and input
    names in ``what`` are written as words (:func:`calstudy.core.labels.plain`)."""
    what = plain(what)
    values = [float(v) for v in values]
    verdicts = list(verdicts)
    if len(values) != len(verdicts) or not values:
        raise CalibrationError(f"{len(values)} values but {len(verdicts)} verdicts")
    order = np.argsort(values)
    values = [values[i] for i in order]
    verdicts = [verdicts[i] for i in order]
    unit = f" {unit}" if unit else ""
    changes = verdict_changes(values, verdicts, fmt=lambda x: f"{x:g}{unit}")
    span = f"{values[0]:g}-{values[-1]:g}{unit}"
    at = [v for x, v in zip(values, verdicts, strict=True) if np.isclose(x, float(default))]
    at_default = f", {at[0]} at the default {float(default):g}{unit}" if at else ""
    if not changes:
        return f"{what}: {verdicts[0]} at every value swept ({span})"
    return f"{what}: the verdict changes " + "; ".join(changes) + f" (swept {span}{at_default})"


# ---------------------------------------------------------------------------------------------
# notebook 02: the deviation distribution and the drift


def chi_square_distance(counts, published_percent) -> np.ndarray:
    """Pearson chi-square of each row of bin ``counts (N, 5)`` against the published shares,
    the last two bins merged (the published one beyond 0.5 mm is empty, so it has no expected
    count of its own): 3 degrees of freedom."""
    c = np.atleast_2d(np.asarray(counts, dtype=float))
    p = np.asarray(published_percent, dtype=float)
    c = np.column_stack([c[:, :3], c[:, 3:].sum(axis=1)])
    p = np.r_[p[:3], p[3:].sum()]
    if np.any(c.sum(axis=1) <= 0.0) or np.any(p <= 0.0):
        raise CalibrationError(
            "a chi-square distance needs counts in every row and a positive published share "
            f"in every merged bin; row totals {c.sum(axis=1).min():g} (smallest), shares {p}"
        )
    expected = c.sum(axis=1, keepdims=True) * p / p.sum()
    return ((c - expected) ** 2 / expected).sum(axis=1)


#: 5 % critical value of :func:`chi_square_distance` (3 degrees of freedom)
CHI2_CRITICAL = float(chi2.ppf(0.95, 3))


def deviation_distribution(trials: pd.DataFrame, n_compensation: int) -> pd.DataFrame:
    """The deviation half of Table 1 as a whole distribution at ``n_compensation``: per bin the
    median simulated share and the published one, then the Kolmogorov distance and the
    chi-square statistic over trials (median and 95 % spread) with their 5 % critical values."""
    pub = load_published().table1
    sub = trials[trials["n_compensation"] == n_compensation]
    counts = sub[[f"deviation_bin{k}" for k in range(5)]].to_numpy(float)
    n = counts.sum(axis=1, keepdims=True)
    rows = []
    for k, label in enumerate(pub.deviation_bins):
        med, lo, hi = median_and_spread(100.0 * counts[:, k] / n[:, 0])
        rows.append(
            {
                "figure": f"share {label} mm (%)",
                "simulated": med,
                "spread_low": lo,
                "spread_high": hi,
                "published": float(pub.deviation_percent[k]),
            }
        )
    for name, values, critical in (
        ("Kolmogorov distance", bin_distance(counts, pub.deviation_percent), None),
        ("chi-square (3 dof)", chi_square_distance(counts, pub.deviation_percent), CHI2_CRITICAL),
    ):
        med, lo, hi = median_and_spread(values)
        crit = kolmogorov_bound(int(n[0, 0])) if critical is None else critical
        rows.append(
            {
                "figure": f"{name}, 5 % critical {crit:.3g}",
                "simulated": med,
                "spread_low": lo,
                "spread_high": hi,
                "published": 0.0,
            }
        )
    return pd.DataFrame(rows)


def deviation_statistics(sub: pd.DataFrame) -> dict[str, np.ndarray]:
    """Per trial of ``sub`` the shortfall of the deviation bins from the published ones
    (:func:`calstudy.papers.hybrid.compensation.shortfall_distance`): ``deviation_shortfall``
    after compensation and, where the trials carry the controls' bins, ``_null`` (no offset)
    and ``_oracle`` (the drift removed)."""
    pub = load_published().table1.deviation_percent
    out = {}
    kinds = (("deviation", ""), ("deviation_null", "_null"), ("deviation_oracle", "_oracle"))
    for prefix, name in kinds:
        columns = [f"{prefix}_bin{k}" for k in range(5)]
        if all(c in sub for c in columns):
            out[f"deviation_shortfall{name}"] = shortfall_distance(sub[columns].to_numpy(), pub)
    return out


def deviation_verdicts(sub: pd.DataFrame, min_trials: int = 30):
    """``hybrid.deviation`` on the trials of ``sub``: the shortfall of the five deviation bins
    from the published ones against its 5 % critical value (bound), with its null and oracle
    controls (:data:`CLAIMS`, the verdict gated by the oracle) where the trials carry their
    bins, the claim alone otherwise (the sweeps); ``min_trials`` 30 at a sweep point."""
    stats = deviation_statistics(sub)
    columns = CLAIMS["hybrid.deviation"]
    if "deviation_shortfall_null" not in stats:
        columns = ClaimColumns(columns.figure)
    n_vectors = int(sub[[f"deviation_bin{k}" for k in range(5)]].to_numpy().sum(axis=1)[0])
    return judge_claim(
        "hybrid.deviation",
        stats,
        columns,
        reference=shortfall_bound(n_vectors),
        min_trials=min_trials,
    )


def summarise_drift(sweep: pd.DataFrame) -> pd.DataFrame:
    """The drift rows of the sensitivity sweep: per drift sigma the share within +-0.3 mm with
    the drift (claim) and without it (oracle), the Kolmogorov and chi-square distances of the
    deviation bins to the published ones (medians over stations) and the ``hybrid.deviation``
    verdict by its rule."""
    pub = load_published().table1
    drift = sweep[sweep["parameter"] == "drift_sigma_mm"]
    rows = []
    for value, sub in drift.groupby("value", sort=True):
        judged = verdict_or_none(lambda s=sub: deviation_verdicts(s))
        counts = sub[[f"deviation_bin{k}" for k in range(5)]].to_numpy(float)
        rows.append(
            {
                "drift_sigma_mm": float(value),
                "stations": len(sub),
                "within_0p3_pct": float(np.median(sub["within_0p3"])),
                "oracle_within_0p3_pct": float(np.median(sub["within_0p3_oracle"])),
                "bin_le_0p1_pct": float(np.median(100.0 * counts[:, 0] / counts.sum(axis=1))),
                "shortfall": float(np.median(shortfall_distance(counts, pub.deviation_percent))),
                "kolmogorov": float(np.median(bin_distance(counts, pub.deviation_percent))),
                "chi_square": float(np.median(chi_square_distance(counts, pub.deviation_percent))),
                "verdict": verdict_text(judged),
            }
        )
    return pd.DataFrame(rows)


def bin_distance(counts: np.ndarray, published_percent) -> np.ndarray:
    """Kolmogorov distance per row of ``counts (N, 5)``: the largest gap between the cumulative
    shares of the bins and those of the published bins."""
    c = np.asarray(counts, dtype=float)
    share = np.cumsum(c, axis=1) / np.maximum(1.0, c.sum(axis=1, keepdims=True))
    pub = np.asarray(published_percent, dtype=float)
    return np.abs(share - np.cumsum(pub) / pub.sum()).max(axis=1)


def kolmogorov_bound(n_vectors: int) -> float:
    """5 % critical Kolmogorov distance for ``n_vectors`` values against a fixed distribution
    (``1.36 / sqrt(n)``): a station drawn from the published distribution exceeds it in 5 % of
    cases."""
    return 1.36 / np.sqrt(n_vectors)
