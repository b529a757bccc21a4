"""The synthetic cell of the ``selfcal`` paper: true stations, views, scans and tracker readings.

A drawn :class:`Station` is the "true" system (robot with manufacturing errors, base placement,
sensor mounting, sphere placements); :func:`simulate` moves it to planned views and returns what
the identification sees (:class:`calstudy.selfcal.identify.Measurements`), with the
scanner, repeatability and tracker noise of the scenario. Every function that draws takes the
``rng`` it draws from.

Frames: ``part`` (the tracker's), robot ``base``, ``flange`` and ``sensor``. Millimetres and
radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from calstudy.core.geometry import look_at, make_transform, rotvec_to_matrix
from calstudy.core.montecarlo import child_rng, streams
from calstudy.models.kinematics import Robot
from calstudy.models.robots import perturb_robot
from calstudy.papers.selfcal.scenario import Scenario
from calstudy.selfcal.identify import Measurements, check_sphere_layout, fit_sphere_cap
from calstudy.selfcal.model import (
    BASE,
    IS_LENGTH,
    N_PARAMS,
    ROBOT,
    SENSOR,
    default_model,
    parameters_from_robot,
    params_to_pose,
    pose_to_params,
)
from calstudy.selfcal.planning import ViewGeometry, draw_until, plan_views

# ----------------------------------------------------------------------------------------------
# the true station


def _random_motion(rng: np.random.Generator, sigma_mm: float, sigma_rad: float) -> np.ndarray:
    return make_transform(
        rotvec_to_matrix(rng.normal(0.0, sigma_rad, 3)), rng.normal(0.0, sigma_mm, 3)
    )


@dataclass
class Station:
    """A drawn "true" system and what is known of it before calibration.

    Attributes
    ----------
    true_robot : Robot
        Nominal robot plus manufacturing errors (``d2`` kept at 0, see :func:`draw_station`).
    part2base, sensor2flange : numpy.ndarray, shape (4, 4)
        True robot placement in the part frame and true sensor mounting.
    true_params, nominal_params : numpy.ndarray, shape (30,)
        The true system, and the "good" initial estimate: nominal robot, rough base pose from
        the layout, sensor pose from the bracket drawing.
    spheres_base : numpy.ndarray, shape (k, 3)
        Calibration sphere centres in the robot base frame (mm).
    """

    true_robot: Robot
    part2base: np.ndarray
    sensor2flange: np.ndarray
    true_params: np.ndarray
    nominal_params: np.ndarray
    spheres_base: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def spheres_part(self) -> np.ndarray:
        """True sphere centres in the part frame, (k, 3) mm."""
        return self.spheres_base @ self.part2base[:3, :3].T + self.part2base[:3, 3]


def view_geometry(scenario: Scenario) -> ViewGeometry:
    """The scenario's scanner as the view planning sees it: standoff, field, view cone, roll."""
    return ViewGeometry(
        scenario.scanner.standoff_mm,
        scenario.scanner.field_mm,
        scenario.scanner.depth_mm,
        math.radians(scenario.scanner.view_cone_deg),
        scenario.scanner.roll_deg,
    )


def draw_placements(scenario: Scenario, n: int, rng: np.random.Generator, tries: int = 1000):
    """``n`` sphere centres (n, 3) in the robot base frame, uniform in the envelope, spaced.

    Centres closer than ``min_separation_mm`` to an earlier one are redrawn.
    """
    spheres = scenario.spheres
    lo = np.array(spheres.envelope_min_mm, float)
    hi = np.array(spheres.envelope_max_mm, float)

    def draw(found: list[np.ndarray]) -> np.ndarray | None:
        c = rng.uniform(lo, hi)
        return c if all(np.linalg.norm(c - o) >= spheres.min_separation_mm for o in found) else None

    return draw_until(
        n,
        tries,
        draw,
        lambda _: (
            f"could not place {n} spheres {spheres.min_separation_mm:g} mm apart in the "
            f"envelope after {tries} draws"
        ),
    )


