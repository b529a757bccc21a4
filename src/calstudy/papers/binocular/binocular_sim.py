"""The simulated eye-in-hand binocular station of notebook 04 (binocular paper, Section 4).

A KUKA KR 210 (nominal model from ``data/robots/kuka_kr210.toml``; the simulated world moves a
"true" robot that differs by the file's tolerances) carries the binocular sensor of Table 1 and
observes the multi-target calibrator (Table 2) from about 850 mm. Each dot is rendered in a
region of interest (ROI) of both cameras: exact perspective and distortion, circle of confusion
(Eq. 4, 7), two exposures fused (Eq. 3), sensor noise. One :func:`run_trial` reproduces the
paper's experiments (a)-(p) and the field check of Section 4.3 on one draw of everything random.

Assumptions are in ``data/binocular/*.toml`` with their reasons; the functions here only read them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.stats import rmse
from calstudy.estimators import binocular as bino
from calstudy.models import optics as coc
from calstudy.models.kinematics import Robot, load_robot, perturb_robot

#: Viewpoints drawn per requested pose before :func:`viewpoints` gives up (unreachable target).
MAX_VIEW_TRIES = 20


@dataclass
class Scenario:
    """Everything fixed of the station: sensor (Table 1), calibrator, robot, configuration."""

    sensor: bino.StereoSensor
    layout: np.ndarray  # (8, 3) calibrator frame, P1-P8
    layout_residual: np.ndarray
    robot: Robot
    sensor2flange: np.ndarray
    calibrator2base: np.ndarray
    config: dict = field(repr=False)

    @property
    def focal_mm(self) -> float:
        return float(self.sensor.k_left[0, 0] * self.config["sensor"]["image"]["pixel_pitch_mm"])


def _plate_frame(centre, normal) -> np.ndarray:
    """Frame with origin ``centre`` and z along ``normal`` (x horizontal)."""
    z = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    return geo.make_transform(np.column_stack([x, np.cross(z, x), z]), centre)


def load_scenario(directory=None) -> Scenario:
    """The station of ``data/binocular/*.toml`` and the robot ``data/robots/<model>.toml``
    named in ``station.toml [robot]`` (the KR 210 by default).

    ``directory`` holds your own ``sensor.toml``, ``calibrator.toml`` and ``station.toml`` (same
    keys as those of ``data/binocular``) in their place.
    """
    sensor_t, cal_t, station_t = (
        bino.load_toml(n, directory) for n in ("sensor", "calibrator", "station")
    )
    layout, residual = bino.solve_calibrator_layout(
        cal_t["standard"]["distance_mm"], cal_t["standard"]["start_angle_deg"]
    )
    h = np.array(station_t["handeye"]["matrix"], dtype=float)
    h[:3, :3] = geo.project_to_so3(h[:3, :3])
    c = station_t["calibrator"]
    height = c["p7_height_mm"]
    p7 = np.array([math.sqrt(c["p7_distance_mm"] ** 2 - height**2), 0.0, height])
    tilt = math.radians(c["plate_tilt_deg"])
    normal = np.array([-math.cos(tilt), 0.0, math.sin(tilt)])
    return Scenario(
        sensor=bino.StereoSensor.from_table(sensor_t),
        layout=layout,
        layout_residual=residual,
        robot=load_robot(station_t["robot"]["model"]),
        sensor2flange=h,
        calibrator2base=_plate_frame(p7, normal),
        config={"sensor": sensor_t, "calibrator": cal_t, "station": station_t},
    )


# ----------------------------------------------------------------------------------------------
# poses


def _ik_any(robot: Robot, flange2base: np.ndarray) -> np.ndarray:
    """IK from a few start configurations facing the target; the first that converges."""
    yaw = math.atan2(flange2base[1, 3], flange2base[0, 3])
    for a5 in (60.0, -60.0, 20.0, -20.0):
        for a4 in (0.0, 90.0, -90.0, 180.0):
            for a6 in (0.0, 90.0, -90.0, 180.0):
                q0 = np.array([yaw, math.radians(-50), math.radians(40), 0, 0, 0])
                q0[3:] = np.radians([a4, a5, a6])
                try:
                    return robot.ik(flange2base, q0, tol=1e-9)
                except CalibrationError:  # unreachable or singular from this start
                    continue
    raise CalibrationError("no IK solution found for a viewpoint; the view is out of reach")


def viewpoints(scenario: Scenario, target2base, n: int, rng: np.random.Generator):
    """``n`` sensor poses viewing a target frame (origin at its centre, z towards the robot).

    Directions within ``cone_deg`` of the target normal, roll within ``+-roll_deg``, distance
    within ``+-distance_spread_mm`` of the observation distance (``station.toml [poses]``).

    Returns
    -------
    q : (n, 6) array
        Joint angles (computed with the nominal model, as the controller does).
    flange2base : (n, 4, 4) array
        Flange poses the controller reports (nominal model).

    Raises
    ------
    CalibrationError
        If fewer than ``n`` of ``MAX_VIEW_TRIES * n`` drawn viewpoints are reachable.
    """
    cfg = scenario.config["station"]["poses"]
    t = np.asarray(target2base, dtype=float)
    qs, flanges = [], []
    for _ in range(MAX_VIEW_TRIES * n):
        if len(qs) == n:
            break
        cone = math.radians(cfg["cone_deg"]) * math.sqrt(rng.uniform())
        phi = rng.uniform(0, 2 * math.pi)
        roll = math.radians(rng.uniform(-cfg["roll_deg"], cfg["roll_deg"]))
        dist = cfg["observation_distance_mm"] + rng.uniform(-1, 1) * cfg["distance_spread_mm"]
        local = np.array(
            [math.sin(cone) * math.cos(phi), math.sin(cone) * math.sin(phi), math.cos(cone)]
        )
        view = t[:3, :3] @ local  # from the target towards the sensor
        aim = scenario.sensor.aim_point(dist)
        look = geo.look_at(np.zeros(3), -view)[:3, :3]  # camera z along -view
        ref = geo.look_at(np.zeros(3), aim)[:3, :3]  # sensor frame: z along aim
        rot = look @ geo.rotvec_to_matrix(np.array([0.0, 0.0, roll])) @ ref.T
        sensor2base = geo.make_transform(rot, t[:3, 3] - rot @ aim)
        flange = sensor2base @ geo.invert(scenario.sensor2flange)
        try:
            q = _ik_any(scenario.robot, flange)
        except CalibrationError:
            continue
        qs.append(q)
        flanges.append(scenario.robot.fk(q))
    if len(qs) < n:
        raise CalibrationError(
            f"only {len(qs)} of {n} viewpoints are within the robot's reach after "
            f"{MAX_VIEW_TRIES * n} draws; move the target closer or narrow cone_deg"
        )
    return np.array(qs), np.array(flanges)


# ----------------------------------------------------------------------------------------------
# imaging


def _project(k, dist, point) -> np.ndarray:
    uv, _ = cv2.projectPoints(
        np.asarray(point, dtype=float).reshape(1, 3), np.zeros(3), np.zeros(3), k, dist
    )
    return uv.reshape(2)


@dataclass
class Imaging:
    """Switches of the imaging model: ``noise`` (image noise, camera-calibration errors, SBR dot
    offsets, CMM and tracker errors, robot repeatability) and ``defocus`` (Eq. 4, 7); both on in
    the notebook, off in the noise-free tests."""

    noise: bool = True
    defocus: bool = True

    @staticmethod
    def dot_radius(scenario: Scenario) -> float:
        return 0.5 * scenario.config["calibrator"]["sbr"]["dot_diameter_mm"]


def image_dot(scenario, camera, centre_cam, normal_cam, rng, imaging: Imaging):
    """Fused ROI of one dot in one camera: render, defocus (Eq. 4, 7), two exposures, fuse (Eq. 3).

    Returns ``(fused, origin, delta_px)``: the ROI, its top-left pixel, the true CoC radius.
    """
    k, dist, _ = camera
    cfg = scenario.config["sensor"]
    optics, exp, noise = cfg["optics"], cfg["exposure"], cfg["noise"]
    radius = Imaging.dot_radius(scenario)
    delta = 0.0
    if imaging.defocus:
        delta = float(
            coc.coc_radius_px(
                centre_cam[2],
                optics["focus_distance_mm"],
                scenario.focal_mm,
                optics["f_number"],
                cfg["image"]["pixel_pitch_mm"],
            )
        )
    uv = _project(k, dist, centre_cam)
    r_px = radius * k[0, 0] / centre_cam[2]
    origin, shape = coc.roi_around(
        uv, r_px, 4.0 * delta + 10.0, scenario.sensor.width, scenario.sensor.height
    )
    sharp = coc.render_dot(k, dist, centre_cam, normal_cam, radius, origin, shape)
    blurred = coc.defocus(sharp, delta)
    if not imaging.noise:
        return blurred, origin, delta
    shots = [
        coc.expose(
            blurred,
            t,
            exp["dot_peak_at_100ms"],
            exp["background_at_100ms"],
            noise["read_noise_dn"],
            noise["electrons_per_dn"],
            rng,
            exp["bits"],
        )
        for t in exp["times_ms"]
    ]
    fused = coc.fuse_exposures(
        shots, exp["weight_contrast"], exp["weight_exposure"], exp["well_exposed_sigma"]
    )
    return fused, origin, delta


@dataclass
class Observation:
    """Dot centres of one pose: image points and triangulated sensor-frame points."""

    uv_raw: np.ndarray  # (2, m, 2) left/right
    uv_rect: np.ndarray
    raw: np.ndarray  # (m, 3) sensor frame, without rectification
    rect: np.ndarray  # (m, 3) with rectification


def observe(scenario, true_sensor, sensor2base, dots_base, normal_base, rng, imaging: Imaging):
    """Image the dots ``(m, 3)`` (base frame, one plate normal) from a true sensor pose.

    The physical cameras are ``true_sensor``; centres are triangulated with the calibrated
    ``scenario.sensor`` (Table 1). The rectification uses the CoC radius (Eq. 4) at the depth
    of the unrectified triangulation, as a real system would.
    """
    cfg = scenario.config["sensor"]
    det, optics = cfg["detection"], cfg["optics"]
    base2sensor = geo.invert(sensor2base)
    dots_s = geo.apply(base2sensor, dots_base)
    normal_s = base2sensor[:3, :3] @ normal_base
    rois = []
    for camera in true_sensor.cameras():
        s2c = camera[2]
        row = []
        for p in dots_s:
            row.append(
                image_dot(scenario, camera, geo.apply(s2c, p), s2c[:3, :3] @ normal_s, rng, imaging)
            )
        rois.append(row)
    kwargs = {
        "low": det["canny_low"],
        "high": det["canny_high"],
        "min_points": det["min_edge_points"],
    }
    uv_raw = np.array([[coc.detect_centre(img, o, **kwargs) for img, o, _ in row] for row in rois])
    tol = det["ray_tolerance_mm"]
    raw = scenario.sensor.triangulate(uv_raw[0], uv_raw[1], tol)
    if not imaging.defocus:
        return Observation(uv_raw, uv_raw.copy(), raw, raw.copy())
    uv_rect = np.empty_like(uv_raw)
    for c, (_, _, s2c) in enumerate(scenario.sensor.cameras()):
        depth = geo.apply(s2c, raw)[:, 2]
        est = coc.coc_radius_px(
            depth,
            optics["focus_distance_mm"],
            scenario.focal_mm,
            optics["f_number"],
            cfg["image"]["pixel_pitch_mm"],
        )
        for i, (img, o, _) in enumerate(rois[c]):
            fixed = coc.rectify_coc(img, float(est[i])) if est[i] >= 1.0 / 3.0 else img
            uv_rect[c, i] = coc.detect_centre(fixed, o, **kwargs)
    rect = scenario.sensor.triangulate(uv_rect[0], uv_rect[1], tol)
    return Observation(uv_raw, uv_rect, raw, rect)


# ----------------------------------------------------------------------------------------------
# one trial


def _uniform_disc(rng, n: int, radius: float) -> np.ndarray:
    r = radius * np.sqrt(rng.uniform(size=n))
    a = rng.uniform(0, 2 * math.pi, n)
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(n)])


def _sigma_distance_mm(table: dict, length_mm) -> np.ndarray:
    return 1e-3 * (table["sigma_um"] + table["sigma_um_per_m"] * np.asarray(length_mm) / 1000.0)


@dataclass
class World:
    """The random truth of one trial."""

    robot: Robot
    sensor: bino.StereoSensor
    dot_offsets: np.ndarray  # (6, 3) calibrator frame
    standard_pairs: np.ndarray
    standard_mm: np.ndarray


def draw_world(
    scenario: Scenario,
    rng,
    robot_scale: float = 1.0,
    imaging: Imaging | None = None,
    calibration_scale: float = 1.0,
) -> World:
    """Draw the true robot, the true cameras, the SBR dot offsets and the CMM standards.

    ``robot_scale`` multiplies the robot tolerances, ``calibration_scale`` the cameras'
    calibration uncertainty (``sensor.toml [calibration_uncertainty]``). Scales only change the
    size of the errors: the same ``rng`` draws the same numbers at any scale, so with one seed
    the true cameras at scale 2 differ from Table 1 by exactly twice those at scale 1.
    """
    if calibration_scale < 0:
        raise CalibrationError(f"calibration_scale is {calibration_scale}; it must be >= 0")
    imaging = imaging or Imaging()
    tol = scenario.robot.tolerances
    robot = perturb_robot(
        scenario.robot,
        rng,
        tol["sigma_length_mm"] * robot_scale,
        tol["sigma_angle_deg"] * robot_scale,
    )
    sigmas = scenario.config["sensor"]["calibration_uncertainty"]
    sigmas = {k: v * calibration_scale * imaging.noise for k, v in sigmas.items()}
    sensor = scenario.sensor.perturbed(sigmas, rng)
    sbr = scenario.config["calibrator"]["sbr"]
    offsets = _uniform_disc(rng, 6, 1e-3 * sbr["dot_centring_um"] * imaging.noise)
    pairs = bino.all_pairs(8)
    lengths = np.linalg.norm(scenario.layout[pairs[:, 0]] - scenario.layout[pairs[:, 1]], axis=1)
    sigma = _sigma_distance_mm(scenario.config["calibrator"]["cmm"], lengths) * imaging.noise
    return World(robot, sensor, offsets, pairs, lengths + sigma * rng.standard_normal(len(lengths)))


def _true_sensor_pose(scenario, world, q, rng, noise: bool) -> np.ndarray:
    flange = world.robot.fk(q)
    if noise:
        sigma = scenario.config["station"]["robot"]["repeatability_mm"] / 3.0
        flange = geo.perturb(flange, 0.0, sigma, rng)
    return flange @ scenario.sensor2flange


def _observe_from(scenario, world, q, dots, normal, rng, imaging) -> list:
    """Observations of the dots ``(m, 3)`` (base frame) from each joint configuration in ``q``."""
    return [
        observe(
            scenario,
            world.sensor,
            _true_sensor_pose(scenario, world, qi, rng, imaging.noise),
            dots,
            normal,
            rng,
            imaging,
        )
        for qi in q
    ]


def _view_calibrator(scenario, world, n, rng, imaging):
    q, flange = viewpoints(scenario, scenario.calibrator2base, n, rng)
    dots = geo.apply(scenario.calibrator2base, scenario.layout[:6] + world.dot_offsets)
    normal = scenario.calibrator2base[:3, 2]
    return flange, _observe_from(scenario, world, q, dots, normal, rng, imaging)


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
    (:func:`draw_world`); ``field=False`` skips the field check, which is drawn last.

    Returns
    -------
    dict
        ``table2`` (7, 2): the 7 distances to P7 averaged over the 6 poses, without and with
        rectification; ``table3`` (7, 2): with rectification, without and with the observed-error
        modification; ``standard`` (7,): the CMM standard distances; ``handeye`` dict of the true,
        preliminary and updated ``sensor2flange``; ``fig13`` (10, 2): distances P7 to the base
        origin with the preliminary and updated matrix and ``fig13_standard``; ``field`` list of
        per-region dicts.
    """
    imaging = imaging or Imaging()
    world = draw_world(scenario, rng, robot_scale, imaging, calibration_scale)
    n_cal = scenario.config["station"]["poses"]["n_calibration"]
    flange, obs = _view_calibrator(scenario, world, n_cal, rng, imaging)
    raw8 = bino.with_virtual(np.array([o.raw for o in obs]))
    rect8 = bino.with_virtual(np.array([o.rect for o in obs]))
    mod8 = np.array(
        [bino.modify_observed_error(p, world.standard_pairs, world.standard_mm)[0] for p in rect8]
    )
    rows = [0, 1, 2, 3, 4, 5, 7]
    standard = np.array([world.standard_mm[_pair_index(world.standard_pairs, r, 6)] for r in rows])
    table2 = np.column_stack(
        [bino.distances_to_p7(raw8).mean(0), bino.distances_to_p7(rect8).mean(0)]
    )
    table3 = np.column_stack([table2[:, 1], bino.distances_to_p7(mod8).mean(0)])
    holdout = np.mean([holdout_distances(p, world) for p in rect8], axis=0)
    poses = np.array([bino.calibrator_pose(scenario.layout[:6], r[:6]) for r in raw8])
    pre = bino.preliminary_handeye(flange, poses)
    upd, d_eta = bino.correct_transformation(flange, pre, rect8, mod8)
    # Fig. 13: ten more poses, P7 to the base origin
    n_val = scenario.config["station"]["poses"]["n_validation"]
    vflange, vobs = _view_calibrator(scenario, world, n_val, rng, imaging)
    vmod = np.array(
        [
            bino.modify_observed_error(
                bino.with_virtual(o.rect), world.standard_pairs, world.standard_mm
            )[0]
            for o in vobs
        ]
    )
    lt = scenario.config["station"]["laser_tracker"]
    # the tracker measures the sphere centres (SMRs in the nests), not the dots
    p7_standard = float(np.linalg.norm(geo.apply(scenario.calibrator2base, scenario.layout[6])))
    p7_standard += (
        float(_sigma_distance_mm(lt, p7_standard) * rng.standard_normal()) * imaging.noise
    )
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
    regions = (
        [_field_region(scenario, world, k, pre, upd, rng, imaging) for k in range(3)]
        if field
        else []
    )
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
        "fig13": fig13,
        "fig13_standard": p7_standard,
        "field": regions,
    }


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


def region_layout(standard_mm) -> np.ndarray:
    """Six SBRs of a field region: five at the given distances around the sixth (the centre),
    72 deg apart, in the region's plane; ``(6, 3)`` in the region frame."""
    d = np.asarray(standard_mm, dtype=float)
    a = np.radians(72.0 * np.arange(5))
    return np.vstack([np.column_stack([d * np.cos(a), d * np.sin(a), np.zeros(5)]), np.zeros(3)])


def _field_region(scenario, world, k, pre, upd, rng, imaging) -> dict:
    cfg = scenario.config["station"]["field"]
    centre = np.array(cfg["centres_mm"][k], dtype=float)
    normal = np.array(cfg["faces_point_mm"], dtype=float) - centre
    region2base = _plate_frame(centre, normal)
    layout = region_layout(cfg["standard_mm"][k]) + _uniform_disc(
        rng, 6, 1e-3 * scenario.config["calibrator"]["sbr"]["dot_centring_um"] * imaging.noise
    )
    q, flange = viewpoints(scenario, region2base, cfg["n_poses"], rng)
    dots = geo.apply(region2base, layout)
    obs = _observe_from(scenario, world, q, dots, region2base[:3, 2], rng, imaging)
    pts = np.array([o.rect for o in obs])  # (poses, 6, 3)
    lt = scenario.config["station"]["laser_tracker"]
    true_d = np.linalg.norm(layout[:5] - layout[5], axis=1)
    standard = true_d + _sigma_distance_mm(lt, true_d) * rng.standard_normal(5) * imaging.noise
    out = {"region": cfg["regions"][k], "names": cfg["names"][k], "standard": standard}
    for label, h in (("preliminary", pre), ("updated", upd)):
        in_flange = np.einsum("ij,pmj->pmi", h[:3, :3], pts) + h[:3, 3]
        d_flange = np.linalg.norm(in_flange[:, :5] - in_flange[:, 5:6], axis=-1).mean(0)
        in_base = np.einsum("pij,pmj->pmi", flange[:, :3, :3], in_flange) + flange[:, None, :3, 3]
        mean_base = in_base.mean(0)
        d_base = np.linalg.norm(mean_base[:5] - mean_base[5], axis=1)
        out[f"{label}_flange"] = d_flange
        out[f"{label}_base"] = d_base
    return out


# ----------------------------------------------------------------------------------------------
# Monte Carlo and tables


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


def trial_metrics(trials: list[dict]) -> pd.DataFrame:
    """One row per trial: the RMSEs of Tables 2, 3, 5, Fig. 13 and the hand-eye errors."""
    rows = []
    for k, t in enumerate(trials):
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
            row[f"rot_err_{label}_mrad"] = 1e3 * float(
                geo.rotation_error(hand[label], hand["true"])
            )
            row[f"trans_err_{label}_mm"] = float(geo.translation_error(hand[label], hand["true"]))
        if t["field"]:
            for label in ("preliminary", "updated"):
                for frame in ("flange", "base"):
                    err = np.concatenate(
                        [f[f"{label}_{frame}"] - f["standard"] for f in t["field"]]
                    )
                    row[f"field_{label}_{frame}"] = rmse(err)
        rows.append(row)
    return pd.DataFrame(rows)


def published(name: str, key: str):
    """A published value from ``data/binocular/<name>.toml [published]``."""
    return bino.load_toml(name)["published"][key]


def distance_table(trial: dict, which: str) -> pd.DataFrame:
    """Table 2 (``which="table2"``) or 3 of one trial beside the published one, mm."""
    cal = bino.load_toml("calibrator")
    names = cal["standard"]["names"]
    pub = cal["published"]
    values = trial[which]
    return pd.DataFrame(
        {
            "pair": names,
            "standard_mm": trial["standard"],
            "without_mm": values[:, 0],
            "with_mm": values[:, 1],
            "error_without_mm": values[:, 0] - trial["standard"],
            "error_with_mm": values[:, 1] - trial["standard"],
            "published_standard_mm": cal["standard"]["distance_mm"],
            "published_without_mm": pub[f"{which}_control"],
            "published_with_mm": pub[f"{which}_experimental"],
        }
    )


def handeye_table(trial: dict) -> pd.DataFrame:
    """Table 4: true, preliminary and updated ``sensor2flange`` (one trial) beside the published."""
    rows = []
    hand = trial["handeye"]
    pub = {k: np.array(published("station", f"table4_{k}")) for k in ("preliminary", "updated")}
    for label in ("true", "preliminary", "updated"):
        for i in range(3):
            rows.append(
                {
                    "matrix": label,
                    "row": i + 1,
                    **{f"c{j + 1}": hand[label][i, j] for j in range(4)},
                }
            )
    for label, m in pub.items():
        for i in range(3):
            rows.append(
                {
                    "matrix": f"published {label}",
                    "row": i + 1,
                    **{f"c{j + 1}": m[i, j] for j in range(4)},
                }
            )
    return pd.DataFrame(rows)


def fig13_table(trial: dict) -> pd.DataFrame:
    """Fig. 13: distance P7 to the base origin per validation pose, with both matrices."""
    f = trial["fig13"]
    std = trial["fig13_standard"]
    return pd.DataFrame(
        {
            "pose": np.arange(1, len(f) + 1),
            "standard_mm": std,
            "preliminary_mm": f[:, 0],
            "updated_mm": f[:, 1],
            "error_preliminary_mm": f[:, 0] - std,
            "error_updated_mm": f[:, 1] - std,
        }
    )


def field_table(trial: dict) -> pd.DataFrame:
    """Table 5 of one trial: each region's distances with both calibrations beside the published."""
    pre = published("station", "table5_preliminary")
    upd = published("station", "table5_updated")
    stds = bino.load_toml("station")["field"]["standard_mm"]
    rows = []
    for k, f in enumerate(trial["field"]):
        for i, name in enumerate(f["names"]):
            rows.append(
                {
                    "region": f["region"],
                    "pair": name,
                    "standard_mm": f["standard"][i],
                    "preliminary_flange_mm": f["preliminary_flange"][i],
                    "updated_flange_mm": f["updated_flange"][i],
                    "preliminary_base_mm": f["preliminary_base"][i],
                    "updated_base_mm": f["updated_base"][i],
                    "published_standard_mm": stds[k][i],
                    "published_preliminary_mm": pre[k][i],
                    "published_updated_mm": upd[k][i],
                }
            )
    return pd.DataFrame(rows)


def rmse_summary(metrics: pd.DataFrame) -> pd.DataFrame:
    """RMSE without/with each step: median and 95 % interval over trials, beside the paper."""
    from calstudy.core.stats import percentile_interval

    t5 = np.array(published("station", "table5_rmse"))
    specs = [
        (
            "Table 2: CoC rectification",
            "t2_without",
            "t2_with",
            published("calibrator", "table2_rmse"),
        ),
        (
            "Table 3: observed-error modification",
            "t3_without",
            "t3_with",
            published("calibrator", "table3_rmse"),
        ),
        (
            "Table 3, hold-out: P1-P6 to P7",
            "t3_holdout_without",
            "t3_holdout_with",
            [math.nan, math.nan],
        ),
        (
            "Fig. 13: transformation correction",
            "fig13_preliminary",
            "fig13_updated",
            published("station", "fig13_rmse"),
        ),
        (
            "Table 5: field, base frame",
            "field_preliminary_base",
            "field_updated_base",
            list(t5.mean(0)),
        ),
        (
            "Table 5: field, flange frame",
            "field_preliminary_flange",
            "field_updated_flange",
            list(t5.mean(0)),
        ),
    ]
    rows = []
    for label, a, b, pub in specs:
        if a not in metrics:
            continue
        ratio = metrics[b] / metrics[a]
        lo, hi = percentile_interval(ratio) if len(ratio) > 1 else (float(ratio.iloc[0]),) * 2
        rows.append(
            {
                "step": label,
                "published_without_mm": pub[0],
                "published_with_mm": pub[1],
                "published_ratio": pub[1] / pub[0],
                "without_mm": float(metrics[a].median()),
                "with_mm": float(metrics[b].median()),
                "ratio": float(ratio.median()),
                "ratio_low": lo,
                "ratio_high": hi,
            }
        )
    return pd.DataFrame(rows)


def defocus_shift(scenario: Scenario, depths_mm, tilt_deg: float = 20.0) -> pd.DataFrame:
    """How defocus moves the detected centre of one dot, noise-free, without and with rectification.

    A dot 10 deg off the left camera's axis (tilted ``tilt_deg`` about x) is rendered at each
    depth with the CoC radius of Eq. 4; its centre is detected in the blurred image itself
    (``blur_only``) and after two noise-free exposures (saturation and 8-bit quantisation kept)
    fused by Eq. 3 (``fused``), each without and with rectification. The shift is the detected
    minus the true image of the dot centre, px.
    """
    camera = scenario.sensor.cameras()[0]
    k, dist, _ = camera
    cfg = scenario.config["sensor"]
    exp, optics = cfg["exposure"], cfg["optics"]
    det = cfg["detection"]
    kwargs = {
        "low": det["canny_low"],
        "high": det["canny_high"],
        "min_points": det["min_edge_points"],
    }
    t = math.radians(tilt_deg)
    normal = np.array([0.0, math.sin(t), -math.cos(t)])
    rng = np.random.default_rng(0)  # unused: no noise
    rows = []
    for z in depths_mm:
        centre = float(z) * np.array([0.15, 0.1, 1.0])  # off-axis: vignetting and distortion act
        delta = float(
            coc.coc_radius_px(
                z,
                optics["focus_distance_mm"],
                scenario.focal_mm,
                optics["f_number"],
                cfg["image"]["pixel_pitch_mm"],
            )
        )
        uv = _project(k, dist, centre)
        r_px = Imaging.dot_radius(scenario) * k[0, 0] / z
        origin, shape = coc.roi_around(
            uv, r_px, 4 * delta + 10, scenario.sensor.width, scenario.sensor.height
        )
        sharp = coc.render_dot(k, dist, centre, normal, Imaging.dot_radius(scenario), origin, shape)
        blurred = coc.defocus(sharp, delta)
        shots = [
            coc.expose(
                blurred,
                tm,
                exp["dot_peak_at_100ms"],
                exp["background_at_100ms"],
                0.0,
                math.inf,
                rng,
                exp["bits"],
            )
            for tm in exp["times_ms"]
        ]
        fused = coc.fuse_exposures(
            shots, exp["weight_contrast"], exp["weight_exposure"], exp["well_exposed_sigma"]
        )
        row = {"depth_mm": float(z), "coc_radius_px": delta}
        for label, img in (("blur_only", blurred), ("fused", fused)):
            raw = coc.detect_centre(img, origin, **kwargs) - uv
            rect = raw
            if delta >= 1 / 3:
                rect = coc.detect_centre(coc.rectify_coc(img, delta), origin, **kwargs) - uv
            row[f"{label}_shift_u_px"] = raw[0]
            row[f"{label}_shift_v_px"] = raw[1]
            row[f"{label}_shift_px"] = float(np.hypot(*raw))
            row[f"{label}_rectified_shift_px"] = float(np.hypot(*rect))
        rows.append(row)
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# claims and figures


def claim_rows(metrics: pd.DataFrame, notebook: str) -> list:
    """The four claim rows; each verdict is computed from the per-trial RMSE ratios."""
    from calstudy.claims import verdict_vs_published

    t5 = np.array(published("station", "table5_rmse"))
    specs = [
        ("binocular.coc", "t2_without", "t2_with", published("calibrator", "table2_rmse")),
        (
            "binocular.observed_error",
            "t3_without",
            "t3_with",
            published("calibrator", "table3_rmse"),
        ),
        (
            "binocular.transformation",
            "fig13_preliminary",
            "fig13_updated",
            published("station", "fig13_rmse"),
        ),
        ("binocular.field", "field_preliminary_base", "field_updated_base", None),
    ]
    rows = []
    for claim, a, b, pub in specs:
        if pub is None:
            ratio = float(np.mean(t5[:, 1] / t5[:, 0]))
            text = f"{ratio:.3f} (mean of " + ", ".join(f"{y:.3f}/{x:.3f}" for x, y in t5) + " mm)"
        else:
            ratio = pub[1] / pub[0]
            text = f"{ratio:.3f} ({pub[1]:.3f}/{pub[0]:.3f} mm)"
        v = verdict_vs_published(
            ratio, metrics[b].to_numpy(), metrics[a].to_numpy(), kind="ratio", direction="lower"
        )
        rows.append(v.row(claim, text, "ratio", notebook))
    return rows


def shift_figure(table: pd.DataFrame, scenario: Scenario):
    """Detected-centre shift against depth, without and with rectification."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for label, name in (("fused", "fused exposures"), ("blur_only", "blur only")):
        ax.plot(table["depth_mm"], table[f"{label}_shift_px"], "o-", label=f"{name}")
        ax.plot(
            table["depth_mm"],
            table[f"{label}_rectified_shift_px"],
            "s--",
            label=f"{name}, rectified",
        )
    ax2 = ax.twinx()
    ax2.plot(table["depth_mm"], table["coc_radius_px"], "k:")
    ax2.set_ylabel("circle-of-confusion radius, dotted (px)")
    focus = scenario.config["sensor"]["optics"]["focus_distance_mm"]
    ax.set_xlabel(f"dot depth (mm); focused at {focus:g} mm")
    ax.set_ylabel("centre shift (px)")
    ax.set_title("Defocus shift of a detected dot centre (noise-free)")
    ax.legend(loc="upper center", fontsize=8)
    fig.tight_layout()
    return fig


def fig13_figure(table: pd.DataFrame):
    """Fig. 13 equivalent: error of the P7-to-base distance per validation pose."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    x = table["pose"].to_numpy()
    ax.bar(x - 0.2, table["error_preliminary_mm"].abs(), 0.4, label="preliminary (AX = XB)")
    ax.bar(x + 0.2, table["error_updated_mm"].abs(), 0.4, label="updated (Eq. 14-22)")
    ax.set_xticks(x)
    ax.set_xlabel("validation pose")
    ax.set_ylabel("|distance error| (mm)")
    ax.set_title("Distance from P7 to the base origin (one trial)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def summary_figure(summary: pd.DataFrame):
    """RMSE ratio (with / without) per step: median and 95 % interval, and the published ratio."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.2, 3.6))
    y = np.arange(len(summary))
    err = [summary["ratio"] - summary["ratio_low"], summary["ratio_high"] - summary["ratio"]]
    ax.errorbar(summary["ratio"], y, xerr=err, fmt="o", label="simulation (median, 95 %)")
    ax.plot(summary["published_ratio"], y, "r*", markersize=10, label="paper")
    ax.axvline(1.0, color="grey", lw=0.8)
    ax.set_yticks(y, summary["step"], fontsize=8)
    ax.set_xlabel("RMSE with / without the step")
    ax.invert_yaxis()
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return fig


def sweep_figure(
    sweep: pd.DataFrame,
    x: str = "robot_scale",
    series=(("fig13_preliminary", "preliminary"), ("fig13_updated", "updated")),
    paper=None,
    xlabel: str = "robot error scale (x tolerances of the robot's file)",
    ylabel: str = "Fig. 13 RMSE (mm, median)",
):
    """Median RMSEs of a sweep against the swept scale ``x``, with the paper's values.

    ``series`` pairs a column of ``sweep`` with its label; ``paper`` pairs each published value
    with its label (drawn dotted in the colour of the series at the same position). The defaults
    draw Fig. 13 against the robot error scale (:func:`robot_sweep`).
    """
    import matplotlib.pyplot as plt

    if paper is None:
        fig13 = published("station", "fig13_rmse")
        paper = ((fig13[0], "paper, preliminary"), (fig13[1], "paper, updated"))
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for col, label in series:
        ax.plot(sweep[x], sweep[col], "o-", label=label)
    for i, (value, label) in enumerate(paper):
        ax.axhline(value, color=f"C{i}", ls=":", label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def robot_sweep_figure(sweep: pd.DataFrame, scenario: Scenario):
    """Fig. 13 RMSEs against the robot error scale (:func:`robot_sweep`) of ``scenario``'s robot."""
    model = scenario.config["station"]["robot"]["model"]
    return sweep_figure(sweep, xlabel=f"robot error scale (x tolerances of {model}.toml)")


def calibration_sweep_figure(sweep: pd.DataFrame):
    """Tables 2 and 3 RMSE against the scale of the cameras' calibration errors
    (:func:`calibration_sweep`), with the paper's 0.049, 0.041 and 0.034 mm."""
    t2 = published("calibrator", "table2_rmse")
    t3 = published("calibrator", "table3_rmse")
    return sweep_figure(
        sweep,
        x="calibration_scale",
        series=(
            ("t2_without", "Table 2, without rectification"),
            ("t2_with", "Table 2, with rectification (= Table 3, without)"),
            ("t3_with", "Table 3, with modification"),
            ("t3_holdout_with", "hold-out P1-P6, with modification"),
        ),
        paper=(
            (t2[0], "paper, without rectification"),
            (t2[1], "paper, with rectification"),
            (t3[1], "paper, with modification"),
        ),
        xlabel="camera calibration error scale (x sensor.toml [calibration_uncertainty])",
        ylabel="RMSE of distances to P7 (mm, median)",
    )


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
        ``verdict_observed_error``) by the rule of :func:`claim_rows`.

    Raises
    ------
    CalibrationError
        If ``n_trials`` is below 2 (a verdict needs an interval) or a scale is negative.
    """
    from calstudy.claims import verdict_vs_published
    from calstudy.core.stats import percentile_interval

    if n_trials < 2:
        raise CalibrationError(f"n_trials is {n_trials}; a verdict per scale needs at least 2")
    claims = {
        "coc": ("t2", published("calibrator", "table2_rmse")),
        "observed_error": ("t3", published("calibrator", "table3_rmse")),
    }
    rows = []
    for scale in scales:
        m = trial_metrics(
            monte_carlo(
                scenario,
                seed,
                n_trials,
                stream=200,
                progress=progress,
                field=False,
                calibration_scale=float(scale),
            )
        )
        row = {"calibration_scale": float(scale), "n_trials": n_trials}
        row.update(m.drop(columns="trial").median().to_dict())
        for key in ("t2", "t3", "t3_holdout"):
            ratio = m[f"{key}_with"] / m[f"{key}_without"]
            lo, hi = percentile_interval(ratio)
            row.update(
                {
                    f"{key}_ratio": float(ratio.median()),
                    f"{key}_ratio_low": lo,
                    f"{key}_ratio_high": hi,
                }
            )
        for claim, (key, pub) in claims.items():
            v = verdict_vs_published(
                pub[1] / pub[0],
                m[f"{key}_with"].to_numpy(),
                m[f"{key}_without"].to_numpy(),
                kind="ratio",
                direction="lower",
            )
            row[f"verdict_{claim}"] = v.verdict
        rows.append(row)
    return pd.DataFrame(rows)


def layout_table(scenario: Scenario) -> pd.DataFrame:
    """The solved calibrator layout (calibrator frame, mm) with each target's distance to P7,
    the Table 2 standard and the residual."""
    std = scenario.config["calibrator"]["standard"]["distance_mm"]
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
