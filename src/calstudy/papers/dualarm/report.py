"""Tables, figures and claim verdicts of the ``dualarm`` notebook, from the Monte Carlo tables of
:mod:`calstudy.papers.dualarm.experiments`, with the paper's numbers
(:func:`calstudy.papers.dualarm.scenario.load_published`) beside them."""

from __future__ import annotations

import numpy as np
import pandas as pd

from calstudy.claims import ClaimColumns, claim_row, control_rows, judge_claim
from calstudy.core.stats import median_and_spread
from calstudy.papers.dualarm.experiments import marker_error
from calstudy.papers.dualarm.scenario import SPHERES
from calstudy.papers.dualarm.schema import PublishedFile, Scenario


def survey_table(scn: Scenario, views: list, recon) -> pd.DataFrame:
    """One row on a marker survey (``survey_markers`` of ``views``): images taken and used,
    clusters of the image graph, bundle-adjustment residuals and the RMS distance of the markers
    from Table A1."""
    return pd.DataFrame(
        {
            "images": [len(views)],
            "images used (>= 4 markers)": [len(recon.used_views)],
            "clusters": [len(recon.clusters)],
            "cluster centres": [" ".join(str(c.centre) for c in recon.clusters)],
            "RMS reprojection (px)": [recon.bundle.rms_px],
            "RMS Euclidean residual (mm)": [recon.bundle.rms_mm],
            "markers vs Table A1, RMS (mm)": [marker_error(scn, recon.bundle.points)],
        }
    )


def part(trials: pd.DataFrame, name: str) -> pd.DataFrame:
    """The rows of one part (``calibration``, ``bundle``, ``icp``, ``global``) of the station
    trials, without the columns that part does not fill."""
    return trials[trials["part"] == name].dropna(axis=1, how="all").reset_index(drop=True)


def icp_per_trial(icp: pd.DataFrame) -> pd.DataFrame:
    """Mean before/after/oracle errors per trial, arm and sphere."""
    cols = [c for c in ("before_mm", "after_mm", "null_mm", "oracle_mm") if c in icp]
    return icp.groupby(["arm", "sphere", "trial"], as_index=False)[cols].mean()


def icp_summary(icp: pd.DataFrame, published: PublishedFile) -> pd.DataFrame:
    """Figs. 5-6 in numbers: per arm and sphere, the mean error before and after ICP (mean of
    the per-trial means, 95 % interval over trials), their ratio, and the paper's values."""
    pub = {(int(a), s): (b, c) for a, s, b, c in published.icp.rows}
    rows = []
    for (arm, sphere), g in icp_per_trial(icp).groupby(["arm", "sphere"]):
        ratio = g["after_mm"] / g["before_mm"]
        b, a = pub[(int(arm), sphere)]
        _, low, high = median_and_spread(g["after_mm"])
        rows.append(
            {
                "arm": arm,
                "sphere": sphere,
                "before_mm": g["before_mm"].mean(),
                "after_mm": g["after_mm"].mean(),
                "oracle_mm": g["oracle_mm"].mean(),
                "after_ci_low": low,
                "after_ci_high": high,
                "ratio": ratio.median(),
                "published_before_mm": b,
                "published_after_mm": a,
                "published_ratio": a / b,
            }
        )
    return pd.DataFrame(rows)


def table1(
    global_df: pd.DataFrame, published: PublishedFile, method: str = "coded markers"
) -> pd.DataFrame:
    """Table 1: mean absolute per-axis centre errors per group and over all groups."""
    g = global_df[global_df["method"] == method]
    g = g.astype({"group": int})
    pub = {int(r[0]): r[1:] for r in published.table1.rows}
    rows = []
    for group, part in [*g.groupby("group"), (0, g)]:
        p = pub.get(int(group), [np.nan] * 3)
        rows.append(
            {
                "group": "all" if group == 0 else str(group),
                "dx_mm": part["dx_mm"].mean(),
                "dy_mm": part["dy_mm"].mean(),
                "dz_mm": part["dz_mm"].mean(),
                "published_dx_mm": p[0],
                "published_dy_mm": p[1],
                "published_dz_mm": p[2],
            }
        )
    return pd.DataFrame(rows)


