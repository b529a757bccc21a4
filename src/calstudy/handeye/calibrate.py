"""Hand-eye calibration of a cell from measured pose lists: AX = XB and AX = ZB.

The input a researcher usually has is two lists of poses taken at the same instants: the robot
flange in the base frame (from the controller) and a calibration target in the camera frame (from
the camera's pose estimation). This module turns them into a calibration with its uncertainty.

Problem form. With ``A_i = flange2base_i``, ``B_i = target2camera_i``, the unknown
``X = camera2flange`` and the fixed target ``Z = target2base``, every pose satisfies

.. math:: A_i X B_i = Z,

the robot-world-hand-eye form AX = ZB (OpenCV's ``calibrateRobotWorldHandEye``). The classic
AX = XB form (``calibrateHandEye``) eliminates ``Z`` from pairs of poses; both lead to the same
maximum-likelihood problem in ``(X, Z)``. For a camera fixed in the cell and a target on the
flange (``setup="eye_to_hand"``) the robot poses are inverted, ``A_i = base2flange_i``, and the
unknowns become ``X = camera2base`` and ``Z = target2flange``.

Steps of :func:`calibrate_handeye` and :func:`calibrate_robot_world_handeye`, in the modules
:mod:`~calstudy.handeye.inputs` (1, 2), :mod:`~calstudy.handeye.refine`
(3, 4) and :mod:`~calstudy.handeye.robust` (noise level, outliers):

1. ``prepare_poses``: storage convention, units, near-orthonormal rotations re-projected to
   SO(3) (largest correction reported), beyond ``ortho_tol`` a :class:`CalibrationError`.
2. ``motion_conditioning``: refuses too few or duplicate poses, pure translations and rotations
   about a single axis, naming the cause.
3. Closed forms (OpenCV's Tsai, Park, Horaud, Andreff, Daniilidis; or Shah, Li) on a fixed
   number of well-spread poses (OpenCV forms every pair of the poses it is given), each scored by
   its per-pose residual on all poses; a result far above the best (factor ``REFUSE_FACTOR``) is
   refused. The whole fit is linear in the pose count.
4. ``refine_ml``: maximum likelihood on SE(3) residuals of the target pose (per-pose weights,
   analytic Jacobian), optionally robust (Huber or Cauchy by iterative reweighting, or RANSAC over
   pose triplets), or on the reprojection error when target points and pixels are given.
5. ``check_cell`` (:mod:`~calstudy.handeye.checks`), on every path: the camera's and
   the robot's ranges, a noise level estimated robustly and compared with what any instrument
   gives, a step of the target in time order. After a failure only,
   :mod:`~calstudy.handeye.diagnose` tries the common reading mistakes and the
   calibration refuses naming the ones that fit (``check_convention="warn"``: warns and goes on).

Pose-list files are read and written by :mod:`~calstudy.handeye.posefile`; a simulated cell
is drawn by :mod:`~calstudy.handeye.simulate`.

Noise model of the refinement: the measured target pose is ``B_i exp(xi_i)`` with a rotation
error ``N(0, sigma_rot^2 I)`` (rad) and a translation error ``N(0, sigma_trans^2 I)`` (mm); robot
poses are exact. The residuals are whitened with these, so the covariance at the truth,
``(J^T J)^-1``, is the Cramer-Rao bound (:func:`calstudy.handeye.refine.handeye_crb`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError, CalibrationWarning
from calstudy.core.estimation import (
    MISFIT_POLICIES,
    Estimate,
    apply_fit_check,
    covariance_from_jacobian,
    goodness_of_fit,
)
from calstudy.estimators.axxb import OPENCV_METHODS
from calstudy.handeye.checks import CellCheck, CellLimits, check_cell
from calstudy.handeye.inputs import (
    ORTHO_TOL,
    Conditioning,
    PreparedPoses,
    motion_conditioning,
    prepare_poses,
)
from calstudy.handeye.refine import (
    OPENCV_RWHE_METHODS,
    PARAM_NAMES,
    ClosedForm,
    check_pose_weights,
    closed_forms,
    pose_residuals,
    refine_ml,
    refine_reprojection,
    robot_error_map,
    target_in_world,
    whitened_at,
)
from calstudy.handeye.robust import (
    MIN_CAMERA_SHARE,
    eiv_sigmas,
    outlier_limit,
    outlier_scores,
    ransac_inliers,
    robust_sigmas,
    robust_weights,
)

#: pose counts below this are flagged: the covariance cannot be trusted (too few residuals to
#: estimate the noise and the robot's error)
MIN_TRUSTED_POSES = 6
#: condition number of the whitened Jacobian above which the refinement is refused
MAX_JACOBIAN_CONDITION = 1e10
ROBUST = (None, "huber", "cauchy", "ransac")


# ----------------------------------------------------------------------------------------------
# the result and the public entry points


#: the frames each setup solves for: (the camera's mount, the target's mount)
SETUP_FRAMES = {
    "eye_in_hand": ("camera2flange", "target2base"),
    "eye_to_hand": ("camera2base", "target2flange"),
}


@dataclass(frozen=True, eq=False)
class HandEyeResult:
    """A hand-eye calibration with its uncertainty and diagnostics.

    The two solved transforms are named by their frames: eye-in-hand (camera on the flange)
    gives ``camera2flange`` and ``target2base``, eye-to-hand (camera fixed, target on the
    flange) gives ``camera2base`` and ``target2flange``; the other two fields are ``None``.
    :attr:`camera2mount` and :attr:`target2mount` are the solved pair whatever the setup.

    Attributes
    ----------
    setup : {"eye_in_hand", "eye_to_hand"}
    camera2flange, target2base : (4, 4) array or None
        Eye-in-hand: the camera's pose on the flange and the fixed target's pose in the robot
        base frame, mm.
    camera2base, target2flange : (4, 4) array or None
        Eye-to-hand: the fixed camera's pose in the base frame and the target's pose on the
        flange, mm.
    covariance : (12, 12) array
        Covariance of ``[theta_camera, t_camera, theta_target, t_target]`` (rad, mm) of
        :attr:`camera2mount` and :attr:`target2mount`, ``R = R_est exp(theta)`` (rotation error
        in the camera frame, target frame for the target).
    covariance_basis : str
        ``"given noise level"`` or ``"scaled by residual chi2 (s^2 = ...)"``.
    estimate : Estimate
        The refinement's (or the closed form's) result record.
    method : str
        Closed form used as the start, and the refinement (``"Park + ML"``).
    residuals : (N, 6) array
        Per-pose residuals ``[t (mm, camera frame), rot (rad)]`` of the measured target pose.
    outlier_score : (N,) array
        Whitened squared residual of each pose (chi-square with 6 degrees of freedom for an
        inlier).
    flagged : list of int
        Ids of poses whose score exceeds the ``1 - outlier_alpha`` quantile.
    weights : (N,) array
        Final per-pose weights (user weights times robust weights).
    sigma_rot, sigma_trans : float
        Camera noise used (given, or estimated robustly from the residuals), rad and mm.
    conditioning : Conditioning
    closed_forms : list of ClosedForm
    check : CellCheck
        The plausibility check of the fit (ranges, noise level, time order) and, after a
        failure with ``check_convention="warn"``, its diagnosis.
    prepared : PreparedPoses
        The canonical input, with the largest re-orthonormalisation correction.
    notes : list of str
        Remarks on the fit (flagged poses, too few poses for the covariance, a misfit).
    robot_sigma_rot : float
        Robot rotation error used (errors in variables; stated, or estimated from how the
        residuals' rotation and translation parts co-vary), rad per axis.
    dof : float
        Degrees of freedom behind the covariance's scale (inf: the noise was given): ``3 N - 6``,
        those of the rotation or of the translation residuals alone, from which each part of
        the noise level is estimated.
    """

    setup: str
    camera2flange: np.ndarray | None
    target2base: np.ndarray | None
    camera2base: np.ndarray | None
    target2flange: np.ndarray | None
    covariance: np.ndarray
    covariance_basis: str
    estimate: Estimate
    method: str
    residuals: np.ndarray
    outlier_score: np.ndarray
    flagged: list
    weights: np.ndarray
    sigma_rot: float
    sigma_trans: float
    conditioning: Conditioning
    closed_forms: list
    check: CellCheck
    prepared: PreparedPoses
    notes: list = field(default_factory=list)
    robot_sigma_rot: float = 0.0
    dof: float = float("inf")

    @property
    def camera2mount(self) -> np.ndarray:
        """The camera's pose (4, 4), mm, in the frame it is fixed to: ``camera2flange``
        (eye-in-hand) or ``camera2base`` (eye-to-hand)."""
        return self.camera2flange if self.setup == "eye_in_hand" else self.camera2base

    @property
    def target2mount(self) -> np.ndarray:
        """The target's pose (4, 4), mm, in the frame it is fixed to: ``target2base``
        (eye-in-hand) or ``target2flange`` (eye-to-hand)."""
        return self.target2base if self.setup == "eye_in_hand" else self.target2flange

    @property
    def covariance_trusted(self) -> bool:
        """False below :data:`MIN_TRUSTED_POSES` poses (the coverage of the 95 % region is then
        well below 90 %; a note says so)."""
        return self.prepared.a.shape[0] >= MIN_TRUSTED_POSES

    def region_limit(self, level: float = 0.95, k: int = 6) -> float:
        """Limit of the squared Mahalanobis distance of a ``k``-parameter block at ``level``.

        ``chi2_k`` with a given noise level, ``k F(k, dof)`` with an estimated one (the scale of
        the covariance is then estimated from ``dof`` residual degrees of freedom).

        Parameters
        ----------
        level : float
            Coverage of the region, in (0, 1).
        k : int
            Parameters of the block (6 for one transform).

        Returns
        -------
        float
            The limit (dimensionless).

        Raises
        ------
        None
            An out-of-range ``level`` gives nan.
        """
        from scipy.special import chdtri, fdtri

        if np.isinf(self.dof):
            return float(chdtri(k, 1.0 - level))
        return float(k * fdtri(k, self.dof, level))

    def camera_distance(self, camera2mount_true) -> float:
        """Squared Mahalanobis distance of :attr:`camera2mount` from a true pose.

        Parameters
        ----------
        camera2mount_true : array_like, shape (4, 4)
            The true ``camera2flange`` (eye-in-hand) or ``camera2base`` (eye-to-hand), mm.

        Returns
        -------
        float
            The distance under the covariance of ``[theta_camera, t_camera]`` (dimensionless):
            inside the 95 % region when at most ``region_limit(0.95)``.

        Raises
        ------
        numpy.linalg.LinAlgError
            If the covariance block is singular.
        """
        xt = np.asarray(camera2mount_true, dtype=float)
        x = self.camera2mount
        theta = geo.matrix_to_rotvec(x[:3, :3].T @ xt[:3, :3])
        e = np.concatenate([theta, xt[:3, 3] - x[:3, 3]])
        return float(e @ np.linalg.solve(self.covariance[:6, :6], e))

    @property
    def std(self) -> np.ndarray:
        """Standard deviations ``(12,)`` of ``[theta_camera, t_camera, theta_target, t_target]``
        (rad, mm)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def point_covariance(self, point_camera) -> np.ndarray:
        """Predicted uncertainty of a point of the camera frame mapped to the flange (or base).

        Parameters
        ----------
        point_camera : array_like, shape (3,)
            A tool or measured point in the camera frame, mm.

        Returns
        -------
        numpy.ndarray, shape (3, 3)
            Covariance of ``camera2mount @ p``, mm^2.

        Raises
        ------
        CalibrationError
            If ``point_camera`` is not 3 finite numbers.
        """
        p = geo.check_shape("point", point_camera, (3,))
        jac = np.zeros((3, 12))
        jac[:, 0:3] = -self.camera2mount[:3, :3] @ geo.skew(p)
        jac[:, 3:6] = np.eye(3)
        return jac @ self.covariance @ jac.T


def _choose(forms: list[ClosedForm], method: str) -> ClosedForm:
    if method == "best":
        ok = [c for c in forms if not c.refused]
        if not ok:
            raise CalibrationError(
                "every closed form failed or was refused: "
                + "; ".join(f"{c.method}: {c.refused}" for c in forms)
            )
        return min(ok, key=lambda c: c.score)
    chosen = next(c for c in forms if c.method == method)
    if chosen.refused:
        raise CalibrationError(
            f"OpenCV {method} result refused, {chosen.refused}; use method='best' or another method"
        )
    return chosen


@dataclass(frozen=True)
class _Options:
    """The keyword options of the entry points, as :func:`_calibrate` uses them."""

    refine: bool
    sigma_rot: float | None
    sigma_trans: float | None
    weights: object
    robot_sigma_rot: float | None
    robust: str | None
    outlier_alpha: float
    check_convention: str
    rng: np.random.Generator | None
    ransac_samples: int
    target_points: object
    pixels: object
    camera_matrix: object
    pixel_sigma: float | None
    misfit: str = "flag"
    limits: CellLimits | None = None
    rereadings: Callable[[], dict] | None = None


@dataclass
class _Fit:
    """The calibration between two steps of :func:`_calibrate`."""

    x: np.ndarray
    z: np.ndarray
    w_user: np.ndarray
    w: np.ndarray
    given: bool
    label: str
    s_rot: float = float("nan")
    s_trans: float = float("nan")
    rho: float = 0.0  # robot rotation error, rad per axis
    given_robot: bool = False
    est: Estimate | None = None
    cov: np.ndarray | None = None
    jc: float = float("nan")


def _check_options(opt: _Options) -> None:
    if opt.robust not in ROBUST:
        raise CalibrationError(f"unknown robust option {opt.robust!r}; use one of {ROBUST}")
    if opt.check_convention not in ("raise", "warn", "off"):
        raise CalibrationError(
            f"check_convention must be raise, warn or off; got {opt.check_convention!r}"
        )
    if (opt.sigma_rot is None) != (opt.sigma_trans is None):
        raise CalibrationError("give both sigma_rot and sigma_trans, or neither")
    if not 0 < opt.outlier_alpha < 1:
        raise CalibrationError(f"outlier_alpha must be in (0, 1); got {opt.outlier_alpha:g}")
    if opt.misfit not in MISFIT_POLICIES:
        raise CalibrationError(f"misfit must be one of {MISFIT_POLICIES}; got {opt.misfit!r}")


#: the closed-form start is checked with noise limits this much wider (a gross failure stops
#: the calibration before the refinement, which on misread data takes many iterations)
START_SLACK = 3.0


def _check_cell(
    prep: PreparedPoses, x, res, w, opt: _Options, notes: list, slack: float = 1.0
) -> CellCheck:
    """The plausibility check of the fit; after a failure the diagnosis, then a refusal (or a
    warning) naming the failures and the likely causes, best first."""
    limits = opt.limits if opt.limits is not None else CellLimits()
    check = check_cell(prep.a, prep.b, x, res, w, limits, slack)
    if not check.failures or opt.check_convention == "off":
        return check
    from calstudy.handeye.diagnose import diagnose

    reread = None
    if opt.rereadings is not None:

        def reread():
            out = {}
            for cause, (robot, camera) in opt.rereadings().items():
                try:
                    p = _reprepare(prep, robot, camera)
                except CalibrationError:
                    continue
                out[cause] = (p.a, p.b)
            return out

    check.diagnosis, cause = diagnose(prep.a, prep.b, limits, reread, check.break_after)
    check.message = (
        "implausible hand-eye fit: " + "; ".join(check.failures) + ". Likely causes: " + cause
    )
    if opt.check_convention == "raise":
        raise CalibrationError(check.message)
    # the caller of calibrate_handeye: _check_cell, _calibrate, the entry point
    warnings.warn(check.message, CalibrationWarning, stacklevel=4)
    notes.append(check.message)
    return check


def _reprepare(prep: PreparedPoses, robot, camera) -> PreparedPoses:
    """Other stored poses through the declared conventions, units and setup of ``prep``."""
    return prepare_poses(
        robot,
        camera,
        setup=prep.setup,
        convention=(prep.robot_convention, prep.camera_convention),
        robot_unit=prep.robot_unit,
        camera_unit=prep.camera_unit,
        ortho_tol=0.099,
        ids=prep.ids,
    )


def _start(a, b, start: ClosedForm, opt: _Options, notes: list) -> _Fit:
    """Weights (user's, times RANSAC's inliers), start ``(X, Z)`` and the noise level."""
    n = a.shape[0]
    weights = opt.weights
    w_user = check_pose_weights(weights, n)
    w = w_user.copy()
    if opt.robust == "ransac":
        if opt.rng is None:
            raise CalibrationError("robust='ransac' draws pose triplets: pass rng")
        inl = ransac_inliers(a, b, opt.rng, opt.ransac_samples)
        w = w_user * inl
        notes.append(f"RANSAC kept {int(inl.sum())} of {n} poses")
    x, z = start.x, start.z
    if opt.robust == "ransac" or (weights is not None):
        z = target_in_world(a[w > 0], b[w > 0], x)
    fit = _Fit(x, z, w_user, w, given=opt.sigma_rot is not None, label=start.method)
    if fit.given:
        fit.s_rot, fit.s_trans = float(opt.sigma_rot), float(opt.sigma_trans)
        if not (0 < fit.s_rot < np.inf and 0 < fit.s_trans < np.inf):
            raise CalibrationError(
                f"sigma_rot and sigma_trans must be positive and finite; got {fit.s_rot:g}, "
                f"{fit.s_trans:g}"
            )
    else:
        fit.s_rot, fit.s_trans = robust_sigmas(pose_residuals(a, b, x, z)[w > 0])
    if opt.robot_sigma_rot is not None:
        fit.rho, fit.given_robot = float(opt.robot_sigma_rot), True
        if not 0 <= fit.rho < np.inf:
            raise CalibrationError(f"robot_sigma_rot must be >= 0 and finite; got {fit.rho:g}")
        if not fit.given:
            fit.s_rot, fit.s_trans = _camera_share(a, b, x, z, w, fit.rho)
    return fit


def _camera_share(a, b, x, z, w, rho: float) -> tuple[float, float]:
    """The camera's noise at a stated robot rotation error ``rho``: the rest of the robust
    total, at least :data:`MIN_CAMERA_SHARE` of it."""
    res = pose_residuals(a, b, x, z)[w > 0]
    s_r, s_t = robust_sigmas(res)
    g_t = robot_error_map(a[w > 0], x, z)[0]
    kappa = float(np.mean(np.einsum("nij,nij->n", g_t, g_t))) / 3.0
    return (
        float(np.sqrt(max(s_r**2 - rho**2, MIN_CAMERA_SHARE * s_r**2))),
        float(np.sqrt(max(s_t**2 - rho**2 * kappa, MIN_CAMERA_SHARE * s_t**2))),
    )


def _noise(a, b, x, z, w, fit: _Fit) -> tuple[float, float, float]:
    """The noise level of a fit ``(sigma_rot, sigma_trans, robot_sigma_rot)``: as given, or
    estimated (errors in variables, :func:`eiv_sigmas`) from the residuals."""
    if fit.given:
        return fit.s_rot, fit.s_trans, fit.rho
    if fit.given_robot:
        return (*_camera_share(a, b, x, z, w, fit.rho), fit.rho)
    g_t, g_r = robot_error_map(a[w > 0], x, z)
    return eiv_sigmas(pose_residuals(a, b, x, z)[w > 0], g_t, g_r)


def _closed_form_only(a, b, fit: _Fit) -> None:
    """No refinement: the closed form's residuals and covariance at the noise level."""
    x, z = fit.x, fit.z
    r, jac = whitened_at(a, b, x, z, fit.s_rot, fit.s_trans, fit.w, fit.rho)
    fit.est = Estimate(
        value=(x, z), params=np.zeros(12), residuals=r, method=fit.label, names=list(PARAM_NAMES)
    )
    fit.cov, fit.jc = covariance_from_jacobian(jac, r, sigma=1.0)


def _refine_poses(a, b, fit: _Fit, robust: str | None) -> None:
    """Maximum likelihood on the target poses, iterated with the estimated noise level and the
    robust weights to a fixed point."""
    x, z, w, w_user = fit.x, fit.z, fit.w, fit.w_user
    s_rot, s_trans, rho = fit.s_rot, fit.s_trans, fit.rho
    given = fit.given
    reweight = robust in ("huber", "cauchy")
    # the noise level (if estimated) and robust weights depend on the fit: iterate to a fixed
    # point (a few rounds suffice; the refinement itself is warm-started)
    for _ in range(30 if reweight else (3 if not given else 0)):
        est = refine_ml(a, b, x, z, s_rot, s_trans, w, rho, covariance=False)
        x, z = est.value
        res = pose_residuals(a, b, x, z)
        old = (s_rot, s_trans, w)
        s_rot, s_trans, rho = _noise(a, b, x, z, w_user, fit)
        if reweight:
            tot = _total(s_rot, s_trans, rho, a, x, z)
            w = w_user * robust_weights(outlier_scores(res, *tot), robust)
        if np.max(np.abs(w - old[2])) < 1e-6 and abs(s_rot / old[0] - 1) < 1e-4:
            break
    est = refine_ml(a, b, x, z, s_rot, s_trans, w, rho)
    fit.x, fit.z = est.value
    fit.est, fit.s_rot, fit.s_trans, fit.rho, fit.w = est, s_rot, s_trans, rho, w


def _total(s_rot, s_trans, rho, a, x, z) -> tuple[float, float]:
    """Per-axis rotation and translation noise of a residual, camera and robot together."""
    if rho == 0:
        return s_rot, s_trans
    g_t = robot_error_map(a, x, z)[0]
    kappa = float(np.mean(np.einsum("nij,nij->n", g_t, g_t))) / 3.0
    return float(np.hypot(s_rot, rho)), float(np.sqrt(s_trans**2 + rho**2 * kappa))


def _refine(a, b, fit: _Fit, opt: _Options, start_method: str) -> None:
    """The refinement: on the target poses, then (given target points) on the reprojection."""
    fit.label = f"{start_method} + ML"
    _refine_poses(a, b, fit, opt.robust)
    if opt.target_points is not None:
        if opt.pixel_sigma is None or opt.camera_matrix is None or opt.pixels is None:
            raise CalibrationError(
                "the reprojection refinement needs target_points, pixels, camera_matrix and "
                "pixel_sigma together"
            )
        fit.est = refine_reprojection(
            a,
            b,
            fit.x,
            fit.z,
            opt.target_points,
            opt.pixels,
            opt.camera_matrix,
            opt.pixel_sigma,
            fit.w,
        )
        fit.x, fit.z = fit.est.value
        fit.label = f"{start_method} + ML (reprojection)"
    fit.cov, fit.jc = fit.est.covariance, fit.est.condition_number


def _check_condition(jc: float, cond: Conditioning) -> None:
    cond.jacobian_condition = float(jc)
    if not np.isfinite(jc) or jc > MAX_JACOBIAN_CONDITION:
        raise CalibrationError(
            f"the calibration is undetermined by these poses: condition number of the "
            f"refinement's Jacobian {jc:.3g} (limit {MAX_JACOBIAN_CONDITION:g}); add poses "
            "rotating about other axes"
        )


def _covariance(fit: _Fit, opt: _Options) -> tuple[np.ndarray, str]:
    """The covariance and its basis: the given noise level, or scaled by the residual chi2."""
    cov = fit.cov
    if opt.target_points is not None:
        basis = "given noise level (pixel_sigma)"
    elif fit.given:
        basis = "given noise level"
    else:
        m = int(np.count_nonzero(fit.w)) * 6
        chi = float(np.sum(fit.est.residuals**2))
        s2 = chi / max(m - 12, 1)
        cov = cov * s2
        basis = (
            f"scaled by residual chi2 (s^2 = {s2:.3g}); robot rotation error "
            f"{np.rad2deg(fit.rho):.3g} deg per axis"
        )
    return cov, basis


def _check_fit(ids, fit: _Fit, opt: _Options, notes: list) -> None:
    """Goodness of fit of the pose refinement with a given noise level (with an estimated one
    chi2/dof is 1 by construction; robust weights change its distribution): far outside its
    range, raise or flag by ``opt.misfit``."""
    if not (fit.given and opt.refine and opt.robust is None and opt.target_points is None):
        return
    keep = fit.w > 0
    r = fit.est.residuals.reshape(-1, 6)[keep]
    check = goodness_of_fit(
        r, 12, label="hand-eye ML", block=6, block_names=[f"pose {i}" for i in ids[keep]]
    )
    n_flags = len(fit.est.flags)
    apply_fit_check(fit.est, check, opt.misfit)
    notes.extend(fit.est.flags[n_flags:])


def _flag(ids, score, outlier_alpha: float, x, z, notes: list) -> list[int]:
    """Ids of the poses flagged as outliers; notes on them and on a possible X, Z swap."""
    limit = outlier_limit(outlier_alpha)
    flagged = [int(i) for i in ids[score > limit]]
    if flagged:
        notes.append(f"{len(flagged)} pose(s) flagged as outliers (chi2 > {limit:.3g}): {flagged}")
    if np.linalg.norm(x[:3, 3]) > np.linalg.norm(z[:3, 3]):
        notes.append(
            f"the camera offset |t_X| = {np.linalg.norm(x[:3, 3]):.4g} mm exceeds the target "
            f"offset |t_Z| = {np.linalg.norm(z[:3, 3]):.4g} mm: if both lists are stored inverted, "
            "X and Z swap roles and the data cannot tell (check convention=)"
        )
    return flagged


def _calibrate(
    prep: PreparedPoses, forms: list[ClosedForm], method: str, opt: _Options, cond: Conditioning
) -> HandEyeResult:
    a, b = prep.a, prep.b
    _check_options(opt)
    notes: list[str] = []
    start = _choose(forms, method)
    fit = _start(a, b, start, opt, notes)
    if opt.check_convention == "raise":
        _check_cell(prep, fit.x, pose_residuals(a, b, fit.x, fit.z), fit.w, opt, [], START_SLACK)
    if not opt.refine:
        _closed_form_only(a, b, fit)
    else:
        _refine(a, b, fit, opt, start.method)
    _check_condition(fit.jc, cond)
    x, z = fit.x, fit.z
    res = pose_residuals(a, b, x, z)
    check = _check_cell(prep, x, res, fit.w, opt, notes)
    score = outlier_scores(res, *_total(fit.s_rot, fit.s_trans, fit.rho, a, x, z))
    # the rotation and the translation noise are each estimated from about half the residual
    # degrees of freedom (3 N - 6 of 6 N - 12): the scale of the covariance is known no better
    dof = np.inf if fit.given else 3.0 * np.count_nonzero(fit.w) - 6.0
    if prep.a.shape[0] < MIN_TRUSTED_POSES:
        notes.append(
            f"with {prep.a.shape[0]} poses (fewer than {MIN_TRUSTED_POSES}) the covariance "
            "cannot be trusted: its 95 % region covers the truth in well under 90 % of cells"
        )
    cov, basis = _covariance(fit, opt)
    _check_fit(prep.ids, fit, opt, notes)
    flagged = _flag(prep.ids, score, opt.outlier_alpha, x, z, notes)
    camera_name, target_name = SETUP_FRAMES[prep.setup]
    solved = {"camera2flange": None, "target2base": None, "camera2base": None}
    solved |= {"target2flange": None, camera_name: x, target_name: z}
    return HandEyeResult(
        setup=prep.setup,
        **solved,
        covariance=cov,
        covariance_basis=basis,
        estimate=fit.est,
        method=fit.label,
        residuals=res,
        outlier_score=score,
        flagged=flagged,
        weights=fit.w,
        sigma_rot=fit.s_rot,
        sigma_trans=fit.s_trans,
        robot_sigma_rot=fit.rho,
        dof=float(dof),
        conditioning=cond,
        closed_forms=forms,
        check=check,
        prepared=prep,
        notes=notes,
    )


def _solve(methods: dict, form: str, prep: PreparedPoses, method: str, opt: _Options):
    """The closed forms ``methods`` of an AX = XB or AX = ZB ``form`` as the start of
    :func:`_calibrate` on the prepared poses."""
    if method != "best" and method not in methods:
        raise CalibrationError(
            f"unknown {form} method {method!r}; use 'best' or one of {list(methods)}"
        )
    cond = motion_conditioning(prep.a)
    forms = closed_forms(prep.a, prep.b, list(methods))
    return _calibrate(prep, forms, method, opt, cond)


def calibrate_handeye(
    flange2base,
    target2camera,
    *,
    method: str = "best",
    setup: str = "eye_in_hand",
    convention: str | Sequence[str] | None = None,
    robot_unit: str = "mm",
    camera_unit: str = "mm",
    ortho_tol: float = ORTHO_TOL,
    refine: bool = True,
    sigma_rot: float | None = None,
    sigma_trans: float | None = None,
    weights=None,
    robot_sigma_rot: float | None = None,
    robust: str | None = None,
    outlier_alpha: float = 1e-3,
    check_convention: str = "raise",
    rng: np.random.Generator | None = None,
    ransac_samples: int = 200,
    ids=None,
    target_points=None,
    pixels=None,
    camera_matrix=None,
    pixel_sigma: float | None = None,
    misfit: str = "flag",
    limits: CellLimits | None = None,
    rereadings: Callable[[], dict] | None = None,
) -> HandEyeResult:
    """Hand-eye calibration AX = XB from measured robot and camera poses, with uncertainty.

    Eye-in-hand: the camera is on the flange and sees a fixed target; returns ``camera2flange``
    (and the target pose ``target2base`` as a by-product). Eye-to-hand: the camera is fixed and
    the target is on the flange; returns ``camera2base`` (and ``target2flange``). The start is an
    OpenCV ``calibrateHandEye`` closed form (Tsai, Park, Horaud, Andreff, Daniilidis), then
    maximum likelihood on the SE(3) residuals of the target poses
    (:func:`calstudy.handeye.refine.refine_ml`).

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        Robot flange poses as stored (see ``convention``), translations in ``robot_unit``.
    target2camera : array_like, shape (N, 4, 4)
        Target poses from the camera as stored, translations in ``camera_unit``.
    method : str
        Closed form used as the start (AX = XB: ``"Tsai"``, ``"Park"``, ``"Horaud"``,
        ``"Andreff"``, ``"Daniilidis"``; AX = ZB: ``"Shah"``, ``"Li"``); ``"best"`` (default)
        tries all of them and starts from the one with the smallest residual.
    setup : {"eye_in_hand", "eye_to_hand"}
        Camera on the flange seeing a fixed target, or camera fixed seeing a target on the
        flange.
    convention : str or pair of str, optional
        Storage forms: ``"gripper2base"`` (default) or ``"base2gripper"``; ``"target2camera"``
        (default) or ``"camera2target"``.
    robot_unit, camera_unit : {"mm", "cm", "m", "in"}
        Length unit of the stored robot and camera translations.
    ortho_tol : float
        Rotations off SO(3) by at most this (``max |R^T R - I|``) are re-projected; worse ones are
        refused.
    refine : bool
        Run the maximum-likelihood refinement (default) or return the closed form.
    sigma_rot, sigma_trans : float, optional
        Noise of a measured target pose (rad and mm per axis). When omitted they are estimated
        robustly from the residuals with the robot's rotation error (errors in variables,
        :func:`~calstudy.handeye.robust.eiv_sigmas`), the covariance is scaled by the
        residual chi-square and its regions use the F distribution
        (:meth:`HandEyeResult.region_limit`).
    robot_sigma_rot : float, optional
        The robot's rotation error, rad per axis, if known (its translation error adds to
        ``sigma_trans``); otherwise estimated with the camera's noise, or 0 (robot exact) when
        ``sigma_rot`` and ``sigma_trans`` are given.
    weights : array_like, shape (N,), optional
        Per-pose weights, dimensionless (0 drops a pose).
    robust : {None, "huber", "cauchy", "ransac"}
        Down-weight outlier poses by iterative reweighting, or keep the poses consistent with the
        best of ``ransac_samples`` random pose triplets (needs ``rng``).
    outlier_alpha : float
        False-alarm probability per pose of the outlier flag, in (0, 1).
    check_convention : {"raise", "warn", "off"}
        What to do when the fit is implausible (:func:`~calstudy.handeye.checks.\
check_cell`: translations outside the camera's range or the robot's reach, a pose noise no
        instrument gives, a target that moved during the series): refuse with the likely causes
        tried and ranked (:func:`~calstudy.handeye.diagnose.diagnose`: storage
        convention, transposed rotations, unit factors 10, 25.4 and 1000, shifted rows, rotation
        formats of the file), warn with them (a :class:`calstudy.CalibrationWarning`) and go on,
        or skip the check.
    limits : CellLimits, optional
        The plausible ranges and noise of the check (default :class:`CellLimits()`).
    rereadings : callable, optional
        ``{cause: (flange2base, target2camera)}`` of other readings of the same file's columns
        for the diagnosis (:meth:`calstudy.handeye.posefile.PoseList.rereadings`; passed by
        :meth:`~calstudy.handeye.posefile.PoseList.arguments`).
    rng : numpy.random.Generator, optional
        Needed for ``robust="ransac"``.
    ransac_samples : int
        Random pose triplets tried by ``robust="ransac"``.
    ids : array_like of int, shape (N,), optional
        Pose ids used in messages and in ``flagged`` (default ``0 .. N - 1``).
    target_points, pixels, camera_matrix, pixel_sigma : optional
        Target points (M, 3) mm, their pixels (N, M, 2), K (3, 3) and the pixel noise (px): refine
        on the reprojection error instead of the target poses.
    misfit : {"flag", "raise", "off"}
        With ``sigma_rot`` and ``sigma_trans`` given (no robust loss), the whitened residual
        ``chi2/dof`` is tested against its expected range; above it, ``"flag"`` adds the message
        (naming the poses that disagree most) to ``notes`` with a
        :class:`calstudy.CalibrationWarning`, ``"raise"`` raises :class:`CalibrationError`.

    Returns
    -------
    HandEyeResult
        The solved transforms under their frame names (``camera2flange`` and ``target2base``
        eye-in-hand, ``camera2base`` and ``target2flange`` eye-to-hand) with their covariance,
        per-pose residuals, flagged poses and the checks' findings.

    Raises
    ------
    CalibrationError
        Bad input (named pose and number), degenerate motions (duplicates, pure translations, one
        rotation axis), an implausible fit with its likely causes (``check_convention="raise"``),
        a requested closed form inconsistent with the data, or a refinement that does not
        converge.
    """
    return _solve(
        OPENCV_METHODS,
        "AX = XB",
        prepare_poses(
            flange2base,
            target2camera,
            setup=setup,
            convention=convention,
            robot_unit=robot_unit,
            camera_unit=camera_unit,
            ortho_tol=ortho_tol,
            ids=ids,
        ),
        method,
        _Options(
            refine=refine,
            sigma_rot=sigma_rot,
            sigma_trans=sigma_trans,
            weights=weights,
            robot_sigma_rot=robot_sigma_rot,
            robust=robust,
            outlier_alpha=outlier_alpha,
            check_convention=check_convention,
            rng=rng,
            ransac_samples=ransac_samples,
            target_points=target_points,
            pixels=pixels,
            camera_matrix=camera_matrix,
            pixel_sigma=pixel_sigma,
            misfit=misfit,
            limits=limits,
            rereadings=rereadings,
        ),
    )


def calibrate_robot_world_handeye(
    flange2base,
    target2camera,
    *,
    method: str = "best",
    setup: str = "eye_in_hand",
    convention: str | Sequence[str] | None = None,
    robot_unit: str = "mm",
    camera_unit: str = "mm",
    ortho_tol: float = ORTHO_TOL,
    refine: bool = True,
    sigma_rot: float | None = None,
    sigma_trans: float | None = None,
    weights=None,
    robot_sigma_rot: float | None = None,
    robust: str | None = None,
    outlier_alpha: float = 1e-3,
    check_convention: str = "raise",
    rng: np.random.Generator | None = None,
    ransac_samples: int = 200,
    ids=None,
    target_points=None,
    pixels=None,
    camera_matrix=None,
    pixel_sigma: float | None = None,
    misfit: str = "flag",
    limits: CellLimits | None = None,
    rereadings: Callable[[], dict] | None = None,
) -> HandEyeResult:
    """Robot-world-hand-eye calibration AX = ZB: camera and target poses together.

    Solves ``A_i X = Z inv(B_i)`` for ``X = camera2flange`` and ``Z = target2base`` (eye-in-hand;
    ``camera2base`` and ``target2flange`` eye-to-hand) without forming relative motions. The start
    is OpenCV's ``calibrateRobotWorldHandEye`` (Shah, Li), then the same maximum-likelihood
    refinement as :func:`calibrate_handeye`.

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        Robot flange poses as stored (see ``convention``), translations in ``robot_unit``.
    target2camera : array_like, shape (N, 4, 4)
        Target poses from the camera as stored, translations in ``camera_unit``.
    method : str
        Closed form used as the start (AX = XB: ``"Tsai"``, ``"Park"``, ``"Horaud"``,
        ``"Andreff"``, ``"Daniilidis"``; AX = ZB: ``"Shah"``, ``"Li"``); ``"best"`` (default)
        tries all of them and starts from the one with the smallest residual.
    setup : {"eye_in_hand", "eye_to_hand"}
        Camera on the flange seeing a fixed target, or camera fixed seeing a target on the
        flange.
    convention : str or pair of str, optional
        Storage forms: ``"gripper2base"`` (default) or ``"base2gripper"``; ``"target2camera"``
        (default) or ``"camera2target"``.
    robot_unit, camera_unit : {"mm", "cm", "m", "in"}
        Length unit of the stored robot and camera translations.
    ortho_tol : float
        Rotations off SO(3) by at most this (``max |R^T R - I|``) are re-projected; worse ones are
        refused.
    refine : bool
        Run the maximum-likelihood refinement (default) or return the closed form.
    sigma_rot, sigma_trans : float, optional
        Noise of a measured target pose (rad and mm per axis). When omitted they are estimated
        robustly from the residuals with the robot's rotation error (errors in variables,
        :func:`~calstudy.handeye.robust.eiv_sigmas`), the covariance is scaled by the
        residual chi-square and its regions use the F distribution
        (:meth:`HandEyeResult.region_limit`).
    robot_sigma_rot : float, optional
        The robot's rotation error, rad per axis, if known (its translation error adds to
        ``sigma_trans``); otherwise estimated with the camera's noise, or 0 (robot exact) when
        ``sigma_rot`` and ``sigma_trans`` are given.
    weights : array_like, shape (N,), optional
        Per-pose weights, dimensionless (0 drops a pose).
    robust : {None, "huber", "cauchy", "ransac"}
        Down-weight outlier poses by iterative reweighting, or keep the poses consistent with the
        best of ``ransac_samples`` random pose triplets (needs ``rng``).
    outlier_alpha : float
        False-alarm probability per pose of the outlier flag, in (0, 1).
    check_convention : {"raise", "warn", "off"}
        What to do when the fit is implausible (:func:`~calstudy.handeye.checks.\
check_cell`: translations outside the camera's range or the robot's reach, a pose noise no
        instrument gives, a target that moved during the series): refuse with the likely causes
        tried and ranked (:func:`~calstudy.handeye.diagnose.diagnose`: storage
        convention, transposed rotations, unit factors 10, 25.4 and 1000, shifted rows, rotation
        formats of the file), warn with them (a :class:`calstudy.CalibrationWarning`) and go on,
        or skip the check.
    limits : CellLimits, optional
        The plausible ranges and noise of the check (default :class:`CellLimits()`).
    rereadings : callable, optional
        ``{cause: (flange2base, target2camera)}`` of other readings of the same file's columns
        for the diagnosis (:meth:`calstudy.handeye.posefile.PoseList.rereadings`; passed by
        :meth:`~calstudy.handeye.posefile.PoseList.arguments`).
    rng : numpy.random.Generator, optional
        Needed for ``robust="ransac"``.
    ransac_samples : int
        Random pose triplets tried by ``robust="ransac"``.
    ids : array_like of int, shape (N,), optional
        Pose ids used in messages and in ``flagged`` (default ``0 .. N - 1``).
    target_points, pixels, camera_matrix, pixel_sigma : optional
        Target points (M, 3) mm, their pixels (N, M, 2), K (3, 3) and the pixel noise (px): refine
        on the reprojection error instead of the target poses.
    misfit : {"flag", "raise", "off"}
        With ``sigma_rot`` and ``sigma_trans`` given (no robust loss), the whitened residual
        ``chi2/dof`` is tested against its expected range; above it, ``"flag"`` adds the message
        (naming the poses that disagree most) to ``notes`` with a
        :class:`calstudy.CalibrationWarning`, ``"raise"`` raises :class:`CalibrationError`.

    Returns
    -------
    HandEyeResult
        The solved transforms under their frame names (``camera2flange`` and ``target2base``
        eye-in-hand, ``camera2base`` and ``target2flange`` eye-to-hand) with their covariance,
        per-pose residuals, flagged poses and the checks' findings.

    Raises
    ------
    CalibrationError
        Bad input (named pose and number), degenerate motions (duplicates, pure translations, one
        rotation axis), an implausible fit with its likely causes (``check_convention="raise"``),
        a requested closed form inconsistent with the data, or a refinement that does not
        converge.
    """
    return _solve(
        OPENCV_RWHE_METHODS,
        "AX = ZB",
        prepare_poses(
            flange2base,
            target2camera,
            setup=setup,
            convention=convention,
            robot_unit=robot_unit,
            camera_unit=camera_unit,
            ortho_tol=ortho_tol,
            ids=ids,
        ),
        method,
        _Options(
            refine=refine,
            sigma_rot=sigma_rot,
            sigma_trans=sigma_trans,
            weights=weights,
            robot_sigma_rot=robot_sigma_rot,
            robust=robust,
            outlier_alpha=outlier_alpha,
            check_convention=check_convention,
            rng=rng,
            ransac_samples=ransac_samples,
            target_points=target_points,
            pixels=pixels,
            camera_matrix=camera_matrix,
            pixel_sigma=pixel_sigma,
            misfit=misfit,
            limits=limits,
            rereadings=rereadings,
        ),
    )
