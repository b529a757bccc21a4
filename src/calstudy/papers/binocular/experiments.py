"""Trials and experiments of notebook 04 (binocular paper, Section 4).

One :func:`binocular_trial` reproduces the paper's experiments (a)-(p) on one draw of everything
random (:mod:`calstudy.papers.binocular.simulate`) and returns one row per (robot error scale,
camera calibration error scale): the images are rendered once, for the default errors, and every
other scale changes only what the errors act on (the calibrated sensor that triangulates, the
flange poses the controller reports), so the sweeps share the trial's draws. The same trial also
runs the controls: oracles (the calibration views exposed again without defocus; the exact sphere
centres; Fig. 13 with the true hand-eye matrix) and nulls (each method where its error source is
absent: those views rectified, those centres modified, the update started from the true
matrix). :func:`field_trial` is the field check of Section 4.3. :func:`binocular_experiment`
and :func:`field_experiment` are the factories of :func:`calstudy.io.runs.run_experiments`.
:func:`optics_trial` and :func:`optics_experiment` run Table 2 alone over the optics the paper
does not state (F-number, focused distance, dot size, the rim: :func:`with_optics`), under
either defocus mechanism (``sensor.toml [optics] mechanism``). :func:`defocus_shift` is the
noise-free study of how defocus moves a detected centre, against depth and tilt.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import (
    Experiment,
    child_rng,
    one_blas_thread,
    one_opencv_thread,
    streams,
)
from calstudy.core.stats import rmse
from calstudy.estimators import binocular as bino
from calstudy.estimators.coc import detect_centre
from calstudy.estimators.fitting import fit_rigid
from calstudy.papers.binocular.scenario import Scenario, load_scenario, paper_table
from calstudy.papers.binocular.simulate import (
    Imaging,
    Views,
    World,
    draw_world,
    exact_points,
    expose_and_fuse,
    observe_field_region,
    rectified_centre,
    reimage,
    render_blurred_dot,
    tracker_p7_distance,
    view_calibrator,
    viewpoints,
)

#: Table 2's rows: P1P7 ... P6P7 and P8P7 (indices of the targets measured to P7).
TABLE2_ROWS = (0, 1, 2, 3, 4, 5, 7)
#: Default sweeps: robot error scales (x the robot file's tolerances) and camera calibration error
#: scales (x ``sensor.toml [calibration_uncertainty]``); 1 is the default of each.
ROBOT_SCALES = (0.0, 0.5, 1.0, 2.0)
CALIBRATION_SCALES = (0.0, 0.5, 1.0, 2.0, 3.0)


@dataclass(frozen=True)
class Setup:
    """What a trial reads: the station and the scales of the two sweeps."""

    scenario: Scenario
    robot_scales: tuple = ROBOT_SCALES
    calibration_scales: tuple = CALIBRATION_SCALES


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
        Without and with the modification, mm; ``(..., 6, 2)`` for points ``(..., 8, 3)`` (the
        check of each set of points, all modifications solved as one stack).
    """
    points8 = np.asarray(points8, dtype=float)
    p6 = points8[..., :6, :].reshape(-1, 6, 3)
    pairs = world.standard_pairs
    physical = (pairs < 6).all(axis=1)
    uses = [physical & (pairs != k).all(axis=1) for k in range(6)]
    sets = np.repeat(p6, 6, axis=0)  # (n * 6, 6, 3): every set of points once per target
    modified, _ = bino.modify_observed_errors(
        sets,
        np.array([pairs[u] for u in uses] * len(p6)),
        np.array([world.standard_mm[u] for u in uses] * len(p6)),
    )
    out = np.empty((len(p6), 6, 2))
    before = bino.distances_to_p7(bino.with_virtual(p6))  # (n, 7)
    after = bino.distances_to_p7(bino.with_virtual(modified)).reshape(len(p6), 6, 7)
    out[:, :, 0] = before[:, :6]
    out[:, :, 1] = np.diagonal(after[:, :, :6], axis1=1, axis2=2)
    return out.reshape(points8.shape[:-2] + (6, 2))


def standard_to_p7(world: World) -> np.ndarray:
    """The CMM standards of Table 2's seven distances to P7, mm."""
    pairs = world.standard_pairs
    return np.array([world.standard_mm[_pair_index(pairs, r, 6)] for r in TABLE2_ROWS])


