"""Hand-eye calibration: the fixed-sphere method, AX = XB baselines, the stationary-sensor chain.

The fixed-sphere method (hybrid paper, section 3.1, Eq. 6-14) uses one point fixed in the robot
base frame, the centre of a standard sphere, measured by the flange-mounted sensor from many robot
poses. With the flange pose ``flange2base = [R_0 | T_0]`` and the measured centre ``X_F`` in the
sensor frame, every measurement satisfies ``X_B = R_0 (R_F X_F + T_F) + T_0`` (Eq. 7).

* Pure translations (fixed ``R_0``) give ``R_F`` by SVD (Eq. 9-11).
* Pose changes then give ``T_F`` by linear least squares (Eq. 12-14).
* :func:`sphere_handeye_ml` refines ``R_F, T_F`` and ``X_B`` jointly on all measurements,
  weighting by the sensor's noise: the maximum-likelihood estimate, whose covariance at the true
  parameters is the Cramer-Rao bound.

:func:`opencv_handeye` wraps ``cv2.calibrateHandEye`` (Tsai, Park, Horaud, Andreff, Daniilidis),
which needs the full pose of a target in the sensor frame rather than a point.

:func:`stationary_sensor_to_base` is Eq. 23: a stationary camera located in the robot base frame
from one robot pose and two images of a two-sided target.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.estimation import (
    Estimate,
    apply_fit_check,
    check_condition,
    condition_number,
    goodness_of_fit,
    levenberg_marquardt,
)
from calstudy.estimators.fitting import fit_rotation

#: largest orientation spread (rad) accepted among moves that should be pure translations
PURE_TRANSLATION_TOL = np.deg2rad(0.01)
#: condition number of Eq. 13's matrix above which T_F is declared undetermined
MAX_CONDITION = 1e6
#: condition number of the whitened ML Jacobian above which R_F, T_F, X_B are unobservable (a
#: well-posed station gives about 1e5; translation-only poses give 1e17)
MAX_ML_CONDITION = 1e10
#: smallest rotation (rad) of a motion between two poses that counts for Tsai-Lenz, and smallest
#: angle between the axes of two such motions (the dualarm chain's rotation diversity check)
MIN_PAIR_ROTATION = np.deg2rad(0.5)
#: Rotation (rad) below which a motion counts as none, and axes this close as one axis, in every
#: call of :func:`opencv_handeye`: 0.01 deg (36 arc seconds), below the orientation repeatability
#: of an industrial robot, so such motions carry no information on the hand-eye rotation.
DEGENERATE_ROTATION = np.deg2rad(0.01)

OPENCV_METHODS = {
    "Tsai": cv2.CALIB_HAND_EYE_TSAI,
    "Park": cv2.CALIB_HAND_EYE_PARK,
    "Horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "Andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "Daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}


def _check_measurements(name: str, flange2base, centres) -> tuple[np.ndarray, np.ndarray]:
    poses = geo.check_transform(f"{name} flange poses", flange2base)
    if poses.ndim != 3:
        raise CalibrationError(f"{name} flange poses have shape {poses.shape}; expected (N, 4, 4)")
    pts = geo.check_shape(f"{name} sphere centres", centres, (poses.shape[0], 3))
    return poses, pts


def rotation_from_translations(flange2base, centres, center: bool = True) -> np.ndarray:
    """Sensor-to-flange rotation ``R_F`` from pure robot translations (Eq. 9-11).

    Parameters
    ----------
    flange2base : (n, 4, 4) array
        Flange poses in the robot base frame (mm); all with the same orientation.
    centres : (n, 3) array
        The fixed sphere centre measured in the sensor frame at each pose (mm).
    center : bool
        Subtract the centroids of the difference vectors as Eq. 11 does (the paper's method).
        Without centring (orthogonal Procrustes) three non-collinear positions suffice.

    Returns
    -------
    (3, 3) array
        ``R_F`` of ``sensor2flange``.

    Raises
    ------
    CalibrationError
        If the orientations differ, if there are too few moves or they are collinear, or if the
        sphere centre does not move as far as the flange (:data:`MAX_SCALE_RATIO`: a unit
        mismatch such as centres in metres).
    """
    poses, x_f = _check_measurements("translation", flange2base, centres)
    n = poses.shape[0]
    need = 4 if center else 3
    if n < need:
        raise CalibrationError(
            f"rotation from translations needs at least {need} positions; got {n}"
        )
    r0 = poses[0, :3, :3]
    spread = geo.rotation_error(poses[:, :3, :3], r0)
    if spread.max() > PURE_TRANSLATION_TOL:
        worst = int(np.argmax(spread))
        raise CalibrationError(
            f"moves are not pure translations: orientation of move {worst} differs from move 0 "
            f"by {np.rad2deg(spread[worst]):.4f} deg (tolerance "
            f"{np.rad2deg(PURE_TRANSLATION_TOL):.4f} deg)"
        )
    p1 = x_f[0] - x_f[1:]  # Eq. 10, rows are X_F1 - X_Fi
    p0 = (poses[1:, :3, 3] - poses[0, :3, 3]) @ r0  # rows are R_0^T (T_0i - T_01)
    spread_pts = (poses[1:, :3, 3] - poses[1:, :3, 3].mean(axis=0)) if center else p0
    sv = np.linalg.svd(spread_pts, compute_uv=False)
    if sv.size < 2 or sv[1] <= 1e-9 * max(sv[0], 1.0):
        raise CalibrationError(
            "fewer than 3 non-collinear translations: the translation vectors span one line "
            f"(singular values {', '.join(f'{s:.3g}' for s in sv)} mm); "
            "add a translation off that line"
        )
    _check_same_scale(p1, p0)
    return fit_rotation(p1, p0, center=center)


#: Largest ratio (either way) of the RMS displacement of the sphere centre in the sensor frame to
#: that of the flange over pure translations: equal for a rigid sensor (up to the noise); a unit
#: mismatch gives 1000 (metres) or 25.4 (inches).
MAX_SCALE_RATIO = 2.0


def _check_same_scale(moved_sensor: np.ndarray, moved_flange: np.ndarray) -> None:
    """Refuse pure translations whose sensor-frame displacements ``(n, 3)`` are not as long as
    the flange's ``(n, 3)`` (a rotation keeps lengths): a unit mismatch between the two."""
    rms_s = float(np.sqrt(np.mean(np.sum(moved_sensor**2, axis=1))))
    rms_f = float(np.sqrt(np.mean(np.sum(moved_flange**2, axis=1))))
    ratio = rms_s / rms_f
    if not (1.0 / MAX_SCALE_RATIO <= ratio <= MAX_SCALE_RATIO):
        raise CalibrationError(
            f"over the pure translations the sphere centre moves {ratio:.4g} times as far in the "
            f"sensor frame as the flange (RMS {rms_s:.4g} against {rms_f:.4g} mm; a rigidly "
            f"mounted sensor gives 1, allowed {1 / MAX_SCALE_RATIO:g} to {MAX_SCALE_RATIO:g}): "
            "the sensor data and the flange poses look like different units (metres give "
            "0.001); give both in mm"
        )


def translation_from_rotations(flange2base, centres, rotation) -> tuple[np.ndarray, float]:
    """Sensor-to-flange translation ``T_F`` from pose changes, given ``R_F`` (Eq. 12-14).

    Every pose is differenced with the first one (Eq. 13, read with ``X_Fi`` in row ``i``; the
    printed equation repeats ``X_F2``) and the stacked system ``A T_F = B`` is solved by least
    squares (Eq. 14).

    Parameters
    ----------
    flange2base : (m, 4, 4) array
        Flange poses with different orientations (mm).
    centres : (m, 3) array
        Sphere centre in the sensor frame at each pose (mm).
    rotation : (3, 3) array
        ``R_F`` from :func:`rotation_from_translations`.

    Returns
    -------
    t_f : (3,) array
        ``T_F`` in mm.
    condition_number : float
        Condition number of ``A``.

    Raises
    ------
    CalibrationError
        If all moves are pure translations (``T_F`` undefined) or the rotation axes are all
        parallel (``A`` rank deficient; the condition number is given).
    """
    poses, x_f = _check_measurements("rotation", flange2base, centres)
    r_f = geo.check_rotation("R_F", rotation)
    m = poses.shape[0]
    if m < 3:
        raise CalibrationError(f"T_F needs at least 3 poses with different orientations; got {m}")
    r = poses[:, :3, :3]
    t = poses[:, :3, 3]
    turn = geo.rotation_error(r[1:], r[0])
    if turn.max() < 1e-9:
        raise CalibrationError(
            f"T_F is undefined: the {m} moves are pure translations "
            f"(largest rotation between poses {np.rad2deg(turn.max()):.3g} deg); "
            "add moves that change the flange orientation"
        )
    a = (r[1:] - r[0]).reshape(-1, 3)
    world = np.einsum("nij,jk,nk->ni", r, r_f, x_f)  # R_0i R_F X_Fi
    b = (world[0] - world[1:] + t[0] - t[1:]).reshape(-1)
    cond = condition_number(a)
    if cond > MAX_CONDITION:
        raise CalibrationError(
            f"rotation axes of the {m - 1} moves are parallel (condition number {cond:.3g}); "
            "add a move about another axis"
        )
    t_f, *_ = np.linalg.lstsq(a, b, rcond=None)
    return t_f, cond


def sphere_handeye(
    trans_flange2base, trans_centres, rot_flange2base, rot_centres, center: bool = True
) -> Estimate:
    """The paper's two-step fixed-sphere hand-eye calibration (Eq. 6-14).

    Parameters
    ----------
    trans_flange2base, trans_centres : (n, 4, 4), (n, 3) arrays
        Pure translations (same flange orientation) and the measured centres (mm).
    rot_flange2base, rot_centres : (m, 4, 4), (m, 3) arrays
        Pose changes and the measured centres (mm).
    center : bool
        Centre the difference vectors as Eq. 11 does.

    Returns
    -------
    Estimate
        ``value`` is ``sensor2flange`` (4 x 4); ``params`` is ``[T_F, rotvec(R_F)]``;
        ``condition_number`` that of Eq. 13; no covariance (closed form).
    """
    r_f = rotation_from_translations(trans_flange2base, trans_centres, center=center)
    t_f, cond = translation_from_rotations(rot_flange2base, rot_centres, r_f)
    sensor2flange = geo.make_transform(r_f, t_f)
    return Estimate(
        value=sensor2flange,
        params=geo.pose_to_vector(sensor2flange),
        condition_number=cond,
        method="sphere (Eq. 6-14)",
        names=["tx", "ty", "tz", "rx", "ry", "rz"],
    )


def sphere_centre_in_base(flange2base, centres, sensor2flange) -> np.ndarray:
    """Mean of ``R_0 (R_F X_F + T_F) + T_0`` over the measurements: the sphere centre in base."""
    poses, x_f = _check_measurements("all", flange2base, centres)
    chain = poses @ geo.check_transform("sensor2flange", sensor2flange)
    return (np.einsum("nij,nj->ni", chain[:, :3, :3], x_f) + chain[:, :3, 3]).mean(axis=0)


def _whitening(sensor_sigma, n: int) -> np.ndarray:
    """(n, 3, 3) whitening matrices ``W`` (``W^T W = cov^-1``) of a sigma or a covariance."""
    if np.ndim(sensor_sigma) <= 1:
        sigma = _check_sigma(sensor_sigma)
        return np.broadcast_to(np.diag(1.0 / sigma), (n, 3, 3)).copy()
    a = np.asarray(sensor_sigma, dtype=float)
    if not np.all(np.isfinite(a)):
        raise CalibrationError(f"sensor covariance must be finite; got {a}")
    if a.shape not in ((3, 3), (n, 3, 3)):
        raise CalibrationError(
            f"sensor covariance has shape {a.shape}; expected (3, 3) or ({n}, 3, 3)"
        )
    cov = np.broadcast_to(a, (n, 3, 3))
    try:
        chol = np.linalg.cholesky(0.5 * (cov + np.swapaxes(cov, 1, 2)))
    except np.linalg.LinAlgError as exc:
        raise CalibrationError(f"a sensor covariance is not positive definite ({exc})") from exc
    return np.linalg.inv(chol)


@dataclass
class _SphereProblem:
    poses: np.ndarray
    x_f: np.ndarray
    whiten: np.ndarray  # (N, 3, 3): W_i with W_i^T W_i the inverse covariance of centre i
    base: np.ndarray  # rotation around which the correction is parametrised
    _last: tuple | None = field(default=None, repr=False, compare=False)

    def unpack(self, x):
        # MINPACK asks for the Jacobian where it has just evaluated the residuals: the rotation
        # of the last point is kept (read-only) rather than converted again
        key = np.asarray(x[3:6], dtype=float).tobytes()
        if self._last is None or self._last[0] != key:
            rot = self.base @ geo.rotvec_to_matrix(x[3:6])
            rot.flags.writeable = False
            self._last = (key, rot)
        return geo.make_transform(self._last[1], x[:3]), x[6:9]

    def residuals(self, x):
        s2f, x_b = self.unpack(x)
        # predicted centre in the sensor frame: inv(flange2base @ sensor2flange) @ X_B
        chain = self.poses @ s2f
        rt = np.swapaxes(chain[:, :3, :3], 1, 2)
        pred = np.einsum("nij,nj->ni", rt, x_b - chain[:, :3, 3])
        return np.einsum("nij,nj->ni", self.whiten, pred - self.x_f).ravel()

    def jacobian(self, x):
        s2f, x_b = self.unpack(x)
        r_f, t_f = s2f[:3, :3], s2f[:3, 3]
        r0 = self.poses[:, :3, :3]
        # q = R_0^T (X_B - T_0) - T_F is the centre in the flange frame; pred = R_F^T q
        q = np.einsum("nji,nj->ni", r0, x_b - self.poses[:, :3, 3]) - t_f
        n = q.shape[0]
        jac = np.zeros((n, 3, 9))
        jac[:, :, 0:3] = -r_f.T
        # R_F = base exp(delta); exp(delta + e) = exp(delta) exp(Jr(delta) e), so
        # d(R_F^T q)/d(delta) = [R_F^T q]_x Jr(delta), Jr the right Jacobian of SO(3)
        pred = q @ r_f
        import pinocchio as pin

        jac[:, :, 3:6] = geo.skew(pred) @ pin.Jexp3(np.asarray(x[3:6], dtype=float))
        jac[:, :, 6:9] = np.einsum("ji,njk->nik", r_f, r0.transpose(0, 2, 1))
        return (self.whiten @ jac).reshape(n * 3, 9)


def _check_sigma(sensor_sigma) -> np.ndarray:
    try:
        sigma = np.broadcast_to(np.asarray(sensor_sigma, dtype=float), (3,)).copy()
    except (TypeError, ValueError):
        raise CalibrationError(
            f"sensor sigma must be one value or one per sensor axis (3); got {sensor_sigma!r}"
        ) from None
    if not np.all(np.isfinite(sigma)) or np.any(sigma <= 0):
        raise CalibrationError(f"sensor sigma must be positive and finite (mm); got {sigma}")
    return sigma


def sphere_handeye_ml(
    flange2base,
    centres,
    sensor_sigma,
    initial: np.ndarray,
    *,
    ids=None,
    misfit: str = "flag",
) -> Estimate:
    """Maximum-likelihood fixed-sphere hand-eye: ``R_F, T_F, X_B`` from all measurements jointly.

    Minimises the whitened differences between the measured and the predicted sphere centres in
    the sensor frame, ``(X_F - R_F^T (R_0^T (X_B - T_0) - T_F)) / sigma``, by Levenberg-Marquardt
    with an analytic Jacobian. With Gaussian sensor noise of known ``sigma`` this is the
    maximum-likelihood estimate, and the covariance at the true parameters is the Cramer-Rao bound.

    Parameters
    ----------
    flange2base : (N, 4, 4) array
        All flange poses (translations and pose changes), mm.
    centres : (N, 3) array
        Measured sphere centres in the sensor frame, mm.
    sensor_sigma : float, (3,), (3, 3) or (N, 3, 3) array
        The sensor noise of a measured centre: a standard deviation (mm) for all axes, one per
        sensor axis (independent axes), or the full covariance (mm^2) shared by all
        measurements or one per measurement. Only the full covariance makes this the maximum
        likelihood when the axes are correlated (the line laser's y and z are, strongly).
    initial : (4, 4) array
        Starting ``sensor2flange`` (for example :func:`sphere_handeye`).
    ids : (N,) array, optional
        Measurement ids (e.g. the CSV's ``id`` column), used to name the measurements that
        disagree most when the fit fails.
    misfit : {"flag", "raise", "off"}
        What a failed goodness-of-fit test does (whitened ``chi2/dof`` outside its expected
        range, :func:`calstudy.core.estimation.goodness_of_fit`): ``"flag"`` returns the
        estimate with the message in ``flags`` and a :class:`calstudy.CalibrationWarning` (a
        simulated station whose robot errors the sensor noise does not cover fails it, and its
        estimate is still wanted); ``"raise"`` raises :class:`CalibrationError`. Use ``"raise"``
        for measured data.

    Returns
    -------
    Estimate
        ``value`` is ``sensor2flange``; ``params`` ``[T_F (3), delta (3), X_B (3)]`` with ``delta``
        the rotation correction of ``R_F`` about ``initial`` in the sensor frame; ``covariance``
        ``(J^T J)^-1`` of these parameters (whitened residuals, sigma = 1); ``fit`` the
        goodness-of-fit test.

    Raises
    ------
    CalibrationError
        On bad shapes, fewer than 3 poses, non-positive sigma, if LM does not converge, if the
        poses leave the parameters unobservable (condition number above
        :data:`MAX_ML_CONDITION`, e.g. translations only), or with ``misfit="raise"`` if the
        residuals are far larger than the stated noise (a sphere that moved, mixed units).
    """
    poses, x_f = _check_measurements("ML", flange2base, centres)
    init = geo.check_transform("initial sensor2flange", initial)
    names = None
    if ids is not None:
        id_arr = np.asarray(ids).ravel()
        if id_arr.size != poses.shape[0]:
            raise CalibrationError(f"{id_arr.size} ids for {poses.shape[0]} measurements")
        names = [f"id {i}" for i in id_arr]
    if poses.shape[0] < 3:
        raise CalibrationError(f"ML hand-eye needs at least 3 poses; got {poses.shape[0]}")
    problem = _SphereProblem(poses, x_f, _whitening(sensor_sigma, poses.shape[0]), init[:3, :3])
    x_b0 = sphere_centre_in_base(poses, x_f, init)
    x0 = np.concatenate([init[:3, 3], np.zeros(3), x_b0])
    est = levenberg_marquardt(
        problem.residuals,
        x0,
        jac=problem.jacobian,
        sigma=1.0,
        names=["tx", "ty", "tz", "dx", "dy", "dz", "Xb", "Yb", "Zb"],
        label="ML sphere hand-eye",
        to_value=lambda x: problem.unpack(x)[0],
        max_condition=MAX_ML_CONDITION,
        advice="the poses must include orientation changes about at least two axes (translations "
        "alone leave T_F and the sphere centre confounded)",
    )
    check = goodness_of_fit(
        est.residuals, 9, label="ML sphere hand-eye", block=3, block_names=names
    )
    return apply_fit_check(est, check, misfit)


def sphere_handeye_crb(flange2base, centres_true, sensor_sigma, sensor2flange, x_b) -> np.ndarray:
    """Cramer-Rao bound of ``[T_F, delta, X_B]`` for the fixed-sphere problem at the truth.

    Parameters are as in :func:`sphere_handeye_ml`, with the true ``sensor2flange`` and the true
    sphere centre ``x_b`` in base. Returns the ``(9, 9)`` covariance ``(J^T J)^-1`` of the
    whitened problem; ``sqrt(trace)`` of its blocks is the smallest RMS error any unbiased
    estimator can reach from these poses and this noise.

    Raises
    ------
    CalibrationError
        On bad shapes, a sigma that is not positive and finite, or poses that leave the
        parameters unobservable (condition number above :data:`MAX_ML_CONDITION`).
    """
    poses, x_f = _check_measurements("CRB", flange2base, centres_true)
    t = geo.check_transform("sensor2flange", sensor2flange)
    problem = _SphereProblem(poses, x_f, _whitening(sensor_sigma, poses.shape[0]), t[:3, :3])
    x = np.concatenate([t[:3, 3], np.zeros(3), geo.check_shape("x_b", x_b, (3,))])
    jac = problem.jacobian(x)
    check_condition(
        condition_number(jac),
        MAX_ML_CONDITION,
        "the Cramer-Rao bound of the sphere hand-eye",
        "the poses must include orientation changes about at least two axes",
    )
    return np.linalg.pinv(jac.T @ jac)


def check_rotation_diversity(
    flange2base: np.ndarray, min_rotation: float, tol: float = geo.ORTHONORMAL_TOL
) -> None:
    """Raise a :class:`CalibrationError` unless the flange poses ``(N, 4, 4)`` rotate enough for
    Tsai-Lenz.

    Tsai-Lenz (as ``cv2.calibrateHandEye`` runs it) uses the motion between every pair of poses;
    a pair that does not rotate adds an equation that holds for any rotation and harms nothing.
    The hand-eye rotation is determined once at least two motions rotate by ``min_rotation``
    (rad) or more about axes at least ``min_rotation`` apart (each axis in the frame of the
    motion's first flange, as the method uses it). The message says which condition fails and
    the number behind it. ``tol`` is the orthonormality tolerance of the rotations.
    """
    poses = geo.check_transform("flange poses", flange2base, tol)
    if poses.ndim != 3 or poses.shape[0] < 3:
        raise CalibrationError(
            f"flange poses of shape {poses.shape}: the rotation check needs (N, 4, 4) with N >= 3"
        )
    if not (np.isfinite(min_rotation) and min_rotation > 0.0):
        raise CalibrationError(f"min_rotation must be a positive angle in rad, got {min_rotation}")
    _check_diversity(poses[:, :3, :3], min_rotation)


def _check_diversity(r: np.ndarray, min_rotation: float) -> None:
    """:func:`check_rotation_diversity` on checked rotations ``(N, 3, 3)``, ``N >= 3``."""
    i, j = np.triu_indices(len(r), 1)
    rotvec = geo.matrix_to_rotvec(np.swapaxes(r[i], -1, -2) @ r[j])
    angles = np.linalg.norm(rotvec, axis=1)
    moving = angles >= min_rotation
    if not np.any(moving):
        raise CalibrationError(
            f"no pair of the {len(r)} poses rotates by {np.degrees(min_rotation):.3g} deg or "
            f"more (largest {np.degrees(angles.max()):.3g} deg): pure translations or repeated "
            "orientations leave the hand-eye rotation undetermined; include rotating motions"
        )
    axes = rotvec[moving] / angles[moving, None]
    # the largest angle between two axes; an axis far enough from the first one settles it
    # without the (M, M) matrix of every pair (M ~ N^2 / 2 motions)
    spread = float(np.arccos(np.clip(np.abs(axes @ axes[0]), 0.0, 1.0).min()))
    if spread < min_rotation:
        spread = max(
            float(np.arccos(np.clip(np.abs(axes[k : k + 512] @ axes.T), 0.0, 1.0).min()))
            for k in range(0, len(axes), 512)
        )
    if spread < min_rotation:
        raise CalibrationError(
            f"the {int(moving.sum())} rotating motions of the {len(r)} poses turn about one "
            f"axis (axes within {np.degrees(spread):.3g} deg, minimum "
            f"{np.degrees(min_rotation):.3g} deg): the hand-eye rotation about that axis and the "
            "translation along it are undetermined; include motions about two axes"
        )


@contextmanager
def quiet_opencv():
    """OpenCV's log silenced within the block (its hand-eye solvers log failures on stderr,
    which the callers report as :class:`CalibrationError` instead), the level restored after."""
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)


