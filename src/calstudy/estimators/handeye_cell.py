"""Tables, figure and Monte Carlo check for a hand-eye calibration of one's own cell (notebook 06).

Thin helpers over :mod:`calstudy.estimators.handeye_poses`: the example cell the notebook runs on
by default, the method comparison, the estimate with its uncertainty, the per-pose residuals, and
the predicted against the simulated accuracy at a tool point.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.estimators import handeye_poses as hp
from calstudy.estimators.handeye_sim import SimulatedCell, simulate_cell
from calstudy.estimators.posefile import PoseList


def example_cell(
    seed: int,
    n_poses: int = 20,
    n_duplicates: int = 3,
    outlier: tuple[float, float] = (68.0, 1.8),
    sigma_rot: float = 1e-3,
    sigma_trans: float = 0.2,
    round_rotations: int = 7,
) -> SimulatedCell:
    """The notebook's synthetic cell: ``n_poses`` views, ``n_duplicates`` repeated orientations,
    the last pose a gross outlier, rotation entries rounded to ``round_rotations`` decimals."""
    return simulate_cell(
        np.random.default_rng(seed),
        n_poses,
        sigma_rot,
        sigma_trans,
        n_duplicate_orientations=n_duplicates,
        outlier=outlier,
        round_rotations=round_rotations,
    )


def input_table(pose_list: PoseList, result: hp.HandEyeResult, source: str) -> pd.DataFrame:
    """One row describing the input: source, poses, conventions, units, SO(3) correction."""
    prep = result.prepared
    return pd.DataFrame(
        {
            "source": [source],
            "poses": [len(pose_list)],
            "robot_convention": [prep.robot_convention],
            "camera_convention": [prep.camera_convention],
            "robot_unit": [prep.robot_unit],
            "camera_unit": [prep.camera_unit],
            "max_so3_correction": [prep.max_correction],
            "worst_pose": [prep.worst_pose],
        }
    )


def conditioning_table(result: hp.HandEyeResult) -> pd.DataFrame:
    """The conditioning of the motions (:class:`~calstudy.estimators.handeye_inputs.Conditioning`)
    as one row."""
    c = result.conditioning
    return pd.DataFrame([vars(c)])


def methods_table(results: dict, truth_x: np.ndarray | None = None) -> pd.DataFrame:
    """Closed forms and refinements side by side.

    Parameters
    ----------
    results : dict
        ``{label: HandEyeResult}``; the closed forms of every result are listed once, then each
        result's own estimate under its label.
    truth_x : (4, 4) array, optional
        True ``X`` (synthetic data): adds the rotation (deg) and translation (mm) errors.

    Returns
    -------
    pandas.DataFrame
        ``method, kind, rms_rot_deg, rms_trans_mm, refused, [rot_err_deg, trans_err_mm]``.
    """
    rows, seen = [], set()
    for res in results.values():
        for c in res.closed_forms:
            if c.method in seen:
                continue
            seen.add(c.method)
            rows.append(
                {
                    "method": c.method,
                    "kind": "closed form",
                    "rms_rot_deg": c.rms_rot_deg,
                    "rms_trans_mm": c.rms_trans_mm,
                    "refused": c.refused,
                    "x": c.x,
                }
            )
    for label, res in results.items():
        rot = np.rad2deg(np.sqrt(np.mean(np.sum(res.residuals[:, 3:] ** 2, 1))))
        trans = np.sqrt(np.mean(np.sum(res.residuals[:, :3] ** 2, 1)))
        rows.append(
            {
                "method": label,
                "kind": res.method,
                "rms_rot_deg": rot,
                "rms_trans_mm": trans,
                "refused": "",
                "x": res.x,
            }
        )
    df = pd.DataFrame(rows)
    if truth_x is not None:
        ok = df["x"].map(lambda x: x is not None)
        df["rot_err_deg"] = np.nan
        df["trans_err_mm"] = np.nan
        df.loc[ok, "rot_err_deg"] = [np.rad2deg(geo.rotation_error(x, truth_x)) for x in df.x[ok]]
        df.loc[ok, "trans_err_mm"] = [geo.translation_error(x, truth_x) for x in df.x[ok]]
    return df.drop(columns="x")


def estimate_table(result: hp.HandEyeResult) -> pd.DataFrame:
    """``X`` and ``Z`` with standard deviations: translation (mm) and rotation vector (deg), the
    rotation std about the axes of the estimated frame (``R = R_est exp(theta)``)."""
    std = result.std
    rows = []
    for name, t, off in ((result.x_name, result.x, 0), (result.z_name, result.z, 6)):
        rv = np.rad2deg(geo.matrix_to_rotvec(t[:3, :3]))
        for k, axis in enumerate("xyz"):
            rows.append(
                {
                    "transform": name,
                    "parameter": f"t{axis}_mm",
                    "value": t[k, 3],
                    "std": std[off + 3 + k],
                }
            )
        for k, axis in enumerate("xyz"):
            rows.append(
                {
                    "transform": name,
                    "parameter": f"r{axis}_deg",
                    "value": rv[k],
                    "std": np.rad2deg(std[off + k]),
                }
            )
    df = pd.DataFrame(rows)
    df["covariance"] = result.covariance_basis
    return df


def pose_table(result: hp.HandEyeResult) -> pd.DataFrame:
    """Per-pose residual (mm, deg), outlier score, flag and final weight."""
    res = result.residuals
    return pd.DataFrame(
        {
            "id": result.prepared.ids,
            "trans_mm": np.linalg.norm(res[:, :3], axis=1),
            "rot_deg": np.rad2deg(np.linalg.norm(res[:, 3:], axis=1)),
            "score": result.outlier_score,
            "flagged": np.isin(result.prepared.ids, result.flagged),
            "weight": result.weights,
        }
    )


def pose_residual_figure(table: pd.DataFrame, limit: float):
    """Bar chart of the per-pose outlier score (log scale) with the flag limit; flagged red."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.2))
    colours = np.where(table["flagged"], "tab:red", "tab:blue")
    ax.bar(table["id"].astype(str), table["score"], color=colours)
    ax.axhline(limit, color="k", ls="--", lw=1, label=f"flag limit (chi2_6 = {limit:.3g})")
    ax.set_yscale("log")
    ax.set_xlabel("pose id")
    ax.set_ylabel("whitened residual chi2")
    ax.set_title("Per-pose residuals (red: flagged as outlier)")
    ax.tick_params(axis="x", labelsize=7, rotation=90)
    ax.legend(loc="upper left")
    fig.tight_layout()
    return fig


