"""Coded markers seen by a binocular sensor: triangulation, image graph, clustering, bundle
adjustment.

The structure-from-motion part of the ``dualarm`` paper (SFM-BSV, Section 3): a binocular sensor
images coded markers (ids known) from many unordered poses; the markers' 3-D coordinates in one
global frame follow from

1. the image graph (Eq. 5): the weight of an edge is the number of markers two images share;
2. the clustering of Eq. 6: the fewest *centre* images such that every image shares at least
   ``alpha`` markers with a centre (greedy minimum dominating set), each image joining the centre
   it shares most with;
3. in each cluster, the markers triangulated in the centre image's frame (Eq. 7) and the other
   images located by PnP (checked against a rigid fit of their own triangulated markers);
4. the incremental splice (Eq. 8): clusters joined to the growing reconstruction by a rigid fit
   on their common markers, the best-connected pair first;
5. a bundle adjustment (Eq. 9-10): all camera poses and marker positions refined by
   Levenberg-Marquardt on the reprojection residuals of both cameras and the Euclidean residuals
   between the triangulated and the global marker positions, with a sparse Jacobian.

Frames: ``world2cam`` maps world points into the *left* (reference) camera; the right camera sees
``left2right @ p_left``. Pixels in px, lengths in mm. The rig
(:class:`calstudy.models.stereo.StereoRig`) must have ideal cameras: these steps model no lens
distortion, and refuse a rig whose cameras have one (undistort the image points first).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.fitting import fit_rigid
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig

#: default largest RMS reprojection error (px) a converged bundle adjustment may leave
MAX_RMS_PX = 2.0


@dataclass(frozen=True)
class View:
    """The markers detected in one stereo image pair.

    Attributes
    ----------
    ids : numpy.ndarray of int, shape (N,)
        Marker indices, sorted, unique.
    uv_left, uv_right : numpy.ndarray, shape (N, 2)
        Detected centres in the left and right images, px.
    """

    ids: np.ndarray
    uv_left: np.ndarray
    uv_right: np.ndarray


def make_view(ids, uv_left, uv_right) -> View:
    """A :class:`View` after checking shapes, finiteness and unique ids (sorted by id)."""
    i = np.asarray(ids)
    if i.ndim != 1 or (i.size and not np.issubdtype(i.dtype, np.integer)):
        raise CalibrationError(f"marker ids must be a 1-D integer array; got {i.dtype} {i.shape}")
    ul = geo.check_shape("uv_left", uv_left, (i.size, 2))
    ur = geo.check_shape("uv_right", uv_right, (i.size, 2))
    if np.unique(i).size != i.size:
        raise CalibrationError(f"marker ids repeat within one view: {i.tolist()}")
    order = np.argsort(i)
    return View(i[order].astype(int), ul[order], ur[order])


# ----------------------------------------------------------------------------------------------
# triangulation (Eq. 7)


def _check_ideal(*cameras: PinholeCamera) -> None:
    """Raise if a camera has lens distortion, which these steps do not model."""
    for camera in cameras:
        if camera.distorted:
            raise CalibrationError(
                f"the camera has lens distortion {camera.dist}; structure from motion here "
                "models ideal pinhole cameras: undistort the image points first"
            )


def _projection_matrix(camera: PinholeCamera, world2cam: np.ndarray) -> np.ndarray:
    _check_ideal(camera)
    return camera.K @ world2cam[:3, :]


def triangulate(rig: StereoRig, uv_left, uv_right) -> np.ndarray:
    """Points ``(N, 3)`` in the left camera frame from matched centres (Eq. 7, linear).

    Each point solves the four linear equations ``(u m_3 - m_1) X = 0``, ``(v m_3 - m_2) X = 0``
    of both cameras' projection matrices ``M`` in the least-squares sense.
    """
    ul = geo.check_shape("uv_left", uv_left, (None, 2))
    ur = geo.check_shape("uv_right", uv_right, (ul.shape[0], 2))
    rows = []
    for m, uv in (
        (_projection_matrix(rig.left, np.eye(4)), ul),
        (_projection_matrix(rig.right, rig.left2right), ur),
    ):
        rows.append(uv[:, 0:1, None] * m[None, 2:3, :] - m[None, 0:1, :])
        rows.append(uv[:, 1:2, None] * m[None, 2:3, :] - m[None, 1:2, :])
    a = np.concatenate(rows, axis=1)  # (N, 4, 4)
    lhs, rhs = a[:, :, :3], -a[:, :, 3]
    ata = np.einsum("nki,nkj->nij", lhs, lhs)
    atb = np.einsum("nki,nk->ni", lhs, rhs)
    cond = np.linalg.cond(ata) if len(ata) else np.zeros(0)
    if np.any(cond > 1e14):
        i = int(np.argmax(cond))
        raise CalibrationError(f"point {i} cannot be triangulated (condition number {cond[i]:.3g})")
    return np.linalg.solve(ata, atb[..., None])[..., 0]


# ----------------------------------------------------------------------------------------------
# image graph and clustering (Eq. 5-6)


def image_graph(views: list[View]) -> np.ndarray:
    """Edge weights of Eq. 5: ``w[i, j]`` = markers images ``i`` and ``j`` share; ``(n, n)`` int,
    zero diagonal."""
    if not views:
        raise CalibrationError("the image graph needs at least one view; got 0")
    n_markers = 1 + max((int(v.ids.max()) for v in views if v.ids.size), default=0)
    seen = np.zeros((len(views), n_markers), dtype=int)
    for i, v in enumerate(views):
        seen[i, v.ids] = 1
    w = seen @ seen.T
    np.fill_diagonal(w, 0)
    return w


def cluster_images(weights, alpha: int) -> list[tuple[int, list[int]]]:
    """Clusters of Eq. 6: the fewest centre images whose neighbourhoods cover every image.

    Image ``j`` is a neighbour of ``i`` when they share at least ``alpha`` markers. Centres are
    chosen greedily (the image covering most uncovered images, lowest index on ties), the usual
    approximation of the minimum dominating set; each image then joins the centre it shares most
    markers with.

    Returns
    -------
    list of (centre, members)
        ``members`` includes the centre, sorted.
    """
    w = np.asarray(weights)
    if w.ndim != 2 or w.shape[0] != w.shape[1]:
        raise CalibrationError(f"weights must be a square matrix; got shape {w.shape}")
    if alpha < 1:
        raise CalibrationError(f"alpha must be >= 1 shared marker; got {alpha}")
    n = w.shape[0]
    adj = (w >= alpha) | np.eye(n, dtype=bool)
    uncovered = np.ones(n, dtype=bool)
    centres: list[int] = []
    while uncovered.any():
        gain = (adj & uncovered[None, :]).sum(axis=1)
        best = int(np.argmax(gain))
        centres.append(best)
        uncovered &= ~adj[best]
    members: dict[int, list[int]] = {c: [] for c in centres}
    for j in range(n):
        if j in members:
            members[j].append(j)
            continue
        candidates = [c for c in centres if adj[c, j]]
        best = max(candidates, key=lambda c: (w[c, j], -c))
        members[best].append(j)
    return [(c, sorted(members[c])) for c in centres]


# ----------------------------------------------------------------------------------------------
# PnP


def pnp_pose(object_points, image_uv, camera: PinholeCamera) -> np.ndarray:
    """``target2cam`` of at least 4 known points by ``cv2.solvePnP`` (SQPnP, then LM refinement).

    Raises
    ------
    CalibrationError
        With fewer than 4 points, on bad shapes or if OpenCV finds no pose.
    """
    obj = geo.check_shape("object_points", object_points, (None, 3))
    uv = geo.check_shape("image_uv", image_uv, (obj.shape[0], 2))
    if obj.shape[0] < 4:
        raise CalibrationError(f"PnP needs at least 4 markers; got {obj.shape[0]}")
    _check_ideal(camera)
    k = camera.K
    ok, rvec, tvec = cv2.solvePnP(obj, uv, k, None, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        raise CalibrationError(f"cv2.solvePnP found no pose for the {obj.shape[0]} markers")
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-16)
    rvec, tvec = cv2.solvePnPRefineLM(obj, uv, k, None, rvec, tvec, criteria=criteria)
    return geo.make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())


# ----------------------------------------------------------------------------------------------
# clusters and the incremental splice (Eq. 8)


@dataclass
class Cluster:
    """A cluster reconstructed in its centre image's left camera frame.

    Attributes
    ----------
    centre : int
        Index of the centre image.
    world2cam : dict
        ``view index -> (4, 4)`` transform from the cluster frame to that view's left camera.
    points : dict
        ``marker id -> (3,)`` position in the cluster frame, mm.
    """

    centre: int
    world2cam: dict = field(default_factory=dict)
    points: dict = field(default_factory=dict)


def _initial_pose(rig: StereoRig, obj: np.ndarray, uv_left, uv_right) -> np.ndarray:
    """``world2cam`` of a view from its markers' cluster positions ``obj``: PnP, or the rigid fit
    of the view's own triangulated markers onto ``obj`` if that reprojects better in both images.

    PnP sees the left image only: on a small group of markers whose cluster positions were
    triangulated from a distant image, its pose can start the bundle adjustment in a false
    minimum (a survey in the tests stopped at 4.9 px). The view's own stereo triangulation gives
    a second start.
    """
    candidates = [
        pnp_pose(obj, uv_left, rig.left),
        fit_rigid(obj, triangulate(rig, uv_left, uv_right)),
    ]

    def cost(w2c):
        ul, ur = rig.project(geo.apply(w2c, obj))
        return np.sum((ul - uv_left) ** 2) + np.sum((ur - uv_right) ** 2)

    return min(candidates, key=cost)


def reconstruct_cluster(rig: StereoRig, views: list[View], centre: int, members) -> Cluster:
    """Markers of the centre image triangulated in its frame; the other members located by PnP
    (or the rigid fit of their triangulated markers, whichever reprojects better)."""
    c = views[centre]
    cluster = Cluster(centre, {centre: np.eye(4)})
    for i, p in zip(c.ids, triangulate(rig, c.uv_left, c.uv_right), strict=True):
        cluster.points[int(i)] = p
    for j in members:
        if j == centre:
            continue
        v = views[j]
        common = [k for k, i in enumerate(v.ids) if int(i) in cluster.points]
        if len(common) < 4:
            raise CalibrationError(
                f"PnP needs at least 4 markers; image {j} shares {len(common)} with centre image "
                f"{centre}"
            )
        obj = np.array([cluster.points[int(v.ids[k])] for k in common])
        cluster.world2cam[j] = _initial_pose(rig, obj, v.uv_left[common], v.uv_right[common])
    extra: dict[int, list[np.ndarray]] = {}
    for j in members:
        v = views[j]
        new = [k for k, i in enumerate(v.ids) if int(i) not in cluster.points]
        if new:
            local = triangulate(rig, v.uv_left[new], v.uv_right[new])
            cam2w = geo.invert(cluster.world2cam[j])
            for k, p in zip(new, geo.apply(cam2w, local), strict=True):
                extra.setdefault(int(v.ids[k]), []).append(p)
    for i, ps in extra.items():
        cluster.points[i] = np.mean(ps, axis=0)
    return cluster


def _cluster_names(clusters: list[Cluster], which) -> str:
    return ", ".join(f"cluster {k} (centre image {clusters[k].centre})" for k in which)


def splice_clusters(clusters: list[Cluster]) -> tuple[dict, dict]:
    """Join clusters into one frame (Eq. 8), the best-connected pair first, then the cluster that
    shares most markers with the joined ones, each by a rigid fit on >= 3 common markers.

    Returns
    -------
    world2cam : dict
        ``view -> (4, 4)`` in the frame of the first cluster's centre image.
    points : dict
        ``marker id -> (3,)`` world positions (the mean where clusters overlap).

    Raises
    ------
    CalibrationError
        If some clusters share fewer than 3 markers with the rest (the marker graph is not
        connected); the message names the clusters that cannot be joined.
    """
    if not clusters:
        raise CalibrationError("no clusters to splice (0 clusters)")
    n = len(clusters)
    shared = np.zeros((n, n), dtype=int)
    for a in range(n):
        for b in range(a + 1, n):
            shared[a, b] = shared[b, a] = len(set(clusters[a].points) & set(clusters[b].points))
    start = [0] if n == 1 else list(np.unravel_index(int(np.argmax(shared)), shared.shape))
    first = int(min(start))
    joined = [first]
    world2cam = dict(clusters[first].world2cam)
    gathered: dict[int, list[np.ndarray]] = {i: [p] for i, p in clusters[first].points.items()}
    while len(joined) < n:
        rest = [k for k in range(n) if k not in joined]
        counts = [len(set(clusters[k].points) & set(gathered)) for k in rest]
        k = rest[int(np.argmax(counts))]
        if max(counts) < 3:
            raise CalibrationError(
                f"the marker graph is not connected: {_cluster_names(clusters, rest)} share at "
                f"most {max(counts)} markers with {_cluster_names(clusters, joined)}; a rigid "
                "splice needs 3. Add images that see markers of both parts"
            )
        common = sorted(set(clusters[k].points) & set(gathered))
        src = np.array([clusters[k].points[i] for i in common])
        dst = np.array([np.mean(gathered[i], axis=0) for i in common])
        c2w = fit_rigid(src, dst)  # cluster frame -> world
        w2c = geo.invert(c2w)
        for j, t in clusters[k].world2cam.items():
            world2cam[j] = t @ w2c
        for i, p in clusters[k].points.items():
            gathered.setdefault(i, []).append(geo.apply(c2w, p))
        joined.append(k)
    points = {i: np.mean(ps, axis=0) for i, ps in gathered.items()}
    return world2cam, points


# ----------------------------------------------------------------------------------------------
# bundle adjustment (Eq. 9-10)


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
    return view_idx, marker_idx, uv_l, uv_r, triangulate(rig, uv_l, uv_r)


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
    held (the gauge); the scale comes from the stereo baseline.
    ``scipy.optimize.least_squares`` (trust region reflective, a Levenberg-Marquardt-type
    method) minimises the sum of squares. Each observation touches only its view's 6 and its
    marker's 3 parameters: the Jacobian is sparse, assembled analytically
    as a ``scipy.sparse`` matrix (``jacobian="analytic"``, solved densely: the problem is small),
    or estimated by finite differences grouped by that pattern (``jacobian="sparse-fd"``,
    ``jac_sparsity`` with the LSMR trust-region solver; slower, the same minimum).

    Parameters
    ----------
    rig : StereoRig
    views : list of View
    world2cam : array_like, shape (V, 4, 4)
        Initial left-camera poses.
    points : array_like, shape (M, 3)
        Initial marker positions; rows of markers nobody saw may be NaN.
    fixed_view : int
    sigma_px, sigma_mm : float
        Detection noise (px) and 3-D noise of a triangulated marker (mm), both > 0.
    max_nfev : int
        Evaluation budget.
    max_rms_px : float
        Largest RMS reprojection error of a converged adjustment.
    jacobian : {"analytic", "sparse-fd"}
        How the sparse Jacobian is obtained (see above).
    depth_ref_mm : float or None
        Depth (mm) at which a triangulated marker has the noise ``sigma_mm``; None: the same
        noise at every depth.

    Raises
    ------
    CalibrationError
        On bad shapes, non-finite starts, or if the adjustment diverges: the budget runs out or the
        RMS reprojection error stays above ``max_rms_px``.
    """
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
    view_idx, marker_idx, uv_l, uv_r, p_cam = _observations(rig, views)
    sigma_obs = _euclid_sigma(p_cam, sigma_mm, depth_ref_mm)[:, None]
    used = np.unique(marker_idx)
    if used.max() >= pts.shape[0]:
        raise CalibrationError(f"marker id {used.max()} has no row in points ({pts.shape[0]})")
    geo.check_finite("points of observed markers", pts[used])
    free = [j for j in range(n_v) if j != fixed_view]
    col_of_view = {j: 6 * k for k, j in enumerate(free)}
    col_of_marker = {int(m): 6 * len(free) + 3 * k for k, m in enumerate(used)}
    rv0 = geo.matrix_to_rotvec(poses[:, :3, :3])
    x0 = np.concatenate(
        [np.concatenate([rv0[free], poses[free, :3, 3]], axis=1).ravel(), pts[used].ravel()]
    )

    def unpack(x):
        rv, tr = rv0.copy(), poses[:, :3, 3].copy()
        block = x[: 6 * len(free)].reshape(-1, 6)
        rv[free], tr[free] = block[:, :3], block[:, 3:]
        p = np.full_like(pts, np.nan)
        p[used] = x[6 * len(free) :].reshape(-1, 3)
        return Rotation.from_rotvec(rv).as_matrix(), tr, p

    def fun(x):
        rot, tr, p = unpack(x)
        reproj, euclid = _residual_blocks(rig, rot, tr, p, view_idx, marker_idx, uv_l, uv_r, p_cam)
        return np.concatenate([reproj / sigma_px, euclid / sigma_obs], axis=1).ravel()

    n_obs = view_idx.size
    vcol = np.array([col_of_view.get(int(v), -1) for v in view_idx])
    mcol = np.array([col_of_marker[int(m)] for m in marker_idx])
    cols = np.concatenate([vcol[:, None] + np.arange(6), mcol[:, None] + np.arange(3)], axis=1)
    rows_i = np.broadcast_to(np.arange(7 * n_obs).reshape(n_obs, 7, 1), (n_obs, 7, 9))
    cols_i = np.broadcast_to(cols[:, None, :], (n_obs, 7, 9))
    free_col = np.where(np.arange(9)[None, :] < 6, vcol[:, None] >= 0, True)  # (n_obs, 9)
    keep = np.broadcast_to(free_col[:, None, :], (n_obs, 7, 9))
    rows_k, cols_k = rows_i[keep], cols_i[keep]
    weights = np.concatenate([np.full((n_obs, 4), 1 / sigma_px), np.repeat(1 / sigma_obs, 3, 1)], 1)

    def jac(x):
        rv, tr = rv0.copy(), poses[:, :3, 3].copy()
        block = x[: 6 * len(free)].reshape(-1, 6)
        rv[free], tr[free] = block[:, :3], block[:, 3:]
        rot = Rotation.from_rotvec(rv).as_matrix()
        p = np.full_like(pts, np.nan)
        p[used] = x[6 * len(free) :].reshape(-1, 3)
        jac_l = geo.so3_left_jacobian(rv)
        vals = _jacobian_blocks(rig, rot, tr, jac_l, p, view_idx, marker_idx, p_cam)
        vals *= weights[:, :, None]
        return csr_matrix((vals[keep], (rows_k, cols_k)), shape=(7 * n_obs, x0.size))

    tols = {"xtol": 1e-10, "ftol": 1e-10, "gtol": 1e-10, "max_nfev": max_nfev}
    if jacobian == "analytic":
        res = least_squares(
            fun, x0, jac=lambda x: jac(x).toarray(), method="trf", x_scale="jac", **tols
        )
    elif jacobian == "sparse-fd":
        sparsity = csr_matrix((np.ones(rows_k.size), (rows_k, cols_k)), shape=(7 * n_obs, x0.size))
        res = least_squares(
            fun,
            x0,
            jac_sparsity=sparsity,
            method="trf",
            x_scale="jac",
            tr_solver="lsmr",
            tr_options={"atol": 1e-14, "btol": 1e-14},
            **tols,
        )
    else:
        raise CalibrationError(f"jacobian is {jacobian!r}; expected 'analytic' or 'sparse-fd'")
    rot, tr, p = unpack(res.x)
    reproj, euclid = _residual_blocks(rig, rot, tr, p, view_idx, marker_idx, uv_l, uv_r, p_cam)
    rms_px = float(np.sqrt(np.mean(reproj**2) * 2.0))
    rms_mm = float(np.sqrt(np.mean(np.sum(euclid**2, axis=1))))
    if res.status <= 0 or not np.isfinite(rms_px) or rms_px > max_rms_px:
        raise CalibrationError(
            f"the bundle adjustment diverged: RMS reprojection error {rms_px:.3g} px (limit "
            f"{max_rms_px:g} px) after {res.nfev} evaluations ({res.message})"
        )
    return BundleResult(geo.make_transform(rot, tr), p, rms_px, rms_mm, int(res.nfev))