def opencv_handeye(
    flange2base,
    target2sensor,
    method: str,
    min_pair_rotation: float = DEGENERATE_ROTATION,
    tol: float = geo.ORTHONORMAL_TOL,
) -> np.ndarray:
    """``sensor2flange`` by ``cv2.calibrateHandEye`` (AX = XB) with a named method.

    Parameters
    ----------
    flange2base : (N, 4, 4) array
        Flange poses in the base frame, mm.
    target2sensor : (N, 4, 4) array
        Pose of a fixed target in the sensor frame at each robot pose, mm.
    method : str
        One of ``"Tsai"``, ``"Park"``, ``"Horaud"``, ``"Andreff"``, ``"Daniilidis"``.
    min_pair_rotation : float, default :data:`DEGENERATE_ROTATION`
        The poses must rotate enough overall (:func:`check_rotation_diversity`): at least two
        motions between pose pairs rotating by this much (rad) or more about axes this far
        apart. Every method takes the rotation axes of the motions, undefined for a pure
        translation, and OpenCV returns a wrong answer (with a message on stderr at most) on
        degenerate motions; poses with equal orientations are fine as long as others rotate.
        :data:`MIN_PAIR_ROTATION` is a safe value for designed poses; values below
        :data:`DEGENERATE_ROTATION` are raised to it (pure translations, rotations about one
        axis and a repeated pose are always refused).
    tol : float
        Orthonormality tolerance of the input rotations. For measured poses with rounded
        rotations, :func:`calstudy.estimators.handeye_poses.calibrate_handeye` re-projects them.

    Returns
    -------
    (4, 4) array
        ``sensor2flange``.

    Raises
    ------
    CalibrationError
        For an unknown method, fewer than 3 poses, bad shapes, poses without two motions rotating
        by ``min_pair_rotation`` about axes that far apart (pure translations, rotations about
        one axis, repeated poses: the message names the largest rotation or the spread of the
        axes), OpenCV's own failure, or a non-finite OpenCV result.
    """
    if method not in OPENCV_METHODS:
        raise CalibrationError(
            f"unknown hand-eye method {method!r}; use one of {list(OPENCV_METHODS)}"
        )
    g2b = geo.check_transform("flange poses", flange2base, tol)
    t2c = geo.check_transform("target poses", target2sensor, tol)
    if g2b.ndim != 3 or g2b.shape != t2c.shape:
        raise CalibrationError(
            f"flange poses {g2b.shape} and target poses {t2c.shape} must both be (N, 4, 4)"
        )
    if g2b.shape[0] < 3:
        raise CalibrationError(f"AX = XB needs at least 3 poses; got {g2b.shape[0]}")
    if not (np.isfinite(min_pair_rotation) and min_pair_rotation >= 0.0):
        raise CalibrationError(
            f"min_pair_rotation = {min_pair_rotation} must be a finite angle >= 0 in rad"
        )
    # before OpenCV: on degenerate motions it prints to stderr and returns a wrong answer
    _check_diversity(g2b[:, :3, :3], max(float(min_pair_rotation), DEGENERATE_ROTATION))
    try:
        with quiet_opencv():
            rot, trans = cv2.calibrateHandEye(
                list(g2b[:, :3, :3]),
                list(g2b[:, :3, 3:]),
                list(t2c[:, :3, :3]),
                list(t2c[:, :3, 3:]),
                method=OPENCV_METHODS[method],
            )
    except cv2.error as exc:
        raise CalibrationError(
            f"OpenCV {method} hand-eye failed on {g2b.shape[0]} poses: {exc.err or exc}"
        ) from None
    if rot is None or trans is None:
        raise CalibrationError(f"OpenCV {method} hand-eye returned no result")
    out = geo.make_transform(rot, trans.ravel())
    if np.array_equal(out, np.eye(4)):
        # what OpenCV's Tsai returns (logging an error) when no motion rotates enough
        raise CalibrationError(
            f"OpenCV {method} hand-eye failed on {g2b.shape[0]} poses: not enough informative "
            "motions (include larger rotations)"
        )
    if not np.all(np.isfinite(out)):
        raise CalibrationError(f"OpenCV {method} hand-eye returned a non-finite result")
    return out


