"""Bundle adjustment of coded markers seen by a binocular sensor (Eq. 9-10 of the ``dualarm``
paper).

All camera poses and marker positions are refined by least squares on the reprojection residuals
of both cameras (Eq. 9) and the Euclidean residuals between each triangulated marker and its
global position (Eq. 10), with a sparse Jacobian. The start comes from
:func:`calstudy.estimators.sfm.reconstruct_markers` (image graph, clusters, splice), which calls
:func:`bundle_adjust` as its last step.

Frames: ``world2cam`` maps world points into the *left* (reference) camera; the right camera sees
``left2right @ p_left``. Pixels in px, lengths in mm; the rig must have ideal cameras.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.stereo_views import View, check_ideal
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig

#: default largest RMS reprojection error (px) a converged bundle adjustment may leave
MAX_RMS_PX = 2.0
#: Marquardt damping (relative to the diagonal of ``J^T J``) of the first step, and the least
#: damping after a rejected step
MU0, MU_REJECTED = 1e-9, 1e-4


@dataclass
class BundleResult:
    """Result of :func:`bundle_adjust`.

    Attributes
    ----------
    world2cam : numpy.ndarray, shape (V, 4, 4)
        Left-camera poses of the views.
    points : numpy.ndarray, shape (M, 3)
        Marker positions in the world frame (NaN for markers no view saw), mm.
    rms_px : float
        RMS reprojection error over both cameras, px.
    rms_mm : float
        RMS Euclidean residual (Eq. 10), mm.
    nfev : int
        Residual evaluations.
    """

    world2cam: np.ndarray
    points: np.ndarray
    rms_px: float
    rms_mm: float
    nfev: int


def _observations(rig: StereoRig, views: list[View]):
    view_idx = np.concatenate([np.full(v.ids.size, j) for j, v in enumerate(views)]).astype(int)
    marker_idx = np.concatenate([v.ids for v in views]).astype(int)
    uv_l = np.concatenate([v.uv_left for v in views])
    uv_r = np.concatenate([v.uv_right for v in views])
    check_ideal(rig.left, rig.right)
    return view_idx, marker_idx, uv_l, uv_r, rig.triangulate(uv_l, uv_r)


def _euclid_sigma(p_cam: np.ndarray, sigma_mm: float, depth_ref_mm: float | None) -> np.ndarray:
    """3-D noise ``(N,)`` mm of markers triangulated at ``p_cam``: ``sigma_mm`` at
    ``depth_ref_mm``, growing with the square of the depth as a stereo depth error
    (``Z^2 sigma_d / (f B)``); constant when ``depth_ref_mm`` is None."""
    if not (sigma_mm > 0 and (depth_ref_mm is None or depth_ref_mm > 0)):
        raise CalibrationError(
            f"sigma_mm ({sigma_mm}) and depth_ref_mm ({depth_ref_mm}) must be > 0"
        )
    if depth_ref_mm is None:
        return np.full(len(p_cam), float(sigma_mm))
    behind = np.flatnonzero(~(p_cam[:, 2] > 0.0))
    if behind.size:
        k = int(behind[0])
        raise CalibrationError(
            f"observation {k} triangulates at depth {p_cam[k, 2]:.3g} mm, not in front of the rig"
        )
    return sigma_mm * (p_cam[:, 2] / depth_ref_mm) ** 2


def _project(camera: PinholeCamera, p: np.ndarray) -> np.ndarray:
    z = p[:, 2:3]
    return np.column_stack(
        [camera.fx * p[:, 0:1] / z + camera.cx, camera.fy * p[:, 1:2] / z + camera.cy]
    )


def _residual_blocks(rig, rot, trans, points, view_idx, marker_idx, uv_l, uv_r, p_cam):
    """Reprojection (left, right; px) and Euclidean (mm) residuals of every observation."""
    r = rot[view_idx]
    pl = np.einsum("nij,nj->ni", r, points[marker_idx]) + trans[view_idx]
    l2r = rig.left2right
    pr = pl @ l2r[:3, :3].T + l2r[:3, 3]
    reproj = np.concatenate([_project(rig.left, pl) - uv_l, _project(rig.right, pr) - uv_r], 1)
    euclid = points[marker_idx] - np.einsum("nji,nj->ni", r, p_cam - trans[view_idx])
    return reproj, euclid


def _projection_derivative(camera: PinholeCamera, p: np.ndarray) -> np.ndarray:
    """``d(u, v)/d(p)`` ``(N, 2, 3)`` of the pinhole projection at camera-frame points ``p``."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    d = np.zeros((len(p), 2, 3))
    d[:, 0, 0], d[:, 0, 2] = camera.fx / z, -camera.fx * x / z**2
    d[:, 1, 1], d[:, 1, 2] = camera.fy / z, -camera.fy * y / z**2
    return d