def table2(
    global_df: pd.DataFrame, published: PublishedFile, method: str = "coded markers"
) -> pd.DataFrame:
    """Table 2: mean Euclidean centre errors per group (rows) and arm-1 pose (columns), against
    arm 2's reference centre as in the paper; ``mean_vs_true_centre_mm`` against the true one."""
    g = global_df[global_df["method"] == method].astype({"group": int, "pose": int})
    pub = {int(r[0]): r[1:] for r in published.table2.rows}
    rows = []
    for group, part in [*g.groupby("group"), (0, g)]:
        row = {"group": "all" if group == 0 else str(group)}
        means = part.groupby("pose")["euclid_mm"].mean()
        for k, v in means.items():
            row[f"pose{k}_mm"] = v
        row["mean_mm"] = part["euclid_mm"].mean()
        row["mean_vs_true_centre_mm"] = part["euclid_truth_mm"].mean()
        for k, v in enumerate(pub.get(int(group), [np.nan] * 3)):
            row[f"published_pose{k + 1}_mm"] = v
        rows.append(row)
    return pd.DataFrame(rows)


def table3(global_df: pd.DataFrame, published: PublishedFile) -> pd.DataFrame:
    """Table 3: sphere-A centre errors by global calibration method, reproduced where testable."""
    rows = []
    for name, pub in zip(published.table3.methods, published.table3.rows, strict=True):
        part = global_df[global_df["method"] == name]
        testable = len(part) > 0
        row = {"method": name, "testable": "yes" if testable else "not testable"}
        for k, col in enumerate(["dx_mm", "dy_mm", "dz_mm", "euclid_mm"]):
            row[col] = part[col].mean() if testable else np.nan
            row[f"published_{col}"] = pub[k]
        rows.append(row)
    return pd.DataFrame(rows)


def calibration_summary(trials: pd.DataFrame) -> pd.DataFrame:
    """RMS over trials of the hand-eye and base-to-base errors, and the bundle figures (a
    figure without a rotation or translation part is missing there)."""
    calibration, bundle = part(trials, "calibration"), part(trials, "bundle")
    rows = [
        {
            "quantity": q,
            "rotation_deg_rms": float(np.sqrt(np.mean(g["rotation_deg"] ** 2))),
            "translation_mm_rms": float(np.sqrt(np.mean(g["translation_mm"] ** 2))),
        }
        for q, g in calibration.groupby("quantity", sort=False)
    ]
    out = pd.DataFrame(rows)
    b = bundle.mean(numeric_only=True)
    extra = pd.DataFrame(
        [
            {
                "quantity": "bundle RMS reprojection (px)",
                "rotation_deg_rms": np.nan,
                "translation_mm_rms": b["rms_px"],
            },
            {
                "quantity": "bundle RMS Euclidean residual",
                "rotation_deg_rms": np.nan,
                "translation_mm_rms": b["rms_mm"],
            },
            {
                "quantity": "markers vs Table A1 (RMS)",
                "rotation_deg_rms": np.nan,
                "translation_mm_rms": b["marker_rms_mm"],
            },
            {
                "quantity": "survey link (relative rotation of the groups)",
                "rotation_deg_rms": float(np.sqrt(np.mean(bundle["link_deg"] ** 2))),
                "translation_mm_rms": np.nan,
            },
        ]
    )
    return pd.concat([out, extra], ignore_index=True)


def sweep_summary(sweep: pd.DataFrame, by: str, columns) -> pd.DataFrame:
    """Mean and 95 % interval over trials of ``columns`` per value of ``by``."""
    rows = []
    for key, g in sweep.groupby(by):
        row = {by: key}
        for c in columns:
            _, lo, hi = median_and_spread(g[c])
            row[c] = g[c].mean()
            row[f"{c}_ci_low"], row[f"{c}_ci_high"] = lo, hi
        rows.append(row)
    return pd.DataFrame(rows)


