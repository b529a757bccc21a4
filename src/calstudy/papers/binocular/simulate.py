"""The synthetic world of notebook 04: true robot and cameras, viewpoints, dot images, centres.

The simulated world moves a "true" robot that differs from the nominal model by the robot file's
tolerances, and images through "true" cameras that differ from Table 1 by the calibration
uncertainty of ``sensor.toml``. Each dot is rendered in a region of interest (ROI) of both
cameras: exact perspective and distortion, circle of confusion (Eq. 4) with the blur spot of the
scenario's mechanism (Eq. 7's symmetric Gaussian, or Eq. 7 cut off axis by a lens rim:
:func:`blur_spots`, :func:`blur`), two exposures fused (Eq. 3), sensor noise; its centre
is detected (Eq. 12), with and without the rectification (Eq. 8-11), and triangulated with the
calibrated sensor (Eq. 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import child_rng, streams
from calstudy.estimators import binocular as bino
from calstudy.estimators.coc import (
    detect_centre,
    detect_centres,
    image_gradients,
    rectify_coc,
    rectify_cocs,
)
from calstudy.models import exposure, optics
from calstudy.models.kinematics import Robot
from calstudy.models.robots import perturb_robot
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig
from calstudy.papers.binocular.scenario import Scenario, plate_frame
from calstudy.papers.binocular.schema import Cmm, Tracker

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
    cfg = scenario.station.poses
    t = target2base
    cone = math.radians(cfg.cone_deg) * math.sqrt(rng.uniform())
    phi = rng.uniform(0, 2 * math.pi)
    roll = math.radians(rng.uniform(-cfg.roll_deg, cfg.roll_deg))
    dist = cfg.observation_distance_mm + rng.uniform(-1, 1) * cfg.distance_spread_mm
    local = np.array(
        [math.sin(cone) * math.cos(phi), math.sin(cone) * math.sin(phi), math.cos(cone)]
    )
    view = t[:3, :3] @ local  # from the target towards the sensor
    aim = scenario.rig.aim_point(dist)
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
    the notebook, off in the noise-free tests. ``rectify``: run the rectification (Eq. 8-11)
    even on in-focus images (a null control: the method where its error source is absent)."""

    noise: bool = True
    defocus: bool = True
    rectify: bool = False


