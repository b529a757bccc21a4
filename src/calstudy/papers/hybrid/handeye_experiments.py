"""The hybrid study's hand-eye experiments (notebook 01): the flexible sensor's sphere hand-eye.

The paper's method (Eq. 6-14) against the maximum likelihood of the sensor noise model, its
Cramer-Rao bound and OpenCV's AX = XB solvers on one simulated run (:func:`handeye_trial`), the
Monte Carlo experiments built on it (:func:`handeye_experiment` and the sweeps of the laser noise,
the number of pose changes and the two ranges of the pure translations), and one calibration
with its uncertainty from a user's measurements or a simulated run
(:func:`sphere_station_calibration`).
Every Monte Carlo loop runs through :func:`calstudy.io.runs.run_experiments` with a factory of
this module; a trial function is ``trial(setup, rng, **point) -> list[dict]``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import Experiment, child_rng, trial_rng
from calstudy.core.schema import with_inputs
from calstudy.handeye import (
    OPENCV_METHODS,
    opencv_handeye,
    read_sphere_measurements,
    sphere_handeye,
    sphere_handeye_crb,
    sphere_handeye_ml,
)
from calstudy.papers.hybrid.scenario import load_station
from calstudy.papers.hybrid.simulate import (
    HybridStation,
    make_station,
    simulate_sphere_measurements,
)
from calstudy.papers.hybrid.translation_rotation import (
    translation_rotation_crb,
    translation_rotation_ml,
)

SCENARIOS = {
    # the paper's station: kinematic model error, repeatability and sensor noise
    "station": {"robot_errors": True},
    # sensor noise alone: true robot = nominal, no repeatability; the CRB applies exactly
    "sensor noise only": {"robot_errors": False, "repeatability_mm": 0.0},
}


def check_scenario(name: str) -> dict:
    """The station settings of the scenario ``name`` (a key of :data:`SCENARIOS`).

    Parameters
    ----------
    name : str
        ``"station"`` or ``"sensor noise only"``.

    Returns
    -------
    dict
        Keyword arguments of :func:`calstudy.papers.hybrid.simulate.make_station`.

    Raises
    ------
    CalibrationError
        If ``name`` is not a scenario (the message lists them).
    """
    if name not in SCENARIOS:
        raise CalibrationError(f"unknown scenario {name!r}; use one of {list(SCENARIOS)}")
    return SCENARIOS[name]


def paper_moves(station: HybridStation) -> tuple[int, int]:
    """The paper's calibration moves (section 4.2): pure translations, then pose changes."""
    moves = station.config.calibration_moves
    return moves.n_translations, moves.n_rotations


# ---------------------------------------------------------------------------------------------
# trials of notebook 01


def design_mounting(sensor2flange: np.ndarray) -> np.ndarray:
    """The sensor mounting a drawing gives: the truth rounded to 1 deg (rotation vector) and
    1 mm. The "doing nothing" answer of the hand-eye null control."""
    vec = geo.pose_to_vector(sensor2flange)
    vec[:3] = np.round(vec[:3])
    vec[3:] = np.deg2rad(np.round(np.rad2deg(vec[3:])))
    return geo.pose_from_vector(vec)


