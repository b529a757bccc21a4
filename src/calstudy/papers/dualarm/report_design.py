"""Tables, figures and generated sentences on the design of the ``dualarm`` station: the survey
sweeps (where the verdict of ``dualarm.global`` changes), the error budget of the coded-marker
chain by source, the detection model per target type and the check of Eq. 10 against Eq. 9.

Inputs are the Monte Carlo tables of :func:`~calstudy.papers.dualarm.experiments.
survey_experiment` and :func:`~calstudy.papers.dualarm.experiments.budget_experiment`.
Millimetres, degrees where a column says so.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from calstudy.claims import ClaimColumns, judge_along
from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.labels import claim_label
from calstudy.core.robustness import verdict_changes
from calstudy.core.stats import median_interval
from calstudy.models.targets import circle_centre_bias
from calstudy.papers.dualarm import simulate as sim
from calstudy.papers.dualarm.experiments import BUDGET_SOURCES
from calstudy.papers.dualarm.report import claim_figures, part, published_figures
from calstudy.papers.dualarm.schema import PublishedFile, Scenario

#: the three inputs of the survey sweeps: column -> words
SWEEPS = {
    "bridge_views": "linking images",
    "bridge_tilt_deg": "tilt of the linking images (deg)",
    "calibration_poses": "calibration poses per arm",
}


def sweep_table(sweep: pd.DataFrame, published: PublishedFile) -> pd.DataFrame:
    """Per sweep point: the coded-marker route's mean Euclidean sphere-centre error (median over
    trials with its 95 % interval), the survey's link error, and the verdict ``dualarm.global``
    would get at that point by the v2 rule."""
    rows = []
    points = judge_along(
        sweep,
        list(SWEEPS),
        "dualarm.global",
        ClaimColumns("coded_euclid_mm"),
        **claim_figures(published)["dualarm.global"],
    )
    for key, g, judged in points:
        if judged is None:
            raise CalibrationError(f"sweep point {key}: {len(g)} trials, too few for the rule")
        v = judged.claim
        rows.append(
            {
                **dict(zip(SWEEPS, key, strict=True)),
                "median_mm": v.median,
                "ci_low_mm": v.ci_low,
                "ci_high_mm": v.ci_high,
                "link_deg": float(g["link_deg"].median()),
                "n": len(g),
                "verdict": v.verdict,
            }
        )
    return pd.DataFrame(rows)


def _base_point(scn: Scenario) -> dict:
    return {
        "bridge_views": int(scn.survey.bridge_views),
        "bridge_tilt_deg": float(round(np.degrees(scn.survey.bridge_tilt), 6)),
        "calibration_poses": int(scn.global_test.calibration_poses),
    }


def sweep_lines(table: pd.DataFrame, scn: Scenario) -> dict[str, pd.DataFrame]:
    """Each sweep (column of :data:`SWEEPS`) as the rows of :func:`sweep_table` where the other
    two inputs keep the scenario's design, sorted by the swept input."""
    base = _base_point(scn)
    out = {}
    for col in SWEEPS:
        keep = np.ones(len(table), dtype=bool)
        for other in SWEEPS:
            if other != col:
                keep &= np.isclose(table[other].to_numpy(float), base[other])
        out[col] = table[keep].sort_values(col).reset_index(drop=True)
    return out


def _fmt(x: float) -> str:
    return f"{x:g}"


def sweep_sentences(table: pd.DataFrame, scn: Scenario) -> str:
    """One generated sentence per sweep: where the verdict of ``dualarm.global`` changes along it,
    or that it does not over the swept range, with the medians at the ends."""
    out = []
    for col, line in sweep_lines(table, scn).items():
        name = SWEEPS[col].split(" (")[0]
        xs, verdicts = line[col].tolist(), line["verdict"].tolist()
        ends = (
            f"median {line['median_mm'].iloc[0]:.3f} mm at {_fmt(xs[0])}, "
            f"{line['median_mm'].iloc[-1]:.3f} mm at {_fmt(xs[-1])}"
        )
        steps = "; ".join(verdict_changes(xs, verdicts, "from '{a}' at {x} to '{b}' at {y}"))
        if steps:
            out.append(f"Along the {name}, the verdict changes {steps} ({ends}).")
        else:
            out.append(
                f"Along the {name} ({', '.join(map(_fmt, xs))}), the verdict stays "
                f"'{verdicts[0]}' ({ends})."
            )
    return " ".join(out)


