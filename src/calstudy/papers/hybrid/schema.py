"""Schemas of the hybrid paper's files: ``station.toml``, ``production.toml`` and the rows of the
hybrid and CMM tables of notebook 02. The validated file is what the simulation reads
(:mod:`calstudy.papers.hybrid.scenario`), with its derived objects as properties.

Each TOML file is checked on load (:func:`calstudy.core.schema.load_model`): every key the
simulation reads must be there, with its type and range (lengths in mm, angles in degrees where
the key says ``_deg``), unknown keys are refused (a misspelt key is not silently a default), and
the cross-field rules below hold. A message names the file, the key, the value and the allowed
range, e.g. ``station.toml: handeye.matrix: its rotation is not orthonormal (...)``.

Every input carries its provenance beside it (:mod:`calstudy.core.ledger`), and the station must
be one that can exist (:meth:`StationFile.plausibility`, :meth:`ProductionFile.plausibility`):
the stationary sensors below the panel they look up at, the datums and features on the panel,
noise levels below the physical bounds of :data:`NOISE_BOUNDS`, counts below :data:`MAX_PRODUCTS`
and the other size bounds (checked before anything is allocated).
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from calstudy.core import geometry as geo
from calstudy.core.ledger import Inputs, Ledgered, noise_level
from calstudy.core.schema import (
    Degrees,
    Documented,
    Finite,
    LowHigh,
    NonNegativeFinite,
    Pinhole,
    PositiveFinite,
    Rigid4x4,
    Row,
    Schema,
    Vec3,
    distinct,
    one_each,
    ordered,
)
from calstudy.models.sensors import PinholeCamera

#: most products of a protocol phase: the paper's protocol uses 10-30; each product is a panel
#: of 58 features simulated in memory, so a count is bounded before anything is allocated
MAX_PRODUCTS = 1000
#: at least three products: a mean, a standard deviation and a correlation need them
Products = Annotated[int, Field(ge=3, le=MAX_PRODUCTS)]
#: most moves of a calibration, sensors on a fixture, flexible features
MAX_MOVES, MAX_SENSORS, MAX_FEATURES = 100, 100, 1000

#: physical upper bounds of the noise levels (the unit is the key's), each with its reason:
#: beyond them the instrument is not of the class the station describes. Zero is allowed (an
#: oracle switches the error source off).
NOISE_BOUNDS = {
    # ISO 9283 repeatabilities of industrial arms are 0.02-0.2 mm; 1 mm is five times the worst
    "repeatability_mm": 1.0,
    # a line-laser sensor (feature or datum point, sigma per axis): 1 mm is ten times the
    # coarsest in-line sheet-metal sensors (about 0.1 mm)
    "sensor_mm": 1.0,
    # sub-pixel centre detection: beyond 2 px a hole centre is no longer sub-pixel
    "pixel": 2.0,
    # a CMM (probing or target pre-calibration): 0.1 mm is ten times a shop-floor CMM's error
    "cmm_mm": 0.1,
    "cmm_deg": 0.1,
    # the +-2 mm dimensional tolerance of car-body parts (section 4.3): panels, their clamping
    # and the station's drift beyond it would not be the process the paper describes
    "tolerance_mm": 2.0,
    "placement_deg": 1.0,
    # ISO 2768-1 class c (coarse) allows +-2 mm / +-1 deg on a sensor bracket of 1 m or less
    "mounting_mm": 2.0,
    "mounting_deg": 1.0,
}


def _frozen(array: np.ndarray) -> np.ndarray:
    """``array`` made read-only: a derived array of a (shared, frozen) scenario."""
    array.flags.writeable = False
    return array


class Source(Documented):
    """The ``[source]`` table of data/hybrid/station.toml and production.toml."""
    paper: str = ""
    robot: str = ""
    station: str = ""


class HandEye(Inputs):
    """The ``[handeye]`` table of data/hybrid/station.toml."""
    #: sensor2flange, a rigid 4 x 4 transform (mm); printed to 6 decimals in the paper
    matrix: Rigid4x4

    @cached_property
    def sensor2flange(self) -> np.ndarray:
        """The matrix (4, 4) with its rotation projected onto SO(3) (the printed decimals
        leave it a few 1e-7 off), mm."""
        hand = np.array(self.matrix, dtype=float)
        return _frozen(geo.make_transform(geo.project_to_so3(hand[:3, :3]), hand[:3, 3]))


class Robot(Inputs):
    """The ``[robot]`` table of data/hybrid/station.toml."""
    repeatability_mm: noise_level(NOISE_BOUNDS, "repeatability_mm")


class Sensor(Inputs):
    """The ``[sensor]`` table of data/hybrid/station.toml."""
    standoff_mm: PositiveFinite
    #: the stripe must fall on the sphere: |y| = fraction * R with 0 <= fraction < 1
    stripe_offset_fraction: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]
    #: the flexible sensor's stripe (calstudy.models.sensors.LineLaserSensor)
    sigma_point_mm: noise_level(NOISE_BOUNDS, "sensor_mm")
    #: a circle fit needs at least 3 points
    n_points: Annotated[int, Field(ge=3, le=MAX_FEATURES * 100)]
    arc_half_angle_deg: Annotated[float, Field(gt=0, lt=90, allow_inf_nan=False)]
    #: the noise model's parts beyond the stripe (LineLaserSensor): an independent centre-noise
    #: floor (mm per axis) and the factor on the stripe model's y-(x, z) correlation
    centre_floor_mm: noise_level(NOISE_BOUNDS, "sensor_mm")
    correlation_scale: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]


class SphereTable(Inputs):
    """The ``[sphere]`` table of data/hybrid/station.toml."""
    centre_mm: Vec3
    radius_mm: PositiveFinite


class Moves(Inputs):
    """The ``[calibration_moves]`` table of data/hybrid/station.toml."""
    n_translations: Annotated[int, Field(ge=3, le=MAX_MOVES)]
    n_rotations: Annotated[int, Field(ge=2, le=MAX_MOVES)]
    translation_range_mm: PositiveFinite
    across_plane_range_mm: NonNegativeFinite
    rotation_range_deg: Annotated[float, Field(gt=0, le=180, allow_inf_nan=False)]
    rotation_min_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    #: the values of the two move ranges swept by notebook 01
    translation_ranges_mm: Annotated[list[PositiveFinite], Field(min_length=1)]
    across_plane_ranges_mm: Annotated[list[NonNegativeFinite], Field(min_length=1)]

    _range = ordered("rotation_min_deg", "rotation_range_deg", strict=False)


class Cameras(Pinhole, Inputs):
    """The ``[cameras]`` table of data/hybrid/station.toml: the sensors' pinhole camera."""
    pixel_sigma: noise_level(NOISE_BOUNDS, "pixel")
    #: the values of the hole-centre noise swept by notebook 01
    pixel_sigmas: Annotated[list[NonNegativeFinite], Field(min_length=1)]

    @cached_property
    def camera(self) -> PinholeCamera:
        """The camera of the stationary and flexible sensors."""
        return PinholeCamera(
            fx=self.fx, fy=self.fy, cx=self.cx, cy=self.cy, width=self.width, height=self.height
        )


