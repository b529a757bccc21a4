"""Hand-eye residuals, closed forms and maximum-likelihood refinement for ``A_i X B_i = Z``.

The pieces :func:`calstudy.handeye.calibrate.calibrate_handeye` is made of: per-pose SE(3)
residuals of the target pose, OpenCV's closed forms scored by them, the maximum-likelihood
refinement on those residuals (:func:`refine_ml`) or on the reprojection error
(:func:`refine_reprojection`), and the Cramer-Rao bound (:func:`handeye_crb`). Poses are in the
canonical form of :class:`calstudy.handeye.inputs.PreparedPoses` (mm).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.estimation import Estimate, covariance_from_jacobian
from calstudy.estimators.axxb import (
    DEGENERATE_ROTATION,
    check_rotation_diversity,
    opencv_handeye,
    quiet_opencv,
)

#: OpenCV's AX = ZB (robot-world-hand-eye) solvers
OPENCV_RWHE_METHODS = {
    "Shah": cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    "Li": cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI,
}
#: a closed form whose residual score exceeds the best one's by this factor is refused
REFUSE_FACTOR = 10.0
PARAM_NAMES = ["X_rx", "X_ry", "X_rz", "X_tx", "X_ty", "X_tz"] + [
    "Z_rx",
    "Z_ry",
    "Z_rz",
    "Z_tx",
    "Z_ty",
    "Z_tz",
]


# ----------------------------------------------------------------------------------------------
# residuals and closed forms


def target_in_world(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Chordal mean of ``A_i X B_i`` over the poses: the fixed target ``Z`` given ``X`` (4, 4)."""
    zs = a @ x @ b
    return geo.make_transform(geo.project_to_so3(zs[:, :3, :3].mean(axis=0)), zs[:, :3, 3].mean(0))


def pose_residuals(a, b, x, z) -> np.ndarray:
    """Per-pose residuals ``(N, 6)``: ``[t_B - t_pred (mm, camera frame), log(R_pred^T R_B) (rad)]``
    of the measured ``B_i`` against the prediction ``inv(X) inv(A_i) Z``; a CalibrationError
    for a pose or transform that is not finite."""
    for name, value in (("a", a), ("b", b), ("x", x), ("z", z)):
        if not np.isfinite(value).all():
            raise CalibrationError(f"pose_residuals: {name} holds a non-finite value (nan or inf)")
    pred = geo.invert(x) @ geo.invert(a) @ z
    rot = geo.so3_log(np.swapaxes(pred[:, :3, :3], 1, 2) @ b[:, :3, :3])
    return np.concatenate([b[:, :3, 3] - pred[:, :3, 3], rot], axis=1)


def residual_score(res: np.ndarray, scale_mm: float) -> float:
    """Scale-free size of per-pose residuals ``(N, 6)``: RMS rotation (rad) and RMS translation
    divided by ``scale_mm`` (the camera-target distance), combined as ``sqrt(a^2 + b^2)``.

    A rotation error ``theta`` moves the target by about ``theta * distance``, so the two parts
    weigh alike whatever the units and size of the cell.
    """
    rot = np.mean(np.sum(res[:, 3:] ** 2, axis=1))
    trans = np.mean(np.sum(res[:, :3] ** 2, axis=1)) / scale_mm**2
    return float(np.sqrt(rot + trans))


def pose_scale(b: np.ndarray) -> float:
    """Median camera-target distance of the poses ``b`` (mm, at least 1e-9): the scale of
    :func:`residual_score`."""
    return max(float(np.median(np.linalg.norm(b[:, :3, 3], axis=1))), 1e-9)


#: poses the closed forms start from: OpenCV's solvers form every pair of their poses, so a
#: fixed number of well-spread poses keeps the start's cost constant and the whole fit linear
START_POSES = 12


