"""Your own cell: measurement files, identification on measured data and its validation report.

A measurement folder holds three files (:func:`write_cell` writes them, :func:`read_cell` reads
and checks them; every message names the file, and the row and column where there is one):

``cell.toml``
    ``robot``: the nominal robot, a file in the ``data/robots/*.toml`` form (a path ending in
    ``.toml``, relative to the folder) or the stem of one of the library's; ``[base]`` and
    ``[sensor]``: the nominal robot base in the part (tracker) frame and the sensor frame in the
    flange frame, ``xyz_mm = [x, y, z]`` and ``zyx_deg = [rz, ry, rx]`` (``R = Rz Ry Rx``);
    optional ``[noise]``: standard deviations per axis ``sensor_mm`` (fitted sphere centre),
    ``repeatability_mm`` and ``tracker_mm``. Without ``[noise]`` the covariance of the parameters
    is scaled by the residual chi-square, and the report says so.
``spheres.csv``
    One row per sphere placement: ``sphere`` (an integer id), ``x_<u>, y_<u>, z_<u>``: the
    tracker's (or CMM's) reading of its centre in the part frame.
``measurements.csv``
    One row per robot pose: ``pose`` (integer id), ``set`` (``calibration`` or ``validation``),
    ``sphere`` (an id of ``spheres.csv``), the joint angles ``q1_<a> ... q6_<a>`` and the fitted
    sphere centre in the sensor frame ``cx_<u>, cy_<u>, cz_<u>``.

Units are declared in the header: ``<u>`` is ``mm`` or ``m``, ``<a>`` is ``deg`` or ``rad``.
Lines starting with ``#`` are comments.

:func:`identify_cell` identifies the 30 parameters from the calibration rows
(:func:`calstudy.papers.selfcal.identify.identify`), flags outliers by a stated rejection rule
and refits without them; :func:`validation_report` compares the position errors of the held-out
rows before and after against a requirement.
"""

from __future__ import annotations

import csv
import math
import shutil
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.core.config import check_ids, parse_number, require
from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import euler_zyx_to_matrix, make_transform, matrix_to_euler_zyx
from calstudy.core.schema import check_toml
from calstudy.models.kinematics import Robot
from calstudy.models.robots import load_robot
from calstudy.papers.selfcal.identify import Identification, Measurements, identify
from calstudy.papers.selfcal.model import (
    IS_LENGTH,
    N_PARAMS,
    PARAM_NAMES,
    GlobalModel,
    angle_wrap,
    default_model,
    parameters_from_robot,
)
from calstudy.papers.selfcal.schema import CellFile

CELL_FILE, SPHERES_FILE, MEASUREMENTS_FILE = "cell.toml", "spheres.csv", "measurements.csv"
LENGTH_UNITS = {"mm": 1.0, "m": 1000.0}
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}
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


# ----------------------------------------------------------------------------------------------
# reading


