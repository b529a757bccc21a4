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
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators import sfm as mk
from calstudy.estimators.fitting import fit_rigid, fit_sphere, solve_pnp, solve_pnp_ransac
from calstudy.estimators.handeye import MIN_PAIR_ROTATION, base_to_base, opencv_handeye
from calstudy.estimators.icp import weighted_icp
from calstudy.papers.dualarm import simulate as sim
from calstudy.papers.dualarm.scenario import ARMS, SPHERES, Scenario

# ----------------------------------------------------------------------------------------------
# 1. hand-eye by Tsai-Lenz (Eq. 1-2)


def handeye_data(scn: Scenario, arm: int, rng: np.random.Generator):
    """Arm ``arm`` images the plate from ``handeye_poses`` poses; returns ``(reported
    flange2base, plate2cam by PnP)``, each ``(n, 4, 4)``."""
    reported, uvs = sim.handeye_images(scn, arm, rng)
    return reported, np.stack([solve_pnp(scn.plate_points, uv, scn.rig.left.K) for uv in uvs])


def hand_eyes(scn: Scenario, rng: np.random.Generator) -> np.ndarray:
    """``cam2flange`` ``(2, 4, 4)`` of both arms by Tsai-Lenz (``cv2.calibrateHandEye``), each
    pair of consecutive poses rotating by at least ``MIN_PAIR_ROTATION``."""
    return np.stack(
        [opencv_handeye(*handeye_data(scn, arm, rng), "Tsai", MIN_PAIR_ROTATION) for arm in ARMS]
    )


# ----------------------------------------------------------------------------------------------
# 2-3. markers and the base-to-base chain (Eq. 5-11)


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


def coded_marker_chain(scn: Scenario, rng: np.random.Generator):
    """Steps 1-3 on one simulated station: ``(cam2flange_est (2, 4, 4), reconstruction,
    base2_to_base1 by the coded markers)``."""
    cam2flange = hand_eyes(scn, rng)
    recon = survey_markers(scn, sim.survey_views(scn, rng))
    arm_data = [sim.arm_world_views(scn, arm, rng) for arm in ARMS]
    return cam2flange, recon, marker_base_to_base(scn, cam2flange, recon.bundle.points, arm_data)


def marker_error(scn: Scenario, points) -> float:
    """RMS distance (mm) of reconstructed markers from Table A1 after the best rigid fit."""
    p = np.asarray(points)
    ok = np.all(np.isfinite(p), axis=1)
    fitted = geo.apply(fit_rigid(p[ok], scn.markers[ok]), p[ok])
    return float(np.sqrt(np.mean(np.sum((fitted - scn.markers[ok]) ** 2, axis=1))))


# ----------------------------------------------------------------------------------------------
# 5. the circular-plate comparison (Table 3)


def plate_base_to_base(scn: Scenario, cam2flange_est, rng: np.random.Generator) -> np.ndarray:
    """Baseline: a circle plate halfway between the arms (overlapping field), each arm images it
    from ``calibration_poses`` poses from its own side; RANSAC-PnP poses; Eq. 11."""
    flanges, plate2cams = [], []
    for reported, uvs in sim.circular_plate_images(scn, rng):
        k = scn.rig.left.K
        p2c = [solve_pnp_ransac(scn.plate_points, uv, k, scn.ransac_threshold_px) for uv in uvs]
        flanges.append(reported)
        plate2cams.append(np.stack(p2c))
    return base_to_base(
        flanges[0], cam2flange_est[0], plate2cams[0], flanges[1], cam2flange_est[1], plate2cams[1]
    )


# ----------------------------------------------------------------------------------------------
# 4. sphere scans and M3DHE-ICP (Eq. 3-4)


def scans_in_base(scn, arm, centre_world, radius, n_views, rng, cam2flange_est):
    """A multi-view scan of one sphere by arm ``arm``: clouds in its base by Eq. 3 with the
    reported poses (drifting) and the estimated hand-eye; list of ``(N, 3)`` arrays."""
    reported, clouds = sim.sphere_scans(scn, arm, centre_world, radius, n_views, rng)
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
            stop_below_noise=True,
            tree=tree,
        )
        out.append(geo.apply(res.transform, p))
    return out


