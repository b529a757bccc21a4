"""Pose planning for a cell: views of the spheres for your sensor, the D-optimal choice among
them, and how much better it is than your own poses and than random ones.

A view looks at a sphere from within a cone about the direction to the robot's shoulder, at the
sensor's working distance, the sphere anywhere in its field, turned about the optical axis at
random (:class:`ViewGeometry`); the joint angles come from the nominal robot's inverse
kinematics. :func:`suggest_poses` plans such views of the spheres a cell used, picks as many as
asked by D-optimality (:func:`calstudy.selfcal.design.select_poses`) and compares them with the
cell's own poses and with random choices from the same candidates, predicted
(:func:`predicted_std`) and measured by a Monte Carlo on the identified cell
(:func:`measured_selection_errors`).

Frames: ``part`` (the tracker's), robot ``base``, ``flange`` and ``sensor``. Millimetres and
radians.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError, CalibrationWarning
from calstudy.core.geometry import look_at, make_transform
from calstudy.core.montecarlo import child_rng, streams
from calstudy.core.stats import median_interval
from calstudy.models.kinematics import Robot
from calstudy.selfcal.design import candidate_jacobians, observability, select_poses
from calstudy.selfcal.identify import Measurements, scaled_jacobian
from calstudy.selfcal.measured import CellFit, MeasuredCell, identify_measurements
from calstudy.selfcal.model import N_PARAMS, default_model

#: random selections of the same size that the planned poses are compared with
RANDOM_SELECTIONS = 200
#: replications of the measured comparison of planned and random poses (the notebook's default)
MEASURED_REPLICATIONS = 200
#: fewest replications whose median has a 95 % order-statistic interval
MIN_REPLICATIONS = 6


@dataclass(frozen=True)
class ViewGeometry:
    """How views of a sphere are drawn for a sensor.

    Attributes
    ----------
    standoff_mm : float
        The sensor's working distance, mm.
    field_mm, depth_mm : float
        Half-widths of its field across and along the optical axis, mm: the point looked at lies
        within them of the sphere's centre.
    view_cone_rad : float
        Half-angle of the cone of viewing directions about the direction to the shoulder, rad.
    roll_deg : float
        Largest turn about the optical axis, degrees.
    """

    standoff_mm: float
    field_mm: float
    depth_mm: float
    view_cone_rad: float
    roll_deg: float


def draw_until(n: int, tries: int, draw, failure) -> np.ndarray:
    """``n`` results of ``draw(found)`` in at most ``tries`` calls (``None`` is a miss).

    Parameters
    ----------
    n : int
        Results wanted.
    tries : int
        Calls allowed.
    draw : callable
        ``draw(found)`` with the list of results so far; returns a result or None.
    failure : callable
        ``failure(found_count)`` gives the error message.

    Returns
    -------
    numpy.ndarray, shape (n, ...)
        The results in the order found.

    Raises
    ------
    CalibrationError
        With the message ``failure(len(found))`` when ``tries`` calls found fewer than ``n``.
    """
    out: list[np.ndarray] = []
    for _ in range(tries):
        item = draw(out)
        if item is not None:
            out.append(item)
            if len(out) == n:
                return np.array(out)
    raise CalibrationError(failure(len(out)))


def _roll(deg: float) -> np.ndarray:
    """``make_transform(euler_zyx_to_matrix(deg, 0, 0), 0)``, a turn about z by ``deg``, built
    as scipy builds it (the quaternion ``(x, y, z, w) = (0, 0, sin h, cos h)`` of the half angle
    ``h``, then its matrix): the same bytes, signed zeros included, at a tenth of the cost (a
    test checks it)."""
    half = float(np.deg2rad(deg)) / 2.0 + 0.0  # -0 turns as +0, as in scipy
    x = y = 0.0
    z, w = math.sin(half), math.cos(half)
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, xz, xw, yz, yw, zw = x * y, x * z, x * w, y * z, y * w, z * w
    return np.array(
        [
            [x2 - y2 - z2 + w2, 2.0 * (xy - zw), 2.0 * (xz + yw), 0.0],
            [2.0 * (xy + zw), -x2 + y2 - z2 + w2, 2.0 * (yz - xw), 0.0],
            [2.0 * (xz - yw), 2.0 * (yz + xw), -x2 - y2 + z2 + w2, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _view_pose(geometry: ViewGeometry, centre: np.ndarray, frame: np.ndarray, rng) -> np.ndarray:
    """A drawn sensor pose (4, 4) in the base frame looking at ``centre`` (see plan_views).

    ``frame`` (3, 3) has its z column along the unit direction from the sphere to the robot's
    shoulder (``look_at(0, towards)``).
    """
    tilt = geometry.view_cone_rad * math.sqrt(rng.uniform())
    turn = rng.uniform(0, 2 * math.pi)
    d = frame @ [
        math.sin(tilt) * math.cos(turn),
        math.sin(tilt) * math.sin(turn),
        math.cos(tilt),
    ]
    offset = rng.uniform(-1.0, 1.0, 3) * [
        geometry.field_mm,
        geometry.field_mm,
        geometry.depth_mm,
    ]
    distance = geometry.standoff_mm + offset[2]
    eye = centre + distance * d
    sensor2base = look_at(eye, centre)
    roll = _roll(rng.uniform(-geometry.roll_deg, geometry.roll_deg))
    shift = make_transform(np.eye(3), [-offset[0], -offset[1], 0.0])
    return sensor2base @ roll @ shift


def _shoulder(robot: Robot) -> np.ndarray:
    """Point on axis 1 at the height of axis 2, robot base frame (where views look from)."""
    return robot.base[:3, :3] @ [0.0, 0.0, robot.links[0].d] + robot.base[:3, 3]


def plan_views(
    robot: Robot,
    sensor2flange,
    geometry: ViewGeometry,
    centre_base,
    n: int,
    rng: np.random.Generator,
    max_tries: int = 200,
) -> np.ndarray:
    """Joint angles that show the sphere at ``centre_base`` to the sensor.

    Planned with the nominal robot and sensor mounting (all the controller knows): each view
    looks at a point within ``field_mm``/``depth_mm`` of the sphere, from a direction within
    ``view_cone_rad`` of the direction to the robot's shoulder, turned about the optical axis by
    at most ``roll_deg``. Views whose inverse kinematics fails or leaves the joint limits are
    redrawn.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    sensor2flange : array_like, shape (4, 4)
        The nominal sensor frame in the flange frame, mm.
    geometry : ViewGeometry
        How the views are drawn.
    centre_base : array_like, shape (3,)
        The sphere's centre in the robot base frame, mm.
    n : int
        Views wanted.
    rng : numpy.random.Generator
        The stream the views draw from.
    max_tries : int
        Views drawn at most.

    Returns
    -------
    numpy.ndarray, shape (n, 6)
        Joint angles, rad.

    Raises
    ------
    CalibrationError
        Fewer than ``n`` reachable views in ``max_tries`` draws.
    """
    flange2sensor = np.linalg.inv(sensor2flange)
    centre = np.asarray(centre_base, float)
    towards = _shoulder(robot) - centre
    towards /= np.linalg.norm(towards)
    frame = look_at(np.zeros(3), towards)[:3, :3]

    def draw(_found: list[np.ndarray]) -> np.ndarray | None:
        flange2base = _view_pose(geometry, centre, frame, rng) @ flange2sensor
        q0 = _seed_configuration(robot, flange2base[:3, 3])
        try:
            return robot.ik(flange2base, q0)
        except CalibrationError:
            return None

    return draw_until(
        n,
        max_tries,
        draw,
        lambda found: (
            f"found only {found} of {n} reachable views of the sphere at "
            f"{np.round(centre, 1).tolist()} mm after {max_tries} tries"
        ),
    )


def _seed_configuration(robot: Robot, flange_xyz) -> np.ndarray:
    """An elbow-up start for IK: joint 1 towards the point, arm half bent, wrist bent down."""
    q1 = math.atan2(flange_xyz[1], flange_xyz[0])
    return np.array([q1, 0.3, 0.0, 0.0, -0.8, 0.0])


def candidate_views(
    robot: Robot, sensor2flange, geometry: ViewGeometry, spheres_base, per_sphere: int, rng
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate poses: ``per_sphere`` reachable views of each sphere (:func:`plan_views`).

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    sensor2flange : array_like, shape (4, 4)
        The nominal sensor frame in the flange frame, mm.
    geometry : ViewGeometry
        How the views are drawn.
    spheres_base : array_like, shape (k, 3)
        Sphere centres in the robot base frame, mm.
    per_sphere : int
        Views per sphere.
    rng : numpy.random.Generator
        Sphere ``k`` draws from ``child_rng`` of the stream ``"candidate views"``, key ``k``.

    Returns
    -------
    Q : numpy.ndarray, shape (k per_sphere, 6)
        Joint angles, rad.
    sphere : numpy.ndarray, shape (k per_sphere,)
        Each candidate's sphere (index into ``spheres_base``).

    Raises
    ------
    CalibrationError
        A sphere with fewer than ``per_sphere`` reachable views.
    """
    (views_rng,) = streams(rng, "candidate views")
    views = [
        plan_views(robot, sensor2flange, geometry, c, per_sphere, child_rng(views_rng, str(k)))
        for k, c in enumerate(np.asarray(spheres_base, float))
    ]
    return np.vstack(views), np.repeat(np.arange(len(views)), per_sphere)