def draw_station(scenario: Scenario, rng: np.random.Generator) -> Station:
    """Draw a true system: manufacturing errors, base and sensor poses, four sphere placements.

    :func:`calstudy.models.robots.perturb_robot` perturbs every link parameter; the offset
    ``d2``
    along the axis of joint 2 is then set back to 0 because Eq. 2 has no such parameter (for
    parallel axes 2 and 3 it is carried by ``d3``), so the true system lies in the model class.
    The robot, the base, the sensor and the sphere placements draw from their own streams of
    ``rng`` (:func:`calstudy.core.montecarlo.streams`).
    """
    robot_rng, base_rng, sensor_rng, sites_rng = streams(
        rng, "robot", "base", "sensor", "sphere placements"
    )
    true_robot = perturb_robot(scenario.nominal_robot, robot_rng)
    vec = true_robot.parameters()
    vec[5 + 2] = 0.0  # d of link 2
    true_robot = true_robot.with_parameters(vec)
    base, sensor = scenario.base, scenario.sensor
    part2base = base.rough @ _random_motion(base_rng, base.sigma_mm, math.radians(base.sigma_deg))
    sensor2flange = sensor.design @ _random_motion(
        sensor_rng, sensor.sigma_mm, math.radians(sensor.sigma_deg)
    )
    spheres = draw_placements(scenario, scenario.spheres.count, sites_rng)
    check_sphere_layout(spheres, scenario.spheres.radius_mm)
    return Station(
        true_robot,
        part2base,
        sensor2flange,
        parameters_from_robot(true_robot, part2base, sensor2flange),
        parameters_from_robot(scenario.nominal_robot, scenario.base.rough, scenario.sensor.design),
        spheres,
    )


# ----------------------------------------------------------------------------------------------
# measurement simulation


def _cap_frame(centre_sensor: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) whose z column points from the centre ``(3,)`` to the sensor origin."""
    return look_at(np.zeros(3), -centre_sensor / np.linalg.norm(centre_sensor))[:3, :3]


def scan_cap(centre_sensor, radius_mm: float, half_angle: float, n: int, sigma: float, rng):
    """Points (n, 3) of the sphere cap facing the sensor origin, with isotropic normal noise.

    Area-uniform on the cap of half-angle ``half_angle`` (rad) around the direction from the
    centre to the sensor origin; sensor frame, mm.
    """
    c = np.asarray(centre_sensor, dtype=float)
    return _scan_cap(c, _cap_frame(c), radius_mm, half_angle, n, sigma, rng)


def _scan_cap(c, frame, radius_mm, half_angle, n, sigma, rng) -> np.ndarray:
    """:func:`scan_cap` with the cap's frame (columns x, y, z with z along the axis) given."""
    u = rng.uniform(math.cos(half_angle), 1.0, n)
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    s = np.sqrt(1.0 - u**2)
    local = np.empty((n, 3))
    local[:, 0] = s * np.cos(phi)
    local[:, 1] = s * np.sin(phi)
    local[:, 2] = u
    return c + radius_mm * local @ frame.T + rng.normal(0.0, sigma, (n, 3))


@cache
def _cap_covariance_local(radius_mm: float, half_angle: float, n: int, sigma: float):
    """The fitted centre's covariance (3, 3) in the cap's own frame (see the function below);
    it depends on the scalars only, so every view of a simulation shares it."""
    # second moments of the unit normal over the area-uniform cap, in the local frame
    cos_a = math.cos(half_angle)
    mean_u = (1.0 + cos_a) / 2.0
    mean_u2 = (1.0 + cos_a + cos_a**2) / 3.0
    mean_s2 = 1.0 - mean_u2
    gtg = np.zeros((4, 4))
    gtg[0, 0] = gtg[1, 1] = mean_s2 / 2.0
    gtg[2, 2] = mean_u2
    gtg[2, 3] = gtg[3, 2] = mean_u
    gtg[3, 3] = 1.0
    cov = sigma**2 / n * np.linalg.inv(gtg)[:3, :3]
    cov.flags.writeable = False
    return cov


def cap_centre_covariance(centre_sensor, radius_mm, half_angle, n, sigma) -> np.ndarray:
    """Covariance (3, 3) of the fitted centre of such a cap, to first order (for ML weights).

    The fit's linearisation: ``sigma^2 [(G^T G)^-1]_{:3,:3}`` with rows ``G_i = [n_i, 1]``
    (unit normals, radius), evaluated on the expected area-uniform point distribution.
    """
    frame = _cap_frame(np.asarray(centre_sensor, dtype=float))
    return frame @ _cap_covariance_local(radius_mm, half_angle, n, sigma) @ frame.T


