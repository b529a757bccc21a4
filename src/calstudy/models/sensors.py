"""Simulated instruments: a pinhole camera (optionally with lens distortion) and a line-structured
laser sensor.

Each instrument maps true geometry to what it reports, with a stated noise model; every noise
level that is not from a paper is a documented assumption. Millimetres, pixels and radians. A pose
``target2cam`` maps target points to the camera frame, ``p_cam = target2cam @ p_target``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calstudy.core.circles import CIRCLE_METHODS, fit_circles_2d_batch
from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import apply, check_shape, check_transform

#: Termination of the iterative undistortion: exact to double precision for the binocular paper's
#: lenses (Table 1).
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)


def _indices(mask: np.ndarray, limit: int = 10) -> str:
    idx = np.flatnonzero(mask)
    text = ", ".join(str(i) for i in idx[:limit])
    return text + (", ..." if idx.size > limit else "")


# ----------------------------------------------------------------------------------------------
# pinhole camera


@dataclass(frozen=True, kw_only=True)
class PinholeCamera:
    """A pinhole camera, hybrid Eq. 15, ideal unless it has OpenCV lens distortion (binocular
    Eq. 6).

    The camera frame has its origin at the projection centre, z along the optical axis (points
    in front have z > 0), x towards increasing u and y towards increasing v. Pixel centres are at
    integer coordinates (OpenCV's convention), so the image spans ``-0.5 <= u <= width - 0.5``
    and ``-0.5 <= v <= height - 0.5``.

    Attributes
    ----------
    fx, fy : float
        Focal lengths in px, positive.
    cx, cy : float
        Principal point in px.
    skew : float
        Skew factor ``K[0, 1]`` in px (the paper's gamma_c); 0 for OpenCV compatibility.
    width, height : int
        Image size in px.
    dist : tuple of float
        OpenCV distortion coefficients ``k1 k2 p1 p2 [k3 ...]`` (4, 5, 8, 12 or 14 values);
        empty (the default) for an ideal camera.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    skew: float = 0.0
    width: int
    height: int
    dist: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        values = [self.fx, self.fy, self.cx, self.cy, self.skew, self.width, self.height]
        if not np.isfinite(values).all():
            raise CalibrationError(f"camera parameters must be finite; got {values}")
        dist = tuple(float(d) for d in np.asarray(self.dist, dtype=float).reshape(-1))
        if len(dist) not in (0, 4, 5, 8, 12, 14) or not np.isfinite(dist).all():
            raise CalibrationError(
                f"distortion must be 0, 4, 5, 8, 12 or 14 finite OpenCV coefficients; got {dist}"
            )
        object.__setattr__(self, "dist", dist)
        if self.fx <= 0 or self.fy <= 0:
            raise CalibrationError(f"focal lengths must be positive; got {self.fx}, {self.fy} px")
        if self.width <= 0 or self.height <= 0:
            raise CalibrationError(f"image size must be positive; got {self.width} x {self.height}")

    @property
    def K(self) -> np.ndarray:  # noqa: N802  (the standard name of the intrinsic matrix)
        """Intrinsic matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``, shape (3, 3), px."""
        return np.array([[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def distorted(self) -> bool:
        """True if the camera has a non-zero distortion coefficient."""
        return any(d != 0.0 for d in self.dist)

    @property
    def dist_coeffs(self) -> np.ndarray:
        """The distortion coefficients as OpenCV takes them, shape (len(dist),)."""
        return np.array(self.dist, dtype=float)

    def project(self, points_cam) -> np.ndarray:
        """Image coordinates of points given in the camera frame.

        Parameters
        ----------
        points_cam : array_like, shape (N, 3)
            Points in the camera frame, mm.

        Returns
        -------
        numpy.ndarray, shape (N, 2)
            ``(u, v)`` in px, noise-free; through the lens distortion (``cv2.projectPoints``)
            if the camera has one.

        Raises
        ------
        CalibrationError
            On a wrong shape, non-finite values, or a point at or behind the camera (z <= 0).
        """
        p = check_shape("points_cam", points_cam, (None, 3))
        behind = p[:, 2] <= 0
        if behind.any():
            i = int(np.argmax(behind))
            raise CalibrationError(
                f"target behind the camera: point {i} at z = {p[i, 2]:.1f} mm "
                f"({int(behind.sum())} of {len(p)} points at z <= 0)"
            )
        if self.distorted:
            zero = np.zeros(3)
            uv, _ = cv2.projectPoints(p, zero, zero, self.K, self.dist_coeffs)
            return uv.reshape(-1, 2)
        q = p @ self.K.T
        return q[:, :2] / q[:, 2:]

    def normalise(self, uv) -> np.ndarray:
        """Undistorted normalised coordinates ``(N, 2)`` (``x / z``, ``y / z`` in the camera
        frame) of image points ``uv`` ``(N, 2)`` px, by ``cv2.undistortPointsIter``."""
        pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        return cv2.undistortPointsIter(
            pts, self.K, self.dist_coeffs, None, None, UNDISTORT_CRITERIA
        ).reshape(-1, 2)

    def in_image(self, uv) -> np.ndarray:
        """Boolean mask, shape (N,), of image points ``uv`` (N, 2) that lie inside the image."""
        uv = np.asarray(uv, dtype=float)
        return (
            (uv[:, 0] >= -0.5)
            & (uv[:, 0] <= self.width - 0.5)
            & (uv[:, 1] >= -0.5)
            & (uv[:, 1] <= self.height - 0.5)
        )

    def observe(
        self,
        target2cam,
        points_target,
        sigma_px: float,
        rng: np.random.Generator,
        require_in_image: bool = True,
    ) -> np.ndarray:
        """Image coordinates of target points as a feature detector reports them.

        The true projection plus i.i.d. Gaussian noise of ``sigma_px`` on u and v, standing for
        the error of the ellipse-centre extraction (hybrid 3.2.2).

        Parameters
        ----------
        target2cam : array_like, shape (4, 4)
            Pose of the target in the camera frame.
        points_target : array_like, shape (N, 3)
            Points in the target frame, mm.
        sigma_px : float
            Standard deviation of the pixel noise per coordinate, px, >= 0.
        rng : numpy.random.Generator
            Source of the noise.
        require_in_image : bool
            Raise if a noise-free projection falls outside the image.

        Returns
        -------
        numpy.ndarray, shape (N, 2)
            Noisy ``(u, v)`` in px.

        Raises
        ------
        CalibrationError
            On bad input, a point behind the camera, or (with ``require_in_image``) points
            outside the image.
        """
        pose = check_transform("target2cam", target2cam)
        pts = check_shape("points_target", points_target, (None, 3))
        if not (np.isfinite(sigma_px) and sigma_px >= 0):
            raise CalibrationError(f"sigma_px must be >= 0; got {sigma_px}")
        uv = self.project(apply(pose, pts))
        if require_in_image:
            outside = ~self.in_image(uv)
            if outside.any():
                i = int(np.argmax(outside))
                where = f"points {_indices(outside)}; point {i} at u = {uv[i, 0]:.1f}, v = "
                raise CalibrationError(
                    f"{int(outside.sum())} of {len(uv)} points fall outside the {self.width} x "
                    f"{self.height} image ({where}{uv[i, 1]:.1f} px)"
                )
        return uv + rng.normal(0.0, sigma_px, uv.shape)


# ----------------------------------------------------------------------------------------------
# line-structured laser sensor


def stripe_offset_recommended(radius_mm: float) -> float:
    """Distance in mm of the laser plane from the sphere centre that hybrid 3.1 recommends.

    The paper asks that "the laser should project on R/4 of the sphere surface". We read it as:
    the laser plane passes at ``|y| = R/4`` from the sphere centre, so the stripe is a circle of
    radius ``sqrt(15)/4 R ≈ 0.97 R``, close to a great circle, and its centre is well fixed in
    the plane. The other reading (the plane ``R/4`` below the sphere's apex, ``|y| = 3R/4``)
    gives a smaller circle but a better-conditioned ``y``; notebooks that depend on this choice
    should sweep the offset.

    Parameters
    ----------
    radius_mm : float
        Sphere radius, mm, positive.

    Returns
    -------
    float
        ``radius_mm / 4``.
    """
    if not (np.isfinite(radius_mm) and radius_mm > 0):
        raise CalibrationError(f"sphere radius must be positive; got {radius_mm} mm")
    return radius_mm / 4.0


@dataclass(frozen=True)
class LineLaserSensor:
    """A line-structured laser sensor that measures a sphere centre in one shot (hybrid 3.1).

    Sensor frame: origin at the sensor, z the viewing direction (the sphere is in front, z > 0),
    the laser plane is ``y = 0`` with x along the stripe. A sphere of centre ``(cx, cy, cz)``
    and known radius ``R`` is cut by the plane in a circle of radius ``r = sqrt(R^2 - cy^2)``
    centred at ``(cx, 0, cz)``. The sensor sees the arc of that circle that faces it: the points
    whose direction from the circle centre lies within ``arc_half_angle_deg`` of the direction
    from the circle centre to the sensor origin, sampled at ``n_points`` equal angular steps.
    Each point gets independent Gaussian noise of ``sigma_point_mm`` in x and in z (within the
    laser plane). A circle fit (see ``circle_fit``) gives ``cx, cz`` and ``r``; then
    ``cy = side * sqrt(R^2 - r^2)``. This is the one-shot, known-radius method
    the paper cites as its reference [17], as we read it.

    Attributes
    ----------
    sigma_point_mm : float
        Noise of one stripe point per in-plane coordinate, mm. Assumption: 0.02 mm, the
        order of the single-point repeatability that industrial line-laser sensors specify at
        short stand-off; the paper states none.
    n_points : int
        Stripe points on the visible arc. Assumption: 200 (a stripe of about 1000 camera
        columns over the sensor's field, of which the sphere covers a fifth).
    arc_half_angle_deg : float
        Half-angle of the visible arc, deg. Assumption: 70 deg; beyond it the surface is seen
        so obliquely that the stripe is lost.
    side : int
        Which side of the laser plane the sphere centre is on, known from the set-up: +1 means
        the centre has ``y > 0`` in the sensor frame (the stripe crosses the sphere on its -y
        side), -1 means ``y < 0``. The circle alone cannot tell the two apart.
    circle_fit : {"geometric", "kasa"}
        Circle fit of the stripe (:func:`calstudy.core.circles.fit_circles_2d_batch`). Default
        ``"geometric"``: the Kasa fit refined to the orthogonal-distance (maximum-likelihood)
        circle, because the plain Kasa fit is biased on the visible arc (at the default noise
        about 1e-3 mm in x-z and 2e-3 mm in y, a tenth of the per-shot scatter in y) and a
        sensor's own software would not leave that bias in; ``"kasa"`` keeps the algebraic fit.
    centre_floor_mm : float
        Standard deviation (mm, per axis) of an independent, isotropic error added to every
        measured centre beyond the stripe model (the sensor's own calibration over its field,
        the sphere's form): 0 leaves the stripe model as the whole noise.
    correlation_scale : float
        Factor in [0, 1] on the correlation between the y error and the x, z errors that the
        known-radius reconstruction gives: the y error of a shot becomes ``s e_y + sqrt(1 - s^2)
        sigma_y n`` with ``n`` standard normal and ``sigma_y`` its linearised standard deviation,
        so its variance stays and its covariances with x and z scale by ``s``. 1 (default) is
        the stripe model as derived.
    """

    sigma_point_mm: float = 0.02
    n_points: int = 200
    arc_half_angle_deg: float = 70.0
    side: int = 1
    circle_fit: str = "geometric"
    centre_floor_mm: float = 0.0
    correlation_scale: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma_point_mm) and self.sigma_point_mm >= 0):
            raise CalibrationError(f"sigma_point_mm must be >= 0; got {self.sigma_point_mm}")
        if self.n_points < 3:
            raise CalibrationError(f"a circle fit needs at least 3 points; got {self.n_points}")
        if not 0 < self.arc_half_angle_deg <= 180:
            raise CalibrationError(
                f"arc_half_angle_deg must be in (0, 180]; got {self.arc_half_angle_deg}"
            )
        if self.side not in (1, -1):
            raise CalibrationError(f"side must be +1 or -1; got {self.side}")
        if self.circle_fit not in CIRCLE_METHODS:
            raise CalibrationError(
                f"circle_fit must be one of {CIRCLE_METHODS}; got {self.circle_fit!r}"
            )
        if not (np.isfinite(self.centre_floor_mm) and self.centre_floor_mm >= 0):
            raise CalibrationError(f"centre_floor_mm must be >= 0; got {self.centre_floor_mm}")
        if not 0 <= self.correlation_scale <= 1:
            raise CalibrationError(
                f"correlation_scale must be in [0, 1]; got {self.correlation_scale}"
            )

    def _check_geometry(self, c: np.ndarray, radius: float, r: np.ndarray) -> None:
        behind = c[:, 2] <= 0
        if behind.any():
            i = int(np.argmax(behind))
            raise CalibrationError(
                f"sphere centre is behind the sensor: z = {c[i, 2]:.1f} mm at shot {i}"
            )
        miss = np.abs(c[:, 1]) >= radius
        if miss.any():
            i = int(np.argmax(miss))
            raise CalibrationError(
                f"laser plane misses the sphere: |y| = {abs(c[i, 1]):.1f} mm >= radius "
                f"{radius:.1f} mm at shot {i}"
            )
        wrong = self.side * c[:, 1] < 0
        if wrong.any():
            i = int(np.argmax(wrong))
            raise CalibrationError(
                f"sphere centre is on the wrong side of the laser plane: y = {c[i, 1]:.2f} mm "
                f"at shot {i}, but side = {self.side:+d}"
            )
        inside = np.hypot(c[:, 0], c[:, 2]) <= r
        if inside.any():
            i = int(np.argmax(inside))
            raise CalibrationError(
                f"the sensor is inside the sphere at shot {i}: distance "
                f"{np.hypot(c[i, 0], c[i, 2]):.1f} mm from the stripe centre <= its radius "
                f"{r[i]:.1f} mm"
            )

    def _stripe(self, c: np.ndarray, r: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy visible arcs in the laser plane, shape (N, n_points, 2) as (x, z), mm."""
        towards_sensor = np.arctan2(-c[:, 2], -c[:, 0])
        half = np.deg2rad(self.arc_half_angle_deg)
        angles = towards_sensor[:, None] + np.linspace(-half, half, self.n_points)[None, :]
        arcs = np.stack(
            [c[:, 0:1] + r[:, None] * np.cos(angles), c[:, 2:3] + r[:, None] * np.sin(angles)],
            axis=2,
        )
        return arcs + rng.normal(0.0, self.sigma_point_mm, arcs.shape)

    def measure_sphere_centre(self, centres_sensor, radius_mm: float, rng: np.random.Generator):
        """Sphere centres as the sensor reports them, one laser shot each.

        Parameters
        ----------
        centres_sensor : array_like, shape (N, 3) or (3,)
            True sphere centres in the sensor frame, mm.
        radius_mm : float
            The sphere's radius, mm, known (calibrated) and used as true.
        rng : numpy.random.Generator
            Source of the stripe-point noise.

        Returns
        -------
        numpy.ndarray, shape like ``centres_sensor``
            Measured centres in the sensor frame, mm.

        Raises
        ------
        CalibrationError
            On bad input; if a centre is behind the sensor (z <= 0), the laser plane misses or
            grazes the sphere (``|y| >= R``), a centre is on the other side than ``side``, the
            sensor is inside the sphere, or noise makes the fitted stripe radius exceed ``R``
            (the plane too close to the centre for this noise).
        """
        single = np.ndim(centres_sensor) == 1
        if single:
            c = check_shape("centres_sensor", centres_sensor, (3,))[None, :]
        else:
            c = check_shape("centres_sensor", centres_sensor, (None, 3))
        if c.shape[0] == 0:
            raise CalibrationError("centres_sensor is empty (0 sphere centres)")
        if not (np.isfinite(radius_mm) and radius_mm > 0):
            raise CalibrationError(f"sphere radius must be positive; got {radius_mm} mm")
        r = np.sqrt(np.maximum(radius_mm**2 - c[:, 1] ** 2, 0.0))
        self._check_geometry(c, radius_mm, r)
        fit_xz, fit_r = fit_circles_2d_batch(self._stripe(c, r, rng), self.circle_fit)
        # round-off may put a noise-free fit through the centre a hair above R
        over = ~(fit_r <= radius_mm * (1.0 + 1e-12))
        if over.any():
            i = int(np.argmax(over))
            raise CalibrationError(
                f"fitted stripe radius {fit_r[i]:.4f} mm > sphere radius {radius_mm} mm at shot "
                f"{i} (laser plane only {abs(c[i, 1]):.3f} mm from the centre); move the stripe "
                "further from the centre"
            )
        y = self.side * np.sqrt(np.maximum(radius_mm**2 - fit_r**2, 0.0))
        out = np.column_stack([fit_xz[:, 0], y, fit_xz[:, 1]])
        # the parts beyond the stripe model draw after it: at their defaults nothing is drawn
        if self.correlation_scale < 1:
            s = self.correlation_scale
            sigma_y = np.sqrt(self._stripe_covariance(c, radius_mm, r)[:, 1, 1])
            noise = rng.normal(0.0, 1.0, len(c))
            out[:, 1] = c[:, 1] + s * (out[:, 1] - c[:, 1]) + np.sqrt(1 - s**2) * sigma_y * noise
        if self.centre_floor_mm > 0:
            out = out + rng.normal(0.0, self.centre_floor_mm, out.shape)
        return out[0] if single else out

    def centre_covariance(self, centres_sensor, radius_mm: float) -> np.ndarray:
        """Covariance of measured sphere centres, linearised from the stripe-point noise.

        The geometric circle fit is the maximum-likelihood circle of the stripe, so to first
        order ``cov(cx, cz, r) = sigma_point^2 (A^T A)^-1`` with row ``[u_x, u_z, 1]`` of ``A``
        per stripe point (``u`` the unit direction from the circle centre to the point), and
        ``(x, y, z) = (cx, side sqrt(R^2 - r^2), cz)`` maps it with ``dy/dr = -side r / |y|``.
        The y-z (and x-y) correlation this gives is strong (about -0.97 at the reference stand-off
        and R/4 stripe offset): a per-axis sigma misses it.
        ``correlation_scale`` scales the covariances of y with x and z, and ``centre_floor_mm``
        adds its variance to every axis, as :meth:`measure_sphere_centre` draws them.

        Parameters
        ----------
        centres_sensor : array_like, shape (N, 3) or (3,)
            Sphere centres in the sensor frame, mm (true, predicted or measured ones).
        radius_mm : float
            Sphere radius, mm.

        Returns
        -------
        numpy.ndarray, shape (N, 3, 3) or (3, 3)
            Covariance of each measured centre along the sensor axes, mm^2.

        Raises
        ------
        CalibrationError
            On bad input or a geometry the sensor cannot measure (see
            :meth:`measure_sphere_centre`).
        """
        single = np.ndim(centres_sensor) == 1
        c = check_shape("centres_sensor", np.atleast_2d(centres_sensor), (None, 3))
        if not (np.isfinite(radius_mm) and radius_mm > 0):
            raise CalibrationError(f"sphere radius must be positive; got {radius_mm} mm")
        r = np.sqrt(np.maximum(radius_mm**2 - c[:, 1] ** 2, 0.0))
        self._check_geometry(c, radius_mm, r)
        cov = self._stripe_covariance(c, radius_mm, r)
        if self.correlation_scale < 1:
            cov[:, 1, [0, 2]] *= self.correlation_scale
            cov[:, [0, 2], 1] *= self.correlation_scale
        if self.centre_floor_mm > 0:
            cov = cov + self.centre_floor_mm**2 * np.eye(3)
        return cov[0] if single else cov

    def _stripe_covariance(self, c: np.ndarray, radius_mm: float, r: np.ndarray) -> np.ndarray:
        """The stripe model's linearised covariance of centres ``c (N, 3)`` (stripe radii
        ``r``), before the parts beyond it."""
        towards_sensor = np.arctan2(-c[:, 2], -c[:, 0])
        half = np.deg2rad(self.arc_half_angle_deg)
        angles = towards_sensor[:, None] + np.linspace(-half, half, self.n_points)[None, :]
        a = np.stack([np.cos(angles), np.sin(angles), np.ones_like(angles)], axis=2)
        cov_fit = self.sigma_point_mm**2 * np.linalg.inv(np.swapaxes(a, 1, 2) @ a)
        jac = np.zeros((c.shape[0], 3, 3))
        jac[:, 0, 0] = 1.0
        jac[:, 2, 1] = 1.0
        jac[:, 1, 2] = -self.side * r / np.abs(c[:, 1])
        return jac @ cov_fit @ np.swapaxes(jac, 1, 2)

    def centre_std(
        self, centre_sensor, radius_mm: float, rng: np.random.Generator, n_shots: int = 500
    ) -> np.ndarray:
        """Per-axis standard deviation of the measured centre over repeated shots.

        The repeatability a user measures by shooting the same sphere ``n_shots`` times without
        moving anything.

        Parameters
        ----------
        centre_sensor : array_like, shape (3,)
            True sphere centre in the sensor frame, mm.
        radius_mm : float
            Sphere radius, mm.
        rng : numpy.random.Generator
            Source of the noise.
        n_shots : int
            Number of shots, >= 2.

        Returns
        -------
        numpy.ndarray, shape (3,)
            Sample standard deviations (ddof = 1) of x, y, z in mm.
        """
        c = check_shape("centre_sensor", centre_sensor, (3,))
        if n_shots < 2:
            raise CalibrationError(f"a standard deviation needs at least 2 shots; got {n_shots}")
        shots = self.measure_sphere_centre(np.tile(c, (n_shots, 1)), radius_mm, rng)
        return shots.std(axis=0, ddof=1)


__all__ = ["UNDISTORT_CRITERIA", "LineLaserSensor", "PinholeCamera", "stripe_offset_recommended"]
