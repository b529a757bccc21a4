"""Hand-eye calibration by the fixed-sphere method (hybrid paper, Eq. 6-14).

The fixed-sphere method (hybrid paper, section 3.1, Eq. 6-14) uses one point fixed in the robot
base frame, the centre of a standard sphere, measured by the flange-mounted sensor from many robot
poses. With the flange pose ``flange2base = [R_0 | T_0]`` and the measured centre ``X_F`` in the
sensor frame, every measurement satisfies ``X_B = R_0 (R_F X_F + T_F) + T_0`` (Eq. 7).

* Pure translations (fixed ``R_0``) give ``R_F`` by SVD (Eq. 9-11).
* Pose changes then give ``T_F`` by linear least squares (Eq. 12-14).
* :func:`sphere_handeye_ml` refines ``R_F, T_F`` and ``X_B`` jointly on all measurements,
  weighting by the sensor's noise: the maximum-likelihood estimate, whose covariance at the true
  parameters is the Cramer-Rao bound.

The AX = XB closed forms, which need the full pose of a target in the sensor frame rather than
a point, are :func:`calstudy.estimators.axxb.opencv_handeye`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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

    Raises
    ------
    CalibrationError
        On bad shapes or non-finite values; if the translations change the orientation or are
        too few or collinear, or the centres do not move as far as the flange (a unit mismatch);
        if the pose changes do not rotate about two axes (Eq. 13 rank deficient).
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


def whitening(sensor_sigma, n: int) -> np.ndarray:
    """Whitening matrices of ``n`` measured centres: ``W_i`` with ``W_i^T W_i = cov_i^-1``.

    Parameters
    ----------
    sensor_sigma : float, array_like of shape (3,), (3, 3) or (n, 3, 3)
        Standard deviation of a centre (one value or one per sensor axis, mm), or the
        covariance of every centre (one for all, or one each, mm^2).
    n : int
        Number of centres.

    Returns
    -------
    numpy.ndarray, shape (n, 3, 3)
        ``W_i = L_i^-1`` for the Cholesky factor ``L_i`` of ``cov_i`` (symmetrised).

    Raises
    ------
    CalibrationError
        If a sigma is not positive and finite, a covariance is not finite, has another shape or
        is not positive definite.
    """
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
    problem = _SphereProblem(poses, x_f, whitening(sensor_sigma, poses.shape[0]), init[:3, :3])
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

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        All flange poses, mm.
    centres_true : array_like, shape (N, 3)
        The true sphere centres in the sensor frame, mm.
    sensor_sigma : float or array_like, shape (3,), (3, 3) or (N, 3, 3)
        The sensor noise as in :func:`sphere_handeye_ml` (mm, or mm^2 for a covariance).
    sensor2flange : array_like, shape (4, 4)
        The true hand-eye transform, mm.
    x_b : array_like, shape (3,)
        The true sphere centre in the base frame, mm.

    Returns
    -------
    numpy.ndarray, shape (9, 9)
        The covariance ``(J^T J)^-1`` of ``[T_F (mm), delta (rad), X_B (mm)]`` of the whitened
        problem; ``sqrt(trace)`` of its blocks is the smallest RMS error any unbiased estimator
        can reach from these poses and this noise.

    Raises
    ------
    CalibrationError
        On bad shapes, a sigma that is not positive and finite, or poses that leave the
        parameters unobservable (condition number above :data:`MAX_ML_CONDITION`).
    """
    poses, x_f = _check_measurements("CRB", flange2base, centres_true)
    t = geo.check_transform("sensor2flange", sensor2flange)
    problem = _SphereProblem(poses, x_f, whitening(sensor_sigma, poses.shape[0]), t[:3, :3])
    x = np.concatenate([t[:3, 3], np.zeros(3), geo.check_shape("x_b", x_b, (3,))])
    jac = problem.jacobian(x)
    check_condition(
        condition_number(jac),
        MAX_ML_CONDITION,
        "the Cramer-Rao bound of the sphere hand-eye",
        "the poses must include orientation changes about at least two axes",
    )
    return np.linalg.pinv(jac.T @ jac)

