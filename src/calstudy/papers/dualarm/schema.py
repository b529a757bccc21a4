"""The dual-arm scanning station of the ``dualarm`` paper (notebook 05), as validated from its
``scenario.toml`` (or a copy describing yours): :class:`Scenario`, and the paper's numbers,
:class:`PublishedFile`.

The validated file is the station: each table keeps its inputs as the file gives them (lengths
mm, angles degrees where the key says ``_deg``, rotation vectors rad), each input's provenance
beside it (:mod:`calstudy.core.ledger`), and derives what the simulation uses: the stereo rig,
the markers and transforms as arrays, angles in radians. Frames follow the study's naming:
``cam2flange`` maps left-camera points to the flange, ``world2base`` the marker (world) frame to
a robot base, ``base2_to_base1`` base 2 to base 1.

Checked on load (:func:`calstudy.core.schema.load_model`): every key read must be there with its
type and range (lengths mm, angles degrees where the key says ``_deg``, rotation vectors rad),
unknown keys are refused, and the cross-field rules below hold (one position per marker name,
every marker in a declared group, a principal point inside the image, an outlier range that is
a range), and the station can exist (:meth:`Scenario.plausibility`: stereo cameras that
converge at a workable angle, spheres and markers within the arms' reach, noise levels below the
physical bounds of :data:`NOISE_BOUNDS`, counts below their size bounds, checked before anything
is allocated). A message names the file, the key, the value and the allowed range.
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, PrivateAttr, field_validator, model_validator

from calstudy.core import geometry as geo
from calstudy.core.ledger import Inputs, Ledgered, noise_level
from calstudy.core.schema import (
    Documented,
    Finite,
    Fraction,
    LowHigh,
    NonNegativeFinite,
    Pixels,
    PositiveFinite,
    Radians,
    Row,
    Texts,
    Vec3,
    check_principal_point,
    distinct,
    one_each,
)
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig, stereo_rig

#: the two arms, numbered as in the paper
ARMS = (1, 2)

#: an angle from a direction (a tilt, an incidence, a viewing angle), degrees
Tilt = Annotated[float, Field(ge=0, le=90, allow_inf_nan=False)]
#: most points of a scan (ICP pairs them by a KD tree), poses, views, iterations, markers
MAX_POINTS, MAX_POSES, MAX_ITERATIONS, MAX_MARKERS = 100_000, 100, 10_000, 1000
#: the convergence angle of a stereo head (between the two optical axes at the convergence
#: point, deg): below 2 deg depth is hardly triangulated (its error grows as 1 / angle), beyond
#: 60 deg the two images of a surface differ too much to match and their common field vanishes
CONVERGENCE_DEG = (2.0, 60.0)
#: the farthest (mm) the flange of an arm of the 1.4-1.6 m class that [layout] assumes comes from
#: its base origin: e.g. the KUKA KR 16-2 of data/robots, shoulder circle 675 mm up and 260 mm
#: out, 1351 mm from it to the wrist point and 158 mm on to the flange, about 2.4 m at most
ARM_ENVELOPE_MM = 2500.0

#: physical upper bounds of the noise levels (the unit is the key's), each with its reason:
#: beyond them the instrument is not of the class the paper uses; zero is allowed (an oracle)
NOISE_BOUNDS = {
    # a structured-light point scattering by 1 mm is 35 times the paper's 0.029 mm accuracy and
    # a tenth of sphere B's radius: no sphere fit the paper reports would be possible
    "point_mm": 1.0,
    # a view whose fitted sphere radius is off by 1 mm is 35 times the paper's diameter errors
    "sphere_fit_mm": 1.0,
    # sub-pixel centre detection: beyond 2 px a centre is no longer sub-pixel
    "px": 2.0,
    # a marker triangulated worse than 1 mm cannot give the 0.1 mm calibration of Table 3
    "marker_mm": 1.0,
    # ISO 9283 repeatabilities of industrial arms are 0.02-0.2 mm; 1 mm is five times the worst
    "repeat_mm": 1.0,
    "repeat_deg": 0.1,
    # a drift step of 1 mm (0.1 deg) per move is beyond the absolute accuracy of such arms
    "drift_mm": 1.0,
    "drift_deg": 0.1,
    # a robot base placed from a drawing to worse than 20 mm (1 deg) is not placed at all
    "design_mm": 20.0,
    "design_deg": 1.0,
}


#: a rotation vector (rad), at most half a turn beyond pi
RotVec = Annotated[
    list[Annotated[float, Field(ge=-7, le=7, allow_inf_nan=False)]],
    Field(min_length=3, max_length=3),
]


class Camera(Inputs):
    """The ``[camera]`` table of data/dualarm/scenario.toml."""

    width: Pixels
    height: Pixels
    fx_px: PositiveFinite
    fy_px: PositiveFinite
    cx_px: Finite
    cy_px: Finite

    @model_validator(mode="after")
    def _centre_in_image(self) -> Camera:
        check_principal_point(self.cx_px, self.cy_px, self.width, self.height)
        return self

    @cached_property
    def pinhole(self) -> PinholeCamera:
        """The model of each of the head's two equal cameras (no lens distortion)."""
        return PinholeCamera(
            fx=self.fx_px,
            fy=self.fy_px,
            cx=self.cx_px,
            cy=self.cy_px,
            width=self.width,
            height=self.height,
        )


