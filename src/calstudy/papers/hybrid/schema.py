"""Schemas of the hybrid paper's files: ``station.toml``, ``production.toml`` and the rows of the
hybrid and CMM tables of notebook 02.

Each TOML file is checked on load (:func:`calstudy.core.schema.check_toml`): every key the
simulation reads must be there, with its type and range (lengths in mm, angles in degrees where
the key says ``_deg``), unknown keys are refused (a misspelt key is not silently a default), and
the cross-field rules below hold. A message names the file, the key, the value and the allowed
range, e.g. ``station.toml: handeye.matrix: its rotation is not orthonormal (...)``.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from calstudy.core.schema import (
    Degrees,
    Documented,
    Finite,
    NonNegativeFinite,
    PositiveFinite,
    PositiveInt,
    Schema,
    Vec3,
    check_principal_point,
    rotation_problem,
)

#: at least three products: a mean, a standard deviation and a correlation need them
Products = Annotated[int, Field(ge=3)]
Row4 = Annotated[list[Finite], Field(min_length=4, max_length=4)]


class Source(Documented):
    """The ``[source]`` table of data/hybrid/station.toml and production.toml."""
    paper: str = ""
    robot: str = ""
    station: str = ""


class HandEye(Documented):
    """The ``[handeye]`` table of data/hybrid/station.toml."""
    #: sensor2flange, a rigid 4 x 4 transform (mm); printed to 6 decimals in the paper
    matrix: Annotated[list[Row4], Field(min_length=4, max_length=4)]

    @field_validator("matrix")
    @classmethod
    def _rigid(cls, matrix: list) -> list:
        m = np.array(matrix, dtype=float)
        if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
            raise ValueError(f"the last row is {m[3].tolist()}; a rigid transform has [0, 0, 0, 1]")
        problem = rotation_problem(m)
        if problem:
            raise ValueError(f"not a rigid transform: {problem}")
        return matrix


class Robot(Documented):
    """The ``[robot]`` table of data/hybrid/station.toml."""
    repeatability_mm: NonNegativeFinite


class Sensor(Documented):
    """The ``[sensor]`` table of data/hybrid/station.toml."""
    standoff_mm: PositiveFinite
    #: the stripe must fall on the sphere: |y| = fraction * R with 0 <= fraction < 1
    stripe_offset_fraction: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]


class SphereTable(Documented):
    """The ``[sphere]`` table of data/hybrid/station.toml."""
    centre_mm: Vec3


class Moves(Documented):
    """The ``[calibration_moves]`` table of data/hybrid/station.toml."""
    n_translations: Annotated[int, Field(ge=3)]
    n_rotations: Annotated[int, Field(ge=2)]
    translation_range_mm: PositiveFinite
    across_plane_range_mm: NonNegativeFinite
    rotation_range_deg: Annotated[float, Field(gt=0, le=180, allow_inf_nan=False)]
    rotation_min_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    #: the values of the two move ranges swept by notebook 01
    translation_ranges_mm: Annotated[list[PositiveFinite], Field(min_length=1)]
    across_plane_ranges_mm: Annotated[list[NonNegativeFinite], Field(min_length=1)]

    @model_validator(mode="after")
    def _range(self) -> Moves:
        if self.rotation_min_deg > self.rotation_range_deg:
            raise ValueError(
                f"rotation_min_deg = {self.rotation_min_deg} exceeds rotation_range_deg = "
                f"{self.rotation_range_deg}"
            )
        return self


class Cameras(Documented):
    """The ``[cameras]`` table of data/hybrid/station.toml."""
    fx: PositiveFinite
    fy: PositiveFinite
    cx: Finite
    cy: Finite
    width: PositiveInt
    height: PositiveInt
    pixel_sigma: NonNegativeFinite
    #: the values of the hole-centre noise swept by notebook 01
    pixel_sigmas: Annotated[list[NonNegativeFinite], Field(min_length=1)]

    @model_validator(mode="after")
    def _centre_in_image(self) -> Cameras:
        check_principal_point(self.cx, self.cy, self.width, self.height)
        return self


class Target(Documented):
    """The ``[target]`` table of data/hybrid/station.toml."""
    cmm_sigma_mm: NonNegativeFinite
    cmm_sigma_deg: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)]


class Stationary(Documented):
    """The ``[stationary]`` table of data/hybrid/station.toml."""
    positions_mm: Annotated[list[Vec3], Field(min_length=3)]
    tilts_deg: list[Annotated[list[Degrees], Field(min_length=2, max_length=2)]]
    #: mounting tolerance of a sensor on the fixture (3 sigma per axis), mm and deg
    mounting_tolerance_mm: NonNegativeFinite
    mounting_tolerance_deg: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)]

    @model_validator(mode="after")
    def _same_count(self) -> Stationary:
        if len(self.tilts_deg) != len(self.positions_mm):
            raise ValueError(
                f"{len(self.positions_mm)} positions_mm but {len(self.tilts_deg)} tilts_deg; "
                "one tilt per sensor"
            )
        return self


class Workpiece(Documented):
    """The ``[workpiece]`` table of data/hybrid/station.toml."""
    size_mm: Annotated[list[PositiveFinite], Field(min_length=2, max_length=2)]
    nominal_origin_mm: Vec3
    nominal_rotz_deg: Degrees
    datum_A_slot_mm: Vec3
    datum_B_hole_mm: Vec3
    datum_C_plane_mm: Vec3
    placement_sigma_mm: NonNegativeFinite
    placement_sigma_deg: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)]
    datum_sigma_mm: NonNegativeFinite
    free_direction_mm: NonNegativeFinite

    @model_validator(mode="after")
    def _datums_not_collinear(self) -> Workpiece:
        datums = (self.datum_A_slot_mm, self.datum_B_hole_mm, self.datum_C_plane_mm)
        a, b, c = (np.array(v, float) for v in datums)
        area = float(np.linalg.norm(np.cross(b - a, c - a)))
        if area <= 1e-6 * max(1.0, float(np.linalg.norm(b - a) * np.linalg.norm(c - a))):
            raise ValueError("datums A, B and C are collinear; the 3-2-1 frame needs a triangle")
        return self


class StationFile(Documented):
    """``data/hybrid/station.toml``."""

    source: Source = Source()
    handeye: HandEye
    robot: Robot
    sensor: Sensor
    sphere: SphereTable
    calibration_moves: Moves
    cameras: Cameras
    target: Target
    stationary: Stationary
    workpiece: Workpiece


# ---------------------------------------------------------------------------------------------
# production.toml


class Protocol(Documented):
    """The ``[protocol]`` table of data/hybrid/production.toml."""
    n_before: Products
    n_compensation: Products
    n_compensation_max: Products
    n_follow_up: Products

    @model_validator(mode="after")
    def _max(self) -> Protocol:
        if self.n_compensation_max < max(self.n_before, self.n_compensation):
            raise ValueError(
                f"n_compensation_max = {self.n_compensation_max} is below n_before = "
                f"{self.n_before} or n_compensation = {self.n_compensation}"
            )
        return self


class Variation(Documented):
    """The ``[variation]`` table of data/hybrid/production.toml."""
    part_sigma_mm: NonNegativeFinite


class FeatureNoise(Documented):
    """The ``[sensors]`` table of data/hybrid/production.toml."""
    feature_sigma_mm: NonNegativeFinite


class Sigma(Documented):
    """The ``[cmm]`` table of data/hybrid/production.toml."""
    sigma_mm: NonNegativeFinite


Sweep = Annotated[list[NonNegativeFinite], Field(min_length=1)]


class SweepTable(Documented):
    """The ``[sweep]`` table of data/hybrid/production.toml."""
    part_sigma_mm: Sweep
    feature_sigma_mm: Sweep
    repeatability_mm: Sweep
    drift_sigma_mm: Sweep


class StationaryFeatures(Documented):
    """The ``[stationary_features]`` table of data/hybrid/production.toml."""
    ids: Annotated[list[str], Field(min_length=3)]
    kinds: Annotated[list[str], Field(min_length=3)]
    #: the points of sensors 4.. (sensors 1-3 measure the datums of station.toml)
    others_xyz_mm: list[Vec3]

    @model_validator(mode="after")
    def _counts(self) -> StationaryFeatures:
        n = 3 + len(self.others_xyz_mm)
        if len(self.ids) != n or len(self.kinds) != n:
            raise ValueError(
                f"{len(self.ids)} ids, {len(self.kinds)} kinds and {n} points (3 datums + "
                f"{len(self.others_xyz_mm)} others_xyz_mm); they must match"
            )
        return self


class Feature(Schema):
    """The ``[[flexible.features]]`` table of data/hybrid/production.toml."""
    id: Annotated[str, Field(min_length=1)]
    kind: str
    xyz_mm: Vec3
    view: Vec3
    yaw_deg: Degrees

    @model_validator(mode="after")
    def _view(self) -> Feature:
        if float(np.linalg.norm(self.view)) < 1e-9:
            raise ValueError(f"view of {self.id} is the zero vector; it is a direction")
        return self


class Flexible(Documented):
    """The ``[flexible]`` table of data/hybrid/production.toml."""
    features: Annotated[list[Feature], Field(min_length=1)]


class ProductionFile(Documented):
    """``data/hybrid/production.toml``."""

    source: Source = Source()
    protocol: Protocol
    variation: Variation
    sensors: FeatureNoise
    cmm: Sigma
    drift: Sigma
    sweep: SweepTable
    stationary_features: StationaryFeatures
    flexible: Flexible


# ---------------------------------------------------------------------------------------------
# the rows of the hybrid and CMM tables (notebook 02)


class MeasurementRow(Schema):
    """One row of a hybrid or CMM table: a feature point of one product, mm."""

    product: Annotated[int, Field(ge=0)]
    phase: Literal["compensation", "follow-up"]
    point_id: Annotated[str, Field(min_length=1)]
    x_mm: Finite
    y_mm: Finite
    z_mm: Finite


# ---------------------------------------------------------------------------------------------
# published.toml (the paper's numbers, not an input of the simulation)

#: largest gap (percentage points) between a printed share and its count: the paper prints to
#: two decimals and sometimes truncates (10 / 174 = 5.747 % printed 5.74)
PERCENT_TOL = 0.01
Percent = Annotated[float, Field(ge=0, le=100, allow_inf_nan=False)]
FiveLabels = Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=5, max_length=5)]
FiveCounts = Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=5, max_length=5)]
FivePercent = Annotated[list[Percent], Field(min_length=5, max_length=5)]


def _ascending(values: list) -> list:
    if any(b <= a for a, b in zip(values, values[1:], strict=False)):
        raise ValueError("the edges are not ascending")
    return values


class Systematic(Documented):
    """The ``[systematic]`` table of data/hybrid/published.toml."""

    range_mm: Annotated[list[NonNegativeFinite], Field(min_length=2, max_length=2)]

    @field_validator("range_mm")
    @classmethod
    def _range(cls, value: list) -> list:
        if value[0] > value[1]:
            raise ValueError(f"{value} is not [low, high]")
        return value


class Table1(Documented):
    """The ``[table1]`` table of data/hybrid/published.toml: counts and shares of the 174
    vectors per bin, which must agree with each other within :data:`PERCENT_TOL`."""

    deviation_bins: FiveLabels
    deviation_edges_mm: Annotated[list[PositiveFinite], Field(min_length=4, max_length=4)]
    deviation_counts: FiveCounts
    deviation_percent: FivePercent
    correlation_bins: FiveLabels
    correlation_edges: Annotated[
        list[Annotated[float, Field(ge=-1, le=1, allow_inf_nan=False)]],
        Field(min_length=4, max_length=4),
    ]
    correlation_counts: FiveCounts
    correlation_percent: FivePercent
    within_0p3_percent: Percent
    r_above_0p7_percent: Percent

    @field_validator("deviation_edges_mm", "correlation_edges")
    @classmethod
    def _edges(cls, value: list) -> list:
        return _ascending(value)

    @model_validator(mode="after")
    def _shares(self) -> Table1:
        total = sum(self.deviation_counts)
        if total == 0 or sum(self.correlation_counts) != total:
            raise ValueError(
                f"deviation_counts sum to {total}, correlation_counts to "
                f"{sum(self.correlation_counts)}; both count the same vectors (> 0)"
            )
        checks = [
            (f"{half}_percent #{i + 1}", pct[i], counts[i])
            for half, counts, pct in (
                ("deviation", self.deviation_counts, self.deviation_percent),
                ("correlation", self.correlation_counts, self.correlation_percent),
            )
            for i in range(5)
        ]
        checks += [
            ("within_0p3_percent", self.within_0p3_percent, sum(self.deviation_counts[:3])),
            ("r_above_0p7_percent", self.r_above_0p7_percent, sum(self.correlation_counts[:3])),
        ]
        for name, pct, count in checks:
            if abs(pct - 100.0 * count / total) > PERCENT_TOL + 1e-9:
                raise ValueError(
                    f"{name} = {pct} disagrees with its count: {count} of {total} is "
                    f"{100.0 * count / total:.4g} % (allowed gap {PERCENT_TOL} points)"
                )
        return self


class PublishedFile(Documented):
    """``data/hybrid/published.toml``."""

    source: Source = Source()
    systematic: Systematic
    table1: Table1