# ----------------------------------------------------------------------------------------------
# the whole reconstruction


@dataclass
class MarkerReconstruction:
    """Result of :func:`reconstruct_markers`: the bundle result plus the graph and clusters.

    Views showing fewer than ``alpha`` markers are left out; ``used_views`` lists the indices
    (into the input list) of the others, in the order of the bundle's poses, the graph and the
    clusters.
    """

    bundle: BundleResult
    weights: np.ndarray
    clusters: list[Cluster]
    reference_view: int
    used_views: list[int]


def reconstruct_markers(
    rig: StereoRig,
    views: list[View],
    n_markers: int,
    *,
    alpha: int,
    sigma_px: float,
    sigma_mm: float,
    max_nfev: int = 200,
    depth_ref_mm: float | None = None,
) -> MarkerReconstruction:
    """Global marker coordinates from unordered stereo views (Eq. 5-10).

    The world frame is the left camera of the first cluster's centre image. Views with fewer
    than ``alpha`` markers are not used. ``sigma_px``, ``sigma_mm``, ``max_nfev`` and
    ``depth_ref_mm`` are passed to :func:`bundle_adjust`.

    Raises
    ------
    CalibrationError
        If a member image shares fewer than 4 markers with its centre (PnP), if the clusters
        cannot be joined (naming them), or if the bundle adjustment diverges.
    """
    used = [j for j, v in enumerate(views) if v.ids.size >= alpha]
    if not used:
        raise CalibrationError(
            f"no view shows {alpha} markers (most: {max(v.ids.size for v in views)})"
        )
    views = [views[j] for j in used]
    weights = image_graph(views)
    clusters = [reconstruct_cluster(rig, views, c, m) for c, m in cluster_images(weights, alpha)]
    w2c, pts = splice_clusters(clusters)
    ref = next(iter(w2c))
    poses = np.stack([w2c[j] for j in range(len(views))])
    points = np.full((n_markers, 3), np.nan)
    for i, p in pts.items():
        points[i] = p
    bundle = bundle_adjust(
        rig,
        views,
        poses,
        points,
        fixed_view=ref,
        sigma_px=sigma_px,
        sigma_mm=sigma_mm,
        max_nfev=max_nfev,
        depth_ref_mm=depth_ref_mm,
    )
    return MarkerReconstruction(bundle, weights, clusters, ref, used)


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
    weights as in :func:`bundle_adjust`)."""
    pts = geo.check_shape("points", points, (None, 3))
    init = geo.check_transform("world2cam", world2cam)
    view_idx, marker_idx, uv_l, uv_r, p_cam = _observations(rig, [view])
    if view.ids.size < 4:
        raise CalibrationError(f"PnP needs at least 4 markers; the view has {view.ids.size}")
    sigma_obs = _euclid_sigma(p_cam, sigma_mm, depth_ref_mm)[:, None]

    def fun(x):
        rot = Rotation.from_rotvec(x[None, :3]).as_matrix()
        reproj, euclid = _residual_blocks(
            rig, rot, x[None, 3:], pts, view_idx, marker_idx, uv_l, uv_r, p_cam
        )
        return np.concatenate([reproj.ravel() / sigma_px, (euclid / sigma_obs).ravel()])

    x0 = np.concatenate([geo.matrix_to_rotvec(init[:3, :3]), init[:3, 3]])
    res = least_squares(fun, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=400)
    if res.status <= 0:
        raise CalibrationError(f"camera pose refinement did not converge ({res.message})")
    return geo.make_transform(Rotation.from_rotvec(res.x[:3]).as_matrix(), res.x[3:])


__all__ = [
    "BundleResult",
    "Cluster",
    "MarkerReconstruction",
    "View",
    "bundle_adjust",
    "cluster_images",
    "image_graph",
    "make_view",
    "pnp_pose",
    "reconstruct_cluster",
    "reconstruct_markers",
    "refine_camera_pose",
    "splice_clusters",
    "triangulate",
]
