"""Schemas of the binocular paper's files: ``sensor.toml``, ``calibrator.toml`` and
``station.toml`` (the scenario folder of notebook 04, ``data/binocular`` or a copy describing
your cell), with their ``[published]`` tables.

Each file is checked on load (:func:`calstudy.core.schema.validate`): every key the simulation
reads must be there, with its type and range (lengths in mm, angles in degrees where the key says
``_deg``, image coordinates in px), unknown keys are refused (a misspelt key is not silently a
default), and the cross-field rules below hold: a principal point inside the image, Canny
thresholds ``low < high``, proper rotations (the extrinsic and the hand-eye matrix, printed to 4
decimals, must be rotations within :data:`ROTATION_TOL` before they are re-orthonormalised),
standard distances that admit a calibrator layout, one name, distance and
centre per field region. A message names the file, the key, the value and the allowed range, e.g.
``calibrator.toml: standard.distance_mm: P2P7 = 58.853, P3P7 = 55.181, P5P7 = 200.0 admit no
layout: ...``
(:func:`calstudy.estimators.binocular.layout_problem`).

Every input carries its provenance beside it (:mod:`calstudy.core.ledger`); noise levels lie
below the physical bounds of :data:`NOISE_BOUNDS` and counts below their size bounds (checked
before anything is allocated). Whether the robot reaches the views the station asks for needs
all three files and the robot's table: :func:`calstudy.papers.binocular.scenario.check_reach`.
"""

from __future__ import annotations

from functools import cached_property
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from calstudy.core import geometry as geo
from calstudy.core.ledger import Inputs, Ledgered, noise_level
from calstudy.core.schema import (
    Degrees,
    Documented,
    Finite,
    NonNegativeFinite,
    Pixels,
    PositiveFinite,
    Texts,
    Vec3,
    check_principal_point,
    distinct,
    one_each,
    ordered,
    rigid_transform,
    rotation_problem,
)
from calstudy.estimators.binocular import layout_problem
from calstudy.models.sensors import PinholeCamera

#: largest ``|R^T R - I|`` of a rotation printed to 4 decimals (the paper's Table 1 and Table 4
#: give about 1e-4); the loader then projects it onto SO(3)
ROTATION_TOL = 2e-3

Row3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
Row4 = Annotated[list[Finite], Field(min_length=4, max_length=4)]
Matrix3 = Annotated[list[Row3], Field(min_length=3, max_length=3)]
Matrix34 = Annotated[list[Row4], Field(min_length=3, max_length=3)]
#: a count of OpenCV distortion coefficients (k1 k2 p1 p2 [k3 ...])
DIST_LENGTHS = (4, 5, 8, 12, 14)
#: the seven standard distances to P7 (P1P7 ... P6P7, P8P7)
Seven = Annotated[list[PositiveFinite], Field(min_length=7, max_length=7)]
Pair = Annotated[list[NonNegativeFinite], Field(min_length=2, max_length=2)]
Name = Annotated[str, Field(min_length=1)]
#: lengths of a station in mm that all lie below this look like metres
METRES_SUSPECT_MM = 10.0
#: most poses of a protocol and regions of a field (the paper uses 6, 10 and 3)
MAX_POSES, MAX_REGIONS = 1000, 100

#: physical upper bounds of the noise levels (the unit is the key's), each with its reason:
#: beyond them the instrument is not of the class the paper uses; zero is allowed (an oracle)
NOISE_BOUNDS = {
    # read noise of a machine-vision camera: 50 DN is a fifth of an 8-bit full scale
    "read_noise_dn": 50.0,
    # errors a stereo calibration that still measures to 0.1 mm can leave (Table 1's digits
    # imply far less): 50 px of focal length or principal point, 0.01 in k1, 1 mrad, 1 mm
    "calibration_px": 50.0,
    "k1": 0.01,
    "extrinsic_rad": 1e-3,
    "extrinsic_mm": 1.0,
    # CMM and laser tracker: 100 um (+ 100 um/m) is ten times the coarsest of either class
    "reference_um": 100.0,
    # a retro-reflective dot centred worse than 0.1 mm in its sphere is not an SBR
    "dot_centring_um": 100.0,
    # ISO 9283 repeatabilities of industrial arms are 0.02-0.2 mm; 1 mm is five times the worst
    "repeatability_mm": 1.0,
}


def _metres(values, what: str) -> None:
    """ValueError if the lengths ``values`` (mm) all lie below :data:`METRES_SUSPECT_MM`."""
    size = float(np.max(np.abs(np.asarray(values, dtype=float))))
    if size < METRES_SUSPECT_MM:
        raise ValueError(
            f"{what} is {size:g} mm, below {METRES_SUSPECT_MM:g} mm: metres? (write millimetres)"
        )