class Target(Inputs):
    """The ``[target]`` table of data/hybrid/station.toml."""
    cmm_sigma_mm: noise_level(NOISE_BOUNDS, "cmm_mm")
    cmm_sigma_deg: noise_level(NOISE_BOUNDS, "cmm_deg")


class Stationary(Inputs):
    """The ``[stationary]`` table of data/hybrid/station.toml."""
    positions_mm: Annotated[list[Vec3], Field(min_length=3, max_length=MAX_SENSORS)]
    tilts_deg: Annotated[
        list[Annotated[list[Degrees], Field(min_length=2, max_length=2)]],
        Field(max_length=MAX_SENSORS),
    ]
    #: mounting tolerance of a sensor on the fixture (3 sigma per axis), mm and deg
    mounting_tolerance_mm: noise_level(NOISE_BOUNDS, "mounting_mm")
    mounting_tolerance_deg: noise_level(NOISE_BOUNDS, "mounting_deg")

    @cached_property
    def design(self) -> np.ndarray:
        """``statcam2base`` (S, 4, 4) of the sensors as designed: at ``positions_mm``, tilted
        about x then y by ``tilts_deg``."""
        tilts = np.deg2rad(np.array(self.tilts_deg, dtype=float))
        zero = np.zeros(len(tilts))
        rot = geo.rotvec_to_matrix(np.column_stack([tilts[:, 0], zero, zero]))
        rot = rot @ geo.rotvec_to_matrix(np.column_stack([zero, tilts[:, 1], zero]))
        return _frozen(geo.make_transform(rot, np.array(self.positions_mm, dtype=float)))

    _same_count = one_each("positions_mm", "tilts_deg", note="one tilt per sensor")


