"""The simulated cell of the ``selfcal`` paper and its published numbers, from ``data/selfcal/``.

:func:`load_scenario` reads ``data/selfcal/scenario.toml`` (or a copy describing your own cell)
into a :class:`Scenario`, the validated file itself: every key the simulation reads is there
with its type and range (lengths mm, angles degrees where the key says ``_deg``), unknown keys
are refused, and the rules across keys hold (the sphere envelope is a box, its spheres fit in it
at their minimum separation, the scanner stands outside the spheres it measures, the robot
reaches the envelope, noise levels lie below the physical bounds of :data:`NOISE_BOUNDS`, counts
below their size bounds). Every input carries its provenance beside it
(:mod:`calstudy.core.ledger`); every number names its source in the paper or says why it is
assumed. The robot table the file names is checked by :func:`calstudy.models.robots.load_robot`
(a missing one: ``FileNotFoundError`` with the tables available).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cached_property
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from calstudy.core.ledger import Inputs, Ledgered, noise_level
from calstudy.core.schema import (
    Degrees,
    Documented,
    NonNegativeFinite,
    PositiveFinite,
    PositiveInt,
    Vec3,
    load_paper_file,
)
from calstudy.models.kinematics import Robot
from calstudy.models.reach import reach_bound
from calstudy.models.robots import load_robot
from calstudy.selfcal.cellfile import RobotName, zyx_pose

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


class Repeatability(Inputs):
    """The ``[repeatability]`` table of data/selfcal/scenario.toml."""

    sigma_mm: noise_level(NOISE_BOUNDS, "repeatability_mm")


class Base(Inputs):
    """The ``[base]`` table of data/selfcal/scenario.toml."""

    rough_xyz_mm: Vec3
    rough_zyx_deg: Annotated[list[Degrees], Field(min_length=3, max_length=3)]
    sigma_mm: NonNegativeFinite
    sigma_deg: AngleSigma

    @cached_property
    def rough(self) -> np.ndarray:
        """``part2base`` (4, 4) of the layout drawing, mm."""
        return zyx_pose(self.rough_xyz_mm, self.rough_zyx_deg)


class SensorMount(Inputs):
    """The ``[sensor]`` table of data/selfcal/scenario.toml."""

    design_xyz_mm: Vec3
    design_zyx_deg: Annotated[list[Degrees], Field(min_length=3, max_length=3)]
    sigma_mm: NonNegativeFinite
    sigma_deg: AngleSigma

    @cached_property
    def design(self) -> np.ndarray:
        """``sensor2flange`` (4, 4) of the bracket drawing, mm."""
        return zyx_pose(self.design_xyz_mm, self.design_zyx_deg)


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
    sigma_point_mm: noise_level(NOISE_BOUNDS, "point_mm")
    max_fit_condition: Annotated[float, Field(ge=1, allow_inf_nan=False)]


class Tracker(Inputs):
    """The ``[tracker]`` table of data/selfcal/scenario.toml."""

    u0_mm: noise_level(NOISE_BOUNDS, "tracker_mm")
    u1_mm_per_m: noise_level(NOISE_BOUNDS, "tracker_mm_per_m")
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
    link_masses_kg: Annotated[list[NonNegativeFinite], Field(min_length=6, max_length=6)] = [
        0.0
    ] * 6
    arm_weight_fraction: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = 0.0
    arm_weight_sweep: list[Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]] = [0.0]
    stiffness_nm_per_rad: Annotated[list[PositiveFinite], Field(min_length=6, max_length=6)]
    scale: NonNegativeFinite
    sweep_scales: Annotated[list[NonNegativeFinite], Field(min_length=1)]


class Published(Documented):
    """The ``[published]`` table of data/selfcal/scenario.toml."""

    convergence_iterations: PositiveInt


class Scenario(Ledgered, Inputs):
    """The simulated cell of ``data/selfcal/scenario.toml`` (or a copy describing yours),
    validated: every table as in the file (mm, degrees where a key says ``_deg``), each input
    with its provenance (:mod:`calstudy.core.ledger`).

    Besides the cell, it carries the paper's published numbers the verdicts test against:
    ``protocol.requirement_mm`` (the 0.42 mm body-in-white requirement) and
    ``published.convergence_iterations`` (LM converges within 4 iterations, Fig. 5);
    ``compliance.scale`` switches the unmodelled joint compliance under the payload (0: the
    true robot lies in the model class). Frozen: a changed copy is
    :func:`calstudy.core.schema.with_inputs` (validated again; never ``model_copy(update=...)``,
    which would keep the cached :attr:`nominal_robot`).
    """

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

    @cached_property
    def nominal_robot(self) -> Robot:
        """The robot table ``robot`` names (:func:`calstudy.models.robots.load_robot`)."""
        return load_robot(self.robot)

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
        self._check_reach()

    def _check_reach(self) -> None:
        """Refuse a sphere envelope that the robot reaches from none of its points.

        A view puts the scanner within ``sqrt((standoff + depth)^2 + 2 field^2)`` of the
        sphere's centre, and the robot's wrist point within ``|sensor_design^-1 c|`` of the
        scanner (:class:`~calstudy.models.reach.ReachBound`; the views are planned with the
        design mount). Every point of the envelope lies at least ``|clip(C) - C| - r`` from the
        shoulder circle (centre ``C``, radius ``r``); when that exceeds the reach plus both
        offsets, no placement of a sphere in the envelope can be measured. Microseconds, before
        any simulation. The message names ``spheres.envelope_min_mm`` and ``envelope_max_mm``,
        their values and by how much the envelope's nearest point misses the reach.
        """
        bound = reach_bound(self.nominal_robot)
        lo = np.array(self.spheres.envelope_min_mm, float)
        hi = np.array(self.spheres.envelope_max_mm, float)
        nearest = np.clip(bound.centre, lo, hi)
        wrist = np.linalg.inv(self.sensor.design) @ np.append(bound.wrist, 1.0)
        scanner = self.scanner
        view = math.hypot(scanner.standoff_mm + scanner.depth_mm, math.sqrt(2) * scanner.field_mm)
        slack = view + float(np.linalg.norm(wrist[:3]))
        beyond = float(np.linalg.norm(nearest - bound.centre)) - bound.radius - bound.reach - slack
        if beyond > bound.margin_mm():
            raise ValueError(
                f"spheres.envelope_min_mm = {lo.tolist()}, envelope_max_mm = {hi.tolist()}: from "
                f"the envelope's nearest point the robot's wrist stays at least {beyond:.0f} mm "
                "beyond its reach, for every view at the scanner's standoff: no sphere placed "
                "there can be measured"
            )


def load_scenario(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> Scenario:
    """Read the scenario (default ``data/selfcal/scenario.toml``); see the file for sources.

    Parameters
    ----------
    path : str or Path, optional
        The scenario file; default (None or ``""``) the paper's.
    overrides : mapping of str to object, optional
        Dotted keys of the file and their values (``{"scanner.sigma_point_mm": 0.05}``, the
        file's units), applied before validation: a value outside its ledger range is refused
        as in the file (:func:`calstudy.core.schema.apply_overrides`).

    Returns
    -------
    Scenario
        The validated, frozen scenario.

    Raises
    ------
    FileNotFoundError
        If the file (or the robot table it names) does not exist.
    CalibrationError
        If the file is not valid TOML, an override names no input, or the table breaks
        :class:`Scenario`: a missing or unknown key, a value out of range (a negative radius,
        ``views_per_sphere = 0``), an envelope that is not a box or beyond the robot's reach;
        the message names the file, the key, the value and the allowed range.
    """
    return load_paper_file(
        "selfcal", "scenario.toml", Scenario, "selfcal scenario", path, overrides
    )



__all__ = ["NOISE_BOUNDS", "Scenario", "load_scenario"]
