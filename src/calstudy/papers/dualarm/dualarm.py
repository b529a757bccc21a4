"""The dual-arm hand-eye scanning station of the ``dualarm`` paper, simulated and calibrated.

Two robot arms each carry a binocular structured-light sensor. The chain of the paper:

1. per arm, the hand-eye transform by Tsai-Lenz (Eq. 1-2) from images of a calibration plate,
   plate poses by PnP (:func:`tsai_handeye`);
2. the 14 coded markers of Table A1, in two groups that the arms see separately, reconstructed in
   one world frame by structure from motion (:mod:`calstudy.estimators.sfm`, Eq. 5-10);
3. each arm locates the world from three poses (PnP, then Eq. 9-10 with the markers held), and
   Eq. 11 chains both arms into the base-to-base transform (:func:`base_to_base`);
4. multi-view scans of standard spheres, stitched in the robot frame (Eq. 3) and corrected by
   weighted ICP (:mod:`calstudy.estimators.icp`, Eq. 4);
5. the comparison: a circular calibration plate in the overlapping field, RANSAC-PnP, the same
   chain (:func:`plate_base_to_base`).

The tables, figures and verdicts built from these experiments are in
:mod:`calstudy.papers.dualarm.report`.

Frames follow the study's naming: ``cam2flange`` maps left-camera points to the flange,
``flange2base`` the flange to its robot base, ``world2cam`` the marker (world) frame to the left
camera, ``base2_to_base1`` base 2 to base 1. Millimetres and radians.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.estimators import sfm as mk
from calstudy.estimators.fitting import fit_rigid, fit_sphere, solve_pnp
from calstudy.estimators.handeye import opencv_handeye
from calstudy.estimators.icp import weighted_icp
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig, stereo_rig

#: smallest rotation (rad) between consecutive hand-eye poses accepted by :func:`tsai_handeye`
MIN_PAIR_ROTATION = np.deg2rad(0.5)
ARMS = (1, 2)
SPHERES = ("A", "B")


# ----------------------------------------------------------------------------------------------
# the scenario


@dataclass(frozen=True)
class Scenario:
    """Everything the simulated station is made of (read from ``data/dualarm/scenario.toml``).

    Lengths in mm, angles in rad, pixels in px. ``cam2flange[a]``, ``world2base[a]`` are the
    true transforms of arm ``a + 1``.
    """

    rig: StereoRig
    markers: np.ndarray
    marker_names: tuple
    marker_group: np.ndarray
    cam2flange: np.ndarray
    world2base: np.ndarray
    base2_to_base1: np.ndarray
    point_sigma_mm: float
    points_per_scan: int
    max_incidence: float
    working_distance_mm: float
    sigma_px: float
    marker_sigma_mm: float
    loss_rate: float
    max_view_angle: float
    repeat_sigma_mm: float
    repeat_sigma_rad: float
    drift_step_mm: float
    drift_step_rad: float
    sphere_radius: dict
    plate_points: np.ndarray
    handeye_poses: int
    handeye_tilt: float
    survey_views_per_group: int
    survey_bridge_views: int
    survey_bridge_distance_mm: float
    survey_bridge_tilt: float
    survey_tilt: float
    min_shared_markers: int
    global_groups: int
    global_poses: int
    calibration_poses: int
    placement_offsets_mm: tuple
    stand_height_mm: float
    plate_tilt: float
    plate_jitter: float
    plate_outlier_rate: float
    plate_outlier_px: tuple
    ransac_threshold_px: float
    icp_z_weight: float
    icp_z_threshold_mm: float
    icp_max_iterations: int
    icp_max_pair_mm: float
    icp_views: int
    icp_tilt: float
    icp_sphere_offset_mm: float

    def replace(self, **changes) -> Scenario:
        """A copy with some fields changed (e.g. all noise set to 0)."""
        return dataclasses.replace(self, **changes)

    def noise_free(self) -> Scenario:
        """The same station with exact detections, sensor, robot poses and no marker losses."""
        return self.replace(
            point_sigma_mm=0.0,
            sigma_px=0.0,
            loss_rate=0.0,
            repeat_sigma_mm=0.0,
            repeat_sigma_rad=0.0,
            drift_step_mm=0.0,
            drift_step_rad=0.0,
            plate_outlier_rate=0.0,
        )

    def group_centre(self, arm: int) -> np.ndarray:
        """Centroid ``(3,)`` of the marker group arm ``arm`` (1 or 2) sees, world frame."""
        return self.markers[self.marker_group == arm - 1].mean(axis=0)


def _pose(rotvec, translation) -> np.ndarray:
    return geo.make_transform(geo.rotvec_to_matrix(rotvec), translation)


def load_scenario(path: str | Path | None = None) -> Scenario:
    """Read the station from ``data/dualarm/scenario.toml`` (or ``path``)."""
    p = data_path("dualarm", "scenario.toml") if path is None else Path(path)
    d = tomllib.loads(p.read_text())
    cam, st, se, de = d["camera"], d["stereo"], d["sensor"], d["detection"]
    camera = PinholeCamera(
        fx=cam["fx_px"],
        fy=cam["fy_px"],
        cx=cam["cx_px"],
        cy=cam["cy_px"],
        width=cam["width"],
        height=cam["height"],
    )
    rig = stereo_rig(camera, st["baseline_mm"], st["convergence_distance_mm"])
    m = d["markers"]
    names = tuple(m["names"])
    group = np.array([m["groups"].index(n.split("-")[0]) for n in names])
    c = d["calibration"]
    cam2flange = np.stack(
        [_pose(c[f"cam2flange_{a}_rotvec"], c[f"cam2flange_{a}_mm"]) for a in ARMS]
    )
    b2b1 = _pose(c["base2_to_base1_rotvec"], c["base2_to_base1_mm"])
    w2b1 = _pose(d["layout"]["world2base1_rotvec"], d["layout"]["world2base1_mm"])
    r, sp, he, sv = d["robot"], d["spheres"], d["handeye"], d["survey"]
    gt, cp, ic = d["global_test"], d["circular_plate"], d["icp"]
    rows, cols, pitch = he["grid_rows"], he["grid_cols"], he["pitch_mm"]
    gx, gy = np.meshgrid(
        (np.arange(cols) - (cols - 1) / 2) * pitch, (np.arange(rows) - (rows - 1) / 2) * pitch
    )
    plate = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    deg = np.deg2rad
    return Scenario(
        rig=rig,
        markers=np.asarray(m["xyz_mm"], dtype=float),
        marker_names=names,
        marker_group=group,
        cam2flange=cam2flange,
        world2base=np.stack([w2b1, geo.invert(b2b1) @ w2b1]),
        base2_to_base1=b2b1,
        point_sigma_mm=se["point_sigma_mm"],
        points_per_scan=se["points_per_scan"],
        max_incidence=deg(se["max_incidence_deg"]),
        working_distance_mm=se["working_distance_mm"],
        sigma_px=de["sigma_px"],
        marker_sigma_mm=de["marker_sigma_mm"],
        loss_rate=de["loss_rate"],
        max_view_angle=deg(de["max_view_angle_deg"]),
        repeat_sigma_mm=r["repeat_sigma_mm"],
        repeat_sigma_rad=deg(r["repeat_sigma_deg"]),
        drift_step_mm=r["drift_step_sigma_mm"],
        drift_step_rad=deg(r["drift_step_sigma_deg"]),
        sphere_radius={"A": sp["diameter_a_mm"] / 2, "B": sp["diameter_b_mm"] / 2},
        plate_points=plate,
        handeye_poses=he["n_poses"],
        handeye_tilt=deg(he["tilt_deg"]),
        survey_views_per_group=sv["views_per_group"],
        survey_bridge_views=sv["bridge_views"],
        survey_bridge_distance_mm=sv["bridge_distance_mm"],
        survey_bridge_tilt=deg(sv["bridge_tilt_deg"]),
        survey_tilt=deg(sv["tilt_deg"]),
        min_shared_markers=sv["min_shared_markers"],
        global_groups=gt["n_groups"],
        global_poses=gt["n_poses"],
        calibration_poses=gt["calibration_poses"],
        placement_offsets_mm=tuple(gt["placement_offsets_mm"]),
        stand_height_mm=gt["stand_height_mm"],
        plate_tilt=deg(cp["tilt_deg"]),
        plate_jitter=deg(cp["jitter_deg"]),
        plate_outlier_rate=cp["outlier_rate"],
        plate_outlier_px=tuple(cp["outlier_px"]),
        ransac_threshold_px=cp["ransac_threshold_px"],
        icp_z_weight=ic["z_weight"],
        icp_z_threshold_mm=ic["z_threshold_mm"],
        icp_max_iterations=ic["max_iterations"],
        icp_max_pair_mm=ic["max_pair_distance_mm"],
        icp_views=ic["n_views"],
        icp_tilt=deg(ic["tilt_deg"]),
        icp_sphere_offset_mm=ic["sphere_offset_mm"],
    )


# ----------------------------------------------------------------------------------------------
# simulated poses and detections


def view_poses(
    rng: np.random.Generator,
    target,
    distance_mm: float,
    n: int,
    tilt: float,
    axis=(0.0, 0.0, 1.0),
    up=None,
) -> np.ndarray:
    """``cam2world`` ``(n, 4, 4)`` of cameras ``distance_mm`` from ``target``, looking at it from
    directions within ``tilt`` rad of ``axis`` (uniform in the cone), image rotated at random
    about the optical axis unless ``up`` fixes it."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    out = np.empty((n, 4, 4))
    cos_t = 1.0 - rng.random(n) * (1.0 - np.cos(tilt))
    phi = rng.random(n) * 2 * np.pi
    spin = rng.random(n) * 2 * np.pi
    for k in range(n):
        s = np.sqrt(1.0 - cos_t[k] ** 2)
        d = cos_t[k] * a + s * (np.cos(phi[k]) * e1 + np.sin(phi[k]) * e2)
        u = up if up is not None else np.cos(spin[k]) * e1 + np.sin(spin[k]) * e2
        out[k] = geo.look_at(np.asarray(target) + distance_mm * d, target, up=u)
    return out


