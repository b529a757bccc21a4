"""The calibration chain of the ``dualarm`` paper on the simulated station, one trial, the Monte
Carlo and the sweeps.

1. per arm, the hand-eye transform by Tsai-Lenz (Eq. 1-2) from images of a calibration plate,
   plate poses by PnP (:func:`hand_eyes`);
2. the 14 coded markers of Table A1, in two groups that the arms see separately, reconstructed in
   one world frame by structure from motion (:func:`survey_markers`, Eq. 5-10);
3. each arm locates the world from three poses (PnP, then Eq. 9-10 with the markers held), and
   Eq. 11 chains both arms into the base-to-base transform (:func:`marker_base_to_base`);
4. multi-view scans of standard spheres, stitched in the robot frame (Eq. 3) and corrected by
   weighted ICP (:func:`icp_correct`, Eq. 4);
5. the comparison: a circular calibration plate in the overlapping field, RANSAC-PnP, the same
   chain (:func:`plate_base_to_base`).

The measurements come from :mod:`calstudy.papers.dualarm.simulate`; the tables, figures and
verdicts built from these experiments are in :mod:`calstudy.papers.dualarm.report`. Millimetres
and radians.

Random streams: each independent component of a trial (the hand-eye images of each arm, the
survey, each arm's calibration poses, the plate, each sphere's multi-view scans, each placement's
global scans) draws from its own stream of the trial's generator
(:func:`calstudy.core.montecarlo.streams`), named after the component, so that the number of
draws one of them makes (markers in the field, visible points) cannot shift another's.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import Experiment, child_rng, streams
from calstudy.estimators import sfm as mk
from calstudy.estimators.axxb import MIN_PAIR_ROTATION, opencv_handeye
from calstudy.estimators.bundle import refine_camera_pose
from calstudy.estimators.fitting import fit_rigid, fit_sphere, solve_pnp, solve_pnp_ransac
from calstudy.estimators.icp import weighted_icp
from calstudy.estimators.stereo_views import View
from calstudy.papers.dualarm import simulate as sim
from calstudy.papers.dualarm.scenario import SPHERES, load_scenario
from calstudy.papers.dualarm.schema import ARMS, Scenario

# ----------------------------------------------------------------------------------------------
# 1. hand-eye by Tsai-Lenz (Eq. 1-2)


def handeye_data(scn: Scenario, arm: int, rng: np.random.Generator):
    """Arm ``arm`` images the plate from ``handeye.n_poses`` poses; returns ``(reported
    flange2base, plate2cam by PnP)``, each ``(n, 4, 4)``."""
    reported, uvs = sim.handeye_images(scn, arm, rng)
    points, k = scn.handeye.plate_points, scn.rig.left.K
    return reported, np.stack([solve_pnp(points, uv, k) for uv in uvs])


def hand_eyes(scn: Scenario, rng: np.random.Generator) -> np.ndarray:
    """``cam2flange`` ``(2, 4, 4)`` of both arms by Tsai-Lenz (``cv2.calibrateHandEye``, every
    pair of poses), the poses checked for rotation diversity (two motions of at least
    ``MIN_PAIR_ROTATION`` about axes that far apart). Each arm draws from its own stream of
    ``rng``."""
    arm_rngs = streams(rng, *(f"hand-eye arm {arm}" for arm in ARMS))
    return np.stack(
        [
            opencv_handeye(*handeye_data(scn, arm, r), "Tsai", MIN_PAIR_ROTATION)
            for arm, r in zip(ARMS, arm_rngs, strict=True)
        ]
    )


# ----------------------------------------------------------------------------------------------
# 2-3. markers and the base-to-base chain (Eq. 5-11)


def survey_markers(scn: Scenario, views: list[View], max_nfev: int = 200):
    """Global marker coordinates from the survey views (Eq. 5-10); the Eq. 10 weight is the
    marker noise at the working distance, scaled with the square of each marker's depth."""
    return mk.reconstruct_markers(
        scn.rig,
        views,
        len(scn.markers.xyz),
        alpha=scn.survey.min_shared_markers,
        sigma_px=max(scn.detection.sigma_px, 1e-3),
        sigma_mm=max(scn.detection.marker_sigma_mm, 1e-3),
        max_nfev=max_nfev,
        depth_ref_mm=scn.sensor.working_distance_mm,
    )