def spread_subset(a: np.ndarray, k: int = START_POSES) -> np.ndarray:
    """Indices (sorted) of ``k`` well-spread robot poses of ``a`` (N, 4, 4), all if ``N <= k``.

    Greedy farthest-point selection on the orientations (chordal distance ``|R_i - R_j|``, the
    relative rotations the closed forms need) and, in a tenth of the weight, the positions
    relative to their spread: ``O(N k)``, deterministic (starts at the first pose).
    """
    n = a.shape[0]
    if n <= k:
        return np.arange(n)
    t = a[:, :3, 3]
    scale = max(float(np.sqrt(np.mean(np.sum((t - t.mean(0)) ** 2, 1)))), 1e-12)
    feat = np.concatenate([a[:, :3, :3].reshape(n, 9), 0.1 * t / scale], 1)
    picked = [0]
    dist = np.sum((feat - feat[0]) ** 2, 1)
    for _ in range(k - 1):
        j = int(np.argmax(dist))
        picked.append(j)
        dist = np.minimum(dist, np.sum((feat - feat[j]) ** 2, 1))
    return np.unique(picked)


@dataclass
class ClosedForm:
    """One closed-form solution and its fit to the data.

    Attributes
    ----------
    method : str
    x, z : (4, 4) arrays or None
        The solution (None if the solver failed).
    rms_rot_deg, rms_trans_mm : float
        RMS per-pose residual of the target pose, deg and mm.
    score : float
        :func:`residual_score` (dimensionless).
    seconds : float
        Wall time of the solver call.
    refused : str
        Why it was refused ("" if accepted).
    """

    method: str
    x: np.ndarray | None
    z: np.ndarray | None
    rms_rot_deg: float
    rms_trans_mm: float
    score: float
    seconds: float
    refused: str = ""


def check_proper(name: str, t: np.ndarray) -> np.ndarray:
    """``t`` if it is a finite rigid transform; else CalibrationError (OpenCV's solvers can return
    a reflection or NaN on inconsistent data)."""
    if not np.all(np.isfinite(t)):
        raise CalibrationError(f"{name} returned a non-finite result")
    r = t[:3, :3]
    dev = np.abs(r.T @ r - np.eye(3)).max()
    if dev > 1e-6 or np.linalg.det(r) < 0:
        raise CalibrationError(
            f"{name} returned no rotation (max |R^T R - I| = {dev:.3g}, det {np.linalg.det(r):.3g})"
        )
    return t


def _opencv_rwhe(a: np.ndarray, b: np.ndarray, method: str) -> tuple[np.ndarray, np.ndarray]:
    """``(X, Z)`` by ``cv2.calibrateRobotWorldHandEye``: it solves ``B = inv(X) inv(A) Z`` and
    returns ``inv(Z)`` ("base2world") and ``inv(X)`` ("gripper2cam"). Degenerate motions (pure
    translations, rotations about one axis, a repeated pose) are refused first, as by
    :func:`calstudy.estimators.axxb.opencv_handeye`: OpenCV would return a wrong answer."""
    check_rotation_diversity(a, DEGENERATE_ROTATION)
    ainv = geo.invert(a)
    with quiet_opencv():
        r_w, t_w, r_g, t_g = cv2.calibrateRobotWorldHandEye(
            list(b[:, :3, :3]),
            list(b[:, :3, 3:]),
            list(ainv[:, :3, :3]),
            list(ainv[:, :3, 3:]),
            method=OPENCV_RWHE_METHODS[method],
        )
    x = geo.invert(geo.make_transform(r_g, t_g.ravel()))
    z = geo.invert(geo.make_transform(r_w, t_w.ravel()))
    return x, z


