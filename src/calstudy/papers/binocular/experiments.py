"""Trials, Monte Carlo loops and sweeps of notebook 04 (binocular paper, Section 4).

One :func:`run_trial` reproduces the paper's experiments (a)-(p) and the field check of
Section 4.3 on one draw of everything random (:mod:`calstudy.papers.binocular.simulate`);
:func:`monte_carlo` repeats it, :func:`trial_metrics` reduces each trial to its RMSEs, and the
sweeps scale the robot's and the cameras' errors. :func:`defocus_shift` is the noise-free study
of how defocus moves a detected centre.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from calstudy.claims import verdict_vs_published
from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.stats import median_and_spread, rmse
from calstudy.estimators import binocular as bino
from calstudy.estimators.coc import detect_centre
from calstudy.papers.binocular.scenario import Scenario, published
from calstudy.papers.binocular.simulate import (
    FieldRegion,
    Imaging,
    World,
    draw_world,
    expose_and_fuse,
    observe_field_region,
    rectified_centre,
    render_blurred_dot,
    tracker_p7_distance,
    view_calibrator,
)

#: Table 2's rows: P1P7 ... P6P7 and P8P7 (indices of the targets measured to P7).
TABLE2_ROWS = (0, 1, 2, 3, 4, 5, 7)


# ----------------------------------------------------------------------------------------------
# one trial


def _pair_index(pairs: np.ndarray, a: int, b: int) -> int:
    lo, hi = min(a, b), max(a, b)
    return int(np.flatnonzero((pairs[:, 0] == lo) & (pairs[:, 1] == hi))[0])


def holdout_distances(points8, world: World) -> np.ndarray:
    """Distances P1P7 ... P6P7 without and with a modification that never saw the evaluated target.

    For target ``k``, Eq. 25 uses only the standard distances among the other five physical
    targets (10 distances); ``Pk`` keeps its measured coordinates (its columns are zero, so the
    least-norm solution leaves it alone) and P7 is the centroid of the modified P2, P3, P5. The
    evaluated distance is thus not one of the constraints: a check that is not circular.

    Returns
    -------
    (6, 2) array
        Without and with the modification, mm.
    """
    p6 = np.asarray(points8, dtype=float)[:6]
    pairs = world.standard_pairs
    physical = (pairs < 6).all(axis=1)
    out = np.empty((6, 2))
    for k in range(6):
        use = physical & (pairs != k).all(axis=1)
        modified, _ = bino.modify_observed_error(p6, pairs[use], world.standard_mm[use])
        out[k, 0] = bino.distances_to_p7(bino.with_virtual(p6))[k]
        out[k, 1] = bino.distances_to_p7(bino.with_virtual(modified))[k]
    return out


def _calibrate(scenario: Scenario, world: World, rng, imaging: Imaging) -> dict:
    """Steps (a)-(n): calibration views, Tables 2 and 3, preliminary and updated hand-eye."""
    n_cal = scenario.config["station"]["poses"]["n_calibration"]
    flange, obs = view_calibrator(scenario, world, n_cal, rng, imaging)
    raw8 = bino.with_virtual(np.array([o.raw for o in obs]))
    rect8 = bino.with_virtual(np.array([o.rect for o in obs]))
    mod8 = np.array(
        [bino.modify_observed_error(p, world.standard_pairs, world.standard_mm)[0] for p in rect8]
    )
    pairs = world.standard_pairs
    standard = np.array([world.standard_mm[_pair_index(pairs, r, 6)] for r in TABLE2_ROWS])
    table2 = np.column_stack(
        [bino.distances_to_p7(raw8).mean(0), bino.distances_to_p7(rect8).mean(0)]
    )
    table3 = np.column_stack([table2[:, 1], bino.distances_to_p7(mod8).mean(0)])
    holdout = np.mean([holdout_distances(p, world) for p in rect8], axis=0)
    poses = np.array([bino.calibrator_pose(scenario.layout[:6], r[:6]) for r in raw8])
    pre = bino.preliminary_handeye(flange, poses)
    upd, d_eta = bino.correct_transformation(flange, pre, rect8, mod8)
    return {
        "standard": standard,
        "table2": table2,
        "table3": table3,
        "table3_holdout": holdout,
        "handeye": {
            "true": scenario.sensor2flange,
            "preliminary": pre,
            "updated": upd,
            "d_eta": d_eta,
        },
    }


def _validate(scenario: Scenario, world: World, pre, upd, rng, imaging: Imaging) -> dict:
    """Fig. 13: ten more poses, P7 (rectified, modified) to the base origin with both matrices."""
    n_val = scenario.config["station"]["poses"]["n_validation"]
    vflange, vobs = view_calibrator(scenario, world, n_val, rng, imaging)
    vmod = np.array(
        [
            bino.modify_observed_error(
                bino.with_virtual(o.rect), world.standard_pairs, world.standard_mm
            )[0]
            for o in vobs
        ]
    )
    p7_standard = tracker_p7_distance(scenario, rng, imaging)
    fig13 = (
        np.column_stack(
            [
                np.linalg.norm(geo.apply(vflange[i] @ h, vmod[i, 6]), axis=-1)
                for h in (pre, upd)
                for i in range(n_val)
            ]
        )
        .reshape(2, n_val)
        .T
    )
    return {"fig13": fig13, "fig13_standard": p7_standard}


def region_distances(region: FieldRegion, pre, upd) -> dict:
    """Table 5 of one region: the distances from the first five SBRs to the sixth, averaged over
    the poses, with each hand-eye matrix, in the flange frame (``*_flange``) and in the base
    frame through the reported flange poses (``*_base``)."""
    pts, flange = region.points, region.flange2base
    out = {"region": region.region, "names": region.names, "standard": region.standard}
    for label, h in (("preliminary", pre), ("updated", upd)):
        in_flange = np.einsum("ij,pmj->pmi", h[:3, :3], pts) + h[:3, 3]
        d_flange = np.linalg.norm(in_flange[:, :5] - in_flange[:, 5:6], axis=-1).mean(0)
        in_base = np.einsum("pij,pmj->pmi", flange[:, :3, :3], in_flange) + flange[:, None, :3, 3]
        mean_base = in_base.mean(0)
        d_base = np.linalg.norm(mean_base[:5] - mean_base[5], axis=1)
        out[f"{label}_flange"] = d_flange
        out[f"{label}_base"] = d_base
    return out


def run_trial(
    scenario: Scenario,
    rng,
    robot_scale: float = 1.0,
    imaging: Imaging | None = None,
    field: bool = True,
    calibration_scale: float = 1.0,
) -> dict:
    """One replication of the paper's experiments (a)-(p) and the field check (Section 4.3).

    ``robot_scale`` and ``calibration_scale`` multiply the robot's and the cameras' errors
    (:func:`~calstudy.papers.binocular.simulate.draw_world`); ``field=False`` skips the field
    check, which is drawn last.

    Returns
    -------
    dict
        ``table2`` (7, 2): the 7 distances to P7 averaged over the 6 poses, without and with
        rectification; ``table3`` (7, 2): with rectification, without and with the observed-error
        modification; ``table3_holdout`` (6, 2): :func:`holdout_distances` averaged over the
        poses; ``standard`` (7,): the CMM standard distances; ``handeye`` dict of the true,
        preliminary and updated ``sensor2flange`` and ``d_eta``; ``fig13`` (10, 2): distances P7
        to the base origin with the preliminary and updated matrix and ``fig13_standard``;
        ``field`` list of per-region dicts (:func:`region_distances`).
    """
    imaging = imaging or Imaging()
    world = draw_world(scenario, rng, robot_scale, imaging, calibration_scale)
    out = _calibrate(scenario, world, rng, imaging)
    pre, upd = out["handeye"]["preliminary"], out["handeye"]["updated"]
    out.update(_validate(scenario, world, pre, upd, rng, imaging))
    out["field"] = (
        [
            region_distances(observe_field_region(scenario, world, k, rng, imaging), pre, upd)
            for k in range(3)
        ]
        if field
        else []
    )
    return out


# ----------------------------------------------------------------------------------------------
# Monte Carlo


def monte_carlo(
    scenario: Scenario,
    seed: int,
    n_trials: int,
    robot_scale: float = 1.0,
    stream: int = 0,
    progress: bool = False,
    field: bool = True,
    calibration_scale: float = 1.0,
) -> list[dict]:
    """``n_trials`` replications (:func:`run_trial`), seeded by ``(seed, stream, k)``."""
    if n_trials < 1:
        raise CalibrationError(f"n_trials is {n_trials}; need at least 1")
    out = []
    for k in range(n_trials):
        rng = np.random.default_rng(np.random.SeedSequence([seed, stream, k]))
        out.append(
            run_trial(scenario, rng, robot_scale, field=field, calibration_scale=calibration_scale)
        )
        if progress:
            print(f"trial {k + 1}/{n_trials}", end="\r" if k + 1 < n_trials else "\n", flush=True)
    return out


def _trial_row(k: int, t: dict) -> dict:
    """The RMSEs of one trial (:func:`trial_metrics`)."""
    std = t["standard"]
    hand = t["handeye"]
    row = {
        "trial": k,
        "t2_without": rmse(t["table2"][:, 0] - std),
        "t2_with": rmse(t["table2"][:, 1] - std),
        "t3_without": rmse(t["table3"][:, 0] - std),
        "t3_with": rmse(t["table3"][:, 1] - std),
        "t3_holdout_without": rmse(t["table3_holdout"][:, 0] - std[:6]),
        "t3_holdout_with": rmse(t["table3_holdout"][:, 1] - std[:6]),
        "fig13_preliminary": rmse(t["fig13"][:, 0] - t["fig13_standard"]),
        "fig13_updated": rmse(t["fig13"][:, 1] - t["fig13_standard"]),
    }
    for label in ("preliminary", "updated"):
        row[f"rot_err_{label}_mrad"] = 1e3 * float(geo.rotation_error(hand[label], hand["true"]))
        row[f"trans_err_{label}_mm"] = float(geo.translation_error(hand[label], hand["true"]))
    if t["field"]:
        for label in ("preliminary", "updated"):
            for frame in ("flange", "base"):
                err = np.concatenate([f[f"{label}_{frame}"] - f["standard"] for f in t["field"]])
                row[f"field_{label}_{frame}"] = rmse(err)
    return row


def trial_metrics(trials: list[dict]) -> pd.DataFrame:
    """One row per trial: the RMSEs of Tables 2, 3, 5, Fig. 13 and the hand-eye errors."""
    return pd.DataFrame([_trial_row(k, t) for k, t in enumerate(trials)])


# ----------------------------------------------------------------------------------------------
# sweeps


def robot_sweep(scenario: Scenario, seed: int, scales, n_trials: int, progress: bool = False):
    """Median Fig. 13 RMSE and hand-eye errors for each robot error scale (field check skipped)."""
    rows = []
    for j, scale in enumerate(scales):
        m = trial_metrics(
            monte_carlo(
                scenario, seed, n_trials, scale, stream=100 + j, progress=progress, field=False
            )
        )
        med = m.drop(columns="trial").median()
        rows.append({"robot_scale": float(scale), "n_trials": n_trials, **med.to_dict()})
    return pd.DataFrame(rows)


def _calibration_row(metrics: pd.DataFrame, scale: float, n_trials: int) -> dict:
    """One row of :func:`calibration_sweep` from the trial metrics at one scale."""
    row = {"calibration_scale": float(scale), "n_trials": n_trials}
    row.update(metrics.drop(columns="trial").median().to_dict())
    for key in ("t2", "t3", "t3_holdout"):
        ratio = metrics[f"{key}_with"] / metrics[f"{key}_without"]
        median, lo, hi = median_and_spread(ratio)
        row.update({f"{key}_ratio": median, f"{key}_ratio_low": lo, f"{key}_ratio_high": hi})
    claims = {
        "coc": ("t2", published("calibrator", "table2_rmse")),
        "observed_error": ("t3", published("calibrator", "table3_rmse")),
    }
    for claim, (key, pub) in claims.items():
        v = verdict_vs_published(
            pub[1] / pub[0],
            metrics[f"{key}_with"].to_numpy(),
            metrics[f"{key}_without"].to_numpy(),
            kind="ratio",
            direction="lower",
        )
        row[f"verdict_{claim}"] = v.verdict
    return row


def calibration_sweep(
    scenario: Scenario, seed: int, scales, n_trials: int, progress: bool = False
) -> pd.DataFrame:
    """Tables 2 and 3 and their verdicts for each scale of the cameras' calibration errors.

    Every scale runs the same ``n_trials`` replications (random stream 200, field check
    skipped): the trials share their robot, dot offsets, CMM errors, calibration poses and the
    direction of the camera errors, whose size alone changes (image noise is drawn anew where a
    region of interest changes size). Scale 0 is a sensor that matches Table 1 exactly.

    Returns
    -------
    DataFrame
        One row per scale: ``calibration_scale``, ``n_trials``, the median of every column of
        :func:`trial_metrics`; for Table 2 (``t2``), Table 3 (``t3``) and the hold-out check
        (``t3_holdout``) the median RMSE ratio with / without and its 95 % interval over the
        trials (``*_ratio``, ``*_ratio_low``, ``*_ratio_high``); the verdicts of
        ``binocular.coc`` and ``binocular.observed_error`` (``verdict_coc``,
        ``verdict_observed_error``) by the rule of
        :func:`calstudy.papers.binocular.report.claim_rows`.

    Raises
    ------
    CalibrationError
        If ``n_trials`` is below 2 (a verdict needs an interval) or a scale is negative.
    """
    if n_trials < 2:
        raise CalibrationError(f"n_trials is {n_trials}; a verdict per scale needs at least 2")
    rows = []
    for scale in scales:
        trials = monte_carlo(
            scenario,
            seed,
            n_trials,
            stream=200,
            progress=progress,
            field=False,
            calibration_scale=float(scale),
        )
        rows.append(_calibration_row(trial_metrics(trials), scale, n_trials))
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# defocus shift of a detected centre


def defocus_shift(scenario: Scenario, depths_mm, tilt_deg: float = 20.0) -> pd.DataFrame:
    """How defocus moves the detected centre of one dot, noise-free, without and with rectification.

    A dot 10 deg off the left camera's axis (tilted ``tilt_deg`` about x) is rendered at each
    depth with the CoC radius of Eq. 4; its centre is detected in the blurred image itself
    (``blur_only``) and after two noise-free exposures (saturation and 8-bit quantisation kept)
    fused by Eq. 3 (``fused``), each without and with rectification. The shift is the detected
    minus the true image of the dot centre, px.
    """
    camera = scenario.sensor.left
    t = math.radians(tilt_deg)
    normal = np.array([0.0, math.sin(t), -math.cos(t)])
    rng = np.random.default_rng(0)  # unused: no noise
    rows = []
    for z in depths_mm:
        centre = float(z) * np.array([0.15, 0.1, 1.0])  # off-axis: vignetting and distortion act
        delta = float(scenario.coc_radius_px(z))
        uv, origin, blurred = render_blurred_dot(scenario, camera, centre, normal, delta)
        fused = expose_and_fuse(scenario, blurred, rng, 0.0, math.inf)
        row = {"depth_mm": float(z), "coc_radius_px": delta}
        for label, img in (("blur_only", blurred), ("fused", fused)):
            raw = detect_centre(img, origin, **scenario.detection) - uv
            rect = rectified_centre(scenario, img, origin, delta) - uv
            row[f"{label}_shift_u_px"] = raw[0]
            row[f"{label}_shift_v_px"] = raw[1]
            row[f"{label}_shift_px"] = float(np.hypot(*raw))
            row[f"{label}_rectified_shift_px"] = float(np.hypot(*rect))
        rows.append(row)
    return pd.DataFrame(rows)
