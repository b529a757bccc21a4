"""Trials and Monte Carlo experiments of the ``selfcal`` notebook (run by the shared engine).

Each experiment is built by a module-level factory (``*_experiment``) from JSON-able keyword
arguments (the scenario path, ``""`` for the paper's, and the trial count), so that the tests can
rebuild it from ``experiments.json`` and recompute stored trials:

- :func:`calibration_experiment`: the experiment that decides the claims; :func:`calibration_trial`
  draws a cell, measures it, identifies it by the one-step model (paper's LM, maximum likelihood,
  very poor start) and by every multi-step route, and validates each on 10 new placements,
  beside the two controls (nothing identified; the true parameters).
- :func:`compliance_sweep_experiment`: the same trial at several sizes of the unmodelled joint
  compliance; :func:`arm_weight_sweep_experiment`: with the arm's own weight on the joints.
- :func:`noise_sweep_experiment`: the same trial with all noise scaled.
- :func:`robustness_experiment`: the same trial on the scenario with some inputs overridden (a
  point of the robustness map, :mod:`calstudy.papers.selfcal.robustness`).
- :func:`basin_experiment`: :func:`basin_trial`, convergence from starts farther and farther away.
- :func:`pose_selection_experiment`: :func:`pose_selection_trial`, D-optimal against random
  measuring poses of the same number.
- :func:`interval_coverage`: how often the intervals and the joint region of the own-cell
  identification hold the truth, with the noise declared and without.

:func:`simulated_cell` and :func:`write_example_measurements` give the simulated cell as measured
data (the notebook's default and ``data/selfcal/example_measurements``).

The engine hands every trial its own generator (seed, experiment, sweep point, trial index).
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError, CalibrationWarning
from calstudy.core.montecarlo import Experiment, child_rng, trial_rng
from calstudy.core.paths import scenario_file
from calstudy.core.schema import read_toml, with_inputs
from calstudy.papers.selfcal.routes import (
    hand_eye,
    refit,
    three_step,
    three_step_alternated,
    three_step_reordered,
    two_step,
)
from calstudy.papers.selfcal.scenario import Scenario, load_scenario
from calstudy.papers.selfcal.simulate import (
    Station,
    draw_placements,
    draw_station,
    poor_start,
    simulate,
    tracker_sigma,
    view_geometry,
)
from calstudy.selfcal.design import (
    candidate_jacobians,
    observability,
    select_poses_sizes,
)
from calstudy.selfcal.identify import (
    RANK_RTOL,
    Identification,
    Measurements,
    crb_covariance,
    identifiability,
    identify,
    scaled_jacobian,
)
from calstudy.selfcal.measured import MeasuredCell, identify_measurements, write_cell
from calstudy.selfcal.model import (
    BASE,
    IS_LENGTH,
    N_PARAMS,
    PARAM_NAMES,
    ROBOT,
    SENSOR,
    angle_wrap,
    default_model,
    scaled_error,
)
from calstudy.selfcal.planning import candidate_views

ONE_STEP = "one-step (paper)"
ONE_STEP_ML = "one-step ML"
NULL = "nothing identified"
ORACLE = "ideal identification"
TRUTH = "true parameters"
#: the sequential multi-step routes (no final joint refit): as the paper describes it, reordered,
#: alternated, two-step; selfcal.one_step is judged against the best of them
ROUTES = (
    "three-step",
    "three-step reordered",
    "three-step alternated",
    "two-step (sensor+robot, then exterior)",
)
#: the two-step route followed by a refit on all 72 equations: of the base alone, of all 30
REFITS = (
    "two-step, base refitted on all equations",
    "two-step, then full joint refit",
)
#: null of selfcal.residual: base and sensor identified (72 equations), the robot left nominal
NULL_ROBOT_NOMINAL = "base and sensor identified, robot nominal"
#: null of selfcal.robot_params: the robot reported as nominal plus noise of the tolerance class
#: (what a method that finds nothing but returns changes of the right size would report), with
#: the base and sensor of :data:`NULL_ROBOT_NOMINAL`
NULL_ROBOT_NOISE = "robot nominal plus tolerance-sized noise"
METHODS = (
    ONE_STEP,
    ONE_STEP_ML,
    *ROUTES,
    *REFITS,
    NULL,
    NULL_ROBOT_NOMINAL,
    NULL_ROBOT_NOISE,
    ORACLE,
    TRUTH,
)
#: the paper's reading of Fig. 6: an identified change within this many tolerance standard
#: deviations of the robot's tolerance class counts as "of the size of manufacturing errors"
TOLERANCE_CLASS_SIGMAS = 3.0
#: rounds of the alternated route (hand-eye then robot); its limit is the two-step joint fit
ALTERNATION_ROUNDS = 5
#: iterations of Fig. 5 stored per trial (the last value repeats after the solver stopped)
HISTORY_LENGTH = 12
#: evaluation budget of one identification; a failed run counts as this many iterations
MAX_EVALUATIONS = 100
#: a start reached "the same solution" when its scaled parameter distance to the good start's
#: solution is below this (mm, angles as mm at 1 m)
SAME_SOLUTION_MM = 1e-3


#: bump when a trial function changes what it returns: it keys the engine's trial cache
TRIAL_VERSION = "selfcal-trials-3"


def _scenario(scenario_toml: str) -> Scenario:
    return load_scenario(scenario_toml or None)


def scenario_key(scenario_toml: str = "") -> str:
    """Cache key of a scenario: the scenario file, the robot table it names, the trial version.

    The scenario holds a Pinocchio robot, which has no stable text form for the engine's default
    fingerprint.
    """
    path = scenario_file("selfcal", "scenario.toml", scenario_toml or None)
    sc = load_scenario(path)
    robot = sc.nominal_robot
    record = {
        "version": TRIAL_VERSION,
        "scenario": Path(path).read_text(),
        "robot": [
            robot.name,
            robot.parameters().tolist(),
            robot.base.tolist(),
            robot.tool.tolist(),
        ],
    }
    return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()


def _experiment(name, trial, scenario_toml, n_trials, points=({},)) -> Experiment:
    return Experiment(
        name, trial, _scenario(scenario_toml), n_trials, points, scenario_key(scenario_toml)
    )


# ----------------------------------------------------------------------------------------------
# one calibration trial


def _cell(scenario: Scenario, rng: np.random.Generator, compliance_scale: float):
    """Draw a true cell, its 24 calibration measurements and 10 validation measurements (each
    from its own child stream of ``rng``)."""
    st = draw_station(scenario, child_rng(rng, "station"))
    views = scenario.protocol.views_per_sphere
    cal = child_rng(rng, "calibration measurements")
    meas = simulate(scenario, st, st.spheres_base, views, cal, compliance_scale)
    n_val = scenario.protocol.validation_placements
    val_sites = draw_placements(scenario, n_val, child_rng(rng, "validation sites"))
    val_rng = child_rng(rng, "validation measurements")
    val = simulate(scenario, st, val_sites, 1, val_rng, compliance_scale)
    return st, meas, val


def _history(fit: Identification | None, prefix: str) -> dict:
    if fit is None:
        return {f"{prefix}_err_{i}": math.nan for i in range(HISTORY_LENGTH)}
    e = fit.mean_error_mm
    return {f"{prefix}_err_{i}": float(e[min(i, len(e) - 1)]) for i in range(HISTORY_LENGTH)}


def _conv(value: float, i: int) -> float:
    return float(value if IS_LENGTH[i] else math.degrees(value))


def _one_step_extras(scenario, st, meas, val, good, poor, ml) -> dict:
    """Trial-level columns of the one-step row: convergence, rank, CRB, robot parameters."""
    model = default_model()
    truth = st.true_params
    _, jac = model.points_and_jacobian(truth, meas.Q, meas.C_true)
    sv = np.linalg.svd(scaled_jacobian(jac), compute_uv=False)
    crb = crb_covariance(meas, truth, model)
    _, jv = model.points_and_jacobian(truth, val.Q, val.C_true)
    crb_rms = math.sqrt(float(np.trace(jv @ crb @ jv.T)) / len(val))
    same = poor is not None and scaled_error(poor.params, good.params) < SAME_SOLUTION_MM
    row = {
        "crb_model_rms_mm": crb_rms,
        "jacobian_rank": int(np.sum(sv > sv[0] * RANK_RTOL)),
        "jacobian_condition": float(sv[0] / sv[-1]),
        "good_iterations": good.iterations_to(),
        "good_solver_iterations": good.iterations,
        "poor_converged": poor is not None,
        "poor_same_solution": bool(same),
        "poor_iterations": poor.iterations_to() if poor is not None else MAX_EVALUATIONS,
        "poor_solver_iterations": poor.iterations if poor is not None else MAX_EVALUATIONS,
        **_history(good, "good"),
        **_history(poor, "poor"),
    }
    std = good.estimate.std
    for i in range(ROBOT.start, ROBOT.stop):
        name = PARAM_NAMES[i]
        row[f"true_{name}"] = _conv(truth[i] - st.nominal_params[i], i)
        row[f"id_{name}"] = _conv(angle_wrap(good.params - st.nominal_params)[i], i)
        row[f"ml_{name}"] = _conv(angle_wrap(ml.params - st.nominal_params)[i], i)
        row[f"std_{name}"] = _conv(std[i], i)
    return row


def _validate(params: np.ndarray, val: Measurements, truth: np.ndarray) -> dict:
    """Validation errors (Eq. 13-14) of one parameter vector on the validation placements.

    ``val_*``: identified model at the commanded joints and fitted centres against the tracker
    (what the paper reports). ``model_rms_mm``: identified model at the commanded joints and the
    noise-free centres against where the sensor really saw them (true model at the joint angles
    as the robot stood): the error of the identified geometry, unmodelled deflection included.
    """
    model = default_model()
    err = np.linalg.norm(model.points(params, val.Q, val.C) - val.P_ref, axis=1)
    q_true = val.Q if val.Q_true is None else val.Q_true
    reference = model.points(truth, q_true, val.C_true)
    model_err = np.linalg.norm(model.points(params, val.Q, val.C_true) - reference, axis=1)
    return {
        "val_mean_mm": float(err.mean()),
        "val_max_mm": float(err.max()),
        "val_rms_mm": float(np.sqrt(np.mean(err**2))),
        "model_rms_mm": float(np.sqrt(np.mean(model_err**2))),
        "robot_param_error": scaled_error(params, truth, ROBOT),
    }


def robot_tolerance(scenario: Scenario) -> np.ndarray:
    """Standard deviations (18,) of the robot's tolerance class, in the order of the 18 robot
    parameters (mm for lengths, rad for angles): the ``[tolerances]`` of the robot's table,
    from which the true robots are drawn."""
    tol = scenario.nominal_robot.tolerances or {}
    if "sigma_length_mm" not in tol or "sigma_angle_deg" not in tol:
        raise CalibrationError(
            f"the {scenario.nominal_robot.name} has no tolerances table (sigma_length_mm, "
            "sigma_angle_deg): the robot-parameter claim is judged in its units"
        )
    angle = math.radians(float(tol["sigma_angle_deg"]))
    return np.where(IS_LENGTH[ROBOT], float(tol["sigma_length_mm"]), angle)


def _robot_columns(params, truth, nominal, sigma) -> dict:
    """The robot parameters in units of the tolerance class (``sigma``, (18,)): the RMS of
    identified minus true (``robot_tol_error``; for the nominal robot, the manufacturing error)
    and the largest identified change from nominal (``robot_change_max_sigmas``, the paper's
    reading of Fig. 6)."""
    error = angle_wrap(np.asarray(params, float) - truth)[ROBOT] / sigma
    change = angle_wrap(np.asarray(params, float) - nominal)[ROBOT] / sigma
    return {
        "robot_tol_error": float(np.sqrt(np.mean(error**2))),
        "robot_change_max_sigmas": float(np.max(np.abs(change))),
    }


def _ideal_identification(meas: Measurements, st: Station) -> np.ndarray:
    """The one-step fit to noise-free data at the same poses (commanded joints, exact centres
    and tracker readings, the robot where it really stood): the oracle of the controls."""
    model = default_model()
    q_true = meas.Q if meas.Q_true is None else meas.Q_true
    exact = replace(meas, C=meas.C_true, P_ref=model.points(st.true_params, q_true, meas.C_true))
    return identify(exact, st.nominal_params, max_evaluations=MAX_EVALUATIONS).params


def calibration_trial(
    scenario: Scenario,
    rng: np.random.Generator,
    compliance_scale: float | None = None,
    noise_scale: float = 1.0,
    arm_weight_fraction: float | None = None,
) -> list[dict]:
    """One simulated calibration, identified every way and validated; one row per method.

    Methods (:data:`METHODS`): the paper's one-step LM from the good start, one-step maximum
    likelihood, the four sequential multi-step routes (:data:`ROUTES`) on the same 24
    measurements, the two-step route refitted on all equations (:data:`REFITS`: the base alone,
    then all 30), the null control (the good initial estimate, nothing identified), the
    informative nulls (:data:`NULL_ROBOT_NOMINAL`: base and sensor identified with the robot left
    nominal; :data:`NULL_ROBOT_NOISE`: the same with the robot reported as nominal plus noise of
    its tolerance class, :func:`robot_tolerance`), the oracle control (the ideal
    identification: the same model fitted to the same poses without any measurement noise,
    i.e. the geometric error that identification corrects removed as far as the 30-parameter
    model can; with compliance 0 it is the truth) and the true parameters themselves. The
    one-step row also carries the trial's convergence
    (good and very poor start), Jacobian rank, the Cramer-Rao prediction of the model error and
    the 18 robot parameters; the alternated row the rounds it ran. Every row carries its
    validation errors, its robot parameters in units of the tolerance class
    (``robot_tol_error``, ``robot_change_max_sigmas``) and its scaled distance from the
    one-step and the two-step results (``step_from_one_step``, ``step_from_two_step``; mm,
    angles as mm at 1 m).
    """
    if noise_scale != 1.0:
        changes = {
            "repeatability.sigma_mm": scenario.repeatability.sigma_mm * noise_scale,
            "scanner.sigma_point_mm": scenario.scanner.sigma_point_mm * noise_scale,
            "tracker.u0_mm": scenario.tracker.u0_mm * noise_scale,
            "tracker.u1_mm_per_m": scenario.tracker.u1_mm_per_m * noise_scale,
        }
        scenario = with_inputs(scenario, changes)
    if arm_weight_fraction is not None:
        scenario = with_inputs(scenario, {"compliance.arm_weight_fraction": arm_weight_fraction})
    scale = scenario.compliance.scale if compliance_scale is None else compliance_scale
    st, meas, val = _cell(scenario, rng, scale)
    good = identify(meas, st.nominal_params, max_evaluations=MAX_EVALUATIONS)
    start = poor_start(scenario, st, child_rng(rng, "poor start"))
    try:
        poor = identify(meas, start, max_evaluations=MAX_EVALUATIONS)
    except CalibrationError:
        poor = None
    ml = identify(meas, st.nominal_params, weighted=True, max_evaluations=MAX_EVALUATIONS)
    # the three three-step routes begin with the same hand-eye fit: computed once
    robot = scenario.nominal_robot
    first = hand_eye(meas, robot, st.nominal_params)
    alternated, rounds = three_step_alternated(
        meas, robot, st.nominal_params, max_rounds=ALTERNATION_ROUNDS, first=first
    )
    sequential = two_step(meas, robot, st.nominal_params)
    sigma = robot_tolerance(scenario)
    robot_nominal = refit(meas, st.nominal_params, BASE, SENSOR)
    robot_noise = robot_nominal.copy()
    robot_noise[ROBOT] += child_rng(rng, "null robot noise").normal(0.0, sigma)
    params = {
        ONE_STEP: good.params,
        ONE_STEP_ML: ml.params,
        ROUTES[0]: three_step(meas, robot, st.nominal_params, first=first),
        ROUTES[1]: three_step_reordered(meas, robot, st.nominal_params, first=first),
        ROUTES[2]: alternated,
        ROUTES[3]: sequential,
        REFITS[0]: refit(meas, sequential, BASE),
        REFITS[1]: refit(meas, sequential),
        NULL: st.nominal_params,
        NULL_ROBOT_NOMINAL: robot_nominal,
        NULL_ROBOT_NOISE: robot_noise,
        ORACLE: _ideal_identification(meas, st),
        TRUTH: st.true_params,
    }
    rows = [
        {
            "method": name,
            **_validate(p, val, st.true_params),
            **_robot_columns(p, st.true_params, st.nominal_params, sigma),
            "step_from_one_step": scaled_error(p, good.params),
            "step_from_two_step": scaled_error(p, sequential),
        }
        for name, p in params.items()
    ]
    rows[0].update(_one_step_extras(scenario, st, meas, val, good, poor, ml))
    rows[METHODS.index(ROUTES[2])]["rounds"] = rounds
    return rows


def calibration_experiment(scenario_toml: str = "", n_trials: int = 200) -> Experiment:
    """The experiment that decides the five claims, at the scenario's compliance."""
    return _experiment("calibration", calibration_trial, scenario_toml, n_trials)


