"""How the defocus error of the calibration views reaches the Fig. 13 baseline (notebook 04).

Reads the rows of the F-number sweep (:func:`calstudy.papers.binocular.experiments.optics_trial`
with :func:`calstudy.papers.binocular.experiments.handeye_chain`): per F-number, the image
shifts, the 3-D point errors along and across the calibrator plate, the calibrator pose error,
the preliminary hand-eye error and the Fig. 13 RMSE it gives, with and without the defocus.
Nothing here simulates.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from calstudy.papers.binocular.report import OPTICS, loglog_crossing
from calstudy.papers.binocular.scenario import paper_table, published

#: Columns of :func:`chain_table` taken as medians over the trials of a sweep point.
CHAIN_MEDIANS = (
    "t2_without",
    "shift_px_rms",
    "shift_px_max",
    "depth_min_mm",
    "depth_max_mm",
    "point_err_normal_mm",
    "point_err_inplane_mm",
    "pose_rot_err_mrad",
    "move_deg",
    "rot_err_preliminary_mrad",
    "trans_err_preliminary_mm",
    "rot_err_sharp_mrad",
    "trans_err_sharp_mm",
    "fig13_exact_p7_preliminary",
    "fig13_exact_p7_sharp",
    "fig13_exact_p7_true",
)


def chain_table(sweep: pd.DataFrame) -> pd.DataFrame:
    """Per F-number of the sweep (the other optics at their default): N, the medians of
    :data:`CHAIN_MEDIANS` (mm, px, mrad, deg) and the median hand-eye translation error per
    mrad of calibrator pose error (``mm_per_mrad``)."""
    sel = sweep
    for key, _, _ in OPTICS:
        if key != "f_number" and key in sel:
            sel = sel[sel[key] == 0.0]
    rows = []
    for value, d in sel.groupby("f_number", sort=True):
        row = {"f_number": float(value), "n": len(d)}
        row.update({c: float(d[c].median()) for c in CHAIN_MEDIANS})
        per_mrad = d["trans_err_preliminary_mm"] / d["pose_rot_err_mrad"]
        row["mm_per_mrad"] = float(per_mrad.median())
        rows.append(row)
    return pd.DataFrame(rows)


def chain_text(table: pd.DataFrame, trials_default: pd.DataFrame, f_number: float) -> str:
    """The chain in sentences, from the F-number sweep ``table`` (:func:`chain_table`) and the
    default trials of the main experiment (``trials_default``, run at ``f_number``)."""
    t = table.sort_values("f_number").reset_index(drop=True)
    near = t.iloc[int(np.argmin(np.abs(np.log(t["f_number"] / f_number))))]
    fig13 = published("station", "fig13_rmse")[0]
    t2 = published("calibrator", "table2_rmse")[0]
    d = trials_default
    distance = paper_table("station").poses.observation_distance_mm
    text = (
        f"At f/{near['f_number']:g}, the swept F-number nearest the calibrated one, the "
        f"calibration views hold the dots between {near['depth_min_mm']:.0f} and "
        f"{near['depth_max_mm']:.0f} mm from the cameras; the detected centres move by "
        f"{near['shift_px_rms']:.2g} px RMS (up to {near['shift_px_max']:.2g} px). Triangulated, "
        f"these shifts give point errors of {near['point_err_normal_mm']:.2g} mm RMS along the "
        f"plate normal against {near['point_err_inplane_mm']:.2g} mm across the plate: the "
        f"distances to P7 of Table 2 lie in the plate and see mainly the smaller part (median "
        f"{near['t2_without']:.2g} mm), while the calibrator poses fitted to the points tilt by "
        f"{near['pose_rot_err_mrad']:.2g} mrad RMS. AX = XB turns each mrad of pose error into "
        f"about {near['mm_per_mrad']:.2g} mm of hand-eye translation error (the sensor sits "
        f"about {distance:.0f} mm from the calibrator and the moves between the six poses "
        f"rotate by {near['move_deg']:.2g} deg in the median): the preliminary matrix is off by "
        f"{near['trans_err_preliminary_mm']:.2g} mm and "
        f"{near['rot_err_preliminary_mrad']:.2g} mrad, and gives a Fig. 13 baseline of "
        f"{near['fig13_exact_p7_preliminary']:.2g} mm with P7 itself measured exactly. The full "
        f"experiment at f/{f_number:.3g} gives a Fig. 13 baseline of "
        f"{d['fig13_preliminary'].median():.3g} mm and a hand-eye translation error of "
        f"{d['trans_err_preliminary_mm'].median():.3g} mm; the paper's baseline is {fig13:.3g} mm."
    )
    f_meet = loglog_crossing(t["f_number"], t["fig13_exact_p7_preliminary"], fig13)
    if f_meet is None:
        text += (
            f" No swept F-number brings the Fig. 13 baseline down to {fig13:.3g} mm (from "
            f"{t['fig13_exact_p7_preliminary'].iloc[0]:.2g} mm at f/{t['f_number'].iloc[0]:g} to "
            f"{t['fig13_exact_p7_preliminary'].iloc[-1]:.2g} mm at f/{t['f_number'].iloc[-1]:g})."
        )
    else:
        logs = np.log(t["f_number"]), np.log(t["t2_without"])
        t2_there = math.exp(np.interp(math.log(f_meet), *logs))
        text += (
            f" The baseline meets {fig13:.3g} mm near f/{f_meet:.3g}, where the Table 2 RMSE "
            f"without rectification is {t2_there:.2g} mm against the paper's {t2:.3g} mm."
        )
    text += (
        f" With the defocus switched off in the same views the baseline is "
        f"{t['fig13_exact_p7_sharp'].median():.2g} mm (the cameras' calibration errors, image "
        f"noise and dot offsets) and with the true matrix "
        f"{t['fig13_exact_p7_true'].median():.2g} mm (the robot alone)."
    )
    return text


def chain_figure(table: pd.DataFrame):
    """Two panels against the F-number: the Table 2 RMSE without rectification, and the Fig. 13
    baseline with the preliminary matrix (defocus on, off) and the true one, each beside the
    paper's value."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

    t = table.sort_values("f_number")
    fig, (left, right) = plt.subplots(1, 2, figsize=(7.8, 3.2))
    left.plot(t["f_number"], t["t2_without"], "o-", label="simulated (median)")
    left.axhline(published("calibrator", "table2_rmse")[0], color="k", ls=":", label="paper")
    left.set_ylabel("Table 2 RMSE without\nrectification (mm)", fontsize=9)
    for col, label, style in (
        ("fig13_exact_p7_preliminary", "preliminary matrix", "o-"),
        ("fig13_exact_p7_sharp", "preliminary, defocus off", "s--"),
        ("fig13_exact_p7_true", "true matrix", "^:"),
    ):
        right.plot(t["f_number"], t[col], style, label=label)
    right.axhline(published("station", "fig13_rmse")[0], color="k", ls=":", label="paper")
    right.set_yscale("log")
    right.yaxis.set_major_locator(FixedLocator([0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10]))
    right.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    right.yaxis.set_minor_formatter(NullFormatter())
    right.set_ylabel("Fig. 13 RMSE, P7 exact (mm)", fontsize=9)
    for ax in (left, right):
        ax.set_xlabel("F-number", fontsize=9)
        ax.tick_params(labelsize=8)
    handles, labels = right.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=7, bbox_to_anchor=(0.5, 0.0))
    left.legend(fontsize=7, loc="upper right")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return fig