class Stereo(Inputs):
    """The ``[stereo]`` table of data/dualarm/scenario.toml."""

    baseline_mm: PositiveFinite
    convergence_distance_mm: PositiveFinite


class Sensor(Inputs):
    """The ``[sensor]`` table of data/dualarm/scenario.toml."""

    #: the sensors' accuracy as the paper states it (mm)
    stated_accuracy_mm: PositiveFinite
    #: the paper's diameter errors of the sphere fits (mm): sensor 1 A, B; sensor 2 A, B
    diameter_errors_mm: Annotated[list[NonNegativeFinite], Field(min_length=1)]
    point_sigma_mm: noise_level(NOISE_BOUNDS, "point_mm")
    #: the systematic error of one view: every point of the view moved along the sphere's
    #: normal by one draw of N(0, sphere_fit_sigma_mm), so the view's fitted radius is off
    sphere_fit_sigma_mm: noise_level(NOISE_BOUNDS, "sphere_fit_mm")
    #: a sphere fit needs at least 4 points
    points_per_scan: Annotated[int, Field(ge=4, le=MAX_POINTS)]
    max_incidence_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]
    working_distance_mm: PositiveFinite

    max_incidence = Radians("max_incidence_deg")


class Detection(Inputs):
    """The ``[detection]`` table of data/dualarm/scenario.toml."""

    sigma_px: noise_level(NOISE_BOUNDS, "px")
    #: radius of a coded marker's centre circle (its perspective bias grows with radius^2)
    marker_radius_mm: Annotated[float, Field(ge=0, le=50, allow_inf_nan=False)]
    marker_sigma_mm: noise_level(NOISE_BOUNDS, "marker_mm")
    #: the probability that a visible marker is lost in an image
    loss_rate: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]
    max_view_angle_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]

    max_view_angle = Radians("max_view_angle_deg")


class Markers(Inputs):
    """The ``[markers]`` table of data/dualarm/scenario.toml."""

    names: Annotated[
        list[Annotated[str, Field(min_length=1)]], Field(min_length=3, max_length=MAX_MARKERS)
    ]
    xyz_mm: Annotated[list[Vec3], Field(min_length=3, max_length=MAX_MARKERS)]
    groups: Annotated[list[str], Field(min_length=2, max_length=2)]

    #: runs before :meth:`_consistent`
    _one_each = one_each("names", "xyz_mm")

    @model_validator(mode="after")
    def _consistent(self) -> Markers:
        distinct(self.names, "marker names")
        strays = [n for n in self.names if n.split("-")[0] not in self.groups]
        if strays:
            raise ValueError(
                f"markers {strays} belong to no group of {self.groups} (a name is <group>-<code>)"
            )
        return self

    @cached_property
    def xyz(self) -> np.ndarray:
        """Table A1: the markers ``(N, 3)``, world frame, mm."""
        return np.asarray(self.xyz_mm, dtype=float)

    @cached_property
    def group_index(self) -> np.ndarray:
        """The group of each marker ``(N,)``: 0 or 1, the index in ``groups``."""
        return np.array([self.groups.index(n.split("-")[0]) for n in self.names])

    def group_centre(self, arm: int) -> np.ndarray:
        """Centroid ``(3,)`` of the marker group arm ``arm`` (1 or 2) sees, world frame."""
        return self.xyz[self.group_index == arm - 1].mean(axis=0)