def robustness_experiment(
    scenario_toml: str = "", n_trials: int = 10, overrides: dict | None = None
) -> Experiment:
    """One point of a robustness map: :func:`calibration_trial` on the scenario with
    ``overrides`` (dotted keys of ``scenario.toml``, set before it is validated and checked
    against their ledger ranges). The name is the same at every point, so every point runs the
    same trials (paired seeds); the cache key holds the overrides."""
    key = scenario_key(scenario_toml)
    if overrides:
        record = json.dumps({"scenario": key, "overrides": overrides}, sort_keys=True)
        key = hashlib.sha256(record.encode()).hexdigest()
    scenario = load_scenario(scenario_toml or None, overrides)
    return Experiment("robustness", calibration_trial, scenario, n_trials, ({},), key)


def compliance_sweep_experiment(scenario_toml: str = "", n_trials: int = 30) -> Experiment:
    """:func:`calibration_trial` at each compliance scale of the scenario's ``sweep_scales``
    other than the scenario's own (that point is :func:`calibration_experiment`)."""
    sc = _scenario(scenario_toml)
    scales = [s for s in sc.compliance.sweep_scales if s != sc.compliance.scale]
    points = [{"compliance_scale": float(s)} for s in scales]
    return _experiment("compliance_sweep", calibration_trial, scenario_toml, n_trials, points)


