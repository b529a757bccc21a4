"""Noise level and outliers of a hand-eye calibration.

A robust noise level from per-pose residuals (:func:`robust_sigmas`), the per-pose outlier
score and its flag limit, the weights of the Huber and Cauchy losses, and RANSAC over pose
triplets (:func:`ransac_inliers`), as :func:`calstudy.handeye.calibrate.calibrate_handeye`
uses them.
"""

from __future__ import annotations

import cv2
import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.estimators.axxb import opencv_handeye
from calstudy.handeye.refine import (
    check_proper,
    pose_residuals,
    pose_scale,
    target_in_world,
)

#: median of the chi-square distribution with 3 degrees of freedom (robust noise estimate;
#: ``scipy.stats.chi2.median(3)``, which a test checks: scipy.stats is imported only when needed)
CHI2_3_MEDIAN = 2.3659738843753377


def outlier_limit(alpha: float = 1e-3) -> float:
    """Outlier flag limit: the ``1 - alpha`` quantile of chi-square with 6 degrees of freedom.

    A pose whose whitened squared residual (``HandEyeResult.outlier_score``) exceeds it is
    flagged.

    Parameters
    ----------
    alpha : float
        False-alarm probability per pose, in (0, 1).

    Returns
    -------
    float
        The limit (dimensionless).

    Raises
    ------
    CalibrationError
        If ``alpha`` is not in (0, 1).
    """
    from scipy.special import chdtri  # chi2.isf without importing scipy.stats

    if not 0.0 < alpha < 1.0:
        raise CalibrationError(f"alpha = {alpha!r}: a false-alarm probability must be in (0, 1)")

    return float(chdtri(6, alpha))


def robust_sigmas(res: np.ndarray, alpha: float = 1e-3) -> tuple[float, float]:
    """Noise level ``(sigma_rot, sigma_trans)`` from per-pose residuals ``(N, 6)``, robustly.

    A median-based start (each part is ``sigma^2 chi2(3)`` for an inlier) marks the poses beyond
    the ``1 - alpha`` quantile; the RMS of the others, corrected for the 12 fitted parameters,
    is the estimate (reweighted least-median: efficient on clean data, robust to outliers).
    A CalibrationError if ``res`` holds no pose.
    """
    n = res.shape[0]
    if n == 0:
        raise CalibrationError("robust_sigmas needs the residuals of at least 1 pose; got 0 poses")
    rr = np.sum(res[:, 3:] ** 2, 1)
    tt = np.sum(res[:, :3] ** 2, 1)
    keep = (n - 2.0) / n  # 12 parameters take 2 of the 6 N degrees of freedom per pose
    s_r = np.sqrt(max(np.median(rr) / (CHI2_3_MEDIAN * keep), 1e-30))
    s_t = np.sqrt(max(np.median(tt) / (CHI2_3_MEDIAN * keep), 1e-30))
    inl = rr / s_r**2 + tt / s_t**2 <= outlier_limit(alpha)
    m = int(inl.sum())
    if m > 2:
        s_r = np.sqrt(max(rr[inl].sum() / (3.0 * (m - 2)), 1e-30))
        s_t = np.sqrt(max(tt[inl].sum() / (3.0 * (m - 2)), 1e-30))
    return float(s_r), float(s_t)


#: the camera's share of a residual variance is kept at least this fraction of the total
MIN_CAMERA_SHARE = 0.1


