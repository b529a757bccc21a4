"""Your own cell: measurement files, identification on measured data and its validation report.

A measurement folder holds three files (:func:`write_cell` writes them, :func:`read_cell` reads
and checks them; every message names the file, and the row and column where there is one):

``cell.toml``
    ``robot``: the nominal robot, a file in the ``data/robots/*.toml`` form (a path ending in
    ``.toml``, relative to the folder), a URDF file (a path ending in ``.urdf``, read by
    :func:`calstudy.models.urdf.robot_from_urdf`; optional ``flange``: the name of its flange
    frame, default the last joint's frame) or the stem of one of the library's; ``[base]`` and
    ``[sensor]``: the nominal robot base in the part (tracker) frame and the sensor frame in the
    flange frame, ``xyz_mm = [x, y, z]`` and ``zyx_deg = [rz, ry, rx]`` (``R = Rz Ry Rx``);
    optional in ``[sensor]``: ``standoff_mm``, ``field_mm``, ``depth_mm``, the sensor's working
    distance and the half-widths of its field across and along the optical axis (the pose
    planning of :func:`calstudy.selfcal.planning.suggest_poses` plans for them);
    optional ``[noise]``: standard deviations per axis ``sensor_mm`` (fitted sphere centre),
    ``repeatability_mm`` and ``tracker_mm``. Without ``[noise]`` the covariance of the parameters
    comes from the residuals (the error of each view and the one shared by the views of a
    sphere), and the report says so.
``spheres.csv``
    One row per sphere placement: ``sphere`` (an integer id), ``x_<u>, y_<u>, z_<u>``: the
    tracker's (or CMM's) reading of its centre in the part frame.
``measurements.csv``
    One row per robot pose: ``pose`` (integer id), ``set`` (``calibration`` or ``validation``),
    ``sphere`` (an id of ``spheres.csv``), the joint angles ``q1_<a> ... q6_<a>`` and the fitted
    sphere centre in the sensor frame ``cx_<u>, cy_<u>, cz_<u>``.

Units are declared in the header: ``<u>`` is ``mm`` or ``m``, ``<a>`` is ``deg`` or ``rad``.
Lines starting with ``#`` are comments.

:func:`identify_measurements` identifies the 30 parameters from the calibration rows
(:func:`calstudy.selfcal.identify.identify`), flags outliers by a stated rejection rule
and refits without them; :func:`validation_report` compares the position errors of the held-out
rows before and after against a requirement.
"""

from __future__ import annotations

import itertools
import math
import re
import shutil
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from calstudy.core.errors import CalibrationError, CalibrationWarning
from calstudy.core.geometry import check_shape, matrix_to_euler_zyx
from calstudy.core.schema import load_model
from calstudy.core.stats import interval_level
from calstudy.core.userfile import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    check_ids,
    parse_number,
    read_csv_table,
    require_columns,
)
from calstudy.estimators.shared_error import SharedErrorFit, shared_error_fit
from calstudy.models.kinematics import Robot
from calstudy.models.robots import load_robot
from calstudy.models.urdf import robot_from_urdf
from calstudy.selfcal.cellfile import CellFile
from calstudy.selfcal.design import BaseParameters, base_parameters
from calstudy.selfcal.identify import (
    Identification,
    Measurements,
    identify,
    scaled_jacobian,
)
from calstudy.selfcal.model import (
    IS_LENGTH,
    N_PARAMS,
    PARAM_NAMES,
    GlobalModel,
    angle_wrap,
    default_model,
    parameters_from_robot,
)

CELL_FILE, SPHERES_FILE, MEASUREMENTS_FILE = "cell.toml", "spheres.csv", "measurements.csv"
SETS = ("calibration", "validation")
#: the rejection rule: a measurement is an outlier if ``|e|^2 / sigma^2`` exceeds the 99.9 %
#: quantile of chi-square with 3 degrees of freedom (``|e|`` above 4.03 sigma), with ``sigma``
#: per axis declared or estimated robustly (median of ``|e|^2`` over its chi-square(3) median)
CHI2_3_999 = 16.266
CHI2_3_MEDIAN = 2.366
#: lengths that all lie below this (mm) look like metres: the spread of the sphere placements,
#: the sensor centres (a scanner's stand-off)
METRES_SUSPECT_MM = 10.0
#: the robust scale is not taken below this (mm): the rounding of the files
MIN_SIGMA_MM = 1e-4
DEFAULT_REQUIREMENT_MM = 0.42
#: below this many identified directions (beyond the parameters you fix) the poses are refused:
#: a one-point sensor or one sphere costs 3 of the 30, a pose repeated or one joint moving far more
MIN_IDENTIFIED = 24
#: per-axis noise (mm) assumed for the rank at the start when none is declared: the smallest of a
#: tracker-and-scanner cell (a tracker's 10-15 um); the rank at the fit uses the residual scale
START_SIGMA_MM = 0.01
#: largest share of the calibration rows the rejection rule may set aside
MAX_OUTLIER_SHARE = 0.25
IDENTIFIED, FIXED_BY_YOU, NOT_IDENTIFIABLE = "identified", "fixed by you", "not identifiable"
#: the two bases of the covariance of :func:`identify_measurements`
DECLARED = "declared noise"
RESIDUAL = "residual variances (per view and per sphere)"


@dataclass
class MeasuredCell:
    """A cell's measurement folder, read and checked (lengths mm, angles rad).

    Attributes
    ----------
    robot : Robot
        The nominal robot.
    start : (30,) the nominal parameters (robot, base and sensor as declared): the LM start.
    calibration, validation : Measurements
        Rows of each set (``validation`` may be empty); ``sphere`` is an index into ``spheres``.
    spheres : (k, 3) tracker readings in the part frame, mm; ``sphere_ids`` their ids.
    pose_ids : dict of the ``pose`` ids of each set.
    part2base, sensor2flange : (4, 4) the nominal base placement and sensor mounting.
    sensor_geometry : dict or None
        The ``[sensor]`` keys ``standoff_mm``, ``field_mm``, ``depth_mm`` the file gives (for
        the pose planning); None if it gives none.
    noise : dict or None
        Declared standard deviations per axis (``sensor_mm``, ``repeatability_mm``,
        ``tracker_mm``); None if the file declares none.
    source : str
        Where the data came from (for the notebook's messages).
    """

    robot: Robot
    start: np.ndarray
    calibration: Measurements
    validation: Measurements
    spheres: np.ndarray
    sphere_ids: np.ndarray
    pose_ids: dict
    noise: dict | None
    source: str
    part2base: np.ndarray
    sensor2flange: np.ndarray
    sensor_geometry: dict | None = None


