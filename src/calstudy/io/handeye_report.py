"""Tables, figure and Monte Carlo check for a hand-eye calibration of one's own cell (notebook 06).

Thin helpers over the door :mod:`calstudy.handeye`: the example cell the notebook runs on
by default, the method comparison, the estimate with its uncertainty, the per-pose residuals, and
the predicted against the simulated accuracy at a tool point.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.core.montecarlo import Experiment
from calstudy.handeye import (
    SETUP_FRAMES,
    HandEyeResult,
    PoseList,
    SimulatedCell,
    calibrate_handeye,
    calibrate_robot_world_handeye,
    plan_poses,
    read_pose_list,
    simulate_cell,
    write_pose_list,
)
from calstudy.handeye.plan import point_jacobian, point_rms, pose_information


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


def input_table(pose_list: PoseList, result: HandEyeResult, source: str) -> pd.DataFrame:
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


def conditioning_table(result: HandEyeResult) -> pd.DataFrame:
    """The conditioning of the motions (:class:`~calstudy.handeye.inputs.Conditioning`)
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
                "x": res.camera2mount,
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


def estimate_table(result: HandEyeResult) -> pd.DataFrame:
    """The camera's and the target's pose with standard deviations: translation (mm) and
    rotation vector (deg), the rotation std about the axes of the estimated frame
    (``R = R_est exp(theta)``)."""
    std = result.std
    rows = []
    names = SETUP_FRAMES[result.setup]
    transforms = (result.camera2mount, result.target2mount)
    for name, t, off in zip(names, transforms, (0, 6), strict=True):
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


def pose_table(result: HandEyeResult) -> pd.DataFrame:
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


@dataclass(frozen=True)
class ToolPointCell:
    """What one re-calibration of the tool-point check needs (the engine's scenario).

    ``a`` are the robot poses kept (flagged poses left out), ``b_true`` the camera poses the
    estimate predicts for them, ``x`` the estimate, ``point`` the tool point in the camera frame
    (mm), ``sigma_rot``/``sigma_trans`` the noise level, ``robust``/``setup`` as calibrated.
    """

    a: np.ndarray
    b_true: np.ndarray
    x: np.ndarray
    point: np.ndarray
    sigma_rot: float
    sigma_trans: float
    given_sigmas: bool


def tool_point_cell(result: HandEyeResult, point_camera, given_sigmas: bool) -> ToolPointCell:
    """The scenario of :func:`tool_point_trial` from a calibration ``result``."""
    keep = ~np.isin(result.prepared.ids, result.flagged)
    a = result.prepared.a[keep]
    return ToolPointCell(
        a=a,
        b_true=geo.invert(result.camera2mount) @ geo.invert(a) @ result.target2mount,
        x=result.camera2mount,
        point=np.asarray(point_camera, dtype=float),
        sigma_rot=float(result.sigma_rot),
        sigma_trans=float(result.sigma_trans),
        given_sigmas=given_sigmas,
    )


def tool_point_trial(cell: ToolPointCell, rng: np.random.Generator) -> dict:
    """One re-calibration: camera poses re-drawn around the estimate with its noise level, the
    hand-eye fitted again, and the tool point's deviation from the estimate's (mm)."""
    b = geo.perturb(cell.b_true, cell.sigma_rot, cell.sigma_trans, rng)
    sigmas = {"sigma_rot": cell.sigma_rot, "sigma_trans": cell.sigma_trans}
    fit = calibrate_handeye(
        cell.a, b, setup="eye_in_hand", check_convention="off",
        **(sigmas if cell.given_sigmas else {}),
    )
    d = geo.apply(fit.camera2mount, cell.point) - geo.apply(cell.x, cell.point)
    return {"dx_mm": float(d[0]), "dy_mm": float(d[1]), "dz_mm": float(d[2])}


def tool_point_summary(result: HandEyeResult, point_camera, trials: pd.DataFrame | None):
    """Predicted (:meth:`HandEyeResult.point_covariance`) against simulated accuracy of a tool
    point mapped by ``X``: std along x, y, z and the RMS radius, mm; the simulated row from the
    rows of :func:`tool_point_trial` (none if ``trials`` is None or empty)."""
    cov = result.point_covariance(np.asarray(point_camera, dtype=float))
    rows = [("predicted", *np.sqrt(np.diag(cov)), np.sqrt(np.trace(cov)))]
    if trials is not None and len(trials):
        dev = trials[["dx_mm", "dy_mm", "dz_mm"]].to_numpy(float)
        sim = dev.T @ dev / len(dev)
        rows.append(("simulated", *np.sqrt(np.diag(sim)), np.sqrt(np.trace(sim))))
    return pd.DataFrame(rows, columns=["kind", "std_x_mm", "std_y_mm", "std_z_mm", "rms_mm"])


def cell_sigmas(sigma_rot_rad: float, sigma_trans_mm: float) -> dict:
    """The noise keywords of the calibration: given when ``sigma_rot_rad > 0``, else estimated
    from the residuals (an empty dict)."""
    if sigma_rot_rad > 0:
        return {"sigma_rot": sigma_rot_rad, "sigma_trans": sigma_trans_mm}
    return {}


@dataclass(frozen=True)
class CellCalibration:
    """The notebook's calibration of one cell.

    Attributes
    ----------
    poses : PoseList
        The pose list calibrated (the user's file, or the synthetic cell read back).
    source : str
        Where the poses come from, for the report.
    cell : SimulatedCell or None
        The synthetic cell, or None for a user's list.
    truth : (4, 4) array or None
        The synthetic cell's ``camera2flange`` (mm), or None.
    fits : dict
        ``{label: HandEyeResult}``: plain ML, robust ML and the robust AX = ZB fit.
    robust : HandEyeResult
        The robust ML fit, the one the report describes.
    """

    poses: PoseList
    source: str
    cell: SimulatedCell | None
    truth: np.ndarray | None
    fits: dict
    robust: HandEyeResult