def base_to_base(
    flange2base_1, cam2flange_1, world2cam_1, flange2base_2, cam2flange_2, world2cam_2
) -> np.ndarray:
    """``base2_to_base1`` of two robots whose cameras locate one world frame (dualarm Eq. 11).

    ``world2base_a = flange2base_a @ cam2flange_a @ world2cam_a``, averaged over arm ``a``'s
    poses by :func:`calstudy.core.geometry.mean_transform`; then
    ``base2_to_base1 = world2base_1 @ world2base_2^-1``.

    Parameters
    ----------
    flange2base_1, flange2base_2 : array_like, shape (N_a, 4, 4)
        Each robot's flange poses, mm.
    cam2flange_1, cam2flange_2 : array_like, shape (4, 4)
        Each robot's hand-eye transform.
    world2cam_1, world2cam_2 : array_like, shape (N_a, 4, 4)
        The world frame in each camera at each pose.

    Returns
    -------
    (4, 4) array
        ``base2_to_base1`` (``p_base1 = base2_to_base1 @ p_base2``).

    Raises
    ------
    CalibrationError
        On bad shapes, non-orthonormal rotations, or unequal numbers of flange and camera poses.
    """
    w2b = []
    for g2b, c2f, w2c in (
        (flange2base_1, cam2flange_1, world2cam_1),
        (flange2base_2, cam2flange_2, world2cam_2),
    ):
        g = geo.check_transform("flange poses", g2b).reshape(-1, 4, 4)
        w = geo.check_transform("world2cam", w2c).reshape(-1, 4, 4)
        if len(g) != len(w):
            raise CalibrationError(f"{len(g)} flange poses but {len(w)} camera poses")
        w2b.append(geo.mean_transform(g @ geo.check_transform("cam2flange", c2f) @ w))
    return w2b[0] @ geo.invert(w2b[1])