def _rotation(matrix: list, what: str) -> None:
    problem = rotation_problem(np.array(matrix, dtype=float), ROTATION_TOL)
    if problem:
        raise ValueError(f"{what} is not a rotation: {problem}")


# ----------------------------------------------------------------------------------------------
# sensor.toml


class Image(Inputs):
    """The ``[image]`` table of data/binocular/sensor.toml."""

    width: Pixels
    height: Pixels
    #: mm per pixel: 1-50 um (a value in um, 4.6, is refused)
    pixel_pitch_mm: Annotated[float, Field(gt=0, le=0.05, allow_inf_nan=False)]


class Camera(Inputs):
    """The ``[left]`` and ``[right]`` tables of data/binocular/sensor.toml (px)."""

    fx: PositiveFinite
    fy: PositiveFinite
    cx: Finite
    cy: Finite
    #: OpenCV k1 k2 p1 p2 [k3 ...]
    dist: list[Finite]

    @field_validator("dist")
    @classmethod
    def _dist(cls, dist: list) -> list:
        if len(dist) not in DIST_LENGTHS:
            raise ValueError(
                f"{len(dist)} coefficients; OpenCV takes k1 k2 p1 p2 [k3 ...]: "
                f"{', '.join(map(str, DIST_LENGTHS))} values"
            )
        for i, (name, limit) in enumerate((("k1", 10.0), ("k2", 10.0), ("p1", 0.1), ("p2", 0.1))):
            if abs(dist[i]) > limit:
                raise ValueError(f"{name} = {dist[i]} (entry #{i + 1}): must be within +-{limit}")
        return dist

    def pinhole(self, image: Image) -> PinholeCamera:
        """The camera of this table with the sensor of ``image``."""
        return PinholeCamera(
            fx=self.fx,
            fy=self.fy,
            cx=self.cx,
            cy=self.cy,
            width=image.width,
            height=image.height,
            dist=tuple(self.dist),
        )


class Extrinsic(Inputs):
    """The ``[extrinsic]`` table of data/binocular/sensor.toml: left2right, mm."""

    rotation: Matrix3
    translation_mm: Vec3

    @field_validator("rotation")
    @classmethod
    def _proper(cls, rotation: list) -> list:
        _rotation(rotation, "left2right")
        return rotation

    @field_validator("translation_mm")
    @classmethod
    def _baseline(cls, t: list) -> list:
        if float(np.linalg.norm(t)) <= 0.0:
            raise ValueError("the cameras coincide (baseline 0); stereo needs a baseline")
        _metres(t, "the baseline's largest coordinate")
        return t

    @cached_property
    def left2right(self) -> np.ndarray:
        """``(4, 4)``: the rotation projected onto SO(3) (it is printed to 4 decimals)."""
        rotation = geo.project_to_so3(np.array(self.rotation, dtype=float))
        return geo.make_transform(rotation, np.array(self.translation_mm, dtype=float))


#: The defocus mechanisms a scenario may select (``[optics] mechanism``): the paper's symmetric
#: Gaussian blur spot (Eq. 7) and the study's lens-rim vignetting (the spot cut off axis).
MECHANISMS = ("gaussian", "rim")


class Optics(Inputs):
    """The ``[optics]`` table of data/binocular/sensor.toml (Eq. 4, 7)."""

    NOT_INPUTS = frozenset({"calibrate_f_number_to"})

    #: the blur spot of a defocused point: ``gaussian`` (Eq. 7) or ``rim`` (Eq. 7 cut by the rim)
    mechanism: Literal[MECHANISMS]
    f_number: Annotated[float, Field(ge=0.5, le=128, allow_inf_nan=False)]
    focus_distance_mm: PositiveFinite
    #: which published baseline the notebook calibrates the f-number to (text, for the reader)
    calibrate_f_number_to: str = ""
    #: the lens rim that cuts the pupil for off-axis points (mechanical vignetting), in mm
    rim_radius_mm: PositiveFinite
    #: its distance in front of the entrance pupil (negative: behind it), in mm
    rim_distance_mm: Annotated[float, Field(ge=-1000, le=1000, allow_inf_nan=False)]


class Exposure(Inputs):
    """The ``[exposure]`` table of data/binocular/sensor.toml (Eq. 3)."""

    times_ms: Annotated[list[PositiveFinite], Field(min_length=1, max_length=10)]
    bits: Annotated[int, Field(ge=1, le=16)]
    dot_peak_at_100ms: PositiveFinite
    #: the background's share of full scale at 100 ms
    background_at_100ms: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]
    weight_contrast: NonNegativeFinite
    weight_exposure: NonNegativeFinite
    well_exposed_sigma: PositiveFinite

    @model_validator(mode="after")
    def _dot_brighter(self) -> Exposure:
        if self.dot_peak_at_100ms <= self.background_at_100ms:
            raise ValueError(
                f"dot_peak_at_100ms = {self.dot_peak_at_100ms} is not above "
                f"background_at_100ms = {self.background_at_100ms}; the dot would be invisible"
            )
        return self