def icp_figure(icp: pd.DataFrame, arm: int):
    """Figs. 5-6 equivalent: per view, the mean centre-distance error before and after ICP for
    spheres A and B of one arm (bars: mean over trials; whiskers: 95 % interval)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(8, 3.4), sharey=True)
    for ax, sphere in zip(axes, SPHERES, strict=True):
        g = icp[(icp["arm"] == arm) & (icp["sphere"] == sphere)]
        views = sorted(g["view"].unique())
        x = np.arange(len(views))
        for k, (col, label) in enumerate((("before_mm", "before ICP"), ("after_mm", "after ICP"))):
            stats = [g[g["view"] == v][col] for v in views]
            mean = np.array([s.mean() for s in stats])
            ci = np.array([median_and_spread(s)[1:] for s in stats])
            ax.bar(
                x + (k - 0.5) * 0.38, mean, 0.38, label=label, yerr=np.abs(ci.T - mean), capsize=2
            )
        ax.set_xticks(x, [str(v) for v in views])
        ax.set_xlabel("view (relative to view 0)")
        ax.set_title(f"arm {arm}, sphere {sphere}")
    axes[0].set_ylabel("centre distance error (mm)")
    axes[0].legend()
    fig.tight_layout()
    return fig


def sweep_figure(
    summary: pd.DataFrame, x: str, columns, labels, xlabel: str, ylabel: str, title: str
):
    """Lines with 95 % bands of ``columns`` of a :func:`sweep_summary` table against ``x``."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for c, lab in zip(columns, labels, strict=True):
        ax.plot(summary[x], summary[c], marker="o", label=lab)
        ax.fill_between(summary[x], summary[f"{c}_ci_low"], summary[f"{c}_ci_high"], alpha=0.2)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    return fig


def claim_samples(trials: pd.DataFrame) -> dict[str, np.ndarray]:
    """Per-trial figures of the three claims and their controls, in trial order:
    ``icp_before/after/null/oracle`` (mean over the 4 arm-sphere pairs of the mean over views;
    ``null``: the centroid correction), and the mean Euclidean sphere-centre error of Tables 1-2
    per method (``coded``, ``plate``, ``design`` (the design drawing's base-to-base),
    ``plate_retake`` (the plate taken again), ``true`` (true calibration)). Trials without the
    ICP part, or without the Tables 1-2 part, give only the figures of the other."""
    out = {}
    if (trials["part"] == "icp").any():
        per = icp_per_trial(part(trials, "icp")).groupby("trial")
        icp = per[["before_mm", "after_mm", "null_mm", "oracle_mm"]].mean().sort_index()
        out.update(
            icp_before=icp["before_mm"].to_numpy(),
            icp_after=icp["after_mm"].to_numpy(),
            icp_null=icp["null_mm"].to_numpy(),
            icp_oracle=icp["oracle_mm"].to_numpy(),
        )
    if (trials["part"] == "global").any():
        g = part(trials, "global").groupby(["method", "trial"])["euclid_mm"].mean().unstack(0)
        g = g.sort_index()
        out.update(
            coded=g["coded markers"].to_numpy(),
            plate=g["circular plate"].to_numpy(),
            design=g["design drawing"].to_numpy(),
            plate_retake=g["plate retake"].to_numpy(),
            true=g["true calibration"].to_numpy(),
        )
    return out