class Calibration(Inputs):
    """The ``[calibration]`` table of data/dualarm/scenario.toml."""

    cam2flange_1_rotvec: RotVec
    cam2flange_1_mm: Vec3
    cam2flange_2_rotvec: RotVec
    cam2flange_2_mm: Vec3
    base2_to_base1_rotvec: RotVec
    base2_to_base1_mm: Vec3

    @cached_property
    def cam2flange(self) -> np.ndarray:
        """Table A2: the true hand-eyes ``(2, 4, 4)``, arm ``a`` at index ``a - 1``."""
        return np.stack([_pose(getattr(self, f"cam2flange_{a}_rotvec"),
                               getattr(self, f"cam2flange_{a}_mm")) for a in ARMS])

    @cached_property
    def base2_to_base1(self) -> np.ndarray:
        """Table A2: the true base of arm 2 in the base of arm 1 ``(4, 4)``."""
        return _pose(self.base2_to_base1_rotvec, self.base2_to_base1_mm)


class Layout(Inputs):
    """The ``[layout]`` table of data/dualarm/scenario.toml."""

    world2base1_rotvec: RotVec
    world2base1_mm: Vec3


class Robot(Inputs):
    """The ``[robot]`` table of data/dualarm/scenario.toml."""

    repeat_sigma_mm: noise_level(NOISE_BOUNDS, "repeat_mm")
    repeat_sigma_deg: noise_level(NOISE_BOUNDS, "repeat_deg")
    drift_step_sigma_mm: noise_level(NOISE_BOUNDS, "drift_mm")
    drift_step_sigma_deg: noise_level(NOISE_BOUNDS, "drift_deg")

    repeat_sigma_rad = Radians("repeat_sigma_deg")
    #: the drift steps (mm, rad) of a sweep point, the file's scaled (:meth:`scaled_drift`)
    _drift: tuple[float, float] | None = PrivateAttr(None)

    @property
    def drift_step_mm(self) -> float:
        """The drift step per move, mm."""
        return self.drift_step_sigma_mm if self._drift is None else self._drift[0]

    @property
    def drift_step_rad(self) -> float:
        """The drift step per move, rad."""
        return np.deg2rad(self.drift_step_sigma_deg) if self._drift is None else self._drift[1]

    def scaled_drift(self, scale: float) -> Robot:
        """A copy whose drift steps are these times ``scale`` (a sweep point of the drift, or
        its calibrated scale)."""
        copied = self.model_copy()
        copied._drift = (self.drift_step_mm * scale, self.drift_step_rad * scale)
        return copied


class Design(Inputs):
    """The ``[design]`` table of data/dualarm/scenario.toml: how far the base-to-base transform
    of the station's design drawing is from the true one (each robot placed to the drawing)."""

    base_sigma_mm: noise_level(NOISE_BOUNDS, "design_mm")
    base_sigma_deg: noise_level(NOISE_BOUNDS, "design_deg")

    base_sigma_rad = Radians("base_sigma_deg")


class Spheres(Inputs):
    """The ``[spheres]`` table of data/dualarm/scenario.toml."""

    diameter_a_mm: PositiveFinite
    diameter_b_mm: PositiveFinite

    @property
    def radius(self) -> dict[str, float]:
        """Sphere -> radius, mm."""
        return {"A": self.diameter_a_mm / 2, "B": self.diameter_b_mm / 2}


