"""The simulated hybrid inspection station (hybrid paper, sections 2-4): the synthetic world.

The station has a KUKA KR 16-2 carrying a line-laser sensor (the flexible sensor), ten stationary
sensors on the fixture, a standard sphere, the two-sided 5 x 7 hole target and a panel located by
the 3-2-1 rule. All numbers come from ``data/hybrid/station.toml`` (paper facts and documented
assumptions, read by :func:`calstudy.papers.hybrid.scenario.load_station`). Two robots exist: the
*true* robot moves in the simulated world; the controller reports flange poses from the *nominal*
model, as the paper's station does.

Calibration poses are *taught*: the operator jogs the real robot until the sensor sees the sphere
(or the target sits over a stationary sensor), so the joint angles come from the true robot and
the reported flange pose is the nominal forward kinematics of those angles. Pure translations are
jogged in the controller's base frame, i.e. at constant *nominal* orientation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import streams
from calstudy.core.schema import file_key
from calstudy.estimators.fitting import solve_pnp
from calstudy.handeye.sphere_csv import SphereMeasurements
from calstudy.models.kinematics import Robot
from calstudy.models.reach import reach_bound
from calstudy.models.robots import load_robot, perturb_robot, robot_file
from calstudy.models.sensors import LineLaserSensor, PinholeCamera
from calstudy.models.targets import HoleTarget, ManufacturedHoleTarget, Sphere
from calstudy.papers.hybrid.scenario import load_station
from calstudy.papers.hybrid.schema import Stationary, StationFile, Target, Workpiece

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


def _rz(angle: float) -> np.ndarray:
    return geo.rotvec_to_matrix(np.array([0.0, 0.0, angle]))


RX_PI = np.diag([1.0, -1.0, -1.0])


#: the designed pure translations, in units of the ranges (along the laser line, across the
#: plane, along the viewing direction; the first is the reference pose): each move spans a new
#: direction, so the centred differences of Eq. 11 are never nearly collinear
DESIGNED_SHIFTS = np.array(
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, 1.0]]
)


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
    statcam2base_design: np.ndarray
    base2work_nominal: np.ndarray
    base2work_true: np.ndarray
    datums_work: np.ndarray
    datum_sigma: float
    free_direction: float
    config: StationFile | None = field(default=None, repr=False)
    translation_pattern: str = "random"
    # memos, not copied by dataclasses.replace: the sphere's reference pose depends on the
    # fields above (a station with other fields finds its own), the IK answers on the robot
    # and the pose only (their key)
    _sphere_ref: np.ndarray | None = field(default=None, init=False, repr=False)
    _ik_memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    # ------------------------------------------------------------------ robot motion

    def solve_ik(
        self, robot: Robot, flange2base: np.ndarray, q0=None, only_q0: bool = False
    ) -> np.ndarray:
        """Joint angles of ``robot`` for a flange pose, trying ``q0`` then the built-in seeds.

        Without ``q0`` the answer depends on the robot and the pose only; a station asks for the
        same one several times (its sphere reference pose: once to find it, once for the
        repeatability, once to teach the moves), so it is kept, by robot and pose.
        """
        if q0 is not None:
            return self._solve_ik(robot, flange2base, q0, only_q0)
        pose = np.asarray(flange2base, dtype=float)
        key = (robot.key(), pose.tobytes())
        if key not in self._ik_memo:
            self._ik_memo[key] = self._solve_ik(robot, pose, None, only_q0)
        return self._ik_memo[key].copy()

    def _solve_ik(self, robot: Robot, flange2base: np.ndarray, q0, only_q0: bool) -> np.ndarray:
        # a pose beyond the arm's reach fails from every seed (calstudy.models.reach proves
        # it): refuse it without the searches, which would only stall
        bound = reach_bound(robot)
        excess = bound.excess(flange2base)
        if excess > bound.margin_mm():
            raise CalibrationError(
                f"flange pose out of reach of the {robot.name}: its wrist point lies "
                f"{excess:.1f} mm beyond the arm's reach"
            )
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
        orientation, restricted to +-``across_plane_range_mm`` across the laser plane so the
        stripe stays on its side: drawn at random, or with ``translation_pattern`` "designed"
        at the corners of :data:`DESIGNED_SHIFTS` (the full ranges, along independent
        directions). Pose changes: the sensor tilted about the sphere centre by
        ``rotation_min_deg`` to ``rotation_range_deg`` about random axes, each taught on the true
        robot (all four from ``[calibration_moves]`` of ``station.toml``). Translations and
        pose changes draw from their own streams of ``rng``: a pose change drawn again because
        the robot cannot reach it does not shift the translations.
        """
        cfg = self.config.calibration_moves
        trans_rng, rot_rng = streams(rng, "translation moves", "rotation moves")
        ref = self.sphere_reference_pose()
        s2f = self.sensor2flange_true
        q_ref = self.solve_ik(self.true, ref @ geo.invert(s2f))
        f_ref = self.nominal.fk(q_ref)
        span = cfg.translation_range_mm
        across = cfg.across_plane_range_mm
        shifts = trans_rng.uniform(-1.0, 1.0, (n_trans, 3))
        if self.translation_pattern == "designed":
            shifts = DESIGNED_SHIFTS[np.arange(n_trans) % len(DESIGNED_SHIFTS)]
        elif self.translation_pattern != "random":
            raise CalibrationError(
                f"translation pattern {self.translation_pattern!r}; use 'random' or 'designed'"
            )
        shifts_sensor = shifts * np.array([span, across, span])
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
        rng = rot_rng
        while len(q_rot) < n_rot:
            # an operator teaches only poses the robot reaches: draw again when it cannot
            attempts += 1
            if attempts > 50 * n_rot:
                raise CalibrationError(f"only {len(q_rot)} of {n_rot} tilted poses are reachable")
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            angle = np.deg2rad(rng.uniform(cfg.rotation_min_deg, cfg.rotation_range_deg))
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
        sensor axis is the first (15 degree steps) that the nominal robot reaches at the sensor's
        design pose (searched once per sensor and cached), and the true robot is then taught from
        that configuration over the sensor where it truly sits (the operator sees its image).
        """
        statcam2base = self.statcam2base_true[index]
        front2flange = self.sensor2flange_true @ self.front2sensor

        def flange_for(yaw, back2front, where=statcam2base):
            back2statcam = geo.make_transform(RX_PI @ _rz(yaw), [0.0, 0.0, self.standoff])
            front2base = where @ back2statcam @ geo.invert(back2front)
            return front2base @ geo.invert(front2flange), back2statcam

        design = self.statcam2base_design[index]
        key = (
            index,
            design.tobytes(),
            float(self.standoff),
            front2flange.tobytes(),
            self.target.back2front().tobytes(),
            self.nominal.key(),
        )
        if key not in _STATIONARY_SEEDS:
            for yaw in np.deg2rad(np.arange(0.0, 360.0, 15.0)):
                pose, _ = flange_for(yaw, self.target.back2front(), design)
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


#: IK seeds of the stationary-sensor poses on the nominal robot, by sensor and every input of the
#: search (pure geometry cache)
_STATIONARY_SEEDS: dict = {}


def make_station(
    rng: np.random.Generator,
    *,
    robot_errors: bool = True,
    sigma_point_mm: float | None = None,
    pixel_sigma: float | None = None,
    repeatability_mm: float | None = None,
    robot_error_scale: float = 1.0,
    config: StationFile | None = None,
) -> HybridStation:
    """Draw a station: the true robot, the made target, the CMM value, the panel placement.

    Parameters
    ----------
    rng
        Source of every draw: the robot, the target, the stationary mounts and the workpiece
        placement each draw from their own stream of it
        (:func:`calstudy.core.montecarlo.streams`).
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
    config
        The station description (default :func:`calstudy.papers.hybrid.scenario.load_station`).
    """
    if not (np.isfinite(robot_error_scale) and robot_error_scale >= 0):
        raise CalibrationError(
            f"robot_error_scale is {robot_error_scale!r}; expected a finite factor >= 0"
        )
    cfg = load_station() if config is None else config
    robot_rng, target_rng, mount_rng, place_rng = streams(
        rng, "robot", "target", "stationary mounts", "workpiece"
    )
    nominal, true = _draw_robots(robot_rng, robot_errors, robot_error_scale)
    stripe = cfg.sensor
    laser = LineLaserSensor(
        sigma_point_mm=stripe.sigma_point_mm if sigma_point_mm is None else sigma_point_mm,
        n_points=stripe.n_points,
        arc_half_angle_deg=stripe.arc_half_angle_deg,
        centre_floor_mm=stripe.centre_floor_mm,
        correlation_scale=stripe.correlation_scale,
    )
    sphere = Sphere(radius_mm=cfg.sphere.radius_mm, centre=np.array(cfg.sphere.centre_mm))
    target, made, back2front_cmm = _make_target(cfg.target, target_rng)
    statcam2base_design = cfg.stationary.design
    statcam2base_true = _mount_stationary(statcam2base_design, cfg.stationary, mount_rng)
    standoff = stripe.standoff_mm
    wcfg = cfg.workpiece
    base2work_nominal, work2base_true = _place_workpiece(wcfg, place_rng)
    station = HybridStation(
        nominal=nominal,
        true=true,
        sensor2flange_true=cfg.handeye.sensor2flange,
        laser=laser,
        camera=cfg.cameras.camera,
        pixel_sigma=cfg.cameras.pixel_sigma if pixel_sigma is None else pixel_sigma,
        sphere=sphere,
        standoff=standoff,
        stripe_offset=stripe.stripe_offset_fraction * sphere.radius_mm,
        joint_sigma=0.0,
        target=target,
        target_made=made,
        back2front_cmm=back2front_cmm,
        front2sensor=geo.make_transform(RX_PI, [0.0, 0.0, standoff]),
        statcam2base_true=statcam2base_true,
        statcam2base_design=statcam2base_design,
        base2work_nominal=base2work_nominal,
        base2work_true=geo.invert(work2base_true),
        datums_work=wcfg.datums,
        datum_sigma=wcfg.datum_sigma_mm,
        free_direction=wcfg.free_direction_mm,
        config=cfg,
    )
    rep = cfg.robot.repeatability_mm if repeatability_mm is None else repeatability_mm
    station.joint_sigma = repeatability_joint_sigma(station, rep / 3.0)
    return station


def _draw_robots(
    rng: np.random.Generator, robot_errors: bool, robot_error_scale: float
) -> tuple[Robot, Robot]:
    """The nominal KUKA KR 16-2 and the true one drawn at ``robot_error_scale`` x its
    tolerances (the nominal one again without ``robot_errors``)."""
    nominal = _nominal_robot("kuka_kr16_2")
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
    return nominal, true


def _nominal_robot(name: str) -> Robot:
    """``load_robot(name)``, read once per process while its file is unchanged: the stations of a
    study share the nominal robot (only its Pinocchio scratch data is written, by every
    kinematics call afresh)."""
    key = file_key(robot_file(name))
    if key not in _NOMINAL:
        _NOMINAL.clear()
        _NOMINAL[key] = load_robot(name)
    return _NOMINAL[key]


#: the nominal robot of :func:`_nominal_robot`, by (resolved path, modification time, size)
_NOMINAL: dict = {}


def _make_target(
    tcfg: Target, rng: np.random.Generator
) -> tuple[HoleTarget, ManufacturedHoleTarget, np.ndarray]:
    """The hole target as designed and as made, and its ``back2front`` as the CMM measured it
    (``[target]``)."""
    target = HoleTarget()
    made = target.manufactured(rng)
    back2front_cmm = geo.perturb(
        made.back2front, np.deg2rad(tcfg.cmm_sigma_deg), tcfg.cmm_sigma_mm, rng
    )
    return target, made, back2front_cmm


def _mount_stationary(
    design: np.ndarray, st: Stationary, rng: np.random.Generator
) -> np.ndarray:
    """``statcam2base (10, 4, 4)`` where the stationary sensors truly sit: the design pose moved
    by the mounting tolerance of ``[stationary]`` read as 3 sigma per axis."""
    return geo.perturb(
        design,
        np.deg2rad(st.mounting_tolerance_deg) / 3.0,
        st.mounting_tolerance_mm / 3.0,
        rng,
    )


def _place_workpiece(
    wcfg: Workpiece, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``(base2work_nominal, work2base_true)``: the fixture pose of ``[workpiece]`` and the
    panel as clamped (one draw of the placement variation)."""
    work2base_nominal = geo.make_transform(
        _rz(np.deg2rad(wcfg.nominal_rotz_deg)), np.array(wcfg.nominal_origin_mm, dtype=float)
    )
    base2work_nominal = geo.invert(work2base_nominal)
    work2base_true = geo.perturb(
        work2base_nominal, np.deg2rad(wcfg.placement_sigma_deg), wcfg.placement_sigma_mm, rng
    )
    return base2work_nominal, work2base_true


