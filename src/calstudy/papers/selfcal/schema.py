"""Schema of the ``cell.toml`` of a measurement folder of the selfcal paper (your own cell).

Checked on load (:func:`calstudy.core.schema.check_toml`): every key read must be there with its
type and range (lengths mm, angles degrees where the key says ``_deg``), unknown keys are
refused. The simulated cell's ``scenario.toml`` is :class:`calstudy.papers.selfcal.scenario.
Scenario`.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from calstudy.core.schema import (
    Degrees,
    Documented,
    NonNegativeFinite,
    PositiveFinite,
    Schema,
    Vec3,
)

RobotName = Annotated[str, Field(min_length=1)]


class Pose(Schema):
    """The ``[base]`` table of a cell's cell.toml."""

    xyz_mm: Vec3
    zyx_deg: Annotated[list[Degrees], Field(min_length=3, max_length=3)]


class SensorPose(Pose):
    """The ``[sensor]`` table of a cell's cell.toml: the mounting and, optionally, the sensor's
    working distance and the half-widths of its field across and along the optical axis (mm),
    which the pose planning uses (the paper's scanner when absent)."""

    standoff_mm: PositiveFinite | None = None
    field_mm: PositiveFinite | None = None
    depth_mm: PositiveFinite | None = None


class Noise(Schema):
    """The ``[noise]`` table of a cell's cell.toml."""

    sensor_mm: NonNegativeFinite
    repeatability_mm: NonNegativeFinite
    tracker_mm: NonNegativeFinite


class CellFile(Documented):
    """``cell.toml`` of a measurement folder (:mod:`calstudy.papers.selfcal.measured`)."""

    robot: RobotName
    flange: RobotName | None = None
    base: Pose
    sensor: SensorPose
    noise: Noise | None = None


__all__ = ["CellFile", "RobotName"]