def pose_errors(scn: Scenario, n: int, rng: np.random.Generator, drift: bool) -> np.ndarray:
    """Errors ``E`` ``(n, 4, 4)`` of reported flange poses: ``true = reported @ E``.

    Repeatability on every pose; with ``drift``, a random walk from the first pose adds the
    attitude drift of a multi-view scan.
    """
    rep = geo.perturb(np.tile(np.eye(4), (n, 1, 1)), scn.repeat_sigma_rad, scn.repeat_sigma_mm, rng)
    if not drift:
        return rep
    steps = geo.perturb(np.tile(np.eye(4), (n, 1, 1)), scn.drift_step_rad, scn.drift_step_mm, rng)
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
    true = scn.world2base[a] @ np.asarray(cam2world) @ geo.invert(scn.cam2flange[a])
    reported = true @ geo.invert(pose_errors(scn, len(true), rng, drift))
    return true, reported


def observe_markers(scn: Scenario, world2cam, rng: np.random.Generator) -> mk.View:
    """Markers detected in one stereo pair: visible in both images and facing the camera, each
    lost with probability ``loss_rate``, centres with ``sigma_px`` noise."""
    w2c = np.asarray(world2cam)
    pl = geo.apply(w2c, scn.markers)
    pr = geo.apply(scn.rig.left2right, pl)
    eye = geo.invert(w2c)[:3, 3]
    to_cam = eye - scn.markers
    cos_view = to_cam[:, 2] / np.linalg.norm(to_cam, axis=1)  # markers face world +z
    front = (pl[:, 2] > 0) & (pr[:, 2] > 0) & (cos_view > np.cos(scn.max_view_angle))
    ul = np.full((len(pl), 2), -1e9)
    ur = np.full((len(pl), 2), -1e9)
    ul[front] = scn.rig.left.project(pl[front])
    ur[front] = scn.rig.right.project(pr[front])
    seen = front & scn.rig.left.in_image(ul) & scn.rig.right.in_image(ur)
    seen &= rng.random(len(pl)) >= scn.loss_rate
    noise = rng.normal(0.0, scn.sigma_px, (2, len(pl), 2))
    ids = np.flatnonzero(seen)
    return mk.make_view(ids, ul[ids] + noise[0, ids], ur[ids] + noise[1, ids])


