"""The hybrid study's experiments: trial functions and the factories that build them.

Every Monte Carlo loop of notebooks 01 and 02 runs through :func:`calstudy.io.runs.run_experiments`
with a factory of this module (``<name>_experiment(**json_able_kwargs) -> Experiment``); the
engine gives each trial its generator from (seed, experiment, sweep point, trial), so there are no
stream numbers here. A trial function is ``trial(setup, rng, **point) -> list[dict]`` with scalar
values; ``setup`` is a plain dict of the notebook's settings (its cache fingerprint).

Notebook 01 (the station's calibration): the hand-eye of the flexible sensor from the fixed sphere
(its factories are in :mod:`calstudy.papers.hybrid.handeye_experiments`), the stationary
sensors by the homography chain with its null and oracle controls and the 3-2-1 frame
(:func:`stationary_experiment`, :func:`rps_penalty_experiment`), the robot's absolute accuracy
(:func:`robot_accuracy_experiment`).

Notebook 02 (the station in production): stations drawn and calibrated as in notebook 01
(:func:`calibrated_station`), run through the paper's compensation protocol
(:func:`production_experiment`), and the sweeps of its assumptions
(:func:`sensitivity_experiment`, :func:`robot_error_experiment`); the part variation the published
correlation bins need (:func:`part_variation_experiment`) and one point of the robustness map of
the three claims (:func:`robustness_experiment`, driven by
:mod:`calstudy.papers.hybrid.production_robustness`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import Experiment, child_rng, trial_rng
from calstudy.core.schema import with_inputs
from calstudy.estimators.fitting import fit_homography, homography_to_pose, solve_pnp
from calstudy.estimators.workpiece import orthogonality, rps_frame_penalty, rps_frame_so3
from calstudy.handeye import sphere_handeye
from calstudy.models.robots import load_robot, perturb_robot, pose_errors
from calstudy.papers.hybrid.compensation import (
    analyse_run,
    before_compensation,
    correlation_bins,
    correlations,
    frame_fixed,
)
from calstudy.papers.hybrid.handeye_experiments import (
    SCENARIOS,
    check_scenario,
    paper_moves,
    station_config,
)
from calstudy.papers.hybrid.scenario import (
    SWEEP_KEYS,
    Scenario,
    load_production,
    load_scenario,
    load_station,
    panel_features,
)
from calstudy.papers.hybrid.schema import StationFile
from calstudy.papers.hybrid.simulate import (
    HybridStation,
    make_station,
    simulate_sphere_measurements,
)
from calstudy.papers.hybrid.simulate_production import (
    ProductionStation,
    simulate_products,
    simulate_run,
    teach_program,
)

#: the variants of :func:`stationary_trial`, in the order of its rows
STATIONARY_VARIANTS = (
    "homography",
    "pnp",
    "images only, homography",
    "images only, pnp",
    "design pose",
    "exact target, homography",
    "exact target, pnp",
    "drawing target, homography",
)


def _target_poses(method: str, front_cad, back_cad, uv_pair, k) -> tuple:
    """``(front2cam, back2cam)`` of the two-sided target from its two images, by Eq. 19 from
    the homographies (``method="homography"``) or by maximum-likelihood PnP (``"pnp"``)."""
    (uv_front, uv_back) = uv_pair
    if method == "pnp":
        return solve_pnp(front_cad, uv_front, k), solve_pnp(back_cad, uv_back, k)
    return (
        homography_to_pose(fit_homography(front_cad[:, :2], uv_front), k),
        homography_to_pose(fit_homography(back_cad[:, :2], uv_back), k),
    )


def stationary_sensor_to_base(
    flange2base, sensor2flange, front2flexcam, back2statcam, back2front
) -> np.ndarray:
    """Pose of a stationary camera in the robot base frame by Eq. 23.

    ``statcam2base = flange2base @ sensor2flange @ front2flexcam @ inv(back2statcam @ front2back)``
    which, with ``front2back = inv(back2front)``, is
    ``flange2base @ sensor2flange @ front2flexcam @ back2front @ inv(back2statcam)``.

    Parameters
    ----------
    flange2base : (4, 4) array
        Flange pose reported by the robot (forward kinematics), mm.
    sensor2flange : (4, 4) array
        Hand-eye of the flexible sensor; its camera frame is taken as the sensor frame.
    front2flexcam : (4, 4) array
        Front face of the target in the flexible sensor's camera frame (from its image).
    back2statcam : (4, 4) array
        Back face of the target in the stationary camera frame (from its image).
    back2front : (4, 4) array
        Back face to front face of the target (pre-calibrated on a CMM).

    Returns
    -------
    (4, 4) array
        ``statcam2base``.
    """
    mats = [
        geo.check_transform(name, m)
        for name, m in [
            ("flange2base", flange2base),
            ("sensor2flange", sensor2flange),
            ("front2flexcam", front2flexcam),
            ("back2statcam", back2statcam),
            ("back2front", back2front),
        ]
    ]
    f2b, s2f, front2cam, back2cam, b2f = mats
    return f2b @ s2f @ front2cam @ b2f @ geo.invert(back2cam)


def stationary_trial(
    station: HybridStation,
    sensor2flange: np.ndarray,
    rng: np.random.Generator,
    variants=STATIONARY_VARIANTS,
) -> list[dict]:
    """Calibrate the ten stationary sensors once (Eq. 23); errors per sensor and per variant.

    Variants: ``"homography"`` (the paper: Eq. 19 poses, the calibrated hand-eye, reported flange
    poses); ``"pnp"`` (same chain with ML PnP poses); ``"images only, homography|pnp"`` (the true
    hand-eye and the actual flange pose: the error the images, the target and the CMM leave);
    ``"design pose"`` (no calibration: the sensor's pose on the drawing, off by its mounting
    error; the null control of ``hybrid.stationary``); ``"exact target, homography|pnp"``
    (the images-only chains with a target made exactly to its drawing and its back-to-front
    transform known exactly: the hole tolerance and the CMM error removed, the pixel noise kept;
    the oracle control); ``"drawing target, homography"`` (the images-only homography chain with
    the back-to-front transform taken from the target's drawing: the CMM step skipped, a broken
    chain that the claim's criterion should tell from the paper's).

    ``variants`` (a subset of :data:`STATIONARY_VARIANTS`) selects the rows computed; every image
    is drawn whatever the selection, so the generator leaves the trial in the same state and a
    variant's rows do not depend on which others are computed.
    """
    unknown = set(variants) - set(STATIONARY_VARIANTS)
    if unknown:
        raise CalibrationError(
            f"unknown stationary variants {sorted(unknown)}; use {list(STATIONARY_VARIANTS)}"
        )
    wanted = [v for v in STATIONARY_VARIANTS if v in variants]
    rows = []
    k = station.camera.K
    front_cad = station.target.front_points()
    back_cad = station.target.back_points()
    b2f_exact = station.target.back2front()
    s2f_true = station.sensor2flange_true
    field_point = np.array([0.0, 0.0, station.standoff])  # centre of the measuring field
    for i in range(len(station.statcam2base_true)):
        q, _ = station.stationary_pose(i)
        reported, actual = station.move(q, rng)
        reported, actual = reported[0], actual[0]
        front2base = actual @ s2f_true @ station.front2sensor
        back2statcam = (
            geo.invert(station.statcam2base_true[i]) @ front2base @ station.target_made.back2front
        )
        uv_f = station.camera.observe(
            station.front2sensor, station.target_made.front_points, station.pixel_sigma, rng
        )
        uv_b = station.camera.observe(
            back2statcam, station.target_made.back_points, station.pixel_sigma, rng
        )
        # the same views of an exactly made target whose back-to-front transform is known
        # exactly (the oracle control: the target's errors removed, the pixel noise kept)
        back2statcam_exact = back2statcam @ geo.invert(station.target_made.back2front) @ b2f_exact
        uv_f0 = station.camera.observe(station.front2sensor, front_cad, station.pixel_sigma, rng)
        uv_b0 = station.camera.observe(back2statcam_exact, back_cad, station.pixel_sigma, rng)
        truth = station.statcam2base_true[i]
        poses: dict = {}  # (method, exact target) -> the target's two poses, fitted once
        for name in wanted:
            if name == "design pose":
                est = station.statcam2base_design[i]
            else:
                method = "pnp" if name.endswith("pnp") else "homography"
                exact = name.startswith("exact target")
                if (method, exact) not in poses:
                    uv_pair = (uv_f0, uv_b0) if exact else (uv_f, uv_b)
                    poses[method, exact] = _target_poses(method, front_cad, back_cad, uv_pair, k)
                # the paper's chain uses what the station knows; the others, the truth
                paper = name in ("homography", "pnp")
                flange, hand = (reported, sensor2flange) if paper else (actual, s2f_true)
                b2f = b2f_exact if exact else station.back2front_cmm
                if name.startswith("drawing target"):
                    b2f = b2f_exact  # the drawing's transform, the made target's images
                est = stationary_sensor_to_base(flange, hand, *poses[method, exact], b2f)
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
    so3: bool = True,
) -> list[dict]:
    """Locate the panel once by the 3-2-1 rule with the calibrated stationary sensors A, B, C.

    The datum points are measured in the first three stationary sensors' frames with noise and
    mapped to the base frame with their calibrated poses ``statcam2base[:3]``. Returns one row
    per solver (the penalty LM for each ``M``, and with ``so3`` the SO(3) solution) with the
    frame error: the largest displacement it causes at the panel's corners and datums (mm), and
    the rotation error.
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
    length, width = station.config.workpiece.size_mm
    corners = np.array([[0, 0, 0], [length, 0, 0], [0, width, 0], [length, width, 0]], dtype=float)
    check_pts_base = geo.apply(work2base_true, np.vstack([corners, station.datums_work]))
    rows = []
    solvers = [(f"penalty M={m:g}", m) for m in penalties] + ([("SO(3)", None)] if so3 else [])
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
                "eq4_residual": float(np.abs(orthogonality(r)).max()),
                "evaluations": est.iterations,
            }
        )
    return rows


