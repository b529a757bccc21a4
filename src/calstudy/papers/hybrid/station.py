"""The simulated hybrid inspection station (hybrid paper, sections 2-4) and its calibration runs.

The station has a KUKA KR 16-2 carrying a line-laser sensor (the flexible sensor), ten stationary
sensors on the fixture, a standard sphere, the two-sided 5 x 7 hole target and a panel located by
the 3-2-1 rule. All numbers come from ``data/hybrid/station.toml`` (paper facts and documented
assumptions). Two robots exist: the *true* robot moves in the simulated world; the controller
reports flange poses from the *nominal* model, as the paper's station does.

Calibration poses are *taught*: the operator jogs the real robot until the sensor sees the sphere
(or the target sits over a stationary sensor), so the joint angles come from the true robot and
the reported flange pose is the nominal forward kinematics of those angles. Pure translations are
jogged in the controller's base frame, i.e. at constant *nominal* orientation.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.estimators.fitting import fit_homography, homography_to_pose, solve_pnp
from calstudy.estimators.handeye import (
    OPENCV_METHODS,
    SphereMeasurements,
    opencv_handeye,
    sphere_handeye,
    sphere_handeye_crb,
    sphere_handeye_ml,
    stationary_sensor_to_base,
)
from calstudy.estimators.workpiece import rps_frame_penalty, rps_frame_so3
from calstudy.models.kinematics import Robot, load_robot, perturb_robot
from calstudy.models.sensors import LineLaserSensor, PinholeCamera
from calstudy.models.targets import HoleTarget, ManufacturedHoleTarget, Sphere

#: a few joint configurations (deg) tried as IK seeds, arm reaching forward and down
_IK_SEEDS_DEG = np.array(
    [
        [0.0, -45.0, 100.0, 0.0, 45.0, 0.0],
        [0.0, -30.0, 80.0, 0.0, 60.0, 0.0],
        [0.0, -60.0, 110.0, 0.0, 30.0, 0.0],
        [0.0, -20.0, 60.0, 0.0, 80.0, 0.0],
        [0.0, -45.0, 100.0, 90.0, 45.0, -90.0],
        [0.0, -45.0, 100.0, -90.0, 45.0, 90.0],
    ]
)


def load_config() -> dict:
    """The station description ``data/hybrid/station.toml`` as a dict."""
    with open(data_path("hybrid", "station.toml"), "rb") as handle:
        return tomllib.load(handle)


def _rz(angle: float) -> np.ndarray:
    return geo.rotvec_to_matrix(np.array([0.0, 0.0, angle]))


RX_PI = np.diag([1.0, -1.0, -1.0])


@dataclass
class HybridStation:
    """A drawn station: robots, sensors, targets and the truth of every transform (mm, rad).

    Build one with :func:`make_station`. Fields ending in ``_true`` are the simulated world;
    an estimator never sees them.
    """

    nominal: Robot
    true: Robot
    sensor2flange_true: np.ndarray
    laser: LineLaserSensor
    camera: PinholeCamera
    pixel_sigma: float
    sphere: Sphere
    standoff: float
    stripe_offset: float
    joint_sigma: float
    target: HoleTarget
    target_made: ManufacturedHoleTarget
    back2front_cmm: np.ndarray
    front2sensor: np.ndarray
    statcam2base_true: np.ndarray
    base2work_nominal: np.ndarray
    base2work_true: np.ndarray
    datums_work: np.ndarray
    datum_sigma: float
    free_direction: float
    config: dict = field(repr=False, default_factory=dict)
    _sphere_ref: np.ndarray | None = field(default=None, repr=False)

    # ------------------------------------------------------------------ robot motion

    def solve_ik(
        self, robot: Robot, flange2base: np.ndarray, q0=None, only_q0: bool = False
    ) -> np.ndarray:
        """Joint angles of ``robot`` for a flange pose, trying ``q0`` then the built-in seeds."""
        seeds = [] if q0 is None else [np.asarray(q0, dtype=float)]
        yaw = np.arctan2(flange2base[1, 3], flange2base[0, 3])
        for s in np.deg2rad(_IK_SEEDS_DEG) if not (only_q0 and seeds) else []:
            s = s.copy()
            s[0] = yaw
            seeds.append(s)
        last = None
        for seed in seeds:
            try:
                return robot.ik(flange2base, seed)
            except CalibrationError as exc:
                last = exc
        raise CalibrationError(f"flange pose out of reach of the {robot.name}: {last}")

    def move(self, q, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Stop at joint angles ``q (N, 6)``: (reported nominal flange2base, actual true one).

        The actual pose carries the robot's repeatability as Gaussian joint noise.
        """
        q = np.atleast_2d(q)
        reported = self.nominal.fk_many(q)
        actual = self.true.fk_many(q + rng.normal(0.0, self.joint_sigma, q.shape))
        return reported, actual

    # ------------------------------------------------------------------ flexible sensor

    def sphere_reference_pose(self) -> np.ndarray:
        """``sensor2base`` looking down at the sphere, the laser plane at the stripe offset.

        The yaw about the vertical is the first (in 15 degree steps) for which the true robot
        reaches the pose. Computed once per station.
        """
        if self._sphere_ref is not None:
            return self._sphere_ref
        x_b = self.sphere.centre
        centre_in_sensor = np.array([0.0, self.stripe_offset, self.standoff])
        for yaw in np.deg2rad(np.arange(0.0, 360.0, 15.0)):
            rot = _rz(yaw) @ RX_PI
            pose = geo.make_transform(rot, x_b - rot @ centre_in_sensor)
            try:
                self.solve_ik(self.true, pose @ geo.invert(self.sensor2flange_true))
            except CalibrationError:
                continue
            self._sphere_ref = pose
            return pose
        raise CalibrationError("no yaw lets the robot see the sphere from above")

    def sphere_moves(self, n_trans: int, n_rot: int, rng: np.random.Generator):
        """Joint angles of the calibration moves: ``(q_trans (n, 6), q_rot (m, 6))``.

        Translations: the reference pose taught on the true robot, then moves of the flange
        position within +-``translation_range_mm`` in the controller's frame at constant nominal
        orientation, restricted to +-2 mm across the laser plane so the stripe stays on its side.
        Pose changes: the sensor tilted about the sphere centre by 10 degrees to
        ``rotation_range_deg`` about random axes, each taught on the true robot.
        """
        cfg = self.config["calibration_moves"]
        ref = self.sphere_reference_pose()
        s2f = self.sensor2flange_true
        q_ref = self.solve_ik(self.true, ref @ geo.invert(s2f))
        f_ref = self.nominal.fk(q_ref)
        span = cfg["translation_range_mm"]
        shifts_sensor = rng.uniform(-1.0, 1.0, (n_trans, 3)) * np.array([span, 2.0, span])
        shifts_sensor[0] = 0.0
        shifts_base = shifts_sensor @ ref[:3, :3].T
        q_trans = np.array(
            [
                self.solve_ik(
                    self.nominal, geo.make_transform(f_ref[:3, :3], f_ref[:3, 3] + d), q_ref
                )
                for d in shifts_base
            ]
        )
        about = geo.make_transform(np.eye(3), self.sphere.centre)
        q_rot = []
        attempts = 0
        while len(q_rot) < n_rot:
            # an operator teaches only poses the robot reaches: draw again when it cannot
            attempts += 1
            if attempts > 50 * n_rot:
                raise CalibrationError(f"only {len(q_rot)} of {n_rot} tilted poses are reachable")
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            angle = np.deg2rad(rng.uniform(10.0, cfg["rotation_range_deg"]))
            turn = about @ geo.make_transform(geo.rotvec_to_matrix(axis * angle), np.zeros(3))
            pose = turn @ geo.invert(about) @ ref
            try:
                q_rot.append(self.solve_ik(self.true, pose @ geo.invert(s2f), q_ref, only_q0=True))
            except CalibrationError:
                continue
        return q_trans, np.array(q_rot)

    def measure_sphere(self, q, rng: np.random.Generator):
        """Reported flange poses, measured centres and actual flange poses at joint angles ``q``."""
        reported, actual = self.move(q, rng)
        sensor2base = actual @ self.sensor2flange_true
        rt = np.swapaxes(sensor2base[:, :3, :3], 1, 2)
        true_c = np.einsum("nij,nj->ni", rt, self.sphere.centre - sensor2base[:, :3, 3])
        return (
            reported,
            self.laser.measure_sphere_centre(true_c, self.sphere.radius_mm, rng),
            actual,
        )

    def observe_target_pose(self, actual_flange2base, target2base, rng: np.random.Generator):
        """The hole target's pose in the flexible sensor's camera frame, from a noisy image (PnP).

        Used by the AX = XB baselines: the target lies where the sphere was, facing the sensor.
        """
        poses = []
        pts = self.target_made.front_points
        for f2b in actual_flange2base:
            t2c = geo.invert(f2b @ self.sensor2flange_true) @ target2base
            uv = self.camera.observe(t2c, pts, self.pixel_sigma, rng)
            poses.append(solve_pnp(self.target.front_points(), uv, self.camera.K))
        return np.array(poses)

    def sensor_sigma(self, rng: np.random.Generator) -> np.ndarray:
        """Per-axis repeatability of the sphere-centre measurement at the reference stand-off."""
        centre = np.array([0.0, self.stripe_offset, self.standoff])
        return self.laser.centre_std(centre, self.sphere.radius_mm, rng)

    # ------------------------------------------------------------------ stationary sensors

    def stationary_pose(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles and the target's ``back2statcam`` for calibrating stationary sensor ``i``.

        The back face is held at the stand-off of the sensor, facing it; the yaw about the
        sensor axis is the first (15 degree steps) that the nominal robot reaches (searched once
        per sensor and cached), and the true robot is then taught from that configuration.
        """
        statcam2base = self.statcam2base_true[index]
        front2flange = self.sensor2flange_true @ self.front2sensor

        def flange_for(yaw, back2front):
            back2statcam = geo.make_transform(RX_PI @ _rz(yaw), [0.0, 0.0, self.standoff])
            front2base = statcam2base @ back2statcam @ geo.invert(back2front)
            return front2base @ geo.invert(front2flange), back2statcam

        key = (index, statcam2base.tobytes())
        if key not in _STATIONARY_SEEDS:
            for yaw in np.deg2rad(np.arange(0.0, 360.0, 15.0)):
                pose, _ = flange_for(yaw, self.target.back2front())
                try:
                    _STATIONARY_SEEDS[key] = (yaw, self.solve_ik(self.nominal, pose))
                    break
                except CalibrationError:
                    continue
            else:
                raise CalibrationError(
                    f"the robot cannot hold the target over stationary sensor {index + 1}"
                )
        yaw, seed = _STATIONARY_SEEDS[key]
        pose, back2statcam = flange_for(yaw, self.target_made.back2front)
        return self.solve_ik(self.true, pose, seed), back2statcam


#: IK seeds of the stationary-sensor poses on the nominal robot, by sensor (pure geometry cache)
_STATIONARY_SEEDS: dict = {}


def make_station(
    rng: np.random.Generator,
    *,
    robot_errors: bool = True,
    sigma_point_mm: float | None = None,
    pixel_sigma: float | None = None,
    repeatability_mm: float | None = None,
    robot_error_scale: float = 1.0,
) -> HybridStation:
    """Draw a station: the true robot, the made target, the CMM value, the panel placement.

    Parameters
    ----------
    rng
        Source of every draw.
    robot_errors
        If False the true robot equals the nominal one (no kinematic model error).
    sigma_point_mm, pixel_sigma, repeatability_mm
        Override the laser stripe-point noise, the hole-centre pixel noise and the robot
        repeatability of ``station.toml``.
    robot_error_scale
        Factor (>= 0) on the kinematic tolerances of ``data/robots/kuka_kr16_2.toml`` when the
        true robot is drawn: its link parameters are the nominal ones plus ``robot_error_scale``
        times the errors drawn at the file's tolerances. The draws are the same for every
        factor, so 0 gives the nominal robot and leaves every other draw of the station as it
        is. Ignored when ``robot_errors`` is False.
    """
    if not (np.isfinite(robot_error_scale) and robot_error_scale >= 0):
        raise CalibrationError(
            f"robot_error_scale is {robot_error_scale!r}; expected a finite factor >= 0"
        )
    cfg = load_config()
    nominal = load_robot("kuka_kr16_2")
    tol = nominal.tolerances
    true = (
        perturb_robot(
            nominal,
            rng,
            sigma_length_mm=robot_error_scale * tol["sigma_length_mm"],
            sigma_angle_deg=robot_error_scale * tol["sigma_angle_deg"],
        )
        if robot_errors
        else nominal.with_parameters(nominal.parameters())
    )
    hand = np.array(cfg["handeye"]["matrix"], dtype=float)
    sensor2flange = geo.make_transform(geo.project_to_so3(hand[:3, :3]), hand[:3, 3])
    cam = cfg["cameras"]
    camera = PinholeCamera(
        fx=cam["fx"],
        fy=cam["fy"],
        cx=cam["cx"],
        cy=cam["cy"],
        width=cam["width"],
        height=cam["height"],
    )
    laser = (
        LineLaserSensor()
        if sigma_point_mm is None
        else LineLaserSensor(sigma_point_mm=sigma_point_mm)
    )
    sphere = Sphere(centre=np.array(cfg["sphere"]["centre_mm"], dtype=float))
    target = HoleTarget()
    made = target.manufactured(rng)
    tcfg = cfg["target"]
    back2front_cmm = geo.perturb(
        made.back2front, np.deg2rad(tcfg["cmm_sigma_deg"]), tcfg["cmm_sigma_mm"], rng
    )
    standoff = cfg["sensor"]["standoff_mm"]
    front2sensor = geo.make_transform(RX_PI, [0.0, 0.0, standoff])
    st = cfg["stationary"]
    tilts = np.deg2rad(np.array(st["tilts_deg"], dtype=float))
    rot = geo.rotvec_to_matrix(
        np.column_stack([tilts[:, 0], np.zeros(len(tilts)), np.zeros(len(tilts))])
    )
    rot = rot @ geo.rotvec_to_matrix(
        np.column_stack([np.zeros(len(tilts)), tilts[:, 1], np.zeros(len(tilts))])
    )
    statcam2base = geo.make_transform(rot, np.array(st["positions_mm"], dtype=float))
    wcfg = cfg["workpiece"]
    work2base_nominal = geo.make_transform(
        _rz(np.deg2rad(wcfg["nominal_rotz_deg"])), np.array(wcfg["nominal_origin_mm"], dtype=float)
    )
    base2work_nominal = geo.invert(work2base_nominal)
    work2base_true = geo.perturb(
        work2base_nominal, np.deg2rad(wcfg["placement_sigma_deg"]), wcfg["placement_sigma_mm"], rng
    )
    datums = np.array(
        [wcfg["datum_A_slot_mm"], wcfg["datum_B_hole_mm"], wcfg["datum_C_plane_mm"]], dtype=float
    )
    station = HybridStation(
        nominal=nominal,
        true=true,
        sensor2flange_true=sensor2flange,
        laser=laser,
        camera=camera,
        pixel_sigma=cam["pixel_sigma"] if pixel_sigma is None else pixel_sigma,
        sphere=sphere,
        standoff=standoff,
        stripe_offset=cfg["sensor"]["stripe_offset_fraction"] * sphere.radius_mm,
        joint_sigma=0.0,
        target=target,
        target_made=made,
        back2front_cmm=back2front_cmm,
        front2sensor=front2sensor,
        statcam2base_true=statcam2base,
        base2work_nominal=base2work_nominal,
        base2work_true=geo.invert(work2base_true),
        datums_work=datums,
        datum_sigma=wcfg["datum_sigma_mm"],
        free_direction=wcfg["free_direction_mm"],
        config=cfg,
    )
    rep = cfg["robot"]["repeatability_mm"] if repeatability_mm is None else repeatability_mm
    station.joint_sigma = repeatability_joint_sigma(station, rep / 3.0)
    return station


def repeatability_joint_sigma(station: HybridStation, sigma_pos: float) -> float:
    """Joint noise (rad) whose flange scatter at the sphere pose is ``sigma_pos`` mm per axis."""
    if sigma_pos == 0:
        return 0.0
    ref = station.sphere_reference_pose()
    q = station.solve_ik(station.true, ref @ geo.invert(station.sensor2flange_true))
    jv = station.true.jacobian(q)[:3]
    return float(sigma_pos / np.sqrt(np.sum(jv**2) / 3.0))


# ---------------------------------------------------------------------------------------------
# experiments


def simulate_sphere_measurements(
    station: HybridStation, n_trans: int, n_rot: int, rng: np.random.Generator
) -> tuple[SphereMeasurements, np.ndarray]:
    """One fixed-sphere calibration run: the measurements and the actual flange poses."""
    q_t, q_r = station.sphere_moves(n_trans, n_rot, rng)
    q = np.concatenate([q_t, q_r])
    reported, centres, actual = station.measure_sphere(q, rng)
    meas = SphereMeasurements(
        ids=np.arange(len(q)),
        group=np.array(["translation"] * n_trans + ["rotation"] * n_rot),
        flange2base=reported,
        centres=centres,
    )
    return meas, actual


def handeye_trial(
    station: HybridStation,
    n_trans: int,
    n_rot: int,
    rng: np.random.Generator,
    sensor_sigma: np.ndarray,
    baselines: bool = True,
) -> dict[str, tuple[float, float]]:
    """Errors (rotation deg, translation mm) of every hand-eye method on one simulated run.

    Methods: the paper's (``"sphere"``), its ML refinement (``"ML"``), the Cramer-Rao bound at the
    truth under sensor noise alone (``"CRB"``, an expected RMS), and with ``baselines`` the five
    OpenCV AX = XB methods fed with the hole target's pose seen at the same robot poses.
    """
    meas, actual = simulate_sphere_measurements(station, n_trans, n_rot, rng)
    truth = station.sensor2flange_true
    out: dict[str, tuple[float, float]] = {}

    def err(t):
        return float(np.rad2deg(geo.rotation_error(t, truth))), float(
            geo.translation_error(t, truth)
        )

    paper = sphere_handeye(*meas.select("translation"), *meas.select("rotation"))
    out["sphere"] = err(paper.value)
    ml = sphere_handeye_ml(meas.flange2base, meas.centres, sensor_sigma, paper.value)
    out["ML"] = err(ml.value)
    # centres the sensor would report without noise at the reported poses: the CRB's linearisation
    clean = np.einsum(
        "nji,nj->ni",
        (meas.flange2base @ truth)[:, :3, :3],
        station.sphere.centre - (meas.flange2base @ truth)[:, :3, 3],
    )
    crb = sphere_handeye_crb(meas.flange2base, clean, sensor_sigma, truth, station.sphere.centre)
    out["CRB"] = (
        float(np.rad2deg(np.sqrt(np.trace(crb[3:6, 3:6])))),
        float(np.sqrt(np.trace(crb[:3, :3]))),
    )
    if baselines:
        target2base = geo.make_transform(np.eye(3), station.sphere.centre)
        t2s = station.observe_target_pose(actual, target2base, rng)
        for name in OPENCV_METHODS:
            out[name] = err(opencv_handeye(meas.flange2base, t2s, name))
    return out


def stationary_trial(
    station: HybridStation, sensor2flange: np.ndarray, rng: np.random.Generator
) -> list[dict]:
    """Calibrate the ten stationary sensors once (Eq. 23); errors per sensor and per variant.

    Variants: ``"homography"`` (the paper: Eq. 19 poses, the calibrated hand-eye, reported flange
    poses); ``"pnp"`` (same chain with ML PnP poses); ``"images only, homography|pnp"`` (the true
    hand-eye and the actual flange pose: the error the images, the target and the CMM leave).
    """
    rows = []
    k = station.camera.K
    front_cad = station.target.front_points()
    back_cad = station.target.back_points()
    for i in range(len(station.statcam2base_true)):
        q, _ = station.stationary_pose(i)
        reported, actual = station.move(q, rng)
        reported, actual = reported[0], actual[0]
        front2base = actual @ station.sensor2flange_true @ station.front2sensor
        back2statcam = (
            geo.invert(station.statcam2base_true[i]) @ front2base @ station.target_made.back2front
        )
        uv_f = station.camera.observe(
            station.front2sensor, station.target_made.front_points, station.pixel_sigma, rng
        )
        uv_b = station.camera.observe(
            back2statcam, station.target_made.back_points, station.pixel_sigma, rng
        )
        f_h = homography_to_pose(fit_homography(front_cad[:, :2], uv_f), k)
        b_h = homography_to_pose(fit_homography(back_cad[:, :2], uv_b), k)
        f_p = solve_pnp(front_cad, uv_f, k)
        b_p = solve_pnp(back_cad, uv_b, k)
        b2f = station.back2front_cmm
        truth = station.statcam2base_true[i]
        s2f_true = station.sensor2flange_true
        variants = {
            "homography": stationary_sensor_to_base(reported, sensor2flange, f_h, b_h, b2f),
            "pnp": stationary_sensor_to_base(reported, sensor2flange, f_p, b_p, b2f),
            "images only, homography": stationary_sensor_to_base(actual, s2f_true, f_h, b_h, b2f),
            "images only, pnp": stationary_sensor_to_base(actual, s2f_true, f_p, b_p, b2f),
        }
        field_point = np.array([0.0, 0.0, station.standoff])  # centre of the measuring field
        for name, est in variants.items():
            rows.append(
                {
                    "sensor": i + 1,
                    "variant": name,
                    "rotation_error_deg": float(np.rad2deg(geo.rotation_error(est, truth))),
                    "translation_error_mm": float(geo.translation_error(est, truth)),
                    "field_error_mm": float(
                        np.linalg.norm(geo.apply(est, field_point) - geo.apply(truth, field_point))
                    ),
                    "estimate": est,
                }
            )
    return rows


def rps_trial(
    station: HybridStation,
    statcam2base: np.ndarray,
    rng: np.random.Generator,
    penalties=(1e4,),
) -> list[dict]:
    """Locate the panel once by the 3-2-1 rule with the calibrated stationary sensors A, B, C.

    The datum points are measured in the first three stationary sensors' frames with noise and
    mapped to the base frame with their calibrated poses ``statcam2base[:3]``. Returns one row
    per solver (the penalty LM for each ``M``, and the SO(3) solution) with the frame error: the
    largest displacement it causes at the panel's corners and datums (mm), and the rotation error.
    """
    free = np.zeros((3, 3))
    free[0, 0] = rng.uniform(-1, 1) * station.free_direction  # along the slot
    free[2, :2] = rng.uniform(-1, 1, 2) * station.free_direction  # within the plane
    work2base_true = geo.invert(station.base2work_true)
    datums_base_true = geo.apply(work2base_true, station.datums_work + free)
    measured = np.empty((3, 3))
    for j in range(3):
        in_cam = geo.apply(geo.invert(station.statcam2base_true[j]), datums_base_true[j])
        in_cam = in_cam + rng.normal(0.0, station.datum_sigma, 3)
        measured[j] = geo.apply(statcam2base[j], in_cam)
    corners = np.array([[0, 0, 0], [1500, 0, 0], [0, 1200, 0], [1500, 1200, 0]], dtype=float)
    check_pts_base = geo.apply(work2base_true, np.vstack([corners, station.datums_work]))
    rows = []
    solvers = [(f"penalty M={m:g}", m) for m in penalties] + [("SO(3)", None)]
    for name, m in solvers:
        if m is None:
            est = rps_frame_so3(measured, station.datums_work, station.base2work_nominal)
        else:
            est = rps_frame_penalty(
                measured, station.datums_work, station.base2work_nominal, penalty=m
            )
        disp = geo.apply(est.value, check_pts_base) - geo.apply(
            station.base2work_true, check_pts_base
        )
        r = est.value[:3, :3]
        rows.append(
            {
                "solver": name,
                "penalty": np.nan if m is None else m,
                "frame_error_mm": float(np.linalg.norm(disp, axis=1).max()),
                "rotation_error_deg": float(
                    np.rad2deg(geo.rotation_error(geo.project_to_so3(r), station.base2work_true))
                ),
                "orthogonality_defect": float(np.abs(r.T @ r - np.eye(3)).max()),
                "evaluations": est.iterations,
            }
        )
    return rows


def with_overrides(station: HybridStation, **changes) -> HybridStation:
    """A copy of ``station`` with some fields replaced."""
    return replace(station, **changes)


# ---------------------------------------------------------------------------------------------
# Monte Carlo runners (each trial has its own generator, spawned from the seed)

SCENARIOS = {
    # the paper's station: kinematic model error, repeatability and sensor noise
    "station": {"robot_errors": True},
    # sensor noise alone: true robot = nominal, no repeatability; the CRB applies exactly
    "sensor noise only": {"robot_errors": False, "repeatability_mm": 0.0},
}


def trial_generators(seed: int, n_trials: int, stream: int = 0) -> list[np.random.Generator]:
    """Independent generators for ``n_trials`` trials of experiment ``stream``, from ``seed``."""
    children = np.random.SeedSequence([seed, stream]).spawn(n_trials)
    return [np.random.default_rng(c) for c in children]


def log_progress(progress: bool, text: str) -> None:
    if progress:
        print(text, flush=True)


def handeye_monte_carlo(
    seed: int,
    n_trials: int,
    scenario: str = "station",
    n_trans: int = 4,
    n_rot: int = 6,
    sigma_point_mm: float | None = None,
    baselines: bool = True,
    stream: int = 0,
    progress: bool = False,
):
    """Hand-eye errors of every method over ``n_trials`` drawn stations (a long-format table).

    Columns: trial, scenario, n_trans, n_rot, sigma_point_mm, method, rotation_error_deg,
    translation_error_mm. The ``CRB`` rows hold the Cramer-Rao bound (expected RMS) of each trial.
    """
    import time

    import pandas as pd

    if scenario not in SCENARIOS:
        raise CalibrationError(f"unknown scenario {scenario!r}; use one of {list(SCENARIOS)}")
    start = time.perf_counter()
    rows = []
    for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
        station = make_station(rng, sigma_point_mm=sigma_point_mm, **SCENARIOS[scenario])
        sigma = station.sensor_sigma(rng)
        errors = handeye_trial(station, n_trans, n_rot, rng, sigma, baselines=baselines)
        for method, (rot, trans) in errors.items():
            rows.append(
                {
                    "trial": k,
                    "scenario": scenario,
                    "n_trans": n_trans,
                    "n_rot": n_rot,
                    "sigma_point_mm": station.laser.sigma_point_mm,
                    "method": method,
                    "rotation_error_deg": rot,
                    "translation_error_mm": trans,
                }
            )
    log_progress(
        progress,
        f"hand-eye, {scenario}, {n_trans}+{n_rot} moves, sigma "
        f"{rows[0]['sigma_point_mm']:g} mm: {n_trials} trials "
        f"in {time.perf_counter() - start:.1f} s",
    )
    return pd.DataFrame(rows)


def summarise_errors(df, by: list[str]):
    """RMS, median and 95th percentile of the rotation and translation errors per group."""
    import pandas as pd

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


def stationary_monte_carlo(
    seed: int, n_trials: int, scenario: str = "station", stream: int = 1, progress: bool = False
):
    """Stationary-sensor errors over ``n_trials`` stations, each with its own hand-eye run.

    Each trial draws a station, calibrates the flexible sensor by the paper's sphere method
    (4 + 6 moves), then the ten stationary sensors by Eq. 23. Returns (errors table with columns
    trial, scenario, sensor, variant, rotation_error_deg, translation_error_mm; RPS table, see
    :func:`rps_trial`, from the calibrated sensors A, B, C).
    """
    import time

    import pandas as pd

    start = time.perf_counter()
    rows, rps_rows = [], []
    for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
        station = make_station(rng, **SCENARIOS[scenario])
        meas, _ = simulate_sphere_measurements(station, 4, 6, rng)
        s2f = sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
        trial_rows = stationary_trial(station, s2f, rng)
        for r in trial_rows:
            rows.append(
                {"trial": k, "scenario": scenario} | {c: r[c] for c in r if c != "estimate"}
            )
        calibrated = np.array([r["estimate"] for r in trial_rows if r["variant"] == "homography"])
        for r in rps_trial(station, calibrated, rng):
            rps_rows.append({"trial": k, "scenario": scenario} | r)
    log_progress(
        progress,
        f"stationary sensors, {scenario}: {n_trials} trials in {time.perf_counter() - start:.1f} s",
    )
    return pd.DataFrame(rows), pd.DataFrame(rps_rows)


def rps_penalty_sweep(seed: int, penalties, n_trials: int, stream: int = 2):
    """How the 3-2-1 solution depends on the penalty ``M`` of Eq. 5, from two starting points.

    Per trial: a station with its true stationary calibration (so only datum noise matters), the
    datums measured once, then the penalty LM for every ``M`` from the nominal fixture pose and
    from a far start (the identity, i.e. no knowledge of the fixture), against the SO(3) solution
    on the same data. Failures (no convergence, a reflection) are counted, not hidden.
    """
    import pandas as pd

    rows = []
    for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
        station = make_station(rng)
        for start_name, start in (
            ("nominal fixture pose", station.base2work_nominal),
            ("identity", np.eye(4)),
        ):
            st = replace(station, base2work_nominal=start)
            try:
                trial = rps_trial(
                    st,
                    station.statcam2base_true,
                    np.random.default_rng([seed, k]),
                    penalties=penalties,
                )
            except CalibrationError:
                trial = []
            so3 = next((r for r in trial if r["solver"] == "SO(3)"), None)
            for m in penalties:
                r = next((r for r in trial if r["penalty"] == m), None)
                rows.append(
                    {
                        "trial": k,
                        "start": start_name,
                        "penalty": m,
                        "converged": r is not None,
                        "evaluations": np.nan if r is None else r["evaluations"],
                        "orthogonality_defect": np.nan if r is None else r["orthogonality_defect"],
                        "frame_error_mm": np.nan if r is None else r["frame_error_mm"],
                        "excess_over_so3_mm": np.nan
                        if r is None or so3 is None
                        else r["frame_error_mm"] - so3["frame_error_mm"],
                    }
                )
    return pd.DataFrame(rows)


def robot_accuracy(seed: int, n_robots: int, n_configs: int, stream: int = 3):
    """Absolute accuracy of drawn "true" robots against the nominal model (what the controller
    computes with): flange position and rotation errors over random configurations, per robot."""
    import pandas as pd

    from calstudy.models.kinematics import pose_errors

    nominal = load_robot("kuka_kr16_2")
    rows = []
    for k, rng in enumerate(trial_generators(seed, n_robots, stream)):
        true = perturb_robot(nominal, rng)
        pos, rot = pose_errors(nominal, true, nominal.random_configurations(rng, n_configs))
        rows.append(
            {
                "robot": k,
                "position_error_rms_mm": float(np.sqrt(np.mean(pos**2))),
                "position_error_max_mm": float(pos.max()),
                "rotation_error_rms_deg": float(np.rad2deg(np.sqrt(np.mean(rot**2)))),
            }
        )
    return pd.DataFrame(rows)


def calibrate_handeye(measurements_csv: str, seed: int, sensor_sigma_mm=None):
    """The fixed-sphere hand-eye from a user's CSV if given, else from one simulated run.

    Returns ``(source, measurements, paper_estimate, ml_estimate, table)`` where ``table`` lists
    ``sensor2flange`` (translation mm, rotation vector deg) by the paper's method and by the ML
    refinement with its standard deviations, and, for simulated data, the truth.
    """
    import pandas as pd

    from calstudy.estimators.handeye import read_sphere_measurements

    rng = np.random.default_rng([seed, 99])
    truth = None
    if measurements_csv:
        meas = read_sphere_measurements(measurements_csv)
        source = f"user measurements from {measurements_csv} ({len(meas.ids)} rows)"
        sigma = np.broadcast_to(np.asarray(sensor_sigma_mm, dtype=float), (3,))
    else:
        station = make_station(rng)
        meas, _ = simulate_sphere_measurements(station, 4, 6, rng)
        source = "one simulated run of the station (no user measurements given)"
        sigma = station.sensor_sigma(rng)
        truth = station.sensor2flange_true
    paper = sphere_handeye(*meas.select("translation"), *meas.select("rotation"))
    ml = sphere_handeye_ml(meas.flange2base, meas.centres, sigma, paper.value)
    names = ["tx_mm", "ty_mm", "tz_mm", "rx_deg", "ry_deg", "rz_deg"]
    scale = np.array([1, 1, 1, 180 / np.pi, 180 / np.pi, 180 / np.pi])
    table = pd.DataFrame(
        {
            "parameter": names,
            "paper_method": geo.pose_to_vector(paper.value) * scale,
            "ml": geo.pose_to_vector(ml.value) * scale,
            "ml_std": ml.std[:6] * scale,
        }
    )
    if truth is not None:
        table["truth"] = geo.pose_to_vector(truth) * scale
    return source, meas, paper, ml, table


def nominal_model_cost(handeye_summary, stationary_summary):
    """RMS errors of each step in both scenarios and their ratio (station / sensor noise only)."""
    import pandas as pd

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
    from calstudy.claims import verdict_vs_ml

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