def _jacobian_blocks(rig, rot, trans, jl, points, view_idx, marker_idx, p_cam) -> np.ndarray:
    """Unweighted derivatives ``(N, 7, 9)`` of each observation's residuals with respect to its
    view's ``[rotvec, t]`` (world2cam) and its marker's position."""
    r, jv, t = rot[view_idx], jl[view_idx], trans[view_idx]
    x = points[marker_idx]
    rx = np.einsum("nij,nj->ni", r, x)
    pl = rx + t
    l2r = rig.left2right
    a = l2r[:3, :3]
    pr = pl @ a.T + l2r[:3, 3]
    d_pl = np.concatenate(
        [_projection_derivative(rig.left, pl), _projection_derivative(rig.right, pr) @ a], axis=1
    )  # (N, 4, 3) derivative of the four pixel residuals by p_left
    out = np.zeros((len(x), 7, 9))
    out[:, :4, :3] = d_pl @ (-geo.skew(rx) @ jv)
    out[:, :4, 3:6] = d_pl
    out[:, :4, 6:] = d_pl @ r
    rt = np.swapaxes(r, -1, -2)
    y = p_cam - t
    out[:, 4:, :3] = -rt @ geo.skew(y) @ jv
    out[:, 4:, 3:6] = rt
    out[:, 4:, 6:] = np.eye(3)
    return out


def _check_start(views: list[View], world2cam, points, fixed_view: int, sigma_px: float):
    """``(poses (V, 4, 4), points (M, 3))`` of the start, after checking shapes, the gauge view
    and the pixel noise."""
    n_v = len(views)
    poses = geo.check_transform("world2cam", world2cam)
    if poses.shape != (n_v, 4, 4):
        raise CalibrationError(f"world2cam has shape {poses.shape}; expected ({n_v}, 4, 4)")
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise CalibrationError(f"points has shape {pts.shape}; expected (M, 3)")
    if not (0 <= fixed_view < n_v):
        raise CalibrationError(f"fixed_view {fixed_view} is not one of the {n_v} views")
    if not sigma_px > 0:
        raise CalibrationError(f"sigma_px ({sigma_px}) must be > 0")
    return poses, pts


def _check_in_front(rig: StereoRig, poses: np.ndarray, pts: np.ndarray, obs) -> None:
    """Raise unless the start of every observed marker lies in front of both cameras of each
    view that sees it (else its projection divides by a depth of zero or flips)."""
    view_idx, marker_idx = obs[0], obs[1]
    p_left = (
        np.einsum("nij,nj->ni", poses[view_idx, :3, :3], pts[marker_idx])
        + poses[view_idx, :3, 3]
    )
    depth = np.minimum(p_left[:, 2], geo.apply(rig.left2right, p_left)[:, 2])
    bad = np.flatnonzero(~(depth > 0.0))
    if bad.size:
        k = int(bad[0])
        raise CalibrationError(
            f"the start of marker {int(marker_idx[k])} lies at depth {depth[k]:.3g} mm in view "
            f"{int(view_idx[k])}: every start point must lie in front of both cameras"
        )