def arm_weight_sweep_experiment(scenario_toml: str = "", n_trials: int = 30) -> Experiment:
    """:func:`calibration_trial` with the share of the arm's own weight on the joints at each
    value of the scenario's ``arm_weight_sweep`` other than its own (that point is
    :func:`calibration_experiment`), the payload's compliance at the scenario's scale."""
    sc = _scenario(scenario_toml)
    own = sc.compliance.arm_weight_fraction
    points = [{"arm_weight_fraction": float(f)} for f in sc.compliance.arm_weight_sweep if f != own]
    return _experiment("arm_weight_sweep", calibration_trial, scenario_toml, n_trials, points)


def noise_sweep_experiment(
    scenario_toml: str = "", n_trials: int = 30, scales: list[float] | None = None
) -> Experiment:
    """:func:`calibration_trial` with repeatability, scanner and tracker noise scaled together
    (``scales`` without 1, which is :func:`calibration_experiment`)."""
    scales = [0.5, 2.0, 4.0] if scales is None else scales
    points = [{"noise_scale": float(s)} for s in scales if s != 1.0]
    return _experiment("noise_sweep", calibration_trial, scenario_toml, n_trials, points)


# ----------------------------------------------------------------------------------------------
# basin of convergence


def basin_trial(scenario: Scenario, rng: np.random.Generator, start_scale: float) -> dict:
    """Identification from the good start and from a very poor start ``start_scale`` times as far.

    Returns whether the far start converged, to the same solution as the good start, and its
    iterations (a failure counts as :data:`MAX_EVALUATIONS`).
    """
    st = draw_station(scenario, child_rng(rng, "station"))
    cal = child_rng(rng, "calibration measurements")
    meas = simulate(scenario, st, st.spheres_base, scenario.protocol.views_per_sphere, cal)
    good = identify(meas, st.nominal_params, max_evaluations=MAX_EVALUATIONS)
    try:
        start = poor_start(scenario, st, child_rng(rng, "poor start"), start_scale)
        far = identify(meas, start, max_evaluations=MAX_EVALUATIONS)
    except CalibrationError:
        far = None
    same = far is not None and scaled_error(far.params, good.params) < SAME_SOLUTION_MM
    return {
        "converged": far is not None,
        "same_solution": bool(same),
        "iterations": far.iterations_to() if far is not None else MAX_EVALUATIONS,
        "solver_iterations": far.iterations if far is not None else MAX_EVALUATIONS,
    }