def _csv_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and (line number, cells) of the data rows; comments and blank lines skipped."""
    if not path.is_file():
        raise CalibrationError(f"{path}: no such file")
    with open(path, newline="") as handle:
        numbered = [(i + 1, ln) for i, ln in enumerate(handle) if not ln.lstrip().startswith("#")]
    rows = [
        (n, r) for (n, _), r in zip(numbered, csv.reader(ln for _, ln in numbered), strict=True)
    ]
    rows = [(n, r) for n, r in rows if any(c.strip() for c in r)]
    if not rows:
        raise CalibrationError(f"{path}: the file is empty")
    header = [h.strip() for h in rows[0][1]]
    if not rows[1:]:
        raise CalibrationError(f"{path}: no data rows")
    for n, r in rows[1:]:
        if len(r) != len(header):
            raise CalibrationError(
                f"{path}: row {n} has {len(r)} cells; the header has {len(header)}"
            )
    return header, rows[1:]


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
    if name not in header:
        raise CalibrationError(f"{path}: missing column {name!r}")
    k = header.index(name)
    if not parse:
        return [(n, r[k].strip()) for n, r in rows]
    return np.array([parse_number(path, n, name, r[k].strip()) for n, r in rows])


def _ids(path, header, rows, name) -> np.ndarray:
    values = _column(path, header, rows, name)
    bad = np.flatnonzero(values != np.round(values))
    if bad.size:
        raise CalibrationError(
            f"{path}: row {rows[bad[0]][0]}, column {name!r}: {values[bad[0]]} is not an integer"
        )
    return values.astype(int)


def read_spheres(path) -> tuple[np.ndarray, np.ndarray]:
    """Sphere ids (k,) and tracker readings (k, 3) mm of ``spheres.csv``."""
    path = Path(path)
    header, rows = _csv_rows(path)
    ids = _ids(path, header, rows, "sphere")
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        raise CalibrationError(f"{path}: sphere {int(uniq[counts > 1][0])} appears more than once")
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
    header, rows = _csv_rows(path)
    poses = _ids(path, header, rows, "pose")
    check_ids(path, poses.astype(float))
    sets = _column(path, header, rows, "set", parse=False)
    for n, s in sets:
        if s not in SETS:
            raise CalibrationError(f"{path}: row {n}, column 'set': {s!r} is not one of {SETS}")
    sphere = _ids(path, header, rows, "sphere")
    known = {int(s): i for i, s in enumerate(sphere_ids)}
    for (n, _), s in zip(rows, sphere, strict=True):
        if s not in known:
            raise CalibrationError(
                f"{path}: row {n}, column 'sphere': sphere {s} is not in {SPHERES_FILE}"
            )
    qcols, qf = _unit_columns(path, header, [f"q{i}" for i in range(1, 7)], ANGLE_UNITS, "joints")
    ccols, cf = _unit_columns(path, header, ["cx", "cy", "cz"], LENGTH_UNITS, "sensor centres")
    out = pd.DataFrame({"line": [n for n, _ in rows], "pose": poses, "set": [s for _, s in sets]})
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


def _pose_from(table: dict, key: str, source) -> np.ndarray:
    xyz = np.asarray(require(table, f"{key}.xyz_mm", source), float)
    zyx = np.asarray(require(table, f"{key}.zyx_deg", source), float)
    if xyz.shape != (3,) or zyx.shape != (3,) or not np.all(np.isfinite([*xyz, *zyx])):
        raise CalibrationError(f"{source}: [{key}] xyz_mm and zyx_deg need 3 finite numbers each")
    return make_transform(euler_zyx_to_matrix(*zyx), xyz)


def _robot_from(table: dict, folder: Path, source) -> Robot:
    name = str(require(table, "robot", source))
    if name.endswith(".toml"):
        path = (folder / name).resolve()
        if not path.is_file():
            raise CalibrationError(f"{source}: robot file {path} does not exist")
        return load_robot(path)  # the cell's own table, read in place
    return load_robot(name)


def _noise(table: dict, source) -> dict | None:
    noise = table.get("noise")
    if noise is None:
        return None
    out = {}
    for key in ("sensor_mm", "repeatability_mm", "tracker_mm"):
        value = float(require(table, f"noise.{key}", source))
        if not math.isfinite(value) or value < 0:
            raise CalibrationError(f"{source}: [noise] {key} = {value} must be >= 0 and finite")
        out[key] = value
    return out


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


def read_cell(folder) -> MeasuredCell:
    """Read and check a measurement folder (format in the module docstring).

    Raises
    ------
    CalibrationError
        A missing file, key or column, a unit not declared, a cell that is not a number (with
        its file, row and column), a repeated id, an unknown sphere or set, no calibration rows;
        a declared unit the values contradict (joint angles all within +-pi in degree columns,
        sphere placements within 10 mm of each other or sensor centres within 10 mm of the
        sensor in mm columns).
    """
    folder = Path(folder)
    cell_path = folder / CELL_FILE
    if not cell_path.is_file():
        raise CalibrationError(f"{cell_path}: no such file (the cell description)")
    table = check_toml(cell_path, CellFile, "cell description")
    robot = _robot_from(table, folder, cell_path)
    part2base = _pose_from(table, "base", cell_path)
    sensor2flange = _pose_from(table, "sensor", cell_path)
    start = parameters_from_robot(robot, part2base, sensor2flange)
    noise = _noise(table, cell_path)
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
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    robot_file = Path(robot_file)
    shutil.copyfile(robot_file, folder / robot_file.name)
    text = [
        "# calstudy selfcal: one cell (read by calstudy.papers.selfcal.measured.read_cell)",
        f'robot = "{robot_file.name}"  # nominal MDH table, data/robots/*.toml form',
        "",
        _toml_pose("base", part2base, "nominal robot base in the part (tracker) frame"),
        _toml_pose("sensor", sensor2flange, "nominal sensor frame in the flange frame"),
    ]
    if noise is None:
        text.append(
            "# no [noise] table (sensor_mm, repeatability_mm, tracker_mm): the covariance of the\n"
            "# parameters is then scaled by the residual chi-square"
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
    """Identification of a measured cell (:func:`identify_cell`).

    Attributes
    ----------
    fit : Identification
        The final fit (outliers excluded); ``fit.params`` the 30 parameters.
    covariance : (30, 30) mm and rad.
    covariance_basis : str
        ``"declared noise"`` (maximum likelihood, covariance from the declared standard
        deviations) or ``"residual chi-square"`` (least squares, ``s^2 (J^T J)^-1`` with ``s^2``
        the residual sum of squares over its degrees of freedom).
    sigma_mm : float
        Per-axis residual scale used by the rejection rule.
    residuals : pandas.DataFrame
        One row per calibration measurement: ``pose``, ``sphere``, ``ex, ey, ez, error_mm`` at the
        final parameters, ``normalised`` (``|e|^2 / sigma^2``) and ``outlier``.
    condition_number : float
        Of the scaled identification Jacobian of the kept measurements.
    rounds : int
        Fits run (1 without outliers).
    """

    fit: Identification
    covariance: np.ndarray
    covariance_basis: str
    sigma_mm: float
    residuals: pd.DataFrame
    condition_number: float
    rounds: int

    @property
    def params(self) -> np.ndarray:
        return self.fit.params

    @property
    def outliers(self) -> np.ndarray:
        return self.residuals["outlier"].to_numpy(bool)


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


def _scale(err2: np.ndarray, noise: dict | None) -> float:
    if noise is not None:
        s2 = noise["sensor_mm"] ** 2 + noise["repeatability_mm"] ** 2 + noise["tracker_mm"] ** 2
        return max(math.sqrt(s2), MIN_SIGMA_MM)
    return max(math.sqrt(float(np.median(err2)) / CHI2_3_MEDIAN), MIN_SIGMA_MM)


def identify_cell(
    meas: Measurements,
    start,
    noise: dict | None = None,
    reject: bool = True,
    max_rounds: int = 5,
    pose_ids=None,
    model: GlobalModel | None = None,
) -> CellFit:
    """Identify the 30 parameters from measured data, flag outliers and refit without them.

    Rule: after each fit, a measurement whose ``|e|^2 / sigma^2`` exceeds :data:`CHI2_3_999`
    (chi-square, 3 degrees of freedom, 99.9 %) is an outlier, ``sigma`` the declared per-axis
    noise or the robust scale of the kept residuals; the fit is repeated on the rest (warm start)
    until the set stops changing or ``max_rounds`` fits ran. With ``noise`` the fit is maximum
    likelihood and the covariance follows from the declared noise; without, least squares and
    the covariance scaled by the residual chi-square.
    """
    model = default_model() if model is None else model
    weighted = noise is not None and meas.cov is not None
    keep = np.ones(len(meas), bool)
    params = np.asarray(start, float)
    rounds = 0
    while True:
        rounds += 1
        fit = identify(subset(meas, keep), params, weighted=weighted, model=model)
        params = fit.params
        e = model.points(params, meas.Q, meas.C) - meas.P_ref
        err2 = np.einsum("ij,ij->i", e, e)
        sigma = _scale(err2[keep], noise)
        new = err2 / sigma**2 <= CHI2_3_999 if reject else keep
        if np.array_equal(new, keep) or rounds >= max_rounds or 3 * new.sum() < N_PARAMS:
            break
        keep = new
    ids = np.arange(1, len(meas) + 1) if pose_ids is None else np.asarray(pose_ids)
    table = pd.DataFrame({"pose": ids, "sphere": meas.sphere})
    table[["ex_mm", "ey_mm", "ez_mm"]] = e
    table["error_mm"] = np.sqrt(err2)
    table["normalised"] = err2 / sigma**2
    table["outlier"] = ~keep
    _, jac = model.points_and_jacobian(params, meas.Q[keep], meas.C[keep])
    s = np.linalg.svd(jac * np.where(IS_LENGTH, 1.0, 1e-3), compute_uv=False)
    basis = "declared noise" if weighted else "residual chi-square"
    return CellFit(fit, fit.estimate.covariance, basis, sigma, table, float(s[0] / s[-1]), rounds)


def parameter_report(cell_fit: CellFit, start) -> pd.DataFrame:
    """Per parameter: nominal, identified, change and standard deviation (mm or deg)."""
    p = cell_fit.params
    std = np.sqrt(np.clip(np.diag(cell_fit.covariance), 0.0, None))
    conv = np.where(IS_LENGTH, 1.0, 180.0 / math.pi)
    return pd.DataFrame(
        {
            "name": PARAM_NAMES,
            "unit": np.where(IS_LENGTH, "mm", "deg"),
            "nominal": np.asarray(start) * conv,
            "identified": p * conv,
            "change": angle_wrap(p - np.asarray(start)) * conv,
            "std": std * conv,
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

    Returns the per-measurement table (``sphere``, ``before_mm``, ``after_mm``, ``within``) and a
    summary (count, mean, RMS and largest error before and after, the requirement and whether
    the largest error after calibration meets it).
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