# ---------------------------------------------------------------------------------------------
# trial functions and factories of notebook 01


def stationary_run(
    setup: dict,
    rng: np.random.Generator,
    scenario: str = "station",
    pixel_sigma: float | None = None,
) -> list[dict]:
    """One station: the sphere hand-eye (4 + 6 moves), the ten stationary sensors by Eq. 23 and
    the 3-2-1 frame from the calibrated sensors A, B, C.

    ``pixel_sigma`` overrides the hole-centre noise of ``station.toml`` (px), and
    ``setup["overrides"]``, if given, other inputs of it by their dotted keys. Rows with
    ``step == "stationary"``: ``sensor, variant`` and the errors of :func:`stationary_trial`;
    rows with ``step == "rps"``: the columns of :func:`rps_trial`.
    """
    config = station_config(setup.get("overrides"))
    station = make_station(rng, pixel_sigma=pixel_sigma, config=config, **check_scenario(scenario))
    meas, _ = simulate_sphere_measurements(station, *paper_moves(station), rng)
    s2f = sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    rows = stationary_trial(station, s2f, child_rng(rng, "stationary sensors"))
    out = [{"step": "stationary"} | {c: r[c] for c in r if c != "estimate"} for r in rows]
    calibrated = np.array([r["estimate"] for r in rows if r["variant"] == "homography"])
    out += [{"step": "rps"} | r for r in rps_trial(station, calibrated, child_rng(rng, "datums"))]
    return out


