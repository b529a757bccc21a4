"""The eye-in-hand binocular station of notebook 04 (binocular paper, Section 4) and its
published numbers.

A KUKA KR 210 (nominal model from ``data/robots/kuka_kr210.toml``) carries the binocular sensor
of Table 1 (``sensor.toml``) and observes the multi-target calibrator of Table 2
(``calibrator.toml``) from about 850 mm; ``station.toml`` holds the hand-eye matrix, the
calibrator's place, the poses and the field regions of Section 4.3. Assumptions are in those
files with their reasons and provenance; :class:`Scenario` holds the three validated files and
derives the rig, the layout and the frames from them. The paper's own numbers (Tables 2-5,
Fig. 13) are the ``[published]`` tables of the same files, read by :func:`published`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cached_property
from pathlib import Path

import numpy as np
from pydantic import ConfigDict

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import scenario_file
from calstudy.core.schema import (
    Schema,
    apply_overrides,
    is_study_file,
    load_paper_file,
    read_toml,
    validate,
)
from calstudy.estimators.binocular import solve_calibrator_layout
from calstudy.models import optics
from calstudy.models.kinematics import Robot
from calstudy.models.reach import reach_bound
from calstudy.models.robots import load_robot
from calstudy.models.stereo import StereoRig
from calstudy.papers.binocular.schema import SCHEMAS, CalibratorFile, SensorFile, StationFile

PAPER = "binocular"
#: The files of a scenario folder (``data/binocular`` or your own).
TABLES = ("sensor", "calibrator", "station")
#: largest miss of a solved calibrator layout on a standard distance, mm
LAYOUT_RESIDUAL_MM = 1e-6


class Scenario(Schema):
    """Everything fixed of the station: the three validated files of a scenario folder (sensor
    of Table 1, calibrator, station) and the nominal robot the station names.

    Derived (computed once): :attr:`rig`, :attr:`layout` and :attr:`layout_residual`,
    :attr:`sensor2flange`, :attr:`calibrator2base` and the optics. Lengths in mm.
    """

    model_config = ConfigDict(arbitrary_types_allowed=True)

    sensor: SensorFile
    calibrator: CalibratorFile
    station: StationFile
    #: nominal robot model (``data/robots/<station.robot.model>.toml``)
    robot: Robot

    @cached_property
    def rig(self) -> StereoRig:
        """The calibrated sensor of Table 1 (sensor frame: the left camera)."""
        s = self.sensor
        cameras = (s.left.pinhole(s.image), s.right.pinhole(s.image))
        return StereoRig.from_left2right(*cameras, s.extrinsic.left2right)

    @cached_property
    def layout_solution(self) -> tuple[np.ndarray, np.ndarray]:
        """P1-P8 ``(8, 3)`` in the calibrator frame, mm, and their distances to P7 minus
        Table 2's ``(7,)`` (:func:`calstudy.estimators.binocular.solve_calibrator_layout`)."""
        standard = self.calibrator.standard
        return solve_calibrator_layout(standard.distance_mm, standard.start_angle_deg)

    @property
    def layout(self) -> np.ndarray:
        """P1-P8 ``(8, 3)`` in the calibrator frame, mm."""
        return self.layout_solution[0]

    @property
    def layout_residual(self) -> np.ndarray:
        """The layout's distances to P7 minus Table 2's ``(7,)``, mm."""
        return self.layout_solution[1]

    @cached_property
    def sensor2flange(self) -> np.ndarray:
        """The true hand-eye matrix ``H_gc`` ``(4, 4)``, its rotation projected onto SO(3)."""
        h = np.array(self.station.handeye.matrix, dtype=float)
        h[:3, :3] = geo.project_to_so3(h[:3, :3])
        return h

    @cached_property
    def calibrator2base(self) -> np.ndarray:
        """The calibrator frame ``(4, 4)`` (origin P7, z along the plate normal) in the base
        frame: P7 at the tracker's distance from the base origin and the given height, the
        plate facing the robot, tilted upwards."""
        c = self.station.calibrator
        height = c.p7_height_mm
        p7 = np.array([math.sqrt(c.p7_distance_mm**2 - height**2), 0.0, height])
        tilt = math.radians(c.plate_tilt_deg)
        return plate_frame(p7, np.array([-math.cos(tilt), 0.0, math.sin(tilt)]))

    @property
    def focal_mm(self) -> float:
        """Focal length of the left camera, mm, by the thin-lens equation.

        ``fx`` times the pixel pitch is the lens-to-sensor distance ``v`` of a lens focused at
        ``d_A`` (``sensor.toml [optics] focus_distance_mm``), not the focal length:
        ``1/f = 1/v + 1/d_A``, ``f = v d_A / (v + d_A)``.
        """
        v = float(self.rig.left.fx * self.sensor.image.pixel_pitch_mm)
        d_a = float(self.sensor.optics.focus_distance_mm)
        return v * d_a / (v + d_a)

    @property
    def dot_radius_mm(self) -> float:
        """Radius of an SBR's retro-reflective dot, mm."""
        return 0.5 * self.calibrator.sbr.dot_diameter_mm

    @property
    def detection(self) -> dict:
        """Keyword arguments of :func:`calstudy.estimators.coc.detect_centre` (``[detection]``)."""
        det = self.sensor.detection
        return {"low": det.canny_low, "high": det.canny_high, "min_points": det.min_edge_points}

    def coc_radius_px(self, depth_mm):
        """Circle-of-confusion radius (Eq. 4), px, of points at ``depth_mm`` (scalar or array)
        from a camera with the optics of ``sensor.toml``."""
        opt = self.sensor.optics
        return optics.coc_radius_px(
            depth_mm,
            opt.focus_distance_mm,
            self.focal_mm,
            opt.f_number,
            self.sensor.image.pixel_pitch_mm,
        )


