"""Schema of the dualarm paper's ``scenario.toml`` (the station of notebook 05, or a copy
describing yours).

Checked on load (:func:`calstudy.core.schema.check_toml`): every key read must be there with its
type and range (lengths mm, angles degrees where the key says ``_deg``, rotation vectors rad),
unknown keys are refused, and the cross-field rules below hold (one position per marker name,
every marker in a declared group, a principal point inside the image, an outlier range that is
a range). A message names the file, the key, the value and the allowed range.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import ConfigDict, Field, field_validator, model_validator

from calstudy.core.schema import (
    Documented,
    Finite,
    Fraction,
    NonNegativeFinite,
    PositiveFinite,
    PositiveInt,
    Row,
    Schema,
    Vec3,
    check_principal_point,
)

#: an angle from a direction (a tilt, an incidence, a viewing angle), degrees
Tilt = Annotated[float, Field(ge=0, le=90, allow_inf_nan=False)]
#: a rotation vector (rad), at most half a turn beyond pi
RotVec = Annotated[
    list[Annotated[float, Field(ge=-7, le=7, allow_inf_nan=False)]],
    Field(min_length=3, max_length=3),
]


class Camera(Documented):
    """The ``[camera]`` table of data/dualarm/scenario.toml."""

    width: PositiveInt
    height: PositiveInt
    fx_px: PositiveFinite
    fy_px: PositiveFinite
    cx_px: Finite
    cy_px: Finite

    @model_validator(mode="after")
    def _centre_in_image(self) -> Camera:
        check_principal_point(self.cx_px, self.cy_px, self.width, self.height)
        return self


class Stereo(Documented):
    """The ``[stereo]`` table of data/dualarm/scenario.toml."""

    baseline_mm: PositiveFinite
    convergence_distance_mm: PositiveFinite


class Sensor(Documented):
    """The ``[sensor]`` table of data/dualarm/scenario.toml."""

    point_sigma_mm: NonNegativeFinite
    #: a sphere fit needs at least 4 points
    points_per_scan: Annotated[int, Field(ge=4)]
    max_incidence_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]
    working_distance_mm: PositiveFinite


class Detection(Documented):
    """The ``[detection]`` table of data/dualarm/scenario.toml."""

    sigma_px: NonNegativeFinite
    #: radius of a coded marker's centre circle (its perspective bias grows with radius^2)
    marker_radius_mm: Annotated[float, Field(ge=0, le=50, allow_inf_nan=False)]
    marker_sigma_mm: NonNegativeFinite
    #: the probability that a visible marker is lost in an image
    loss_rate: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]
    max_view_angle_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]


class Markers(Documented):
    """The ``[markers]`` table of data/dualarm/scenario.toml."""

    names: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=3)]
    xyz_mm: Annotated[list[Vec3], Field(min_length=3)]
    groups: Annotated[list[str], Field(min_length=2, max_length=2)]

    @model_validator(mode="after")
    def _consistent(self) -> Markers:
        if len(self.names) != len(self.xyz_mm):
            raise ValueError(f"{len(self.names)} names but {len(self.xyz_mm)} xyz_mm; one each")
        if len(set(self.names)) != len(self.names):
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ValueError(f"marker names repeated: {dup}")
        strays = [n for n in self.names if n.split("-")[0] not in self.groups]
        if strays:
            raise ValueError(
                f"markers {strays} belong to no group of {self.groups} (a name is <group>-<code>)"
            )
        return self


class Calibration(Documented):
    """The ``[calibration]`` table of data/dualarm/scenario.toml."""

    cam2flange_1_rotvec: RotVec
    cam2flange_1_mm: Vec3
    cam2flange_2_rotvec: RotVec
    cam2flange_2_mm: Vec3
    base2_to_base1_rotvec: RotVec
    base2_to_base1_mm: Vec3


class Layout(Documented):
    """The ``[layout]`` table of data/dualarm/scenario.toml."""

    world2base1_rotvec: RotVec
    world2base1_mm: Vec3


class Robot(Documented):
    """The ``[robot]`` table of data/dualarm/scenario.toml."""

    repeat_sigma_mm: NonNegativeFinite
    repeat_sigma_deg: NonNegativeFinite
    drift_step_sigma_mm: NonNegativeFinite
    drift_step_sigma_deg: NonNegativeFinite


class Spheres(Documented):
    """The ``[spheres]`` table of data/dualarm/scenario.toml."""

    diameter_a_mm: PositiveFinite
    diameter_b_mm: PositiveFinite


class HandEye(Documented):
    """The ``[handeye]`` table of data/dualarm/scenario.toml."""

    grid_rows: Annotated[int, Field(ge=2)]
    grid_cols: Annotated[int, Field(ge=2)]
    pitch_mm: PositiveFinite
    #: Tsai-Lenz needs at least 3 poses (2 motions about different axes)
    n_poses: Annotated[int, Field(ge=3)]
    tilt_deg: Tilt
    #: turn of the image about the optical axis between views, within +-roll_deg
    roll_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    #: radius of the plate's circles; less than half the pitch (checked below)
    circle_radius_mm: NonNegativeFinite

    @model_validator(mode="after")
    def _circles_apart(self) -> HandEye:
        if 2 * self.circle_radius_mm >= self.pitch_mm:
            raise ValueError(
                f"circle_radius_mm = {self.circle_radius_mm} overlaps the next circle at "
                f"pitch_mm = {self.pitch_mm}; below half the pitch"
            )
        return self


class Survey(Documented):
    """The ``[survey]`` table of data/dualarm/scenario.toml."""

    views_per_group: PositiveInt
    bridge_views: PositiveInt
    bridge_distance_mm: PositiveFinite
    bridge_tilt_deg: Tilt
    bridge_roll_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    tilt_deg: Tilt
    #: PnP needs at least 3 shared markers
    min_shared_markers: Annotated[int, Field(ge=3)]


class GlobalTest(Documented):
    """The ``[global_test]`` table of data/dualarm/scenario.toml."""

    n_groups: PositiveInt
    n_poses: PositiveInt
    calibration_poses: PositiveInt
    placement_offsets_mm: Annotated[list[Finite], Field(min_length=1)]
    stand_height_mm: Finite

    @model_validator(mode="after")
    def _one_offset_per_group(self) -> GlobalTest:
        if len(self.placement_offsets_mm) != self.n_groups:
            raise ValueError(
                f"{len(self.placement_offsets_mm)} placement_offsets_mm for n_groups = "
                f"{self.n_groups}; one per group"
            )
        return self


class CircularPlate(Documented):
    """The ``[circular_plate]`` table of data/dualarm/scenario.toml."""

    tilt_deg: Tilt
    jitter_deg: Tilt
    outlier_rate: Fraction
    outlier_px: Annotated[list[NonNegativeFinite], Field(min_length=2, max_length=2)]
    #: where the plate lies: (x, y) mm from the point between the marker groups, on the table
    offset_mm: Annotated[list[Finite], Field(min_length=2, max_length=2)]
    ransac_threshold_px: PositiveFinite

    @model_validator(mode="after")
    def _range(self) -> CircularPlate:
        lo, hi = self.outlier_px
        if lo > hi:
            raise ValueError(f"outlier_px = {self.outlier_px} is not [low, high]")
        return self


class Icp(Documented):
    """The ``[icp]`` table of data/dualarm/scenario.toml."""

    z_weight: PositiveFinite
    z_threshold_mm: PositiveFinite
    max_iterations: PositiveInt
    max_pair_distance_mm: PositiveFinite
    n_views: Annotated[int, Field(ge=2)]
    tilt_deg: Tilt
    sphere_offset_mm: Finite


class ScenarioFile(Documented):
    """``data/dualarm/scenario.toml``."""

    name: str = ""
    camera: Camera
    stereo: Stereo
    sensor: Sensor
    detection: Detection
    markers: Markers
    calibration: Calibration
    layout: Layout
    robot: Robot
    spheres: Spheres
    handeye: HandEye
    survey: Survey
    global_test: GlobalTest
    circular_plate: CircularPlate
    icp: Icp


# ----------------------------------------------------------------------------------------------
# published.toml (the paper's numbers, not an input of the simulation)

Mm = NonNegativeFinite
#: a pose group, 0 for the row over all groups
Group = Annotated[int, Field(ge=0)]


class Texts(Schema):
    """A table of texts only (``[nuisance_targets]``): any key, every value a string."""

    model_config = ConfigDict(extra="allow", frozen=True, str_strip_whitespace=True)
    __pydantic_extra__: dict[str, str]


def _one_row_each(rows: list, what: str) -> list:
    groups = [r[0] for r in rows]
    dup = sorted({g for g in groups if groups.count(g) > 1})
    if dup:
        raise ValueError(f"{what} repeated: {dup}; one row each")
    return rows


class IcpTable(Documented):
    """The ``[icp]`` table of data/dualarm/published.toml: ``[arm, sphere, before, after]``."""

    rows: Annotated[
        list[Annotated[tuple[Annotated[int, Field(ge=1, le=2)], Literal["A", "B"], Mm, Mm], Row]],
        Field(min_length=1),
    ]

    @field_validator("rows")
    @classmethod
    def _pairs(cls, rows: list) -> list:
        _one_row_each([((arm, sphere), *rest) for arm, sphere, *rest in rows], "arm-sphere pairs")
        return rows


class GroupTable(Documented):
    """The ``[table1]`` and ``[table2]`` tables of data/dualarm/published.toml: ``[group, three
    errors]`` per row (group 0: all groups), mm."""

    rows: Annotated[list[Annotated[tuple[Group, Mm, Mm, Mm], Row]], Field(min_length=1)]
    overall: Mm | None = None

    @field_validator("rows")
    @classmethod
    def _groups(cls, rows: list) -> list:
        return _one_row_each(rows, "groups")


class MethodTable(Documented):
    """The ``[table3]`` table of data/dualarm/published.toml: ``[dx, dy, dz, euclid]`` per
    method, mm."""

    methods: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]
    rows: list[Annotated[tuple[Mm, Mm, Mm, Mm], Row]]
    not_testable: str = ""

    @model_validator(mode="after")
    def _one_row_per_method(self) -> MethodTable:
        if len(self.rows) != len(self.methods):
            raise ValueError(f"{len(self.methods)} methods but {len(self.rows)} rows; one each")
        return self


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


__all__ = ["PublishedFile", "ScenarioFile"]