def basin_experiment(scenario_toml: str = "", n_trials: int = 30) -> Experiment:
    """:func:`basin_trial` at the start scales of the scenario (``poor_start.basin_scales``)."""
    sc = _scenario(scenario_toml)
    points = [{"start_scale": float(s)} for s in sc.poor_start.basin_scales]
    return _experiment("basin", basin_trial, scenario_toml, n_trials, points)


# ----------------------------------------------------------------------------------------------
# the example cell and its identifiability


def example_station(scenario: Scenario, seed: int) -> tuple[Station, Measurements]:
    """The station and measurements of trial 0 of :func:`calibration_experiment`."""
    rng = trial_rng(seed, "calibration", {}, 0)
    st = draw_station(scenario, child_rng(rng, "station"))
    cal = child_rng(rng, "calibration measurements")
    meas = simulate(scenario, st, st.spheres_base, scenario.protocol.views_per_sphere, cal)
    return st, meas


def _null_space_parameters(meas: Measurements, params, rank: int) -> list[str]:
    """Parameters with weight above 0.2 in the null space of the scaled Jacobian."""
    _, jac = default_model().points_and_jacobian(params, meas.Q, meas.C_true)
    _, _, vt = np.linalg.svd(scaled_jacobian(jac))
    null = vt[rank:]
    weight = np.sqrt((null**2).sum(axis=0))
    return [PARAM_NAMES[i] for i in np.flatnonzero(weight > 0.2)]