def stationary_sensor_to_base(
    flange2base, sensor2flange, front2flexcam, back2statcam, back2front
) -> np.ndarray:
    """Pose of a stationary camera in the robot base frame by Eq. 23.

    ``statcam2base = flange2base @ sensor2flange @ front2flexcam @ inv(back2statcam @ front2back)``
    which, with ``front2back = inv(back2front)``, is
    ``flange2base @ sensor2flange @ front2flexcam @ back2front @ inv(back2statcam)``.

    Parameters
    ----------
    flange2base : (4, 4) array
        Flange pose reported by the robot (forward kinematics), mm.
    sensor2flange : (4, 4) array
        Hand-eye of the flexible sensor; its camera frame is taken as the sensor frame.
    front2flexcam : (4, 4) array
        Front face of the target in the flexible sensor's camera frame (from its image).
    back2statcam : (4, 4) array
        Back face of the target in the stationary camera frame (from its image).
    back2front : (4, 4) array
        Back face to front face of the target (pre-calibrated on a CMM).

    Returns
    -------
    (4, 4) array
        ``statcam2base``.
    """
    mats = [
        geo.check_transform(name, m)
        for name, m in [
            ("flange2base", flange2base),
            ("sensor2flange", sensor2flange),
            ("front2flexcam", front2flexcam),
            ("back2statcam", back2statcam),
            ("back2front", back2front),
        ]
    ]
    f2b, s2f, front2cam, back2cam, b2f = mats
    return f2b @ s2f @ front2cam @ b2f @ geo.invert(back2cam)


#: columns of a user's fixed-sphere measurement file, in order