def calibrate_cell(
    *,
    seed: int,
    poses_csv: str,
    setup: str,
    n_poses: int,
    n_duplicates: int,
    outlier: tuple[float, float],
    sigmas: dict,
    robust: str | None,
) -> CellCalibration:
    """The notebook's calibration, as one recipe: the pose list (the user's file, or the
    synthetic cell written to a pose list and read back), the plain and robust ML hand-eye and
    the robot-world-hand-eye fit.

    Parameters
    ----------
    seed : int
        Seed of the synthetic cell and of RANSAC.
    poses_csv : str
        The user's pose list; empty for the synthetic cell.
    setup : {"eye_in_hand", "eye_to_hand"}
    n_poses, n_duplicates : int
        Synthetic cell: views, and repeated orientations among them.
    outlier : (float, float)
        Synthetic cell: the last pose's offset, mm and deg (0, 0: none).
    sigmas : dict
        The noise keywords of :func:`cell_sigmas`.
    robust : {None, "huber", "cauchy", "ransac"}

    Returns
    -------
    CellCalibration

    Raises
    ------
    CalibrationError
        From :func:`calstudy.handeye.read_pose_list` and
        :func:`calstudy.handeye.calibrate_handeye`.
    """
    cell = None
    if poses_csv:
        poses, source, truth = read_pose_list(poses_csv), f"user pose list {poses_csv}", None
    else:
        # through the file format, as a user's list would come: the writer's rounding included
        cell = example_cell(seed, n_poses, n_duplicates, outlier)
        with tempfile.TemporaryDirectory() as tmp:
            path = write_pose_list(
                Path(tmp) / "poses.csv", cell.flange2base, cell.target2camera, rotation="matrix"
            )
            poses = read_pose_list(path)
        source, truth = "synthetic cell", cell.camera2flange
    plain = calibrate_handeye(**poses.arguments(), setup=setup, **sigmas)
    robust_fit = calibrate_handeye(
        **poses.arguments(), setup=setup, robust=robust, rng=np.random.default_rng(seed), **sigmas
    )
    rwhe = calibrate_robot_world_handeye(
        **poses.arguments(), setup=setup, robust=robust, rng=np.random.default_rng(seed), **sigmas
    )
    fits = {"ML": plain, f"ML, {robust}": robust_fit, f"AX = ZB ML, {robust}": rwhe}
    return CellCalibration(poses, source, cell, truth, fits, robust_fit)


def tool_point_experiment(
    n_trials: int,
    tool_point_mm: list,
    seed: int,
    poses_csv: str = "",
    setup: str = "eye_in_hand",
    n_poses: int = 20,
    n_duplicates: int = 3,
    outlier_mm: float = 68.0,
    outlier_deg: float = 1.8,
    sigma_rot_rad: float = 0.0,
    sigma_trans_mm: float = 0.0,
    robust: str | None = "cauchy",
) -> Experiment:
    """The Monte Carlo check of the predicted tool-point accuracy, as an engine experiment built
    from the notebook's parameters alone (it repeats the calibration to get the estimate)."""
    sigmas = cell_sigmas(sigma_rot_rad, sigma_trans_mm)
    fit = calibrate_cell(
        seed=seed,
        poses_csv=poses_csv,
        setup=setup,
        n_poses=n_poses,
        n_duplicates=n_duplicates,
        outlier=(outlier_mm, outlier_deg),
        sigmas=sigmas,
        robust=robust,
    ).robust
    cell = tool_point_cell(fit, tool_point_mm, bool(sigmas))
    return Experiment("tool_point", tool_point_trial, cell, n_trials)


def plan_table(
    result: HandEyeResult, point_camera, pose_counts=(6, 10, 15), seed: int = 0
) -> pd.DataFrame:
    """The plan of :func:`calstudy.handeye.plan.plan_poses` among the poses of a
    calibration (flagged ones left out), with its estimate as the nominal ``X``, ``Z`` and its
    noise level: per pose count, the predicted RMS error at the tool point (mm) of the planned
    poses, the median over 200 random choices of as many, and of all the poses kept."""
    keep = ~np.isin(result.prepared.ids, result.flagged)
    a = result.prepared.a[keep]
    point = np.asarray(point_camera, dtype=float)
    noise = (result.sigma_rot, result.sigma_trans, result.robot_sigma_rot)
    x, z = result.camera2mount, result.target2mount
    infos = pose_information(a, x, z, *noise)
    pj = point_jacobian(x, point)
    rng = np.random.default_rng(seed)
    rows = []
    for n in (c for c in pose_counts if c <= len(a)):
        plan = plan_poses(a, x, z, n, noise[0], noise[1], point, noise[2])
        picks = np.array([rng.choice(len(a), n, replace=False) for _ in range(200)])
        random = point_rms(infos[picks].sum(axis=1), pj)
        rows.append(
            {
                "n_poses": n,
                "planned_rms_mm": plan.predicted_rms_mm,
                "random_median_rms_mm": float(np.median(random)),
                "all_poses_rms_mm": float(point_rms(infos.sum(axis=0), pj)),
                "planned_ids": " ".join(str(i) for i in result.prepared.ids[keep][plan.chosen]),
            }
        )
    return pd.DataFrame(rows)