def _modify(world: World, points8) -> np.ndarray:
    return bino.modify_observed_errors(
        points8, world.standard_pairs, world.standard_mm, combine=bino.virtual_weights()
    )[0]


def distance_figures(world: World, cal: Views, val: Views, sharp: Views, model, tol: float):
    """Tables 2-3 of one trial triangulated with the calibrated sensor ``model``.

    Returns ``(row, state)``: the row's distance figures (RMSEs and Table 2/3 errors per pair,
    mm) and what the hand-eye steps need (calibrator poses, rectified and modified points of the
    calibration views, modified P7 of the validation views).
    """
    std = standard_to_p7(world)
    raw, rect = cal.points(model, tol)
    raw8, rect8 = bino.with_virtual(raw), bino.with_virtual(rect)
    mod8 = _modify(world, rect8)
    d_raw = bino.distances_to_p7(raw8).mean(0)
    d_rect = bino.distances_to_p7(rect8).mean(0)
    d_mod = bino.distances_to_p7(mod8).mean(0)
    hold = np.mean(holdout_distances(rect8, world), axis=0)
    sharp_raw, sharp_rect = sharp.points(model, tol)
    d_sharp = bino.distances_to_p7(bino.with_virtual(sharp_raw)).mean(0)
    d_sharp_rect = bino.distances_to_p7(bino.with_virtual(sharp_rect)).mean(0)
    row = {
        "t2_without": rmse(d_raw - std),
        "t2_with": rmse(d_rect - std),
        "t2_oracle": rmse(d_sharp - std),
        "t2_null_with": rmse(d_sharp_rect - std),
        "t3_without": rmse(d_rect - std),
        "t3_with": rmse(d_mod - std),
        "t3_holdout_without": rmse(hold[:, 0] - std[:6]),
        "t3_holdout_with": rmse(hold[:, 1] - std[:6]),
    }
    names = paper_table("calibrator").standard.names
    for label, d in (("raw", d_raw), ("rect", d_rect), ("mod", d_mod)):
        row.update({f"err_{label}_{n}": float(e) for n, e in zip(names, d - std, strict=True)})
    _, vrect = val.points(model, tol)
    state = {
        "raw8": raw8,
        "rect8": rect8,
        "mod8": mod8,
        "val_p7": _modify(world, bino.with_virtual(vrect))[:, 6],
    }
    return row, state


def transformation_figures(scenario, state, flange, vflange, p7_standard: float) -> dict:
    """Tables 4 and Fig. 13 of one trial: preliminary (AX = XB, Eq. 13) and updated (Eq. 14-22)
    hand-eye matrices from the reported ``flange`` poses, their errors against the truth, and the
    RMSE of P7's distance to the base origin over the validation poses ``vflange`` with each
    matrix and with the true one (the oracle control). The calibrator poses depend on the
    points alone: they are fitted once per ``state`` and kept in it."""
    if "poses" not in state:
        state["poses"] = np.array([fit_rigid(scenario.layout[:6], r[:6]) for r in state["raw8"]])
    poses = state["poses"]
    pre = bino.preliminary_handeye(flange, poses)
    upd, _ = bino.correct_transformation(flange, pre, state["rect8"], state["mod8"])
    true = scenario.sensor2flange
    null, _ = bino.correct_transformation(flange, true, state["rect8"], state["mod8"])
    row = {}
    for label, h in (("preliminary", pre), ("updated", upd), ("true", true), ("null", null)):
        d = np.array(
            [
                np.linalg.norm(geo.apply(f @ h, p))
                for f, p in zip(vflange, state["val_p7"], strict=True)
            ]
        )
        row[f"fig13_{label}"] = rmse(d - p7_standard)
    for label, h in (("preliminary", pre), ("updated", upd)):
        row[f"rot_err_{label}_mrad"] = 1e3 * float(geo.rotation_error(h, true))
        row[f"trans_err_{label}_mm"] = float(geo.translation_error(h, true))
    return row


def exact_figures(world: World, exact8) -> dict:
    """The leave-one-target-out check on the exact points ``(n, 8, 3)`` of the calibration views
    (:func:`calstudy.papers.binocular.simulate.exact_points` with P7, P8): without the
    modification (``t3_holdout_exact``, the oracle control: the observed error removed) and with
    it (``t3_null_with``, the null control: the modification where there is nothing to
    modify), mm."""
    std = standard_to_p7(world)[:6]
    hold = np.mean(holdout_distances(exact8, world), axis=0)
    return {
        "t3_holdout_exact": rmse(hold[:, 0] - std),
        "t3_null_with": rmse(hold[:, 1] - std),
    }


