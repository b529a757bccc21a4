"""The sensor's rotation from the pure translations alone: weighted fit and its bound.

The paper (Eq. 10-11) takes the hand-eye rotation from the sphere centres measured after pure
translations of the flange by an unweighted SVD fit. With the flange orientation fixed, a centre
in the sensor frame is ``c_i = k - R^T v_i`` with ``v_i = R_F^T t_F,i`` (the flange translation in
the flange frame), ``R`` the sensor-to-flange rotation and ``k`` a constant that mixes the sphere
position and the sensor's offset. :func:`translation_rotation_ml` fits ``R`` and ``k`` weighted by
each centre's covariance (maximum likelihood for Gaussian centre noise);
:func:`translation_rotation_crb` is the Cramer-Rao bound of ``R`` from these data, the offset
``k`` a nuisance. Comparing the two with the full bound (all moves) says how much of the rotation
information the pure translations carry, and how much the unweighted fit loses.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.handeye.sphere import whitening


def _check(flange2base, centres, covariances):
    poses = np.asarray(flange2base, dtype=float)
    c = np.asarray(centres, dtype=float)
    cov = np.asarray(covariances, dtype=float)
    n = poses.shape[0] if poses.ndim == 3 else -1
    if poses.shape != (n, 4, 4) or c.shape != (n, 3) or cov.shape != (n, 3, 3) or n < 3:
        raise CalibrationError(
            f"expected N >= 3 poses (N, 4, 4), centres (N, 3) and covariances (N, 3, 3); got "
            f"{poses.shape}, {c.shape}, {cov.shape}"
        )
    spread = float(np.abs(poses[:, :3, :3] - poses[0, :3, :3]).max())
    if spread > 1e-6:
        raise CalibrationError(
            f"the flange orientation changes by up to {spread:.3g} between the moves; the "
            "rotation from pure translations needs one orientation"
        )
    whiten = whitening(cov, n)
    v = np.einsum("nji,nj->ni", poses[:, :3, :3], poses[:, :3, 3])
    return c, v, whiten


def translation_rotation_ml(flange2base, centres, covariances, rotation0) -> np.ndarray:
    """Sensor-to-flange rotation from pure translations, each centre weighted by its covariance.

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        Flange poses of the pure translations (one orientation), mm.
    centres : array_like, shape (N, 3)
        Measured sphere centres in the sensor frame, mm.
    covariances : array_like, shape (N, 3, 3)
        Covariance of each centre, mm^2 (positive definite).
    rotation0 : array_like, shape (3, 3)
        Starting rotation (the unweighted SVD fit).

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        The rotation ``R`` of sensor2flange.

    Raises
    ------
    CalibrationError
        On bad shapes, fewer than 3 moves, moves that change the orientation, or no convergence.
    """
    c, v, whiten = _check(flange2base, centres, covariances)
    r0 = np.asarray(rotation0, dtype=float)
    k0 = np.mean(c + v @ r0, axis=0)  # c_i + R^T v_i = k, v @ r0 = (R^T v_i)_i

    def residuals(p):
        r = r0 @ geo.rotvec_to_matrix(p[:3])
        return np.einsum("nij,nj->ni", whiten, c - p[3:] + v @ r).ravel()

    res = least_squares(residuals, np.r_[np.zeros(3), k0], method="lm", xtol=1e-12)
    if not res.success:
        raise CalibrationError(f"the weighted rotation did not converge ({res.message})")
    return r0 @ geo.rotvec_to_matrix(res.x[:3])


def translation_rotation_crb(flange2base, centres_true, covariances, rotation) -> float:
    """Cramer-Rao bound of the rotation from pure translations: the smallest RMS rotation error
    (deg, over the three axes) that any unbiased estimator reaches from these moves and this
    centre noise, the offset ``k`` estimated alongside.

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        Flange poses of the pure translations (one orientation), mm.
    centres_true : array_like, shape (N, 3)
        The true centres in the sensor frame, mm (shape-checked only; the bound depends on the
        moves and covariances).
    covariances : array_like, shape (N, 3, 3)
        Covariance of each centre at the truth, mm^2.
    rotation : array_like, shape (3, 3)
        The true sensor-to-flange rotation.

    Returns
    -------
    float
        ``sqrt(trace)`` of the rotation block of the inverse Fisher information, in degrees.

    Raises
    ------
    CalibrationError
        On bad shapes, or moves that leave the rotation unobservable (collinear translations).
    """
    _, v, whiten = _check(flange2base, centres_true, covariances)
    w = v @ np.asarray(rotation, dtype=float)  # R^T v_i
    # d(c_i)/d(delta) = [w_i]x for R = R_true exp([delta]); d(c_i)/dk = I
    eye = np.tile(np.eye(3), (len(w), 1, 1))
    jac = np.concatenate([np.stack([geo.skew(wi) for wi in w]), eye], axis=2)
    jw = np.einsum("nij,njk->nik", whiten, jac).reshape(-1, 6)
    fisher = jw.T @ jw
    a, b, d = fisher[:3, :3], fisher[:3, 3:], fisher[3:, 3:]
    schur = a - b @ np.linalg.solve(d, b.T)
    eig = np.linalg.eigvalsh(schur)
    if eig[0] <= 1e-9 * eig[-1]:
        raise CalibrationError(
            "the pure translations leave the rotation unobservable (the moves are collinear); "
            "translate along at least two directions"
        )
    return float(np.rad2deg(np.sqrt(np.trace(np.linalg.inv(schur)))))