def paper_point_sentence(table: pd.DataFrame, scn: Scenario) -> str:
    """Which points of the survey sweeps the paper's setup resembles, in one generated sentence.

    The paper fixes the calibration poses per arm (``global_test.calibration_poses``, provenance
    ``paper``) and leaves the linking images and their tilt open: the points it resembles are
    those with its number of poses, each linking design it does not rule out. The sentence names
    them, the verdict of ``dualarm.global`` at the scenario's design and the verdicts over them.

    Parameters
    ----------
    table : pandas.DataFrame
        :func:`sweep_table`.
    scn : Scenario
        The station (its design and the ledger of the swept inputs).

    Returns
    -------
    str
        One sentence.

    Raises
    ------
    CalibrationError
        If the sweep holds no point with the paper's number of poses.
    """
    base = _base_point(scn)
    poses = base["calibration_poses"]
    kind = scn.global_test.provenance["calibration_poses"].kind
    same = table[table["calibration_poses"] == poses]
    if same.empty:
        raise CalibrationError(
            f"the survey sweep has no point with the paper's {poses} calibration poses per arm"
        )
    at = np.ones(len(table), dtype=bool)
    for col in SWEEPS:
        at &= np.isclose(table[col].to_numpy(float), base[col])
    design = table[at].iloc[0]
    verdicts = list(dict.fromkeys(same["verdict"]))
    lo, hi = same["median_mm"].min(), same["median_mm"].max()
    views = ", ".join(map(_fmt, sorted(set(same["bridge_views"]))))
    tilts = ", ".join(map(_fmt, sorted(set(same["bridge_tilt_deg"]))))
    over = (
        f"it is '{verdicts[0]}' at every one of them"
        if len(verdicts) == 1
        else f"over them it takes {' and '.join(repr(v) for v in verdicts)}"
    )
    return (
        f"The paper's setup ({poses} calibration poses per arm, {kind}; no count or tilt of the "
        f"linking images) resembles the {len(same)} sweep points with {poses} poses ({views} "
        f"linking images, tilts {tilts} deg); at the scenario's design among them "
        f"({_fmt(base['bridge_views'])} linking images, {_fmt(base['bridge_tilt_deg'])} deg) "
        f"{claim_label('dualarm.global')} is '{design['verdict']}' (median "
        f"{design['median_mm']:.3f} mm), and "
        f"{over} (medians {lo:.3f}-{hi:.3f} mm)."
    )


