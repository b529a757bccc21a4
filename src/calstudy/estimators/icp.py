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
#: an update with ``delta^T H delta / s^2`` below this is smaller than its own standard error
NOISE_STEP = 1.0


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
        The last update moved the cloud by less than the tolerance (or, with
        ``stop_below_noise``, was below the noise).
    """

    transform: np.ndarray
    iterations: int
    pairs: int
    rms_mm: float
    converged: bool


def _weighted_rigid_step(
    p: np.ndarray, q: np.ndarray, w: np.ndarray, c: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """One Gauss-Newton step ``(4, 4)`` towards the rigid motion minimising
    ``sum (R p + t - q)^T diag(w) (R p + t - q)`` over fixed pairs ``p -> q`` ``(N, 3)``.

    The pairs are centred on ``p``'s centroid first, which keeps the normal equations well
    conditioned far from the origin. The 6 x 6 normal equations are accumulated directly from
    the 3 x 3 moments of the pairs, never from an ``(N, 3, 6)`` Jacobian. Repeated on fixed
    pairs, the steps converge quadratically. Also returns ``delta^T H delta / s^2``, the size
    of the step in units of its own standard error, with ``s^2`` the weighted residual variance
    of the pairs (``3 N - 6`` degrees of freedom): below 1, the step is smaller than its
    standard error. ``c``: ``p``'s centroid ``p.sum(axis=0) / N`` if already at hand.
    """
    n = p.shape[0]
    if c is None:
        c = p.sum(axis=0) / n
    x = p - c
    r = p - q
    # the Jacobian of axis j is a_j = [x_k x e_j, e_j] per pair; with sum_k x_k = 0 the normal
    # equations need only the moments M = x^T x and C = x^T r:
    #   H_rot = sum_j w_j [e_j]_x M [e_j]_x^T,  H_rot,t = 0,  H_t = n diag(w),
    #   g_rot = -sum_j w_j [e_j]_x C[:, j],      g_t = w * sum_k r_k
    # each [e_j]_x M [e_j]_x^T only moves entries of M and flips signs, so the sums are written
    # out term by term (in the order of j, as scalars: the same floating-point operations)
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = (x.T @ x).tolist()
    (_, c01, c02), (c10, _, c12), (c20, c21, _) = (x.T @ r).tolist()
    w0, w1, w2 = w.tolist()
    st = (w * r.sum(axis=0)).tolist()
    h = np.array(
        [
            [w1 * m22 + w2 * m11, -(w2 * m10), -(w1 * m20), 0.0, 0.0, 0.0],
            [-(w2 * m01), w0 * m22 + w2 * m00, -(w0 * m21), 0.0, 0.0, 0.0],
            [-(w1 * m02), -(w0 * m12), w0 * m11 + w1 * m00, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, n * w0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, n * w1, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, n * w2],
        ]
    )
    g = np.array(
        [-(w1 * c21) + w2 * c12, w0 * c20 - w2 * c02, -(w0 * c10) + w1 * c01, *st]
    )
    delta = -np.linalg.solve(h, g)
    s2 = float((r**2 @ w).sum()) / max(3 * n - 6, 1)
    rot = geo.so3_exp(delta[:3])[0]
    # rotation about the centroid, then the translation
    step = np.zeros((4, 4))
    step[:3, :3] = rot
    step[:3, 3] = c - rot @ c + delta[3:]
    step[3, 3] = 1.0
    return step, float(delta @ h @ delta) / max(s2, 1e-300)


def _check_cloud(name: str, cloud) -> np.ndarray:
    a = np.asarray(cloud, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise CalibrationError(f"{name} has shape {a.shape}; expected (N, 3)")
    if a.shape[0] == 0:
        raise CalibrationError(f"{name} is empty (0 points)")
    return geo.check_finite(name, a)


def _moves_less_than(
    step: np.ndarray, cur: np.ndarray, paired: np.ndarray, tol: float, c: np.ndarray | None = None
) -> bool:
    """Whether ``step`` moves every point of ``cur`` by less than ``tol`` (max norm).

    The step's mean displacement over the ``paired`` points it was fitted to is its translation
    at their centroid, and no point moves less than that mean in every axis; a step whose
    translation there exceeds ``tol`` (with a margin far above rounding) moves some point by
    more, and the cloud need not be mapped to see it. The margin covers the rounding of both
    displacements (a few ulps of the largest coordinate). ``c``: the centroid
    ``paired.sum(axis=0) / len(paired)`` if already at hand.
    """
    if c is None:
        c = paired.sum(axis=0) / paired.shape[0]
    at_centroid = step[:3, :3] @ c + step[:3, 3] - c
    # the largest |coordinate|, without an array of absolute values
    margin = 1e-9 + 1e-13 * max(float(paired.max()), -float(paired.min()))
    if float(np.abs(at_centroid).max()) > tol + margin:
        return False
    return float(np.abs(geo.apply(step, cur) - cur).max()) < tol


class _Pairs:
    """Nearest neighbours in the reference of a moving cloud, kept from one correspondence
    update to the next and asked of the tree again only where they may have changed.

    At some position ``x`` of a point the tree gives its ``K`` nearest reference points within
    ``max_pair_mm``: the first ``K - 1`` are its candidates, the ``K``-th lies at ``d_K`` (the
    bound if there is none), so every other reference point lies at least ``d_K`` from ``x``.
    Moved since by ``D = |x' - x|``, every non-candidate lies at least ``d_K - D`` from ``x'``
    (triangle inequality): while the nearest candidate, measured at ``x'``, is closer than that
    (by a margin above rounding, and clear of the next candidate by that margin), it is the
    point's nearest neighbour, within the bound. Only the other points are queried again. The
    pairs are those of a fresh query of the whole cloud: the same indices, the same points left
    without a pair.
    """

    #: neighbours asked of the tree per point: K - 1 candidates and the K-th as the bound
    #: (``update`` compares the three candidates of K = 4 side by side)
    K = 4
    #: margin (mm) that keeps the tests strict beyond the rounding of the distances
    MARGIN = 1e-9

    def __init__(self, kd: cKDTree, reference: np.ndarray, bound: float, workers: int):
        self.kd, self.bound, self.workers = kd, bound, workers
        # the reference by coordinate, with a row after it for a missing neighbour (the tree's
        # index n) so far away that no test passes on it
        self.ref = np.vstack([reference, np.full((1, 3), 1e150)]).T.copy()
        self.at = None  # (N, 3) where each point was last queried

    def _query(self, x: np.ndarray):
        d, i = self.kd.query(x, k=self.K, distance_upper_bound=self.bound, workers=self.workers)
        limit = np.minimum(d[:, -1], self.bound)
        return i[:, : self.K - 1].T, limit, np.isfinite(d[:, 0]), i[:, 0]

    def update(self, cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(paired (N,) bool, index (N,) of the nearest reference point; the tree's n where
        none lies within the bound)`` of the cloud at ``cur``."""
        if self.at is None:
            self.at = cur.copy()
            self.cand, self.limit, self.paired, self.idx = self._query(cur)
            self.cand = self.cand.copy()
            return self.paired, self.idx
        x, y, z = cur.T.copy()
        rx, ry, rz = self.ref
        cand = self.cand
        # squared distances at ``cur`` of the three candidates at once, (3, N), each the same
        # sum ((x - rx)^2 + (y - ry)^2) + (z - rz)^2 as one candidate at a time
        d2 = (x - rx.take(cand)) ** 2 + (y - ry.take(cand)) ** 2 + (z - rz.take(cand)) ** 2
        d0, d1, d2 = d2
        # the nearest (the first of equals, in candidate order), its index and the next, by
        # exact comparisons: the values of a pass that keeps the nearest so far
        near01 = np.minimum(d0, d1)
        best = np.where(d2 < near01, cand[2], np.where(d1 < d0, cand[1], cand[0]))
        first = np.sqrt(np.minimum(near01, d2))
        second = np.sqrt(np.minimum(np.maximum(d0, d1), np.maximum(near01, d2)))
        # |cur - at| per point, summed (dx^2 + dy^2) + dz^2 as np.sum(..., axis=1) sums a row
        dx, dy, dz = (cur - self.at).T
        moved = np.sqrt(dx**2 + dy**2 + dz**2)
        first += self.MARGIN
        ok = (first < self.limit - moved) & (first < second)
        np.copyto(self.idx, best, where=ok)
        self.paired |= ok
        stale = np.flatnonzero(~ok)
        if stale.size:
            at = cur[stale]
            self.at[stale] = at
            cand, self.limit[stale], self.paired[stale], self.idx[stale] = self._query(at)
            self.cand[:, stale] = cand
        return self.paired, self.idx