def stationary_experiment(n_trials: int = 200) -> Experiment:
    """Stationary sensors and the 3-2-1 frame in both scenarios (points ``scenario``)."""
    points = [{"scenario": name} for name in SCENARIOS]
    return Experiment("stationary", stationary_run, {"version": 4}, n_trials, points)


def stationary_pixel_experiment(pixel_sigmas=None, n_trials: int = 30) -> Experiment:
    """The stationary sensors against the hole-centre noise (px), sensor noise only (the
    scenario of the verdict). Default values: ``[cameras] pixel_sigmas`` of ``station.toml``."""
    values = load_station().cameras.pixel_sigmas if pixel_sigmas is None else pixel_sigmas
    if len(values) == 0:
        raise CalibrationError("no pixel noise values to sweep; give at least one")
    points = [{"scenario": "sensor noise only", "pixel_sigma": float(v)} for v in values]
    return Experiment("stationary_pixel", stationary_run, {"version": 4}, n_trials, points)


#: the far start of the penalty sweep: the nominal fixture pose turned by this angle (deg)
FAR_START_DEG = 90.0


def rps_penalty_run(setup: dict, rng: np.random.Generator) -> list[dict]:
    """How the 3-2-1 solution depends on the penalty ``M`` of Eq. 5, from three starting points.

    A station with its true stationary calibration (only datum noise matters), the datums
    measured once, then the penalty LM for every ``M`` from the nominal fixture pose, from the
    identity and from a far start (the nominal pose turned by ``FAR_START_DEG`` about an axis
    drawn per trial), against the SO(3) solution on the same data. Failures are rows with
    ``converged`` False, not hidden; ``eq4_residual`` is the largest of the six conditions of
    Eq. 4 at the solution, ``orthogonality_defect`` the largest entry of ``R^T R - I``.
    """
    penalties = [float(m) for m in setup["penalties"]]
    station = make_station(rng)
    axis = child_rng(rng, "far start").normal(size=3)
    turn = geo.rotvec_to_matrix(np.deg2rad(FAR_START_DEG) * axis / np.linalg.norm(axis))
    far = station.base2work_nominal.copy()
    far[:3, :3] = turn @ far[:3, :3]
    # the reference: the SO(3) solution from the nominal fixture pose, on the same datums
    so3 = rps_trial(station, station.statcam2base_true, child_rng(rng, "datums"), [])[0]
    rows = []
    for start_name, start in (
        ("nominal fixture pose", station.base2work_nominal),
        ("identity", np.eye(4)),
        (f"nominal turned {FAR_START_DEG:g} deg", far),
    ):
        st = replace(station, base2work_nominal=start)
        for m in penalties:
            try:  # each M alone, on the same datums: one failure does not hide the others
                datums = child_rng(rng, "datums")
                r = rps_trial(st, station.statcam2base_true, datums, [m], so3=False)[0]
            except CalibrationError:
                r = None
            rows.append(
                {
                    "start": start_name,
                    "penalty": m,
                    "converged": r is not None,
                    "evaluations": np.nan if r is None else r["evaluations"],
                    "orthogonality_defect": np.nan if r is None else r["orthogonality_defect"],
                    "eq4_residual": np.nan if r is None else r["eq4_residual"],
                    "frame_error_mm": np.nan if r is None else r["frame_error_mm"],
                    "excess_over_so3_mm": np.nan
                    if r is None
                    else r["frame_error_mm"] - so3["frame_error_mm"],
                }
            )
    return rows