def locate_world(scn: Scenario, view: View, points) -> np.ndarray:
    """``world2cam`` of one view of known markers: PnP (>= 4 markers), then Eq. 9-10."""
    obj = np.asarray(points)[view.ids]
    init = mk.pnp_pose(obj, view.uv_left, scn.rig.left)
    return refine_camera_pose(
        scn.rig,
        view,
        points,
        init,
        sigma_px=max(scn.detection.sigma_px, 1e-3),
        sigma_mm=max(scn.detection.marker_sigma_mm, 1e-3),
        depth_ref_mm=scn.sensor.working_distance_mm,
    )


def base_to_base(
    flange2base_1, cam2flange_1, world2cam_1, flange2base_2, cam2flange_2, world2cam_2
) -> np.ndarray:
    """``base2_to_base1`` of two robots whose cameras locate one world frame (dualarm Eq. 11).

    ``world2base_a = flange2base_a @ cam2flange_a @ world2cam_a``, averaged over arm ``a``'s
    poses by :func:`calstudy.core.geometry.mean_transform`; then
    ``base2_to_base1 = world2base_1 @ world2base_2^-1``.

    Parameters
    ----------
    flange2base_1, flange2base_2 : array_like, shape (N_a, 4, 4)
        Each robot's flange poses, mm.
    cam2flange_1, cam2flange_2 : array_like, shape (4, 4)
        Each robot's hand-eye transform.
    world2cam_1, world2cam_2 : array_like, shape (N_a, 4, 4)
        The world frame in each camera at each pose.

    Returns
    -------
    (4, 4) array
        ``base2_to_base1`` (``p_base1 = base2_to_base1 @ p_base2``).

    Raises
    ------
    CalibrationError
        On bad shapes, non-orthonormal rotations, or unequal numbers of flange and camera poses.
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
        w2b.append(geo.mean_transform(g @ geo.check_transform("cam2flange", c2f) @ w))
    return w2b[0] @ geo.invert(w2b[1])


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


def _chain(scn: Scenario, rng: np.random.Generator):
    """Steps 1-3 with what the error budget needs: ``(cam2flange_est, reconstruction,
    base2_to_base1, arm data, the same arm data exact, survey views)``."""
    cam2flange = hand_eyes(scn, rng)
    survey, *arm_rngs = streams(rng, "survey", *(f"calibration poses arm {arm}" for arm in ARMS))
    views = sim.survey_views(scn, survey)
    recon = survey_markers(scn, views)
    pairs = [
        sim.arm_world_views(scn, arm, r, exact=True)
        for arm, r in zip(ARMS, arm_rngs, strict=True)
    ]
    noisy, exact = [p[0] for p in pairs], [p[1] for p in pairs]
    ours = marker_base_to_base(scn, cam2flange, recon.bundle.points, noisy)
    return cam2flange, recon, ours, noisy, exact, views


def coded_marker_chain(scn: Scenario, rng: np.random.Generator):
    """Steps 1-3 on one simulated station: ``(cam2flange_est (2, 4, 4), reconstruction,
    base2_to_base1 by the coded markers)``."""
    return _chain(scn, rng)[:3]


def group_fits(scn: Scenario, points) -> list[np.ndarray]:
    """Per marker group, the rigid transform taking the group's Table A1 positions onto its
    reconstructed ones (markers never reconstructed left out)."""
    p = np.asarray(points)
    out = []
    for g in (0, 1):
        ok = (scn.markers.group_index == g) & np.all(np.isfinite(p), axis=1)
        out.append(fit_rigid(scn.markers.xyz[ok], p[ok]))
    return out


def link_error_deg(scn: Scenario, points) -> float:
    """Error (deg) of the survey's link: the rotation between the two groups' best fits, zero
    when the reconstruction places one group exactly relative to the other."""
    t0, t1 = group_fits(scn, points)
    return float(np.degrees(geo.rotation_error(t0, t1)))


def split_survey_error(scn: Scenario, points) -> dict[str, np.ndarray]:
    """The reconstructed markers with one part of their error kept: ``link`` (each group's true
    shape placed where the reconstruction puts the group: only the relative pose of the groups
    in error) and ``shape`` (each reconstructed group moved onto its true place: only the shapes
    in error)."""
    p = np.asarray(points)
    link, shape = p.copy(), p.copy()
    for g, t in zip((0, 1), group_fits(scn, p), strict=True):
        m = scn.markers.group_index == g
        link[m] = geo.apply(t, scn.markers.xyz[m])
        shape[m] = geo.apply(geo.invert(t), p[m])
    return {"link": link, "shape": shape}


def marker_error(scn: Scenario, points) -> float:
    """RMS distance (mm) of reconstructed markers from Table A1 after the best rigid fit."""
    p = np.asarray(points)
    ok = np.all(np.isfinite(p), axis=1)
    fitted = geo.apply(fit_rigid(p[ok], scn.markers.xyz[ok]), p[ok])
    return float(np.sqrt(np.mean(np.sum((fitted - scn.markers.xyz[ok]) ** 2, axis=1))))


# ----------------------------------------------------------------------------------------------
# 5. the circular-plate comparison (Table 3)


def plate_base_to_base(
    scn: Scenario, cam2flange_est, rng: np.random.Generator, sigma_px: float | None = None
) -> np.ndarray:
    """Baseline: a circle plate halfway between the arms (overlapping field), each arm images it
    from ``global_test.calibration_poses`` poses from its own side, circle centres to ``sigma_px``;
    RANSAC-PnP poses; Eq. 11. The plate draws from its own stream of ``rng``."""
    flanges, plate2cams = [], []
    (plate_rng,) = streams(rng, "plate")
    for reported, uvs in sim.circular_plate_images(scn, plate_rng, sigma_px):
        k, threshold = scn.rig.left.K, scn.circular_plate.ransac_threshold_px
        p2c = [solve_pnp_ransac(scn.handeye.plate_points, uv, k, threshold) for uv in uvs]
        flanges.append(reported)
        plate2cams.append(np.stack(p2c))
    return base_to_base(
        flanges[0], cam2flange_est[0], plate2cams[0], flanges[1], cam2flange_est[1], plate2cams[1]
    )


def design_base_to_base(scn: Scenario, rng: np.random.Generator) -> np.ndarray:
    """The null control of ``dualarm.global``: ``base2_to_base1`` read off the station's design
    drawing, each robot standing where the drawing puts it to ``design.base_sigma_mm`` and
    ``design.base_sigma_deg`` (one draw of ``rng``). A method that only reads the drawing passes
    the claim's test when the robots are placed well enough; it fails when they are not."""
    return geo.perturb(
        scn.calibration.base2_to_base1, scn.design.base_sigma_rad, scn.design.base_sigma_mm, rng
    )