def plate_frame(centre, normal) -> np.ndarray:
    """Frame ``(4, 4)`` with origin ``centre`` (mm) and z along ``normal`` (x horizontal)."""
    z = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    return geo.make_transform(np.column_stack([x, np.cross(z, x), z]), centre)


def scenario_files(path: str | Path | None = None) -> dict[str, Path]:
    """``{"sensor": ..., "calibrator": ..., "station": ...}``: the files of the folder ``path``,
    default ``data/binocular`` (NotADirectoryError if ``path`` is a file)."""
    own = None if path in (None, "") else Path(path)
    if own is not None and own.exists() and not own.is_dir():
        raise NotADirectoryError(
            f"{own}: not a folder; a scenario folder holds {', '.join(f'{n}.toml' for n in TABLES)}"
        )
    return {n: scenario_file(PAPER, f"{n}.toml", own and own / f"{n}.toml") for n in TABLES}


def load_scenario(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> Scenario:
    """The station of ``data/binocular/*.toml`` and the robot ``data/robots/<model>.toml``
    named in ``station.toml [robot]`` (the KR 210 by default).

    Parameters
    ----------
    path : str or Path, optional
        A folder with your own ``sensor.toml``, ``calibrator.toml`` and ``station.toml`` (same
        keys as those of ``data/binocular``) to use in their place.
    overrides : mapping of str to object, optional
        Dotted keys, the file's name first (``{"sensor.optics.f_number": 5.6}``), and the values
        to read in their place; each is validated as if the file held it.

    Returns
    -------
    Scenario
        The validated, frozen station.

    Raises
    ------
    FileNotFoundError
        If a file is missing.
    NotADirectoryError
        If ``path`` is a file.
    CalibrationError
        If a file is not valid TOML or breaks its schema (:mod:`calstudy.papers.binocular.
        schema`: a missing or unknown key, a value out of range, a matrix that is not a
        rotation, standard distances that admit no calibrator layout; the message names the
        file, the key, the value and the allowed range), if an override names no input, if the
        layout solved from ``start_angle_deg`` misses a standard distance by more than
        :data:`LAYOUT_RESIDUAL_MM`, or if the robot cannot reach the views (:func:`check_reach`).
    """
    files = scenario_files(path)
    raw = {name: read_toml(file, f"binocular {name} table") for name, file in files.items()}
    raw = apply_overrides(raw, overrides)
    tables = {
        name: validate(SCHEMAS[name], raw[name], file, study=is_study_file(file))
        for name, file in files.items()
    }
    robot = load_robot(tables["station"].robot.model)
    scenario = Scenario(**tables, robot=robot)
    standard = scenario.calibrator.standard
    worst = int(np.argmax(np.abs(scenario.layout_residual)))
    if abs(scenario.layout_residual[worst]) > LAYOUT_RESIDUAL_MM:
        raise CalibrationError(
            f"{files['calibrator']}: standard.start_angle_deg = {standard.start_angle_deg}: "
            f"the layout solved from these angles misses {standard.names[worst]} by "
            f"{scenario.layout_residual[worst]:.3g} mm (allowed {LAYOUT_RESIDUAL_MM:g}); the "
            "distances admit a layout: start from other angles"
        )
    check_reach(scenario, files["station"])
    return scenario


def check_reach(scenario: Scenario, source: str | Path = "station.toml") -> None:
    """Refuse a station whose robot cannot reach any of the views of a target.

    The views of a target (the calibrator, each field region) put the sensor at
    ``observation_distance_mm +- distance_spread_mm`` from it, within ``cone_deg`` of its
    normal, turned by any roll: every sensor origin then lies within ``|mid| + spread +
    2 d sin(cone / 2)`` of the central one (``mid`` the sensor frame's offset from the baseline
    midpoint the views aim from) and the robot's wrist point within ``|sensor2flange^-1 c|`` of
    the sensor origin (:class:`~calstudy.models.reach.ReachBound`). When even the nearest such
    wrist point lies beyond the arm's reach, no view of that target is reachable: the check
    costs microseconds and runs before any simulation.

    Parameters
    ----------
    scenario : Scenario
        The loaded station.
    source : str or Path
        The station file, for the message.

    Raises
    ------
    CalibrationError
        Naming ``poses.observation_distance_mm`` and its value, the target and by how much the
        nearest view misses the reach.
    """
    poses, field = scenario.station.poses, scenario.station.field
    d, spread = float(poses.observation_distance_mm), float(poses.distance_spread_mm)
    bound = reach_bound(scenario.robot)
    aim1, aim2 = scenario.rig.aim_point(1.0), scenario.rig.aim_point(2.0)
    mid = 2.0 * aim1 - aim2
    wrist = geo.invert(scenario.sensor2flange) @ np.append(bound.wrist, 1.0)
    slack = (
        float(np.linalg.norm(mid)) + spread + 2.0 * d * math.sin(math.radians(poses.cone_deg) / 2.0)
    )
    slack += float(np.linalg.norm(wrist[:3]))
    targets = [("the calibrator", scenario.calibrator2base)]
    for name, centre in zip(field.regions, field.centres_mm, strict=True):
        normal = np.array(field.faces_point_mm, dtype=float) - np.array(centre, float)
        targets.append((f"field region {name!r}", plate_frame(np.array(centre, float), normal)))
    for what, target2base in targets:
        central = target2base[:3, 3] + d * target2base[:3, 2]
        rel = central - bound.centre
        h = float(rel @ bound.axis)
        rho = math.sqrt(max(float(rel @ rel) - h * h, 0.0))
        beyond = math.hypot(rho - bound.radius, h) - bound.reach - slack
        if beyond > bound.margin_mm():
            raise CalibrationError(
                f"{source}: poses.observation_distance_mm = {poses.observation_distance_mm}: "
                f"every view of {what} at that distance puts the robot's wrist at least "
                f"{beyond:.0f} mm beyond its reach ({bound.reach:.0f} mm from the shoulder "
                "circle): the robot cannot hold the sensor there"
            )


def paper_table(name: str) -> SensorFile | CalibratorFile | StationFile:
    """``data/binocular/<name>.toml`` as the paper gives it (never a scenario folder of yours),
    validated against its schema (its ``[published]`` table too).

    Raises
    ------
    CalibrationError
        If ``name`` is not one of :data:`TABLES`, or the file breaks its schema.
    """
    if name not in SCHEMAS:
        raise CalibrationError(f"no binocular table {name!r}; the tables are {', '.join(TABLES)}")
    # kept by its file key
    return load_paper_file(PAPER, f"{name}.toml", SCHEMAS[name], f"binocular {name} table")


def published(name: str, key: str):
    """A published value from ``data/binocular/<name>.toml [published]``; CalibrationError
    naming the file and the key if the table has no such value."""
    table = getattr(paper_table(name), "published", None)
    if table is None or key not in type(table).model_fields:
        raise CalibrationError(f"data/binocular/{name}.toml: no value 'published.{key}'")
    return getattr(table, key)


__all__ = [
    "Scenario",
    "check_reach",
    "load_scenario",
    "paper_table",
    "plate_frame",
    "published",
    "scenario_files",
]