# ----------------------------------------------------------------------------------------------
# 1. hand-eye by Tsai-Lenz (Eq. 1-2)


def tsai_handeye(flange2base, target2cam, min_pair_rotation: float = MIN_PAIR_ROTATION):
    """``cam2flange`` by Tsai-Lenz (``cv2.calibrateHandEye``, ``CALIB_HAND_EYE_TSAI``).

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        Reported flange poses.
    target2cam : array_like, shape (N, 4, 4)
        Plate poses in the camera (from PnP).
    min_pair_rotation : float
        Smallest rotation (rad) of the robot between consecutive poses: Tsai-Lenz takes the
        rotation axis of each motion, undefined for a pure translation.

    Raises
    ------
    CalibrationError
        With fewer than 3 poses, bad shapes, or a consecutive pair rotating less than
        ``min_pair_rotation`` (the message names the pair and its angle).
    """
    g2b = geo.check_transform("flange poses", flange2base)
    t2c = geo.check_transform("plate poses", target2cam)
    if g2b.ndim != 3 or g2b.shape[0] < 3:
        n = g2b.shape[0] if g2b.ndim == 3 else 1
        raise CalibrationError(f"Tsai-Lenz needs at least 3 poses (2 motions); got {n}")
    rel = np.swapaxes(g2b[:-1, :3, :3], -1, -2) @ g2b[1:, :3, :3]
    angles = geo.rotation_angle(rel)
    k = int(np.argmin(angles))
    if angles[k] < min_pair_rotation:
        raise CalibrationError(
            f"poses {k} and {k + 1} differ by a rotation of {np.degrees(angles[k]):.3g} deg "
            f"(minimum {np.degrees(min_pair_rotation):.3g} deg); Tsai-Lenz needs rotating motions"
        )
    return opencv_handeye(g2b, t2c, "Tsai")