class Noise(Inputs):
    """The ``[noise]`` table of data/binocular/sensor.toml."""

    read_noise_dn: noise_level(NOISE_BOUNDS, "read_noise_dn")
    electrons_per_dn: PositiveFinite


class CalibrationUncertainty(Inputs):
    """The ``[calibration_uncertainty]`` table of data/binocular/sensor.toml."""

    focal_px: noise_level(NOISE_BOUNDS, "calibration_px")
    principal_point_px: noise_level(NOISE_BOUNDS, "calibration_px")
    k1: noise_level(NOISE_BOUNDS, "k1")
    extrinsic_rotation_rad: noise_level(NOISE_BOUNDS, "extrinsic_rad")
    extrinsic_translation_mm: noise_level(NOISE_BOUNDS, "extrinsic_mm")


class Detection(Inputs):
    """The ``[detection]`` table of data/binocular/sensor.toml."""

    canny_low: Annotated[float, Field(gt=0, lt=1, allow_inf_nan=False)]
    canny_high: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)]
    #: an ellipse needs at least 5 points
    min_edge_points: Annotated[int, Field(ge=5, le=100_000)]
    ray_tolerance_mm: PositiveFinite

    _order = ordered("canny_low", "canny_high")


class SensorFile(Ledgered):
    """``data/binocular/sensor.toml``."""

    source: Texts = Texts()
    image: Image
    left: Camera
    right: Camera
    extrinsic: Extrinsic
    optics: Optics
    exposure: Exposure
    noise: Noise
    calibration_uncertainty: CalibrationUncertainty
    detection: Detection

    def plausibility(self) -> None:
        """The focus lies beyond the lens-to-sensor distance; both principal points lie in
        the image."""
        self._focus_beyond_image_distance()
        self._centres_in_image()

    def _focus_beyond_image_distance(self) -> None:
        image_distance = self.left.fx * self.image.pixel_pitch_mm
        if self.optics.focus_distance_mm <= image_distance:
            raise ValueError(
                f"optics.focus_distance_mm = {self.optics.focus_distance_mm} is not beyond the "
                f"lens-to-sensor distance {image_distance:.4g} mm (left.fx x "
                "image.pixel_pitch_mm): a measuring camera images at a magnification below 1"
            )

    def _centres_in_image(self) -> None:
        for side in ("left", "right"):
            cam = getattr(self, side)
            try:
                check_principal_point(cam.cx, cam.cy, self.image.width, self.image.height)
            except ValueError as exc:
                raise ValueError(f"{side}: {exc}") from None


# ----------------------------------------------------------------------------------------------
# calibrator.toml


class Standard(Inputs):
    """The ``[standard]`` table of data/binocular/calibrator.toml."""

    names: Annotated[list[Name], Field(min_length=7, max_length=7)]
    distance_mm: Seven
    start_angle_deg: Annotated[list[Degrees], Field(min_length=6, max_length=6)]

    @field_validator("names")
    @classmethod
    def _names(cls, names: list) -> list:
        return distinct(names, "distance names")

    @field_validator("distance_mm")
    @classmethod
    def _layout(cls, distance_mm: list, info: ValidationInfo) -> list:
        names = info.data.get("names") or [f"P{k}P7" for k in (1, 2, 3, 4, 5, 6, 8)]
        problem = layout_problem(distance_mm, names)
        if problem:
            raise ValueError(problem)
        _metres(distance_mm, "the largest distance")
        return distance_mm


class Cmm(Inputs):
    """The ``[cmm]`` table of data/binocular/calibrator.toml: sigma = a + b L."""

    sigma_um: noise_level(NOISE_BOUNDS, "reference_um")
    sigma_um_per_m: noise_level(NOISE_BOUNDS, "reference_um")


class Sbr(Inputs):
    """The ``[sbr]`` table of data/binocular/calibrator.toml."""

    dot_centring_um: noise_level(NOISE_BOUNDS, "dot_centring_um")
    dot_diameter_mm: PositiveFinite


class CalibratorPublished(Documented):
    """The ``[published]`` table of data/binocular/calibrator.toml (Tables 2-3), mm."""

    table2_control: Seven
    table2_experimental: Seven
    table2_rmse: Pair
    table3_control: Seven
    table3_experimental: Seven
    table3_rmse: Pair


class CalibratorFile(Ledgered):
    """``data/binocular/calibrator.toml``."""

    source: Texts = Texts()
    standard: Standard
    cmm: Cmm
    sbr: Sbr
    published: CalibratorPublished | None = None