def closed_forms(a: np.ndarray, b: np.ndarray, methods: Sequence[str]) -> list[ClosedForm]:
    """Run OpenCV closed forms on canonical poses and score them; refuse the inconsistent ones.

    The solvers see the :data:`START_POSES` well-spread poses of :func:`spread_subset` (all poses
    up to that many; OpenCV forms every pair of the poses it is given, a cost quadratic in their
    number); every result is scored on all poses.

    Parameters
    ----------
    a, b : (N, 4, 4) arrays
        Canonical poses (:class:`PreparedPoses`), mm.
    methods : sequence of str
        Names from :data:`OPENCV_METHODS` (AX = XB; ``Z`` then follows by a chordal mean) and
        :data:`OPENCV_RWHE_METHODS` (AX = ZB).

    Returns
    -------
    list of ClosedForm
        In the order of ``methods``; a result whose score exceeds the best by
        :data:`REFUSE_FACTOR`, or that failed or is not finite, has ``refused`` set.
    """
    import time

    scale = pose_scale(b)
    sub = spread_subset(a)
    a_s, b_s = a[sub], b[sub]
    out = []
    for m in methods:
        start = time.perf_counter()
        reason = ""
        try:
            if m in OPENCV_RWHE_METHODS:
                x, z = _opencv_rwhe(a_s, b_s, m)
                check_proper(m, z)
            else:
                x = opencv_handeye(a_s, b_s, m)
            x = check_proper(m, x)
            if m not in OPENCV_RWHE_METHODS:
                z = target_in_world(a, b, x)
            res = pose_residuals(a, b, x, z)
        except (CalibrationError, cv2.error) as exc:
            x = z = None
            res = None
            reason = f"solver failed: {str(exc).splitlines()[0]}"
        seconds = time.perf_counter() - start
        if res is None or not np.all(np.isfinite(res)):
            out.append(ClosedForm(m, None, None, np.inf, np.inf, np.inf, seconds, reason or "nan"))
            continue
        out.append(
            ClosedForm(
                m,
                x,
                z,
                float(np.rad2deg(np.sqrt(np.mean(np.sum(res[:, 3:] ** 2, 1))))),
                float(np.sqrt(np.mean(np.sum(res[:, :3] ** 2, 1)))),
                residual_score(res, scale),
                seconds,
            )
        )
    best = min((c.score for c in out), default=np.inf)
    for c in out:
        if not c.refused and c.score > REFUSE_FACTOR * max(best, 1e-12):
            c.refused = (
                f"inconsistent with the data: residual score {c.score:.3g} is "
                f"{c.score / max(best, 1e-300):.3g} times the best ({best:.3g})"
            )
    return out


# ----------------------------------------------------------------------------------------------
# maximum-likelihood refinement