def tool_point_check(
    result: hp.HandEyeResult,
    point_camera,
    n_trials: int,
    rng: np.random.Generator,
    **calibrate_kwargs,
) -> pd.DataFrame:
    """Predicted against simulated accuracy of a tool point mapped by ``X``.

    The prediction is :meth:`HandEyeResult.point_covariance`. The check re-draws the camera
    poses ``n_trials`` times on the same robot poses around the estimate, with the estimated
    noise level, recalibrates each time and takes the spread of ``X p``; outliers (flagged poses)
    are left out of the simulation. ``n_trials = 0`` gives only the prediction.

    Returns
    -------
    pandas.DataFrame
        Rows ``predicted`` and (if simulated) ``simulated``: std along x, y, z and the RMS
        radius, mm.
    """
    p = np.asarray(point_camera, dtype=float)
    cov = result.point_covariance(p)
    rows = [("predicted", *np.sqrt(np.diag(cov)), np.sqrt(np.trace(cov)))]
    if n_trials > 0:
        keep = ~np.isin(result.prepared.ids, result.flagged)
        a = result.prepared.a[keep]
        b_true = geo.invert(result.x) @ geo.invert(a) @ result.z
        pts = []
        for _ in range(n_trials):
            b = geo.perturb(b_true, result.sigma_rot, result.sigma_trans, rng)
            fit = hp.calibrate_handeye(
                a, b, setup="eye_in_hand", check_convention="off", **calibrate_kwargs
            )
            pts.append(geo.apply(fit.x, p))
        dev = np.array(pts) - geo.apply(result.x, p)
        sim = dev.T @ dev / n_trials
        rows.append(("simulated", *np.sqrt(np.diag(sim)), np.sqrt(np.trace(sim))))
    return pd.DataFrame(rows, columns=["kind", "std_x_mm", "std_y_mm", "std_z_mm", "rms_mm"])
