"""Schema of the selfcal paper's ``scenario.toml`` (the simulated cell, or a copy describing
yours); a measurement folder's ``cell.toml`` is :mod:`calstudy.selfcal.cellfile`.

It is checked on load (:func:`calstudy.core.schema.check_toml`): every key read must be there
with its type and range (lengths mm, angles degrees where the key says ``_deg``), unknown keys
are refused, and the cross-field rules below hold (the sphere envelope is a box, its spheres fit
in it at their minimum separation, the scanner stands outside the spheres it measures, noise
levels lie below the physical bounds of :data:`NOISE_BOUNDS`, counts below their size bounds).
Every input of ``scenario.toml`` carries its provenance beside it
(:mod:`calstudy.core.ledger`). The robot table a file names is checked by
:func:`calstudy.models.robots.load_robot` (a missing one: ``FileNotFoundError`` with the
tables available).
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import Field, model_validator

from calstudy.core.ledger import Inputs, Ledgered, noise_level
from calstudy.core.schema import (
    Degrees,
    Documented,
    NonNegativeFinite,
    PositiveFinite,
    PositiveInt,
    Vec3,
)
from calstudy.selfcal.cellfile import RobotName

#: a half-angle of a cone, degrees
HalfAngle = Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]
AngleSigma = Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]

#: physical upper bounds of the noise levels (mm, mm/m), each with its reason: beyond them the
#: instrument is not of the class the scenario describes; zero is allowed (an oracle)
NOISE_BOUNDS = {
    # ISO 9283 repeatabilities of industrial arms are 0.02-0.2 mm; 1 mm is five times the worst
    "repeatability_mm": 1.0,
    # a scanner whose points scatter by 1 mm cannot fit the centre of a tooling sphere of some
    # tens of mm to the tenths of a millimetre the 0.42 mm requirement needs
    "point_mm": 1.0,
    # laser trackers: 10-50 um + 5-10 um/m; 1 mm (or 1 mm/m) is twenty times the coarsest
    "tracker_mm": 1.0,
    "tracker_mm_per_m": 1.0,
}
#: most spheres, views, validation placements and points of a cap (sizes bounded before any
#: allocation; the paper uses 4, 6, 10)
MAX_SPHERES, MAX_VIEWS, MAX_PLACEMENTS, MAX_POINTS = 50, 100, 1000, 100_000


def _noise(bound: str):
    """A noise level bounded by ``NOISE_BOUNDS[bound]`` (``core.ledger.noise_level``)."""
    return noise_level(NOISE_BOUNDS[bound])


class Repeatability(Inputs):
    """The ``[repeatability]`` table of data/selfcal/scenario.toml."""

    sigma_mm: _noise("repeatability_mm")


class Base(Inputs):
    """The ``[base]`` table of data/selfcal/scenario.toml."""

    rough_xyz_mm: Vec3
    rough_zyx_deg: Annotated[list[Degrees], Field(min_length=3, max_length=3)]
    sigma_mm: NonNegativeFinite
    sigma_deg: AngleSigma


class SensorMount(Inputs):
    """The ``[sensor]`` table of data/selfcal/scenario.toml."""

    design_xyz_mm: Vec3
    design_zyx_deg: Annotated[list[Degrees], Field(min_length=3, max_length=3)]
    sigma_mm: NonNegativeFinite
    sigma_deg: AngleSigma


class PoorStart(Inputs):
    """The ``[poor_start]`` table of data/selfcal/scenario.toml."""

    base_mm: NonNegativeFinite
    base_deg: AngleSigma
    sensor_mm: NonNegativeFinite
    sensor_deg: AngleSigma
    robot_length_mm: NonNegativeFinite
    robot_angle_deg: AngleSigma
    basin_scales: Annotated[list[NonNegativeFinite], Field(min_length=1)]


class Spheres(Inputs):
    """The ``[spheres]`` table of data/selfcal/scenario.toml."""

    count: Annotated[int, Field(ge=3, le=MAX_SPHERES)]
    radius_mm: PositiveFinite
    min_separation_mm: NonNegativeFinite
    envelope_min_mm: Vec3
    envelope_max_mm: Vec3

    @model_validator(mode="after")
    def _envelope(self) -> Spheres:
        lo, hi = self.envelope_min_mm, self.envelope_max_mm
        if any(a >= b for a, b in zip(lo, hi, strict=True)):
            raise ValueError(f"envelope_min_mm {lo} is not below envelope_max_mm {hi} everywhere")
        diagonal = math.dist(lo, hi)
        if self.min_separation_mm >= diagonal:
            raise ValueError(
                f"min_separation_mm = {self.min_separation_mm} is not below the envelope's "
                f"diagonal {diagonal:.1f} mm: no two spheres fit"
            )
        return self


class Scanner(Inputs):
    """The ``[scanner]`` table of data/selfcal/scenario.toml."""

    standoff_mm: PositiveFinite
    field_mm: PositiveFinite
    depth_mm: PositiveFinite
    view_cone_deg: HalfAngle
    roll_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    cap_half_angle_deg: HalfAngle
    #: a sphere fit (centre and radius) needs at least 4 points
    points_per_cap: Annotated[int, Field(ge=4, le=MAX_POINTS)]
    sigma_point_mm: _noise("point_mm")
    max_fit_condition: Annotated[float, Field(ge=1, allow_inf_nan=False)]


class Tracker(Inputs):
    """The ``[tracker]`` table of data/selfcal/scenario.toml."""

    u0_mm: _noise("tracker_mm")
    u1_mm_per_m: _noise("tracker_mm_per_m")
    coverage: PositiveFinite


class Protocol(Inputs):
    """The ``[protocol]`` table of data/selfcal/scenario.toml."""

    views_per_sphere: Annotated[int, Field(ge=1, le=MAX_VIEWS)]
    validation_placements: Annotated[int, Field(ge=1, le=MAX_PLACEMENTS)]
    requirement_mm: PositiveFinite
    crb_multiple: Annotated[float, Field(ge=1, allow_inf_nan=False)]


class Compliance(Inputs):
    """The ``[compliance]`` table of data/selfcal/scenario.toml."""

    payload_kg: NonNegativeFinite
    stiffness_nm_per_rad: Annotated[list[PositiveFinite], Field(min_length=6, max_length=6)]
    scale: NonNegativeFinite
    sweep_scales: Annotated[list[NonNegativeFinite], Field(min_length=1)]


class Published(Documented):
    """The ``[published]`` table of data/selfcal/scenario.toml."""

    convergence_iterations: PositiveInt


class ScenarioFile(Ledgered, Inputs):
    """``data/selfcal/scenario.toml``."""

    robot: RobotName
    repeatability: Repeatability
    base: Base
    sensor: SensorMount
    poor_start: PoorStart
    spheres: Spheres
    scanner: Scanner
    tracker: Tracker
    protocol: Protocol
    compliance: Compliance
    published: Published

    def plausibility(self) -> None:
        """The scanner stands outside every sphere it measures: the nearest a sphere centre comes
        (``standoff_mm - depth_mm``) exceeds the sphere's radius."""
        nearest = self.scanner.standoff_mm - self.scanner.depth_mm
        if nearest <= self.spheres.radius_mm:
            raise ValueError(
                f"scanner.standoff_mm = {self.scanner.standoff_mm}: a sphere centre comes as "
                f"near as standoff_mm - depth_mm = {nearest:g} mm to the scanner, within the "
                f"sphere's radius spheres.radius_mm = {self.spheres.radius_mm}: the scanner "
                "would sit inside the sphere (standoff_mm must exceed depth_mm + radius_mm)"
            )


__all__ = ["ScenarioFile"]