class HandEye(Inputs):
    """The ``[handeye]`` table of data/dualarm/scenario.toml."""

    grid_rows: Annotated[int, Field(ge=2, le=100)]
    grid_cols: Annotated[int, Field(ge=2, le=100)]
    pitch_mm: PositiveFinite
    #: Tsai-Lenz needs at least 3 poses (2 motions about different axes)
    n_poses: Annotated[int, Field(ge=3, le=MAX_POSES)]
    tilt_deg: Tilt
    #: turn of the image about the optical axis between views, within +-roll_deg
    roll_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    #: radius of the plate's circles; less than half the pitch (checked below)
    circle_radius_mm: NonNegativeFinite

    tilt = Radians("tilt_deg")
    roll = Radians("roll_deg")

    @model_validator(mode="after")
    def _circles_apart(self) -> HandEye:
        if 2 * self.circle_radius_mm >= self.pitch_mm:
            raise ValueError(
                f"circle_radius_mm = {self.circle_radius_mm} overlaps the next circle at "
                f"pitch_mm = {self.pitch_mm}; below half the pitch"
            )
        return self

    @cached_property
    def plate_points(self) -> np.ndarray:
        """Circle centres ``(rows * cols, 3)`` of the calibration plate, plate frame (z = 0)."""
        rows, cols, pitch = self.grid_rows, self.grid_cols, self.pitch_mm
        gx, gy = np.meshgrid(
            (np.arange(cols) - (cols - 1) / 2) * pitch, (np.arange(rows) - (rows - 1) / 2) * pitch
        )
        return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])


class Survey(Inputs):
    """The ``[survey]`` table of data/dualarm/scenario.toml."""

    views_per_group: Annotated[int, Field(ge=1, le=MAX_POSES)]
    bridge_views: Annotated[int, Field(ge=1, le=MAX_POSES)]
    bridge_distance_mm: PositiveFinite
    bridge_tilt_deg: Tilt
    bridge_roll_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    tilt_deg: Tilt
    #: PnP needs at least 3 shared markers
    min_shared_markers: Annotated[int, Field(ge=3, le=MAX_MARKERS)]

    bridge_tilt = Radians("bridge_tilt_deg")
    bridge_roll = Radians("bridge_roll_deg")
    tilt = Radians("tilt_deg")


class GlobalTest(Inputs):
    """The ``[global_test]`` table of data/dualarm/scenario.toml."""

    n_groups: Annotated[int, Field(ge=1, le=MAX_POSES)]
    n_poses: Annotated[int, Field(ge=1, le=MAX_POSES)]
    calibration_poses: Annotated[int, Field(ge=1, le=MAX_POSES)]
    placement_offsets_mm: Annotated[list[Finite], Field(min_length=1, max_length=MAX_POSES)]
    stand_height_mm: Finite

    @model_validator(mode="after")
    def _one_offset_per_group(self) -> GlobalTest:
        if len(self.placement_offsets_mm) != self.n_groups:
            raise ValueError(
                f"{len(self.placement_offsets_mm)} placement_offsets_mm for n_groups = "
                f"{self.n_groups}; one per group"
            )
        return self


class CircularPlate(Inputs):
    """The ``[circular_plate]`` table of data/dualarm/scenario.toml."""

    tilt_deg: Tilt
    jitter_deg: Tilt
    outlier_rate: Fraction
    outlier_px: Annotated[list[NonNegativeFinite], Field(min_length=2, max_length=2), LowHigh]
    #: where the plate lies: (x, y) mm from the point between the marker groups, on the table
    offset_mm: Annotated[list[Finite], Field(min_length=2, max_length=2)]
    ransac_threshold_px: PositiveFinite

    tilt = Radians("tilt_deg")
    jitter = Radians("jitter_deg")


class Icp(Inputs):
    """The ``[icp]`` table of data/dualarm/scenario.toml."""

    z_weight: PositiveFinite
    z_threshold_mm: PositiveFinite
    max_iterations: Annotated[int, Field(ge=1, le=MAX_ITERATIONS)]
    max_pair_distance_mm: PositiveFinite
    n_views: Annotated[int, Field(ge=2, le=MAX_POSES)]
    tilt_deg: Tilt
    sphere_offset_mm: Finite

    tilt = Radians("tilt_deg")