def null_b2b1(scn: Scenario, cam2flange_est, rng: np.random.Generator, plate_sigma_px) -> dict:
    """The null controls of the two global claims on one trial, each from its own child stream
    of ``rng``: ``design drawing`` (:func:`design_base_to_base`) and ``plate retake`` (the
    circular plate taken again: new images of the same plate from new poses, the same
    calibration; judged against the plate, it shows what the comparison makes of a method no
    better than the plate)."""
    return {
        "design drawing": design_base_to_base(scn, child_rng(rng, "design drawing")),
        "plate retake": plate_base_to_base(
            scn, cam2flange_est, child_rng(rng, "plate retake"), plate_sigma_px
        ),
    }


# ----------------------------------------------------------------------------------------------
# 4. sphere scans and M3DHE-ICP (Eq. 3-4)


def scans_in_base(scn, arm, centre_world, radius, n_views, rng, cam2flange_est, drift=True):
    """A scan of one sphere by arm ``arm`` from ``n_views`` poses: ``(clouds in its base by Eq. 3
    with the reported poses and the estimated hand-eye, the same clouds with the true poses and
    the true hand-eye)``, each a list of ``(N, 3)`` arrays. ``drift``: the poses of a multi-view
    scan drift."""
    reported, true, clouds = sim.sphere_scans(scn, arm, centre_world, radius, n_views, rng, drift)
    true_c2f = scn.calibration.cam2flange[arm - 1]
    return (
        [geo.apply(g @ cam2flange_est, p) for g, p in zip(reported, clouds, strict=True)],
        [geo.apply(g @ true_c2f, p) for g, p in zip(true, clouds, strict=True)],
    )


