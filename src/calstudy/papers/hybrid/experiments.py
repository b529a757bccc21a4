"""The hybrid study's experiments: trial functions, Monte Carlo loops and sweeps.

Notebook 01 (the station's calibration): the hand-eye of the flexible sensor from the fixed
sphere against OpenCV's AX = XB solvers and maximum likelihood (:func:`handeye_monte_carlo`), the
stationary sensors by the homography chain (:func:`stationary_monte_carlo`), the 3-2-1 workpiece
frame (:func:`rps_trial`, :func:`rps_penalty_sweep`) and the robot's absolute accuracy.

Notebook 02 (the station in production): stations drawn and calibrated as in notebook 01
(:func:`calibrated_station`), run through the paper's compensation protocol
(:func:`production_monte_carlo`), and the sweeps of its assumptions (:func:`sensitivity_sweep`,
:func:`robot_error_sweep`).

Every trial has its own generator, spawned from the notebook's seed (:func:`trial_generators`).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.fitting import fit_homography, homography_to_pose, solve_pnp
from calstudy.estimators.handeye import (
    OPENCV_METHODS,
    opencv_handeye,
    read_sphere_measurements,
    sphere_handeye,
    sphere_handeye_crb,
    sphere_handeye_ml,
    stationary_sensor_to_base,
)
from calstudy.estimators.workpiece import rps_frame_penalty, rps_frame_so3
from calstudy.models.kinematics import load_robot, perturb_robot, pose_errors
from calstudy.papers.hybrid.compensation import analyse_run, before_compensation
from calstudy.papers.hybrid.scenario import SWEEP_LABELS, Scenario, load_features
from calstudy.papers.hybrid.simulate import (
    HybridStation,
    make_station,
    simulate_sphere_measurements,
)
from calstudy.papers.hybrid.simulate_production import (
    ProductionStation,
    simulate_run,
    teach_program,
)

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
    """Print ``text`` (flushed) if ``progress``."""
    if progress:
        print(text, flush=True)


def paper_moves(station: HybridStation) -> tuple[int, int]:
    """The paper's calibration moves (section 4.2): pure translations, then pose changes."""
    moves = station.config["calibration_moves"]
    return moves["n_translations"], moves["n_rotations"]


# ---------------------------------------------------------------------------------------------
# trials of notebook 01


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
    length, width = station.config["workpiece"]["size_mm"]
    corners = np.array([[0, 0, 0], [length, 0, 0], [0, width, 0], [length, width, 0]], dtype=float)
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


# ---------------------------------------------------------------------------------------------
# Monte Carlo runners of notebook 01


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


def stationary_monte_carlo(
    seed: int, n_trials: int, scenario: str = "station", stream: int = 1, progress: bool = False
):
    """Stationary-sensor errors over ``n_trials`` stations, each with its own hand-eye run.

    Each trial draws a station, calibrates the flexible sensor by the paper's sphere method
    (4 + 6 moves), then the ten stationary sensors by Eq. 23. Returns (errors table with columns
    trial, scenario, sensor, variant, rotation_error_deg, translation_error_mm; RPS table, see
    :func:`rps_trial`, from the calibrated sensors A, B, C).
    """
    start = time.perf_counter()
    rows, rps_rows = [], []
    for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
        station = make_station(rng, **SCENARIOS[scenario])
        meas, _ = simulate_sphere_measurements(station, *paper_moves(station), rng)
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
    rng = np.random.default_rng([seed, 99])
    truth = None
    if measurements_csv:
        meas = read_sphere_measurements(measurements_csv)
        source = f"user measurements from {measurements_csv} ({len(meas.ids)} rows)"
        sigma = np.broadcast_to(np.asarray(sensor_sigma_mm, dtype=float), (3,))
    else:
        station = make_station(rng)
        meas, _ = simulate_sphere_measurements(station, *paper_moves(station), rng)
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


# ---------------------------------------------------------------------------------------------
# notebook 02: calibrated stations in production


def calibrated_station(
    rng: np.random.Generator, robot_errors: bool = True, robot_error_scale: float = 1.0
) -> ProductionStation:
    """Draw a station and calibrate it as notebook 01 does (sphere hand-eye, homography chain).

    ``robot_error_scale`` multiplies the robot's kinematic tolerances (see
    :func:`calstudy.papers.hybrid.simulate.make_station`).
    """
    station = make_station(rng, robot_errors=robot_errors, robot_error_scale=robot_error_scale)
    return calibrate(station, rng)


def calibrate(st: HybridStation, rng: np.random.Generator) -> ProductionStation:
    """Calibrate a drawn station by the paper's methods: the flexible sensor from the sphere
    (4 translations, 6 pose changes), the stationary sensors by the homography chain (Eq. 23)."""
    features = load_features(station_config=st.config)
    meas, _ = simulate_sphere_measurements(st, *paper_moves(st), rng)
    s2f = sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    rows = stationary_trial(st, s2f, rng)
    cams = np.array([r["estimate"] for r in rows if r["variant"] == "homography"])
    return ProductionStation(st, features, teach_program(st, features), s2f, cams)


