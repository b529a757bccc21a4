"""Trials, Monte Carlo loops and sweeps of the ``selfcal`` notebook.

:func:`run_trial` is one simulated calibration (draw a cell, measure it, identify it every way,
validate); :func:`monte_carlo` repeats it, :func:`noise_sweep` repeats that at scaled noise, and
:func:`identifiability_designs` compares the scanner with a one-point sensor on the same poses.
Trial ``t`` of seed ``s`` draws from ``numpy.random.default_rng([s, t])``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.stats import median_and_spread
from calstudy.papers.selfcal.identify import (
    RANK_RTOL,
    Identification,
    Measurements,
    identifiability,
    identify,
    scaled_jacobian,
    three_step,
)
from calstudy.papers.selfcal.model import (
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
from calstudy.papers.selfcal.scenario import Scenario
from calstudy.papers.selfcal.simulate import (
    Station,
    draw_placements,
    draw_station,
    poor_start,
    simulate,
)

METHODS = ("one-step (paper)", "one-step ML", "three-step", "nominal robot")


# ----------------------------------------------------------------------------------------------
# one trial


def _identify_all(scenario: Scenario, st: Station, meas: Measurements, rng: np.random.Generator):
    """The fits from the good and very poor starts and by ML, and the parameters per method."""
    fits: dict[str, Identification | None] = {}
    fits["good"] = identify(meas, st.nominal_params)
    try:
        fits["poor"] = identify(meas, poor_start(scenario, st, rng))
    except CalibrationError:
        fits["poor"] = None
    fits["ml"] = identify(meas, st.nominal_params, weighted=True)
    ext = np.zeros(N_PARAMS, bool)
    ext[BASE] = ext[SENSOR] = True
    params = {
        METHODS[0]: fits["good"].params,
        METHODS[1]: fits["ml"].params,
        METHODS[2]: three_step(meas, scenario.robot, st.nominal_params),
        METHODS[3]: identify(meas, st.nominal_params, free=ext).params,
    }
    return fits, params


def _validation_rows(trial: int, params: dict, val: Measurements, truth: np.ndarray):
    """Per method the validation errors (``methods`` rows) and, in trial 0, per placement."""
    model = default_model()
    reference = model.points(truth, val.Q, val.C_true)
    methods, validation = [], []
    for name, p in params.items():
        err = model.points(p, val.Q, val.C) - val.P_ref
        norm = np.linalg.norm(err, axis=1)
        model_err = np.linalg.norm(model.points(p, val.Q, val.C_true) - reference, axis=1)
        methods.append(
            {
                "trial": trial,
                "method": name,
                "val_mean_mm": norm.mean(),
                "val_max_mm": norm.max(),
                "val_rms_mm": float(np.sqrt(np.mean(norm**2))),
                "model_rms_mm": float(np.sqrt(np.mean(model_err**2))),
                "robot_param_error": scaled_error(p, truth, ROBOT),
            }
        )
        if trial == 0:
            validation += [
                {
                    "method": name,
                    "placement": j + 1,
                    "dx_mm": e[0],
                    "dy_mm": e[1],
                    "dz_mm": e[2],
                    "norm_mm": n,
                }
                for j, (e, n) in enumerate(zip(err, norm, strict=True))
            ]
    return methods, validation


def _convergence_row(trial: int, fits: dict, st: Station, meas: Measurements) -> dict:
    """Iterations of the fits, whether the poor start found the same solution, Jacobian rank."""
    truth = st.true_params
    convergence = {
        "trial": trial,
        "good_iterations": fits["good"].iterations_to(),
        "good_solver_iterations": fits["good"].iterations,
        "poor_converged": fits["poor"] is not None,
        "poor_iterations": fits["poor"].iterations_to() if fits["poor"] else np.nan,
        "poor_solver_iterations": fits["poor"].iterations if fits["poor"] else np.nan,
        "poor_same_solution": bool(
            fits["poor"] is not None
            and scaled_error(fits["poor"].params, fits["good"].params) < 1e-3
        ),
        "nominal_robot_param_error": scaled_error(st.nominal_params, truth, ROBOT),
    }
    _, jac = default_model().points_and_jacobian(truth, meas.Q, meas.C_true)
    sv = np.linalg.svd(scaled_jacobian(jac), compute_uv=False)
    convergence["jacobian_rank"] = int(np.sum(sv > sv[0] * RANK_RTOL))
    convergence["jacobian_condition"] = float(sv[0] / sv[-1])
    return convergence


def _robot_rows(trial: int, fits: dict, st: Station) -> list[dict]:
    """Per robot parameter: true, identified (paper and ML) minus nominal, and the std."""
    truth = st.true_params
    std = fits["good"].estimate.std
    return [
        {
            "trial": trial,
            "name": PARAM_NAMES[i],
            "unit": "mm" if IS_LENGTH[i] else "deg",
            "true_minus_nominal": _conv(truth[i] - st.nominal_params[i], i),
            "identified_minus_nominal": _conv(
                angle_wrap(fits["good"].params - st.nominal_params)[i], i
            ),
            "ml_identified_minus_nominal": _conv(
                angle_wrap(fits["ml"].params - st.nominal_params)[i], i
            ),
            "std": _conv(std[i], i),
        }
        for i in range(ROBOT.start, ROBOT.stop)
    ]


def _conv(value: float, i: int) -> float:
    return float(value if IS_LENGTH[i] else math.degrees(value))


def run_trial(scenario: Scenario, seed: int, trial: int) -> dict:
    """One simulated calibration: draw a station, measure, identify every way, validate.

    Returns a dict of tables (lists of row dicts): ``methods``, ``history``, ``convergence``
    (with the rank of the Jacobian at the truth), ``robot`` and ``validation``.
    """
    rng = np.random.default_rng([seed, trial])
    st = draw_station(scenario, rng)
    meas = simulate(scenario, st, st.spheres_base, scenario.views_per_sphere, rng)
    val_sites = draw_placements(scenario, scenario.n_validation, rng)
    val = simulate(scenario, st, val_sites, 1, rng)
    fits, params = _identify_all(scenario, st, meas, rng)
    methods, validation = _validation_rows(trial, params, val, st.true_params)
    history = [
        {"trial": trial, "start": start, "iteration": i, "mean_error_mm": e}
        for start in ("good", "poor")
        if fits[start] is not None
        for i, e in enumerate(fits[start].mean_error_mm)
    ]
    return {
        "methods": methods,
        "history": history,
        "convergence": [_convergence_row(trial, fits, st, meas)],
        "robot": _robot_rows(trial, fits, st),
        "validation": validation,
    }


# ----------------------------------------------------------------------------------------------
# Monte Carlo and sweeps


def monte_carlo(scenario: Scenario, seed: int, n_trials: int, progress: bool = False) -> dict:
    """:func:`run_trial` over ``n_trials`` seeds; one DataFrame per table of its result."""
    if n_trials < 2:
        raise CalibrationError(f"Monte Carlo needs at least 2 trials (got {n_trials})")
    tables: dict[str, list] = {}
    for t in range(n_trials):
        if progress and (t % 20 == 0 or t == n_trials - 1):
            print(f"trial {t + 1}/{n_trials}", flush=True)
        for key, rows in run_trial(scenario, seed, t).items():
            tables.setdefault(key, []).extend(rows)
    return {k: pd.DataFrame(v) for k, v in tables.items()}


def noise_sweep(
    scenario: Scenario, seed: int, scales, n_trials: int, progress: bool = False
) -> pd.DataFrame:
    """Validation errors when repeatability, scanner and tracker noise are scaled together.

    The residual verdict rests on these three assumed noise levels; each ``scale`` multiplies
    all three. Returns per scale the median and 95 % interval of the largest validation error
    of the one-step identification and of the three-step route.
    """
    rows = []
    for k, f in enumerate(scales):
        u0, u1, cov = scenario.tracker
        sc = scenario.with_(
            repeatability_mm=scenario.repeatability_mm * f,
            sigma_point_mm=scenario.sigma_point_mm * f,
            tracker=(u0 * f, u1 * f, cov),
        )
        mc = monte_carlo(sc, seed + 1000 * (k + 1), n_trials, progress)["methods"]
        for name in (METHODS[0], METHODS[2]):
            med, lo, hi = median_and_spread(mc.loc[mc["method"] == name, "val_max_mm"])
            rows.append(
                {
                    "noise_scale": f,
                    "method": name,
                    "val_max_mm_median": med,
                    "val_max_mm_lo": lo,
                    "val_max_mm_hi": hi,
                }
            )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# the example cell and its identifiability


def example_station(scenario: Scenario, seed: int) -> tuple[Station, Measurements]:
    """The station and its measurements in trial 0 (the same draws as :func:`run_trial`)."""
    rng = np.random.default_rng([seed, 0])
    st = draw_station(scenario, rng)
    return st, simulate(scenario, st, st.spheres_base, scenario.views_per_sphere, rng)


def _null_space_parameters(meas: Measurements, params, rank: int) -> list[str]:
    """Parameters with weight above 0.2 in the null space of the scaled Jacobian."""
    _, jac = default_model().points_and_jacobian(params, meas.Q, meas.C_true)
    _, _, vt = np.linalg.svd(scaled_jacobian(jac))
    null = vt[rank:]
    weight = np.sqrt((null**2).sum(axis=0))
    return [PARAM_NAMES[i] for i in np.flatnonzero(weight > 0.2)]


def identifiability_designs(scenario: Scenario, meas: Measurements, params) -> dict:
    """:func:`calstudy.papers.selfcal.identify.identifiability` for the scanner's measurements
    and for a one-point sensor.

    The second design replaces every measured centre by the same sensor-frame point (on the
    optical axis at the working distance): what a sensor that returns a single point (a tracker
    reflector on the flange, a touch probe) would give from the same robot positions.

    Returns
    -------
    dict of DataFrames: ``singular`` and ``parameters`` (with a ``design`` column) and
    ``summary`` (design, rank, condition numbers, the parameters of the null space).
    """
    one_point = np.tile([0.0, 0.0, scenario.standoff_mm], (len(meas), 1))
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