def simulate_handeye(scn: Scenario, arm: int, rng: np.random.Generator):
    """Arm ``arm`` images the plate from ``handeye_poses`` poses; returns ``(reported
    flange2base, plate2cam by PnP)``."""
    plate2world = geo.make_transform(np.eye(3), scn.group_centre(arm))
    cam2world = view_poses(
        rng, plate2world[:3, 3], scn.working_distance_mm, scn.handeye_poses, scn.handeye_tilt
    )
    _, reported = arm_poses(scn, arm, cam2world, rng, drift=False)
    plate2cam = np.empty_like(cam2world)
    for k, c2w in enumerate(cam2world):
        true = geo.invert(c2w) @ plate2world
        uv = scn.rig.left.observe(true, scn.plate_points, scn.sigma_px, rng)
        plate2cam[k] = solve_pnp(scn.plate_points, uv, scn.rig.left.K)
    return reported, plate2cam


# ----------------------------------------------------------------------------------------------
# 2-3. markers and the base-to-base chain (Eq. 5-11)


def survey_views(scn: Scenario, rng: np.random.Generator, bridges: bool = True) -> list[mk.View]:
    """The scanner's unordered stereo images of the markers: ``survey_views_per_group`` of each
    group and ``survey_bridge_views`` of both (none with ``bridges=False``)."""
    poses = [
        view_poses(
            rng,
            scn.group_centre(arm),
            scn.working_distance_mm,
            scn.survey_views_per_group,
            scn.survey_tilt,
        )
        for arm in ARMS
    ]
    if bridges:
        mid = 0.5 * (scn.group_centre(1) + scn.group_centre(2))
        poses.append(
            view_poses(
                rng,
                mid,
                scn.survey_bridge_distance_mm,
                scn.survey_bridge_views,
                scn.survey_bridge_tilt,
                up=(0.0, 1.0, 0.0),
            )
        )
    cam2world = np.concatenate(poses)
    return [observe_markers(scn, geo.invert(c), rng) for c in cam2world]


def survey_markers(scn: Scenario, views: list[mk.View], max_nfev: int = 200):
    """Global marker coordinates from the survey views (Eq. 5-10); the Eq. 10 weight is the
    marker noise at the working distance, scaled with the square of each marker's depth."""
    return mk.reconstruct_markers(
        scn.rig,
        views,
        len(scn.markers),
        alpha=scn.min_shared_markers,
        sigma_px=max(scn.sigma_px, 1e-3),
        sigma_mm=max(scn.marker_sigma_mm, 1e-3),
        max_nfev=max_nfev,
        depth_ref_mm=scn.working_distance_mm,
    )


def locate_world(scn: Scenario, view: mk.View, points) -> np.ndarray:
    """``world2cam`` of one view of known markers: PnP (>= 4 markers), then Eq. 9-10."""
    obj = np.asarray(points)[view.ids]
    init = mk.pnp_pose(obj, view.uv_left, scn.rig.left)
    return mk.refine_camera_pose(
        scn.rig,
        view,
        points,
        init,
        sigma_px=max(scn.sigma_px, 1e-3),
        sigma_mm=max(scn.marker_sigma_mm, 1e-3),
        depth_ref_mm=scn.working_distance_mm,
    )


def mean_transform(transforms) -> np.ndarray:
    """Average of rigid transforms ``(N, 4, 4)``: mean translation, rotation projected to SO(3)."""
    t = geo.check_transform("transforms", transforms)
    return geo.make_transform(geo.project_to_so3(t[:, :3, :3].mean(axis=0)), t[:, :3, 3].mean(0))


def base_to_base(
    flange2base_1, cam2flange_1, world2cam_1, flange2base_2, cam2flange_2, world2cam_2
):
    """``base2_to_base1`` by Eq. 11 from each arm's poses ``(N_a, 4, 4)`` seeing one world frame.

    ``world2base_a = flange2base_a @ cam2flange_a @ world2cam_a``, averaged over the arm's poses;
    then ``base2_to_base1 = world2base_1 @ world2base_2^-1``.
    """
    w2b = []
    for g2b, c2f, w2c in (
        (flange2base_1, cam2flange_1, world2cam_1),
        (flange2base_2, cam2flange_2, world2cam_2),
    ):
        g = geo.check_transform("flange poses", g2b).reshape(-1, 4, 4)
        w = geo.check_transform("world2cam", w2c).reshape(-1, 4, 4)
        if len(g) != len(w):
            raise CalibrationError(f"{len(g)} flange poses but {len(w)} camera poses")
        w2b.append(mean_transform(g @ geo.check_transform("cam2flange", c2f) @ w))
    return w2b[0] @ geo.invert(w2b[1])


