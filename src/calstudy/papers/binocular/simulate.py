"""The synthetic world of notebook 04: true robot and cameras, viewpoints, dot images, centres.

The simulated world moves a "true" robot that differs from the nominal model by the robot file's
tolerances, and images through "true" cameras that differ from Table 1 by the calibration
uncertainty of ``sensor.toml``. Each dot is rendered in a region of interest (ROI) of both
cameras: exact perspective and distortion, circle of confusion (Eq. 4, 7), two exposures fused
(Eq. 3), sensor noise; its centre is detected (Eq. 12), with and without the rectification
(Eq. 8-11), and triangulated with the calibrated sensor (Eq. 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators import binocular as bino
from calstudy.estimators.coc import detect_centre, rectify_coc
from calstudy.models import optics
from calstudy.models.kinematics import Robot, perturb_robot
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig
from calstudy.papers.binocular.scenario import Scenario, plate_frame

#: Viewpoints drawn per requested pose before :func:`viewpoints` gives up (unreachable target).
MAX_VIEW_TRIES = 20


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


def _draw_sensor_pose(scenario: Scenario, target2base: np.ndarray, rng) -> np.ndarray:
    """One ``sensor2base`` viewing the target: direction in the cone, roll, distance."""
    cfg = scenario.config["station"]["poses"]
    t = target2base
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
    return geo.make_transform(rot, t[:3, 3] - rot @ aim)


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
    t = np.asarray(target2base, dtype=float)
    qs, flanges = [], []
    for _ in range(MAX_VIEW_TRIES * n):
        if len(qs) == n:
            break
        sensor2base = _draw_sensor_pose(scenario, t, rng)
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


@dataclass
class Imaging:
    """Switches of the imaging model: ``noise`` (image noise, camera-calibration errors, SBR dot
    offsets, CMM and tracker errors, robot repeatability) and ``defocus`` (Eq. 4, 7); both on in
    the notebook, off in the noise-free tests."""

    noise: bool = True
    defocus: bool = True


def render_blurred_dot(scenario: Scenario, camera: PinholeCamera, centre, normal, delta_px):
    """Sharp image of a dot (camera frame: ``centre`` mm, unit ``normal``) in an ROI around
    it, blurred by the circle of confusion ``delta_px`` (Eq. 7).

    Returns ``(uv, origin, blurred)``: the projected centre ``(2,)`` px, the ROI's top-left
    pixel and the ROI.
    """
    uv = camera.project(np.asarray(centre, dtype=float).reshape(1, 3))[0]
    radius = scenario.dot_radius_mm
    r_px = radius * camera.fx / centre[2]
    origin, shape = optics.roi_around(uv, r_px, 4.0 * delta_px + 10.0, camera.width, camera.height)
    sharp = optics.render_dot(
        camera.K, camera.dist_coeffs, centre, normal, radius, origin, shape
    )
    return uv, origin, optics.defocus(sharp, delta_px)


def expose_and_fuse(
    scenario: Scenario, blurred, rng, read_noise_dn: float, electrons_per_dn: float
) -> np.ndarray:
    """The exposures of ``sensor.toml [exposure]`` of a blurred ROI, fused (Eq. 3)."""
    exp = scenario.config["sensor"]["exposure"]
    shots = [
        optics.expose(
            blurred,
            t,
            exp["dot_peak_at_100ms"],
            exp["background_at_100ms"],
            read_noise_dn,
            electrons_per_dn,
            rng,
            exp["bits"],
        )
        for t in exp["times_ms"]
    ]
    return optics.fuse_exposures(
        shots, exp["weight_contrast"], exp["weight_exposure"], exp["well_exposed_sigma"]
    )


def image_dot(scenario, camera: PinholeCamera, centre_cam, normal_cam, rng, imaging: Imaging):
    """Fused ROI of one dot in one camera: render, defocus (Eq. 4, 7), two exposures, fuse (Eq. 3).

    Returns ``(fused, origin, delta_px)``: the ROI, its top-left pixel, the true CoC radius.
    """
    delta = float(scenario.coc_radius_px(centre_cam[2])) if imaging.defocus else 0.0
    _, origin, blurred = render_blurred_dot(scenario, camera, centre_cam, normal_cam, delta)
    if not imaging.noise:
        return blurred, origin, delta
    noise = scenario.config["sensor"]["noise"]
    fused = expose_and_fuse(
        scenario, blurred, rng, noise["read_noise_dn"], noise["electrons_per_dn"]
    )
    return fused, origin, delta


def rectified_centre(scenario: Scenario, image, origin, delta_px: float) -> np.ndarray:
    """Dot centre ``(2,)`` px after the rectification (Eq. 8-11) with CoC radius ``delta_px``;
    below 1/3 px there is nothing to rectify and the image is used as it is."""
    fixed = rectify_coc(image, float(delta_px)) if delta_px >= 1.0 / 3.0 else image
    return detect_centre(fixed, origin, **scenario.detection)


@dataclass
class Observation:
    """Dot centres of one pose: image points and triangulated sensor-frame points."""

    uv_raw: np.ndarray  # (2, m, 2) left/right
    uv_rect: np.ndarray
    raw: np.ndarray  # (m, 3) sensor frame, without rectification
    rect: np.ndarray  # (m, 3) with rectification


def observe(scenario, true_sensor: StereoRig, sensor2base, dots_base, normal_base, rng, imaging):
    """Image the dots ``(m, 3)`` (base frame, one plate normal) from a true sensor pose.

    The physical cameras are ``true_sensor``; centres are triangulated with the calibrated
    ``scenario.sensor`` (Table 1). The rectification uses the CoC radius (Eq. 4) at the depth
    of the unrectified triangulation, as a real system would.
    """
    base2sensor = geo.invert(sensor2base)
    dots_s = geo.apply(base2sensor, dots_base)
    normal_s = base2sensor[:3, :3] @ normal_base
    rois = [
        [
            image_dot(scenario, camera, geo.apply(s2c, p), s2c[:3, :3] @ normal_s, rng, imaging)
            for p in dots_s
        ]
        for camera, s2c in true_sensor.cameras()
    ]
    kwargs = scenario.detection
    uv_raw = np.array([[detect_centre(img, o, **kwargs) for img, o, _ in row] for row in rois])
    tol = scenario.config["sensor"]["detection"]["ray_tolerance_mm"]
    raw = bino.triangulate(scenario.sensor, uv_raw[0], uv_raw[1], tol)
    if not imaging.defocus:
        return Observation(uv_raw, uv_raw.copy(), raw, raw.copy())
    uv_rect = np.empty_like(uv_raw)
    for c, (_, s2c) in enumerate(scenario.sensor.cameras()):
        est = scenario.coc_radius_px(geo.apply(s2c, raw)[:, 2])
        for i, (img, o, _) in enumerate(rois[c]):
            uv_rect[c, i] = rectified_centre(scenario, img, o, est[i])
    rect = bino.triangulate(scenario.sensor, uv_rect[0], uv_rect[1], tol)
    return Observation(uv_raw, uv_rect, raw, rect)


# ----------------------------------------------------------------------------------------------
# the random truth of a trial


def uniform_disc(rng, n: int, radius: float) -> np.ndarray:
    """``n`` points ``(n, 3)`` uniform in a disc of ``radius`` in the plane ``z = 0``."""
    r = radius * np.sqrt(rng.uniform(size=n))
    a = rng.uniform(0, 2 * math.pi, n)
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(n)])


def sigma_distance_mm(table: dict, length_mm) -> np.ndarray:
    """Standard deviation (mm) of a distance measured by an instrument with ``sigma_um`` +
    ``sigma_um_per_m`` (``[cmm]``, ``[laser_tracker]``)."""
    return 1e-3 * (table["sigma_um"] + table["sigma_um_per_m"] * np.asarray(length_mm) / 1000.0)


@dataclass
class World:
    """The random truth of one trial."""

    robot: Robot
    sensor: StereoRig
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
    offsets = uniform_disc(rng, 6, 1e-3 * sbr["dot_centring_um"] * imaging.noise)
    pairs = bino.all_pairs(8)
    lengths = np.linalg.norm(scenario.layout[pairs[:, 0]] - scenario.layout[pairs[:, 1]], axis=1)
    sigma = sigma_distance_mm(scenario.config["calibrator"]["cmm"], lengths) * imaging.noise
    return World(robot, sensor, offsets, pairs, lengths + sigma * rng.standard_normal(len(lengths)))


def _true_sensor_pose(scenario, world, q, rng, noise: bool) -> np.ndarray:
    flange = world.robot.fk(q)
    if noise:
        sigma = scenario.config["station"]["robot"]["repeatability_mm"] / 3.0
        flange = geo.perturb(flange, 0.0, sigma, rng)
    return flange @ scenario.sensor2flange


def observe_from(scenario, world, q, dots, normal, rng, imaging) -> list[Observation]:
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


def view_calibrator(scenario, world, n, rng, imaging) -> tuple[np.ndarray, list[Observation]]:
    """``n`` views of the calibrator: reported flange poses ``(n, 4, 4)`` and observations."""
    q, flange = viewpoints(scenario, scenario.calibrator2base, n, rng)
    dots = geo.apply(scenario.calibrator2base, scenario.layout[:6] + world.dot_offsets)
    normal = scenario.calibrator2base[:3, 2]
    return flange, observe_from(scenario, world, q, dots, normal, rng, imaging)


def tracker_p7_distance(scenario: Scenario, rng, imaging: Imaging) -> float:
    """The laser tracker's distance from P7 to the base origin (Section 4.2), mm, with its
    error: the tracker measures the sphere centres (SMRs in the nests), not the dots."""
    lt = scenario.config["station"]["laser_tracker"]
    p7_standard = float(np.linalg.norm(geo.apply(scenario.calibrator2base, scenario.layout[6])))
    p7_standard += float(sigma_distance_mm(lt, p7_standard) * rng.standard_normal()) * imaging.noise
    return p7_standard


# ----------------------------------------------------------------------------------------------
# field regions (Section 4.3)


def region_layout(standard_mm) -> np.ndarray:
    """Six SBRs of a field region: five at the given distances around the sixth (the centre),
    72 deg apart, in the region's plane; ``(6, 3)`` in the region frame."""
    d = np.asarray(standard_mm, dtype=float)
    a = np.radians(72.0 * np.arange(5))
    return np.vstack([np.column_stack([d * np.cos(a), d * np.sin(a), np.zeros(5)]), np.zeros(3)])