class Scenario(Ledgered, Inputs):
    """The station of ``data/dualarm/scenario.toml``: cameras, markers of Table A1, transforms of
    Table A2, noise and the experiments' geometry (module docstring)."""

    NOT_INPUTS = frozenset({"name"})

    name: str = ""
    camera: Camera
    stereo: Stereo
    sensor: Sensor
    detection: Detection
    markers: Markers
    calibration: Calibration
    layout: Layout
    robot: Robot
    design: Design
    spheres: Spheres
    handeye: HandEye
    survey: Survey
    global_test: GlobalTest
    circular_plate: CircularPlate
    icp: Icp

    @cached_property
    def rig(self) -> StereoRig:
        """The binocular sensor of ``[camera]`` and ``[stereo]``."""
        return stereo_rig(
            self.camera.pinhole, self.stereo.baseline_mm, self.stereo.convergence_distance_mm
        )

    @cached_property
    def world2base(self) -> np.ndarray:
        """The true bases ``(2, 4, 4)``: the marker (world) frame in the base of each arm."""
        lay = self.layout
        w2b1 = _pose(lay.world2base1_rotvec, lay.world2base1_mm)
        return np.stack([w2b1, geo.invert(self.calibration.base2_to_base1) @ w2b1])

    def with_drift_scale(self, scale: float) -> Scenario:
        """The same station with the robots' drift steps times ``scale``."""
        return self.model_copy(update={"robot": self.robot.scaled_drift(scale)})

    def noise_free(self) -> Scenario:
        """The same station with exact detections (no noise, no perspective bias of the circle
        centres), sensor, robot poses and no marker losses."""
        quiet = self.replace(
            {
                "sensor.point_sigma_mm": 0.0,
                "sensor.sphere_fit_sigma_mm": 0.0,
                "detection.sigma_px": 0.0,
                "detection.marker_radius_mm": 0.0,
                "detection.loss_rate": 0.0,
                "handeye.circle_radius_mm": 0.0,
                "robot.repeat_sigma_mm": 0.0,
                "robot.repeat_sigma_deg": 0.0,
                "circular_plate.outlier_rate": 0.0,
            }
        )
        return quiet.with_drift_scale(0.0)

    def plausibility(self) -> None:
        """The camera stands outside the spheres it scans; the stereo head converges at an angle
        within :data:`CONVERGENCE_DEG`; every sphere
        placement and marker group lies within reach of the arm that scans it: no farther from
        its base than :data:`ARM_ENVELOPE_MM` plus the camera's offset from the flange plus the
        working distance."""
        radius = 0.5 * max(self.spheres.diameter_a_mm, self.spheres.diameter_b_mm)
        if self.sensor.working_distance_mm <= radius:
            raise ValueError(
                f"sensor.working_distance_mm = {self.sensor.working_distance_mm}: not beyond the "
                f"radius of the spheres it scans ({radius:g} mm, spheres.diameter_a_mm / 2); the "
                "camera would sit inside the sphere"
            )
        st = self.stereo
        angle = math.degrees(math.atan2(st.baseline_mm, st.convergence_distance_mm))
        lo, hi = CONVERGENCE_DEG
        if not lo <= angle <= hi:
            raise ValueError(
                f"stereo.baseline_mm = {st.baseline_mm}: with convergence_distance_mm = "
                f"{st.convergence_distance_mm} the cameras converge at {angle:.3g} deg, outside "
                f"the {lo:g}-{hi:g} deg a stereo head can work with (baseline / convergence "
                f"distance between {math.tan(math.radians(lo)):.3g} and "
                f"{math.tan(math.radians(hi)):.3g})"
            )
        world2base = self.world2base
        centres = [self.markers.group_centre(arm) for arm in ARMS]
        middle = 0.5 * (centres[0] + centres[1])
        radius_a = 0.5 * self.spheres.diameter_a_mm
        lift = self.global_test.stand_height_mm + radius_a
        places = [
            (
                "global_test.stand_height_mm",
                self.global_test.stand_height_mm,
                f"sphere A at placement_offsets_mm #{k + 1}",
                np.array([middle[0], middle[1] + off, lift]),
            )
            for k, off in enumerate(self.global_test.placement_offsets_mm)
        ]
        for arm, centre in enumerate(centres):
            places.append(
                (
                    "icp.sphere_offset_mm",
                    self.icp.sphere_offset_mm,
                    f"the ICP sphere beside marker group {self.markers.groups[arm]}",
                    np.array([centre[0] + self.icp.sphere_offset_mm, centre[1], lift]),
                )
            )
            places.append(
                (
                    "markers.xyz_mm",
                    [round(float(v), 3) for v in centre],
                    f"the centre of marker group {self.markers.groups[arm]}",
                    centre,
                )
            )
        offsets = (self.calibration.cam2flange_1_mm, self.calibration.cam2flange_2_mm)
        for key, value, what, point in places:
            for arm in range(2):
                reach = ARM_ENVELOPE_MM + float(np.linalg.norm(offsets[arm]))
                reach += self.sensor.working_distance_mm
                far = float(np.linalg.norm((world2base[arm] @ np.append(point, 1.0))[:3]))
                if far > reach:
                    raise ValueError(
                        f"{key} = {value}: {what} lies {far:.0f} mm from the base of arm "
                        f"{arm + 1}; its camera reaches at most {reach:.0f} mm (an arm envelope "
                        f"of {ARM_ENVELOPE_MM:g} mm, the camera's offset from the flange and the "
                        "working distance): the arm cannot scan it"
                    )


