"""The synthetic world of the ``dualarm`` paper: camera poses, robot errors, detections, scans.

The simulated station (:class:`~calstudy.papers.dualarm.schema.Scenario`) knows the true
transforms; what these functions hand on is what the calibration sees: the flange poses the robots
*report* (true poses spoiled by repeatability and, during multi-view scans, by drift), marker and
plate-circle centres in the images, and point clouds in the left camera frame.

Frames: ``cam2world`` places the left camera in the marker (world) frame, ``world2cam`` is its
inverse, ``flange2base`` the flange in its robot base. Millimetres, radians, pixels.
"""

from __future__ import annotations

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.stereo_views import View, make_view
from calstudy.models.targets import circle_centre_bias
from calstudy.papers.dualarm.schema import ARMS, Scenario

# ----------------------------------------------------------------------------------------------
# poses


def view_poses(
    rng: np.random.Generator,
    target,
    distance_mm: float,
    n: int,
    tilt: float,
    axis=(0.0, 0.0, 1.0),
    up=None,
    roll: float | None = None,
) -> np.ndarray:
    """``cam2world`` ``(n, 4, 4)`` of cameras ``distance_mm`` from ``target``, looking at it from
    directions within ``tilt`` rad of ``axis`` (uniform in the cone). The image is rotated at
    random about the optical axis unless ``up`` fixes it; with ``roll``, by a uniform angle within
    ``+-roll`` rad of the orientation ``up`` (default: a fixed direction normal to ``axis``)
    gives, as an operator turns the sensor a little between views rather than at random."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    out = np.empty((n, 4, 4))
    cos_t = 1.0 - rng.random(n) * (1.0 - np.cos(tilt))
    phi = rng.random(n) * 2 * np.pi
    spin = rng.random(n) * 2 * np.pi
    turn = (2.0 * rng.random(n) - 1.0) * (roll or 0.0)
    for k in range(n):
        s = np.sqrt(1.0 - cos_t[k] ** 2)
        d = cos_t[k] * a + s * (np.cos(phi[k]) * e1 + np.sin(phi[k]) * e2)
        if roll is not None:
            ref = np.asarray(up if up is not None else e1, dtype=float)
            u = geo.rotvec_to_matrix(d * turn[k]) @ ref
        else:
            u = up if up is not None else np.cos(spin[k]) * e1 + np.sin(spin[k]) * e2
        out[k] = geo.look_at(np.asarray(target) + distance_mm * d, target, up=u)
    return out


def pose_errors(scn: Scenario, n: int, rng: np.random.Generator, drift: bool) -> np.ndarray:
    """Errors ``E`` ``(n, 4, 4)`` of reported flange poses: ``true = reported @ E``.

    Repeatability on every pose; with ``drift``, a random walk from the first pose adds the
    attitude drift of a multi-view scan.
    """
    rep = geo.perturb(
        np.tile(np.eye(4), (n, 1, 1)), scn.robot.repeat_sigma_rad, scn.robot.repeat_sigma_mm, rng
    )
    if not drift:
        return rep
    steps = geo.perturb(
        np.tile(np.eye(4), (n, 1, 1)), scn.robot.drift_step_rad, scn.robot.drift_step_mm, rng
    )
    walk = np.empty_like(steps)
    walk[0] = np.eye(4)
    for k in range(1, n):
        walk[k] = walk[k - 1] @ steps[k]
    return walk @ rep


def arm_poses(
    scn: Scenario, arm: int, cam2world, rng: np.random.Generator, drift: bool
) -> tuple[np.ndarray, np.ndarray]:
    """True and reported ``flange2base`` ``(n, 4, 4)`` that put arm ``arm``'s left camera at
    ``cam2world``."""
    a = arm - 1
    true = scn.world2base[a] @ np.asarray(cam2world) @ geo.invert(scn.calibration.cam2flange[a])
    reported = true @ geo.invert(pose_errors(scn, len(true), rng, drift))
    return true, reported


def mid_point(scn: Scenario) -> np.ndarray:
    """World point ``(3,)`` halfway between the centres of the two marker groups."""
    return 0.5 * (scn.markers.group_centre(1) + scn.markers.group_centre(2))


def plate_place(scn: Scenario) -> np.ndarray:
    """Centre ``(3,)`` of Table 3's circular plate (world): on the table (z = 0),
    ``circular_plate.offset_mm`` (x, y) from the point between the marker groups."""
    mid = mid_point(scn)
    dx, dy = scn.circular_plate.offset_mm
    return np.array([mid[0] + dx, mid[1] + dy, 0.0])


# ----------------------------------------------------------------------------------------------
# images of the markers and of the calibration plate


def _bias(camera_k, points_cam, normal_cam, radius: float) -> np.ndarray:
    """Perspective bias ``(N, 2)`` (px) of circular targets of ``radius`` at ``points_cam``
    facing ``normal_cam`` (3,), in the camera with intrinsics ``camera_k``."""
    normals = np.broadcast_to(normal_cam, np.shape(points_cam))
    return circle_centre_bias(camera_k, points_cam, normals, radius)


def observe_markers(scn: Scenario, world2cam, rng: np.random.Generator) -> View:
    """Markers detected in one stereo pair: visible in both images and facing the camera, each
    lost with probability ``detection.loss_rate``; each centre is the centre of the marker
    circle's image ellipse (perspective bias for ``detection.marker_radius_mm``) with
    ``detection.sigma_px`` noise."""
    w2c = np.asarray(world2cam)
    pl = geo.apply(w2c, scn.markers.xyz)
    pr = geo.apply(scn.rig.left2right, pl)
    eye = geo.invert(w2c)[:3, 3]
    to_cam = eye - scn.markers.xyz
    cos_view = to_cam[:, 2] / np.linalg.norm(to_cam, axis=1)  # markers face world +z
    front = (pl[:, 2] > 0) & (pr[:, 2] > 0) & (cos_view > np.cos(scn.detection.max_view_angle))
    ul = np.full((len(pl), 2), -1e9)
    ur = np.full((len(pl), 2), -1e9)
    ul[front] = scn.rig.left.project(pl[front])
    ur[front] = scn.rig.right.project(pr[front])
    seen = front & scn.rig.left.in_image(ul) & scn.rig.right.in_image(ur)
    if scn.detection.marker_radius_mm > 0.0 and np.any(front):
        up_l = w2c[:3, :3] @ [0.0, 0.0, 1.0]
        up_r = scn.rig.left2right[:3, :3] @ up_l
        ul[front] += _bias(scn.rig.left.K, pl[front], up_l, scn.detection.marker_radius_mm)
        ur[front] += _bias(scn.rig.right.K, pr[front], up_r, scn.detection.marker_radius_mm)
    seen &= rng.random(len(pl)) >= scn.detection.loss_rate
    noise = rng.normal(0.0, scn.detection.sigma_px, (2, len(pl), 2))
    ids = np.flatnonzero(seen)
    return make_view(ids, ul[ids] + noise[0, ids], ur[ids] + noise[1, ids])


def plate_images(
    scn: Scenario,
    plate2world,
    cam2world,
    rng: np.random.Generator,
    outliers: bool = False,
    sigma_px: float | None = None,
) -> np.ndarray:
    """Circle centres ``(n, N, 2)`` (px) of the plate at ``plate2world`` in the left image of
    each of the ``n`` cameras ``cam2world``: the centres of the circles' image ellipses
    (perspective bias for ``handeye.circle_radius_mm``), with ``sigma_px`` noise (the scenario's
    unless given); with ``outliers``, a fraction ``circular_plate.outlier_rate`` of them moved by
    ``circular_plate.outlier_px`` in a random direction (gross detection errors)."""
    uvs = np.empty((len(cam2world), len(scn.handeye.plate_points), 2))
    for k, c2w in enumerate(cam2world):
        true = geo.invert(c2w) @ plate2world
        sig = scn.detection.sigma_px if sigma_px is None else sigma_px
        uv = scn.rig.left.observe(true, scn.handeye.plate_points, sig, rng)
        if scn.handeye.circle_radius_mm > 0.0:
            pts = geo.apply(true, scn.handeye.plate_points)
            uv += _bias(scn.rig.left.K, pts, true[:3, 2], scn.handeye.circle_radius_mm)
        if outliers:
            bad = rng.random(len(uv)) < scn.circular_plate.outlier_rate
            lo, hi = scn.circular_plate.outlier_px
            mag = rng.uniform(lo, hi, len(uv))
            ang = rng.uniform(0, 2 * np.pi, len(uv))
            uv[bad] += (mag * np.column_stack([np.cos(ang), np.sin(ang)]).T).T[bad]
        uvs[k] = uv
    return uvs


def handeye_images(scn: Scenario, arm: int, rng: np.random.Generator):
    """Arm ``arm`` images the plate (at its marker group) from ``handeye.n_poses`` poses:
    ``(reported flange2base (n, 4, 4), circle centres (n, N, 2))``."""
    plate2world = geo.make_transform(np.eye(3), scn.markers.group_centre(arm))
    cam2world = view_poses(
        rng,
        plate2world[:3, 3],
        scn.sensor.working_distance_mm,
        scn.handeye.n_poses,
        scn.handeye.tilt,
        roll=scn.handeye.roll,
    )
    _, reported = arm_poses(scn, arm, cam2world, rng, drift=False)
    return reported, plate_images(scn, plate2world, cam2world, rng)


def circular_plate_images(
    scn: Scenario, rng: np.random.Generator, sigma_px: float | None = None
) -> list:
    """Table 3's comparison: a circle plate in the overlapping field, on the table beside the
    sphere stand (``circular_plate.offset_mm`` from the point between the marker groups), each
    arm images it from ``global_test.calibration_poses`` poses from its own side, with gross
    detection errors and circle centres good to ``sigma_px`` (calibrated to the paper's plate
    figure, rule 11; the scenario's marker noise unless given). Per arm ``(reported flange2base
    (n, 4, 4), circle centres (n, N, 2))``."""
    plate2world = geo.make_transform(np.eye(3), plate_place(scn))
    out = []
    for arm, side in zip(ARMS, (1.0, -1.0), strict=True):
        axis = (0.0, side * np.sin(scn.circular_plate.tilt), np.cos(scn.circular_plate.tilt))
        cam2world = view_poses(
            rng,
            plate2world[:3, 3],
            scn.sensor.working_distance_mm,
            scn.global_test.calibration_poses,
            scn.circular_plate.jitter,
            axis=axis,
        )
        _, reported = arm_poses(scn, arm, cam2world, rng, drift=False)
        uv = plate_images(scn, plate2world, cam2world, rng, outliers=True, sigma_px=sigma_px)
        out.append((reported, uv))
    return out


def survey_views(scn: Scenario, rng: np.random.Generator, bridges: bool = True) -> list[View]:
    """The scanner's unordered stereo images of the markers: ``survey.views_per_group`` of each
    group and ``survey.bridge_views`` of both (none with ``bridges=False``), the linking images
    held with the short side of the image along the line of the groups (world y, across the stereo
    baseline: at 1000 mm the two images of a rig converging at 500 mm overlap little along the
    baseline), turned by at most ``survey.bridge_roll_deg`` about the optical axis."""
    poses = [
        view_poses(
            rng,
            scn.markers.group_centre(arm),
            scn.sensor.working_distance_mm,
            scn.survey.views_per_group,
            scn.survey.tilt,
        )
        for arm in ARMS
    ]
    if bridges:
        poses.append(
            view_poses(
                rng,
                mid_point(scn),
                scn.survey.bridge_distance_mm,
                scn.survey.bridge_views,
                scn.survey.bridge_tilt,
                up=(0.0, 1.0, 0.0),
                roll=scn.survey.bridge_roll,
            )
        )
    cam2world = np.concatenate(poses)
    return [observe_markers(scn, geo.invert(c), rng) for c in cam2world]


def arm_world_views(scn: Scenario, arm: int, rng: np.random.Generator, exact: bool = False):
    """Arm ``arm`` sees its marker group from ``global_test.calibration_poses`` poses: ``(reported
    flange2base, views)``; with ``exact`` also ``(true flange2base, views without noise, bias or
    losses)`` of the same poses (the per-arm location switched off in the error budget)."""
    cam2world = view_poses(
        rng,
        scn.markers.group_centre(arm),
        scn.sensor.working_distance_mm,
        scn.global_test.calibration_poses,
        scn.survey.tilt,
    )
    true, reported = arm_poses(scn, arm, cam2world, rng, drift=False)
    views = [observe_markers(scn, geo.invert(c), rng) for c in cam2world]
    if not exact:
        return reported, views
    quiet = scn.noise_free()
    return (reported, views), (
        true,
        [observe_markers(quiet, geo.invert(c), rng) for c in cam2world],
    )


# ----------------------------------------------------------------------------------------------
# sphere scans


def scan_sphere(scn: Scenario, centre_world, radius: float, cam2world, rng) -> np.ndarray:
    """Points ``(points_per_scan, 3)`` of the sphere cap the left camera at ``cam2world`` sees,
    in the left camera frame, with ``sensor.point_sigma_mm`` noise per coordinate and the
    view's systematic error: every point moved along the sphere's normal by one draw of
    ``N(0, sensor.sphere_fit_sigma_mm)`` (the view's fitted radius is off by it; drawn even at
    0, so that the draws after it do not depend on it)."""
    c = np.asarray(centre_world, dtype=float)
    eye = np.asarray(cam2world)[:3, 3]
    n_draw = 4 * scn.sensor.points_per_scan
    normals = rng.normal(size=(n_draw, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    pts = c + radius * normals
    view = eye - pts
    cos_inc = np.einsum("ij,ij->i", normals, view) / np.linalg.norm(view, axis=1)
    vis = np.flatnonzero(cos_inc > np.cos(scn.sensor.max_incidence))[: scn.sensor.points_per_scan]
    if vis.size < scn.sensor.points_per_scan:
        raise CalibrationError(
            f"the scan sees {vis.size} sphere points; {scn.sensor.points_per_scan} requested"
        )
    world2cam = geo.invert(cam2world)
    local = geo.apply(world2cam, pts[vis])
    noisy = local + rng.normal(0.0, scn.sensor.point_sigma_mm, local.shape)
    radial = rng.normal(0.0, 1.0) * scn.sensor.sphere_fit_sigma_mm
    return noisy + radial * (normals[vis] @ world2cam[:3, :3].T)


def sphere_scans(
    scn: Scenario, arm: int, centre_world, radius: float, n_views: int, rng, drift: bool = True
):
    """A scan of one sphere by arm ``arm`` from ``n_views`` poses (with ``drift``, the arm
    drifting from view to view; else each pose with its repeatability only): ``(reported
    flange2base (n_views, 4, 4), true flange2base, clouds)``, each cloud ``(points_per_scan,
    3)`` in the left camera frame."""
    cam2world = view_poses(rng, centre_world, scn.sensor.working_distance_mm, n_views, scn.icp.tilt)
    true, reported = arm_poses(scn, arm, cam2world, rng, drift=drift)
    return reported, true, [scan_sphere(scn, centre_world, radius, c, rng) for c in cam2world]


def sphere_place(scn: Scenario, arm: int, radius: float) -> np.ndarray:
    """Where arm ``arm``'s multi-view test sphere stands (world): ``icp.sphere_offset_mm`` beside
    its marker group, on the stand."""
    g = scn.markers.group_centre(arm)
    return np.array(
        [g[0] + scn.icp.sphere_offset_mm, g[1], scn.global_test.stand_height_mm + radius]
    )


def global_sphere_place(scn: Scenario, offset_mm: float, radius: float) -> np.ndarray:
    """Where sphere A stands for one group of Tables 1-2 (world): ``offset_mm`` along the line
    of the bases from the point between the marker groups, on the stand."""
    mid = mid_point(scn)
    return np.array([mid[0], mid[1] + offset_mm, scn.global_test.stand_height_mm + radius])