def icp_options(scn: Scenario) -> dict:
    """The scenario's weighted-ICP settings (Eq. 4), as keywords of
    :func:`calstudy.estimators.icp.weighted_icp`."""
    return {
        "z_weight": scn.icp.z_weight,
        "z_threshold_mm": scn.icp.z_threshold_mm,
        "max_iterations": scn.icp.max_iterations,
        "max_pair_mm": scn.icp.max_pair_distance_mm,
    }


def icp_correct(scn: Scenario, clouds: list[np.ndarray]) -> list[np.ndarray]:
    """M3DHE-ICP: every cloud after the first moved onto the first by weighted ICP (Eq. 4),
    each alignment ended once its update is below the noise."""
    tree = cKDTree(clouds[0])
    out = [clouds[0]]
    for p in clouds[1:]:
        res = weighted_icp(p, clouds[0], **icp_options(scn), stop_below_noise=True, tree=tree)
        out.append(geo.apply(res.transform, p))
    return out


def centroid_correct(clouds: list[np.ndarray]) -> list[np.ndarray]:
    """The null control of ``dualarm.icp``: every cloud after the first moved so that its mean
    point meets the first cloud's, a correction that ignores the shape of the surface. It
    passes when the views see the same part of the sphere and fails when they see different
    caps, whose mean points lie apart by the geometry of the caps."""
    c0 = clouds[0].mean(axis=0)
    return [clouds[0], *(p + (c0 - p.mean(axis=0)) for p in clouds[1:])]


def centre_errors(clouds: list[np.ndarray]) -> np.ndarray:
    """Distances ``(n - 1,)`` of the sphere centres fitted to clouds 1.. from that of cloud 0."""
    c = np.array([fit_sphere(p)[0] for p in clouds])
    return np.linalg.norm(c[1:] - c[0], axis=1)


def icp_rows(scn: Scenario, cam2flange_est, rng: np.random.Generator, icp: bool = True):
    """Figs. 5-6: per arm, sphere and view 1.., the centre-distance error before ICP, after it
    (``icp``), after the null correction (``null_mm``, :func:`centroid_correct`), and with the
    errors between views removed from the simulation (``oracle_mm``: the clouds mapped with the
    true flange poses and hand-eye, what a perfect correction reaches). Each arm's scan of each
    sphere draws from its own stream of ``rng``."""
    rows = []
    names = [f"multi-view scans arm {arm} sphere {s}" for arm in ARMS for s in SPHERES]
    scan_rngs = iter(streams(rng, *names))
    for arm in ARMS:
        for s in SPHERES:
            r = scn.spheres.radius[s]
            place = sim.sphere_place(scn, arm, r)
            scan_rng = next(scan_rngs)
            clouds, exact = scans_in_base(
                scn, arm, place, r, scn.icp.n_views, scan_rng, cam2flange_est[arm - 1]
            )
            before = centre_errors(clouds)
            after = centre_errors(icp_correct(scn, clouds)) if icp else before * np.nan
            oracle = centre_errors(exact)
            null = centre_errors(centroid_correct(clouds))
            for k in range(len(before)):
                rows.append(
                    {
                        "part": "icp",
                        "arm": arm,
                        "sphere": s,
                        "view": k + 1,
                        "before_mm": float(before[k]),
                        "after_mm": float(after[k]),
                        "null_mm": float(null[k]),
                        "oracle_mm": float(oracle[k]),
                    }
                )
    return rows


def _centre_rows(name: str, group: int, c12, ref, truth) -> list[dict]:
    """Rows of Tables 1-2 for one method and group: arm 1's centres ``c12`` ``(n, 3)`` in base 2
    against arm 2's reference centre ``ref`` and the true centre ``truth``."""
    rows = []
    for k in range(len(c12)):
        d = np.abs(c12[k] - ref)
        rows.append(
            {
                "part": "global",
                "method": name,
                "group": group,
                "pose": k + 1,
                "dx_mm": float(d[0]),
                "dy_mm": float(d[1]),
                "dz_mm": float(d[2]),
                "euclid_mm": float(np.linalg.norm(c12[k] - ref)),
                "euclid_truth_mm": float(np.linalg.norm(c12[k] - truth)),
            }
        )
    return rows