@dataclass
class FieldRegion:
    """One field region as measured (Table 5): reported flange poses ``(p, 4, 4)``, the
    rectified sensor-frame SBR centres ``(p, 6, 3)`` and the tracker's standard distances ``(5,)``
    from the first five SBRs to the sixth."""

    region: str
    names: list
    flange2base: np.ndarray
    points: np.ndarray
    standard: np.ndarray


def observe_field_region(scenario, world, k: int, rng, imaging) -> FieldRegion:
    """Draw field region ``k`` (``station.toml [field]``) and measure it from its poses."""
    cfg = scenario.config["station"]["field"]
    centre = np.array(cfg["centres_mm"][k], dtype=float)
    normal = np.array(cfg["faces_point_mm"], dtype=float) - centre
    region2base = plate_frame(centre, normal)
    layout = region_layout(cfg["standard_mm"][k]) + uniform_disc(
        rng, 6, 1e-3 * scenario.config["calibrator"]["sbr"]["dot_centring_um"] * imaging.noise
    )
    q, flange = viewpoints(scenario, region2base, cfg["n_poses"], rng)
    dots = geo.apply(region2base, layout)
    obs = observe_from(scenario, world, q, dots, region2base[:3, 2], rng, imaging)
    pts = np.array([o.rect for o in obs])  # (poses, 6, 3)
    lt = scenario.config["station"]["laser_tracker"]
    true_d = np.linalg.norm(layout[:5] - layout[5], axis=1)
    standard = true_d + sigma_distance_mm(lt, true_d) * rng.standard_normal(5) * imaging.noise
    return FieldRegion(cfg["regions"][k], cfg["names"][k], flange, pts, standard)