def eiv_sigmas(res: np.ndarray, g_t: np.ndarray, g_r: np.ndarray, alpha: float = 1e-3):
    """Camera noise and robot rotation error ``(sigma_rot, sigma_trans, robot_sigma_rot)`` (rad,
    mm, rad per axis) from per-pose residuals ``(N, 6)`` (errors in variables).

    A robot rotation error ``delta`` moves the translation residual by ``g_t delta`` and the
    rotation residual by ``g_r delta`` (:func:`~calstudy.handeye.refine.\
robot_error_map`); the camera's noise moves them independently. So the covariance of the
    translation and rotation residuals is ``robot_sigma_rot^2 g_t g_r^T`` alone, and its moment
    estimate over the inlier poses (:func:`robust_sigmas`' inliers) gives ``robot_sigma_rot``
    (0 if negative); the camera's share is the rest of the robust total, at least
    :data:`MIN_CAMERA_SHARE` of it. (A robot's translation error is indistinguishable from the
    camera's translation noise and stays in ``sigma_trans``.)

    Parameters
    ----------
    res : (N, 6) array
        Per-pose residuals ``[t (mm), rot (rad)]``.
    g_t, g_r : (N, 3, 3) arrays
        The maps of :func:`~calstudy.handeye.refine.robot_error_map` at the fit.
    alpha : float
        False-alarm probability of the inlier test.

    Returns
    -------
    (float, float, float)
        ``sigma_rot`` (rad), ``sigma_trans`` (mm) of the camera and ``robot_sigma_rot`` (rad),
        per axis.
    """
    s_r, s_t = robust_sigmas(res, alpha)
    score = np.sum(res[:, 3:] ** 2, 1) / s_r**2 + np.sum(res[:, :3] ** 2, 1) / s_t**2
    inl = score <= outlier_limit(alpha)
    cross = g_t[inl] @ np.swapaxes(g_r[inl], 1, 2)  # (M, 3, 3): cov(t, rot) / rho^2
    num = float(np.einsum("ni,nij,nj->", res[inl, :3], cross, res[inl, 3:]))
    rho2 = max(num / max(float(np.sum(cross**2)), 1e-300), 0.0)
    kappa = float(np.mean(np.einsum("nij,nij->n", g_t[inl], g_t[inl]))) / 3.0
    rho2 = min(rho2, (1 - MIN_CAMERA_SHARE) * s_r**2, (1 - MIN_CAMERA_SHARE) * s_t**2 / kappa)
    return (
        float(np.sqrt(s_r**2 - rho2)),
        float(np.sqrt(s_t**2 - rho2 * kappa)),
        float(np.sqrt(rho2)),
    )


def outlier_scores(res, sigma_rot, sigma_trans):
    """Whitened squared residual of each pose ``(N,)``: chi-square with 6 degrees of freedom for
    an inlier; a CalibrationError unless both sigmas are positive."""
    if not (sigma_rot > 0 and sigma_trans > 0):
        raise CalibrationError(
            f"outlier_scores needs positive noise levels; got sigma_rot = {sigma_rot}, "
            f"sigma_trans = {sigma_trans}"
        )
    return np.sum(res[:, :3] ** 2, 1) / sigma_trans**2 + np.sum(res[:, 3:] ** 2, 1) / sigma_rot**2


def robust_weights(score: np.ndarray, loss: str, c: float = 2.0) -> np.ndarray:
    """Iteratively reweighted least-squares weights of the ``"huber"`` or ``"cauchy"`` loss (a
    CalibrationError naming any other)."""
    if loss not in ("huber", "cauchy"):
        raise CalibrationError(f"robust loss {loss!r}: use 'huber' or 'cauchy'")
    u = np.sqrt(score / 6.0)
    if loss == "huber":
        return np.where(u <= c, 1.0, c / np.maximum(u, 1e-300))
    return 1.0 / (1.0 + (u / c) ** 2)


def ransac_inliers(a, b, rng, n_samples: int) -> np.ndarray:
    """Inlier mask by least-median-of-squares over random pose triplets (Park closed form)."""
    n = a.shape[0]
    scale = pose_scale(b)
    best, best_med = None, np.inf
    for _ in range(n_samples):
        idx = rng.choice(n, 3, replace=False)
        try:
            x = check_proper("Park", opencv_handeye(a[idx], b[idx], "Park"))
            z = target_in_world(a[idx], b[idx], x)
            res = pose_residuals(a, b, x, z)
        except (CalibrationError, cv2.error):
            continue
        per = np.sum(res[:, 3:] ** 2, 1) + np.sum(res[:, :3] ** 2, 1) / scale**2
        med = float(np.median(per))
        if np.isfinite(med) and med < best_med:
            best, best_med = per, med
    if best is None:
        raise CalibrationError(f"RANSAC: none of the {n_samples} pose triplets gave a solution")
    # LMedS scale with the small-sample correction of Rousseeuw and Leroy
    s0 = 1.4826 * (1.0 + 5.0 / max(n - 3, 1)) * np.sqrt(best_med)
    return best <= (2.5 * s0) ** 2