def identifiability_designs(scenario: Scenario, meas: Measurements, params) -> dict:
    """:func:`calstudy.selfcal.identify.identifiability` for the scanner's measurements
    and for a one-point sensor.

    The second design replaces every measured centre by the same sensor-frame point (on the
    optical axis at the working distance): what a sensor that returns a single point (a tracker
    reflector on the flange, a touch probe) would give from the same robot positions.

    Returns
    -------
    dict of DataFrames: ``singular`` and ``parameters`` (with a ``design`` column) and
    ``summary`` (design, rank, condition numbers, the parameters of the null space).
    """
    one_point = np.tile([0.0, 0.0, scenario.scanner.standoff_mm], (len(meas), 1))
    designs = {
        "scanner (sphere anywhere in the field)": meas,
        "one sensor point": replace(meas, C_true=one_point),
    }
    singular, parameters, summary = [], [], []
    for design, m in designs.items():
        sv, pt, summ = identifiability(m, params)
        sv.insert(0, "design", design)
        pt.insert(0, "design", design)
        singular.append(sv)
        parameters.append(pt)
        names = _null_space_parameters(m, params, summ["rank"])
        summary.append(
            {
                "design": design,
                **summ,
                "null_dimension": N_PARAMS - summ["rank"],
                "null_space_parameters": " ".join(names),
            }
        )
    return {
        "singular": pd.concat(singular, ignore_index=True),
        "parameters": pd.concat(parameters, ignore_index=True),
        "summary": pd.DataFrame(summary),
    }