def _views(scenario, world, rng, imaging, model1):
    n_cal = scenario.station.poses.n_calibration
    n_val = scenario.station.poses.n_validation
    cal_rng, val_rng = streams(rng, "calibration views", "validation views")
    cal = view_calibrator(scenario, world, n_cal, cal_rng, imaging, model1)
    val = view_calibrator(scenario, world, n_val, val_rng, imaging, model1)
    return cal, val


@one_opencv_thread()
def binocular_trial(setup: Setup, rng, defocus: bool = True) -> list[dict]:
    """One replication of the paper's experiments (a)-(p), one row per sweep scale.

    Rows: ``robot_scale`` 1 with every ``calibration_scale`` of ``setup``, and
    ``calibration_scale`` 1 with every other ``robot_scale``; the default is (1, 1). Columns:
    the RMSEs of Table 2 (``t2_without``, ``t2_with``; ``t2_oracle`` from the calibration views
    exposed again without defocus: the same true poses and sharp images, fresh image noise; the
    oracle control of the rectification; ``t2_null_with``: those views rectified, its null
    control), Table 3 (``t3_without``, ``t3_with``: the paper's protocol, scored on the very
    distances the modification is fitted to), the leave-one-target-out check
    (``t3_holdout_without``, ``t3_holdout_with``; ``t3_holdout_exact`` and ``t3_null_with``: on
    the exact sphere centres without and with the modification, its oracle and null controls,
    :func:`exact_figures`; ``t3_holdout_truecam``: triangulated with the exact cameras), Fig. 13
    (``fig13_preliminary``, ``fig13_updated``; ``fig13_true``: with the true hand-eye matrix, the
    oracle control; ``fig13_null``: the update started from the true matrix, the null control),
    the hand-eye errors and the per-pair errors of Tables 2-3 (``err_{raw,rect,mod}_<pair>``).
    ``defocus=False`` switches the defocus off everywhere (a test of the oracle's reach).
    The world, the calibration and validation views, the tracker and the sharp images draw
    from their own children of ``rng`` (:func:`calstudy.core.montecarlo.child_rng`).
    """
    scenario = setup.scenario
    imaging = Imaging(defocus=defocus)
    world = draw_world(scenario, child_rng(rng, "world"), imaging)
    model1 = world.model(scenario, 1.0)
    tol = scenario.sensor.detection.ray_tolerance_mm
    cal, val = _views(scenario, world, rng, imaging, model1)
    p7_standard = tracker_p7_distance(scenario, child_rng(rng, "tracker"), imaging)
    sharp_rng = child_rng(rng, "sharp images")
    sharp = reimage(scenario, cal, sharp_rng, Imaging(defocus=False, rectify=True), model1)
    exact = exact_figures(world, bino.with_virtual(exact_points(scenario, cal)))
    cal_scales = sorted({float(c) for c in setup.calibration_scales} | {0.0, 1.0})
    # The ray-gap tolerance guards against wrong matches; the gap of a true match grows with the
    # camera calibration error, so the guard widens with the calibration scale (values unchanged).
    figures = {
        c: distance_figures(world, cal, val, sharp, world.model(scenario, c), tol * max(1.0, c))
        for c in cal_scales
    }
    robot_scales = sorted({float(r) for r in setup.robot_scales} | {1.0})
    rows = []
    combos = [(1.0, float(c)) for c in setup.calibration_scales]
    combos += [(float(r), 1.0) for r in setup.robot_scales if float(r) != 1.0]
    if (1.0, 1.0) not in combos:
        combos.insert(0, (1.0, 1.0))
    reported = {
        r: (cal.reported(scenario, world, r), val.reported(scenario, world, r))
        for r in robot_scales
        if any(rc[0] == r for rc in combos)
    }
    for r, c in combos:
        row, state = figures[c]
        out = {"robot_scale": r, "calibration_scale": c, **row}
        out["t3_holdout_truecam"] = figures[0.0][0]["t3_holdout_without"]
        out.update(exact)
        out["redrawn_views"] = cal.redrawn + val.redrawn
        out.update(transformation_figures(scenario, state, *reported[r], p7_standard))
        rows.append(out)
    return rows


# ----------------------------------------------------------------------------------------------
# field regions (Section 4.3)


def region_distances(region, pre, upd) -> dict:
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