def tracker_sigma(scenario: Scenario, points_part) -> np.ndarray:
    """Standard deviation per axis (mm) of the tracker's reading of each point (m, 3)."""
    t = scenario.tracker
    dist_m = np.linalg.norm(np.asarray(points_part, float), axis=-1) / 1000.0
    return (t.u0_mm + t.u1_mm_per_m * dist_m) / t.coverage / math.sqrt(3.0)


GRAVITY_MPS2 = 9.81


def link_gravity_torques(robot: Robot, q, masses_kg) -> np.ndarray:
    """Joint torques (6,) N m that the links' own weight loads the joints with at ``q`` (rad).

    Each link's mass (``masses_kg``, one per link) sits at the midpoint of the link, between the
    origins of its two DH frames; gravity acts along -z of the robot base frame. Joint ``j``
    carries the links from ``j`` outward and turns about the z axis of frame ``j - 1``.
    """
    frames = [robot.base]
    for link, angle in zip(robot.links, q, strict=True):
        frames.append(frames[-1] @ link.transform(angle))
    origins = np.array([f[:3, 3] for f in frames])
    centres = 0.5 * (origins[:-1] + origins[1:])
    weights = -np.asarray(masses_kg, float)[:, None] * GRAVITY_MPS2 * np.array([0.0, 0.0, 1.0])
    torque = np.zeros(len(robot.links))
    for j in range(len(robot.links)):
        axis, at = frames[j][:3, 2], origins[j]
        moments = np.cross(centres[j:] - at, weights[j:])
        torque[j] = float(axis @ moments.sum(axis=0))
    return torque / 1000.0


def joint_deflection(scenario: Scenario, robot: Robot, Q, scale: float | None = None):
    """Joint deflections (m, 6) rad of a compliant robot under the sensor's payload and the
    arm's own weight.

    Static joint compliance: ``K dq = J(q)^T F + tau_links(q)`` with ``F`` the payload's weight
    (-z of the robot base frame, ``payload_kg``) at the flange, ``J`` the flange Jacobian (mm/rad,
    so the torque is divided by 1000 for N m), ``tau_links`` the torques of the links' own
    weight (``link_masses_kg``, :func:`link_gravity_torques`) and ``K`` the joint stiffnesses of
    the scenario (N m/rad), multiplied by ``1/scale``. ``scale`` (default
    ``scenario.compliance.scale``) 0 removes the error: the true robot then lies in the model
    class.
    """
    scale = scenario.compliance.scale if scale is None else float(scale)
    Q = np.asarray(Q, float)
    if scale == 0.0:
        return np.zeros_like(Q)
    force = np.array([0.0, 0.0, -scenario.compliance.payload_kg * GRAVITY_MPS2])
    torque = np.array([robot.jacobian(q)[:3].T @ force for q in Q]) / 1000.0
    share = scenario.compliance.arm_weight_fraction
    masses = share * np.asarray(scenario.compliance.link_masses_kg, float)
    if share > 0 and masses.any():
        torque = torque + np.array([link_gravity_torques(robot, q, masses) for q in Q])
    return scale * torque / np.asarray(scenario.compliance.stiffness_nm_per_rad, float)


def _measure_view(scenario: Scenario, pose: np.ndarray, centre_part, rng, repeat, tracker):
    """One view of one sphere: the fitted centre ``C``, the noise-free one, their covariance.

    ``pose`` is the commanded sensor pose in the part frame (4, 4); the repeatability error is
    drawn here, then the scan. ``repeat`` and ``tracker`` (3, 3) are the parts of the covariance
    that do not change from view to view: the repeatability and the tracker's reading of this
    sphere. Returns ``C`` (3,), ``C_true`` (3,) and the covariance (3, 3) of ``P - P_ref`` in the
    part frame.
    """
    pose = pose.copy()
    pose[:3, 3] += rng.normal(0.0, scenario.repeatability.sigma_mm, 3)
    c_true = np.linalg.solve(pose, np.append(centre_part, 1.0))[:3]
    cap = (
        scenario.spheres.radius_mm,
        math.radians(scenario.scanner.cap_half_angle_deg),
        scenario.scanner.points_per_cap,
        scenario.scanner.sigma_point_mm,
    )
    frame = _cap_frame(c_true)
    cloud = _scan_cap(c_true, frame, *cap, rng)
    centre_fit, _, _ = fit_sphere_cap(cloud, scenario.scanner.max_fit_condition)
    cov_c = frame @ _cap_covariance_local(*cap) @ frame.T
    rot = pose[:3, :3]
    return centre_fit, c_true, rot @ cov_c @ rot.T + repeat + tracker