def sweep_figure(table: pd.DataFrame, scn: Scenario, published: PublishedFile):
    """Three panels, one per sweep: median sphere-centre error of the coded-marker route with its
    95 % interval, the paper's 0.100 mm and the best other method of Table 3."""
    import matplotlib.pyplot as plt

    f = published_figures(published)
    fig, axes = plt.subplots(1, 3, figsize=(8, 3.2), sharey=True)
    for ax, (col, line) in zip(axes, sweep_lines(table, scn).items(), strict=True):
        x = line[col].to_numpy(float)
        y = line["median_mm"].to_numpy(float)
        err = np.abs(line[["ci_low_mm", "ci_high_mm"]].to_numpy(float).T - y)
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label="coded markers (median)")
        ax.axhline(f["global"], color="C2", ls="--", label=f"paper: {f['global']:.3f} mm")
        ax.axhline(
            f["global_reference"],
            color="C3",
            ls=":",
            label=f"best other method: {f['global_reference']:.3f} mm",
        )
        ax.set_xlabel(SWEEPS[col])
        ax.set_ylim(bottom=0)
    axes[0].set_ylabel("sphere-centre error (mm)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, frameon=False)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return fig


def budget_methods() -> dict[str, str]:
    """Method names of the budget rows -> labels, whole chain first, test floor last."""
    return {
        "coded markers": "all sources (whole chain)",
        **{f"budget: {s}": f"{s} alone" for s in BUDGET_SOURCES},
        "true calibration": "test floor (no calibration error)",
    }


def budget_table(budget: pd.DataFrame) -> pd.DataFrame:
    """The error budget: per source switched on alone, the mean Euclidean sphere-centre error of
    the Tables 1-2 test per trial, as its median over the paired trials with a 95 % interval,
    and its share of the whole chain's median in quadrature."""
    g = part(budget, "global").groupby(["method", "trial"])["euclid_mm"].mean().unstack(0)
    whole = float(np.median(g["coded markers"]))
    rows = []
    for method, label in budget_methods().items():
        med, lo, hi = median_interval(g[method].to_numpy())
        rows.append(
            {
                "source": label,
                "median_mm": med,
                "ci_low_mm": lo,
                "ci_high_mm": hi,
                "share_of_variance_pct": 100 * (med / whole) ** 2,
                "n": int(g[method].size),
            }
        )
    return pd.DataFrame(rows)


def budget_figure(table: pd.DataFrame):
    """Horizontal bars of :func:`budget_table` with their 95 % intervals."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.2))
    y = np.arange(len(table))[::-1]
    med = table["median_mm"].to_numpy(float)
    err = np.abs(table[["ci_low_mm", "ci_high_mm"]].to_numpy(float).T - med)
    colors = ["C0"] + ["C1"] * (len(table) - 2) + ["C7"]
    ax.barh(y, med, xerr=err, color=colors, capsize=3)
    ax.set_yticks(y, table["source"])
    ax.set_xlabel("mean sphere-centre error per trial, median over trials (mm)")
    fig.tight_layout()
    return fig


def eq10_table(budget: pd.DataFrame) -> pd.DataFrame:
    """The survey's bundle adjustment with Eq. 9 and 10 against Eq. 9 alone, on the same images:
    medians over trials of the markers' RMS error and the link error, and the median paired
    ratio."""
    e = part(budget, "eq10")
    rows = []
    for name, both, alone in (
        ("markers vs Table A1, RMS (mm)", "marker_rms_mm", "marker_rms_eq9_only_mm"),
        ("survey link error (deg)", "link_deg", "link_eq9_only_deg"),
    ):
        ratio = median_interval((e[both] / e[alone]).to_numpy())
        rows.append(
            {
                "quantity": name,
                "Eq. 9 and 10": float(e[both].median()),
                "Eq. 9 alone": float(e[alone].median()),
                "paired ratio": ratio[0],
                "ratio_ci_low": ratio[1],
                "ratio_ci_high": ratio[2],
                "n": len(e),
            }
        )
    return pd.DataFrame(rows)


def detection_table(scn: Scenario, rng: np.random.Generator, n_views: int = 20) -> pd.DataFrame:
    """The detection model per target type: RMS and largest perspective bias of the detected
    circle centres (exact conic centre minus the image of the centre) in the views each step
    uses, and the random noise added on top."""
    mid = sim.mid_point(scn)
    plate = geo.make_transform(np.eye(3), sim.plate_place(scn))
    cases = []
    he_place = geo.make_transform(np.eye(3), scn.markers.group_centre(1))
    cam = sim.view_poses(
        rng, he_place[:3, 3], scn.sensor.working_distance_mm, n_views, scn.handeye.tilt, roll=0.0
    )
    cases.append(("plate circles, hand-eye views", cam, he_place, scn.handeye.circle_radius_mm))
    axis = (0.0, np.sin(scn.circular_plate.tilt), np.cos(scn.circular_plate.tilt))
    cam = sim.view_poses(
        rng, plate[:3, 3], scn.sensor.working_distance_mm, n_views, scn.circular_plate.jitter, axis
    )
    cases.append(("plate circles, Table 3 plate", cam, plate, scn.handeye.circle_radius_mm))
    cam = sim.view_poses(
        rng, scn.markers.group_centre(1), scn.sensor.working_distance_mm, n_views, scn.survey.tilt
    )
    cases.append(("coded markers, views of one group", cam, None, scn.detection.marker_radius_mm))
    cam = sim.view_poses(
        rng, mid, scn.survey.bridge_distance_mm, n_views, scn.survey.bridge_tilt, up=(0, 1, 0)
    )
    cases.append(("coded markers, linking images", cam, None, scn.detection.marker_radius_mm))
    k = scn.rig.left.K
    rows = []
    for name, cams, target, radius in cases:
        biases = []
        for c2w in cams:
            w2c = geo.invert(c2w)
            if target is None:
                pts, normal = geo.apply(w2c, scn.markers.xyz), w2c[:3, :3] @ [0.0, 0.0, 1.0]
            else:
                t2c = w2c @ target
                pts, normal = geo.apply(t2c, scn.handeye.plate_points), t2c[:3, 2]
            normals = np.broadcast_to(normal, pts.shape)
            biases.append(np.linalg.norm(circle_centre_bias(k, pts, normals, radius), axis=1))
        b = np.concatenate(biases)
        rows.append(
            {
                "target and views": name,
                "radius_mm": radius,
                "bias_rms_px": float(np.sqrt(np.mean(b**2))),
                "bias_max_px": float(b.max()),
            }
        )
    return pd.DataFrame(rows)