def _calibration_views(scenario, rng):
    """One draw of the world at the default errors and its calibration views (steps (a)-(c)):
    ``(imaging, world, model, ray tolerance, views)``, the world and the views each from its own
    stream of ``rng``."""
    imaging = Imaging()
    world_rng, cal_rng = streams(rng, "world", "calibration views")
    world = draw_world(scenario, world_rng, imaging)
    model = world.model(scenario, 1.0)
    tol = scenario.sensor.detection.ray_tolerance_mm
    n_cal = scenario.station.poses.n_calibration
    cal = view_calibrator(scenario, world, n_cal, cal_rng, imaging, model)
    return imaging, world, model, tol, cal


@one_opencv_thread()
def field_trial(setup: Setup, rng) -> dict:
    """The field check of Section 4.3 on one draw: the calibration of (a)-(n) at the default
    errors, then three regions of six SBRs from six poses each (Table 5). Columns: per region
    ``k`` (1-3) and overall, the RMSE of the five distances with the preliminary and the
    updated matrix, in the flange frame and in the base frame
    (``field{k}_{preliminary,updated}_{flange,base}``, ``field_*`` over all 15)."""
    scenario = setup.scenario
    imaging, world, model, tol, cal = _calibration_views(scenario, rng)
    raw, rect = cal.points(model, tol)
    rect8 = bino.with_virtual(rect)
    state = {"raw8": bino.with_virtual(raw), "rect8": rect8, "mod8": _modify(world, rect8)}
    poses = np.array([fit_rigid(scenario.layout[:6], r[:6]) for r in state["raw8"]])
    pre = bino.preliminary_handeye(cal.flange2base, poses)
    upd, _ = bino.correct_transformation(cal.flange2base, pre, state["rect8"], state["mod8"])
    regions = [
        region_distances(
            observe_field_region(
                scenario, world, k, child_rng(rng, f"field region {k + 1}"), imaging, model
            ),
            pre,
            upd,
        )
        for k in range(3)
    ]
    row = {}
    for label in ("preliminary", "updated"):
        for frame in ("flange", "base"):
            errs = [f[f"{label}_{frame}"] - f["standard"] for f in regions]
            for k, e in enumerate(errs):
                row[f"field{k + 1}_{label}_{frame}"] = rmse(e)
            row[f"field_{label}_{frame}"] = rmse(np.concatenate(errs))
    return row


# ----------------------------------------------------------------------------------------------
# factories of the notebook's experiments


def _scenario(
    scenario_dir: str, f_number: float | None = None, mechanism: str | None = None
) -> Scenario:
    """The station of ``scenario_dir`` (default the paper's) with ``f_number`` and the defocus
    ``mechanism`` (None: the file's) read in place of ``sensor.toml [optics] f_number`` and
    ``mechanism`` and validated as the file's."""
    overrides = {}
    if f_number is not None:
        overrides["sensor.optics.f_number"] = float(f_number)
    if mechanism is not None:
        overrides["sensor.optics.mechanism"] = str(mechanism)
    return load_scenario(scenario_dir or None, overrides or None)


def scenario_key(setup: Setup) -> str:
    """Cache fingerprint of a setup: the three tables, the robot's nominal model, tolerances and
    base/tool frames, the hand-eye and calibrator frames and the sweep scales (the robot object
    holds a pinocchio model without a stable form)."""
    sc = setup.scenario
    robot = sc.robot
    parts = [
        sc.model_dump_json(exclude={"robot"}).encode(),
        json.dumps(robot.tolerances, sort_keys=True).encode(),
        np.ascontiguousarray(robot.parameters()).tobytes(),
        np.ascontiguousarray(robot.base).tobytes(),
        np.ascontiguousarray(robot.tool).tobytes(),
        np.ascontiguousarray(sc.sensor2flange).tobytes(),
        np.ascontiguousarray(sc.calibrator2base).tobytes(),
        repr((setup.robot_scales, setup.calibration_scales)).encode(),
    ]
    return hashlib.sha256(b"|".join(parts)).hexdigest()