# ----------------------------------------------------------------------------------------------
# published.toml (the paper's numbers, not an input of the simulation)

Mm = NonNegativeFinite
#: a pose group, 0 for the row over all groups
Group = Annotated[int, Field(ge=0)]


def _pose(rotvec, translation) -> np.ndarray:
    return geo.make_transform(geo.rotvec_to_matrix(rotvec), translation)


class IcpTable(Documented):
    """The ``[icp]`` table of data/dualarm/published.toml: ``[arm, sphere, before, after]``."""

    rows: Annotated[
        list[Annotated[tuple[Annotated[int, Field(ge=1, le=2)], Literal["A", "B"], Mm, Mm], Row]],
        Field(min_length=1),
    ]

    @field_validator("rows")
    @classmethod
    def _pairs(cls, rows: list) -> list:
        distinct([(arm, sphere) for arm, sphere, *_ in rows], "arm-sphere pairs", "; one row each")
        return rows


class GroupTable(Documented):
    """The ``[table1]`` and ``[table2]`` tables of data/dualarm/published.toml: ``[group, three
    errors]`` per row (group 0: all groups), mm."""

    rows: Annotated[list[Annotated[tuple[Group, Mm, Mm, Mm], Row]], Field(min_length=1)]
    overall: Mm | None = None

    @field_validator("rows")
    @classmethod
    def _groups(cls, rows: list) -> list:
        distinct([r[0] for r in rows], "groups", "; one row each")
        return rows


class MethodTable(Documented):
    """The ``[table3]`` table of data/dualarm/published.toml: ``[dx, dy, dz, euclid]`` per
    method, mm."""

    methods: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]
    rows: list[Annotated[tuple[Mm, Mm, Mm, Mm], Row]]
    not_testable: str = ""

    _one_row_per_method = one_each("methods", "rows")


class PublishedFile(Documented):
    """``data/dualarm/published.toml``."""

    icp: IcpTable
    table1: GroupTable
    table2: GroupTable
    table3: MethodTable
    nuisance_targets: Texts = Texts()

    @model_validator(mode="after")
    def _overall(self) -> PublishedFile:
        if self.table2.overall is None:
            raise ValueError("table2.overall: missing (required)")
        return self


__all__ = ["ARMS", "PublishedFile", "Scenario"]
