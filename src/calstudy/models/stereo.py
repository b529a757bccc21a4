"""A binocular (stereo) sensor: two pinhole cameras and the rigid transform between them.

One rig serves both papers with a stereo sensor: ``binocular`` (two cameras with OpenCV lens
distortion and the extrinsic of its Table 1, :meth:`StereoRig.from_left2right`) and ``dualarm`` (two
equal ideal cameras converging on a point, :func:`stereo_rig`).

Frames: the sensor frame is the left camera frame. ``right2left`` is the pose of the right camera
in the left one (``p_left = right2left @ p_right``); ``left2right`` its inverse, the extrinsic of
a stereo calibration (``p_right = R p_left + t``). Both are kept exactly as given: a rig built
from one holds the other as :func:`calstudy.core.geometry.invert` of it. Millimetres, pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.models.sensors import PinholeCamera

#: Largest ``|left2right @ right2left - I|`` accepted when both transforms are given.
INVERSE_TOL = 1e-9


#: the standard deviations :meth:`StereoRig.perturbed` draws with
SIGMA_KEYS = (
    "focal_px",
    "principal_point_px",
    "k1",
    "extrinsic_rotation_rad",
    "extrinsic_translation_mm",
)


@dataclass(frozen=True)
class StereoRig:
    """A calibrated binocular sensor.

    Attributes
    ----------
    left, right : PinholeCamera
        The two cameras (the left one is the sensor's reference frame), with their distortion.
    right2left : numpy.ndarray, shape (4, 4)
        Pose of the right camera in the left camera frame (``p_left = right2left @ p_right``).
    left2right : numpy.ndarray, shape (4, 4)
        Its inverse (``p_right = left2right @ p_left``); computed from ``right2left`` if not
        given, checked against it if given.

    Raises
    ------
    CalibrationError
        If a transform is not rigid, or the two given transforms are not inverse to each other.
    """

    left: PinholeCamera
    right: PinholeCamera
    right2left: np.ndarray
    left2right: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        r2l = geo.check_transform("right2left", self.right2left)
        object.__setattr__(self, "right2left", r2l)
        if self.left2right is None:
            object.__setattr__(self, "left2right", geo.invert(r2l))
            return
        l2r = geo.check_transform("left2right", self.left2right)
        gap = float(np.abs(l2r @ r2l - np.eye(4)).max())
        if gap > INVERSE_TOL:
            raise CalibrationError(
                f"left2right and right2left are not inverse to each other (by {gap:.3g})"
            )
        object.__setattr__(self, "left2right", l2r)

    @classmethod
    def from_left2right(
        cls, left: PinholeCamera, right: PinholeCamera, left2right
    ) -> StereoRig:
        """A rig from the extrinsic ``left2right`` ``(4, 4)`` of a stereo calibration."""
        l2r = geo.check_transform("left2right", left2right)
        return cls(left, right, geo.invert(l2r), l2r)

    @property
    def rotation(self) -> np.ndarray:
        """``R`` of ``left2right``, shape (3, 3) (a copy)."""
        return self.left2right[:3, :3].copy()

    @property
    def translation(self) -> np.ndarray:
        """``t`` of ``left2right``, shape (3,), mm (a copy)."""
        return self.left2right[:3, 3].copy()

    def cameras(self) -> list[tuple[PinholeCamera, np.ndarray]]:
        """``[(camera, sensor2camera), ...]`` for the left and the right camera."""
        return [(self.left, np.eye(4)), (self.right, self.left2right)]

    def camera(self, side: str) -> PinholeCamera:
        """The ``"left"`` or ``"right"`` camera."""
        if side not in ("left", "right"):
            raise CalibrationError(f"camera side is {side!r}; expected 'left' or 'right'")
        return self.left if side == "left" else self.right

    def project(self, points_left) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free ``(uv_left, uv_right)``, each ``(N, 2)`` px, of points ``(N, 3)`` in the
        left camera frame (mm), through each camera's distortion."""
        p = geo.check_shape("points_left", points_left, (None, 3))
        return self.left.project(p), self.right.project(geo.apply(self.left2right, p))

    def normalise(self, uv, side: str) -> np.ndarray:
        """Undistorted normalised coordinates ``(N, 2)`` of image points ``(N, 2)`` of the
        ``side`` (``"left"`` or ``"right"``) camera."""
        return self.camera(side).normalise(uv)

    def triangulate(self, uv_left, uv_right) -> np.ndarray:
        """Points in the left camera frame from matched image points: both undistorted to
        normalised coordinates (:meth:`normalise`), then :meth:`triangulate_normalised`.

        Parameters
        ----------
        uv_left, uv_right : array_like, shape (N, 2)
            Matched image points of the left and the right camera, px.

        Returns
        -------
        numpy.ndarray, shape (N, 3)
            The points in the left camera frame, mm.

        Raises
        ------
        CalibrationError
            If the arrays are not ``(N, 2)`` of one ``N``, hold NaN or infinity, or a pair of
            rays is parallel (see :meth:`triangulate_normalised`).
        """
        ul = geo.check_shape("uv_left", uv_left, (None, 2))
        ur = geo.check_shape("uv_right", uv_right, (ul.shape[0], 2))
        return self.triangulate_normalised(self.normalise(ul, "left"), self.normalise(ur, "right"))

    def triangulate_normalised(self, x_left, x_right) -> np.ndarray:
        """Points in the left camera frame from matched normalised coordinates, by
        ``cv2.triangulatePoints`` (the linear, homogeneous solution) with the projection
        matrices ``[I | 0]`` and ``[R | t]`` of ``left2right``.

        Parameters
        ----------
        x_left, x_right : numpy.ndarray, shape (N, 2)
            Undistorted normalised coordinates (``x / z``, ``y / z``) of both cameras, finite
            (as :meth:`normalise` returns them).

        Returns
        -------
        numpy.ndarray, shape (N, 3)
            The points in the left camera frame, mm.

        Raises
        ------
        CalibrationError
            If a pair of rays is parallel (a point at infinity: its homogeneous scale is 0) or
            meets beyond the range of floats.
        """
        p1 = np.hstack([np.eye(3), np.zeros((3, 1))])
        p2 = np.hstack([self.rotation, self.translation[:, None]])
        hom = cv2.triangulatePoints(p1, p2, x_left.T.copy(), x_right.T.copy())
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            points = (hom[:3] / hom[3]).T
        bad = ~np.isfinite(points).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise CalibrationError(
                f"point {i} cannot be triangulated: its two rays are parallel (homogeneous "
                f"scale {hom[3, i]:.3g})"
            )
        return points

    def perturbed(self, sigmas: dict, rng: np.random.Generator) -> StereoRig:
        """A rig whose parameters differ from this one by normal calibration errors.

        ``sigmas`` holds the standard deviations ``focal_px``, ``principal_point_px``, ``k1``
        (both cameras), ``extrinsic_rotation_rad`` and ``extrinsic_translation_mm`` (of
        ``left2right``). Draws, in order: the extrinsic rotation, each camera's focal lengths,
        principal point and ``k1`` (left, then right), the extrinsic translation.

        Raises
        ------
        CalibrationError
            If a standard deviation is missing, not finite or negative.
        """
        for key in SIGMA_KEYS:
            value = sigmas.get(key)
            if value is None or not (np.isfinite(value) and value >= 0):
                raise CalibrationError(
                    f"calibration sigma {key} = {value!r}: must be given, finite and >= 0 "
                    f"(keys {', '.join(SIGMA_KEYS)})"
                )
        rot = geo.rotvec_to_matrix(rng.normal(0.0, sigmas["extrinsic_rotation_rad"], 3))
        left = _perturbed_camera(self.left, sigmas, rng)
        right = _perturbed_camera(self.right, sigmas, rng)
        rotation = rot @ self.rotation
        translation = self.translation + rng.normal(0.0, sigmas["extrinsic_translation_mm"], 3)
        return StereoRig.from_left2right(left, right, geo.make_transform(rotation, translation))

    def aim_point(self, distance_mm: float) -> np.ndarray:
        """Sensor-frame point ``distance_mm`` from the baseline midpoint, where both optical axes
        point best (along the line from the midpoint to the axes' closest approach)."""
        if not (np.isfinite(distance_mm) and distance_mm > 0):
            raise CalibrationError(f"aim distance {distance_mm} mm must be a finite number > 0")
        c_left, d_left = np.zeros(3), np.array([0.0, 0.0, 1.0])
        c_right = -self.rotation.T @ self.translation
        d_right = self.rotation.T @ np.array([0.0, 0.0, 1.0])
        w = c_left - c_right
        b = d_left @ d_right
        s = (b * (d_right @ w) - (d_left @ w)) / (1 - b**2)
        u = ((d_right @ w) - b * (d_left @ w)) / (1 - b**2)
        meet = 0.5 * (c_left + s * d_left + c_right + u * d_right)
        mid = 0.5 * (c_left + c_right)
        direction = (meet - mid) / np.linalg.norm(meet - mid)
        return mid + distance_mm * direction


def _perturbed_camera(camera: PinholeCamera, sigmas: dict, rng) -> PinholeCamera:
    """``camera`` with normal errors on ``fx fy`` (``focal_px``), ``cx cy``
    (``principal_point_px``) and ``k1`` (``k1``), drawn in that order; an ideal camera gets
    ``k1 k2 p1 p2`` with the error on ``k1``."""
    focal = rng.normal(0.0, sigmas["focal_px"], 2)
    centre = rng.normal(0.0, sigmas["principal_point_px"], 2)
    dist = np.array(camera.dist or (0.0, 0.0, 0.0, 0.0), dtype=float)
    dist[0] += rng.normal(0.0, sigmas["k1"])
    return replace(
        camera,
        fx=float(camera.fx + focal[0]),
        fy=float(camera.fy + focal[1]),
        cx=float(camera.cx + centre[0]),
        cy=float(camera.cy + centre[1]),
        dist=tuple(dist),
    )


def stereo_rig(camera: PinholeCamera, baseline_mm: float, convergence_mm: float) -> StereoRig:
    """Two equal cameras, the right one ``baseline_mm`` along the left one's x axis, both aimed
    at the point ``convergence_mm`` in front of the left camera."""
    if not (baseline_mm > 0 and convergence_mm > 0):
        raise CalibrationError(
            f"baseline ({baseline_mm} mm) and convergence distance ({convergence_mm} mm) "
            "must be > 0"
        )
    right2left = geo.look_at([baseline_mm, 0.0, 0.0], [0.0, 0.0, convergence_mm], up=[0, -1, 0])
    return StereoRig(camera, camera, right2left)


__all__ = ["StereoRig", "stereo_rig"]