def weighted_icp(
    moving,
    reference,
    *,
    z_weight: float = 20.0,
    z_threshold_mm: float = 0.1,
    max_iterations: int = 200,
    max_pair_mm: float = 2.0,
    tol: float = 1e-6,
    stop_below_noise: bool = False,
    tree: cKDTree | None = None,
    workers: int = 1,
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
    stop_below_noise : bool, default False
        Also end a stage once an update is below the noise: smaller than its own standard
        error, ``delta^T H delta < s^2`` (``H`` the normal matrix, ``s^2`` the weighted residual
        variance of the pairs; the covariance of the update is ``s^2 H^-1``).
        The pairs of two differently sampled clouds are not corresponding points, and the
        residual they leave (for 1,000-point sphere caps: tangential offsets of about half the
        point spacing) makes later updates a random walk of that size, not a convergence: such
        updates cannot be told from noise, and iterating them to ``max_iterations`` adds nothing.
        The threshold is the 1-sigma ellipsoid of the 6-parameter update: an update of pure
        noise has ``delta^T H delta / s^2`` distributed as chi-square with 6 degrees of freedom
        (mean 6) and falls below 1 with probability 0.014 only, so a stage ends at the first such
        rare update, tens of updates into the random walk.
    tree : scipy.spatial.cKDTree, optional
        A prebuilt tree of ``reference``.
    workers : int, default 1
        Threads of the nearest-neighbour query (``cKDTree.query(workers=...)``; -1: all cores).
        Keep 1 when trials already run in parallel processes.

    Raises
    ------
    CalibrationError
        On an empty or non-finite cloud, a moving cloud on one line (or pairs on one line), bad
        weights, or clouds that do not overlap (fewer than ``MIN_PAIRS`` points within
        ``max_pair_mm`` of the reference).
    """
    p0 = _check_cloud("moving cloud", moving)
    q = _check_cloud("reference cloud", reference)
    # on one line the turn about that line is undetermined
    geo.check_not_collinear("points of the moving cloud", p0)
    if not (z_weight > 0 and z_threshold_mm > 0 and max_pair_mm > 0 and max_iterations >= 1):
        raise CalibrationError(
            f"z_weight {z_weight}, z_threshold_mm {z_threshold_mm}, max_pair_mm {max_pair_mm} must "
            f"be > 0 and max_iterations {max_iterations} >= 1"
        )
    kd = cKDTree(q) if tree is None else tree
    w = np.array([1.0, 1.0, z_weight])
    # the reference with one row of NaN after it: the index of a point without a pair (the
    # tree's ``n``) then picks NaN, whose z error no threshold keeps
    q_pad = np.vstack([q, np.full((1, 3), np.nan)])
    nearest = _Pairs(kd, q, max_pair_mm, workers)
    total = np.eye(4)
    it, stage, converged, n_pairs, last = 0, 0, False, 0, None
    while it < max_iterations:
        cur = geo.apply(total, p0)
        paired, idx = nearest.update(cur)
        if stage == 1:
            keep = np.abs(cur[:, 2] - q_pad[idx, 2]) <= z_threshold_mm
        else:
            keep = paired
        n_pairs = int(np.count_nonzero(keep))
        if n_pairs < MIN_PAIRS:
            if it == 0:
                closest = float(kd.query(cur, k=1)[0].min())
                raise CalibrationError(
                    f"the clouds do not overlap: {n_pairs} of {len(cur)} points lie within "
                    f"{max_pair_mm:g} mm of the reference (closest {closest:.3g} mm); ICP needs "
                    f"{MIN_PAIRS}"
                )
            raise CalibrationError(
                f"ICP lost its pairs: {n_pairs} pairs left at iteration {it} (need {MIN_PAIRS})"
            )
        it += 1
        rows = np.flatnonzero(keep)
        pairs = (cur.take(rows, axis=0), q.take(idx.take(rows), axis=0))
        # the centroid of the moving points, shared by the step and its convergence test
        centroid = pairs[0].sum(axis=0) / n_pairs
        try:
            step, size = _weighted_rigid_step(*pairs, w, centroid)
        except np.linalg.LinAlgError:
            raise CalibrationError(
                f"the {n_pairs} paired points at iteration {it} lie on one line: the turn "
                "about it is undetermined"
            ) from None
        total = step @ total
        last = (step, pairs)
        if (stop_below_noise and size < NOISE_STEP) or _moves_less_than(
            step, cur, pairs[0], tol, centroid
        ):
            if stage == 0 and np.isfinite(z_threshold_mm):
                stage = 1
                continue
            converged = True
            break
    step, (a, b) = last
    moved = geo.apply(step, a) - b
    rms = float(np.sqrt(np.mean(np.sum(moved**2, axis=1))))
    return IcpResult(total, it, n_pairs, rms, converged)


__all__ = ["IcpResult", "weighted_icp"]