def _fitted_centres(scans, c2f, cache: dict, exact: bool = False):
    """Arm 2's reference centre and arm 1's per-pose centres (each in its base) of one placement's
    ``scans`` (arm 2's, then arm 1's, from :func:`~calstudy.papers.dualarm.simulate.sphere_scans`)
    mapped by Eq. 3 with the hand-eyes ``c2f`` and the reported (or, ``exact``, true) poses;
    ``cache`` keeps them per hand-eye pair."""
    key = (id(c2f), exact)
    if key not in cache:
        (rep2, true2, cl2), (rep1, true1, cl1) = scans
        g2, g1 = (true2, true1) if exact else (rep2, rep1)
        arm2 = [geo.apply(q @ c2f[1], p) for q, p in zip(g2, cl2, strict=True)]
        ref = fit_sphere(np.concatenate(arm2))[0]
        c1 = [fit_sphere(geo.apply(q @ c2f[0], p))[0] for q, p in zip(g1, cl1, strict=True)]
        cache[key] = (ref, np.array(c1))
    return cache[key]


def global_rows(scn: Scenario, cam2flange_est, b2b1: dict, rng, oracle: bool = True) -> list:
    """Tables 1-3: sphere A at ``global_groups`` places between the arms. The reading of the
    paper's reference centre: the centre fitted to all of arm 2's clouds of the placement
    together (its ``global_poses`` poses, each an ordinary move with the arm's repeatability, no
    multi-view drift), in base 2. Each of arm 1's poses is one scan, its fitted centre mapped into
    base 2 with each estimate in ``b2b1`` (name -> base2_to_base1, or ``(base2_to_base1,
    cam2flange (2, 4, 4))`` for a method whose scans are mapped (Eq. 3) with other hand-eyes than
    ``cam2flange_est``). With ``oracle``, also the method ``true calibration``: the same scans
    with every calibrated transform true and the poses exact (the test's measurement floor).
    Each arm's scans of each placement draw from their own stream of ``rng``."""
    r = scn.spheres.radius["A"]
    rows = []
    (scans_rng,) = streams(rng, "global scans")
    for g, off in enumerate(scn.global_test.placement_offsets_mm[: scn.global_test.n_groups]):
        centre = sim.global_sphere_place(scn, off, r)
        truth = geo.apply(scn.world2base[1], centre)
        scans = [
            sim.sphere_scans(
                scn,
                arm,
                centre,
                r,
                scn.global_test.n_poses,
                child_rng(scans_rng, f"placement {g + 1} arm {arm}"),
                drift=False,
            )
            for arm in (2, 1)
        ]
        centres: dict = {}

        for name, t in b2b1.items():
            t, c2f = t if isinstance(t, tuple) else (t, cam2flange_est)
            ref, c1 = _fitted_centres(scans, c2f, centres)
            rows += _centre_rows(name, g + 1, geo.apply(geo.invert(t), c1), ref, truth)
        if oracle:
            # no calibration error anywhere: true hand-eyes and base-to-base, exact poses
            ref0, c0 = _fitted_centres(scans, scn.calibration.cam2flange, centres, exact=True)
            c0 = geo.apply(geo.invert(scn.calibration.base2_to_base1), c0)
            rows += _centre_rows("true calibration", g + 1, c0, ref0, truth)
    return rows


# ----------------------------------------------------------------------------------------------
# the trials and their experiments (factories rebuilt by name from experiments.json)


def _transform_error(quantity: str, estimate, truth) -> dict:
    return {
        "part": "calibration",
        "quantity": quantity,
        "rotation_deg": float(np.degrees(geo.rotation_error(estimate, truth))),
        "translation_mm": float(geo.translation_error(estimate, truth)),
    }


def _scenario(scenario_toml: str, drift_scale: float = 1.0, overrides=None) -> Scenario:
    return load_scenario(scenario_toml or None, overrides).with_drift_scale(drift_scale)