def arm_world_views(scn: Scenario, arm: int, rng: np.random.Generator):
    """Arm ``arm`` sees its marker group from ``calibration_poses`` poses: ``(reported
    flange2base, views)``."""
    cam2world = view_poses(
        rng, scn.group_centre(arm), scn.working_distance_mm, scn.calibration_poses, scn.survey_tilt
    )
    _, reported = arm_poses(scn, arm, cam2world, rng, drift=False)
    return reported, [observe_markers(scn, geo.invert(c), rng) for c in cam2world]


def marker_base_to_base(scn: Scenario, cam2flange_est, points, arm_data) -> np.ndarray:
    """The paper's base-to-base transform (GCM-DHE): each arm's views located on the global
    markers, chained by Eq. 11. ``arm_data[a] = (reported flange2base, views)``; views showing
    fewer than 4 markers (lost to occlusion) are skipped, as an operator would retake them.

    Raises
    ------
    CalibrationError
        If all of an arm's views show fewer than 4 markers.
    """
    flanges, w2c = [], []
    for arm, (g2b, views) in zip(ARMS, arm_data, strict=True):
        ok = [k for k, v in enumerate(views) if v.ids.size >= 4]
        if not ok:
            counts = [int(v.ids.size) for v in views]
            raise CalibrationError(
                f"PnP needs at least 4 markers; arm {arm}'s views show {counts} markers"
            )
        flanges.append(np.asarray(g2b)[ok])
        w2c.append(np.stack([locate_world(scn, views[k], points) for k in ok]))
    return base_to_base(
        flanges[0], cam2flange_est[0], w2c[0], flanges[1], cam2flange_est[1], w2c[1]
    )


# ----------------------------------------------------------------------------------------------
# 5. the circular-plate comparison (Table 3)


def ransac_pnp(object_points, image_uv, camera: PinholeCamera, threshold_px: float) -> np.ndarray:
    """Pose ``target2cam`` of a planar target by ``cv2.solvePnPRansac``, robust to gross errors.

    RANSAC (AP3P hypotheses, fixed OpenCV seed) selects the inliers; a plane seen obliquely
    admits a second, mirrored pose that reprojects almost as well, so the pose is recomputed on
    the inliers by IPPE (which returns the better of the two), the inliers are recomputed from it
    (reprojection error below ``threshold_px``) and the pose refined by LM on them.
    """
    obj = geo.check_shape("object_points", object_points, (None, 3))
    uv = geo.check_shape("image_uv", image_uv, (obj.shape[0], 2))
    if obj.shape[0] < 4:
        raise CalibrationError(f"PnP needs at least 4 markers; got {obj.shape[0]}")
    cv2.setRNGSeed(0)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        obj,
        uv,
        camera.K,
        None,
        reprojectionError=threshold_px,
        iterationsCount=500,
        confidence=0.999,
        flags=cv2.SOLVEPNP_AP3P,
    )
    if not ok or inliers is None or len(inliers) < 4:
        raise CalibrationError(f"RANSAC-PnP found no pose for the {obj.shape[0]} points")
    keep = inliers.ravel()
    ok, rvec, tvec = cv2.solvePnP(obj[keep], uv[keep], camera.K, None, flags=cv2.SOLVEPNP_IPPE)
    proj = cv2.projectPoints(obj, rvec, tvec, camera.K, None)[0].reshape(-1, 2)
    good = np.linalg.norm(proj - uv, axis=1) < threshold_px
    if not ok or good.sum() < 4:
        raise CalibrationError(
            f"RANSAC-PnP kept {int(good.sum())} of {obj.shape[0]} points within "
            f"{threshold_px:g} px; PnP needs 4"
        )
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-16)
    rvec, tvec = cv2.solvePnPRefineLM(
        obj[good], uv[good], camera.K, None, rvec, tvec, criteria=criteria
    )
    return geo.make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())