# ----------------------------------------------------------------------------------------------
# pose selection: optimised against random poses of the same number

OPTIMISED = "optimised (D-optimal)"
RANDOM = "random"


def _measure_selection(scenario, st, Q, sphere, chosen, rng) -> Measurements:
    k = len(st.spheres_base)
    views = [Q[chosen][sphere[chosen] == s] for s in range(k)]
    return simulate(scenario, st, st.spheres_base, 0, rng, views=views)


def _selection_row(scenario, st, meas, val, blocks) -> dict:
    row = dict(observability(blocks))
    try:
        params = identify(meas, st.nominal_params, max_evaluations=MAX_EVALUATIONS).params
    except CalibrationError:
        return row | {"converged": False}
    return row | {
        "converged": True,
        "param_error": scaled_error(params, st.true_params),
        **_validate(params, val, st.true_params),
    }


def pose_selection_trial(
    scenario: Scenario, rng: np.random.Generator, sizes: str, per_sphere: int
) -> list[dict]:
    """One drawn cell calibrated from ``N`` optimised and ``N`` random poses, for each ``N``.

    Candidates: ``per_sphere`` planned views of each of the cell's spheres. Optimised: the ``N``
    that maximise D-optimality of the scaled Jacobian at the nominal parameters and the sphere
    positions (:func:`calstudy.selfcal.design.select_poses`); random: ``N`` drawn
    uniformly from the same candidates. Both are measured (new noise), identified from the good
    start and validated on the same 10 new placements. One row per (N, selection).
    ``sizes`` is the list of ``N`` as one string of integers ("12 18 24 36": the engine's sweep
    points hold scalars).
    """
    st = draw_station(scenario, child_rng(rng, "station"))
    Q, sphere = candidate_views(
        scenario.nominal_robot,
        scenario.sensor.design,
        view_geometry(scenario),
        st.spheres_base,
        per_sphere,
        child_rng(rng, "candidates"),
    )
    blocks, _ = candidate_jacobians(st.nominal_params, Q, st.spheres_part, sphere)
    n_val = scenario.protocol.validation_placements
    sites = draw_placements(scenario, n_val, child_rng(rng, "validation sites"))
    val = simulate(scenario, st, sites, 1, child_rng(rng, "validation measurements"))
    rows = []
    sizes_n = [int(v) for v in sizes.split()]
    optimised = select_poses_sizes(blocks, sizes_n)
    for n in sizes_n:
        draws = child_rng(rng, f"random selection {n}")
        picks = {
            OPTIMISED: optimised[n],
            RANDOM: np.sort(draws.choice(len(Q), int(n), replace=False)),
        }
        for name, chosen in picks.items():
            noise = child_rng(rng, f"measurements {name} {n}")
            meas = _measure_selection(scenario, st, Q, sphere, chosen, noise)
            row = _selection_row(scenario, st, meas, val, blocks[chosen])
            rows.append({"n_poses": int(n), "selection": name, **row})
    return rows