# ----------------------------------------------------------------------------------------------
# reading


def _unit_columns(path, header, stems, units: dict, what: str) -> tuple[list[str], float]:
    """Columns ``<stem>_<unit>`` for one unit of ``units``; the factor to mm or rad."""
    found = [u for u in units if all(f"{s}_{u}" in header for s in stems)]
    if len(found) != 1:
        wanted = ", ".join(f"{stems[0]}_{u}" for u in units)
        raise CalibrationError(
            f"{path}: the {what} need columns {', '.join(s + '_<unit>' for s in stems)} in "
            f"exactly one unit ({wanted}, ...); found {found or 'none'}"
        )
    return [f"{s}_{found[0]}" for s in stems], units[found[0]]


def _column(path, header, rows, name, parse=True):
    require_columns(path, header, [name])
    k = header.index(name)
    if not parse:
        return [(n, r[k].strip()) for n, r in rows]
    return np.array([parse_number(path, n, name, r[k].strip()) for n, r in rows])


def read_spheres(path) -> tuple[np.ndarray, np.ndarray]:
    """Sphere ids (k,) and tracker readings (k, 3) mm of ``spheres.csv``."""
    path = Path(path)
    header, rows = read_csv_table(path, "sphere table")
    ids = check_ids(path, _column(path, header, rows, "sphere"), [n for n, _ in rows], "sphere")
    cols, factor = _unit_columns(path, header, ["x", "y", "z"], LENGTH_UNITS, "sphere centres")
    xyz = np.column_stack([_column(path, header, rows, c) for c in cols]) * factor
    spread = float(np.ptp(xyz, axis=0).max()) if len(xyz) > 1 else math.inf
    if spread < METRES_SUSPECT_MM:
        raise CalibrationError(
            f"{path}: the {len(xyz)} sphere placements lie within {spread:.4g} mm of each other "
            f"(below {METRES_SUSPECT_MM:g} mm): metres in the {cols[0]} columns? Declare them "
            "x_m, y_m, z_m or write millimetres"
        )
    return ids, xyz


def read_measurements(path, sphere_ids) -> pd.DataFrame:
    """The rows of ``measurements.csv``: ``pose, set, sphere`` (index), ``q1..q6`` rad and
    ``cx, cy, cz`` mm, with the source line number in ``line``."""
    path = Path(path)
    header, rows = read_csv_table(path, "measurement table")
    lines = [n for n, _ in rows]
    poses = check_ids(path, _column(path, header, rows, "pose"), lines, "pose")
    sets = _column(path, header, rows, "set", parse=False)
    for n, s in sets:
        if s not in SETS:
            raise CalibrationError(f"{path}: row {n}, column 'set': {s!r} is not one of {SETS}")
    sphere = check_ids(path, _column(path, header, rows, "sphere"), lines, "sphere", unique=False)
    known = {int(s): i for i, s in enumerate(sphere_ids)}
    for (n, _), s in zip(rows, sphere, strict=True):
        if s not in known:
            raise CalibrationError(
                f"{path}: row {n}, column 'sphere': sphere {s} is not in {SPHERES_FILE}"
            )
    qcols, qf = _unit_columns(path, header, [f"q{i}" for i in range(1, 7)], ANGLE_UNITS, "joints")
    ccols, cf = _unit_columns(path, header, ["cx", "cy", "cz"], LENGTH_UNITS, "sensor centres")
    out = pd.DataFrame({"line": lines, "pose": poses, "set": [s for _, s in sets]})
    out["sphere"] = [known[int(s)] for s in sphere]
    joints = np.column_stack([_column(path, header, rows, c) for c in qcols])
    if qf != 1.0 and float(np.abs(joints).max()) <= math.pi:
        raise CalibrationError(
            f"{path}: every joint angle of the {len(rows)} poses lies within +-pi (largest "
            f"|value| {float(np.abs(joints).max()):.4g}) in columns {qcols[0]} ... {qcols[-1]}: "
            "radians? Declare them q1_rad ... q6_rad or write degrees"
        )
    for i in range(6):
        out[f"q{i + 1}"] = joints[:, i] * qf
    centres = np.column_stack([_column(path, header, rows, c) for c in ccols]) * cf
    reach = float(np.linalg.norm(centres, axis=1).max())
    if reach < METRES_SUSPECT_MM:
        raise CalibrationError(
            f"{path}: every sensor centre lies within {reach:.4g} mm of the sensor origin (below "
            f"{METRES_SUSPECT_MM:g} mm) in columns {', '.join(ccols)}: metres? Declare them "
            "cx_m, cy_m, cz_m or write millimetres"
        )
    for i, name in enumerate(("cx", "cy", "cz")):
        out[name] = centres[:, i]
    return out


def _robot_from(cell: CellFile, folder: Path, source) -> Robot:
    name = cell.robot
    if name.endswith(".urdf"):
        path = (folder / name).resolve()
        if not path.is_file():
            raise CalibrationError(f"{source}: robot file {path} does not exist")
        return robot_from_urdf(path, flange=cell.flange)
    if cell.flange is not None:
        raise CalibrationError(f"{source}: flange names a URDF frame; the robot is not a URDF")
    if name.endswith(".toml"):
        path = (folder / name).resolve()
        if not path.is_file():
            raise CalibrationError(f"{source}: robot file {path} does not exist")
        return load_robot(path)  # the cell's own table, read in place
    return load_robot(name)


def _measurements(rows: pd.DataFrame, noise: dict | None, readings: np.ndarray) -> Measurements:
    m = len(rows)
    cov = tracker = None
    if noise is not None:
        t2 = noise["tracker_mm"] ** 2
        own = noise["sensor_mm"] ** 2 + noise["repeatability_mm"] ** 2
        cov = np.tile((own + t2) * np.eye(3), (m, 1, 1))
        tracker = np.tile(t2 * np.eye(3), (m, 1, 1))
    sphere = rows["sphere"].to_numpy(int)
    return Measurements(
        rows[[f"q{i}" for i in range(1, 7)]].to_numpy(float).reshape(m, 6),
        rows[["cx", "cy", "cz"]].to_numpy(float).reshape(m, 3),
        readings[sphere].reshape(m, 3),
        sphere,
        cov=cov,
        tracker_cov=tracker,
    )


