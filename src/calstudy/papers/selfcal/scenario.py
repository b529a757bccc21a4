"""The simulated cell of the ``selfcal`` paper and its published numbers, from ``data/selfcal/``.

:func:`load_scenario` reads ``data/selfcal/scenario.toml`` (or a copy describing your own cell)
and the robot table it names under ``data/robots/``; every number there names its source in the
paper or says why it is assumed. Lengths in mm and angles in rad once loaded (degrees in the file).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from calstudy.core.config import require, scenario_file
from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import euler_zyx_to_matrix, make_transform
from calstudy.core.schema import check_toml
from calstudy.models.kinematics import Robot
from calstudy.models.reach import reach_bound
from calstudy.models.robots import load_robot
from calstudy.papers.selfcal.schema import ScenarioFile


@dataclass(frozen=True)
class Scenario:
    """Everything the simulation draws from, read from ``data/selfcal/scenario.toml``.

    Besides the cell, it carries the paper's published numbers the verdicts test against:
    ``requirement_mm`` (the 0.42 mm body-in-white requirement) and ``published_iterations``
    (LM converges within 4 iterations, Fig. 5); ``compliance_scale`` switches the unmodelled
    joint compliance under the payload (0: the true robot lies in the model class).
    """

    robot: Robot
    repeatability_mm: float
    base_rough: np.ndarray
    base_sigma: tuple[float, float]
    sensor_design: np.ndarray
    sensor_sigma: tuple[float, float]
    poor: dict
    n_spheres: int
    radius_mm: float
    min_separation_mm: float
    envelope: tuple[np.ndarray, np.ndarray]
    standoff_mm: float
    field_mm: float
    depth_mm: float
    view_cone_rad: float
    roll_deg: float
    cap_half_angle_rad: float
    points_per_cap: int
    sigma_point_mm: float
    max_cap_condition: float
    tracker: tuple[float, float, float]
    views_per_sphere: int
    n_validation: int
    requirement_mm: float
    published_iterations: int
    payload_kg: float
    joint_stiffness: tuple[float, ...]
    compliance_scale: float
    compliance_sweep: tuple[float, ...]
    basin_scales: tuple[float, ...]
    crb_multiple: float

    def with_(self, **changes) -> Scenario:
        """A copy with some fields changed (e.g. ``sigma_point_mm=0`` for noise-free data)."""
        return replace(self, **changes)


_POOR_KEYS = (
    "base_mm",
    "base_deg",
    "sensor_mm",
    "sensor_deg",
    "robot_length_mm",
    "robot_angle_deg",
)


def _pose(xyz, zyx_deg) -> np.ndarray:
    return make_transform(euler_zyx_to_matrix(*zyx_deg), np.asarray(xyz, float))


def load_scenario(path: str | Path | None = None) -> Scenario:
    """Read the scenario (default ``data/selfcal/scenario.toml``); see the file for sources.

    Raises
    ------
    FileNotFoundError
        If the file (or the robot table it names) does not exist.
    CalibrationError
        If the file is not valid TOML or breaks :class:`~calstudy.papers.selfcal.schema.
        ScenarioFile`: a missing or unknown key, a value out of range (a negative radius,
        ``views_per_sphere = 0``), an envelope that is not a box; the message names the file,
        the key, the value and the allowed range.
    """
    path = scenario_file("selfcal", "scenario.toml", path)
    t = check_toml(path, ScenarioFile, "selfcal scenario")

    def get(key: str):
        return require(t, key, path)

    scenario = Scenario(
        robot=load_robot(get("robot")),
        repeatability_mm=float(get("repeatability.sigma_mm")),
        base_rough=_pose(get("base.rough_xyz_mm"), get("base.rough_zyx_deg")),
        base_sigma=(float(get("base.sigma_mm")), math.radians(get("base.sigma_deg"))),
        sensor_design=_pose(get("sensor.design_xyz_mm"), get("sensor.design_zyx_deg")),
        sensor_sigma=(float(get("sensor.sigma_mm")), math.radians(get("sensor.sigma_deg"))),
        poor={k: float(v) for k, v in get("poor_start").items() if k in _POOR_KEYS},
        basin_scales=tuple(float(v) for v in get("poor_start.basin_scales")),
        n_spheres=int(get("spheres.count")),
        radius_mm=float(get("spheres.radius_mm")),
        min_separation_mm=float(get("spheres.min_separation_mm")),
        envelope=(
            np.array(get("spheres.envelope_min_mm"), float),
            np.array(get("spheres.envelope_max_mm"), float),
        ),
        standoff_mm=float(get("scanner.standoff_mm")),
        field_mm=float(get("scanner.field_mm")),
        depth_mm=float(get("scanner.depth_mm")),
        view_cone_rad=math.radians(get("scanner.view_cone_deg")),
        roll_deg=float(get("scanner.roll_deg")),
        cap_half_angle_rad=math.radians(get("scanner.cap_half_angle_deg")),
        points_per_cap=int(get("scanner.points_per_cap")),
        sigma_point_mm=float(get("scanner.sigma_point_mm")),
        max_cap_condition=float(get("scanner.max_fit_condition")),
        tracker=(
            float(get("tracker.u0_mm")),
            float(get("tracker.u1_mm_per_m")),
            float(get("tracker.coverage")),
        ),
        views_per_sphere=int(get("protocol.views_per_sphere")),
        n_validation=int(get("protocol.validation_placements")),
        requirement_mm=float(get("protocol.requirement_mm")),
        published_iterations=int(get("published.convergence_iterations")),
        payload_kg=float(get("compliance.payload_kg")),
        joint_stiffness=tuple(float(k) for k in get("compliance.stiffness_nm_per_rad")),
        compliance_scale=float(get("compliance.scale")),
        compliance_sweep=tuple(float(v) for v in get("compliance.sweep_scales")),
        crb_multiple=float(get("protocol.crb_multiple")),
    )
    check_reach(scenario, path)
    return scenario


def check_reach(scenario: Scenario, source: str | Path = "scenario.toml") -> None:
    """Refuse a sphere envelope that the robot reaches from none of its points.

    A view puts the scanner within ``sqrt((standoff + depth)^2 + 2 field^2)`` of the sphere's
    centre, and the robot's wrist point within ``|sensor_design^-1 c|`` of the scanner
    (:class:`~calstudy.models.reach.ReachBound`; the views are planned with the design mount).
    Every point of the envelope lies at least ``|clip(C) - C| - r`` from the shoulder circle
    (centre ``C``, radius ``r``); when that exceeds the reach plus both offsets, no placement
    of a sphere in the envelope can be measured. Microseconds, before any simulation.

    Parameters
    ----------
    scenario : Scenario
        The loaded cell.
    source : str or Path
        The scenario file, for the message.

    Raises
    ------
    CalibrationError
        Naming ``spheres.envelope_min_mm`` and ``envelope_max_mm``, their values and by how
        much the envelope's nearest point misses the reach.
    """
    bound = reach_bound(scenario.robot)
    lo, hi = scenario.envelope
    nearest = np.clip(bound.centre, lo, hi)
    wrist = np.linalg.inv(scenario.sensor_design) @ np.append(bound.wrist, 1.0)
    view = math.hypot(scenario.standoff_mm + scenario.depth_mm, math.sqrt(2) * scenario.field_mm)
    slack = view + float(np.linalg.norm(wrist[:3]))
    beyond = float(np.linalg.norm(nearest - bound.centre)) - bound.radius - bound.reach - slack
    if beyond > bound.margin_mm():
        raise CalibrationError(
            f"{source}: spheres.envelope_min_mm = {lo.tolist()}, envelope_max_mm = "
            f"{hi.tolist()}: from the envelope's nearest point the robot's wrist stays at least "
            f"{beyond:.0f} mm beyond its reach, for every view at the scanner's standoff: no "
            "sphere placed there can be measured"
        )