@dataclass
class PoseProblem:
    """Whitened SE(3) residuals of ``B_i`` against ``inv(X) inv(A_i) Z``.

    Internal parameters ``[phi_y, t_y, phi_z, t_z]``: ``Y = inv(X)`` with ``R_Y = exp(phi_y)
    R_Y0`` and translation ``t_y``; ``Z`` with ``R_Z = R_Z0 exp(phi_z)`` and translation ``t_z``.
    """

    c: np.ndarray  # inv(A_i), (N, 4, 4)
    b: np.ndarray
    ry0: np.ndarray
    rz0: np.ndarray
    w_rot: np.ndarray  # (N,) sqrt(weight) / sigma_rot
    w_trans: np.ndarray
    wmat: np.ndarray | None = None  # (N, 6, 6) whitening with the robot's error, or None

    @classmethod
    def build(cls, a, b, x, z, sigma_rot, sigma_trans, weights, robot_sigma_rot: float = 0.0):
        sw = np.sqrt(weights)
        y = geo.invert(x)
        if robot_sigma_rot <= 0:
            return cls(geo.invert(a), b, y[:3, :3], z[:3, :3], sw / sigma_rot, sw / sigma_trans)
        cov = pose_covariances(a, x, z, sigma_rot, sigma_trans, robot_sigma_rot)
        wmat = np.linalg.inv(np.linalg.cholesky(cov)) * sw[:, None, None]
        one = np.ones(len(sw))
        return cls(geo.invert(a), b, y[:3, :3], z[:3, :3], one, one, wmat)

    def x0(self, x, z) -> np.ndarray:
        return np.concatenate([np.zeros(3), geo.invert(x)[:3, 3], np.zeros(3), z[:3, 3]])

    def unpack(self, p) -> tuple[np.ndarray, np.ndarray]:
        ry = geo.so3_exp(p[0:3])[0] @ self.ry0
        rz = self.rz0 @ geo.so3_exp(p[6:9])[0]
        x = geo.invert(geo.make_transform(ry, p[3:6]))
        return x, geo.make_transform(rz, p[9:12])

    def _predict(self, p):
        ry = geo.so3_exp(p[0:3])[0] @ self.ry0
        rz = self.rz0 @ geo.so3_exp(p[6:9])[0]
        rc, tc = self.c[:, :3, :3], self.c[:, :3, 3]
        r_hat = ry @ rc @ rz
        u = (rc @ p[9:12] + tc) @ ry.T
        return ry, r_hat, u, u + p[3:6]

    def residuals(self, p) -> np.ndarray:
        _, r_hat, _, t_hat = self._predict(p)
        e = geo.so3_log(np.swapaxes(r_hat, 1, 2) @ self.b[:, :3, :3])
        r = np.concatenate(
            [(self.b[:, :3, 3] - t_hat) * self.w_trans[:, None], e * self.w_rot[:, None]], 1
        )
        if self.wmat is not None:
            r = np.einsum("nij,nj->ni", self.wmat, r)
        return r.ravel()

    def jacobian(self, p) -> np.ndarray:
        ry, r_hat, u, _ = self._predict(p)
        n = r_hat.shape[0]
        e = geo.so3_log(np.swapaxes(r_hat, 1, 2) @ self.b[:, :3, :3])
        jl_y = geo.so3_left_jacobian(-p[0:3])[0].T
        jr_z = geo.so3_left_jacobian(-p[6:9])[0]
        jl_inv_e = np.swapaxes(geo.so3_right_jacobian_inverse(e), 1, 2)
        jac = np.zeros((n, 6, 12))
        jac[:, :3, 0:3] = geo.skew(u) @ jl_y
        jac[:, :3, 3:6] = -np.eye(3)
        jac[:, :3, 9:12] = -(ry @ self.c[:, :3, :3])
        jac[:, 3:, 0:3] = -jl_inv_e @ np.swapaxes(r_hat, 1, 2) @ jl_y
        jac[:, 3:, 6:9] = -jl_inv_e @ jr_z
        jac[:, :3] *= self.w_trans[:, None, None]
        jac[:, 3:] *= self.w_rot[:, None, None]
        if self.wmat is not None:
            jac = self.wmat @ jac
        return jac.reshape(n * 6, 12)

    def to_public(self, x: np.ndarray) -> np.ndarray:
        """Linear map ``(12, 12)`` at ``p = 0`` from internal parameters to ``[theta_X, t_X,
        theta_Z, t_Z]`` (``R_X = R_X0 exp(theta_X)``, ``t_X`` in mm)."""
        y = geo.invert(x)
        g = np.zeros((12, 12))
        g[0:3, 0:3] = -np.eye(3)
        g[3:6, 0:3] = -y[:3, :3].T @ geo.skew(y[:3, 3])
        g[3:6, 3:6] = -y[:3, :3].T
        g[6:12, 6:12] = np.eye(6)
        return g