#: a 6-D pose reading stands for four points of the target frame: its origin and the points this
#: far (mm) along its x, y and z axes
POSE_ARM_MM = 100.0


def measurements_from_poses(
    Q, target2sensor, target2part, target, arm_mm: float = POSE_ARM_MM
) -> Measurements:
    """6-D pose readings (a camera on the flange seeing a target, a marker board or a tracker's
    6-D probe, whose pose in the part frame is known) as point measurements of the model.

    Each reading becomes four rows: the target's origin and the points ``arm_mm`` along its x,
    y and z axes, in the sensor frame (``C``) and in the part frame (``P_ref``). Four points of
    a rigid frame fix its position and orientation, so the identification sees the full pose:
    one target identifies all 30 parameters where one sphere leaves the base rotation about it
    free. Row ``4 i + k`` is point ``k`` of reading ``i``; its ``sphere`` is ``4 target + k``
    (the part-frame reading of a target point is shared by every view of that target).

    Parameters
    ----------
    Q : array_like, shape (m, 6)
        Joint angles, rad.
    target2sensor : array_like, shape (m, 4, 4)
        The target's pose in the sensor frame at each robot pose (what the camera reads), mm.
    target2part : array_like, shape (k, 4, 4)
        The pose of each target in the part frame (the tracker's reading), mm.
    target : array_like of int, shape (m,)
        Which target each reading saw.
    arm_mm : float
        Distance of the axis points from the target's origin; about the target's size.

    Returns
    -------
    Measurements
        ``4 m`` rows, noise not declared.

    Raises
    ------
    CalibrationError
        Shapes that disagree, a target index out of range, non-finite values or an
        ``arm_mm`` that is not positive.
    """
    Q = np.asarray(Q, float)
    t2s = np.asarray(target2sensor, float)
    t2p = np.asarray(target2part, float)
    target = np.asarray(target)
    m = len(Q)
    if Q.shape != (m, 6) or t2s.shape != (m, 4, 4) or target.shape != (m,):
        raise CalibrationError(
            f"pose readings: joint angles {Q.shape}, target poses {t2s.shape} and target "
            f"indices {target.shape} must be (m, 6), (m, 4, 4) and (m,) for one m"
        )
    if t2p.ndim != 3 or t2p.shape[1:] != (4, 4):
        raise CalibrationError(f"target poses in the part frame have shape {t2p.shape}")
    if m and (target.min() < 0 or target.max() >= len(t2p) or np.any(target != target // 1)):
        raise CalibrationError(
            f"target indices must be integers in 0..{len(t2p) - 1}; found {target.min()} to "
            f"{target.max()}"
        )
    if not (np.isfinite(Q).all() and np.isfinite(t2s).all() and np.isfinite(t2p).all()):
        raise CalibrationError("pose readings hold non-finite values")
    if not (math.isfinite(arm_mm) and arm_mm > 0):
        raise CalibrationError(f"arm_mm = {arm_mm} must be a positive length")
    target = target.astype(int)
    local = np.vstack([np.zeros(3), arm_mm * np.eye(3)])  # (4, 3) points of the target frame
    C = np.einsum("mij,kj->mki", t2s[:, :3, :3], local) + t2s[:, None, :3, 3]
    P = np.einsum("mij,kj->mki", t2p[target, :3, :3], local) + t2p[target][:, None, :3, 3]
    return Measurements(
        np.repeat(Q, 4, axis=0),
        C.reshape(4 * m, 3),
        P.reshape(4 * m, 3),
        (4 * target[:, None] + np.arange(4)).reshape(4 * m),
    )


def read_cell(folder) -> MeasuredCell:
    """Read and check a measurement folder (format in the module docstring).

    Parameters
    ----------
    folder : str or path-like
        The folder holding ``cell.toml``, ``spheres.csv`` and ``measurements.csv``.

    Returns
    -------
    MeasuredCell
        The nominal robot and start parameters, the rows of each set (mm, rad), the sphere
        readings, the declared noise and sensor geometry.

    Raises
    ------
    FileNotFoundError
        A missing file (``cell.toml``, ``spheres.csv``, ``measurements.csv``).
    CalibrationError
        A missing key or column, a unit not declared, a cell that is not a number (with
        its file, row and column), a repeated id, an unknown sphere or set, no calibration rows;
        a declared unit the values contradict (joint angles all within +-pi in degree columns,
        sphere placements within 10 mm of each other or sensor centres within 10 mm of the
        sensor in mm columns).
    """
    folder = Path(folder)
    cell_path = folder / CELL_FILE
    cell = load_model(cell_path, CellFile, "cell description")
    robot = _robot_from(cell, folder, cell_path)
    part2base = cell.base.transform
    sensor2flange = cell.sensor.transform
    start = parameters_from_robot(robot, part2base, sensor2flange)
    noise = None if cell.noise is None else cell.noise.model_dump()
    sphere_ids, readings = read_spheres(folder / SPHERES_FILE)
    rows = read_measurements(folder / MEASUREMENTS_FILE, sphere_ids)
    sets = {s: rows[rows["set"] == s] for s in SETS}
    if sets["calibration"].empty:
        raise CalibrationError(f"{folder / MEASUREMENTS_FILE}: no rows of set 'calibration'")
    return MeasuredCell(
        robot,
        start,
        _measurements(sets["calibration"], noise, readings),
        _measurements(sets["validation"], noise, readings),
        readings,
        sphere_ids,
        {s: sets[s]["pose"].to_numpy(int) for s in SETS},
        noise,
        str(folder),
        part2base,
        sensor2flange,
        cell.sensor.geometry,
    )


# ----------------------------------------------------------------------------------------------
# writing


def _fmt(x: float, decimals: int) -> str:
    return f"{x:.{decimals}f}"


def _toml_pose(name: str, transform, comment: str) -> str:
    t = np.asarray(transform, float)
    zyx = matrix_to_euler_zyx(t[:3, :3])
    xyz = ", ".join(f"{v:.3f}" for v in t[:3, 3])
    ang = ", ".join(f"{v:.4f}" for v in zyx)
    return f"[{name}]  # {comment}\nxyz_mm = [{xyz}]\nzyx_deg = [{ang}]\n"


def write_cell(
    folder,
    robot_file,
    part2base,
    sensor2flange,
    spheres_part,
    calibration: Measurements,
    validation: Measurements | None = None,
    noise: dict | None = None,
    joint_decimals: int = 4,
    length_decimals: int = 3,
) -> Path:
    """Write a measurement folder as a user would: ``cell.toml``, ``spheres.csv``,
    ``measurements.csv``, and a copy of ``robot_file`` (a ``data/robots`` form TOML).

    Joint angles in degrees rounded to ``joint_decimals`` (a controller's display), lengths in
    mm rounded to ``length_decimals`` (1 um). ``sphere`` of the measurements indexes
    ``spheres_part``; sphere ids are written from 1, pose ids from 1 in row order.

    Parameters
    ----------
    folder : str or path-like
        Where to write (created if missing).
    robot_file : str or path-like
        The nominal robot table, copied into the folder.
    part2base, sensor2flange : array_like, shape (4, 4)
        The nominal base placement in the part frame and sensor mounting, mm.
    spheres_part : array_like, shape (k, 3)
        The tracker readings of the spheres, mm.
    calibration, validation : Measurements
        The rows of each set (``validation`` optional).
    noise : dict, optional
        Standard deviations per axis (``sensor_mm``, ``repeatability_mm``, ``tracker_mm``);
        None writes no ``[noise]`` table.
    joint_decimals, length_decimals : int
        Decimals of the joint angles (deg) and lengths (mm).

    Returns
    -------
    pathlib.Path
        The folder.

    Raises
    ------
    OSError
        A folder that cannot be written or a robot file that cannot be read.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    robot_file = Path(robot_file)
    shutil.copyfile(robot_file, folder / robot_file.name)
    text = [
        "# calstudy selfcal: one cell (read by calstudy.selfcal.read_cell)",
        f'robot = "{robot_file.name}"  # nominal MDH table, data/robots/*.toml form',
        "",
        _toml_pose("base", part2base, "nominal robot base in the part (tracker) frame"),
        _toml_pose("sensor", sensor2flange, "nominal sensor frame in the flange frame"),
    ]
    if noise is None:
        text.append(
            "# no [noise] table (sensor_mm, repeatability_mm, tracker_mm): the covariance of the\n"
            "# parameters then comes from the residuals"
        )
    else:
        text.append("[noise]  # standard deviations per axis, mm")
        text += [f"{k} = {noise[k]:g}" for k in ("sensor_mm", "repeatability_mm", "tracker_mm")]
    (folder / CELL_FILE).write_text("\n".join(text) + "\n")
    lines = ["# tracker readings of the sphere centres, part frame", "sphere,x_mm,y_mm,z_mm"]
    for i, p in enumerate(np.asarray(spheres_part, float)):
        lines.append(f"{i + 1}," + ",".join(_fmt(v, length_decimals) for v in p))
    (folder / SPHERES_FILE).write_text("\n".join(lines) + "\n")
    header = "pose,set,sphere," + ",".join(f"q{i}_deg" for i in range(1, 7)) + ",cx_mm,cy_mm,cz_mm"
    lines = ["# one row per robot pose: joint angles and the fitted centre in the sensor frame"]
    lines.append(header)
    pose = 0
    for name, meas in (("calibration", calibration), ("validation", validation)):
        if meas is None:
            continue
        for q, c, s in zip(np.degrees(meas.Q), meas.C, meas.sphere, strict=True):
            pose += 1
            cells = [str(pose), name, str(int(s) + 1)]
            cells += [_fmt(v, joint_decimals) for v in q] + [_fmt(v, length_decimals) for v in c]
            lines.append(",".join(cells))
    (folder / MEASUREMENTS_FILE).write_text("\n".join(lines) + "\n")
    return folder


# ----------------------------------------------------------------------------------------------
# identification on measured data


@dataclass
class CellFit:
    """Identification of a measured cell (:func:`identify_measurements`).

    Attributes
    ----------
    fit : Identification
        The final fit (outliers excluded); ``fit.params`` the 30 parameters, those not in
        ``free`` at their start value.
    covariance : (30, 30) mm and rad; zero in the rows and columns of the fixed parameters: the
        covariance of the identified ones only (the subspace the poses fix).
    covariance_basis : str
        :data:`DECLARED` (maximum likelihood, covariance from the declared standard deviations)
        or :data:`RESIDUAL` (least squares; the error of each view and the error shared by the
        views of one sphere estimated from the residuals, :func:`shared_error_covariance`).
    sigma_mm : float
        Per-axis residual scale used by the rejection rule and the noise-aware rank.
    residuals : pandas.DataFrame
        One row per calibration measurement: ``pose``, ``sphere``, ``ex, ey, ez, error_mm`` at the
        final parameters, ``normalised`` (``|e|^2 / sigma^2``) and ``outlier``.
    condition_number : float
        Of the scaled identification Jacobian of the kept measurements in the free parameters.
    rounds : int
        Fits run (1 without outliers).
    free : (30,) bool
        The parameters identified; the others are fixed at the start (by you or because the
        poses do not identify them).
    identifiability : pandas.DataFrame
        Per parameter: ``name``, ``status`` (:data:`IDENTIFIED`, :data:`FIXED_BY_YOU` or
        :data:`NOT_IDENTIFIABLE`) and ``combination``: for a parameter fixed as not identifiable,
        the directions the poses do not fix in which it has a share (unit vectors in scaled
        units, :attr:`~calstudy.selfcal.design.BaseParameters.unidentified`).
    notes : list of str
        What the fit fixed and why, and any rank warning (also issued as a
        :class:`~calstudy.core.errors.CalibrationWarning`).
    residual_errors : SharedErrorFit or None
        None with declared noise (normal intervals, chi-square region); else the two variances
        estimated from the residuals, whose simulated quantiles
        (:meth:`~calstudy.estimators.shared_error.SharedErrorFit.interval_quantiles`,
        :meth:`~calstudy.estimators.shared_error.SharedErrorFit.region_quantile`) the intervals
        and the region use.
    """

    fit: Identification
    covariance: np.ndarray
    covariance_basis: str
    sigma_mm: float
    residuals: pd.DataFrame
    condition_number: float
    rounds: int
    free: np.ndarray
    identifiability: pd.DataFrame
    notes: list[str]
    residual_errors: SharedErrorFit | None

    @property
    def params(self) -> np.ndarray:
        """The identified parameters ``(30,)`` (:data:`PARAM_NAMES`), mm and rad."""
        return self.fit.params

    @property
    def outliers(self) -> np.ndarray:
        """Which measurement rows ``(n,)`` the outlier loop set aside (the ``outlier`` column of
        :attr:`residuals`)."""
        return self.residuals["outlier"].to_numpy(bool)

    @property
    def n_identified(self) -> int:
        """Parameters identified (the rank of the kept poses at the fit)."""
        return int(self.free.sum())

    def half_widths(self, level: float = 0.95) -> np.ndarray:
        """Half-widths of the ``level`` intervals of the parameters: the standard deviation
        times the normal quantile (declared noise) or the simulated quantile of the studentised
        error (:attr:`residual_errors`).

        Parameters
        ----------
        level : float, default 0.95
            Coverage of each interval, in (0, 1).

        Returns
        -------
        ndarray, shape (30,)
            Half-widths in the parameters' units (mm and rad); NaN for the fixed parameters.

        Raises
        ------
        CalibrationError
            If ``level`` is not a number in (0, 1).
        """
        level = interval_level(level)
        std = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        quantile = np.full(N_PARAMS, stats.norm.ppf(0.5 + level / 2))
        if self.residual_errors is not None:
            quantile[self.free] = self.residual_errors.interval_quantiles(level)
        return np.where(self.free, quantile * std, np.nan)

    def region_limit(self, level: float = 0.95) -> float:
        """The bound of ``d^T C^-1 d`` (``d`` the identified parameters' error, ``C`` their
        covariance) of the joint ``level`` region.

        Parameters
        ----------
        level : float, default 0.95
            Coverage of the region, in (0, 1).

        Returns
        -------
        float
            The chi-square quantile with as many degrees of freedom as parameters identified
            (declared noise), else the simulated quantile (:attr:`residual_errors`).

        Raises
        ------
        CalibrationError
            If ``level`` is not a number in (0, 1).
        """
        level = interval_level(level)
        if self.residual_errors is None:
            return float(stats.chi2.ppf(level, self.n_identified))
        return self.residual_errors.region_quantile(level)

    def in_region(self, params, level: float = 0.95) -> bool:
        """Whether a parameter vector lies within the joint ``level`` region of the identified
        parameters (:meth:`region_limit`).

        Parameters
        ----------
        params : array_like, shape (30,)
            Parameters to test (:data:`PARAM_NAMES`), mm and rad; angles are compared modulo a
            turn and the fixed parameters are not compared.
        level : float, default 0.95
            Coverage of the region, in (0, 1).

        Returns
        -------
        bool
            True when ``d^T C^-1 d`` is within :meth:`region_limit`.

        Raises
        ------
        CalibrationError
            If ``params`` is not one finite value per parameter, or ``level`` is not a number
            in (0, 1).
        """
        p = check_shape("params", params, self.params.shape)
        d = angle_wrap(p - self.params)[self.free]
        c = self.covariance[np.ix_(self.free, self.free)]
        return bool(d @ np.linalg.solve(c, d) <= self.region_limit(level))


def subset(meas: Measurements, keep) -> Measurements:
    """The measurements ``keep`` (boolean mask or indices) of ``meas``."""

    def pick(a):
        return None if a is None else a[keep]

    return replace(
        meas,
        Q=meas.Q[keep],
        C=meas.C[keep],
        P_ref=meas.P_ref[keep],
        sphere=meas.sphere[keep],
        C_true=pick(meas.C_true),
        cov=pick(meas.cov),
        tracker_cov=pick(meas.tracker_cov),
        Q_true=pick(meas.Q_true),
    )


def _declared_sigma(noise: dict) -> float:
    s2 = noise["sensor_mm"] ** 2 + noise["repeatability_mm"] ** 2 + noise["tracker_mm"] ** 2
    return max(math.sqrt(s2), MIN_SIGMA_MM)


def _scale(err2: np.ndarray, noise: dict | None) -> float:
    if noise is not None:
        return _declared_sigma(noise)
    return max(math.sqrt(float(np.median(err2)) / CHI2_3_MEDIAN), MIN_SIGMA_MM)


def fixed_mask(fixed) -> np.ndarray:
    """Boolean mask (30,) of the parameters named in ``fixed`` (names of :data:`PARAM_NAMES`).

    Raises
    ------
    CalibrationError
        A name that is not one of the 30 parameters.
    """
    mask = np.zeros(N_PARAMS, bool)
    for name in [] if fixed is None else list(fixed):
        if name not in PARAM_NAMES:
            raise CalibrationError(
                f"fixed parameter {name!r} is not one of the model's: {', '.join(PARAM_NAMES)}"
            )
        mask[PARAM_NAMES.index(name)] = True
    return mask


def _identifiable(meas, params, candidates, sigma, model) -> tuple[np.ndarray, BaseParameters]:
    """Parameters the poses identify (30,) among the ``candidates`` (30,) and the base
    parameters of the candidate columns (noise-aware rank with ``sigma``)."""
    _, jac = model.points_and_jacobian(params, meas.Q, meas.C)
    cols = np.flatnonzero(candidates)
    names = [PARAM_NAMES[i] for i in cols]
    base = base_parameters(jac[:, cols], names, IS_LENGTH[cols], sigma_mm=sigma)
    pivots = base.table["pivot"].to_numpy(int)
    free = np.zeros(N_PARAMS, bool)
    free[cols[pivots <= base.rank]] = True
    return free, base


def _identifiability_table(free, user_fixed, base: BaseParameters) -> pd.DataFrame:
    status = np.where(user_fixed, FIXED_BY_YOU, np.where(free, IDENTIFIED, NOT_IDENTIFIABLE))
    combination = [
        "; ".join(c for c in base.unidentified if re.search(rf"\b{n}\b", c))
        if st == NOT_IDENTIFIABLE
        else ""
        for n, st in zip(PARAM_NAMES, status, strict=True)
    ]
    return pd.DataFrame({"name": PARAM_NAMES, "status": status, "combination": combination})


def _not_identified_note(table: pd.DataFrame, base: BaseParameters, where: str) -> str:
    fixed = table.loc[table["status"] == NOT_IDENTIFIABLE, "name"]
    return (
        f"{where}: the poses identify {int((table['status'] == IDENTIFIED).sum())} parameters; "
        f"{', '.join(fixed)} fixed at the nominal value as not identifiable; the directions the "
        f"poses do not fix (scaled units, angles as mm at 1 m): {' | '.join(base.unidentified)}"
    )


#: link twists of the model's DH links 3 and 4 (axes 3-4 and 4-5) by index in PARAM_NAMES
_DH_TWISTS = {(3, 4): PARAM_NAMES.index("alpha3"), (4, 5): PARAM_NAMES.index("alpha4")}
#: sine of a nominal twist below which two axes count as parallel
PARALLEL_SIN = 1e-6


def parallel_axes_note(start) -> str:
    """A sentence on nominally parallel axes beyond the pair 2-3 (which Hayati's ``beta2``
    models), or "" if there are none: the DH link between them cannot separate the offsets
    along the two axes, so one of them is fixed (:func:`identify_measurements` does so)."""
    pairs = [
        f"{i} and {j}"
        for (i, j), k in _DH_TWISTS.items()
        if abs(math.sin(float(np.asarray(start)[k]))) < PARALLEL_SIN
    ]
    if not pairs:
        return ""
    return (
        f"axes {' and '.join(pairs)} of the nominal robot are parallel: the model's DH link "
        "there (Hayati's beta is only on link 2) fixes only the sum of the offsets d along the "
        "parallel axes and not their tilt about y, so one offset is held at its nominal value"
    )


def _check_rank(n_user_free: int, free: np.ndarray, table: pd.DataFrame, where: str) -> None:
    lost = n_user_free - int(free.sum())
    if lost > N_PARAMS - MIN_IDENTIFIED:
        raise CalibrationError(
            f"{where}: the poses identify {int(free.sum())} of the {n_user_free} parameters "
            f"({lost} directions lost, more than the {N_PARAMS - MIN_IDENTIFIED} that a sensor "
            "seen as one point or one sphere costs): poses repeated, one joint moving or "
            "spheres too few? Not identifiable: "
            + ", ".join(table.loc[table["status"] == NOT_IDENTIFIABLE, "name"])
        )


def _outlier_round(norm: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The next kept set: the worst kept measurement set aside if beyond the threshold."""
    new = keep.copy()
    worst = int(np.argmax(np.where(keep, norm, -np.inf)))
    if norm[worst] > CHI2_3_999:
        new[worst] = False
    return new


def identify_measurements(
    meas: Measurements,
    start,
    noise: dict | None = None,
    reject: bool = True,
    max_rounds: int | None = None,
    pose_ids=None,
    model: GlobalModel | None = None,
    fixed=None,
    check_columns: bool = True,
) -> CellFit:
    """Identify the parameters from measured data, flag outliers and refit without them.

    Identifiable parameters: at the start (nominal parameters, all rows) and again at the fit
    (kept rows, with the residual scale), the column-pivoted QR of the scaled Jacobian with a
    noise-aware rank (:func:`calstudy.selfcal.design.base_parameters`: a direction fixed
    with a standard deviation above :data:`~calstudy.selfcal.design.STD_LIMIT_MM` is not
    identified; at the start without declared noise :data:`START_SIGMA_MM` is assumed) gives the
    parameters
    the poses identify; the others stay at their nominal value, named with the combinations
    they enter, and a :class:`~calstudy.core.errors.CalibrationWarning` says so (two parallel
    axes beyond the pair 2-3, a one-point sensor, one sphere). The covariance is that of the
    identified parameters only.

    Outliers: after each fit the kept measurement with the largest ``|e|^2 / sigma^2`` is set
    aside if that exceeds :data:`CHI2_3_999` (chi-square, 3 degrees of freedom, 99.9 %),
    ``sigma`` the declared per-axis noise or the robust scale of the kept residuals, and the fit
    repeated (warm start), one measurement at a time, so that a few gross errors that spoil the
    first fit do not push good measurements over the threshold; at the end a measurement set
    aside whose residual is within the threshold at the final fit is taken back (one refit).
    With ``noise`` the fit is maximum likelihood and the covariance follows from the declared
    noise (normal intervals, chi-square region); without, least squares and the covariance from
    the residuals, with the tracker error shared by the views of one sphere
    (:func:`shared_error_covariance`, REML), and intervals and region from the simulated
    quantiles of the errors studentised by those two estimated variances
    (:attr:`CellFit.residual_errors`, :meth:`CellFit.half_widths`, :meth:`CellFit.region_limit`).

    Parameters
    ----------
    meas : Measurements
        The calibration rows.
    start : array_like, shape (30,)
        Nominal parameters (mm, rad): the LM start and the value of every fixed parameter.
    noise : dict, optional
        Declared standard deviations per axis (``sensor_mm``, ``repeatability_mm``,
        ``tracker_mm``).
    reject : bool
        Apply the rejection rule.
    max_rounds : int, optional
        Fits allowed for the rejection; default ``len(meas) // 4 + 2``.
    pose_ids : array_like, optional
        Ids of the rows for the residual table (default 1..m).
    model : GlobalModel, optional
        The model (default the shared one).
    fixed : sequence of str, optional
        Parameters to hold at ``start`` (names of :data:`PARAM_NAMES`), e.g. lengths you know
        from a measurement of the arm.
    check_columns : bool
        Refuse sensor-frame columns that fit much better swapped or negated
        (:func:`check_sensor_columns`).

    Raises
    ------
    CalibrationError
        An unknown fixed parameter; columns that look swapped or negated; poses that identify
        fewer than :data:`MIN_IDENTIFIED` directions beyond those you fixed (a pose repeated,
        one joint moving); more than :data:`MAX_OUTLIER_SHARE` of the rows beyond the rejection
        threshold (declared noise too small, or a model that does not fit); LM not converged.

    Returns
    -------
    CellFit
        The fit, its covariance, residuals with the outliers flagged, identifiability and
        notes.
    """
    model = default_model() if model is None else model
    start = np.asarray(start, float)
    user_fixed = fixed_mask(fixed)
    n_user_free = int((~user_fixed).sum())
    weighted = noise is not None and meas.cov is not None
    declared = _declared_sigma(noise) if noise is not None else None
    if check_columns:
        check_sensor_columns(meas, start, model)
    notes: list[str] = []
    start_sigma = START_SIGMA_MM if declared is None else declared
    free, base = _identifiable(meas, start, ~user_fixed, start_sigma, model)
    table = _identifiability_table(free, user_fixed, base)
    _check_rank(n_user_free, free, table, "at the start")
    if free.sum() < n_user_free:
        notes.append(_not_identified_note(table, base, "at the start"))
    if parallel_axes_note(start):
        notes.append(parallel_axes_note(start))
    rounds_allowed = len(meas) // 4 + 2 if max_rounds is None else int(max_rounds)
    keep = np.ones(len(meas), bool)
    params = start.copy()
    rounds = 0
    while True:
        rounds += 1
        fit = identify(subset(meas, keep), params, weighted=weighted, free=free, model=model)
        params = fit.params
        e = model.points(params, meas.Q, meas.C) - meas.P_ref
        err2 = np.einsum("ij,ij->i", e, e)
        sigma = _scale(err2[keep], noise)
        norm = err2 / sigma**2
        if not reject:
            break
        new = _outlier_round(norm, keep)
        if (~new).sum() > MAX_OUTLIER_SHARE * len(meas):
            raise CalibrationError(
                f"{int((norm > CHI2_3_999).sum())} of {len(meas)} calibration rows lie beyond "
                f"the rejection threshold ({int((~keep).sum())} set aside already, median "
                f"|e|^2 / sigma^2 {float(np.median(norm)):.3g} with sigma {sigma:.4g} mm): "
                "the declared noise is too small, or the model does not fit these data "
                "(columns, units, robot file)"
            )
        if np.array_equal(new, keep):
            back = ~keep & (norm <= CHI2_3_999)
            if not back.any():
                break
            new = keep | back
        if rounds >= rounds_allowed:
            notes.append(
                f"outlier rule stopped after {rounds} fits (max_rounds) with "
                f"{int((norm[keep] > CHI2_3_999).sum())} kept rows beyond the threshold"
            )
            break
        keep = new
    kept = subset(meas, keep)
    at_fit, _ = _identifiable(kept, params, free, sigma, model)
    if (free & ~at_fit).any():
        lost = free & ~at_fit
        free = at_fit
        params[lost] = start[lost]
        fit = identify(kept, params, weighted=weighted, free=free, model=model)
        params = fit.params
        rounds += 1
        e = model.points(params, meas.Q, meas.C) - meas.P_ref
        err2 = np.einsum("ij,ij->i", e, e)
        sigma = _scale(err2[keep], noise)
        _, base = _identifiable(kept, params, ~user_fixed, sigma, model)
        table = _identifiability_table(free, user_fixed, base)
        _check_rank(n_user_free, free, table, "at the fit")
        notes.append(_not_identified_note(table, base, "at the fit (noise-aware rank)"))
    if notes:
        warnings.warn("; ".join(notes), CalibrationWarning, stacklevel=2)
    ids = np.arange(1, len(meas) + 1) if pose_ids is None else np.asarray(pose_ids)
    residuals = pd.DataFrame({"pose": ids, "sphere": meas.sphere})
    residuals[["ex_mm", "ey_mm", "ez_mm"]] = e
    residuals["error_mm"] = np.sqrt(err2)
    residuals["normalised"] = err2 / sigma**2
    residuals["outlier"] = ~keep
    _, jac = model.points_and_jacobian(params, kept.Q, kept.C)
    s = np.linalg.svd(scaled_jacobian(jac)[:, free], compute_uv=False)
    cov = np.zeros((N_PARAMS, N_PARAMS))
    if weighted:
        cov[np.ix_(free, free)] = fit.estimate.covariance
        basis = DECLARED
        shared = None
    else:
        r = e[keep].ravel()  # the residuals of the kept rows at the fit
        shared = shared_error_covariance(jac[:, free], r, kept.sphere)
        cov[np.ix_(free, free)] = shared.covariance
        basis = RESIDUAL
    return CellFit(
        fit,
        cov,
        basis,
        sigma,
        residuals,
        float(s[0] / s[-1]),
        rounds,
        free,
        table,
        notes,
        shared,
    )


def shared_error_covariance(jac: np.ndarray, residuals: np.ndarray, sphere) -> SharedErrorFit:
    """Covariance of least-squares parameters when each view has its own error and all views of
    a sphere share the error of its one tracker reading, both variances estimated from the
    residuals.

    The residual covariance is modelled as ``s_e^2 I + s_t^2 S`` (``S`` joins the same axis of two
    views of the same sphere); :func:`calstudy.estimators.shared_error.shared_error_fit` estimates
    the two variances by REML and gives the sandwich ``(J^T J)^-1 J^T V J (J^T J)^-1``: unlike
    ``s^2 (J^T J)^-1`` it does not treat the views of one sphere as independent. With a few
    spheres the shared variance is uncertain; the quantiles of the fit carry that uncertainty.

    Parameters
    ----------
    jac : (3 m, p) Jacobian of the residuals in the identified parameters (mm per mm or rad).
    residuals : (3 m,) residuals at the solution, mm.
    sphere : (m,) sphere of each view.

    Returns
    -------
    SharedErrorFit
        ``covariance`` (p, p) in mm and rad, the two variances (mm^2) and the quantiles of
        intervals (:meth:`~calstudy.estimators.shared_error.SharedErrorFit.interval_quantiles`)
        and of the joint region
        (:meth:`~calstudy.estimators.shared_error.SharedErrorFit.region_quantile`).

    Raises
    ------
    CalibrationError
        No residual degrees of freedom (``3 m <= p``), shapes that disagree.
    """
    sphere = np.asarray(sphere)
    groups = (3 * sphere[:, None] + np.arange(3)).ravel()  # one tracker error per sphere and axis
    return shared_error_fit(jac, residuals, groups)


def _shifted_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS distance of the points ``b`` (m, 3) to ``a`` after the best shift."""
    d = a - b
    return float(np.sqrt(np.mean(np.sum((d - d.mean(axis=0)) ** 2, axis=1))))


def _column_variant(perm, signs) -> str:
    axes = ("cx", "cy", "cz")
    return ", ".join(
        f"{'-' if sg < 0 else ''}{axes[p]} as {axes[i]}"
        for i, (p, sg) in enumerate(zip(perm, signs, strict=True))
        if p != i or sg < 0
    )


def check_sensor_columns(meas: Measurements, start, model: GlobalModel | None = None) -> None:
    """Refuse sensor-frame columns that the nominal cell explains much better swapped or negated.

    The centres the nominal model predicts in the sensor frame, ``inv(sensor2part(q)) P_ref``,
    are compared with the measured ``cx, cy, cz`` and with each of their 47 other orders and
    signs (RMS after the best shift: the nominal mounting is known to degrees, not to a quarter
    turn). If another variant comes closer than the columns as written, both are identified
    and their median residuals compared: the variant's below a third of the written one, the
    columns are refused with the likely cause.

    Raises
    ------
    CalibrationError
        Naming the variant (e.g. ``cy as cx, cx as cy``) and both median residuals (mm).
    """
    model = default_model() if model is None else model
    predicted = model.sensor_centres(start, meas.Q, meas.P_ref)
    best = None
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            if perm == (0, 1, 2) and signs == (1.0, 1.0, 1.0):
                continue
            rms = _shifted_rms(predicted, meas.C[:, perm] * signs)
            if best is None or rms < best[0]:
                best = (rms, perm, signs)
    written = _shifted_rms(predicted, meas.C)
    if best is None or best[0] >= written:
        return
    _, perm, signs = best
    fits = {}
    for key, C in (("written", meas.C), ("variant", meas.C[:, perm] * np.array(signs))):
        try:
            p = identify(replace(meas, C=C, cov=None), start, model=model).params
        except CalibrationError:
            fits[key] = math.inf
            continue
        err = np.linalg.norm(model.points(p, meas.Q, C) - meas.P_ref, axis=1)
        fits[key] = float(np.median(err))
    if fits["variant"] < fits["written"] / 3.0:
        raise CalibrationError(
            f"the sensor-frame columns cx, cy, cz look swapped or negated: read with "
            f"{_column_variant(perm, signs)} the identification leaves a median residual of "
            f"{fits['variant']:.4g} mm, as written {fits['written']:.4g} mm; check the order of "
            "the columns and the direction of the sensor's axes (a left-handed sensor frame?), "
            "or the nominal sensor mounting in cell.toml (a quarter or half turn off?)"
        )


def parameter_report(cell_fit: CellFit, start) -> pd.DataFrame:
    """Per parameter: nominal, identified, change, standard deviation and the half-width of the
    95 % interval (mm or deg, :meth:`CellFit.half_widths`), with the ``status`` of
    :attr:`CellFit.identifiability` and the ``combination`` a parameter fixed as not identifiable
    enters; the standard deviation and half-width of a fixed parameter are NaN (not zero).

    Parameters
    ----------
    cell_fit : CellFit
        The identification (:func:`identify_measurements`).
    start : array_like, shape (30,)
        The nominal parameters, mm and rad.

    Returns
    -------
    pandas.DataFrame
        30 rows: ``name``, ``unit``, ``nominal``, ``identified``, ``change``, ``std``,
        ``half_width_95``, ``status``, ``combination``.

    Raises
    ------
    CalibrationError
        A ``start`` that is not 30 numbers.
    """
    start = np.asarray(start, float)
    if start.shape != (N_PARAMS,):
        raise CalibrationError(f"start has shape {start.shape}; the 30 parameters are needed")
    p = cell_fit.params
    std = np.sqrt(np.clip(np.diag(cell_fit.covariance), 0.0, None))
    std = np.where(cell_fit.free, std, np.nan)
    conv = np.where(IS_LENGTH, 1.0, 180.0 / math.pi)
    return pd.DataFrame(
        {
            "name": PARAM_NAMES,
            "unit": np.where(IS_LENGTH, "mm", "deg"),
            "nominal": start * conv,
            "identified": p * conv,
            "change": angle_wrap(p - start) * conv,
            "std": std * conv,
            "half_width_95": cell_fit.half_widths(0.95) * conv,
            "status": cell_fit.identifiability["status"].to_numpy(),
            "combination": cell_fit.identifiability["combination"].to_numpy(),
        }
    )


# ----------------------------------------------------------------------------------------------
# validation on held-out measurements


def validation_report(
    meas: Measurements,
    before,
    after,
    requirement_mm: float = DEFAULT_REQUIREMENT_MM,
    model: GlobalModel | None = None,
) -> tuple[pd.DataFrame, dict]:
    """Position errors ``|P_i - P_i^n|`` of held-out measurements before and after calibration.

    Parameters
    ----------
    meas : Measurements
        The held-out rows.
    before, after : array_like, shape (30,)
        The parameters before (nominal) and after calibration, mm and rad.
    requirement_mm : float
        The accuracy required of every held-out row, mm.
    model : GlobalModel, optional
        The model (default the shared one).

    Returns
    -------
    table : pandas.DataFrame
        Per row: ``sphere``, ``before_mm``, ``after_mm``, ``within``.
    summary : dict
        Count, mean, RMS and largest error before and after, the requirement and
        ``meets_requirement`` (the largest error after calibration within it).

    Raises
    ------
    CalibrationError
        No rows, or a requirement that is not a positive finite number.
    """
    if len(meas) == 0:
        raise CalibrationError("no validation measurements: mark some rows set = validation")
    if not (math.isfinite(requirement_mm) and requirement_mm > 0):
        raise CalibrationError(f"the requirement {requirement_mm} mm must be a positive number")
    model = default_model() if model is None else model
    errs = {
        k: np.linalg.norm(model.points(p, meas.Q, meas.C) - meas.P_ref, axis=1)
        for k, p in (("before", before), ("after", after))
    }
    table = pd.DataFrame(
        {
            "sphere": meas.sphere,
            "before_mm": errs["before"],
            "after_mm": errs["after"],
            "within": errs["after"] <= requirement_mm,
        }
    )
    summary = {"n": len(meas), "requirement_mm": requirement_mm}
    for k, e in errs.items():
        summary |= {
            f"{k}_mean_mm": float(e.mean()),
            f"{k}_rms_mm": float(np.sqrt(np.mean(e**2))),
            f"{k}_max_mm": float(e.max()),
        }
    summary["meets_requirement"] = bool(summary["after_max_mm"] <= requirement_mm)
    return table, summary