def simulate(
    scenario: Scenario,
    station: Station,
    placements_base,
    views_per_sphere: int,
    rng: np.random.Generator,
    compliance_scale: float | None = None,
    views: list[np.ndarray] | None = None,
) -> Measurements:
    """Measure each sphere placement (k, 3) from ``views_per_sphere`` robot positions.

    ``views`` (one (n_k, 6) array of joint angles per placement) replaces the planned views: the
    poses a selection chose (``views_per_sphere`` is then ignored; a placement without views is
    read by the tracker but not measured).

    The true system moves (true robot, true base and sensor, joint deflection under the payload
    by :func:`joint_deflection`, repeatability); the scanner returns a noisy cap whose LLS fit
    gives ``C``; the tracker reads each placement once with its noise. The measurements record
    the commanded joint angles ``Q`` (what the controller reports) and, for scoring, ``Q_true``.
    The tracker readings, each placement's planned views and each placement's scans draw from
    their own streams of ``rng`` (a new set at every call).
    """
    model = default_model()
    tracker_rng, views_rng, scans_rng = streams(rng, "tracker", "views", "scans")
    placements = np.asarray(placements_base, float)
    parts = station.part2base[:3, :3] @ placements.T
    truth_part = parts.T + station.part2base[:3, 3]
    reading = (
        truth_part
        + tracker_rng.normal(size=truth_part.shape) * tracker_sigma(scenario, truth_part)[:, None]
    )
    Q, Q_true, C, C_true, idx, cov, shared = [], [], [], [], [], [], []
    repeat = scenario.repeatability.sigma_mm**2 * np.eye(3)
    for k, centre in enumerate(placements):
        if views is None:
            planned = plan_views(
                scenario.nominal_robot,
                scenario.sensor.design,
                view_geometry(scenario),
                centre,
                views_per_sphere,
                child_rng(views_rng, str(k)),
            )
        elif len(views[k]) == 0:
            continue
        else:
            planned = np.asarray(views[k], float).reshape(-1, 6)
        stood = planned + joint_deflection(scenario, station.true_robot, planned, compliance_scale)
        poses = model.sensor2part(station.true_params, stood)
        tracker = tracker_sigma(scenario, truth_part[k]) ** 2 * np.eye(3)
        scans = child_rng(scans_rng, str(k))
        for q, q_true, pose in zip(planned, stood, poses, strict=True):
            centre_fit, c_true, cov_view = _measure_view(
                scenario, pose, truth_part[k], scans, repeat, tracker
            )
            Q.append(q)
            Q_true.append(q_true)
            C.append(centre_fit)
            C_true.append(c_true)
            idx.append(k)
            cov.append(cov_view)
            shared.append(tracker)
    return Measurements(
        np.array(Q),
        np.array(C),
        reading[np.array(idx)],
        np.array(idx),
        np.array(C_true),
        np.array(cov),
        np.array(shared),
        np.array(Q_true),
    )


# ----------------------------------------------------------------------------------------------
# initial estimates


def poor_start(
    scenario: Scenario, station: Station, rng: np.random.Generator, scale: float = 1.0
) -> np.ndarray:
    """The "very poor" initial estimate of ``scenario.poor_start`` around the true system.

    ``scale`` multiplies every offset of ``scenario.poor_start`` (the start distance of the basin
    sweep); the directions and signs drawn are the same for every scale.
    """
    p = np.empty(N_PARAMS)
    poor = scenario.poor_start

    def offset(true6, mm, deg):
        t = rng.normal(size=3)
        r = rng.normal(size=3)
        bad = params_to_pose(true6) @ make_transform(
            rotvec_to_matrix(math.radians(deg) * r / np.linalg.norm(r)),
            mm * t / np.linalg.norm(t),
        )
        return pose_to_params(bad)

    p[BASE] = offset(station.true_params[BASE], scale * poor.base_mm, scale * poor.base_deg)
    p[SENSOR] = offset(station.true_params[SENSOR], scale * poor.sensor_mm, scale * poor.sensor_deg)
    signs = rng.choice([-1.0, 1.0], size=18)
    size = np.where(
        IS_LENGTH[ROBOT], scale * poor.robot_length_mm, math.radians(scale * poor.robot_angle_deg)
    )
    p[ROBOT] = station.true_params[ROBOT] + signs * size
    return p