def predicted_std(blocks) -> float:
    """Parameter spread a selection of poses predicts (A-optimality).

    Parameters
    ----------
    blocks : array_like, shape (k, 3, p)
        Scaled Jacobian blocks of the selected poses
        (:func:`calstudy.selfcal.identify.scaled_jacobian`).

    Returns
    -------
    float
        RMS standard deviation of the parameters (scaled units) per mm of measurement noise,
        ``sqrt(trace((J^T J)^-1) / p)``; inf if the selection does not fix every parameter.
    """
    b = np.asarray(blocks, float)
    j = b.reshape(-1, b.shape[-1])
    s = np.linalg.svd(j, compute_uv=False)
    if len(s) < b.shape[-1] or s[-1] <= s[0] * 1e-12:
        return math.inf
    return float(np.sqrt(np.mean(1.0 / s**2)))


def suggest_poses(
    cell: MeasuredCell,
    per_sphere: int,
    rng: np.random.Generator,
    default_geometry: ViewGeometry,
    n_poses: int | None = None,
    standoff_mm: float | None = None,
    field_mm: float | None = None,
    depth_mm: float | None = None,
    free=None,
    truth: CellFit | None = None,
    replications: int = MEASURED_REPLICATIONS,
) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    """Poses to measure next time on a cell, planned for its sensor.

    Candidates: ``per_sphere`` reachable views of each sphere the calibration used, planned with
    the cell's nominal robot and sensor mounting, the sphere within ``field_mm`` of the optical
    axis and ``depth_mm`` of the working distance ``standoff_mm`` (each: the argument, else the
    cell's ``[sensor]`` geometry, else ``default_geometry``). From them, ``n_poses`` D-optimal
    ones (:func:`calstudy.selfcal.design.select_poses`) in the parameters ``free``.

    Parameters
    ----------
    cell : MeasuredCell
        The cell (:func:`calstudy.selfcal.measured.read_cell`).
    per_sphere : int
        Candidate views per sphere.
    rng : numpy.random.Generator
        Draws the candidates, the random selections and the Monte Carlo.
    default_geometry : ViewGeometry
        The view cone and roll, and the sensor geometry where neither an argument nor the cell
        gives it.
    n_poses : int, optional
        Poses to plan; default as many as the calibration has.
    standoff_mm, field_mm, depth_mm : float, optional
        The sensor's working distance and field half-widths, mm.
    free : array_like of bool, shape (30,), optional
        The parameters to plan for (default all; pass :attr:`CellFit.free` to plan for what the
        poses can identify).
    truth : CellFit, optional
        The cell's identification: its parameters are taken as the truth of a Monte Carlo of
        measured errors (:func:`measured_selection_errors`).
    replications : int
        Replications of that Monte Carlo (at least :data:`MIN_REPLICATIONS`).

    Returns
    -------
    suggested : pandas.DataFrame
        The joint angles (deg) with the sphere id, ``n_poses`` rows.
    compare : pandas.DataFrame
        Observability (:func:`calstudy.selfcal.design.observability`) and :func:`predicted_std`
        of your poses and of the selection; ``better`` is True on the selection only if its
        predicted standard deviation is below that of your poses (else keep yours).
    random : dict
        The selection against :data:`RANDOM_SELECTIONS` random choices of ``n_poses`` from the
        same candidates: median of the ratio random / planned of :func:`predicted_std` with its
        95 % order-statistic interval (``ratio_median``, ``ratio_ci_low``, ``ratio_ci_high``),
        and the sensor geometry planned for. With ``truth``, also the measured comparison of
        :func:`measured_selection_errors`.

    Raises
    ------
    CalibrationError
        Fewer candidates than poses asked for (plan more views per sphere), a sensor
        geometry that is not positive, or fewer than :data:`MIN_REPLICATIONS` replications.
    """
    if truth is not None:
        _check_replications(replications)
    given = {"standoff_mm": standoff_mm, "field_mm": field_mm, "depth_mm": depth_mm}
    own = cell.sensor_geometry or {}
    sensor = {
        k: float(v if v is not None else own.get(k, getattr(default_geometry, k)))
        for k, v in given.items()
    }
    for key, value in sensor.items():
        if not (math.isfinite(value) and value > 0):
            raise CalibrationError(f"the sensor's {key} = {value} must be a positive length")
    n = len(cell.calibration) if n_poses is None else int(n_poses)
    free = np.ones(N_PARAMS, bool) if free is None else np.asarray(free, bool)
    geometry = replace(default_geometry, **sensor)
    used = np.unique(cell.calibration.sphere)
    base2part = np.linalg.inv(cell.part2base)
    spheres_base = cell.spheres[used] @ base2part[:3, :3].T + base2part[:3, 3]
    cand_q, cand_s = candidate_views(
        cell.robot, cell.sensor2flange, geometry, spheres_base, per_sphere, rng
    )
    if n > len(cand_q):
        raise CalibrationError(
            f"{n} poses asked for from {len(cand_q)} candidates ({per_sphere} per sphere of "
            f"{len(used)}); plan at least {math.ceil(n / len(used))} views per sphere"
        )
    blocks, _ = candidate_jacobians(cell.start, cand_q, cell.spheres[used], cand_s)
    blocks = blocks[:, :, free]
    chosen = select_poses(blocks, n)
    _, own = default_model().points_and_jacobian(cell.start, cell.calibration.Q, cell.calibration.C)
    own_blocks = scaled_jacobian(own).reshape(len(cell.calibration), 3, -1)[:, :, free]
    suggested = pd.DataFrame(np.degrees(cand_q[chosen]), columns=[f"q{i}_deg" for i in range(1, 7)])
    suggested.insert(0, "sphere", cell.sphere_ids[used][cand_s[chosen]])
    own_std, planned_std = predicted_std(own_blocks), predicted_std(blocks[chosen])
    compare = pd.DataFrame(
        [
            {"poses": "yours", **observability(own_blocks), "predicted_std": own_std},
            {"poses": "selected", **observability(blocks[chosen]), "predicted_std": planned_std},
        ]
    )
    compare["better"] = [False, bool(planned_std < own_std)]
    ratios = [
        predicted_std(blocks[rng.choice(len(cand_q), n, replace=False)]) / planned_std
        for _ in range(RANDOM_SELECTIONS)
    ]
    med, lo, hi = median_interval(np.asarray(ratios, float))
    random = {
        "n_poses": n,
        "candidates": len(cand_q),
        "draws": RANDOM_SELECTIONS,
        "ratio_median": med,
        "ratio_ci_low": lo,
        "ratio_ci_high": hi,
        **sensor,
    }
    if truth is not None:
        random |= measured_selection_errors(
            cell, truth, cand_q, used[cand_s], chosen, replications, rng
        )
    return suggested, compare, random


