"""Plan a hand-eye calibration before measuring: choose N robot poses among candidates and
predict the accuracy at a tool point.

Given nominal ``X`` (camera2flange, e.g. from the bracket drawing) and ``Z`` (target2base),
each candidate flange pose ``A_i`` predicts the target pose the camera will see,
``B_i = inv(X) inv(A_i) Z``, and with the camera's noise (and the robot's rotation error) the
information ``J_i^T J_i`` that pose adds to the maximum-likelihood fit of
:func:`calstudy.handeye.refine.refine_ml` (the same whitened Jacobian). Poses are added
greedily, each time the one that most reduces the predicted variance of the tool point mapped by
``X`` (an A-optimal design for that point); the plan reports the predicted RMS error there, which
the Cramer-Rao bound of the chosen poses gives. ``benchmarks/bench_handeye_plan.py`` checks the
plan against random choices of as many poses by Monte Carlo.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.handeye.refine import whitened_at

#: a small prior information (per parameter, in whitened units) that keeps the greedy start
#: defined before the chosen poses determine all 12 parameters
PRIOR = 1e-6


@dataclass
class PosePlan:
    """A chosen set of robot poses and the accuracy they promise.

    Attributes
    ----------
    chosen : (N,) int array
        Indices of the chosen candidates, in the order they were added.
    predicted_rms_mm : float
        Predicted RMS error of the tool point mapped by ``X`` (the square root of the trace of
        its covariance), mm.
    predicted_curve_mm : (N,) array
        The same after each added pose (from the pose that makes the problem determined).
    """

    chosen: np.ndarray
    predicted_rms_mm: float
    predicted_curve_mm: np.ndarray


def point_jacobian(x: np.ndarray, point_camera: np.ndarray) -> np.ndarray:
    """``(3, 12)`` derivative of ``X @ p`` by ``[theta_X, t_X, theta_Z, t_Z]`` (the public
    coordinates of :class:`~calstudy.handeye.calibrate.HandEyeResult`)."""
    jac = np.zeros((3, 12))
    jac[:, 0:3] = -x[:3, :3] @ geo.skew(point_camera)
    jac[:, 3:6] = np.eye(3)
    return jac


def pose_information(a, x, z, sigma_rot, sigma_trans, robot_sigma_rot=0.0) -> np.ndarray:
    """Fisher information each candidate flange pose adds to the hand-eye fit.

    Parameters
    ----------
    a : (N, 4, 4) array
        Candidate flange poses (canonical, mm).
    x, z : (4, 4) arrays
        Nominal ``X`` and ``Z`` (mm); the camera poses are predicted from them, noise-free.
    sigma_rot, sigma_trans : float
        Camera noise per axis, rad and mm.
    robot_sigma_rot : float
        Robot rotation error per axis, rad.

    Returns
    -------
    (N, 12, 12) array
        ``J_i^T J_i`` of the whitened residuals, in the public coordinates
        ``[theta_X, t_X, theta_Z, t_Z]`` (rad, mm).
    """
    a = np.asarray(a, dtype=float)
    b = geo.invert(x) @ geo.invert(a) @ z
    _, jac = whitened_at(a, b, x, z, sigma_rot, sigma_trans, np.ones(len(a)), robot_sigma_rot)
    j = jac.reshape(len(a), 6, 12)
    return np.swapaxes(j, 1, 2) @ j


def point_rms(info: np.ndarray, pj: np.ndarray) -> np.ndarray:
    """Predicted RMS error (mm) of the tool point for information matrices ``(..., 12, 12)``."""
    cov = np.linalg.inv(info)
    return np.sqrt(np.clip(np.einsum("ij,...jk,ik->...", pj, cov, pj), 0.0, None))


def plan_poses(
    candidates,
    camera2flange,
    target2base,
    n_poses: int,
    sigma_rot: float,
    sigma_trans: float,
    tool_point_mm,
    robot_sigma_rot: float = 0.0,
) -> PosePlan:
    """Choose ``n_poses`` of the candidate flange poses for the smallest predicted error at the
    tool point.

    Parameters
    ----------
    candidates : (M, 4, 4) array
        Reachable flange poses (flange2base, mm) from which the camera sees the target.
    camera2flange, target2base : (4, 4) arrays
        Nominal ``X`` and ``Z`` (mm), e.g. from drawings; the plan depends on them only through
        the viewing geometry.
    n_poses : int
        Poses to choose (at least 3, at most M).
    sigma_rot, sigma_trans : float
        The camera's noise per axis, rad and mm.
    tool_point_mm : (3,) array
        The point in the camera frame whose position in the flange frame matters (mm).
    robot_sigma_rot : float
        The robot's rotation error per axis, rad.

    Returns
    -------
    PosePlan

    Raises
    ------
    CalibrationError
        For fewer than 3 or more than M poses, or non-positive noise.
    """
    a = np.asarray(candidates, dtype=float)
    m = a.shape[0]
    if not 3 <= n_poses <= m:
        raise CalibrationError(f"n_poses must be between 3 and the {m} candidates; got {n_poses}")
    if not (sigma_rot > 0 and sigma_trans > 0):
        raise CalibrationError(
            f"sigma_rot = {sigma_rot} and sigma_trans = {sigma_trans}: both must be positive"
        )
    x = np.asarray(camera2flange, dtype=float)
    z = np.asarray(target2base, dtype=float)
    pj = point_jacobian(x, geo.check_shape("tool point", tool_point_mm, (3,)))
    infos = pose_information(a, x, z, sigma_rot, sigma_trans, robot_sigma_rot)
    total = PRIOR * np.eye(12)
    free = np.ones(m, dtype=bool)
    chosen, curve = [], []
    for _ in range(n_poses):
        trial = total + infos
        score = point_rms(trial, pj)
        score[~free] = np.inf
        k = int(np.argmin(score))
        chosen.append(k)
        free[k] = False
        total = total + infos[k]
        curve.append(float(score[k]))
    final = float(point_rms(total - PRIOR * np.eye(12), pj))
    return PosePlan(np.array(chosen), final, np.array(curve))