def centre_errors(clouds: list[np.ndarray]) -> np.ndarray:
    """Distances ``(n - 1,)`` of the sphere centres fitted to clouds 1.. from that of cloud 0."""
    c = np.array([fit_sphere(p)[0] for p in clouds])
    return np.linalg.norm(c[1:] - c[0], axis=1)


def icp_experiment(scn: Scenario, cam2flange_est, rng: np.random.Generator) -> pd.DataFrame:
    """Figs. 5-6: per arm and sphere, centre-distance errors of views 1.. before/after ICP."""
    rows = []
    for arm in ARMS:
        for s in SPHERES:
            r = scn.sphere_radius[s]
            clouds = scans_in_base(
                scn,
                arm,
                sim.sphere_place(scn, arm, r),
                r,
                scn.icp_views,
                rng,
                cam2flange_est[arm - 1],
            )
            before = centre_errors(clouds)
            after = centre_errors(icp_correct(scn, clouds))
            for k, (b, a) in enumerate(zip(before, after, strict=True)):
                rows.append({"arm": arm, "sphere": s, "view": k + 1, "before_mm": b, "after_mm": a})
    return pd.DataFrame(rows)


def _centre_rows(name: str, group: int, c12, ref, truth) -> list[dict]:
    """Rows of Tables 1-2 for one method and group: arm 1's centres ``c12`` ``(n, 3)`` in base 2
    against arm 2's reference centre ``ref`` and the true centre ``truth``."""
    rows = []
    for k in range(len(c12)):
        d = np.abs(c12[k] - ref)
        rows.append(
            {
                "method": name,
                "group": group,
                "pose": k + 1,
                "dx_mm": d[0],
                "dy_mm": d[1],
                "dz_mm": d[2],
                "euclid_mm": float(np.linalg.norm(c12[k] - ref)),
                "euclid_truth_mm": float(np.linalg.norm(c12[k] - truth)),
            }
        )
    return rows


def global_experiment(scn: Scenario, cam2flange_est, b2b1: dict, rng) -> pd.DataFrame:
    """Tables 1-3: sphere A at ``global_groups`` places between the arms; arm 2's ICP-corrected
    multi-view cloud gives the reference centre in base 2; each of arm 1's ICP-corrected clouds
    is mapped into base 2 with each estimate in ``b2b1`` (name -> base2_to_base1)."""
    r = scn.sphere_radius["A"]
    rows = []
    for g, off in enumerate(scn.placement_offsets_mm[: scn.global_groups]):
        centre = sim.global_sphere_place(scn, off, r)
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
            rows += _centre_rows(name, g + 1, geo.apply(geo.invert(t), c1), ref, truth)
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# one trial and the Monte Carlo


def calibrate_station(scn: Scenario, rng: np.random.Generator):
    """Steps 1-3 and 5 on one simulated station: ``(cam2flange_est (2, 4, 4), reconstruction,
    {"coded markers": b2b1, "circular plate": b2b1})``."""
    cam2flange, recon, ours = coded_marker_chain(scn, rng)
    circ = plate_base_to_base(scn, cam2flange, rng)
    return cam2flange, recon, {"coded markers": ours, "circular plate": circ}


def _transform_error(quantity: str, estimate, truth) -> dict:
    return {
        "quantity": quantity,
        "rotation_deg": float(np.degrees(geo.rotation_error(estimate, truth))),
        "translation_mm": float(geo.translation_error(estimate, truth)),
    }


def run_trial(scn: Scenario, rng: np.random.Generator) -> dict:
    """One simulated replication of the paper's experiments; a dict of DataFrames."""
    cam2flange, recon, b2b1 = calibrate_station(scn, rng)
    cal = [
        _transform_error(f"hand-eye arm {a}", cam2flange[a - 1], scn.cam2flange[a - 1])
        for a in ARMS
    ]
    cal += [
        _transform_error(f"base-to-base, {name}", t, scn.base2_to_base1) for name, t in b2b1.items()
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


# ----------------------------------------------------------------------------------------------
# sweeps


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
            _, recon, b2b = coded_marker_chain(sc, np.random.default_rng(ss))
            err = _transform_error("", b2b, sc.base2_to_base1)
            rows.append(
                {
                    "bridge_views": int(n),
                    "trial": t,
                    "rotation_deg": err["rotation_deg"],
                    "translation_mm": err["translation_mm"],
                    "marker_rms_mm": marker_error(sc, recon.bundle.points),
                }
            )
    return pd.DataFrame(rows)