def _solve(problem: PoseProblem, x, z) -> tuple[np.ndarray, np.ndarray, int]:
    from scipy.optimize import least_squares  # lazy: the tool imports in well under a second

    sol = least_squares(
        problem.residuals,
        problem.x0(x, z),
        jac=problem.jacobian,
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    if sol.status <= 0:
        raise CalibrationError(
            f"ML hand-eye refinement did not converge after {sol.nfev} evaluations "
            f"(cost {sol.cost:.6g}): {sol.message}"
        )
    x1, z1 = problem.unpack(sol.x)
    return x1, z1, int(sol.nfev)


#: AX = ZB needs this many poses with a weight above 0.
MIN_WEIGHTED_POSES = 3


def check_pose_weights(weights, n: int) -> np.ndarray:
    """Per-pose weights ``(n,)`` as a float array: 1 for None, else finite, >= 0, and above 0 for
    at least :data:`MIN_WEIGHTED_POSES` poses.

    Raises
    ------
    CalibrationError
        Naming the shape, the offending weight or the number of poses left.
    """
    if weights is None:
        return np.ones(n)
    w = geo.check_shape("weights", weights, (n,))
    if np.any(w < 0):
        i = int(np.argmin(w))
        raise CalibrationError(f"weights must be >= 0; weight {i} is {w[i]:g}")
    kept = int(np.count_nonzero(w > 0))
    if kept < MIN_WEIGHTED_POSES:
        raise CalibrationError(
            f"weights leave {kept} of the {n} poses with a weight > 0; AX = ZB needs at least "
            f"{MIN_WEIGHTED_POSES}"
        )
    return w


def robot_error_map(a, x, z) -> tuple[np.ndarray, np.ndarray]:
    """How a robot's rotation error moves the residuals: ``(N, 3, 3)`` maps of the rotation error
    ``delta`` (rad, flange frame; ``A_true = A exp(delta)``) to the translation residual (mm) and
    to the rotation residual (rad) of each pose, to first order.

    With ``P_i = inv(X) inv(A_i) Z`` the predicted target pose and ``q_i = t_P + R_X^T t_X`` the
    target seen from the flange origin in camera axes: translation ``[q_i]x R_X^T delta``,
    rotation ``-R_P^T R_X^T delta``.
    """
    pred = geo.invert(x) @ geo.invert(a) @ z
    rxt = x[:3, :3].T
    q = pred[:, :3, 3] + rxt @ x[:3, 3]
    g_t = geo.skew(q) @ rxt
    g_r = -np.swapaxes(pred[:, :3, :3], 1, 2) @ rxt
    return g_t, g_r


def pose_covariances(a, x, z, sigma_rot, sigma_trans, robot_sigma_rot) -> np.ndarray:
    """Covariance ``(N, 6, 6)`` of each pose's residual ``[t (mm), rot (rad)]``: the camera's
    noise (``sigma_trans``, ``sigma_rot`` per axis) plus a robot rotation error of
    ``robot_sigma_rot`` rad per axis through :func:`robot_error_map`."""
    g_t, g_r = robot_error_map(a, x, z)
    g = np.concatenate([g_t, g_r], axis=1)
    cov = robot_sigma_rot**2 * (g @ np.swapaxes(g, 1, 2))
    cov[:, :3, :3] += sigma_trans**2 * np.eye(3)
    cov[:, 3:, 3:] += sigma_rot**2 * np.eye(3)
    return cov


def whitened_at(a, b, x, z, sigma_rot, sigma_trans, weights, robot_sigma_rot: float = 0.0):
    """Whitened residuals ``(6N,)`` and Jacobian ``(6N, 12)`` in public coordinates at (x, z)."""
    prob = PoseProblem.build(a, b, x, z, sigma_rot, sigma_trans, weights, robot_sigma_rot)
    p0 = prob.x0(x, z)
    jac = prob.jacobian(p0) @ np.linalg.inv(prob.to_public(x))
    return prob.residuals(p0), jac


def refine_ml(
    a,
    b,
    x0,
    z0,
    sigma_rot: float,
    sigma_trans: float,
    weights=None,
    robot_sigma_rot: float = 0.0,
    covariance: bool = True,
) -> Estimate:
    """Maximum-likelihood ``(X, Z)`` from canonical poses: whitened SE(3) residuals, LM.

    Minimises ``sum_i w_i (|t_Bi - t_pred,i|^2 / sigma_trans^2 + |log(R_pred,i^T R_Bi)|^2 /
    sigma_rot^2)`` with the prediction ``inv(X) inv(A_i) Z``, by scipy's Levenberg-Marquardt with
    an analytic Jacobian (vectorised over poses).

    Parameters
    ----------
    a, b : (N, 4, 4) arrays
        Canonical poses ``A_i`` and ``B_i`` (:class:`PreparedPoses`), mm.
    x0, z0 : (4, 4) arrays
        Start, e.g. a closed form.
    sigma_rot, sigma_trans : float
        Noise of a measured target pose: rad per axis and mm per axis.
    weights : (N,) array, optional
        Per-pose weights (1 by default; 0 removes a pose).
    robot_sigma_rot : float
        Rotation error of a robot pose, rad per axis (errors in variables: each pose's residual
        then has the covariance of :func:`pose_covariances`, taken at the start and whitened by
        its Cholesky factor). A robot's translation error adds to ``sigma_trans`` (it enters
        the residual as camera translation noise does).
    covariance : bool
        Compute the covariance and the whitened residuals at the solution (False: ``covariance``
        and ``residuals`` are left empty, for the inner rounds of an iteration).

    Returns
    -------
    Estimate
        ``value`` is ``(X, Z)``; ``params`` ``[theta_X, t_X, theta_Z, t_Z]`` (rad, mm) where
        ``R_X = R_X,est exp(theta_X)`` (so the estimate itself has theta = 0); ``covariance``
        ``(J^T J)^-1`` of these coordinates with the given sigmas (not rescaled); ``residuals``
        the whitened residuals ``(6N,)``, per pose ``[t (3), rot (3)]``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    w = check_pose_weights(weights, a.shape[0])
    if not (sigma_rot > 0 and sigma_trans > 0):
        raise CalibrationError(
            f"sigma_rot and sigma_trans must be positive; got {sigma_rot:g}, {sigma_trans:g}"
        )
    prob = PoseProblem.build(a, b, x0, z0, sigma_rot, sigma_trans, w, robot_sigma_rot)
    x1, z1, nfev = _solve(prob, x0, z0)
    if not covariance:
        return Estimate(value=(x1, z1), params=np.zeros(12), iterations=nfev, names=[])
    r, jac = whitened_at(a, b, x1, z1, sigma_rot, sigma_trans, w, robot_sigma_rot)
    cov, cond = covariance_from_jacobian(jac, r, sigma=1.0)
    return Estimate(
        value=(x1, z1),
        params=np.zeros(12),
        covariance=cov,
        residuals=r,
        iterations=nfev,
        condition_number=cond,
        method="ML (SE(3) residuals)",
        names=list(PARAM_NAMES),
    )


def handeye_crb(a, b_true, x, z, sigma_rot: float, sigma_trans: float, weights=None):
    """Cramer-Rao bound ``(12, 12)`` of ``[theta_X, t_X, theta_Z, t_Z]`` at the truth.

    ``(J^T J)^-1`` of the whitened residuals of :func:`refine_ml` evaluated at the true ``X``,
    ``Z`` and noise-free ``B_i`` (rad, mm). Per-pose ``weights`` scale the information as in
    :func:`refine_ml` (a weight w means a noise ``sigma / sqrt(w)`` for that pose).
    """
    w = check_pose_weights(weights, len(a))
    _, jac = whitened_at(
        np.asarray(a, float), np.asarray(b_true, float), x, z, sigma_rot, sigma_trans, w
    )
    try:
        return np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        raise CalibrationError(
            f"the Cramer-Rao bound is undefined: these {len(a)} poses leave the calibration "
            "unobservable (singular information matrix); add poses rotating about other axes"
        ) from None


# ----------------------------------------------------------------------------------------------
# reprojection refinement


def _project(camera_matrix, pts):
    uvw = pts @ camera_matrix.T
    return uvw[..., :2] / uvw[..., 2:3]


@dataclass
class _Reprojection:
    """Whitened pixel residuals of the target points seen through ``inv(X) inv(A_i) Z``, with
    the parameters of :class:`PoseProblem`."""

    prob: PoseProblem
    pts: np.ndarray  # (M, 3) target points, mm
    k: np.ndarray  # camera matrix
    sw: np.ndarray  # (N, M, 1) sqrt(weight) / pixel_sigma, 0 for points not seen
    pxf: np.ndarray  # (N, M, 2) measured pixels, 0 for points not seen

    def parts(self, p):
        ry, r_hat, u, t_hat = self.prob._predict(p)
        cam = np.einsum("nij,mj->nmi", r_hat, self.pts) + t_hat[:, None, :]
        return ry, r_hat, u, cam

    def residuals(self, p):
        cam = self.parts(p)[3]
        return ((self.pxf - _project(self.k, cam)) * self.sw).ravel()

    def jacobian(self, p):
        k, pts, n = self.k, self.pts, self.prob.c.shape[0]
        ry, r_hat, _, cam = self.parts(p)
        jl_y = geo.so3_left_jacobian(-p[0:3])[0].T
        jr_z = geo.so3_left_jacobian(-p[6:9])[0]
        m = pts.shape[0]
        dcam = np.zeros((n, m, 3, 12))
        dcam[..., 0:3] = -geo.skew(cam - p[3:6]) @ jl_y
        dcam[..., 3:6] = np.eye(3)
        dcam[..., 6:9] = -np.einsum("nij,mjk->nmik", r_hat, geo.skew(pts)) @ jr_z
        dcam[..., 9:12] = np.einsum("ij,njk->nik", ry, self.prob.c[:, :3, :3])[:, None]
        x_, y_, z_ = cam[..., 0], cam[..., 1], cam[..., 2]
        dproj = np.zeros((n, m, 2, 3))
        dproj[..., 0, 0] = k[0, 0] / z_
        dproj[..., 0, 1] = k[0, 1] / z_
        dproj[..., 0, 2] = -(k[0, 0] * x_ + k[0, 1] * y_) / z_**2
        dproj[..., 1, 1] = k[1, 1] / z_
        dproj[..., 1, 2] = -k[1, 1] * y_ / z_**2
        out = -(dproj @ dcam) * self.sw[..., None]
        return out.reshape(-1, 12)


def refine_reprojection(
    a, b0, x0, z0, target_points, pixels, camera_matrix, pixel_sigma: float, weights=None
) -> Estimate:
    """Maximum-likelihood ``(X, Z)`` on the reprojection error of the target points.

    The pixel of target point ``P_k`` in image ``i`` is predicted as ``K (R P_k + t)`` (pinhole,
    undistorted pixels) with ``[R | t] = inv(X) inv(A_i) Z``; residuals are the pixel differences
    divided by ``pixel_sigma``. Finite-difference-free: the Jacobian is analytic.

    Parameters
    ----------
    a : (N, 4, 4) array
        Canonical robot poses, mm.
    b0 : (N, 4, 4) array
        Measured target poses (used only for the rotation-free starting values).
    x0, z0 : (4, 4) arrays
        Start.
    target_points : (M, 3) array
        Target points in the target frame, mm.
    pixels : (N, M, 2) array
        Their measured (undistorted) pixels; NaN marks a point not seen in that image.
    camera_matrix : (3, 3) array
        Pinhole intrinsics ``K``.
    pixel_sigma : float
        Pixel noise per axis, px.
    weights : (N,) array, optional
        Per-pose weights.

    Returns
    -------
    Estimate
        As :func:`refine_ml`, with residuals in whitened pixels.
    """
    n = a.shape[0]
    pts = geo.check_shape("target points", target_points, (None, 3))
    px = np.asarray(pixels, dtype=float)
    if px.shape != (n, pts.shape[0], 2):
        raise CalibrationError(f"pixels has shape {px.shape}; expected ({n}, {pts.shape[0]}, 2)")
    k = geo.check_shape("camera matrix", camera_matrix, (3, 3))
    seen = np.isfinite(px).all(axis=2)
    if seen.sum() < 6:
        raise CalibrationError(f"only {int(seen.sum())} pixels are given; need at least 6")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    sw = (np.sqrt(w)[:, None] * seen / pixel_sigma)[..., None]
    pxf = np.where(seen[..., None], px, 0.0)
    prob = PoseProblem.build(a, b0, x0, z0, 1.0, 1.0, w)
    rep = _Reprojection(prob, pts, k, sw, pxf)
    fun, jac = rep.residuals, rep.jacobian
    from scipy.optimize import least_squares

    sol = least_squares(fun, prob.x0(x0, z0), jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    if sol.status <= 0:
        raise CalibrationError(
            f"reprojection refinement did not converge after {sol.nfev} evaluations"
        )
    x1, z1 = prob.unpack(sol.x)
    # re-centre the rotations on the solution, so the covariance refers to theta = 0
    centred = PoseProblem.build(a, b0, x1, z1, 1.0, 1.0, w)
    prob.ry0, prob.rz0 = centred.ry0, centred.rz0
    p0 = centred.x0(x1, z1)
    jac_pub = jac(p0) @ np.linalg.inv(centred.to_public(x1))
    cov, cond = covariance_from_jacobian(jac_pub, fun(p0), sigma=1.0)
    return Estimate(
        value=(x1, z1),
        params=np.zeros(12),
        covariance=cov,
        residuals=fun(p0),
        iterations=int(sol.nfev),
        condition_number=cond,
        method="ML (reprojection)",
        names=list(PARAM_NAMES),
    )