class Workpiece(Inputs):
    """The ``[workpiece]`` table of data/hybrid/station.toml."""
    size_mm: Annotated[list[PositiveFinite], Field(min_length=2, max_length=2)]
    nominal_origin_mm: Vec3
    nominal_rotz_deg: Degrees
    datum_A_slot_mm: Vec3
    datum_B_hole_mm: Vec3
    datum_C_plane_mm: Vec3
    placement_sigma_mm: noise_level(NOISE_BOUNDS, "tolerance_mm")
    placement_sigma_deg: noise_level(NOISE_BOUNDS, "placement_deg")
    datum_sigma_mm: noise_level(NOISE_BOUNDS, "sensor_mm")
    free_direction_mm: NonNegativeFinite

    @cached_property
    def datums(self) -> np.ndarray:
        """Datums A, B and C (3, 3) in the workpiece frame, mm."""
        datums = (self.datum_A_slot_mm, self.datum_B_hole_mm, self.datum_C_plane_mm)
        return _frozen(np.array(datums, dtype=float))

    @model_validator(mode="after")
    def _datums_not_collinear(self) -> Workpiece:
        datums = (self.datum_A_slot_mm, self.datum_B_hole_mm, self.datum_C_plane_mm)
        a, b, c = (np.array(v, float) for v in datums)
        area = float(np.linalg.norm(np.cross(b - a, c - a)))
        if area <= 1e-6 * max(1.0, float(np.linalg.norm(b - a) * np.linalg.norm(c - a))):
            raise ValueError("datums A, B and C are collinear; the 3-2-1 frame needs a triangle")
        return self


class StationFile(Ledgered):
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

    def plausibility(self) -> None:
        """The flexible sensor stands outside the sphere; the stationary sensors sit below the
        panel and look up at it (section 4.1: they are on the fixture's baseboard under the
        underbody); the datums lie on the panel."""
        if self.sensor.standoff_mm <= self.sphere.radius_mm:
            raise ValueError(
                f"sensor.standoff_mm = {self.sensor.standoff_mm}: not beyond the sphere's radius "
                f"sphere.radius_mm = {self.sphere.radius_mm}; the sensor would sit inside the "
                "sphere it measures"
            )
        panel_z = self.workpiece.nominal_origin_mm[2]
        for k, (pos, tilt) in enumerate(
            zip(self.stationary.positions_mm, self.stationary.tilts_deg, strict=True)
        ):
            if pos[2] >= panel_z:
                raise ValueError(
                    f"stationary.positions_mm #{k + 1} z = {pos[2]}: the sensor sits at or above "
                    f"the panel's plane (workpiece.nominal_origin_mm z = {panel_z}); it must be "
                    "below the panel to look up at its underside"
                )
            up = math.cos(math.radians(tilt[0])) * math.cos(math.radians(tilt[1]))
            if up <= 0:
                raise ValueError(
                    f"stationary.tilts_deg #{k + 1} = {tilt}: the sensor looks sideways or down "
                    "(its axis has no upward component); it must look up at the panel"
                )
        size = self.workpiece.size_mm
        for name in ("datum_A_slot_mm", "datum_B_hole_mm", "datum_C_plane_mm"):
            x, y, _ = getattr(self.workpiece, name)
            if not (0 <= x <= size[0] and 0 <= y <= size[1]):
                raise ValueError(
                    f"workpiece.{name} = {[x, y, _]}: not on the {size[0]:g} x {size[1]:g} mm "
                    "panel (workpiece.size_mm; the frame has its origin at a corner)"
                )