def rps_penalty_experiment(penalties=(1e-6, 1e-3, 1.0, 1e3, 1e6), n_trials: int = 30):
    """The penalty sweep of Eq. 5 (all penalties inside each trial, on the same datums)."""
    setup = {"penalties": [float(m) for m in penalties], "far_start_deg": FAR_START_DEG}
    return Experiment("rps_penalty", rps_penalty_run, setup, n_trials)


def robot_accuracy_run(setup: dict, rng: np.random.Generator) -> dict:
    """Absolute accuracy of one drawn "true" robot against the nominal model (what the
    controller computes with), over ``setup["n_configs"]`` random configurations."""
    nominal = load_robot("kuka_kr16_2")
    true = perturb_robot(nominal, child_rng(rng, "robot"))
    draws = child_rng(rng, "configurations")
    configurations = nominal.random_configurations(draws, setup["n_configs"])
    pos, rot = pose_errors(nominal, true, configurations)
    return {
        "position_error_rms_mm": float(np.sqrt(np.mean(pos**2))),
        "position_error_max_mm": float(pos.max()),
        "rotation_error_rms_deg": float(np.rad2deg(np.sqrt(np.mean(rot**2)))),
    }


def robot_accuracy_experiment(n_robots: int = 20, n_configs: int = 200) -> Experiment:
    """The absolute accuracy of ``n_robots`` drawn robots (one trial each)."""
    setup = {"n_configs": int(n_configs)}
    return Experiment("robot_accuracy", robot_accuracy_run, setup, n_robots)


# ---------------------------------------------------------------------------------------------
# notebook 02: calibrated stations in production


def calibrated_station(
    rng: np.random.Generator,
    robot_errors: bool = True,
    robot_error_scale: float = 1.0,
    config: StationFile | None = None,
) -> ProductionStation:
    """Draw a station and calibrate it as notebook 01 does (sphere hand-eye, homography chain).

    ``robot_error_scale`` multiplies the robot's kinematic tolerances and ``config`` is the
    station description, default ``station.toml`` (see
    :func:`calstudy.papers.hybrid.simulate.make_station`).
    """
    station = make_station(
        rng, robot_errors=robot_errors, robot_error_scale=robot_error_scale, config=config
    )
    return calibrate(station, rng)