def _check_replications(replications) -> None:
    if int(replications) != replications or replications < MIN_REPLICATIONS:
        raise CalibrationError(
            f"replications = {replications}: at least {MIN_REPLICATIONS} are needed for a 95 % "
            "interval of the median ratio"
        )


def simulate_cell_rows(truth, Q, sphere, spheres_part, sigma_mm: float, declared: bool, rng):
    """A measured cell's rows simulated from its identified parameters.

    Each row is the sphere centre in the sensor frame that the parameters ``truth`` put at the
    joint angles, plus Gaussian noise of ``sigma_mm`` per axis (the whole per-axis noise of a
    row: sensor, repeatability and tracker together); the tracker reading is the sphere's
    reading.

    Parameters
    ----------
    truth : array_like, shape (30,)
        The parameters taken as the truth (mm, rad).
    Q : array_like, shape (m, 6)
        Joint angles, rad.
    sphere : array_like, shape (m,)
        Index of each row's sphere into ``spheres_part``.
    spheres_part : array_like, shape (k, 3)
        Sphere centres in the part frame, mm.
    sigma_mm : float
        Per-axis standard deviation of a row, mm.
    declared : bool
        Give the rows their covariance (``sigma_mm**2 I``), as a cell with declared noise.
    rng : numpy.random.Generator
        The noise stream.

    Returns
    -------
    Measurements
        ``C_true`` the noise-free centres.
    """
    Q = np.asarray(Q, float)
    sphere = np.asarray(sphere, int)
    p = np.asarray(spheres_part, float)[sphere]
    local = default_model().sensor_centres(np.asarray(truth, float), Q, p)
    cov = np.tile(sigma_mm**2 * np.eye(3), (len(Q), 1, 1)) if declared else None
    return Measurements(Q, local + rng.normal(0.0, sigma_mm, local.shape), p, sphere, local, cov)