# ---------------------------------------------------------------------------------------------
# production.toml


class Protocol(Inputs):
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


class Variation(Inputs):
    """The ``[variation]`` table of data/hybrid/production.toml."""
    part_sigma_mm: noise_level(NOISE_BOUNDS, "tolerance_mm")


class FeatureNoise(Inputs):
    """The ``[sensors]`` table of data/hybrid/production.toml."""
    feature_sigma_mm: noise_level(NOISE_BOUNDS, "sensor_mm")


class CmmNoise(Inputs):
    """The ``[cmm]`` table of data/hybrid/production.toml."""
    sigma_mm: noise_level(NOISE_BOUNDS, "cmm_mm")


class Drift(Inputs):
    """The ``[drift]`` table of data/hybrid/production.toml."""
    sigma_mm: noise_level(NOISE_BOUNDS, "tolerance_mm")


Sweep = Annotated[list[NonNegativeFinite], Field(min_length=1)]


class SweepTable(Inputs):
    """The ``[sweep]`` table of data/hybrid/production.toml."""
    part_sigma_mm: Sweep
    feature_sigma_mm: Sweep
    repeatability_mm: Sweep
    drift_sigma_mm: Sweep


class StationaryFeatures(Inputs):
    """The ``[stationary_features]`` table of data/hybrid/production.toml."""
    ids: Annotated[list[str], Field(min_length=3, max_length=MAX_SENSORS)]
    kinds: Annotated[list[str], Field(min_length=3, max_length=MAX_SENSORS)]
    #: the points of sensors 4.. (sensors 1-3 measure the datums of station.toml)
    others_xyz_mm: Annotated[list[Vec3], Field(max_length=MAX_SENSORS)]

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


class Flexible(Inputs):
    """The ``[flexible]`` table of data/hybrid/production.toml."""
    features: Annotated[list[Feature], Field(min_length=1, max_length=MAX_FEATURES)]


class ProductionFile(Ledgered):
    """``data/hybrid/production.toml``."""

    source: Source = Source()
    protocol: Protocol
    variation: Variation
    sensors: FeatureNoise
    cmm: CmmNoise
    drift: Drift
    sweep: SweepTable
    stationary_features: StationaryFeatures
    flexible: Flexible

    def plausibility(self) -> None:
        """Every feature point has its own id."""
        ids = [f.id for f in self.flexible.features] + list(self.stationary_features.ids)
        distinct(ids, "feature point ids", ": each point needs its own id")


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
FiveLabels = Annotated[
    tuple[Annotated[str, Field(min_length=1)], ...], Field(min_length=5, max_length=5), Row
]
FiveCounts = Annotated[
    tuple[Annotated[int, Field(ge=0)], ...], Field(min_length=5, max_length=5), Row
]
FivePercent = Annotated[tuple[Percent, ...], Field(min_length=5, max_length=5), Row]


def _ascending(values: tuple) -> tuple:
    if any(b <= a for a, b in zip(values, values[1:], strict=False)):
        raise ValueError("the edges are not ascending")
    return values


class Systematic(Documented):
    """The ``[systematic]`` table of data/hybrid/published.toml."""

    range_mm: Annotated[
        tuple[NonNegativeFinite, ...], Field(min_length=2, max_length=2), Row, LowHigh
    ]


class Table1(Documented):
    """The ``[table1]`` table of data/hybrid/published.toml: counts and shares of the 174
    vectors per bin, which must agree with each other within :data:`PERCENT_TOL`."""

    deviation_bins: FiveLabels
    deviation_edges_mm: Annotated[
        tuple[PositiveFinite, ...], Field(min_length=4, max_length=4), Row
    ]
    deviation_counts: FiveCounts
    deviation_percent: FivePercent
    correlation_bins: FiveLabels
    correlation_edges: Annotated[
        tuple[Annotated[float, Field(ge=-1, le=1, allow_inf_nan=False)], ...],
        Field(min_length=4, max_length=4),
        Row,
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