def blur_spots(scenario: Scenario, centres_cam) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The blur spot of each dot (camera frame, ``(m, 3)`` mm): CoC radius (Eq. 4, px), the side
    of the focused distance (+1 beyond, -1 nearer) and the lens rim's disc on the pupil at the
    dot's direction and depth (:func:`calstudy.models.optics.rim_shadow`, ``sensor.toml
    [optics]``).

    Returns ``(deltas (m,), sides (m,), rims (m, 3))``, a rim row being the disc's centre and
    radius in pupil radii.
    """
    c = np.asarray(centres_cam, dtype=float).reshape(-1, 3)
    opt = scenario.sensor.optics
    deltas = np.asarray(scenario.coc_radius_px(c[:, 2]), dtype=float).reshape(-1)
    sides = np.where(c[:, 2] >= opt.focus_distance_mm, 1.0, -1.0)
    centres, radii = optics.rim_shadow(c[:, :2] / c[:, 2:3], *_rim_inputs(scenario), c[:, 2])
    return deltas, sides, np.column_stack([centres, radii])


def _rim_inputs(scenario: Scenario) -> tuple[float, float, float, float]:
    """F-number, focal length, rim radius and rim distance of ``sensor.toml [optics]``."""
    opt = scenario.sensor.optics
    return (opt.f_number, scenario.focal_mm, opt.rim_radius_mm, opt.rim_distance_mm)


def blur(scenario: Scenario, sharp, deltas, sides, rims) -> list:
    """Defocus ``m`` sharp ROIs (a list of 2-D arrays, or a stack), each by its own blur spot
    of the scenario's mechanism (``sensor.toml [optics] mechanism``): the symmetric Gaussian of
    Eq. 7 (``gaussian``, :func:`calstudy.models.optics.defocus`) or Eq. 7 with the rim's cut
    (``rim``, :func:`calstudy.models.optics.defocus_vignetted`; ``rims`` as :func:`blur_spots`
    returns them): the list of blurred ROIs."""
    if scenario.sensor.optics.mechanism == "gaussian":
        return [optics.defocus(img, d) for img, d in zip(sharp, deltas, strict=True)]
    return [
        optics.defocus_vignetted(img, d, s, rim[:2], float(rim[2]))
        for img, d, s, rim in zip(sharp, deltas, sides, rims, strict=True)
    ]


def render_blurred_dot(scenario: Scenario, camera: PinholeCamera, centre, normal, delta_px=None):
    """Sharp image of a dot (camera frame: ``centre`` mm, unit ``normal``) in an ROI around
    it, blurred by its blur spot (:func:`blur_spots`; ``delta_px`` overrides the CoC radius,
    0: in focus).

    Returns ``(uv, origin, blurred)``: the projected centre ``(2,)`` px, the ROI's top-left
    pixel and the ROI.
    """
    centre = np.asarray(centre, dtype=float)
    uv = camera.project(centre.reshape(1, 3))[0]
    deltas, sides, rims = blur_spots(scenario, centre)
    if delta_px is not None:
        deltas = np.array([float(delta_px)])
    radius = scenario.dot_radius_mm
    r_px = radius * camera.fx / centre[2]
    margin = 4.0 * float(deltas[0]) + ROI_MARGIN_PX
    origin, shape = optics.roi_around(uv, r_px, margin, camera.width, camera.height)
    sharp = optics.render_dot(camera.K, camera.dist_coeffs, centre, normal, radius, origin, shape)
    return uv, origin, blur(scenario, [sharp], deltas, sides, rims)[0]


def expose_and_fuse(
    scenario: Scenario, blurred, rng, read_noise_dn: float, electrons_per_dn: float
) -> np.ndarray:
    """The exposures of ``sensor.toml [exposure]`` of a blurred ROI, fused (Eq. 3)."""
    exp = scenario.sensor.exposure
    return exposure.expose_and_fuse(
        blurred,
        exp.times_ms,
        exp.dot_peak_at_100ms,
        exp.background_at_100ms,
        read_noise_dn,
        electrons_per_dn,
        rng,
        exp.bits,
        exp.weight_contrast,
        exp.weight_exposure,
        exp.well_exposed_sigma,
    )


#: Margin of an ROI beyond the dot's edge besides the blur's reach (4 CoC radii), px: room for
#: the edge detection (:func:`render_rois`).
ROI_MARGIN_PX = 10.0


def render_rois(scenario, camera: PinholeCamera, centres_cam, normals_cam):
    """Sharp ROIs of ``m`` dots in one camera, each large enough for its dot with the margin its
    circle of confusion (Eq. 4) needs: ``4 delta + ROI_MARGIN_PX`` px beyond the dot's edge, as
    :func:`render_blurred_dot` (the blur spot reaches 4 delta; each ROI is sized by its own
    dot, so a dot near focus is not processed in the ROI of a blurred neighbour).

    Returns ``(sharp, origins, spots, radii)``: the list of ``m`` ROIs, their top-left pixels
    ``(m, 2)``, the true blur spots of :func:`blur_spots` (CoC radii, sides, rim discs) and the
    dots' radii in the image ``(m,)`` px.
    """
    centres = np.asarray(centres_cam, dtype=float)
    normals = np.asarray(normals_cam, dtype=float)
    deltas, sides, rims = blur_spots(scenario, centres)
    uv = camera.project(centres)
    radii = scenario.dot_radius_mm * camera.fx / centres[:, 2]
    origins, shapes = [], []
    for i in range(len(centres)):
        margin = 4.0 * float(deltas[i]) + ROI_MARGIN_PX
        origin, shape = optics.roi_around(uv[i], radii[i], margin, camera.width, camera.height)
        origins.append(origin)
        shapes.append(shape)
    sharp = optics.render_rois(
        camera.K, camera.dist_coeffs, centres, normals, scenario.dot_radius_mm, origins, shapes
    )
    return sharp, np.array(origins), (deltas, sides, rims), radii


def _in_focus_rois(sharp, origins, radii) -> tuple[list, np.ndarray]:
    """The ROIs of :func:`render_rois` cut to what an in-focus dot needs (the margin
    ``ROI_MARGIN_PX``, no blur), around the same centre pixel."""
    cut, starts = [], []
    for img, origin, r in zip(sharp, origins, radii, strict=True):
        half = (img.shape[0] - 1) // 2
        keep = int(math.ceil(r + ROI_MARGIN_PX))  # roi_around's half size without blur
        off = half - keep
        cut.append(img[off : off + 2 * keep + 1, off : off + 2 * keep + 1])
        starts.append(origin + off)
    return cut, np.array(starts)


def image_dots(
    scenario, camera: PinholeCamera, centres_cam, normals_cam, rng, imaging: Imaging, rendered=None
):
    """Fused ROIs of ``m`` dots in one camera: render (:func:`render_rois`, or the given
    ``rendered`` result of it), defocus (Eq. 4, 7), two exposures, fuse (Eq. 3), dot by dot.
    Without defocus the ROIs are those an in-focus dot needs (:func:`_in_focus_rois`), unless
    they are to be rectified (``imaging.rectify``).

    Returns ``(fused, origins, deltas, rendered)``: the list of ROIs, their top-left pixels
    ``(m, 2)``, the CoC radii ``(m,)`` applied (zeros without defocus) and the
    :func:`render_rois` result.
    """
    if rendered is None:
        rendered = render_rois(scenario, camera, centres_cam, normals_cam)
    sharp, origins, (true_deltas, sides, rims), radii = rendered
    if imaging.defocus:
        deltas = true_deltas
    else:
        deltas = np.zeros(len(true_deltas))
        if not imaging.rectify:  # the rectification needs the room of the blurred ROI
            sharp, origins = _in_focus_rois(sharp, origins, radii)
    blurred = blur(scenario, sharp, deltas, sides, rims)
    if not imaging.noise:
        return blurred, origins, deltas, rendered
    noise = scenario.sensor.noise
    fused = [
        expose_and_fuse(scenario, b, rng, noise.read_noise_dn, noise.electrons_per_dn)
        for b in blurred
    ]
    return fused, origins, deltas, rendered


def rectified_centre(scenario: Scenario, image, origin, delta_px: float) -> np.ndarray:
    """Dot centre ``(2,)`` px after the rectification (Eq. 8-11) with CoC radius ``delta_px``;
    below 1/3 px there is nothing to rectify and the image is used as it is."""
    fixed = rectify_coc(image, float(delta_px)) if delta_px >= 1.0 / 3.0 else image
    return detect_centre(fixed, origin, **scenario.detection)


@dataclass
class Observation:
    """Detected dot centres of one pose in both cameras, ``(2, m, 2)`` px (left, right):
    without (``uv_raw``) and with (``uv_rect``) the rectification."""

    uv_raw: np.ndarray
    uv_rect: np.ndarray
    rendered: tuple = ()  # per camera, the :func:`render_rois` result (oracle re-imaging)

    def points(self, sensor: StereoRig, tol_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """Sensor-frame points ``(m, 3)`` triangulated with the calibrated ``sensor`` (Eq. 1):
        without and with the rectification."""
        raw = bino.triangulate(sensor, self.uv_raw[0], self.uv_raw[1], tol_mm)
        if self.uv_rect is self.uv_raw:
            return raw, raw.copy()
        return raw, bino.triangulate(sensor, self.uv_rect[0], self.uv_rect[1], tol_mm)


def observe(
    scenario, model: StereoRig, sensor2base, dots_base, normal_base, rng, imaging, rendered=None
) -> Observation:
    """Image the dots ``(m, 3)`` (base frame, one plate normal) from a true sensor pose.

    The physical cameras are those of Table 1 (``scenario.rig``); the calibrated ``model``
    differs from them by the calibration errors of the trial. The rectification uses the CoC
    radius (Eq. 4) at the depth of the unrectified triangulation with ``model``, as a real
    system would. ``rendered`` (the ``Observation.rendered`` of an earlier call at the same
    true pose) skips the rendering: the same sharp images exposed again.
    """
    rois = []
    if rendered:
        for c, (camera, _) in enumerate(scenario.rig.cameras()):
            rois.append(image_dots(scenario, camera, None, None, rng, imaging, rendered[c]))
    else:
        base2sensor = geo.invert(sensor2base)
        dots_s = geo.apply(base2sensor, dots_base)
        normal_s = base2sensor[:3, :3] @ normal_base
        for camera, s2c in scenario.rig.cameras():
            n = np.tile(s2c[:3, :3] @ normal_s, (len(dots_s), 1))
            rois.append(image_dots(scenario, camera, geo.apply(s2c, dots_s), n, rng, imaging))
    kept = tuple(r[3] for r in rois)
    kwargs = scenario.detection
    grads = [[image_gradients(img) for img in f] for f, _, _, _ in rois]
    uv_raw = np.array(
        [
            detect_centres(f, org, **kwargs, gradients=g)
            for (f, org, _, _), g in zip(rois, grads, strict=True)
        ]
    )
    if not (imaging.defocus or imaging.rectify):
        return Observation(uv_raw, uv_raw, kept)
    tol = scenario.sensor.detection.ray_tolerance_mm
    raw = bino.triangulate(model, uv_raw[0], uv_raw[1], tol)
    uv_rect = uv_raw.copy()  # below 1/3 px the image is used as it is (rectified_centre)
    for c, (_, s2c) in enumerate(model.cameras()):
        est = np.atleast_1d(scenario.coc_radius_px(geo.apply(s2c, raw)[:, 2]))
        fused, origins, _, _ = rois[c]
        todo = np.flatnonzero(est >= 1.0 / 3.0)
        if todo.size:
            fixed = rectify_cocs([fused[i] for i in todo], est[todo], [grads[c][i] for i in todo])
            uv_rect[c, todo] = detect_centres(fixed, origins[todo], **kwargs)
    return Observation(uv_raw, uv_rect, kept)


# ----------------------------------------------------------------------------------------------
# the random truth of a trial


def uniform_disc(rng, n: int, radius: float) -> np.ndarray:
    """``n`` points ``(n, 3)`` uniform in a disc of ``radius`` in the plane ``z = 0``."""
    r = radius * np.sqrt(rng.uniform(size=n))
    a = rng.uniform(0, 2 * math.pi, n)
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(n)])


def sigma_distance_mm(table: Cmm | Tracker, length_mm) -> np.ndarray:
    """Standard deviation (mm) of a distance measured by an instrument with ``sigma_um`` +
    ``sigma_um_per_m`` (``[cmm]``, ``[laser_tracker]``)."""
    return 1e-3 * (table.sigma_um + table.sigma_um_per_m * np.asarray(length_mm) / 1000.0)


@dataclass
class World:
    """The random truth of one trial.

    The robot's and the cameras' errors are kept as seeds, so that :meth:`robot` and
    :meth:`model` give them at any scale from the same draws: at scale 2 the errors are exactly
    twice those at scale 1.
    """

    robot_seed: int
    camera_seed: int
    dot_offsets: np.ndarray  # (6, 3) calibrator frame
    standard_pairs: np.ndarray
    standard_mm: np.ndarray
    repeatability_mm: float  # sigma per axis of the true flange about the commanded pose
    _robots: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def robot(self, scenario: Scenario, scale: float = 1.0) -> Robot:
        """The true robot with its tolerances (``kuka_kr210.toml``) times ``scale`` (built once
        per nominal robot and scale, then shared: a robot's results depend on its parameters
        alone)."""
        tol = scenario.robot.tolerances
        sigmas = (tol["sigma_length_mm"] * scale, tol["sigma_angle_deg"] * scale)
        key = (scenario.robot.key(), sigmas)
        if key not in self._robots:
            rng = np.random.default_rng(self.robot_seed)
            self._robots[key] = perturb_robot(scenario.robot, rng, *sigmas)
        return self._robots[key]

    def model(self, scenario: Scenario, scale: float = 1.0) -> StereoRig:
        """The calibrated sensor: Table 1 plus the calibration errors of ``sensor.toml
        [calibration_uncertainty]`` times ``scale`` (0: the calibration is exact)."""
        if scale < 0:
            raise CalibrationError(f"calibration scale is {scale}; it must be >= 0")
        table = scenario.sensor.calibration_uncertainty.model_dump(exclude={"provenance"})
        sigmas = {k: v * scale for k, v in table.items()}
        return scenario.rig.perturbed(sigmas, np.random.default_rng(self.camera_seed))


def draw_world(scenario: Scenario, rng, imaging: Imaging | None = None) -> World:
    """Draw the true robot, the cameras' calibration errors, the SBR dot offsets and the CMM
    standards. Without ``imaging.noise`` the SBRs are centred, the CMM and the robot's
    repeatability exact (the robot and the cameras keep their errors: pass scale 0)."""
    imaging = imaging or Imaging()
    seeds = rng.integers(0, 2**63, size=2)
    sbr = scenario.calibrator.sbr
    offsets = uniform_disc(rng, 6, 1e-3 * sbr.dot_centring_um * imaging.noise)
    pairs = bino.all_pairs(8)
    lengths = np.linalg.norm(scenario.layout[pairs[:, 0]] - scenario.layout[pairs[:, 1]], axis=1)
    sigma = sigma_distance_mm(scenario.calibrator.cmm, lengths) * imaging.noise
    standard = lengths + sigma * rng.standard_normal(len(lengths))
    repeat = scenario.station.robot.repeatability_mm / 3.0 * imaging.noise
    return World(int(seeds[0]), int(seeds[1]), offsets, pairs, standard, repeat)


@dataclass
class Views:
    """Views of one target: joint angles ``q`` (n, 6) the controller commanded, the flange poses
    it reports ``flange2base`` (nominal model), the true flange poses ``true_flange2base``, the
    observations and the true sensor poses ``sensor2base`` (n, 4, 4) they were imaged from
    (repeatability included); ``redrawn``: viewpoints drawn again because a dot of their images
    could not be detected (an operator takes another view)."""

    q: np.ndarray
    flange2base: np.ndarray
    true_flange2base: np.ndarray
    observations: list
    sensor2base: np.ndarray | None = None
    redrawn: int = 0

    def reported(self, scenario: Scenario, world: World, robot_scale: float) -> np.ndarray:
        """Reported flange poses ``(n, 4, 4)`` had the true robot's errors been ``robot_scale``
        times those of the trial, for the same true flange poses (the images do not change):
        the controller commands the joints that put a robot with those errors at the default
        true pose, and reports the nominal model's pose of them. Scale 0: the truth (without
        repeatability)."""
        if robot_scale == 1.0:
            return self.flange2base
        true1 = world.robot(scenario, 1.0)
        robot = world.robot(scenario, robot_scale)
        out = []
        for q in self.q:
            q_s = robot.ik(true1.fk(q), q, tol=1e-9)
            out.append(scenario.robot.fk(q_s))
        return np.array(out)

    def points(self, model: StereoRig, tol_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """Triangulated points ``(n, m, 3)`` of all views with ``model``: raw and rectified
        (:meth:`Observation.points` of each view, triangulated as one batch)."""
        obs = self.observations
        sets = []  # (raw, rect) of each view in turn: the order Observation.points takes them
        for o in obs:
            sets.append(o.uv_raw)
            if o.uv_rect is not o.uv_raw:
                sets.append(o.uv_rect)
        uv = np.array(sets)  # (sets, 2 cameras, m, 2)
        pts = iter(bino.triangulate_sets(model, uv[:, 0], uv[:, 1], tol_mm))
        raw, rect = [], []
        for o in obs:
            raw.append(next(pts))
            rect.append(next(pts) if o.uv_rect is not o.uv_raw else raw[-1].copy())
        return np.array(raw), np.array(rect)


#: viewpoints drawn again, at most, for one view whose dots cannot be detected
MAX_REDRAWS = 5


def view_target(scenario, world, target2base, dots, normal, n, rng, imaging, model) -> Views:
    """``n`` views of dots ``(m, 3)`` (base frame) on a target frame ``target2base``.

    The viewpoints, the repeatability of each view and its images draw from their own streams of
    ``rng``. A view in which a dot cannot be detected (a strongly blurred dot whose edge the
    detector loses in the image noise) is replaced by another viewpoint, as an operator takes
    another view, at most :data:`MAX_REDRAWS` times per view; ``Views.redrawn`` counts them.
    """
    poses, repeat, images = streams(rng, "viewpoints", "repeatability", "images")
    true1 = world.robot(scenario, 1.0)
    qs, flanges, true_flanges, obs, sensors, redrawn = [], [], [], [], [], 0
    for i in range(int(n)):
        for attempt in range(MAX_REDRAWS + 1):
            (q,), (flange,) = viewpoints(scenario, target2base, 1, poses)
            t0 = true1.fk(q)
            sigma = world.repeatability_mm
            t = geo.perturb(t0, 0.0, sigma, repeat) if sigma else t0
            sensor2base = t @ scenario.sensor2flange
            noise = child_rng(images, f"view {i} attempt {attempt}")
            try:
                o = observe(scenario, model, sensor2base, dots, normal, noise, imaging)
            except CalibrationError:
                if attempt == MAX_REDRAWS:
                    raise
                redrawn += 1
                continue
            break
        qs.append(q)
        flanges.append(flange)
        true_flanges.append(t0)
        obs.append(o)
        sensors.append(sensor2base)
    return Views(
        np.array(qs), np.array(flanges), np.array(true_flanges), obs, np.array(sensors), redrawn
    )


def view_calibrator(scenario, world, n, rng, imaging, model) -> Views:
    """``n`` views of the calibrator's six SBRs."""
    dots = geo.apply(scenario.calibrator2base, scenario.layout[:6] + world.dot_offsets)
    normal = scenario.calibrator2base[:3, 2]
    return view_target(
        scenario, world, scenario.calibrator2base, dots, normal, n, rng, imaging, model
    )