def handeye_trial(
    station: HybridStation,
    n_trans: int,
    n_rot: int,
    rng: np.random.Generator,
    baselines: bool = True,
) -> dict[str, tuple[float, float]]:
    """Errors (rotation deg, translation mm) of every hand-eye method on one simulated run.

    Methods: the paper's (``"sphere"``); the maximum likelihood of the sensor noise model
    (``"ML"``: every centre weighted by its full covariance from the sensor model, the strong
    y-z correlation of the line laser included); the Cramer-Rao bound of that model at the
    truth (``"CRB"``, an expected RMS); the rotation from the pure translations alone, its
    bound (``"CRB translations"``) and its fit weighted by each centre's covariance
    (``"weighted rotation"``), both without a translation (NaN); the controls: the design
    mounting (``"null control"``,
    doing nothing) and the paper's method on noise-free centres (``"oracle control"``); with
    ``baselines`` the five OpenCV AX = XB methods fed with the hole target's pose seen at the
    same robot poses.
    """
    meas, actual = simulate_sphere_measurements(station, n_trans, n_rot, rng)
    truth = station.sensor2flange_true
    radius = station.sphere.radius_mm
    out: dict[str, tuple[float, float]] = {}

    def err(t):
        return float(np.rad2deg(geo.rotation_error(t, truth))), float(
            geo.translation_error(t, truth)
        )

    paper = sphere_handeye(*meas.select("translation"), *meas.select("rotation"))
    out["sphere"] = err(paper.value)
    cov = station.laser.centre_covariance(meas.centres, radius)
    # the station scenario's robot pose error lies outside the ML's sensor noise model (the
    # chapter says so): its fit check would flag every such trial, so it is off here
    ml = sphere_handeye_ml(meas.flange2base, meas.centres, cov, paper.value, misfit="off")
    out["ML"] = err(ml.value)
    # centres the sensor would report without noise at the actual poses
    chain = actual @ truth
    clean = np.einsum("nji,nj->ni", chain[:, :3, :3], station.sphere.centre - chain[:, :3, 3])
    crb_cov = station.laser.centre_covariance(clean, radius)
    crb = sphere_handeye_crb(meas.flange2base, clean, crb_cov, truth, station.sphere.centre)
    is_t = meas.group == "translation"
    out["CRB"] = (
        float(np.rad2deg(np.sqrt(np.trace(crb[3:6, 3:6])))),
        float(np.sqrt(np.trace(crb[:3, :3]))),
    )
    # the rotation from the pure translations alone: its bound, and the fit weighted by each
    # centre's covariance (the paper's SVD weighs them equally); no translation (NaN)
    f_t, c_t = meas.select("translation")
    out["CRB translations"] = (
        translation_rotation_crb(f_t, clean[is_t], crb_cov[is_t], truth[:3, :3]),
        float("nan"),
    )
    weighted = translation_rotation_ml(f_t, c_t, cov[is_t], paper.value[:3, :3])
    out["weighted rotation"] = (err(geo.make_transform(weighted, truth[:3, 3]))[0], float("nan"))
    out["null control"] = err(design_mounting(truth))
    oracle = sphere_handeye(
        meas.flange2base[is_t], clean[is_t], meas.flange2base[~is_t], clean[~is_t]
    )
    out["oracle control"] = err(oracle.value)
    if baselines:
        target2base = geo.make_transform(np.eye(3), station.sphere.centre)
        t2s = station.observe_target_pose(actual, target2base, child_rng(rng, "target images"))
        for name in OPENCV_METHODS:
            out[name] = err(opencv_handeye(meas.flange2base, t2s, name))
    return out


def handeye_run(
    setup: dict,
    rng: np.random.Generator,
    scenario: str = "sensor noise only",
    sigma_point_mm: float | None = None,
    n_rot: int | None = None,
    translation_range_mm: float | None = None,
    across_plane_range_mm: float | None = None,
    translation_pattern: str = "random",
) -> list[dict]:
    """One hand-eye trial: a drawn station, its calibration run, one row per method.

    ``translation_range_mm`` and ``across_plane_range_mm`` override the ranges of the pure
    translations of ``[calibration_moves]`` in ``station.toml``; ``translation_pattern``
    "designed" puts the translations on a fixed pattern instead of drawing them. Columns: ``method,
    rotation_error_deg, translation_error_mm, laser_sigma_mm, n_translations, n_pose_changes``
    (``CRB`` rows hold the bound's expected RMS of the trial's poses). ``setup["overrides"]``,
    if given, sets inputs of ``station.toml`` by their dotted keys (:func:`station_config`).
    """
    station = make_station(
        rng,
        sigma_point_mm=sigma_point_mm,
        config=station_config(setup.get("overrides")),
        **check_scenario(scenario),
    )
    station = with_move_ranges(station, translation_range_mm, across_plane_range_mm)
    station = replace(station, translation_pattern=translation_pattern)
    n_trans = int(setup["n_trans"])
    n_rot = int(setup["n_rot"] if n_rot is None else n_rot)
    errors = handeye_trial(station, n_trans, n_rot, rng, baselines=bool(setup["baselines"]))
    return [
        {
            "method": method,
            "rotation_error_deg": rot,
            "translation_error_mm": trans,
            "laser_sigma_mm": station.laser.sigma_point_mm,
            "n_translations": n_trans,
            "n_pose_changes": n_rot,
        }
        for method, (rot, trans) in errors.items()
    ]


def station_config(overrides=None):
    """``station.toml`` with ``overrides`` (dotted keys -> values, validated against the
    ledger ranges), or None for the file as it is (what :func:`make_station` then loads); the
    validated file is kept by :func:`~calstudy.core.schema.load_model`, by its version and the
    overrides."""
    return load_station(overrides=dict(overrides)) if overrides else None


def handeye_setup(baselines: bool) -> dict:
    """The setup of a hand-eye trial (:func:`handeye_run`): the station's calibration moves,
    whether to run the AX = XB baselines, and the trial's version (the cache's fingerprint).

    Parameters
    ----------
    baselines : bool
        Run the AX = XB baselines too.

    Returns
    -------
    dict
        ``n_trans``, ``n_rot``, ``baselines``, ``version``.
    """
    n_trans, n_rot = load_station_moves()
    # version 2: the rotation from the pure translations (its bound, a weighted fit) per trial
    return {"n_trans": n_trans, "n_rot": n_rot, "baselines": bool(baselines), "version": 2}