def repeatability_joint_sigma(station: HybridStation, sigma_pos: float) -> float:
    """Joint noise (rad) whose flange scatter at the sphere pose is ``sigma_pos`` mm per axis."""
    if sigma_pos == 0:
        return 0.0
    ref = station.sphere_reference_pose()
    q = station.solve_ik(station.true, ref @ geo.invert(station.sensor2flange_true))
    jv = station.true.jacobian(q)[:3]
    return float(sigma_pos / np.sqrt(np.sum(jv**2) / 3.0))


def simulate_sphere_measurements(
    station: HybridStation, n_trans: int, n_rot: int, rng: np.random.Generator
) -> tuple[SphereMeasurements, np.ndarray]:
    """One fixed-sphere calibration run: the measurements and the actual flange poses. The
    moves and the measurements draw from their own streams of ``rng``."""
    moves, noise = streams(rng, "moves", "measurements")
    q_t, q_r = station.sphere_moves(n_trans, n_rot, moves)
    q = np.concatenate([q_t, q_r])
    reported, centres, actual = station.measure_sphere(q, noise)
    meas = SphereMeasurements(
        ids=np.arange(len(q)),
        group=np.array(["translation"] * n_trans + ["rotation"] * n_rot),
        flange2base=reported,
        centres=centres,
    )
    return meas, actual