def pose_selection_experiment(
    scenario_toml: str = "",
    n_trials: int = 200,
    sizes: list[int] | None = None,
    per_sphere: int = 15,
) -> Experiment:
    """:func:`pose_selection_trial` over ``n_trials`` cells.

    ``sizes``: the numbers of poses compared (default 12, 24, 36); ``per_sphere``: candidate
    views per sphere (default 15, 60 candidates).
    """
    sizes = [12, 24, 36] if sizes is None else [int(n) for n in sizes]
    point = {"sizes": " ".join(str(n) for n in sizes), "per_sphere": int(per_sphere)}
    return _experiment("pose_selection", pose_selection_trial, scenario_toml, n_trials, [point])


# ----------------------------------------------------------------------------------------------
# the simulated cell as measured data, and the example measurement folder


def _example_data(scenario: Scenario, seed: int):
    """Trial 0 of :func:`calibration_experiment`: station, calibration and validation sets."""
    return _cell(scenario, trial_rng(seed, "calibration", {}, 0), scenario.compliance.scale)


def _as_measured(meas: Measurements, sphere_offset: int = 0) -> Measurements:
    """What a user has of simulated measurements: no truth, no noise model."""
    return Measurements(meas.Q, meas.C, meas.P_ref, meas.sphere + sphere_offset)


def simulated_cell(scenario: Scenario, seed: int) -> MeasuredCell:
    """The notebook's simulated cell (trial 0 of the calibration experiment) as measured data:
    24 calibration and 10 validation measurements, noise not declared."""
    st, meas, val = _example_data(scenario, seed)
    k = len(st.spheres_base)
    spheres = np.vstack(
        [meas.P_ref[[np.flatnonzero(meas.sphere == s)[0] for s in range(k)]], val.P_ref]
    )
    return MeasuredCell(
        scenario.nominal_robot,
        st.nominal_params,
        _as_measured(meas),
        _as_measured(val, k),
        spheres,
        np.arange(1, len(spheres) + 1),
        {
            "calibration": np.arange(1, len(meas) + 1),
            "validation": np.arange(len(meas) + 1, len(meas) + len(val) + 1),
        },
        None,
        f"the simulated cell (seed {seed})",
        scenario.base.rough,
        scenario.sensor.design,
    )


#: outliers planted in the example folder: (calibration row, displacement of C in mm)
EXAMPLE_OUTLIERS = ((5, (1.5, -0.8, 0.6)), (17, (0.0, 2.0, -1.2)))


def write_example_measurements(folder, scenario: Scenario | None = None, seed: int = 1) -> Path:
    """Write the example measurement folder (``data/selfcal/example_measurements``).

    The simulated cell of :func:`simulated_cell` as a user would write it: joint angles in
    degrees to 0.001 deg, lengths to 0.001 mm, noise not declared, and two planted outliers
    (:data:`EXAMPLE_OUTLIERS`: the fitted centre of two calibration views displaced, as by a
    scan of the wrong sphere or a partly hidden cap).
    """
    scenario = load_scenario() if scenario is None else scenario
    cell = simulated_cell(scenario, seed)
    calib = cell.calibration
    C = calib.C.copy()
    for row, shift in EXAMPLE_OUTLIERS:
        C[row] += shift
    robot_file = Path(scenario_file("robots", f"{_robot_stem(scenario)}.toml"))
    return write_cell(
        folder,
        robot_file,
        cell.part2base,
        cell.sensor2flange,
        cell.spheres,
        replace(calib, C=C),
        cell.validation,
        joint_decimals=3,
        length_decimals=3,
    )