def load_station_moves() -> tuple[int, int]:
    """The paper's calibration moves of ``station.toml`` (section 4.2)."""
    moves = load_station().calibration_moves
    return moves.n_translations, moves.n_rotations


def handeye_experiment(n_trials: int = 200) -> Experiment:
    """The hand-eye comparison in both scenarios (points ``scenario``), with AX = XB baselines."""
    points = [{"scenario": name} for name in SCENARIOS]
    return Experiment("handeye", handeye_run, handeye_setup(True), n_trials, points)


def handeye_noise_experiment(noise_levels_mm=(0.005, 0.01, 0.02, 0.05), n_trials: int = 30):
    """The hand-eye against the laser's stripe-point noise, sensor noise only."""
    points = [{"sigma_point_mm": float(s)} for s in noise_levels_mm]
    return Experiment("handeye_noise", handeye_run, handeye_setup(False), n_trials, points)


def handeye_moves_experiment(rotation_moves=(3, 4, 6, 10), n_trials: int = 30):
    """The hand-eye against the number of pose changes (4 translations), sensor noise only."""
    points = [{"n_rot": int(m)} for m in rotation_moves]
    return Experiment("handeye_moves", handeye_run, handeye_setup(False), n_trials, points)


#: the noise model's parts beyond the stripe (``[sensor]`` of ``station.toml``) that
#: :func:`handeye_noise_model_experiment` sweeps, each alone
NOISE_MODEL_KEYS = ("sensor.centre_floor_mm", "sensor.correlation_scale")


def handeye_input_run(setup: dict, rng: np.random.Generator, parameter: str, value: float):
    """One hand-eye trial (sensor noise only) with the input ``parameter`` of ``station.toml``
    (a dotted key) at ``value``, validated against its ledger range; the rows of
    :func:`handeye_run`."""
    overrides = {**setup.get("overrides", {}), parameter: float(value)}
    return handeye_run({**setup, "overrides": overrides}, rng)


def handeye_noise_model_experiment(
    centre_floors_mm=(0.0, 0.005, 0.01, 0.02),
    correlation_scales=(0.5, 0.75, 0.9, 1.0),
    n_trials: int = 30,
) -> Experiment:
    """The hand-eye against the assumed parts of the sensor noise model, sensor noise only:
    the independent centre-noise floor (mm per axis) and the factor on the line laser's y-(x, z)
    correlation, each moved alone (the other at its value in ``station.toml``): points
    ``{"parameter": key, "value": v}`` with the keys of :data:`NOISE_MODEL_KEYS`."""
    points = []
    for key, values in zip(NOISE_MODEL_KEYS, (centre_floors_mm, correlation_scales), strict=True):
        if len(values) == 0:
            raise CalibrationError(f"no values of {key} to sweep; give at least one")
        points += [{"parameter": key, "value": float(v)} for v in values]
    return Experiment(
        "handeye_noise_model", handeye_input_run, handeye_setup(False), n_trials, points
    )


def with_move_ranges(
    station: HybridStation,
    translation_range_mm: float | None = None,
    across_plane_range_mm: float | None = None,
) -> HybridStation:
    """``station`` with the ranges of its pure translations replaced (None keeps the value of
    ``station.toml``)."""
    changes = {
        f"calibration_moves.{key}": float(value)
        for key, value in (
            ("translation_range_mm", translation_range_mm),
            ("across_plane_range_mm", across_plane_range_mm),
        )
        if value is not None
    }
    if not changes:
        return station
    return replace(station, config=with_inputs(station.config, changes))


#: the move ranges the range sweep moves, each alone (the other at its value in station.toml)
RANGE_KEYS = {
    "translation_range_mm": "translation_ranges_mm",
    "across_plane_range_mm": "across_plane_ranges_mm",
}


def handeye_range_run(setup: dict, rng: np.random.Generator, parameter: str, value: float):
    """One hand-eye trial (sensor noise only) with the move range ``parameter`` (a key of
    :data:`RANGE_KEYS`) at ``value`` mm; the rows of :func:`handeye_run`."""
    if parameter not in RANGE_KEYS:
        raise CalibrationError(f"unknown move range {parameter!r}; use one of {list(RANGE_KEYS)}")
    return handeye_run(setup, rng, **{parameter: float(value)})


