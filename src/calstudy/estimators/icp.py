"""Weighted point-to-point ICP of multi-view scans (M3DHE-ICP, ``dualarm`` Eq. 4).

A scan from pose ``i``, mapped into the robot base frame with the reported flange pose and the
hand-eye transform (Eq. 3), is moved onto the scan of the reference pose by the rigid motion
``(R, T)`` minimising ``sum_k || W^(1/2) (R p_k + T - q_k) ||^2`` over nearest-neighbour pairs
``(p_k, q_k)`` (a KD tree of the reference cloud), with ``W = diag(1, 1, w_z)`` weighting the
error along the base z axis. The paper's reading as implemented:

* pairs farther apart than ``max_pair_mm`` are not pairs (clouds must overlap);
* the alignment is iterated to convergence; then pairs whose z error exceeds ``z_threshold_mm``
  are dropped as noise points and the alignment is iterated again ("the threshold after
  stitching");
* at most ``max_iterations`` correspondence updates in all.

Each update solves the weighted problem for fixed pairs by Gauss-Newton on a rotation vector and
a translation (no closed form exists for anisotropic weights).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError

#: fewest pairs an update may rest on
MIN_PAIRS = 6


@dataclass
class IcpResult:
    """Result of :func:`weighted_icp`.

    Attributes
    ----------
    transform : numpy.ndarray, shape (4, 4)
        Correction applied to the moving cloud (``p_corrected = transform @ p``).
    iterations : int
        Correspondence updates used.
    pairs : int
        Pairs in the final update.
    rms_mm : float
        Unweighted RMS distance of the final pairs, mm.
    converged : bool
        The last update moved the cloud by less than the tolerance.
    """

    transform: np.ndarray
    iterations: int
    pairs: int
    rms_mm: float
    converged: bool


def _weighted_rigid_step(p: np.ndarray, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """One Gauss-Newton step ``(4, 4)`` towards the rigid motion minimising
    ``sum (R p + t - q)^T diag(w) (R p + t - q)`` over fixed pairs ``p -> q`` ``(N, 3)``.

    The pairs are centred on ``p``'s centroid first, which keeps the normal equations well
    conditioned far from the origin. Repeated on fixed pairs, the steps converge quadratically.
    """
    c = p.mean(axis=0)
    x = p - c
    r = (p - q) * np.sqrt(w)
    # d(R x + t)/d(omega) = -[x]_x, d/dt = I, each row weighted by sqrt(w)
    jac = np.zeros((p.shape[0], 3, 6))
    jac[:, 0, 1], jac[:, 0, 2] = x[:, 2], -x[:, 1]
    jac[:, 1, 0], jac[:, 1, 2] = -x[:, 2], x[:, 0]
    jac[:, 2, 0], jac[:, 2, 1] = x[:, 1], -x[:, 0]
    jac[:, :, 3:] = np.eye(3)
    jac *= np.sqrt(w)[None, :, None]
    flat = jac.reshape(-1, 6)
    delta = -np.linalg.solve(flat.T @ flat, flat.T @ r.ravel())
    rot = geo.rotvec_to_matrix(delta[:3])
    # rotation about the centroid, then the translation
    return geo.make_transform(rot, c - rot @ c + delta[3:])


def _check_cloud(name: str, cloud) -> np.ndarray:
    a = np.asarray(cloud, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise CalibrationError(f"{name} has shape {a.shape}; expected (N, 3)")
    if a.shape[0] == 0:
        raise CalibrationError(f"{name} is empty (0 points)")
    return geo.check_finite(name, a)


def weighted_icp(
    moving,
    reference,
    *,
    z_weight: float = 20.0,
    z_threshold_mm: float = 0.1,
    max_iterations: int = 200,
    max_pair_mm: float = 2.0,
    tol: float = 1e-6,
    tree: cKDTree | None = None,
) -> IcpResult:
    """Align ``moving`` ``(N, 3)`` onto ``reference`` ``(M, 3)`` (both mm, same frame), Eq. 4.

    Parameters
    ----------
    moving, reference : array_like
        Point clouds.
    z_weight : float
        Weight of the squared z error (the paper: 20).
    z_threshold_mm : float
        Pairs with a larger z error are dropped after the first convergence (the paper: 0.1);
        ``inf`` keeps all.
    max_iterations : int
        Largest number of correspondence updates (the paper: 200).
    max_pair_mm : float
        Largest distance of a nearest-neighbour pair.
    tol : float
        Convergence: an update that moves no point by more than ``tol`` mm ends a stage.
        (Point-to-point ICP lets overlapping caps of a sphere slide about its centre with little
        change of cost; the cap on iterations stops such a slide.)
    tree : scipy.spatial.cKDTree, optional
        A prebuilt tree of ``reference``.

    Raises
    ------
    CalibrationError
        On an empty or non-finite cloud, bad weights, or clouds that do not overlap (fewer than
        ``MIN_PAIRS`` points within ``max_pair_mm`` of the reference).
    """
    p0 = _check_cloud("moving cloud", moving)
    q = _check_cloud("reference cloud", reference)
    if not (z_weight > 0 and z_threshold_mm > 0 and max_pair_mm > 0 and max_iterations >= 1):
        raise CalibrationError(
            f"z_weight {z_weight}, z_threshold_mm {z_threshold_mm}, max_pair_mm {max_pair_mm} must "
            f"be > 0 and max_iterations {max_iterations} >= 1"
        )
    kd = cKDTree(q) if tree is None else tree
    w = np.array([1.0, 1.0, z_weight])
    total = np.eye(4)
    it, stage, converged, n_pairs, rms = 0, 0, False, 0, float("nan")
    while it < max_iterations:
        cur = geo.apply(total, p0)
        dist, idx = kd.query(cur, distance_upper_bound=max_pair_mm)
        keep = np.isfinite(dist)
        if stage == 1:
            dz = np.zeros_like(dist)
            dz[keep] = np.abs(cur[keep, 2] - q[idx[keep], 2])
            keep &= dz <= z_threshold_mm
        n_pairs = int(keep.sum())
        if n_pairs < MIN_PAIRS:
            if it == 0:
                nearest = float(kd.query(cur, k=1)[0].min())
                raise CalibrationError(
                    f"the clouds do not overlap: {n_pairs} of {len(cur)} points lie within "
                    f"{max_pair_mm:g} mm of the reference (closest {nearest:.3g} mm); ICP needs "
                    f"{MIN_PAIRS}"
                )
            raise CalibrationError(
                f"ICP lost its pairs: {n_pairs} pairs left at iteration {it} (need {MIN_PAIRS})"
            )
        it += 1
        step = _weighted_rigid_step(cur[keep], q[idx[keep]], w)
        total = step @ total
        moved = geo.apply(step, cur[keep]) - q[idx[keep]]
        rms = float(np.sqrt(np.mean(np.sum(moved**2, axis=1))))
        shift = float(np.abs(geo.apply(step, cur) - cur).max())
        if shift < tol:
            if stage == 0 and np.isfinite(z_threshold_mm):
                stage = 1
                continue
            converged = True
            break
    return IcpResult(total, it, n_pairs, rms, converged)


__all__ = ["IcpResult", "weighted_icp"]