def binocular_experiment(
    scenario_dir: str = "",
    n_trials: int = 200,
    robot_scales=ROBOT_SCALES,
    calibration_scales=CALIBRATION_SCALES,
    f_number: float | None = None,
    mechanism: str | None = None,
    name: str = "binocular",
) -> Experiment:
    """The Monte Carlo of Tables 2-4 and Fig. 13 with both sweeps (:func:`binocular_trial`)
    under experiment ``name``; ``f_number`` and ``mechanism`` replace ``sensor.toml [optics]``'s
    (the calibrated value, the defocus mechanism)."""
    if n_trials < 1:
        raise CalibrationError(f"n_trials is {n_trials}; need at least 1")
    setup = Setup(
        _scenario(scenario_dir, f_number, mechanism),
        tuple(float(r) for r in robot_scales),
        tuple(float(c) for c in calibration_scales),
    )
    return Experiment(name, binocular_trial, setup, int(n_trials), scenario_key=scenario_key(setup))


def field_experiment(
    scenario_dir: str = "",
    n_trials: int = 30,
    f_number: float | None = None,
    mechanism: str | None = None,
) -> Experiment:
    """The Monte Carlo of Table 5 (:func:`field_trial`)."""
    setup = Setup(_scenario(scenario_dir, f_number, mechanism), (), ())
    return Experiment("field", field_trial, setup, int(n_trials), scenario_key=scenario_key(setup))


# ----------------------------------------------------------------------------------------------
# optics sweeps: F-number, focused distance, dot size (Table 2 only)

#: The optics a sweep point may change: key of the trial, table and key in the scenario files.
OPTICS_KEYS = {
    "f_number": "sensor.optics.f_number",
    "focus_distance_mm": "sensor.optics.focus_distance_mm",
    "dot_diameter_mm": "calibrator.sbr.dot_diameter_mm",
    "rim_radius_mm": "sensor.optics.rim_radius_mm",
    "rim_distance_mm": "sensor.optics.rim_distance_mm",
}
#: The keys every optics sweep point carries (the rim's only when a sweep names them).
OPTICS_DEFAULT_KEYS = ("f_number", "focus_distance_mm", "dot_diameter_mm")


def with_optics(scenario: Scenario, **values) -> Scenario:
    """A copy of ``scenario`` with some of :data:`OPTICS_KEYS` replaced (None keeps the file's
    value); the robot is shared."""
    values = {k: v for k, v in values.items() if v is not None}
    unknown = set(values) - set(OPTICS_KEYS)
    if unknown:
        raise CalibrationError(
            f"unknown optics inputs {sorted(unknown)}; known: {list(OPTICS_KEYS)}"
        )
    if not values:
        return scenario
    for key, value in values.items():
        if not (math.isfinite(float(value)) and float(value) > 0):
            raise CalibrationError(f"{key} is {value}; it must be a positive number")
    return scenario.replace({OPTICS_KEYS[key]: float(value) for key, value in values.items()})


@one_opencv_thread()
def optics_trial(
    setup: Setup,
    rng,
    f_number: float = 0.0,
    focus_distance_mm: float = 0.0,
    dot_diameter_mm: float = 0.0,
    rim_radius_mm: float = 0.0,
    rim_distance_mm: float = 0.0,
) -> dict:
    """Table 2 of one trial (steps (a)-(f)) with other optics (0: the scenario's value; the rim
    acts under the ``rim`` mechanism only): the RMSE of the seven distances to P7 without
    (``t2_without``) and with (``t2_with``) the rectification, and with the calibration views
    exposed again without defocus (``t2_oracle``), at the default errors; and the chain to
    Fig. 13 (:func:`handeye_chain`)."""
    scenario = with_optics(
        setup.scenario,
        f_number=f_number or None,
        focus_distance_mm=focus_distance_mm or None,
        dot_diameter_mm=dot_diameter_mm or None,
        rim_radius_mm=rim_radius_mm or None,
        rim_distance_mm=rim_distance_mm or None,
    )
    imaging, world, model, tol, cal = _calibration_views(scenario, rng)
    sharp_imaging = Imaging(defocus=False, rectify=True)
    sharp = reimage(scenario, cal, child_rng(rng, "sharp images"), sharp_imaging, model)
    std = standard_to_p7(world)
    raw, rect = cal.points(model, tol)
    sharp_raw, sharp_rect = sharp.points(model, tol)
    row = {}
    pairs = (("without", raw), ("with", rect), ("oracle", sharp_raw), ("null_with", sharp_rect))
    for label, pts in pairs:
        d = bino.distances_to_p7(bino.with_virtual(pts)).mean(0)
        row[f"t2_{label}"] = rmse(d - std)
    row["redrawn_views"] = cal.redrawn
    fig13_rng = child_rng(rng, "fig13 poses")
    row.update(handeye_chain(scenario, world, cal, sharp, model, tol, fig13_rng))
    return row