def calibrate(st: HybridStation, rng: np.random.Generator) -> ProductionStation:
    """Calibrate a drawn station by the paper's methods: the flexible sensor from the sphere
    (4 translations, 6 pose changes), the stationary sensors by the homography chain (Eq. 23)."""
    features = panel_features(load_production(), st.config)
    meas, _ = simulate_sphere_measurements(st, *paper_moves(st), rng)
    s2f = sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    rows = stationary_trial(st, s2f, child_rng(rng, "stationary sensors"), variants=("homography",))
    cams = np.array([r["estimate"] for r in rows])
    return ProductionStation(st, features, teach_program(st, features), s2f, cams)


def trial_summary(run: dict, scenario: Scenario, n_values) -> tuple[dict, list[dict]]:
    """The systematic-error figures and the Table 1 figures (one row per ``n``) of one run.

    Systematic size in both readings of the paper's "2-4 mm": the length of the 3-D mean
    deviation vector per point (``systematic_median_mm``, median over points) and the mean
    deviation per coordinate, as Fig. 6 plots x, y, z apart (``systematic_coord_median_mm``,
    median |mean| over the coordinates not fixed by the frame; ``coord_above_2mm``, the share of
    them at 2 mm or more).
    """
    before = before_compensation(run, scenario.production.protocol.n_before)
    free = ~before["fixed"]
    norms = np.linalg.norm(before["mean"], axis=1)
    coord = np.abs(before["mean"][free])
    system = {
        "systematic_median_mm": float(np.median(norms)),
        "systematic_max_mm": float(norms.max()),
        "systematic_coord_median_mm": float(np.median(coord)),
        "coord_above_2mm": 100.0 * float(np.mean(coord >= 2.0)),
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
        row["within_0p3_oracle"] = a["within_0p3_oracle"]
        row |= {f"deviation_bin{k}": int(v) for k, v in enumerate(a["deviation_counts"])}
        row |= {f"correlation_bin{k}": int(v) for k, v in enumerate(a["correlation_counts"])}
        rows.append(row)
    return system, rows


def _production_setup(n_values, scenario_toml: str) -> dict:
    scenario = load_scenario(scenario_toml or None)
    protocol = scenario.production.protocol
    n_values = sorted({int(n) for n in n_values} | {protocol.n_compensation})
    if max(n_values) > protocol.n_compensation_max:
        raise CalibrationError(
            f"n values up to {max(n_values)} exceed n_compensation_max "
            f"{protocol.n_compensation_max}"
        )
    # version 2: each trial also runs the station with the robot's error off (two stations);
    # version 3: the stations are those of the scenario's station file, and each row carries
    # the bins of the controls (:func:`control_columns`)
    return {"scenario": scenario, "n_values": n_values, "version": 3}


def _coordinate_size(run: dict, scenario: Scenario) -> tuple[float, float]:
    """Median |mean deviation| before compensation over the coordinates not fixed by the frame,
    and the median panel-to-panel scatter of the same coordinates (mm)."""
    before = before_compensation(run, scenario.production.protocol.n_before)
    free = ~before["fixed"]
    return float(np.median(np.abs(before["mean"][free]))), float(np.median(before["std"][free]))


def production_run(setup: dict, rng: np.random.Generator) -> list[dict]:
    """One drawn and calibrated station run through the paper's protocol: one row per ``n`` of
    ``setup["n_values"]`` with the before-compensation figures and the Table 1 figures.

    Two more stations with the robot's error switched off (the true robot equal to the nominal
    model, the cause the paper names): the same station draws and products
    (``systematic_coord_robot_off_mm``, ``scatter_robot_off_mm``), and an independent station
    (``systematic_coord_floor_mm``): the systematic size that the calibration's noise alone
    leaves, the floor the systematic error is judged against."""
    scenario = setup["scenario"]
    config = scenario.station
    ps = calibrated_station(child_rng(rng, "station"), config=config)
    run = simulate_run(ps, scenario, child_rng(rng, "production"))
    system, rows = trial_summary(run, scenario, setup["n_values"])
    rows = [r | control_columns(analyse_run(run, r["n_compensation"])) for r in rows]
    off = calibrated_station(child_rng(rng, "station"), robot_error_scale=0.0, config=config)
    size_off, scatter_off = _coordinate_size(
        simulate_run(off, scenario, child_rng(rng, "production")), scenario
    )
    floor = calibrated_station(
        child_rng(rng, "calibration-noise floor"), robot_error_scale=0.0, config=config
    )
    size_floor, _ = _coordinate_size(
        simulate_run(floor, scenario, child_rng(rng, "floor production")), scenario
    )
    system |= {
        "systematic_coord_robot_off_mm": size_off,
        "scatter_robot_off_mm": scatter_off,
        "systematic_coord_floor_mm": size_floor,
    }
    return [system | r for r in rows]


def control_columns(analysis: dict) -> dict:
    """The bins of the controls of one :func:`~calstudy.papers.hybrid.compensation.analyse_run`
    as row columns: ``deviation_null_bin<k>`` (no offset), ``deviation_oracle_bin<k>`` (the
    drift removed) and ``correlation_null_bin<k>`` (each reading against another panel)."""
    out = {}
    for prefix, key in (
        ("deviation_null", "deviation_counts_uncompensated"),
        ("deviation_oracle", "deviation_counts_oracle"),
        ("correlation_null", "correlation_counts_mispaired"),
    ):
        out |= {f"{prefix}_bin{k}": int(v) for k, v in enumerate(analysis[key])}
    return out


def production_experiment(n_trials: int = 200, n_values=(3, 5, 10, 15, 20), scenario_toml=""):
    """The paper's protocol on ``n_trials`` drawn and calibrated stations."""
    setup = _production_setup(n_values, scenario_toml)
    return Experiment("production", production_run, setup, n_trials)


def first_station_run(seed: int, n_values=(3, 5, 10, 15, 20), scenario_toml: str = "") -> dict:
    """The simulated run of trial 0 of :func:`production_experiment` again (for Fig. 6 and the
    single-station tables): the same generator, so the same station and products."""
    setup = _production_setup(n_values, scenario_toml)
    rng = trial_rng(seed, "production", {}, 0)
    ps = calibrated_station(child_rng(rng, "station"))
    return simulate_run(ps, setup["scenario"], child_rng(rng, "production"))


def sensitivity_run(setup: dict, rng: np.random.Generator) -> list[dict]:
    """One calibrated station, each assumption moved alone over its values (others at default):
    one row per assumption and value with the two headline shares, the share within +-0.3 mm
    uncompensated and with the drift removed (the controls of ``hybrid.deviation``), the
    Kolmogorov distance of the correlation bins and the deviation bin counts. The station keeps its
    systematic error; the panels, readings and drift are drawn from the same child stream for
    every value (paired: only the assumption differs between two values of a trial)."""
    ps = calibrated_station(child_rng(rng, "station"))
    rows = []
    for name, values in setup["values"].items():
        for v, sc in zip(values, setup["scenarios"][name], strict=True):
            run = simulate_run(ps, sc, child_rng(rng, "production"))
            a = analyse_run(run, sc.production.protocol.n_compensation)
            row = {"parameter": name, "value": float(v)}
            for key in ("within_0p3", "within_0p3_uncompensated", "within_0p3_oracle"):
                row[key] = a[key]
            row["r_above_0p7"] = a["r_above_0p7"]
            row["r_distance"] = float(correlation_distance(a["correlation_counts"]))
            row |= {f"deviation_bin{k}": int(c) for k, c in enumerate(a["deviation_counts"])}
            rows.append(row)
    return rows


def correlation_distance(counts) -> float:
    """Kolmogorov distance (largest gap of the cumulative shares) between a station's
    correlation bins (5 counts, >0.9 first) and the published ones."""
    from calstudy.papers.hybrid.scenario import load_published

    c = np.asarray(counts, dtype=float)
    pub = np.asarray(load_published().table1.correlation_percent, dtype=float)
    share = np.cumsum(c) / max(1.0, c.sum())
    return float(np.max(np.abs(share - np.cumsum(pub) / pub.sum())))


def sensitivity_experiment(n_trials: int = 30, scenario_toml: str = "") -> Experiment:
    """The sweeps of ``[sweep]`` in ``production.toml``, every value inside each trial."""
    scenario = load_scenario(scenario_toml or None)
    sweep = load_production().sweep
    values = {k: [float(v) for v in getattr(sweep, k)] for k in sweep.input_names()}
    # each value's scenario, validated once (beyond the ledger's ranges: a sweep)
    scenarios = {
        k: [with_inputs(scenario, {SWEEP_KEYS[k]: v}) for v in vals] for k, vals in values.items()
    }
    setup = {"values": values, "scenarios": scenarios}
    return Experiment("sensitivity", sensitivity_run, setup, n_trials)


def robot_error_run(setup: dict, rng: np.random.Generator) -> list[dict]:
    """One station at every factor on the robot's kinematic tolerances: the station's draws
    are the same at every factor (the same child streams), so its robot errors keep their
    direction and only their size changes. One row per factor with the figures of
    :func:`trial_summary`."""
    scenario = setup["scenario"]
    rows = []
    for scale in setup["scales"]:
        # a fresh child of the same name: the same station draws at every factor
        ps = calibrated_station(child_rng(rng, "station"), robot_error_scale=float(scale))
        run = simulate_run(ps, scenario, child_rng(rng, "production"))
        n = scenario.production.protocol.n_compensation
        system, (table,) = trial_summary(run, scenario, [n])
        rows.append({"robot_error_scale": float(scale)} | system | table)
    return rows


def robot_error_experiment(
    n_trials: int = 30, scales=(0.0, 0.5, 1.0, 2.0, 3.0), scenario_toml: str = ""
) -> Experiment:
    """The before-compensation and Table 1 figures as the robot's tolerances scale."""
    scales = [float(s) for s in scales]
    if not scales:
        raise CalibrationError("scales is empty; give at least one factor on the tolerances")
    setup = {"scenario": load_scenario(scenario_toml or None), "scales": scales}
    return Experiment("robot_error", robot_error_run, setup, n_trials)


def robustness_experiment(
    scenario_toml: str = "", n_trials: int = 10, overrides: dict | None = None
) -> Experiment:
    """One point of notebook 02's robustness map: :func:`production_run` at the scenario's own
    ``n_compensation`` on the scenario with ``overrides`` (dotted keys beginning with
    ``station.`` or ``production.``, set before it is validated and checked against their
    ledger ranges). The name is the same at every point, so every point runs the same trials
    (paired seeds); the cache key holds the overrides (through the scenario)."""
    scenario = load_scenario(scenario_toml or None, overrides)
    n = scenario.production.protocol.n_compensation
    setup = {"scenario": scenario, "n_values": [n], "version": 3}
    return Experiment("production_robustness", production_run, setup, n_trials)


def part_variation_run(setup: dict, rng: np.random.Generator) -> list[dict]:
    """One calibrated station measuring the follow-up products at every part variation of
    ``setup["values"]`` (the same panels' standard-normal draws scaled, the same readings'
    noise): one row per value with the Kolmogorov distance of the correlation bins to the
    published ones and the share above 0.7."""
    ps = calibrated_station(child_rng(rng, "station"), config=setup["scenario"].station)
    n_follow = setup["scenario"].production.protocol.n_follow_up
    rows = []
    for value, sc in zip(setup["values"], setup["scenarios"], strict=True):
        hybrid, cmm = simulate_products(ps, sc, n_follow, child_rng(rng, "follow-up products"))
        free = ~frame_fixed(hybrid, cmm)
        counts = correlation_bins(correlations(hybrid[:, free], cmm[:, free]))
        rows.append(
            {
                "part_sigma_mm": float(value),
                "r_distance": correlation_distance(counts),
                "r_above_0p7": 100.0 * counts[:3].sum() / counts.sum(),
                "n_defined": int(free.sum()),
            }
        )
    return rows


def part_variation_experiment(
    n_trials: int = 30, values=(0.03, 0.05, 0.07, 0.1, 0.15, 0.25, 0.5), scenario_toml: str = ""
) -> Experiment:
    """The correlation bins against the part variation, every value inside each station: what
    part variation the published correlation bins need (a finding; the scenario keeps its
    own)."""
    scenario = load_scenario(scenario_toml or None)
    values = sorted({float(v) for v in values})
    if not values or values[0] <= 0:
        raise CalibrationError(f"part variations {values} must be a non-empty list of values > 0")
    key = "production.variation.part_sigma_mm"
    scenarios = [with_inputs(scenario, {key: v}) for v in values]
    setup = {"scenario": scenario, "values": values, "scenarios": scenarios}
    return Experiment("part_variation", part_variation_run, setup, n_trials)
