"""Coded markers seen by a binocular sensor: image graph, clustering, PnP, splice, and the whole
reconstruction.

The structure-from-motion part of the ``dualarm`` paper (SFM-BSV, Section 3): a binocular sensor
images coded markers (ids known) from many unordered poses; the markers' 3-D coordinates in one
global frame follow from

1. the image graph (Eq. 5): the weight of an edge is the number of markers two images share;
2. the clustering of Eq. 6: the fewest *centre* images such that every image shares at least
   ``alpha`` markers with a centre (greedy minimum dominating set), each image joining the centre
   it shares most with;
3. in each cluster, the markers triangulated in the centre image's frame (Eq. 7,
   :meth:`calstudy.models.stereo.StereoRig.triangulate`) and the other images located by PnP
   (checked against a rigid fit of their own triangulated markers);
4. the incremental splice (Eq. 8): clusters joined to the growing reconstruction by a rigid fit
   on their common markers, the best-connected pair first;
5. a bundle adjustment (Eq. 9-10, :func:`calstudy.estimators.bundle.bundle_adjust`): all camera
   poses and marker positions refined by Levenberg-Marquardt on the reprojection residuals of
   both cameras and the Euclidean residuals between the triangulated and the global marker
   positions, with a sparse Jacobian.

The observations (:class:`calstudy.estimators.stereo_views.View`) and their triangulation live in
:mod:`calstudy.estimators.stereo_views`, below both this module and the adjustment.

Frames: ``world2cam`` maps world points into the *left* (reference) camera; the right camera sees
``left2right @ p_left``. Pixels in px, lengths in mm. The rig
(:class:`calstudy.models.stereo.StereoRig`) must have ideal cameras: these steps model no lens
distortion, and refuse a rig whose cameras have one (undistort the image points first).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.bundle import BundleResult, bundle_adjust
from calstudy.estimators.fitting import fit_rigid
from calstudy.estimators.stereo_views import View, check_ideal
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig

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
        With fewer than 4 points, on bad shapes or if OpenCV fails or finds no finite pose.
    """
    obj = geo.check_shape("object_points", object_points, (None, 3))
    uv = geo.check_shape("image_uv", image_uv, (obj.shape[0], 2))
    if obj.shape[0] < 4:
        raise CalibrationError(f"PnP needs at least 4 markers; got {obj.shape[0]}")
    check_ideal(camera)
    k = camera.K
    n = obj.shape[0]
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-16)
    try:  # OpenCV asserts on degenerate markers (all on one point or line)
        ok, rvec, tvec = cv2.solvePnP(obj, uv, k, None, flags=cv2.SOLVEPNP_SQPNP)
        if ok:
            rvec, tvec = cv2.solvePnPRefineLM(obj, uv, k, None, rvec, tvec, criteria=criteria)
    except cv2.error as exc:
        raise CalibrationError(f"cv2.solvePnP failed on the {n} markers: {exc.err}") from None
    if not (ok and np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        raise CalibrationError(f"cv2.solvePnP found no pose for the {n} markers")
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
        fit_rigid(obj, rig.triangulate(uv_left, uv_right)),
    ]

    def cost(w2c):
        ul, ur = rig.project(geo.apply(w2c, obj))
        return np.sum((ul - uv_left) ** 2) + np.sum((ur - uv_right) ** 2)

    return min(candidates, key=cost)


def reconstruct_cluster(rig: StereoRig, views: list[View], centre: int, members) -> Cluster:
    """Markers of the centre image triangulated in its frame; the other members located by PnP
    (or the rigid fit of their triangulated markers, whichever reprojects better)."""
    check_ideal(rig.left, rig.right)
    c = views[centre]
    cluster = Cluster(centre, {centre: np.eye(4)})
    for i, p in zip(c.ids, rig.triangulate(c.uv_left, c.uv_right), strict=True):
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
            local = rig.triangulate(v.uv_left[new], v.uv_right[new])
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


__all__ = [
    "Cluster",
    "MarkerReconstruction",
    "cluster_images",
    "image_graph",
    "pnp_pose",
    "reconstruct_cluster",
    "reconstruct_markers",
    "splice_clusters",
]