def handeye_chain(scenario, world: World, cal: Views, sharp: Views, model, tol: float, rng):
    """How the error of the calibration views reaches the preliminary hand-eye matrix and
    Fig. 13, step by step, on one trial.

    Columns: the detected minus the true image of each dot centre (``shift_px_rms``,
    ``shift_px_max``, both cameras, unrectified), the dots' depths in the cameras
    (``depth_min_mm``, ``depth_max_mm``), the RMS error of the unrectified triangulated points
    along the plate normal and across the plate (``point_err_normal_mm``,
    ``point_err_inplane_mm``), the RMS rotation error of the calibrator poses fitted to them
    (``pose_rot_err_mrad``), the median rotation of the moves between the calibration poses
    (``move_deg``), the error of the preliminary AX = XB matrix (``trans_err_preliminary_mm``,
    ``rot_err_preliminary_mrad``; ``*_sharp``: from the same views exposed without defocus) and
    the Fig. 13 RMSE it gives over ``n_validation`` new poses drawn after everything else
    (``fig13_exact_p7_{preliminary,sharp,true}``: P7 taken exact in the sensor frame and
    against its exact distance to the base origin, so that only the matrix and the robot act).
    """
    dots = geo.apply(scenario.calibrator2base, scenario.layout[:6] + world.dot_offsets)
    normal = scenario.calibrator2base[:3, 2]
    shifts, depths, e_normal, e_plane = [], [], [], []
    raw, _ = cal.points(model, tol)
    sharp_raw, _ = sharp.points(model, tol)
    for s2b, obs, pts in zip(cal.sensor2base, cal.observations, raw, strict=True):
        base2sensor = geo.invert(s2b)
        truth = geo.apply(base2sensor, dots)
        for c, (camera, s2c) in enumerate(scenario.rig.cameras()):
            in_cam = geo.apply(s2c, truth)
            depths.append(in_cam[:, 2])
            shifts.append(np.linalg.norm(obs.uv_raw[c] - camera.project(in_cam), axis=1))
        err = pts - truth
        n_s = base2sensor[:3, :3] @ normal
        along = err @ n_s
        e_normal.append(along)
        e_plane.append(np.linalg.norm(err - np.outer(along, n_s), axis=1))
    shifts, depths = np.concatenate(shifts), np.concatenate(depths)
    true_poses = [geo.invert(s) @ scenario.calibrator2base for s in cal.sensor2base]
    poses = {
        label: np.array([fit_rigid(scenario.layout[:6], p) for p in pts])
        for label, pts in (("preliminary", raw), ("sharp", sharp_raw))
    }
    pose_err = [
        geo.rotation_error(p, t) for p, t in zip(poses["preliminary"], true_poses, strict=True)
    ]
    _, angles = bino.motion_axes(cal.flange2base)
    row = {
        "shift_px_rms": float(np.sqrt(np.mean(shifts**2))),
        "shift_px_max": float(shifts.max()),
        "depth_min_mm": float(depths.min()),
        "depth_max_mm": float(depths.max()),
        "point_err_normal_mm": rmse(np.concatenate(e_normal)),
        "point_err_inplane_mm": rmse(np.concatenate(e_plane)),
        "pose_rot_err_mrad": 1e3 * rmse(np.array(pose_err)),
        "move_deg": float(np.degrees(np.median(angles))),
    }
    true = scenario.sensor2flange
    matrices = {k: bino.preliminary_handeye(cal.flange2base, v) for k, v in poses.items()}
    for label, h in matrices.items():
        row[f"trans_err_{label}_mm"] = float(geo.translation_error(h, true))
        row[f"rot_err_{label}_mrad"] = 1e3 * float(geo.rotation_error(h, true))
    n_val = scenario.station.poses.n_validation
    q, vflange = viewpoints(scenario, scenario.calibrator2base, n_val, rng)
    true_robot = world.robot(scenario, 1.0)
    p7_base = geo.apply(scenario.calibrator2base, scenario.layout[6])
    p7_sensor = np.array([geo.apply(geo.invert(true_robot.fk(qi) @ true), p7_base) for qi in q])
    for label, h in (*matrices.items(), ("true", true)):
        d = np.array(
            [np.linalg.norm(geo.apply(f @ h, p)) for f, p in zip(vflange, p7_sensor, strict=True)]
        )
        row[f"fig13_exact_p7_{label}"] = rmse(d - float(np.linalg.norm(p7_base)))
    return row