def _robot_stem(scenario: Scenario) -> str:
    """Stem of the robot file the paper's scenario names (``robot`` of its TOML)."""
    return str(read_toml(scenario_file("selfcal", "scenario.toml"), "selfcal scenario")["robot"])


def probe_rows(scenario: Scenario, st: Station, meas: Measurements, rng) -> Measurements:
    """The views of ``meas`` read as a tracker reflector at the sensor origin: each pose's own
    tracker reading of the reflector (repeatability and tracker noise, nothing shared), the
    sensor-frame point zero."""
    C = np.zeros_like(meas.C)
    truth = default_model().points(st.true_params, meas.Q, C)
    sigma_t = tracker_sigma(scenario, truth)
    P_ref = (
        truth
        + rng.normal(0.0, scenario.repeatability.sigma_mm, truth.shape)
        + rng.normal(size=truth.shape) * sigma_t[:, None]
    )
    own = (scenario.repeatability.sigma_mm**2 + sigma_t**2)[:, None, None] * np.eye(3)
    shared = (sigma_t**2)[:, None, None] * np.eye(3)
    return Measurements(meas.Q, C, P_ref, np.arange(len(meas)), C, own, shared)


def interval_coverage(
    scenario: Scenario, n_cells: int, seed: int = 2026, probe: bool = False, level: float = 0.95
) -> dict:
    """How often the intervals and the joint region of
    :func:`calstudy.selfcal.measured.identify_measurements` hold the truth.

    Each cell is drawn as in the calibration experiment with the joint compliance off (the
    truth in the model class): a new station, its spheres measured from the scenario's views
    (scanner caps, repeatability, one tracker reading per sphere shared by its views); with
    ``probe`` the same poses read as a tracker reflector on the flange instead (one tracker
    reading per pose, 27 parameters identifiable). Each cell is identified with its noise
    declared (the simulated covariance as the weights) and without (covariance from the
    residuals), from the nominal parameters, outlier rule on.

    Parameters
    ----------
    scenario : Scenario
        The paper's scenario or another; its compliance is switched off here.
    n_cells : int
        Cells drawn (cell ``i`` from the generator seeded ``[seed, i]``).
    seed : int
        First entry of every cell's seed.
    probe : bool
        A one-point probe instead of the spheres.
    level : float
        Level of the intervals and the region.

    Returns
    -------
    dict
        ``"declared noise"`` and ``"no noise declared"``, each ``(inside, in_region)``:
        ``inside`` (n_cells, 30) 1.0 where the truth lies within the parameter's interval, 0.0
        outside, NaN for a parameter not identified; ``in_region`` (n_cells,) bool.
    """
    scenario = with_inputs(scenario, {"compliance.scale": 0.0})
    out = {"declared noise": ([], []), "no noise declared": ([], [])}
    for i in range(int(n_cells)):
        rng = np.random.default_rng([seed, i])
        st = draw_station(scenario, rng)
        meas = simulate(scenario, st, st.spheres_base, scenario.protocol.views_per_sphere, rng)
        if probe:
            meas = probe_rows(scenario, st, meas, child_rng(rng, "probe"))
        bare = replace(meas, cov=None, tracker_cov=None, C_true=None, Q_true=None)
        noise = {
            "sensor_mm": 0.0,
            "repeatability_mm": scenario.repeatability.sigma_mm,
            "tracker_mm": 0.0,
        }
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CalibrationWarning)
            fits = {
                "declared noise": identify_measurements(meas, st.nominal_params, noise),
                "no noise declared": identify_measurements(bare, st.nominal_params),
            }
        for key, fit in fits.items():
            d = np.abs(angle_wrap(fit.params - st.true_params))
            inside = np.where(fit.free, (d <= fit.half_widths(level)).astype(float), np.nan)
            out[key][0].append(inside)
            out[key][1].append(fit.in_region(st.true_params, level))
    return {k: (np.array(inside), np.array(region)) for k, (inside, region) in out.items()}