def exact_points(scenario: Scenario, views: Views) -> np.ndarray:
    """The true SBR sphere centres of the calibrator in the sensor frame of each view
    ``(n, 6, 3)``, mm: the points free of any observed error (Eq. 16's ``X_c + dX_c``; the dots'
    offsets from the sphere centres are observed error too)."""
    centres = geo.apply(scenario.calibrator2base, scenario.layout[:6])
    return np.array([geo.apply(geo.invert(s2b), centres) for s2b in views.sensor2base])


def reimage(scenario, views: Views, rng, imaging, model) -> Views:
    """The same true poses (repeatability draw included) and the same sharp images exposed again
    under other ``imaging`` switches, with fresh image noise (oracle controls)."""
    obs = [
        observe(scenario, model, None, None, None, rng, imaging, rendered=o.rendered)
        for o in views.observations
    ]
    return Views(
        views.q, views.flange2base, views.true_flange2base, obs, views.sensor2base, views.redrawn
    )


def tracker_p7_distance(scenario: Scenario, rng, imaging: Imaging) -> float:
    """The laser tracker's distance from P7 to the base origin (Section 4.2), mm, with its
    error: the tracker measures the sphere centres (SMRs in the nests), not the dots."""
    lt = scenario.station.laser_tracker
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


def observe_field_region(scenario, world, k: int, rng, imaging, model) -> FieldRegion:
    """Draw field region ``k`` (``station.toml [field]``) and measure it from its poses."""
    cfg = scenario.station.field
    centre = np.array(cfg.centres_mm[k], dtype=float)
    normal = np.array(cfg.faces_point_mm, dtype=float) - centre
    region2base = plate_frame(centre, normal)
    layout = region_layout(cfg.standard_mm[k]) + uniform_disc(
        rng, 6, 1e-3 * scenario.calibrator.sbr.dot_centring_um * imaging.noise
    )
    dots = geo.apply(region2base, layout)
    views = view_target(
        scenario,
        world,
        region2base,
        dots,
        region2base[:3, 2],
        cfg.n_poses,
        rng,
        imaging,
        model,
    )
    tol = scenario.sensor.detection.ray_tolerance_mm
    _, pts = views.points(model, tol)  # (poses, 6, 3), rectified
    lt = scenario.station.laser_tracker
    true_d = np.linalg.norm(layout[:5] - layout[5], axis=1)
    standard = true_d + sigma_distance_mm(lt, true_d) * rng.standard_normal(5) * imaging.noise
    return FieldRegion(cfg.regions[k], cfg.names[k], views.flange2base, pts, standard)