#: the error sources of the coded-marker chain, each switched on alone in the error budget
BUDGET_SOURCES = ("survey link", "survey shape", "hand-eye", "per-arm location")


def budget_b2b1(scn: Scenario, cam2flange_est, points, noisy, exact) -> dict:
    """The error budget of the coded-marker chain on one trial's draws: for each source of
    :data:`BUDGET_SOURCES`, ``"budget: <source>"`` -> ``(base2_to_base1, cam2flange)`` with
    that source alone in error (the survey's link or shapes (:func:`split_survey_error`), the
    Tsai-Lenz hand-eyes (used in Eq. 11 and Eq. 3), or each arm's location on the markers: pixel
    noise, bias and losses of its calibration views and its reported poses), every other input
    true. The sphere test adds its own floor to each."""
    split = split_survey_error(scn, points)
    true_c2f = scn.calibration.cam2flange
    cases = {
        "survey link": (true_c2f, split["link"], exact),
        "survey shape": (true_c2f, split["shape"], exact),
        "hand-eye": (np.asarray(cam2flange_est), scn.markers.xyz, exact),
        "per-arm location": (true_c2f, scn.markers.xyz, noisy),
    }
    return {
        f"budget: {name}": (marker_base_to_base(scn, c2f, pts, data), c2f)
        for name, (c2f, pts, data) in cases.items()
    }


def station_trial(scn: Scenario, rng: np.random.Generator, plate_sigma_px: float) -> list:
    """One simulated replication of the paper's experiments (steps 1-5), with the controls on
    the same draws: rows of parts ``calibration``, ``bundle``, ``icp`` (before, after, null,
    oracle) and ``global`` (methods: coded markers, circular plate, and the controls ``true
    calibration`` (no calibration error: the test's floor), ``design drawing`` and ``plate
    retake`` (the nulls, :func:`null_b2b1`))."""
    cam2flange, recon, ours = coded_marker_chain(scn, rng)
    circ = plate_base_to_base(scn, cam2flange, rng, plate_sigma_px)
    b2b1 = {
        "coded markers": ours,
        "circular plate": circ,
        **null_b2b1(scn, cam2flange, rng, plate_sigma_px),
    }
    rows = [
        _transform_error(f"hand-eye arm {a}", cam2flange[a - 1], scn.calibration.cam2flange[a - 1])
        for a in ARMS
    ]
    rows += [
        _transform_error(f"base-to-base, {name}", b2b1[name], scn.calibration.base2_to_base1)
        for name in ("coded markers", "circular plate")
    ]
    rows.append(
        {
            "part": "bundle",
            "rms_px": recon.bundle.rms_px,
            "rms_mm": recon.bundle.rms_mm,
            "marker_rms_mm": marker_error(scn, recon.bundle.points),
            "link_deg": link_error_deg(scn, recon.bundle.points),
            "clusters": len(recon.clusters),
        }
    )
    rows += icp_rows(scn, cam2flange, rng)
    rows += global_rows(scn, cam2flange, b2b1, rng)
    return rows


def station_experiment(
    scenario_toml: str = "",
    n_trials: int = 200,
    drift_scale: float = 1.0,
    plate_sigma_px: float = 0.1,
) -> Experiment:
    """The whole chain, ``n_trials`` trials, drift and plate noise as calibrated (rule 11)."""
    return Experiment(
        "station",
        station_trial,
        _scenario(scenario_toml, drift_scale),
        n_trials,
        ({"plate_sigma_px": float(plate_sigma_px)},),
    )


#: the parts of a robustness trial: the multi-view scans and ICP (``dualarm.icp``), and the
#: coded-marker and plate routes with the Tables 1-2 test (``dualarm.global``,
#: ``dualarm.vs_circular``)
ROBUSTNESS_PARTS = ("icp", "global")