def plate_base_to_base(scn: Scenario, cam2flange_est, rng: np.random.Generator) -> np.ndarray:
    """Baseline: a circle plate halfway between the arms (overlapping field), each arm images it
    from ``calibration_poses`` poses from its own side; RANSAC-PnP poses; Eq. 11."""
    mid = 0.5 * (scn.group_centre(1) + scn.group_centre(2))
    plate2world = geo.make_transform(np.eye(3), [mid[0], mid[1], 0.0])
    flanges, plate2cams = [], []
    for arm, side in zip(ARMS, (1.0, -1.0), strict=True):
        axis = (0.0, side * np.sin(scn.plate_tilt), np.cos(scn.plate_tilt))
        cam2world = view_poses(
            rng,
            plate2world[:3, 3],
            scn.working_distance_mm,
            scn.calibration_poses,
            scn.plate_jitter,
            axis=axis,
        )
        _, reported = arm_poses(scn, arm, cam2world, rng, drift=False)
        p2c = np.empty_like(cam2world)
        for k, c2w in enumerate(cam2world):
            true = geo.invert(c2w) @ plate2world
            uv = scn.rig.left.observe(true, scn.plate_points, scn.sigma_px, rng)
            bad = rng.random(len(uv)) < scn.plate_outlier_rate
            lo, hi = scn.plate_outlier_px
            mag = rng.uniform(lo, hi, len(uv))
            ang = rng.uniform(0, 2 * np.pi, len(uv))
            uv[bad] += (mag * np.column_stack([np.cos(ang), np.sin(ang)]).T).T[bad]
            p2c[k] = ransac_pnp(scn.plate_points, uv, scn.rig.left, scn.ransac_threshold_px)
        flanges.append(reported)
        plate2cams.append(p2c)
    return base_to_base(
        flanges[0], cam2flange_est[0], plate2cams[0], flanges[1], cam2flange_est[1], plate2cams[1]
    )


# ----------------------------------------------------------------------------------------------
# 4. sphere scans and M3DHE-ICP (Eq. 3-4)