def handeye_ranges_experiment(
    translation_ranges_mm=None, across_plane_ranges_mm=None, n_trials: int = 30
) -> Experiment:
    """The hand-eye against the ranges of the pure translations, sensor noise only (the
    scenario of the verdict): points ``{"parameter": key, "value": mm}``, each range moved
    alone, the other at its default. Defaults: the values listed in ``[calibration_moves]`` of
    ``station.toml``."""
    moves = load_station().calibration_moves
    given = {
        "translation_range_mm": translation_ranges_mm,
        "across_plane_range_mm": across_plane_ranges_mm,
    }
    points = []
    for key, values in given.items():
        values = getattr(moves, RANGE_KEYS[key]) if values is None else values
        if len(values) == 0:
            raise CalibrationError(f"no values of {key} to sweep; give at least one")
        points += [{"parameter": key, "value": float(v)} for v in values]
    return Experiment("handeye_ranges", handeye_range_run, handeye_setup(False), n_trials, points)


def handeye_pattern_experiment(n_trials: int = 30) -> Experiment:
    """The hand-eye with the pure translations drawn at random (the study's default) and on a
    designed pattern (:data:`calstudy.papers.hybrid.simulate.DESIGNED_SHIFTS`), sensor noise
    only: points ``{"translation_pattern": "random" | "designed"}``."""
    points = [
        {"scenario": "sensor noise only", "translation_pattern": p} for p in ("random", "designed")
    ]
    return Experiment("handeye_pattern", handeye_run, handeye_setup(False), n_trials, points)


def _sensor_sigma(sensor_sigma_mm) -> np.ndarray:
    """``sensor_sigma_mm`` (one value or one per sensor axis) as 3 finite values > 0, mm."""
    try:
        sigma = np.asarray(sensor_sigma_mm, dtype=float)
    except (TypeError, ValueError):
        sigma = np.asarray(np.nan)
    if sigma.shape not in ((), (3,)) or not (np.all(np.isfinite(sigma)) and np.all(sigma > 0)):
        raise CalibrationError(
            f"sensor_sigma_mm = {sensor_sigma_mm!r}: give the standard deviation of a measured "
            "sphere centre as one value or one per sensor axis (3 values), each a finite "
            "number > 0 mm"
        )
    return np.broadcast_to(sigma, (3,))


def sphere_station_calibration(
    measurements_csv: str, seed: int, sensor_sigma_mm=None, misfit: str = "raise"
):
    """The fixed-sphere hand-eye from a user's CSV if given, else from one simulated run.

    ``sensor_sigma_mm`` is the standard deviation (mm, one or one per sensor axis) of a measured
    centre, everything included: the sensor's repeatability and the robot's pose error, which
    the nominal model the flange poses come from does not know. ``misfit`` (``"raise"`` or
    ``"flag"``) says what a user's data whose ML fit is far outside it does: refused, or kept
    with the message in ``ml_estimate.flags`` and a :class:`calstudy.CalibrationWarning`. The
    simulated run always flags (its robot errors are not in the sensor noise).

    Returns ``(source, measurements, paper_estimate, ml_estimate, table)`` where ``table`` lists
    ``sensor2flange`` (translation mm, rotation vector deg) by the paper's method and by the ML
    refinement with its standard deviations, and, for simulated data, the truth.

    Raises
    ------
    CalibrationError
        For a user's CSV, on any check of
        :func:`calstudy.handeye.sphere_csv.read_sphere_measurements`, and if the ML fit is far
        outside ``sensor_sigma_mm`` (goodness of fit, ``misfit="flag"``): the message names the
        measurement ids that disagree most (a sphere that moved between the two series);
        ``misfit="flag"`` turns this into a warning.
    """
    rng = trial_rng(seed, "handeye_calibration", {}, 0)
    truth = None
    if measurements_csv:
        meas = read_sphere_measurements(measurements_csv)
        source = f"user measurements from {measurements_csv} ({len(meas.ids)} rows)"
        sigma = _sensor_sigma(sensor_sigma_mm)
    else:
        station = make_station(rng)
        meas, _ = simulate_sphere_measurements(station, *paper_moves(station), rng)
        source = "one simulated run of the station (no user measurements given)"
        # the full covariance of each centre from the sensor model (the ML of its noise)
        sigma = station.laser.centre_covariance(meas.centres, station.sphere.radius_mm)
        truth = station.sensor2flange_true
    paper = sphere_handeye(*meas.select("translation"), *meas.select("rotation"))
    if measurements_csv:
        # measured data: a fit far outside the stated noise (a sphere that moved between the
        # series, mixed units) is refused (or flagged), naming the ids that disagree most
        ml = sphere_handeye_ml(
            meas.flange2base, meas.centres, sigma, paper.value, ids=meas.ids, misfit=misfit
        )
    else:
        # the simulated station's robot pose error lies outside the ML's sensor noise model:
        # the fit is reported beside the source, not raised or warned
        ml = sphere_handeye_ml(meas.flange2base, meas.centres, sigma, paper.value, misfit="off")
        if ml.fit is not None:
            source += (
                f"; ML chi2/dof {ml.fit.chi2_dof:.3g} against the sensor noise alone (the robot's"
                " pose error is not in that model)"
            )
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