def robustness_trial(
    scn: Scenario, rng: np.random.Generator, plate_sigma_px: float, section: str
) -> list:
    """One trial of a robustness map: the rows of one part of :data:`ROBUSTNESS_PARTS` with the
    controls of its claims, as in :func:`station_trial`. Each component draws from a child
    stream named after it (:func:`calstudy.core.montecarlo.child_rng`), so the hand-eyes, the
    scans and the survey of a trial are the same draws whichever part runs and whatever input
    a point of the map changes."""
    if section not in ROBUSTNESS_PARTS:
        raise CalibrationError(f"section {section!r} is not one of {ROBUSTNESS_PARTS}")
    if section == "icp":
        cam2flange = hand_eyes(scn, child_rng(rng, "chain"))
        return icp_rows(scn, cam2flange, child_rng(rng, "multi-view scans"))
    cam2flange, _, ours = coded_marker_chain(scn, child_rng(rng, "chain"))
    circ = plate_base_to_base(scn, cam2flange, child_rng(rng, "plate"), plate_sigma_px)
    b2b1 = {
        "coded markers": ours,
        "circular plate": circ,
        **null_b2b1(scn, cam2flange, rng, plate_sigma_px),
    }
    return global_rows(scn, cam2flange, b2b1, child_rng(rng, "global scans"))


def robustness_experiment(
    scenario_toml: str = "",
    n_trials: int = 10,
    drift_scale: float = 1.0,
    plate_sigma_px: float = 0.1,
    section: str = "icp",
    overrides: dict | None = None,
) -> Experiment:
    """One point of a robustness map: :func:`robustness_trial` of ``section`` on the scenario
    with ``overrides`` (dotted keys of ``scenario.toml``, set before it is validated). The
    name is the same at every point, so every point runs the same trials (paired seeds); the
    scenario, and so the trial cache's key, holds the overrides."""
    return Experiment(
        "robustness",
        robustness_trial,
        _scenario(scenario_toml, drift_scale, overrides),
        n_trials,
        ({"plate_sigma_px": float(plate_sigma_px), "section": section},),
    )


def drift_trial(scn: Scenario, rng: np.random.Generator, drift_scale: float) -> dict:
    """The before-ICP error of the multi-view scans with the drift steps scaled by
    ``drift_scale``, with hand-eyes calibrated as in the station trial: mean over arms, spheres
    and views, and per arm and sphere."""
    sc = scn.with_drift_scale(drift_scale)
    df = pd.DataFrame(icp_rows(sc, hand_eyes(sc, rng), rng, icp=False))
    per = df.groupby(["arm", "sphere"])["before_mm"].mean()
    return {
        "before_mm": float(per.mean()),
        **{f"before_{a}{s}_mm": float(v) for (a, s), v in per.items()},
    }


def drift_experiment(scenario_toml: str = "", n_trials: int = 30, scales=(1.0,)) -> Experiment:
    """Before-ICP error per arm-sphere pair against the drift scale, the same trials at every
    scale: the pilot of the drift's joint calibration to the paper's four before-ICP errors
    (:func:`calstudy.papers.dualarm.report_calibration.drift_fit`)."""
    points = tuple({"drift_scale": float(s)} for s in scales)
    return Experiment("drift_pilot", drift_trial, _scenario(scenario_toml), n_trials, points)


def plate_trial(scn: Scenario, rng: np.random.Generator, plate_sigma_px: float) -> dict:
    """The circular-plate route alone (hand-eye, plate, Eq. 11, the Tables 1-2 test) with
    circle centres good to ``plate_sigma_px``: its mean Euclidean sphere-centre error."""
    cam2flange = hand_eyes(scn, rng)
    circ = plate_base_to_base(scn, cam2flange, rng, plate_sigma_px)
    df = pd.DataFrame(global_rows(scn, cam2flange, {"circular plate": circ}, rng, oracle=False))
    return {"plate_euclid_mm": float(df["euclid_mm"].mean())}


def plate_experiment(scenario_toml: str = "", n_trials: int = 30, sigmas=(0.1,)) -> Experiment:
    """Plate error against its circle-centre noise: the pilot of the plate noise's calibration
    to Table 3's plate row (:func:`calstudy.papers.dualarm.report_calibration.plate_fit`)."""
    points = tuple({"plate_sigma_px": float(s)} for s in sigmas)
    return Experiment("plate_pilot", plate_trial, _scenario(scenario_toml), n_trials, points)