def scan_sphere(scn: Scenario, centre_world, radius: float, cam2world, rng) -> np.ndarray:
    """Points ``(points_per_scan, 3)`` of the sphere cap the left camera at ``cam2world`` sees,
    in the left camera frame, with ``point_sigma_mm`` noise per coordinate."""
    c = np.asarray(centre_world, dtype=float)
    eye = np.asarray(cam2world)[:3, 3]
    n_draw = 4 * scn.points_per_scan
    normals = rng.normal(size=(n_draw, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    pts = c + radius * normals
    view = eye - pts
    cos_inc = np.einsum("ij,ij->i", normals, view) / np.linalg.norm(view, axis=1)
    vis = np.flatnonzero(cos_inc > np.cos(scn.max_incidence))[: scn.points_per_scan]
    if vis.size < scn.points_per_scan:
        raise CalibrationError(
            f"the scan sees {vis.size} sphere points; {scn.points_per_scan} requested"
        )
    local = geo.apply(geo.invert(cam2world), pts[vis])
    return local + rng.normal(0.0, scn.point_sigma_mm, local.shape)


def scans_in_base(scn, arm, centre_world, radius, n_views, rng, cam2flange_est):
    """A multi-view scan of one sphere by arm ``arm``: clouds in its base by Eq. 3 with the
    reported poses (drifting) and the estimated hand-eye; list of ``(N, 3)`` arrays."""
    cam2world = view_poses(rng, centre_world, scn.working_distance_mm, n_views, scn.icp_tilt)
    _, reported = arm_poses(scn, arm, cam2world, rng, drift=True)
    clouds = [scan_sphere(scn, centre_world, radius, c, rng) for c in cam2world]
    return [geo.apply(g @ cam2flange_est, p) for g, p in zip(reported, clouds, strict=True)]


def icp_correct(scn: Scenario, clouds: list[np.ndarray]) -> list[np.ndarray]:
    """M3DHE-ICP: every cloud after the first moved onto the first by weighted ICP (Eq. 4)."""
    tree = cKDTree(clouds[0])
    out = [clouds[0]]
    for p in clouds[1:]:
        res = weighted_icp(
            p,
            clouds[0],
            z_weight=scn.icp_z_weight,
            z_threshold_mm=scn.icp_z_threshold_mm,
            max_iterations=scn.icp_max_iterations,
            max_pair_mm=scn.icp_max_pair_mm,
            tree=tree,
        )
        out.append(geo.apply(res.transform, p))
    return out


def centre_errors(clouds: list[np.ndarray]) -> np.ndarray:
    """Distances ``(n - 1,)`` of the sphere centres fitted to clouds 1.. from that of cloud 0."""
    c = np.array([fit_sphere(p)[0] for p in clouds])
    return np.linalg.norm(c[1:] - c[0], axis=1)


def sphere_place(scn: Scenario, arm: int, radius: float) -> np.ndarray:
    """Where arm ``arm``'s multi-view test sphere stands (world): ``icp_sphere_offset_mm`` beside
    its marker group, on the stand."""
    g = scn.group_centre(arm)
    return np.array([g[0] + scn.icp_sphere_offset_mm, g[1], scn.stand_height_mm + radius])


def icp_experiment(scn: Scenario, cam2flange_est, rng: np.random.Generator) -> pd.DataFrame:
    """Figs. 5-6: per arm and sphere, centre-distance errors of views 1.. before/after ICP."""
    rows = []
    for arm in ARMS:
        for s in SPHERES:
            r = scn.sphere_radius[s]
            clouds = scans_in_base(
                scn, arm, sphere_place(scn, arm, r), r, scn.icp_views, rng, cam2flange_est[arm - 1]
            )
            before = centre_errors(clouds)
            after = centre_errors(icp_correct(scn, clouds))
            for k, (b, a) in enumerate(zip(before, after, strict=True)):
                rows.append({"arm": arm, "sphere": s, "view": k + 1, "before_mm": b, "after_mm": a})
    return pd.DataFrame(rows)


def global_experiment(scn: Scenario, cam2flange_est, b2b1: dict, rng) -> pd.DataFrame:
    """Tables 1-3: sphere A at ``global_groups`` places between the arms; arm 2's ICP-corrected
    multi-view cloud gives the reference centre in base 2; each of arm 1's ICP-corrected clouds
    is mapped into base 2 with each estimate in ``b2b1`` (name -> base2_to_base1)."""
    r = scn.sphere_radius["A"]
    mid = 0.5 * (scn.group_centre(1) + scn.group_centre(2))
    rows = []
    for g, off in enumerate(scn.placement_offsets_mm[: scn.global_groups]):
        centre = np.array([mid[0], mid[1] + off, scn.stand_height_mm + r])
        arm2 = icp_correct(
            scn, scans_in_base(scn, 2, centre, r, scn.global_poses, rng, cam2flange_est[1])
        )
        ref = fit_sphere(np.concatenate(arm2))[0]
        truth = geo.apply(scn.world2base[1], centre)
        arm1 = icp_correct(
            scn, scans_in_base(scn, 1, centre, r, scn.global_poses, rng, cam2flange_est[0])
        )
        c1 = np.array([fit_sphere(p)[0] for p in arm1])
        for name, t in b2b1.items():
            c12 = geo.apply(geo.invert(t), c1)
            for k in range(len(c12)):
                d = np.abs(c12[k] - ref)
                rows.append(
                    {
                        "method": name,
                        "group": g + 1,
                        "pose": k + 1,
                        "dx_mm": d[0],
                        "dy_mm": d[1],
                        "dz_mm": d[2],
                        "euclid_mm": float(np.linalg.norm(c12[k] - ref)),
                        "euclid_truth_mm": float(np.linalg.norm(c12[k] - truth)),
                    }
                )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# one trial and the Monte Carlo


def calibrate_station(scn: Scenario, rng: np.random.Generator):
    """Steps 1-3 and 5 on one simulated station: ``(cam2flange_est (2, 4, 4), reconstruction,
    {"coded markers": b2b1, "circular plate": b2b1})``."""
    cam2flange = np.stack([tsai_handeye(*simulate_handeye(scn, arm, rng)) for arm in ARMS])
    recon = survey_markers(scn, survey_views(scn, rng))
    arm_data = [arm_world_views(scn, arm, rng) for arm in ARMS]
    ours = marker_base_to_base(scn, cam2flange, recon.bundle.points, arm_data)
    circ = plate_base_to_base(scn, cam2flange, rng)
    return cam2flange, recon, {"coded markers": ours, "circular plate": circ}


def marker_error(scn: Scenario, points) -> float:
    """RMS distance (mm) of reconstructed markers from Table A1 after the best rigid fit."""
    p = np.asarray(points)
    ok = np.all(np.isfinite(p), axis=1)
    fitted = geo.apply(fit_rigid(p[ok], scn.markers[ok]), p[ok])
    return float(np.sqrt(np.mean(np.sum((fitted - scn.markers[ok]) ** 2, axis=1))))


def run_trial(scn: Scenario, rng: np.random.Generator) -> dict:
    """One simulated replication of the paper's experiments; a dict of DataFrames."""
    cam2flange, recon, b2b1 = calibrate_station(scn, rng)
    cal = [
        {
            "quantity": f"hand-eye arm {a}",
            "rotation_deg": float(
                np.degrees(geo.rotation_error(cam2flange[a - 1], scn.cam2flange[a - 1]))
            ),
            "translation_mm": float(
                geo.translation_error(cam2flange[a - 1], scn.cam2flange[a - 1])
            ),
        }
        for a in ARMS
    ]
    cal += [
        {
            "quantity": f"base-to-base, {name}",
            "rotation_deg": float(np.degrees(geo.rotation_error(t, scn.base2_to_base1))),
            "translation_mm": float(geo.translation_error(t, scn.base2_to_base1)),
        }
        for name, t in b2b1.items()
    ]
    bundle = {
        "rms_px": recon.bundle.rms_px,
        "rms_mm": recon.bundle.rms_mm,
        "marker_rms_mm": marker_error(scn, recon.bundle.points),
        "clusters": len(recon.clusters),
        "nfev": recon.bundle.nfev,
    }
    return {
        "calibration": pd.DataFrame(cal),
        "bundle": pd.DataFrame([bundle]),
        "icp": icp_experiment(scn, cam2flange, rng),
        "global": global_experiment(scn, cam2flange, b2b1, rng),
    }


def monte_carlo(scn: Scenario, seed: int, n_trials: int, progress: bool = False) -> dict:
    """``n_trials`` independent trials (streams spawned from ``seed``); DataFrames with a
    ``trial`` column."""
    if n_trials < 1:
        raise CalibrationError(f"n_trials must be >= 1; got {n_trials}")
    streams = np.random.SeedSequence(seed).spawn(n_trials)
    parts: dict[str, list] = {}
    for t, ss in enumerate(streams):
        out = run_trial(scn, np.random.default_rng(ss))
        for key, df in out.items():
            parts.setdefault(key, []).append(df.assign(trial=t))
        if progress:
            print(f"trial {t + 1}/{n_trials}", flush=True)
    return {k: pd.concat(v, ignore_index=True) for k, v in parts.items()}


def _icp_sweep(variants, key: str, seed: int, stream: int, n_trials: int) -> pd.DataFrame:
    """ICP experiment on each ``(value, scenario)`` of ``variants`` with the true hand-eye; per
    trial the mean error before and after ICP and their ratio."""
    rows = []
    for i, (value, sc) in enumerate(variants):
        for t, ss in enumerate(np.random.SeedSequence([seed, stream, i]).spawn(n_trials)):
            df = icp_experiment(sc, sc.cam2flange, np.random.default_rng(ss))
            before, after = df["before_mm"].mean(), df["after_mm"].mean()
            rows.append(
                {
                    key: value,
                    "trial": t,
                    "before_mm": before,
                    "after_mm": after,
                    "ratio": after / before,
                }
            )
    return pd.DataFrame(rows)


def drift_sweep(scn: Scenario, seed: int, scales, n_trials: int) -> pd.DataFrame:
    """ICP experiment with the drift steps scaled by each of ``scales``."""
    variants = [
        (s, scn.replace(drift_step_mm=scn.drift_step_mm * s, drift_step_rad=scn.drift_step_rad * s))
        for s in scales
    ]
    return _icp_sweep(variants, "drift_scale", seed, 7, n_trials)


def density_sweep(scn: Scenario, seed: int, counts, n_trials: int) -> pd.DataFrame:
    """ICP experiment with ``counts`` points per scan: the density of the clouds sets how well
    point-to-point pairs stand for corresponding points, hence the error left after ICP."""
    variants = [(int(n), scn.replace(points_per_scan=int(n))) for n in counts]
    return _icp_sweep(variants, "points_per_scan", seed, 13, n_trials)


def bridge_sweep(scn: Scenario, seed: int, counts, n_trials: int) -> pd.DataFrame:
    """Base-to-base error of the coded-marker chain against the number of survey images that see
    both marker groups (the link between the groups); ``n_trials`` trials per count."""
    rows = []
    for i, n in enumerate(counts):
        sc = scn.replace(survey_bridge_views=int(n))
        for t, ss in enumerate(np.random.SeedSequence([seed, 11, i]).spawn(n_trials)):
            rng = np.random.default_rng(ss)
            cam2flange = np.stack([tsai_handeye(*simulate_handeye(sc, arm, rng)) for arm in ARMS])
            recon = survey_markers(sc, survey_views(sc, rng))
            arm_data = [arm_world_views(sc, arm, rng) for arm in ARMS]
            b2b = marker_base_to_base(sc, cam2flange, recon.bundle.points, arm_data)
            rows.append(
                {
                    "bridge_views": int(n),
                    "trial": t,
                    "rotation_deg": float(np.degrees(geo.rotation_error(b2b, sc.base2_to_base1))),
                    "translation_mm": float(geo.translation_error(b2b, sc.base2_to_base1)),
                    "marker_rms_mm": marker_error(sc, recon.bundle.points),
                }
            )
    return pd.DataFrame(rows)
