"""Schema of a measurement folder's ``cell.toml`` (:mod:`calstudy.selfcal.measured` reads it).

Read and checked by :func:`calstudy.core.schema.load_model`: every key must be there with its
type and range (lengths mm, angles degrees where the key says ``_deg``) and unknown keys are
refused. The robot table a file names is checked by :func:`calstudy.models.robots.load_robot`
(a missing one: ``FileNotFoundError`` with the tables available).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field

from calstudy.core.geometry import euler_zyx_to_matrix, make_transform
from calstudy.core.schema import (
    Degrees,
    Documented,
    NonNegativeFinite,
    PositiveFinite,
    Schema,
    Vec3,
)


def zyx_pose(xyz_mm, zyx_deg) -> np.ndarray:
    """A pose as a file writes it: position ``xyz_mm`` (3,) mm and ZYX Euler angles ``zyx_deg``
    (3,) degrees (:func:`calstudy.core.geometry.euler_zyx_to_matrix`), as a (4, 4) transform."""
    return make_transform(euler_zyx_to_matrix(*zyx_deg), xyz_mm)


#: a robot: the stem of a library table or a file name
RobotName = Annotated[str, Field(min_length=1)]


class Pose(Schema):
    """The ``[base]`` table of a cell's cell.toml."""

    xyz_mm: Vec3
    zyx_deg: Annotated[list[Degrees], Field(min_length=3, max_length=3)]

    @property
    def transform(self) -> np.ndarray:
        """The pose as a 4 x 4 rigid transform (mm), ZYX Euler angles in degrees."""
        return zyx_pose(self.xyz_mm, self.zyx_deg)


class SensorPose(Pose):
    """The ``[sensor]`` table of a cell's cell.toml: the mounting and, optionally, the sensor's
    working distance and the half-widths of its field across and along the optical axis (mm),
    which the pose planning uses (the paper's scanner when absent)."""

    standoff_mm: PositiveFinite | None = None
    field_mm: PositiveFinite | None = None
    depth_mm: PositiveFinite | None = None

    @property
    def geometry(self) -> dict | None:
        """The declared ``standoff_mm``, ``field_mm`` and ``depth_mm`` (mm), or None if none."""
        keys = ("standoff_mm", "field_mm", "depth_mm")
        return {k: getattr(self, k) for k in keys if getattr(self, k) is not None} or None


class Noise(Schema):
    """The ``[noise]`` table of a cell's cell.toml."""

    sensor_mm: NonNegativeFinite
    repeatability_mm: NonNegativeFinite
    tracker_mm: NonNegativeFinite


class CellFile(Documented):
    """``cell.toml`` of a measurement folder (:mod:`calstudy.selfcal.measured`)."""

    robot: RobotName
    flange: RobotName | None = None
    base: Pose
    sensor: SensorPose
    noise: Noise | None = None


__all__ = ["CellFile", "RobotName", "zyx_pose"]