def trial_summary(run: dict, scenario: Scenario, n_values) -> tuple[dict, list[dict]]:
    """The systematic-error figures and the Table 1 figures (one row per ``n``) of one run."""
    before = before_compensation(run, scenario.n_before)
    free = ~before["fixed"]
    norms = np.linalg.norm(before["mean"], axis=1)
    system = {
        "systematic_median_mm": float(np.median(norms)),
        "systematic_max_mm": float(norms.max()),
        "scatter_median_mm": float(np.median(before["std"][free])),
        "lilliefors_not_rejected": 100.0 * float(np.mean(before["lilliefors_p"][free] >= 0.05)),
        "mean_nonzero": 100.0 * float(np.mean(before["t_test_p"][free] < 0.05)),
    }
    rows = []
    for n in n_values:
        a = analyse_run(run, int(n))
        row = {"n_compensation": int(n)}
        row |= {k: a[k] for k in ("within_0p3", "beyond_0p5", "within_0p3_uncompensated")}
        row |= {k: a[k] for k in ("single_within_0p3", "r_above_0p7", "n_vectors", "n_fixed")}
        row |= {f"deviation_bin{k}": int(v) for k, v in enumerate(a["deviation_counts"])}
        row |= {f"correlation_bin{k}": int(v) for k, v in enumerate(a["correlation_counts"])}
        rows.append(row)
    return system, rows


def production_monte_carlo(
    seed: int,
    n_trials: int,
    scenario: Scenario,
    n_values,
    stream: int = 0,
    progress: bool = False,
):
    """Run the paper's protocol on ``n_trials`` drawn and calibrated stations.

    Returns ``(systematic, table1, stations, first_run)``: one row per trial of the
    before-compensation figures; one row per trial and ``n`` of the Table 1 figures; the
    calibrated stations (for the sensitivity sweep); the run of trial 0.
    """
    start = time.perf_counter()
    n_values = sorted({int(n) for n in n_values} | {scenario.n_compensation})
    if max(n_values) > scenario.n_compensation_max:
        raise CalibrationError(
            f"n values up to {max(n_values)} exceed n_compensation_max "
            f"{scenario.n_compensation_max}"
        )
    system_rows, table_rows, stations, first = [], [], [], None
    for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
        ps = calibrated_station(rng)
        run = simulate_run(ps, scenario, rng)
        system, rows = trial_summary(run, scenario, n_values)
        system_rows.append({"trial": k} | system)
        table_rows += [{"trial": k} | r for r in rows]
        stations.append(ps)
        if k == 0:
            first = run
        if progress and (k + 1) % max(1, n_trials // 5) == 0:
            log_progress(
                progress, f"{k + 1}/{n_trials} stations in {time.perf_counter() - start:.1f} s"
            )
    return pd.DataFrame(system_rows), pd.DataFrame(table_rows), stations, first


def sensitivity_sweep(
    stations, scenario: Scenario, values: dict, seed: int, stream: int = 1, progress=False
):
    """The two headline shares as each assumption in ``values`` moves (others at default).

    Each calibrated station of ``stations`` is reused (its systematic error stays); the panels,
    readings and drift are drawn anew for each value. Returns one row per assumption, value
    and station: ``parameter, value, trial, within_0p3, r_above_0p7``.
    """
    start = time.perf_counter()
    rows = []
    for i, (name, vals) in enumerate(values.items()):
        if name not in SWEEP_LABELS:
            raise CalibrationError(f"unknown swept assumption {name!r}; use {list(SWEEP_LABELS)}")
        for j, v in enumerate(vals):
            sc = scenario.with_(**{name: float(v)})
            for k, ps in enumerate(stations):
                rng = np.random.default_rng([seed, stream, i, j, k])
                a = analyse_run(simulate_run(ps, sc, rng), sc.n_compensation)
                rows.append(
                    {
                        "parameter": name,
                        "value": float(v),
                        "trial": k,
                        "within_0p3": a["within_0p3"],
                        "r_above_0p7": a["r_above_0p7"],
                    }
                )
        log_progress(progress, f"sweep of {name}: {time.perf_counter() - start:.1f} s")
    return pd.DataFrame(rows)


def robot_error_sweep(
    seed: int, n_trials: int, scenario: Scenario, scales, stream: int = 2, progress=False
) -> pd.DataFrame:
    """The before-compensation and Table 1 figures as the true robot's manufacturing errors scale.

    For each factor of ``scales``, ``n_trials`` stations are drawn with the kinematic tolerances
    of ``data/robots/kuka_kr16_2.toml`` times the factor, calibrated and run through the paper's
    protocol with the other assumptions of ``scenario``. Station ``k`` gets the same generator
    at every factor (stream ``stream`` of ``seed``), so its robot errors keep their direction and
    only their size changes. Returns one row per factor and station: ``robot_error_scale``,
    ``trial`` and the figures of :func:`trial_summary` at ``scenario.n_compensation``.
    """
    scales = [float(s) for s in scales]
    if not scales:
        raise CalibrationError("scales is empty; give at least one factor on the tolerances")
    start = time.perf_counter()
    rows = []
    for scale in scales:
        for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
            ps = calibrated_station(rng, robot_error_scale=scale)
            run = simulate_run(ps, scenario, rng)
            system, (table,) = trial_summary(run, scenario, [scenario.n_compensation])
            rows.append({"robot_error_scale": scale, "trial": k} | system | table)
        log_progress(progress, f"robot tolerances x {scale:g}: {time.perf_counter() - start:.1f} s")
    return pd.DataFrame(rows)
