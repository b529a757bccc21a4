"""Calibration targets: the standard sphere and the two-sided 5 x 7 hole target of ``hybrid``.

Dimensions the paper does not give are documented assumptions (each field says why). Lengths in
mm. A target's points are given in its own frame; a pose such as ``front2cam`` maps them to a
sensor, ``p_cam = front2cam @ p_front``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import check_shape, invert, make_transform

#: Rotation by pi about x: the back frame's axes in the front frame (x kept, y and z reversed).
_RX_PI = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True, eq=False)
class Sphere:
    """A standard (reference) sphere.

    Attributes
    ----------
    radius_mm : float
        Radius in mm. Assumption: 12.7 mm, i.e. a 25.4 mm (1 inch) diameter sphere. The paper
        (hybrid 4.2) only says the sphere is very hard, has low thermal expansion and serves the
        robot's thermal compensation; 25.4 mm is a stock size of ceramic reference spheres and
        fits within the stripe of a robot-mounted line-laser sensor.
    centre : numpy.ndarray, shape (3,)
        Centre in mm in the frame the sphere is placed in (for the hand-eye study, the robot
        base frame).
    """

    radius_mm: float = 12.7
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        if not (np.isfinite(self.radius_mm) and self.radius_mm > 0):
            raise CalibrationError(f"sphere radius must be positive; got {self.radius_mm} mm")
        object.__setattr__(self, "centre", check_shape("centre", self.centre, (3,)))


@dataclass(frozen=True, eq=False)
class ManufacturedHoleTarget:
    """One made hole target: true hole centres and the true back-to-front transform.

    Attributes
    ----------
    front_points : numpy.ndarray, shape (rows * cols, 3)
        True hole centres on the front face, in the front frame (``z = 0``), mm.
    back_points : numpy.ndarray, shape (rows * cols, 3)
        True centres of the same holes on the back face, in the back frame (``z = 0``), mm.
    back2front : numpy.ndarray, shape (4, 4)
        True transform from the back frame to the front frame;
        ``back2front @ back_points[k]`` is the exit of hole ``k`` seen from the front frame.
    """

    front_points: np.ndarray
    back_points: np.ndarray
    back2front: np.ndarray


@dataclass(frozen=True)
class HoleTarget:
    """The two-sided planar target of hybrid 3.2.2: ``rows x cols`` through-holes in a plate.

    Frames. The *front frame* has its origin at the centre of the hole grid on the front face,
    x along a row (increasing column index), y along a column (increasing row index), z normal
    to the face pointing out of the front face. The *back frame* has its origin at the grid
    centre on the back face, x along the front x and z pointing out of the back face, so it is
    the front frame rotated by pi about x and moved by the thickness along -z_front. Holes are
    numbered row by row: ``k = row * cols + col``; the same ``k`` is the same physical hole on
    both faces.

    Attributes
    ----------
    rows, cols : int
        Holes per column and per row; the paper's target has 5 x 7.
    pitch_mm : float
        Centre distance of neighbouring holes. Assumption: 10 mm (the paper gives only the
        5 x 7 count); it makes a 40 x 60 mm grid, which fits the field of view of an
        inspection sensor at its working distance.
    thickness_mm : float
        Plate thickness. Assumption: 8 mm, a stiff aluminium plate of that size.
    hole_tolerance_mm : float
        Machining accuracy of the hole positions, 0.05 mm (hybrid 3.2.2). Read as: every hole
        centre lies uniformly within +-tolerance of its CAD position in x and in y.
    """

    rows: int = 5
    cols: int = 7
    pitch_mm: float = 10.0
    thickness_mm: float = 8.0
    hole_tolerance_mm: float = 0.05

    def __post_init__(self) -> None:
        if self.rows < 2 or self.cols < 2 or self.rows * self.cols < 4:
            raise CalibrationError(
                f"hole target needs at least 2 x 2 holes; got {self.rows} x {self.cols}"
            )
        for name in ("pitch_mm", "thickness_mm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise CalibrationError(f"hole target {name} must be positive; got {value}")
        tol = self.hole_tolerance_mm
        if not (np.isfinite(tol) and 0 <= tol < self.pitch_mm / 2):
            raise CalibrationError(
                f"hole_tolerance_mm must be in [0, pitch/2); got {tol} (pitch {self.pitch_mm})"
            )

    @property
    def n_holes(self) -> int:
        """Number of holes, ``rows * cols``."""
        return self.rows * self.cols

    def _grid_xy(self) -> np.ndarray:
        col, row = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        x = (col.ravel() - (self.cols - 1) / 2) * self.pitch_mm
        y = (row.ravel() - (self.rows - 1) / 2) * self.pitch_mm
        return np.column_stack([x, y])

    def front_points(self) -> np.ndarray:
        """Nominal (CAD) hole centres in the front frame, shape ``(rows * cols, 3)``, mm, z = 0."""
        return np.column_stack([self._grid_xy(), np.zeros(self.n_holes)])

    def back_points(self) -> np.ndarray:
        """Nominal hole centres in the back frame, shape ``(rows * cols, 3)``, mm, z = 0.

        The same holes as :meth:`front_points` (same order); y is mirrored because the back
        frame is turned over about x.
        """
        return self.front_points() @ _RX_PI

    def back2front(self) -> np.ndarray:
        """Nominal transform from the back frame to the front frame, shape (4, 4)."""
        return make_transform(_RX_PI, [0.0, 0.0, -self.thickness_mm])

    def front2back(self) -> np.ndarray:
        """Inverse of :meth:`back2front`."""
        return invert(self.back2front())

    def manufactured(self, rng: np.random.Generator) -> ManufacturedHoleTarget:
        """Draw one physical target: true hole centres and the true back-to-front transform.

        Model (an assumption; the paper states only the 0.05 mm accuracy):

        - Each hole is a straight through-hole. Its centre on the front face is its CAD
          position plus an error uniform in ``[-tol, tol]`` in x and in y, independent per hole
          and axis (``tol = hole_tolerance_mm``).
        - All holes are drilled in one set-up along one common axis that may be slightly off
          the plate normal (perpendicularity error): hole ``k`` leaves the back face at its front
          centre plus one common in-plane offset ``d``, uniform in ``[-tol, tol]`` in x and y.
          The faces are parallel and the plate has its nominal thickness.
        - The front frame is the reference (it is the CAD frame of the front face). The back
          frame is defined by the back hole pattern: its origin is the centre of the nominal
          grid shifted by ``d``, its axes those of the nominal back frame. So the true
          ``back2front`` is the nominal one with its translation moved by ``d``, and the back
          centres in the back frame carry the same per-hole errors (y mirrored) as the front.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the machining errors.

        Returns
        -------
        ManufacturedHoleTarget
        """
        tol = self.hole_tolerance_mm
        error = np.column_stack([rng.uniform(-tol, tol, (self.n_holes, 2)), np.zeros(self.n_holes)])
        offset = np.append(rng.uniform(-tol, tol, 2), 0.0)
        front = self.front_points() + error
        back2front = self.back2front()
        back2front[:3, 3] += offset
        exits_front = front + offset + np.array([0.0, 0.0, -self.thickness_mm])
        back = (exits_front - back2front[:3, 3]) @ back2front[:3, :3]
        return ManufacturedHoleTarget(front, back, back2front)


__all__ = ["HoleTarget", "ManufacturedHoleTarget", "Sphere"]


# ----------------------------------------------------------------------------------------------
# the image of a circular target


def circle_image_centres(k_matrix, centres_cam, normals_cam, radius: float) -> np.ndarray:
    """Centres ``(N, 2)`` (px) of the ellipses that circles of ``radius`` mm project to in a
    pinhole camera ``k_matrix`` (no distortion): exact, by the projection of the circle's conic.

    A circle with centre ``c`` and unit normal ``n`` (camera frame, ``(N, 3)`` each) lies in the
    plane spanned by two unit vectors ``e1, e2`` normal to ``n``; the homography ``H = K [e1 e2
    c]`` maps its plane coordinates to the image, so its image is the conic ``H^-T diag(1, 1,
    -r^2) H^-1``, whose centre is ``-A^-1 b`` for the conic ``[[A, b], [b^T, c]]``. Under
    perspective that centre is not the image of the circle's centre: a detector that fits the
    ellipse (or takes the centroid of its edge) is biased by the difference, which grows with
    ``radius^2`` and the tilt of the circle, and vanishes for a circle facing the camera.
    """
    k, c, n = _check_circles(k_matrix, centres_cam, normals_cam, radius)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = geo.cross_rows(n, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = geo.cross_rows(n, e1)
    h = k @ np.stack([e1, e2, c], axis=2)  # (N, 3, 3), columns e1, e2, c
    h_inv = np.linalg.inv(h)
    conic = np.swapaxes(h_inv, 1, 2) @ np.diag([1.0, 1.0, -(float(radius) ** 2)]) @ h_inv
    a, b = conic[:, :2, :2], conic[:, :2, 2]
    det = np.linalg.det(a)
    if not np.all(det * a[:, 0, 0] > 0.0) and radius > 0.0:
        bad = int(np.flatnonzero(~(det * a[:, 0, 0] > 0.0))[0])
        raise CalibrationError(
            f"circle {bad} does not image as an ellipse (its conic is degenerate or a "
            "hyperbola): part of it lies at or behind the camera's plane"
        )
    return -np.linalg.solve(a, b[..., None])[..., 0]


def _check_circles(k_matrix, centres_cam, normals_cam, radius: float):
    """The checked inputs of :func:`circle_image_centres`: ``K`` (3, 3), centres and unit
    normals ``(N, 3)``, every circle wholly in front of the camera and not seen edge-on."""
    k = geo.check_finite("camera matrix", geo.check_shape("camera matrix", k_matrix, (3, 3)))
    c = geo.check_finite("circle centres", np.atleast_2d(np.asarray(centres_cam, dtype=float)))
    n = geo.check_finite("circle normals", np.atleast_2d(np.asarray(normals_cam, dtype=float)))
    if c.ndim != 2 or c.shape[1] != 3 or n.shape != c.shape:
        raise CalibrationError(
            f"circle centres {c.shape} and normals {n.shape} must both be (N, 3)"
        )
    if not (np.isfinite(radius) and radius >= 0.0):
        raise CalibrationError(f"circle radius {radius} mm must be finite and >= 0")
    norm = np.linalg.norm(n, axis=1)
    if np.any(norm < 1e-12):
        raise CalibrationError(f"circle normal {int(np.argmin(norm))} is zero")
    n = n / norm[:, None]
    # the lowest depth on the circle: its centre's depth less the radius times the in-plane
    # reach along the optical axis
    nearest = c[:, 2] - radius * np.sqrt(np.clip(1.0 - n[:, 2] ** 2, 0.0, 1.0))
    if np.any(nearest <= 0.0):
        bad = int(np.argmin(nearest))
        raise CalibrationError(
            f"circle {bad} reaches depth {nearest[bad]:.4g} mm: a circle must lie wholly in "
            "front of the camera"
        )
    edge_on = np.abs(np.sum(n * c, axis=1)) <= 1e-9 * np.linalg.norm(c, axis=1)
    if np.any(edge_on):
        raise CalibrationError(
            f"circle {int(np.flatnonzero(edge_on)[0])} is seen edge-on (its plane passes "
            "through the camera centre): it images as a line"
        )
    return k, c, n


def circle_centre_bias(k_matrix, centres_cam, normals_cam, radius: float) -> np.ndarray:
    """Perspective bias ``(N, 2)`` (px) of a circle's detected centre: the centre of its image
    ellipse (:func:`circle_image_centres`) minus the image of its centre; zero for ``radius``
    0."""
    c = np.atleast_2d(np.asarray(centres_cam, dtype=float))
    if radius == 0.0:
        return np.zeros((len(c), 2))
    k = np.asarray(k_matrix, dtype=float)
    proj = (k @ c.T).T
    return circle_image_centres(k, c, normals_cam, radius) - proj[:, :2] / proj[:, 2:]
