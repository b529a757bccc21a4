"""Robot tables and their errors: reading ``data/robots/*.toml`` (or one's own table) through a
schema, and drawing manufacturing errors of a robot within its tolerances.

The kinematics themselves (links, forward and inverse kinematics, Jacobians) are
:mod:`calstudy.models.kinematics`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from calstudy.core import paths, schema
from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import rotation_error, translation_error
from calstudy.models.kinematics import LINK_FIELDS, Link, Robot, check_rng

# ----------------------------------------------------------------------------------------------
# loading


#: largest link length or offset accepted (mm): 10 m, beyond any serial robot
MAX_LINK_MM = 1e4
_Length = Annotated[float, Field(ge=-MAX_LINK_MM, le=MAX_LINK_MM, allow_inf_nan=False)]
_Angle = Annotated[float, Field(ge=-360.0, le=360.0, allow_inf_nan=False)]
_JointLimit = Annotated[float, Field(ge=-720.0, le=720.0, allow_inf_nan=False)]


class LinkEntry(schema.Schema):
    """One ``[[link]]`` of a robot table (mm and degrees)."""

    convention: Literal["dh", "mdh"]
    a_mm: _Length
    alpha_deg: _Angle
    d_mm: _Length
    theta_deg: _Angle
    beta_deg: _Angle = 0.0
    qmin_deg: _JointLimit
    qmax_deg: _JointLimit
    parallel: bool = False

    @model_validator(mode="after")
    def _range(self):
        if self.qmin_deg >= self.qmax_deg:
            raise ValueError(
                f"qmin_deg = {self.qmin_deg:g} must be below qmax_deg = {self.qmax_deg:g}"
            )
        return self


class RobotTolerances(schema.Schema):
    """The ``[tolerances]`` table: standard deviations of the link parameters."""

    sigma_length_mm: Annotated[float, Field(ge=0, le=100, allow_inf_nan=False)]
    sigma_angle_deg: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)]
    justification: str = ""


class RobotFile(schema.Schema):
    """A robot table ``data/robots/<name>.toml``."""

    name: str = Field(min_length=1)
    source: dict[str, str] = {}
    link: list[LinkEntry] = Field(min_length=1, max_length=12)
    tolerances: RobotTolerances | None = None

    @model_validator(mode="after")
    def _one_convention(self):
        conventions = sorted({entry.convention for entry in self.link})
        if len(conventions) > 1:
            raise ValueError(f"links mix conventions {conventions}; use one")
        return self


def _check_robot_units(path, table: RobotFile) -> None:
    """Refuse a table whose angles look like radians or lengths like metres."""
    for i, entry in enumerate(table.link):
        for key in ("alpha_deg", "theta_deg", "beta_deg"):
            value = getattr(entry, key)
            if value != 0 and min(abs(abs(value) - math.pi / 2), abs(abs(value) - math.pi)) < 1e-3:
                raise CalibrationError(
                    f"{path}: link #{i + 1}.{key} = {value:g} looks like radians (pi/2 or pi); the "
                    "table holds degrees"
                )
    lengths = [abs(v) for e in table.link for v in (e.a_mm, e.d_mm)]
    if max(lengths) < 10.0:
        raise CalibrationError(
            f"{path}: every a_mm and d_mm is below 10 (largest {max(lengths):g}): they look like "
            "metres; the table holds millimetres"
        )


def robot_file(name: str | Path) -> Path:
    """The path of robot table ``name``: a file stem of ``data/robots/`` or a path to a
    ``.toml`` file; FileNotFoundError naming it (and the stems available) if it is missing."""
    name_s = str(name)
    if isinstance(name, Path) or name_s.endswith(".toml") or "/" in name_s:
        path = Path(name_s)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such robot table")
        return path
    path = paths.DATA_DIR / "robots" / f"{name_s}.toml"
    if not path.is_file():
        have = sorted(p.stem for p in (paths.DATA_DIR / "robots").glob("*.toml"))
        raise FileNotFoundError(
            f"data/robots/{name_s}.toml: no such robot table; available: {', '.join(have)}"
        )
    return path


def load_robot(name: str | Path) -> Robot:
    """Read a robot table: ``data/robots/<name>.toml``, or a path to one's own ``.toml`` file.

    The file has a top-level ``name`` (display name), a ``[source]`` table, one ``[[link]]`` per
    joint with ``convention``, ``a_mm``, ``alpha_deg``, ``d_mm``, ``theta_deg``, ``beta_deg``,
    ``qmin_deg``, ``qmax_deg`` (and optionally ``parallel``), and a ``[tolerances]`` table with
    ``sigma_length_mm`` and ``sigma_angle_deg``. The schema (:class:`RobotFile`) checks every key
    (unknown keys are refused, so a misspelt key is not silently a default), every range
    (lengths within +-10 m, angles within +-360 deg, ``qmin_deg < qmax_deg``, tolerances >= 0)
    and the units (an angle of 1.5708 looks like radians, all lengths below 10 like metres).

    Parameters
    ----------
    name : str or pathlib.Path
        File stem, e.g. ``"kuka_kr16_2"``, or a path ending in ``.toml``.

    Returns
    -------
    Robot
        With joint limits in rad and ``tolerances`` / ``source`` taken from the file.

    Raises
    ------
    FileNotFoundError
        If the file does not exist (the message lists the tables available).
    CalibrationError
        If the file is not valid TOML or breaks the schema; the message names the file, the
        key (``link #2.a_mm``, entries counted from 1), the value and the allowed range.
    """
    path = robot_file(name)
    in_data = path.parent == paths.DATA_DIR / "robots"
    where = f"data/robots/{path.name}" if in_data else str(path)
    raw = schema.read_toml(path, "robot table")
    raw.setdefault("name", Path(str(name)).stem)
    table = schema.validate(RobotFile, raw, where)
    _check_robot_units(where, table)
    links = [
        Link(
            entry.convention,
            a=entry.a_mm,
            alpha=math.radians(entry.alpha_deg),
            d=entry.d_mm,
            theta=math.radians(entry.theta_deg),
            beta=math.radians(entry.beta_deg),
            parallel=entry.parallel,
        )
        for entry in table.link
    ]
    tolerances = None
    if table.tolerances is not None:
        tolerances = {
            "sigma_length_mm": table.tolerances.sigma_length_mm,
            "sigma_angle_deg": table.tolerances.sigma_angle_deg,
        }
    return Robot(
        table.name,
        links,
        [math.radians(e.qmin_deg) for e in table.link],
        [math.radians(e.qmax_deg) for e in table.link],
        tolerances=tolerances,
        source=dict(table.source),
    )


# ----------------------------------------------------------------------------------------------
# the "true" robot


def _check_sigma(value: float, label: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise CalibrationError(f"{label} must be finite and >= 0 (got {value!r})")
    return value


def perturb_robot(
    robot: Robot,
    rng: np.random.Generator,
    sigma_length_mm: float | None = None,
    sigma_angle_deg: float | None = None,
) -> Robot:
    """A "true" robot: the nominal link parameters plus independent normal manufacturing errors.

    Every ``a`` and ``d`` gets ``N(0, sigma_length_mm^2)`` mm, every ``alpha`` and ``theta`` gets
    ``N(0, sigma_angle_deg^2)`` deg (converted to rad). ``beta`` is perturbed only on links with
    ``parallel=True`` or a nonzero nominal ``beta``; elsewhere it stays as it is (a beta on a
    non-parallel link would duplicate the other parameters). One normal draw per parameter is
    taken in the order of :meth:`Robot.parameters` whatever the mask, so the draws of a seed do
    not depend on which betas are free.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    rng : numpy.random.Generator
        Source of randomness.
    sigma_length_mm, sigma_angle_deg : float, optional
        Standard deviations; by default those of ``robot.tolerances`` (the TOML file).

    Returns
    -------
    Robot
        Same joints, limits, base and tool; perturbed link parameters.
    """
    check_rng(rng)
    defaults = robot.tolerances or {}
    sigmas = []
    for value, key in ((sigma_length_mm, "sigma_length_mm"), (sigma_angle_deg, "sigma_angle_deg")):
        if value is None:
            if key not in defaults:
                raise CalibrationError(
                    f"the {robot.name} has no tolerances table; pass {key} explicitly"
                )
            value = defaults[key]
        sigmas.append(_check_sigma(value, key))
    sigma_length, sigma_angle = sigmas[0], math.radians(sigmas[1])
    scale = np.where(robot.parameter_is_length(), sigma_length, sigma_angle).reshape(robot.nq, -1)
    beta_col = LINK_FIELDS.index("beta")
    for i, link in enumerate(robot.links):
        if not (link.parallel or link.beta != 0.0):
            scale[i, beta_col] = 0.0
    noise = rng.standard_normal(scale.size) * scale.ravel()
    return robot.with_parameters(robot.parameters() + noise)


def pose_errors(nominal: Robot, true: Robot, Q) -> tuple[np.ndarray, np.ndarray]:
    """Flange pose differences between two robots at the same joint angles.

    Parameters
    ----------
    nominal, true : Robot
        Two robots with the same number of joints.
    Q : array_like, shape (N, n)
        Joint angles in rad.

    Returns
    -------
    position_error_mm : numpy.ndarray, shape (N,)
        Distance between the two flange origins, mm.
    rotation_error_rad : numpy.ndarray, shape (N,)
        Angle of the relative rotation of the two flanges, rad.
    """
    if nominal.nq != true.nq:
        raise CalibrationError(
            f"the robots have {nominal.nq} and {true.nq} joints; pose errors need the same number"
        )
    nominal_poses = nominal.fk_many(Q)
    true_poses = true.fk_many(Q)
    return translation_error(nominal_poses, true_poses), rotation_error(nominal_poses, true_poses)