def _observed_markers(marker_idx: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """The sorted ids of the observed markers, after checking that each has a finite start."""
    used = np.unique(marker_idx)
    if used.max() >= pts.shape[0]:
        raise CalibrationError(f"marker id {used.max()} has no row in points ({pts.shape[0]})")
    geo.check_finite("points of observed markers", pts[used])
    return used


@dataclass(frozen=True)
class _Layout:
    """The parameter vector: ``[rotvec, t]`` (world2cam) of every view but the fixed one, then
    the position of every observed marker; the fixed view keeps its start pose."""

    rv0: np.ndarray  # (V, 3) rotation vectors of the start poses
    t0: np.ndarray  # (V, 3) translations of the start poses
    free: list[int]  # the views whose poses are adjusted, in parameter order
    used: np.ndarray  # the observed marker ids, in parameter order
    n_markers: int
    x0: np.ndarray

    @classmethod
    def of(cls, poses: np.ndarray, pts: np.ndarray, fixed_view: int, used: np.ndarray):
        free = [j for j in range(len(poses)) if j != fixed_view]
        rv0 = geo.matrix_to_rotvec(poses[:, :3, :3])
        x0 = np.concatenate(
            [np.concatenate([rv0[free], poses[free, :3, 3]], axis=1).ravel(), pts[used].ravel()]
        )
        return cls(rv0, poses[:, :3, 3], free, used, pts.shape[0], x0)

    def unpack(self, x: np.ndarray):
        """``(rotvecs (V, 3), rotations (V, 3, 3), translations (V, 3), points (M, 3))`` of
        ``x``; NaN for markers no view saw."""
        rv, tr = self.rv0.copy(), self.t0.copy()
        block = x[: 6 * len(self.free)].reshape(-1, 6)
        rv[self.free], tr[self.free] = block[:, :3], block[:, 3:]
        p = np.full((self.n_markers, 3), np.nan)
        p[self.used] = x[6 * len(self.free) :].reshape(-1, 3)
        return rv, geo.rotvec_to_matrix(rv), tr, p


def _sparsity(layout: _Layout, view_idx: np.ndarray, marker_idx: np.ndarray):
    """``(rows, cols, keep)`` of the Jacobian's nonzeros: each observation's 7 residuals
    depend on its view's 6 parameters (unless the view is fixed) and its marker's 3;
    ``keep (N, 7, 9)`` selects them from the dense blocks of :func:`_jacobian_blocks`."""
    col_of_view = {j: 6 * k for k, j in enumerate(layout.free)}
    col_of_marker = {int(m): 6 * len(layout.free) + 3 * k for k, m in enumerate(layout.used)}
    n_obs = view_idx.size
    vcol = np.array([col_of_view.get(int(v), -1) for v in view_idx])
    mcol = np.array([col_of_marker[int(m)] for m in marker_idx])
    cols = np.concatenate([vcol[:, None] + np.arange(6), mcol[:, None] + np.arange(3)], axis=1)
    rows_i = np.broadcast_to(np.arange(7 * n_obs).reshape(n_obs, 7, 1), (n_obs, 7, 9))
    cols_i = np.broadcast_to(cols[:, None, :], (n_obs, 7, 9))
    free_col = np.where(np.arange(9)[None, :] < 6, vcol[:, None] >= 0, True)  # (n_obs, 9)
    keep = np.broadcast_to(free_col[:, None, :], (n_obs, 7, 9))
    return rows_i[keep], cols_i[keep], keep


def _objective(rig: StereoRig, obs, layout: _Layout, sigma_px: float, sigma_obs: np.ndarray):
    """``(fun, jac, (rows, cols, shape))``: the weighted residuals of Eq. 9-10, their analytic
    sparse Jacobian and its pattern, for the observations ``obs`` of :func:`_observations`."""
    view_idx, marker_idx, uv_l, uv_r, p_cam = obs
    rows_k, cols_k, keep = _sparsity(layout, view_idx, marker_idx)
    n_obs = view_idx.size
    weights = np.concatenate([np.full((n_obs, 4), 1 / sigma_px), np.repeat(1 / sigma_obs, 3, 1)], 1)
    shape = (7 * n_obs, layout.x0.size)

    def fun(x):
        _, rot, tr, p = layout.unpack(x)
        reproj, euclid = _residual_blocks(rig, rot, tr, p, view_idx, marker_idx, uv_l, uv_r, p_cam)
        return np.concatenate([reproj / sigma_px, euclid / sigma_obs], axis=1).ravel()

    def jac(x):
        rv, rot, tr, p = layout.unpack(x)
        jac_l = geo.so3_left_jacobian(rv)
        vals = _jacobian_blocks(rig, rot, tr, jac_l, p, view_idx, marker_idx, p_cam)
        vals *= weights[:, :, None]
        return csr_matrix((vals[keep], (rows_k, cols_k)), shape=shape)

    return fun, jac, (rows_k, cols_k, shape)


@dataclass
class _Solution:
    """What :func:`_result` reads of a finished solve (as of ``scipy.optimize.OptimizeResult``):
    ``status`` > 0 converged (1 gradient, 2 cost, 3 step, 4 cost and step), 0 budget spent."""

    x: np.ndarray
    status: int
    nfev: int
    message: str


def _normal_lm(fun, jac, x0: np.ndarray, max_nfev: int, tol: float = 1e-10) -> _Solution:
    """Levenberg-Marquardt on the normal equations of the sparse Jacobian.

    Each step solves ``(J^T J + mu diag(J^T J)) dx = -J^T f`` by Cholesky: Marquardt's damping
    scaled by the columns' norms (the scaling of ``least_squares(x_scale="jac")``), ``mu``
    starting at :data:`MU0` (a Gauss-Newton step: a survey's ``J`` has a condition number near
    1e6, and a damping of 1e-3 held its weakest directions back for a dozen steps) and updated by
    the gain ratio of actual to predicted reduction (Nielsen's rule: shrunk after a good step,
    raised to at least :data:`MU_REJECTED` and then doubled, doubled again, after each rejected
    one). ``J^T J`` has the size of the parameters (6 per view, 3 per marker), far
    smaller than ``J``: one step costs a small dense Cholesky factorisation, where the trust
    region of ``least_squares`` takes a singular value decomposition of the whole ``J``. It
    stops as ``least_squares`` with ``xtol = ftol = gtol = tol``: a step shorter than ``tol (tol
    + |x|)``, a cost reduction below ``tol`` of the cost in a step that the model predicted well
    (gain ratio > 0.25), or a gradient whose largest cosine with a column of ``J`` is below
    ``tol``.
    """
    x = np.array(x0, dtype=float)
    f = fun(x)
    nfev, cost = 1, 0.5 * float(f @ f)
    mu, nu = MU0, 2.0
    while True:
        j = jac(x)
        a = (j.T @ j).toarray()
        g = j.T @ f
        d = np.diag(a).copy()
        d = np.maximum(d, 1e-30 * max(float(d.max()), 1e-300))
        if float(np.max(np.abs(g) / np.sqrt(d))) <= tol * np.sqrt(2.0 * cost):
            return _Solution(x, 1, nfev, "the gradient is orthogonal to the Jacobian's columns")
        while True:
            if nfev >= max_nfev:
                return _Solution(x, 0, nfev, f"the budget of {max_nfev} evaluations is spent")
            try:
                dx = -cho_solve(cho_factor(a + np.diag(mu * d)), g)
            except np.linalg.LinAlgError:
                mu, nu = max(mu * nu, MU_REJECTED), 2.0 * nu
                continue
            except ValueError:  # cho_factor refuses NaN or inf: more damping cannot help
                raise CalibrationError(
                    f"the normal equations hold NaN or inf after {nfev} evaluations: the start "
                    "is too far from a solution (a marker next to a camera?)"
                ) from None
            f_new = fun(x + dx)
            nfev += 1
            cost_new = 0.5 * float(f_new @ f_new)
            predicted = -float(g @ dx + 0.5 * dx @ (a @ dx))
            actual = cost - cost_new
            ratio = actual / predicted if predicted > 0 and np.isfinite(cost_new) else -1.0
            small_x = float(np.linalg.norm(dx)) <= tol * (tol + float(np.linalg.norm(x)))
            small_f = ratio > 0.25 and actual < tol * cost
            if ratio > 0:
                x, f, cost = x + dx, f_new, cost_new
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
                nu = 2.0
            else:
                mu, nu = max(mu * nu, MU_REJECTED), 2.0 * nu
            if small_f or small_x:
                status = 2 * small_f + 3 * small_x - (small_f and small_x)
                return _Solution(x, int(status), nfev, "the cost or the step is below tol")
            if ratio > 0:
                break


def _solve(fun, jac, x0: np.ndarray, pattern, jacobian: str, max_nfev: int):
    """The least-squares solve from ``x0``: with the analytic Jacobian by
    :func:`_normal_lm` (``"analytic"``) or by ``scipy.optimize.least_squares`` solving it densely
    (``"analytic-dense"``, a singular value decomposition of ``J`` per step), or by
    ``least_squares`` with finite differences on its sparsity ``pattern`` ``(rows, cols, shape)``
    (``"sparse-fd"``, LSMR trust-region solver). All stop at ``xtol = ftol = gtol = 1e-10``."""
    tols = {"xtol": 1e-10, "ftol": 1e-10, "gtol": 1e-10, "max_nfev": max_nfev}
    if jacobian == "analytic":
        return _normal_lm(fun, jac, x0, max_nfev)
    if jacobian == "analytic-dense":
        return least_squares(
            fun, x0, jac=lambda x: jac(x).toarray(), method="trf", x_scale="jac", **tols
        )
    if jacobian == "sparse-fd":
        rows_k, cols_k, shape = pattern
        sparsity = csr_matrix((np.ones(rows_k.size), (rows_k, cols_k)), shape=shape)
        return least_squares(
            fun,
            x0,
            jac_sparsity=sparsity,
            method="trf",
            x_scale="jac",
            tr_solver="lsmr",
            tr_options={"atol": 1e-14, "btol": 1e-14},
            **tols,
        )
    raise CalibrationError(
        f"jacobian is {jacobian!r}; expected 'analytic', 'analytic-dense' or 'sparse-fd'"
    )


def _result(rig: StereoRig, obs, layout: _Layout, res, max_rms_px: float) -> BundleResult:
    """The :class:`BundleResult` of a finished solve, or the error if it diverged."""
    view_idx, marker_idx, uv_l, uv_r, p_cam = obs
    _, rot, tr, p = layout.unpack(res.x)
    reproj, euclid = _residual_blocks(rig, rot, tr, p, view_idx, marker_idx, uv_l, uv_r, p_cam)
    rms_px = float(np.sqrt(np.mean(reproj**2) * 2.0))
    rms_mm = float(np.sqrt(np.mean(np.sum(euclid**2, axis=1))))
    if res.status <= 0 or not np.isfinite(rms_px) or rms_px > max_rms_px:
        raise CalibrationError(
            f"the bundle adjustment diverged: RMS reprojection error {rms_px:.3g} px (limit "
            f"{max_rms_px:g} px) after {res.nfev} evaluations ({res.message})"
        )
    return BundleResult(geo.make_transform(rot, tr), p, rms_px, rms_mm, int(res.nfev))


def bundle_adjust(
    rig: StereoRig,
    views: list[View],
    world2cam,
    points,
    *,
    fixed_view: int,
    sigma_px: float,
    sigma_mm: float,
    max_nfev: int = 200,
    max_rms_px: float = MAX_RMS_PX,
    jacobian: str = "analytic",
    depth_ref_mm: float | None = None,
) -> BundleResult:
    """Refine all camera poses and marker positions on Eq. 9-10 with a sparse Jacobian.

    The residual of an observation (marker ``m`` in view ``v``) is its reprojection error in both
    cameras divided by ``sigma_px`` (Eq. 9; the paper divides by ``f``, a fixed rescaling) and the
    difference between the world marker and its triangulated position mapped to the world
    (Eq. 10) divided by the 3-D noise of that triangulation: ``sigma_mm``, or with
    ``depth_ref_mm`` ``sigma_mm (Z / depth_ref_mm)^2`` at the marker's depth ``Z`` in the view,
    since a stereo depth error grows with the square of the depth. ``fixed_view``'s pose is
    held; the scale comes from the stereo baseline. Levenberg-Marquardt minimises the sum of
    squares. Each observation touches only its view's 6 and its marker's 3 parameters: the
    Jacobian is sparse, assembled analytically as a ``scipy.sparse`` matrix and solved through
    its normal equations (``jacobian="analytic"``, :func:`_normal_lm`), or, reaching the same
    minimum more slowly, handed to ``scipy.optimize.least_squares`` (trust region reflective)
    as a dense matrix (``jacobian="analytic-dense"``) or estimated there by finite differences
    grouped by that pattern (``jacobian="sparse-fd"``, ``jac_sparsity``, LSMR solver).

    Parameters
    ----------
    rig : StereoRig
    views : list of View
    world2cam : array_like, shape (V, 4, 4)
        Initial left-camera poses.
    points : array_like, shape (M, 3)
        Initial marker positions; rows of markers nobody saw may be NaN.
    fixed_view : int
        The view whose pose is held (the gauge).
    sigma_px, sigma_mm : float
        Detection noise (px) and 3-D noise of a triangulated marker (mm), both > 0.
    max_nfev, max_rms_px : int, float
        Evaluation budget; largest RMS reprojection error (px) of a converged adjustment.
    jacobian : {"analytic", "analytic-dense", "sparse-fd"}
    depth_ref_mm : float or None
        Depth (mm) of the noise ``sigma_mm``; None: the same noise at every depth.

    Raises
    ------
    CalibrationError
        On bad shapes, non-finite starts, a start point behind a camera, or if the adjustment
        diverges: the budget runs out or the RMS reprojection error stays above ``max_rms_px``.
    """
    poses, pts = _check_start(views, world2cam, points, fixed_view, sigma_px)
    obs = _observations(rig, views)
    sigma_obs = _euclid_sigma(obs[4], sigma_mm, depth_ref_mm)[:, None]
    layout = _Layout.of(poses, pts, fixed_view, _observed_markers(obs[1], pts))
    _check_in_front(rig, poses, pts, obs)
    fun, jac, pattern = _objective(rig, obs, layout, sigma_px, sigma_obs)
    res = _solve(fun, jac, layout.x0, pattern, jacobian, max_nfev)
    return _result(rig, obs, layout, res, max_rms_px)


def refine_camera_pose(
    rig: StereoRig,
    view: View,
    points,
    world2cam,
    *,
    sigma_px: float,
    sigma_mm: float,
    depth_ref_mm: float | None = None,
) -> np.ndarray:
    """One view's ``world2cam`` refined on Eq. 9-10 with the marker positions held fixed (the
    weights as in :func:`bundle_adjust`), by Levenberg-Marquardt (MINPACK) with the analytic
    Jacobian of :func:`bundle_adjust` (the pose columns of each observation's block)."""
    pts = geo.check_shape("points", points, (None, 3))
    init = geo.check_transform("world2cam", world2cam)
    view_idx, marker_idx, uv_l, uv_r, p_cam = _observations(rig, [view])
    if view.ids.size < 4:
        raise CalibrationError(f"PnP needs at least 4 markers; the view has {view.ids.size}")
    if marker_idx.max() >= pts.shape[0]:
        raise CalibrationError(
            f"marker id {marker_idx.max()} has no row in points ({pts.shape[0]})"
        )
    _check_in_front(rig, init[None], pts, (view_idx, marker_idx))
    sigma_obs = _euclid_sigma(p_cam, sigma_mm, depth_ref_mm)[:, None]

    def fun(x):
        rot = geo.rotvec_to_matrix(x[None, :3])
        reproj, euclid = _residual_blocks(
            rig, rot, x[None, 3:], pts, view_idx, marker_idx, uv_l, uv_r, p_cam
        )
        return np.concatenate([reproj.ravel() / sigma_px, (euclid / sigma_obs).ravel()])

    def jac(x):
        rv = x[None, :3]
        blocks = _jacobian_blocks(
            rig,
            geo.rotvec_to_matrix(rv),
            x[None, 3:],
            geo.so3_left_jacobian(rv),
            pts,
            view_idx,
            marker_idx,
            p_cam,
        )[:, :, :6]
        reproj = (blocks[:, :4] / sigma_px).reshape(-1, 6)
        return np.concatenate([reproj, (blocks[:, 4:] / sigma_obs[:, :, None]).reshape(-1, 6)])

    x0 = np.concatenate([geo.matrix_to_rotvec(init[:3, :3]), init[:3, 3]])
    res = least_squares(
        fun, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=400
    )
    if res.status <= 0:
        raise CalibrationError(f"camera pose refinement did not converge ({res.message})")
    return geo.make_transform(geo.rotvec_to_matrix(res.x[:3]), res.x[3:])


__all__ = ["MAX_RMS_PX", "BundleResult", "bundle_adjust", "refine_camera_pose"]