def claim_statistics(trials: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each claim's figure per trial, as its verdict judges it: the after / before ICP ratio
    (``dualarm.icp``), the coded markers' mean sphere-centre error in mm (``dualarm.global``)
    and the coded / plate ratio (``dualarm.vs_circular``); only the claims whose figures the
    trials hold."""
    x = claim_samples(trials)
    stats = {}
    if "icp_after" in x:
        stats["dualarm.icp"] = x["icp_after"] / x["icp_before"]
    if "coded" in x:
        stats["dualarm.global"] = x["coded"]
        stats["dualarm.vs_circular"] = x["coded"] / x["plate"]
    return stats


def published_figures(published: PublishedFile) -> dict[str, float]:
    """The paper's figures the claims are judged against."""
    pub = np.array([r[2:] for r in published.icp.rows], dtype=float)
    t3 = dict(zip(published.table3.methods, published.table3.rows, strict=True))
    return {
        "icp_before": float(pub[:, 0].mean()),
        "icp_after": float(pub[:, 1].mean()),
        "icp_ratio": float(pub[:, 1].mean() / pub[:, 0].mean()),
        "global": float(published.table2.overall),
        "global_reference": float(min(t3["rotary table"][3], t3["handheld scanner"][3])),
        "plate": float(t3["circular plate"][3]),
        "vs_ratio": float(t3["coded markers"][3] / t3["circular plate"][3]),
    }


#: Where each claim's figures sit in the table of :func:`claim_samples`; the rule is the
#: register's.
CLAIMS = {
    "dualarm.icp": ClaimColumns(
        "icp_after",
        baseline="icp_before",
        null="icp_null",
        oracle="icp_oracle",
        mechanism="pose errors between the views of a multi-view scan (drift)",
    ),
    "dualarm.global": ClaimColumns(
        "coded",
        null="design",
        oracle="true",
        mechanism="calibration error of the hand-eye and base-to-base transforms",
    ),
    "dualarm.vs_circular": ClaimColumns(
        "coded",
        baseline="plate",
        null="plate_retake",
        oracle="true",
        mechanism="calibration error of the two routes",
    ),
}


def claim_figures(published: PublishedFile) -> dict[str, dict[str, float]]:
    """Per claim, the paper's figure and the stated reference it is judged against."""
    f = published_figures(published)
    return {
        "dualarm.icp": {"published": f["icp_ratio"]},
        "dualarm.global": {"published": f["global"], "reference": f["global_reference"]},
        "dualarm.vs_circular": {"published": f["vs_ratio"]},
    }


def dualarm_verdicts(trials: pd.DataFrame, published: PublishedFile, ids=None) -> dict:
    """The claims by the v2 rule with their null and oracle controls, on the same trials:
    claim id -> :class:`calstudy.claims.Judged` (verdict after the oracle gate, null control,
    oracle control). ``ids``: only these claims (default: those whose columns of
    :data:`CLAIMS` the trials hold)."""
    x = claim_samples(trials)
    figures = claim_figures(published)
    if ids is None:
        ids = [
            cid
            for cid, columns in CLAIMS.items()
            if {c for c in (columns.figure, columns.baseline, columns.null, columns.oracle) if c}
            <= set(x)
        ]
    return {cid: judge_claim(cid, x, CLAIMS[cid], **figures[cid]) for cid in ids}


def dualarm_claims(trials: pd.DataFrame, published: PublishedFile, notebook: str):
    """``(claim rows, control rows)`` of the three claims (v2 rule, controls on the same
    trials)."""
    f = published_figures(published)
    labels = {
        "dualarm.icp": (
            f"{f['icp_ratio']:.3f} (mean after / mean before ICP: {f['icp_after']:.4f} / "
            f"{f['icp_before']:.3f} mm, 4 arm-sphere pairs)",
            "ratio",
        ),
        "dualarm.global": (
            f"{f['global']:.3f} (below the best other method of Table 3, "
            f"{f['global_reference']:.3f})",
            "mm",
        ),
        "dualarm.vs_circular": (
            f"{f['vs_ratio']:.3f} ({f['global']:.3f} / {f['plate']:.3f})",
            "ratio",
        ),
    }
    claims, controls = [], []
    for cid, judged in dualarm_verdicts(trials, published).items():
        pub, unit = labels[cid]
        claims.append(claim_row(cid, judged, published=pub, unit=unit, notebook=notebook))
        controls += control_rows(cid, judged)
    return claims, controls