def optics_experiment(
    name: str,
    scenario_dir: str = "",
    n_trials: int = 30,
    points=(),
    f_number: float | None = None,
    mechanism: str | None = None,
) -> Experiment:
    """Table 2 at each point of an optics sweep (:func:`optics_trial`): ``points`` are mappings
    of some of :data:`OPTICS_KEYS` (missing: the scenario's value, with ``f_number`` and the
    defocus ``mechanism`` if given)."""
    if n_trials < 1 or not points:
        raise CalibrationError(f"an optics sweep needs points and n_trials >= 1 ({n_trials})")
    unknown = sorted({k for p in points for k in p} - set(OPTICS_KEYS))
    if unknown:
        raise CalibrationError(f"unknown optics inputs {unknown}; known: {list(OPTICS_KEYS)}")
    setup = Setup(_scenario(scenario_dir, f_number, mechanism), (), ())
    keys = [k for k in OPTICS_KEYS if any(k in p for p in points) or k in OPTICS_DEFAULT_KEYS]
    full = [{k: float(p.get(k, 0.0)) for k in keys} for p in points]
    return Experiment(
        name, optics_trial, setup, int(n_trials), points=full, scenario_key=scenario_key(setup)
    )


# ----------------------------------------------------------------------------------------------
# defocus shift of a detected centre


@one_opencv_thread()
@one_blas_thread()
def defocus_shift(
    scenario: Scenario, depths_mm, tilts_deg=(0.0, 20.0, 40.0), field_deg: float = 15.0
) -> pd.DataFrame:
    """How defocus moves the detected centre of one dot, noise-free, without and with rectification.

    A dot ``field_deg`` off the left camera's axis (towards the image corner), tilted by each of
    ``tilts_deg`` about the image's x axis, is rendered at each depth with its blur spot (the CoC
    radius of Eq. 4 and the lens rim's cut, :func:`calstudy.papers.binocular.simulate.
    blur_spots`), exposed twice without noise (saturation and 8-bit quantisation kept) and fused
    (Eq. 3); its centre is detected without and with the rectification, and on the blurred
    float image itself (``float_shift_px``: no exposure, saturation or quantisation). The shift
    is the detected minus the true image of the dot centre, px: its size, and its component
    along the field direction (``radial``, > 0 away from the image centre). The blur spot is the
    scenario's mechanism (``mechanism`` column). The row at the focused
    distance gives the in-focus shift (perspective and pixel sampling alone).

    It runs outside the Monte Carlo engine, so it takes the engine's one BLAS and one OpenCV
    thread itself: one noise-free dot is one draw of the 8-bit quantisation, and a last-bit
    change of the rendered image (BLAS splitting its sums over two threads) can turn a grey
    level of an exposure and, through the fusion weights, move the detected centre by a tenth
    of a pixel.
    """
    camera = scenario.rig.left
    rng = np.random.default_rng(0)  # unused: no noise
    direction = np.array([0.8, 0.6])
    field = math.tan(math.radians(field_deg)) * direction
    rows = []
    for tilt in tilts_deg:
        t = math.radians(float(tilt))
        normal = np.array([0.0, math.sin(t), -math.cos(t)])
        for z in depths_mm:
            centre = float(z) * np.array([field[0], field[1], 1.0])
            uv, origin, blurred = render_blurred_dot(scenario, camera, centre, normal)
            delta = float(scenario.coc_radius_px(z))
            fused = expose_and_fuse(scenario, blurred, rng, 0.0, math.inf)
            raw = detect_centre(fused, origin, **scenario.detection) - uv
            exact = detect_centre(blurred, origin, **scenario.detection) - uv
            rect = rectified_centre(scenario, fused, origin, delta) - uv
            rows.append(
                {
                    "mechanism": scenario.sensor.optics.mechanism,
                    "tilt_deg": float(tilt),
                    "depth_mm": float(z),
                    "coc_radius_px": delta,
                    "shift_px": float(np.hypot(*raw)),
                    "radial_shift_px": float(raw @ direction),
                    "float_shift_px": float(np.hypot(*exact)),
                    "rectified_shift_px": float(np.hypot(*rect)),
                    "rectified_radial_shift_px": float(rect @ direction),
                }
            )
    return pd.DataFrame(rows)