def measured_selection_errors(
    cell: MeasuredCell,
    truth: CellFit,
    cand_q,
    cand_sphere,
    chosen,
    replications: int,
    rng: np.random.Generator,
) -> dict:
    """Monte Carlo of the measured error of planned against random poses on a user's cell.

    The cell's identified parameters are the truth; the noise is the declared one (the fit then
    weights by it) or, without, the fit's per-axis residual scale. Per replication the planned
    poses ``chosen`` and a random choice of as many from the same candidates are measured with
    new noise (:func:`simulate_cell_rows`), each identified from the cell's start as the cell
    was (:func:`~calstudy.selfcal.measured.identify_measurements`, outlier rule on; the column
    check is skipped: the columns are right by construction), and scored by the RMS position
    error at the cell's held-out validation rows (the calibration rows when it has none):
    identified against true model, at their joint angles and sensor-frame centres, without noise.

    Parameters
    ----------
    cell : MeasuredCell
        The cell (start, spheres, noise, validation rows).
    truth : CellFit
        Its identification.
    cand_q : array_like, shape (c, 6)
        Candidate joint angles, rad.
    cand_sphere : array_like, shape (c,)
        Each candidate's sphere (index into ``cell.spheres``).
    chosen : array_like of int, shape (n,)
        The planned candidates.
    replications : int
        At least :data:`MIN_REPLICATIONS`.
    rng : numpy.random.Generator
        Replication ``r`` draws from ``child_rng(rng, "measured replication r")`` alone.

    Returns
    -------
    dict
        ``replications``, ``noise_sigma_mm``, medians ``planned_rms_mm`` and ``random_rms_mm``,
        the paired ratio random / planned (``measured_ratio_median``, ``measured_ratio_ci_low``,
        ``measured_ratio_ci_high``; order-statistic 95 % interval over the replications where
        both identifications succeeded) and the failed identifications ``failed_planned``,
        ``failed_random``.

    Raises
    ------
    CalibrationError
        Fewer than :data:`MIN_REPLICATIONS` replications, or fewer pairs that both succeeded.
    """
    _check_replications(replications)
    model = default_model()
    cand_q, cand_sphere = np.asarray(cand_q, float), np.asarray(cand_sphere, int)
    chosen = np.asarray(chosen, int)
    declared = cell.noise is not None
    sigma = truth.sigma_mm
    sites = cell.validation if len(cell.validation) else cell.calibration
    true_points = model.points(truth.params, sites.Q, sites.C)

    def error(picks, noise_rng) -> float:
        meas = simulate_cell_rows(
            truth.params, cand_q[picks], cand_sphere[picks], cell.spheres, sigma, declared,
            noise_rng,
        )
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", CalibrationWarning)
                fit = identify_measurements(meas, cell.start, cell.noise, check_columns=False)
        except CalibrationError:
            return math.nan
        d = model.points(fit.params, sites.Q, sites.C) - true_points
        return float(np.sqrt(np.mean(np.einsum("ij,ij->i", d, d))))

    planned, random = [], []
    for r in range(int(replications)):
        rep = child_rng(rng, f"measured replication {r}")
        picks = np.sort(child_rng(rep, "selection").choice(len(cand_q), len(chosen), replace=False))
        planned.append(error(chosen, child_rng(rep, "planned measurements")))
        random.append(error(picks, child_rng(rep, "random measurements")))
    planned_a, random_a = np.array(planned), np.array(random)
    both = np.isfinite(planned_a) & np.isfinite(random_a)
    if both.sum() < MIN_REPLICATIONS:
        raise CalibrationError(
            f"only {int(both.sum())} of {replications} replications identified both selections "
            f"(at least {MIN_REPLICATIONS} needed)"
        )
    med, lo, hi = median_interval(random_a[both] / planned_a[both])
    return {
        "replications": int(replications),
        "noise_sigma_mm": float(sigma),
        "planned_rms_mm": float(np.median(planned_a[both])),
        "random_rms_mm": float(np.median(random_a[both])),
        "measured_ratio_median": med,
        "measured_ratio_ci_low": lo,
        "measured_ratio_ci_high": hi,
        "failed_planned": int((~np.isfinite(planned_a)).sum()),
        "failed_random": int((~np.isfinite(random_a)).sum()),
    }