# ----------------------------------------------------------------------------------------------
# station.toml


class HandEye(Inputs):
    """The ``[handeye]`` table of data/binocular/station.toml: sensor2flange, mm."""

    matrix: rigid_transform(ROTATION_TOL)

    @field_validator("matrix")
    @classmethod
    def _in_mm(cls, matrix: list) -> list:
        _metres(np.array(matrix, dtype=float)[:3, 3], "its translation's largest coordinate")
        return matrix


class CalibratorPlace(Inputs):
    """The ``[calibrator]`` table of data/binocular/station.toml."""

    p7_distance_mm: PositiveFinite
    p7_height_mm: Finite
    plate_tilt_deg: Annotated[float, Field(gt=-90, lt=90, allow_inf_nan=False)]

    @model_validator(mode="after")
    def _reach(self) -> CalibratorPlace:
        if abs(self.p7_height_mm) >= self.p7_distance_mm:
            raise ValueError(
                f"|p7_height_mm| = {abs(self.p7_height_mm)} is not below p7_distance_mm = "
                f"{self.p7_distance_mm}; P7 cannot be that high at that distance"
            )
        return self


class Poses(Inputs):
    """The ``[poses]`` table of data/binocular/station.toml."""

    #: at least 10 mm (a value in metres is refused)
    observation_distance_mm: Annotated[float, Field(ge=METRES_SUSPECT_MM, allow_inf_nan=False)]
    #: AX = XB needs at least 3 poses (2 motions about different axes)
    n_calibration: Annotated[int, Field(ge=3, le=MAX_POSES)]
    n_validation: Annotated[int, Field(ge=1, le=MAX_POSES)]
    cone_deg: Annotated[float, Field(ge=0, lt=90, allow_inf_nan=False)]
    roll_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)]
    distance_spread_mm: NonNegativeFinite

    _spread = ordered("distance_spread_mm", "observation_distance_mm")


class RobotTable(Inputs):
    """The ``[robot]`` table of data/binocular/station.toml."""

    model: Name
    repeatability_mm: noise_level(NOISE_BOUNDS, "repeatability_mm")


class Tracker(Inputs):
    """The ``[laser_tracker]`` table of data/binocular/station.toml: sigma = a + b L."""

    sigma_um: noise_level(NOISE_BOUNDS, "reference_um")
    sigma_um_per_m: noise_level(NOISE_BOUNDS, "reference_um")


Five = Annotated[list[PositiveFinite], Field(min_length=5, max_length=5)]


class Field_(Inputs):
    """The ``[field]`` table of data/binocular/station.toml (Table 5)."""

    regions: Annotated[list[Name], Field(min_length=1, max_length=MAX_REGIONS)]
    names: list[Annotated[list[Name], Field(min_length=5, max_length=5)]]
    standard_mm: list[Five]
    centres_mm: list[Vec3]
    faces_point_mm: Vec3
    n_poses: Annotated[int, Field(ge=1, le=MAX_POSES)]

    @field_validator("regions")
    @classmethod
    def _names(cls, regions: list) -> list:
        return distinct(regions, "region names")

    #: runs before :meth:`_faces`, which pairs regions with centres
    _one_each = one_each("regions", "names", "standard_mm", "centres_mm", note="one per region")

    @model_validator(mode="after")
    def _faces(self) -> Field_:
        face = np.array(self.faces_point_mm, dtype=float)
        for region, centre in zip(self.regions, self.centres_mm, strict=True):
            if float(np.linalg.norm(face - np.array(centre, dtype=float))) < 1e-6:
                raise ValueError(
                    f"faces_point_mm is the centre of {region}; it sets the direction it faces"
                )
        return self


class StationPublished(Documented):
    """The ``[published]`` table of data/binocular/station.toml (Table 4, Fig. 13, Table 5)."""

    table4_preliminary: Matrix34
    table4_updated: Matrix34
    fig13_rmse: Pair
    table5_preliminary: list[Five]
    table5_updated: list[Five]
    table5_rmse: list[Pair]

    _regions = one_each(
        "table5_preliminary", "table5_updated", "table5_rmse", note="one row per region"
    )


class StationFile(Ledgered):
    """``data/binocular/station.toml``."""

    source: Texts = Texts()
    handeye: HandEye
    calibrator: CalibratorPlace
    poses: Poses
    robot: RobotTable
    laser_tracker: Tracker
    field: Field_
    published: StationPublished | None = None


#: the schema of each file of a scenario folder
SCHEMAS: dict[str, Any] = {
    "sensor": SensorFile,
    "calibrator": CalibratorFile,
    "station": StationFile,
}

__all__ = [
    "CalibratorFile",
    "ROTATION_TOL",
    "SCHEMAS",
    "SensorFile",
    "StationFile",
]