def survey_trial(
    scn: Scenario,
    rng: np.random.Generator,
    bridge_views: int,
    bridge_tilt_deg: float,
    calibration_poses: int,
) -> dict:
    """The coded-marker route alone (hand-eyes, survey, each arm's calibration poses, Eq. 11, the
    Tables 1-2 test) with a survey of ``bridge_views`` linking images tilted up to
    ``bridge_tilt_deg`` and ``calibration_poses`` poses per arm: its mean Euclidean sphere-centre
    error, the link error of the survey and the markers' RMS error."""
    sc = scn.replace(
        {
            "survey.bridge_views": int(bridge_views),
            "survey.bridge_tilt_deg": bridge_tilt_deg,
            "global_test.calibration_poses": int(calibration_poses),
        }
    )
    cam2flange, recon, ours = coded_marker_chain(sc, rng)
    df = pd.DataFrame(global_rows(sc, cam2flange, {"coded markers": ours}, rng, oracle=False))
    return {
        "coded_euclid_mm": float(df["euclid_mm"].mean()),
        "link_deg": link_error_deg(sc, recon.bundle.points),
        "marker_rms_mm": marker_error(sc, recon.bundle.points),
    }


def survey_points(scn: Scenario, bridge_views=(4, 16), bridge_tilts_deg=(5.0, 25.0), poses=(6, 10)):
    """The sweep points of the survey design: the scenario's design, and one input at a time
    changed to each of the given values (linking images, their tilt, calibration poses per
    arm)."""
    base = {
        "bridge_views": int(scn.survey.bridge_views),
        "bridge_tilt_deg": float(round(np.degrees(scn.survey.bridge_tilt), 6)),
        "calibration_poses": int(scn.global_test.calibration_poses),
    }
    points = [base]
    for key, values in (
        ("bridge_views", bridge_views),
        ("bridge_tilt_deg", bridge_tilts_deg),
        ("calibration_poses", poses),
    ):
        for v in values:
            p = {**base, key: type(base[key])(v)}
            if p not in points:
                points.append(p)
    return tuple(points)


def survey_experiment(
    scenario_toml: str = "",
    n_trials: int = 30,
    bridge_views=(4, 16),
    bridge_tilts_deg=(5.0, 25.0),
    poses=(6, 10),
) -> Experiment:
    """The survey-design sweeps (inputs the paper leaves open, rule 11): the coded-marker
    route's sphere-centre error against the number of linking images, their tilt and the
    calibration poses per arm, one at a time from the scenario's design."""
    scn = _scenario(scenario_toml)
    points = survey_points(scn, bridge_views, bridge_tilts_deg, poses)
    return Experiment("survey_sweep", survey_trial, scn, n_trials, points)


def budget_trial(scn: Scenario, rng: np.random.Generator) -> list:
    """The error budget of the coded-marker chain on one station: the Tables 1-2 test rows of
    the whole chain (``coded markers``), of each source of :data:`BUDGET_SOURCES` alone
    (``budget: <source>``, :func:`budget_b2b1`) and of no calibration error (``true
    calibration``, the test's floor), all on the same draws; and one row (part ``eq10``) on
    the survey's bundle adjustment with and without the Euclidean residual of Eq. 10, which is
    triangulated from the pixels Eq. 9 already uses."""
    cam2flange, recon, ours, noisy, exact, views = _chain(scn, rng)
    b2b1 = {
        "coded markers": ours,
        **budget_b2b1(scn, cam2flange, recon.bundle.points, noisy, exact),
    }
    # Eq. 9 alone: the Euclidean weight so large that Eq. 10 carries no weight
    eq9 = survey_markers(scn.replace({"detection.marker_sigma_mm": 1e9}), views).bundle.points
    eq10 = {
        "part": "eq10",
        "marker_rms_mm": marker_error(scn, recon.bundle.points),
        "marker_rms_eq9_only_mm": marker_error(scn, eq9),
        "link_deg": link_error_deg(scn, recon.bundle.points),
        "link_eq9_only_deg": link_error_deg(scn, eq9),
    }
    return [*global_rows(scn, cam2flange, b2b1, rng), eq10]


def budget_experiment(scenario_toml: str = "", n_trials: int = 30) -> Experiment:
    """The error budget by source, ``n_trials`` paired trials."""
    return Experiment("budget", budget_trial, _scenario(scenario_toml), n_trials)
