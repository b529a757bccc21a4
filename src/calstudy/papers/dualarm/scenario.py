"""The dual-arm scanning station of the ``dualarm`` paper, and the paper's published numbers.

:func:`load_scenario` reads ``data/dualarm/scenario.toml`` (cameras, markers of Table A1,
transforms of Table A2, noise and the experiments' geometry, each entry naming its source or
assumption); :func:`load_published` reads ``data/dualarm/published.toml`` (the results of
Section 4 and Tables 1-3). Both go through :mod:`calstudy.core.config`, so a missing file or key
is reported as in every paper; the scenario is checked on load against
:mod:`calstudy.papers.dualarm.schema` (types, ranges, required keys, cross-field rules).

Frames follow the study's naming: ``cam2flange`` maps left-camera points to the flange,
``world2base`` the marker (world) frame to a robot base, ``base2_to_base1`` base 2 to base 1.
Millimetres and radians (the files hold degrees where a key says so).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.config import require, scenario_file
from calstudy.core.schema import (
    apply_overrides,
    check_toml,
    is_study_file,
    read_toml,
    validate,
    without_provenance,
)
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig, stereo_rig
from calstudy.papers.dualarm.schema import PublishedFile, ScenarioFile

PAPER = "dualarm"
#: the two arms, numbered as in the paper
ARMS = (1, 2)
#: the two standard spheres of Section 4.1
SPHERES = ("A", "B")


@dataclass(frozen=True)
class Scenario:
    """Everything the simulated station is made of (read from ``data/dualarm/scenario.toml``).

    Lengths in mm, angles in rad, pixels in px. ``cam2flange[a]``, ``world2base[a]`` are the
    true transforms of arm ``a + 1``.
    """

    rig: StereoRig
    markers: np.ndarray
    marker_names: tuple
    marker_group: np.ndarray
    cam2flange: np.ndarray
    world2base: np.ndarray
    base2_to_base1: np.ndarray
    point_sigma_mm: float
    points_per_scan: int
    max_incidence: float
    working_distance_mm: float
    sigma_px: float
    marker_radius_mm: float
    circle_radius_mm: float
    marker_sigma_mm: float
    loss_rate: float
    max_view_angle: float
    repeat_sigma_mm: float
    repeat_sigma_rad: float
    drift_step_mm: float
    drift_step_rad: float
    sphere_radius: dict
    plate_points: np.ndarray
    handeye_poses: int
    handeye_tilt: float
    handeye_roll: float
    survey_views_per_group: int
    survey_bridge_views: int
    survey_bridge_distance_mm: float
    survey_bridge_tilt: float
    survey_bridge_roll: float
    survey_tilt: float
    min_shared_markers: int
    global_groups: int
    global_poses: int
    calibration_poses: int
    placement_offsets_mm: tuple
    stand_height_mm: float
    plate_tilt: float
    plate_jitter: float
    plate_offset_mm: tuple
    plate_outlier_rate: float
    plate_outlier_px: tuple
    ransac_threshold_px: float
    icp_z_weight: float
    icp_z_threshold_mm: float
    icp_max_iterations: int
    icp_max_pair_mm: float
    icp_views: int
    icp_tilt: float
    icp_sphere_offset_mm: float

    def replace(self, **changes) -> Scenario:
        """A copy with some fields changed (e.g. all noise set to 0)."""
        return dataclasses.replace(self, **changes)

    def noise_free(self) -> Scenario:
        """The same station with exact detections (no noise, no perspective bias of the circle
        centres), sensor, robot poses and no marker losses."""
        return self.replace(
            point_sigma_mm=0.0,
            sigma_px=0.0,
            marker_radius_mm=0.0,
            circle_radius_mm=0.0,
            loss_rate=0.0,
            repeat_sigma_mm=0.0,
            repeat_sigma_rad=0.0,
            drift_step_mm=0.0,
            drift_step_rad=0.0,
            plate_outlier_rate=0.0,
        )

    def group_centre(self, arm: int) -> np.ndarray:
        """Centroid ``(3,)`` of the marker group arm ``arm`` (1 or 2) sees, world frame."""
        return self.markers[self.marker_group == arm - 1].mean(axis=0)


def _pose(rotvec, translation) -> np.ndarray:
    return geo.make_transform(geo.rotvec_to_matrix(rotvec), translation)


def _rig(d: dict, src: Path) -> StereoRig:
    """The binocular sensor of ``[camera]`` and ``[stereo]``."""
    cam, st = require(d, "camera", src), require(d, "stereo", src)
    camera = PinholeCamera(
        fx=require(cam, "fx_px", src),
        fy=require(cam, "fy_px", src),
        cx=require(cam, "cx_px", src),
        cy=require(cam, "cy_px", src),
        width=require(cam, "width", src),
        height=require(cam, "height", src),
    )
    baseline, convergence = (
        require(st, "baseline_mm", src),
        require(st, "convergence_distance_mm", src),
    )
    return stereo_rig(camera, baseline, convergence)


def _markers(d: dict, src: Path) -> dict:
    """Table A1: ``markers``, ``marker_names`` and ``marker_group`` (0 or 1 per marker)."""
    names = tuple(require(d, "markers.names", src))
    groups = require(d, "markers.groups", src)
    return dict(
        markers=np.asarray(require(d, "markers.xyz_mm", src), dtype=float),
        marker_names=names,
        marker_group=np.array([groups.index(n.split("-")[0]) for n in names]),
    )


def _transforms(d: dict, src: Path) -> dict:
    """Table A2 and the layout: ``cam2flange``, ``world2base``, ``base2_to_base1``."""
    c = require(d, "calibration", src)
    cam2flange = np.stack(
        [
            _pose(require(c, f"cam2flange_{a}_rotvec", src), require(c, f"cam2flange_{a}_mm", src))
            for a in ARMS
        ]
    )
    b2b1 = _pose(require(c, "base2_to_base1_rotvec", src), require(c, "base2_to_base1_mm", src))
    w2b1 = _pose(
        require(d, "layout.world2base1_rotvec", src), require(d, "layout.world2base1_mm", src)
    )
    return dict(
        cam2flange=cam2flange,
        world2base=np.stack([w2b1, geo.invert(b2b1) @ w2b1]),
        base2_to_base1=b2b1,
    )


def _plate_points(d: dict, src: Path) -> np.ndarray:
    """Circle centres ``(rows * cols, 3)`` of the calibration plate, plate frame (z = 0)."""
    rows, cols, pitch = (
        require(d, f"handeye.{k}", src) for k in ("grid_rows", "grid_cols", "pitch_mm")
    )
    gx, gy = np.meshgrid(
        (np.arange(cols) - (cols - 1) / 2) * pitch, (np.arange(rows) - (rows - 1) / 2) * pitch
    )
    return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])


#: Scenario field -> (dotted key in scenario.toml, True if the file holds degrees).
_SCALARS = {
    "point_sigma_mm": ("sensor.point_sigma_mm", False),
    "points_per_scan": ("sensor.points_per_scan", False),
    "max_incidence": ("sensor.max_incidence_deg", True),
    "working_distance_mm": ("sensor.working_distance_mm", False),
    "sigma_px": ("detection.sigma_px", False),
    "marker_sigma_mm": ("detection.marker_sigma_mm", False),
    "marker_radius_mm": ("detection.marker_radius_mm", False),
    "circle_radius_mm": ("handeye.circle_radius_mm", False),
    "loss_rate": ("detection.loss_rate", False),
    "max_view_angle": ("detection.max_view_angle_deg", True),
    "repeat_sigma_mm": ("robot.repeat_sigma_mm", False),
    "repeat_sigma_rad": ("robot.repeat_sigma_deg", True),
    "drift_step_mm": ("robot.drift_step_sigma_mm", False),
    "drift_step_rad": ("robot.drift_step_sigma_deg", True),
    "handeye_poses": ("handeye.n_poses", False),
    "handeye_tilt": ("handeye.tilt_deg", True),
    "handeye_roll": ("handeye.roll_deg", True),
    "survey_views_per_group": ("survey.views_per_group", False),
    "survey_bridge_views": ("survey.bridge_views", False),
    "survey_bridge_distance_mm": ("survey.bridge_distance_mm", False),
    "survey_bridge_tilt": ("survey.bridge_tilt_deg", True),
    "survey_bridge_roll": ("survey.bridge_roll_deg", True),
    "survey_tilt": ("survey.tilt_deg", True),
    "min_shared_markers": ("survey.min_shared_markers", False),
    "global_groups": ("global_test.n_groups", False),
    "global_poses": ("global_test.n_poses", False),
    "calibration_poses": ("global_test.calibration_poses", False),
    "stand_height_mm": ("global_test.stand_height_mm", False),
    "plate_tilt": ("circular_plate.tilt_deg", True),
    "plate_jitter": ("circular_plate.jitter_deg", True),
    "plate_outlier_rate": ("circular_plate.outlier_rate", False),
    "ransac_threshold_px": ("circular_plate.ransac_threshold_px", False),
    "icp_z_weight": ("icp.z_weight", False),
    "icp_z_threshold_mm": ("icp.z_threshold_mm", False),
    "icp_max_iterations": ("icp.max_iterations", False),
    "icp_max_pair_mm": ("icp.max_pair_distance_mm", False),
    "icp_views": ("icp.n_views", False),
    "icp_tilt": ("icp.tilt_deg", True),
    "icp_sphere_offset_mm": ("icp.sphere_offset_mm", False),
}


def load_scenario(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> Scenario:
    """Read the station from ``data/dualarm/scenario.toml`` (or ``path``).

    Parameters
    ----------
    path : path-like, optional
        A scenario file of one's own (same keys).
    overrides : mapping of str to object, optional
        Inputs set by their dotted keys (``{"detection.sigma_px": 0.05}``) before the file is
        validated, so that a value outside the input's ledger range is refused.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    CalibrationError
        If it is not valid TOML or breaks :class:`~calstudy.papers.dualarm.schema.ScenarioFile`:
        a missing or unknown key, a value out of range (``loss_rate = 1.5``, ``points_per_scan
        = -500``), markers without a group; the message names the file, the key, the value and
        the allowed range. An override naming no input is refused with its key.
    """
    src = scenario_file(PAPER, "scenario.toml", path)
    if overrides:
        table = apply_overrides(read_toml(src, "dualarm scenario"), overrides)
        validate(ScenarioFile, table, src, study=is_study_file(src))
        d = without_provenance(table)
    else:
        d = check_toml(src, ScenarioFile, "dualarm scenario")
    scalars = {}
    for field, (key, degrees) in _SCALARS.items():
        value = require(d, key, src)
        scalars[field] = np.deg2rad(value) if degrees else value
    return Scenario(
        rig=_rig(d, src),
        **_markers(d, src),
        **_transforms(d, src),
        sphere_radius={
            "A": require(d, "spheres.diameter_a_mm", src) / 2,
            "B": require(d, "spheres.diameter_b_mm", src) / 2,
        },
        plate_points=_plate_points(d, src),
        placement_offsets_mm=tuple(require(d, "global_test.placement_offsets_mm", src)),
        plate_outlier_px=tuple(require(d, "circular_plate.outlier_px", src)),
        plate_offset_mm=tuple(require(d, "circular_plate.offset_mm", src)),
        **scalars,
    )


# ----------------------------------------------------------------------------------------------
# the paper's numbers


@dataclass(frozen=True)
class Published:
    """The paper's results (``data/dualarm/published.toml``), mm.

    Attributes
    ----------
    icp_rows : list
        Section 4.1: ``[arm, sphere, before, after]`` mean centre errors of the multi-view fits.
    table1_rows : list
        Table 1: ``[group, dx, dy, dz]`` (group 0: all groups).
    table2_rows : list
        Table 2: ``[group, pose 1, pose 2, pose 3]`` (group 0: all groups).
    table2_overall : float
        The overall mean Euclidean error the text gives (about 0.100 mm).
    table3_methods : list of str
        Table 3's global calibration methods.
    table3_rows : list
        Table 3: ``[dx, dy, dz, euclid]`` per method.
    """

    icp_rows: list
    table1_rows: list
    table2_rows: list
    table2_overall: float
    table3_methods: list
    table3_rows: list


#: Published field -> dotted key in published.toml.
_PUBLISHED = {
    "icp_rows": "icp.rows",
    "table1_rows": "table1.rows",
    "table2_rows": "table2.rows",
    "table2_overall": "table2.overall",
    "table3_methods": "table3.methods",
    "table3_rows": "table3.rows",
}


def load_published(path: str | Path | None = None) -> Published:
    """The paper's numbers, ``data/dualarm/published.toml`` (or ``path``).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    CalibrationError
        If it is not valid TOML or breaks :class:`~calstudy.papers.dualarm.schema.PublishedFile`
        (a missing or unknown key, a negative error, a group or an arm-sphere pair given twice,
        methods and rows that differ in number).
    """
    src = scenario_file(PAPER, "published.toml", path)
    d = check_toml(src, PublishedFile, "dualarm published results")
    return Published(**{field: require(d, key, src) for field, key in _PUBLISHED.items()})
