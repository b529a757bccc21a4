"""Closed-form fits: rotations and rigid motions (SVD), circles and spheres (linear least squares),
plane homographies and camera poses.

Every function checks its input (shape, finite values, enough points, degenerate geometry) and
raises :class:`calstudy.CalibrationError` with the number that shows the problem. Millimetres and
pixels; a pose ``target2cam`` maps target points to the camera frame,
``p_cam = target2cam @ p_target``.

Paper references are to ``hybrid`` (``papers/000_fc1e98135301fecc.txt``): Eq. 10-11 (rotation by
SVD) and Eq. 16-19 (homography and the pose it gives).
"""

from __future__ import annotations

import cv2
import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.core.estimation import condition_number, minpack_lm
from calstudy.core.geometry import (
    check_not_collinear,
    check_points,
    check_same_length,
    check_shape,
    cross_rows,
    format_values,
    is_rank_deficient,
    make_transform,
    project_to_so3,
    singular_values,
)

#: Condition number of the (centred, scaled) sphere-fit matrix above which the points are
#: treated as coplanar.
SPHERE_COND_MAX = 1e9
#: Ratio of the 8th to the 1st singular value of the normalised DLT matrix below which the
#: correspondences do not determine a homography (e.g. 3 of 4 points on a line).
HOMOGRAPHY_RANK_TOL = 1e-8
#: Ratio of the smallest to the largest singular value of ``K^-1 H`` below which ``H`` is taken
#: as singular (a plane seen edge-on, or not a homography of a plane at all).
HOMOGRAPHY_SINGULAR_TOL = 1e-8


#: what :func:`_by_array` kept, by (label, dtype, shape, bytes): a study fits the same target
#: points and camera matrix thousands of times; bounded
_KEPT: dict = {}
_KEPT_MAX = 256


def _by_array(label: str, array, compute):
    """``compute(array)``, kept for the next call with an array of the same bytes (its checks
    raise on bad input and are not kept then; anything kept must not be modified)."""
    if not isinstance(array, np.ndarray):
        return compute(array)
    key = (label, array.dtype.str, array.shape, array.tobytes())
    if key not in _KEPT:
        value = compute(array)
        if len(_KEPT) >= _KEPT_MAX:
            _KEPT.clear()
        _KEPT[key] = value
    return _KEPT[key]


# ----------------------------------------------------------------------------------------------
# rotations and rigid motions


def fit_rotation(v_from, v_to, center: bool = True) -> np.ndarray:
    """Rotation ``R`` minimising ``sum |R v_from_i - v_to_i|^2`` by SVD (hybrid Eq. 10-11).

    With the paper's notation ``R_F P_1 = P_0``: ``v_from`` holds the columns of ``P_1`` (sphere
    centre differences in the sensor frame) and ``v_to`` those of ``P_0``. The cross-covariance
    ``K = (P_0 - C_0)(P_1 - C_1)^T = U S V^T`` gives ``R = U diag(1, 1, det(U V^T)) V^T``; the
    determinant fix, which the paper leaves out, keeps ``R`` a rotation rather than a
    reflection when the data are noisy or planar.

    Parameters
    ----------
    v_from, v_to : array_like, shape (N, 3)
        Paired vectors (any unit, the same for both), row ``i`` of ``v_from`` maps to row ``i``
        of ``v_to``.
    center : bool
        Subtract the means ``C_1``, ``C_0`` first, as the paper's Eq. 11 does. With
        ``center=False`` the vectors are used as they are (a pure rotation fit, like
        :meth:`scipy.spatial.transform.Rotation.align_vectors`).

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        The rotation taking ``v_from`` to ``v_to`` (``from2to``).

    Raises
    ------
    CalibrationError
        On wrong shapes, non-finite values, ``N < 2``, or if either (centred) set spans fewer
        than 2 directions, since the rotation about that direction is then undetermined.
    """
    a = check_points("v_from", v_from, 3, 2, "fit_rotation", "vectors")
    b = check_shape("v_to", v_to, (None, 3))
    check_same_length("v_from", a, "v_to", b)
    if center:
        a = a - a.mean(axis=0)
        b = b - b.mean(axis=0)
    for name, vectors in (("v_from", a), ("v_to", b)):
        s = singular_values(vectors)
        if is_rank_deficient(s, 2):
            raise CalibrationError(
                f"difference vectors are collinear (singular values {format_values(s)} of {name}); "
                "use "
                "at least 3 non-collinear translations"
            )
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def fit_rigid(p_from, p_to) -> np.ndarray:
    """Rigid transform ``from2to`` minimising ``sum |R p_from_i + t - p_to_i|^2`` (Kabsch).

    Parameters
    ----------
    p_from, p_to : array_like, shape (N, 3)
        Paired points in mm, ``p_from`` in the frame "from", ``p_to`` the same points in "to".
        ``N >= 3`` and not all on one line.

    Returns
    -------
    numpy.ndarray, shape (4, 4)
        ``from2to`` with ``p_to ≈ from2to @ p_from``.

    Raises
    ------
    CalibrationError
        On wrong shapes, non-finite values, fewer than 3 points or collinear points.
    """
    a = check_points("p_from", p_from, 3, 3, "fit_rigid")
    b = check_shape("p_to", p_to, (None, 3))
    check_same_length("p_from", a, "p_to", b)
    check_not_collinear("p_from points", a)
    check_not_collinear("p_to points", b)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    r = fit_rotation(a - ca, b - cb, center=False)
    return make_transform(r, cb - r @ ca)


def fit_sphere(points) -> tuple[np.ndarray, float, float]:
    """Sphere through 3-D points by linear least squares (``selfcal`` Eq. 7-8).

    Solves ``x^2 + y^2 + z^2 = 2 a x + 2 b y + 2 c z + d``; centre ``(a, b, c)``, radius
    ``sqrt(d + a^2 + b^2 + c^2)``. The points are centred and scaled to unit RMS distance before
    the fit, so the returned condition number describes the geometry of the point set (how much
    of the sphere it covers), not the units or the position of the sphere.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        ``N >= 4`` points in mm, not all in one plane.

    Returns
    -------
    centre : numpy.ndarray, shape (3,)
        In mm, in the frame of ``points``.
    radius : float
        In mm.
    cond : float
        Condition number of the centred, scaled ``N x 4`` design matrix.

    Raises
    ------
    CalibrationError
        On wrong shapes, non-finite values, fewer than 4 points, or (nearly) coplanar points
        (condition number above :data:`SPHERE_COND_MAX`).
    """
    p = check_points("points", points, 3, 4, "sphere fit")
    mean = p.mean(axis=0)
    q = p - mean
    scale = np.sqrt((q**2).sum(axis=1).mean())
    if scale == 0.0:
        raise CalibrationError(f"the {p.shape[0]} points of the sphere fit all coincide")
    q = q / scale
    design = np.column_stack([2.0 * q, np.ones(len(q))])
    cond = condition_number(design)
    if cond > SPHERE_COND_MAX:
        raise CalibrationError(
            f"the {p.shape[0]} points are coplanar (condition number {cond:.3g} of the sphere "
            "fit); a sphere needs at least 4 points not in one plane"
        )
    sol, *_ = np.linalg.lstsq(design, (q**2).sum(axis=1), rcond=None)
    centre_q = sol[:3]
    radius = np.sqrt(sol[3] + centre_q @ centre_q) * scale
    return mean + centre_q * scale, float(radius), cond


# ----------------------------------------------------------------------------------------------
# homography and camera pose


def _check_camera_matrix(k) -> np.ndarray:
    """Check a 3 x 3 intrinsic matrix: upper triangular, ``fx, fy > 0``, ``K[2, 2] = 1``."""
    k = check_shape("K", k, (3, 3))
    _by_array("K", k, _check_intrinsics)
    return k


def _check_intrinsics(k: np.ndarray) -> None:
    lower = np.abs(k[[1, 2, 2], [0, 0, 1]])
    if lower.max() > 1e-12 * np.abs(k).max():
        raise CalibrationError(
            "K is not upper triangular (K[1,0], K[2,0], K[2,1] = "
            f"{format_values(k[[1, 2, 2], [0, 0, 1]])})"
        )
    if not (k[0, 0] > 0 and k[1, 1] > 0 and abs(k[2, 2] - 1.0) < 1e-12):
        raise CalibrationError(
            f"K is not an invertible camera matrix (diagonal {format_values(np.diag(k))}; expected "
            "fx > 0, fy > 0, 1)"
        )


def _homography_matrix(h8) -> np.ndarray:
    """``H`` (3 x 3, C order) from its first eight entries, ``H[2, 2] = 1``."""
    h = np.empty(9)
    h[:8] = h8
    h[8] = 1.0
    return h.reshape(3, 3)


def _homography_residuals(h8, x1, uv):
    """Reprojection residuals ``(2 N,)`` of the plane points ``x1 = [x y 1]`` (N, 3)."""
    q = x1 @ _homography_matrix(h8).T
    return (q[:, :2] / q[:, 2:] - uv).ravel()


def _homography_jacobian(h8, x1, uv):
    """Jacobian ``(2 N, 8)`` of :func:`_homography_residuals`."""
    q = x1 @ _homography_matrix(h8).T
    w = q[:, 2:]
    proj = q[:, :2] / w
    xw = x1 / w
    jac = np.zeros((len(x1), 2, 8))
    jac[:, 0, 0:3] = xw
    jac[:, 1, 3:6] = xw
    jac[:, :, 6:8] = -proj[:, :, None] * xw[:, None, :2]
    return jac.reshape(-1, 8)


def _normalise_2d(p: np.ndarray) -> np.ndarray:
    """Hartley normalisation: centroid at 0, RMS distance sqrt(2)."""
    q = p - p.mean(axis=0)
    scale = np.sqrt((q**2).sum(axis=1).mean())
    return q * (np.sqrt(2.0) / scale) if scale > 0 else q


def _dlt_plane(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parts of the normalised DLT matrix that depend on the target-plane points only:
    ``ah = [a 1]`` (``a`` the Hartley-normalised points) and the matrix ``[ah 0 0] / [0 ah 0]``
    its image columns are written into (read-only: kept by :func:`_by_array`, as a study fits
    images of the same target again and again)."""
    return _by_array("DLT plane", xy, _build_dlt_plane)


def _build_dlt_plane(xy) -> tuple[np.ndarray, np.ndarray]:
    a = _normalise_2d(np.asarray(xy, dtype=float))
    n = len(a)
    ah = np.column_stack([a, np.ones(n)])
    rows = np.zeros((2 * n, 9))  # [ah 0 -u ah] over [0 ah -v ah]
    rows[:n, 0:3] = ah
    rows[n:, 3:6] = ah
    ah.flags.writeable = rows.flags.writeable = False
    return ah, rows


def check_homography_data(xy: np.ndarray, uv: np.ndarray) -> float:
    """Ratio of the 8th to the largest singular value of the normalised DLT matrix of the
    correspondences; CalibrationError if below :data:`HOMOGRAPHY_RANK_TOL` (the points do not
    determine a homography: with 4 points, 3 of them on a line)."""
    ah, plane_rows = _dlt_plane(xy)
    b = _normalise_2d(uv)
    n = len(ah)
    rows = plane_rows.copy()
    np.multiply(-b[:, :1], ah, out=rows[:n, 6:9])
    np.multiply(-b[:, 1:], ah, out=rows[n:, 6:9])
    s = singular_values(rows)
    ratio = float(s[7] / s[0]) if s.size > 7 and s[0] > 0 else 0.0
    if ratio < HOMOGRAPHY_RANK_TOL:
        raise CalibrationError(
            f"the {len(xy)} correspondences do not determine a homography (8th singular value "
            f"of the normalised DLT matrix {ratio:.3g} of the largest, limit "
            f"{HOMOGRAPHY_RANK_TOL:g}): with 4 points, no 3 may lie on a line; add points"
        )
    return ratio


def fit_homography(plane_xy, image_uv, refine: bool = True) -> np.ndarray:
    """Homography ``H`` from target-plane points to image points, ``s [u v 1] = H [x y 1]``.

    Computed by ``cv2.findHomography(method=0)`` (normalised DLT over all points, then OpenCV's
    Levenberg-Marquardt on the reprojection error). OpenCV stops that refinement after 10
    iterations at single-precision tolerances (noise-free reprojection error about 1e-5 px), so
    with ``refine=True`` MINPACK's Levenberg-Marquardt
    (:func:`calstudy.core.estimation.minpack_lm`) continues the same minimisation (sum of squared
    pixel reprojection errors, ``H[2, 2] = 1``) to double precision. This is the
    maximum-likelihood homography for i.i.d. Gaussian pixel noise (hybrid Eq. 18, 20).

    Parameters
    ----------
    plane_xy : array_like, shape (N, 2)
        Points on the target plane in mm (``z = 0`` of the target frame), ``N >= 4``, not all
        on a line.
    image_uv : array_like, shape (N, 2)
        Their image coordinates in px.
    refine : bool
        Continue OpenCV's refinement to convergence (see above).

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        ``H`` normalised so that ``H[2, 2] = 1``.

    Raises
    ------
    CalibrationError
        On wrong shapes, non-finite values, fewer than 4 points, collinear plane or image points,
        or if OpenCV finds no homography.
    """
    xy = check_shape("plane_xy", plane_xy, (None, 2))
    uv = check_shape("image_uv", image_uv, (None, 2))
    check_same_length("plane_xy", xy, "image_uv", uv)
    if xy.shape[0] < 4:
        raise CalibrationError(f"homography needs at least 4 points; got {xy.shape[0]}")
    _by_array("plane points", xy, lambda p: check_not_collinear("points", p))
    check_not_collinear("image points", uv)
    check_homography_data(xy, uv)
    try:
        h, _ = cv2.findHomography(xy, uv, method=0)
    except cv2.error as exc:
        raise CalibrationError(
            f"cv2.findHomography failed on {xy.shape[0]} points: {exc.err}"
        ) from None
    if h is None or h.shape != (3, 3) or not np.isfinite(h).all() or abs(h[2, 2]) < 1e-12:
        raise CalibrationError(
            f"cv2.findHomography found no homography for the {xy.shape[0]} points (degenerate "
            "configuration, e.g. 3 of 4 points on a line)"
        )
    h = h / h[2, 2]
    if refine:
        x = minpack_lm(
            _homography_residuals,
            h.ravel()[:8],
            _homography_jacobian,
            (np.column_stack([xy, np.ones(len(xy))]), uv),
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
        )
        h = _homography_matrix(x)
    if not np.all(np.isfinite(h)):
        raise CalibrationError(f"the homography of the {xy.shape[0]} points is not finite")
    return h


def homography_to_pose(h, k) -> np.ndarray:
    """Pose ``target2cam`` of a planar target from its homography (hybrid Eq. 19).

    With ``M = K^-1 H = [m1 m2 m3]`` and ``gamma = 1 / |m1|``: ``r1 = gamma m1``,
    ``r2 = gamma m2``, ``r3 = r1 x r2``, ``t = gamma m3``. The sign rule of the paper makes the
    target lie in front of the camera: if ``t_z < 0``, ``gamma`` changes sign. The paper takes
    ``[r1 r2 r3]`` as the rotation; under noise ``r1`` and ``r2`` are neither unit nor
    orthogonal, so (a step the paper leaves unsaid) the matrix is replaced by the nearest
    rotation in the Frobenius norm (SVD, :func:`calstudy.core.geometry.project_to_so3`), as Zhang
    (2000) does. ``t`` keeps the paper's scale ``gamma = 1/|m1|``.

    Parameters
    ----------
    h : array_like, shape (3, 3)
        Homography from the target plane (mm) to the image (px), any scale and sign.
    k : array_like, shape (3, 3)
        Camera intrinsic matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`` in px.

    Returns
    -------
    numpy.ndarray, shape (4, 4)
        ``target2cam``: target frame (plane ``z = 0``) to camera frame, translation in mm.

    Raises
    ------
    CalibrationError
        If ``H`` has a wrong shape or non-finite values, ``K`` is not an upper-triangular
        invertible camera matrix, or ``H`` is singular in a way that gives no pose.
    """
    hm = check_shape("H", h, (3, 3))
    km = _check_camera_matrix(k)
    m = np.linalg.solve(km, hm)
    sv = singular_values(m)
    if sv[0] == 0.0 or sv[2] / sv[0] < HOMOGRAPHY_SINGULAR_TOL:
        raise CalibrationError(
            f"H is singular (rank {int(np.sum(sv > sv[0] * HOMOGRAPHY_SINGULAR_TOL))}, singular "
            f"values of K^-1 H {format_values(sv)}): it is not the homography of a plane in "
            "front of the camera"
        )
    norm1 = np.linalg.norm(m[:, 0])
    if norm1 == 0.0 or np.linalg.norm(m[:, 1]) == 0.0:
        raise CalibrationError(
            f"H is singular: |K^-1 h1| = {norm1:.3g}, |K^-1 h2| = {np.linalg.norm(m[:, 1]):.3g}"
        )
    gamma = 1.0 / norm1
    if m[2, 2] == 0.0:
        raise CalibrationError("H gives a target origin in the camera's focal plane (t_z = 0 mm)")
    if gamma * m[2, 2] < 0:
        gamma = -gamma
    r1, r2, t = gamma * m[:, 0], gamma * m[:, 1], gamma * m[:, 2]
    ratio = np.linalg.norm(r2)
    if not 0.5 < ratio < 2.0 or abs(r1 @ r2) > 0.5 * ratio:
        raise CalibrationError(
            f"H is far from a plane's homography under this K: its first two columns give "
            f"|r2|/|r1| = {ratio:.3g} and r1.r2 = {r1 @ r2:.3g} (a rotation gives 1 and 0); "
            "check K and the homography's direction (plane to image)"
        )
    rot = project_to_so3(np.column_stack([r1, r2, cross_rows(r1[None], r2[None])[0]]))
    return make_transform(rot, t)


def _check_pnp_points(obj: np.ndarray) -> None:
    """Object points SOLVEPNP_ITERATIVE accepts: not on a line, at least 6 unless coplanar."""
    check_not_collinear("object points", obj)
    n = obj.shape[0]
    if not is_rank_deficient(singular_values(obj - obj.mean(axis=0)), 3) and n < 6:
        raise CalibrationError(
            f"non-planar object points need at least 6 points for SOLVEPNP_ITERATIVE; got {n}"
        )


def solve_pnp(object_points, image_uv, k, dist=None, refine: bool = True) -> np.ndarray:
    """Pose ``target2cam`` from 3-D/2-D correspondences by ``cv2.solvePnP`` (iterative).

    ``flags=cv2.SOLVEPNP_ITERATIVE`` minimises the sum of squared reprojection errors by
    Levenberg-Marquardt: the maximum-likelihood pose for i.i.d. Gaussian pixel noise. Its
    stopping rule leaves about 1e-7 mm of a noise-free pose, so with ``refine=True``
    ``cv2.solvePnPRefineLM`` continues the same minimisation with a tolerance of 1e-16. OpenCV's
    camera model has no skew: ``K[0, 1]`` must be 0.

    Parameters
    ----------
    object_points : array_like, shape (N, 3)
        Points in the target frame, mm. ``N >= 4`` for a planar target, ``N >= 6`` otherwise
        (OpenCV's initialisation), not all on a line.
    image_uv : array_like, shape (N, 2)
        Their image coordinates, px.
    k : array_like, shape (3, 3)
        Camera intrinsic matrix.
    dist : array_like or None
        OpenCV distortion coefficients (4, 5, 8, 12 or 14 values), or None for none.
    refine : bool
        Continue OpenCV's refinement to convergence (see above).

    Returns
    -------
    numpy.ndarray, shape (4, 4)
        ``target2cam``.

    Raises
    ------
    CalibrationError
        On wrong shapes, non-finite values, too few or collinear points, skew in ``K`` or if
        OpenCV fails.
    """
    obj = check_shape("object_points", object_points, (None, 3))
    uv = check_shape("image_uv", image_uv, (None, 2))
    check_same_length("object_points", obj, "image_uv", uv)
    km = _check_camera_matrix(k)
    if km[0, 1] != 0.0:
        raise CalibrationError(f"OpenCV's camera model has no skew; K[0,1] = {km[0, 1]:.3g}")
    n = obj.shape[0]
    if n < 4:
        raise CalibrationError(f"solve_pnp needs at least 4 points; got {n}")
    _by_array("object points", obj, _check_pnp_points)
    d = None if dist is None else check_shape("dist", np.ravel(dist), (None,))
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, uv, km, d, flags=cv2.SOLVEPNP_ITERATIVE)
    except cv2.error as exc:
        raise CalibrationError(f"cv2.solvePnP failed on {n} points: {exc.err}") from None
    if not ok:
        raise CalibrationError(f"cv2.solvePnP found no pose for the {n} points")
    if refine:
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-16)
        try:
            rvec, tvec = cv2.solvePnPRefineLM(obj, uv, km, d, rvec, tvec, criteria=criteria)
        except cv2.error as exc:
            raise CalibrationError(
                f"cv2.solvePnPRefineLM failed on {n} points: {exc.err}"
            ) from None
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        raise CalibrationError(f"cv2.solvePnP returned a non-finite pose for the {n} points")
    rot, _ = cv2.Rodrigues(rvec)
    return make_transform(rot, tvec.ravel())


def solve_pnp_ransac(object_points, image_uv, k, threshold_px: float) -> np.ndarray:
    """Pose ``target2cam`` of a planar target by ``cv2.solvePnPRansac``, robust to gross errors.

    RANSAC (AP3P hypotheses, 500 iterations, fixed OpenCV seed) selects the inliers; a plane seen
    obliquely admits a second, mirrored pose that reprojects almost as well, so the pose is
    recomputed on the inliers by IPPE (which returns the better of the two), the inliers are
    recomputed from it (reprojection error below ``threshold_px``) and the pose refined by LM on
    them. No lens distortion.

    Parameters
    ----------
    object_points : array_like, shape (N, 3)
        Points of the (planar) target in its frame, mm; ``N >= 4``.
    image_uv : array_like, shape (N, 2)
        Their detected image coordinates, px, some of them possibly gross errors.
    k : array_like, shape (3, 3)
        Camera intrinsic matrix.
    threshold_px : float
        Reprojection error (px) below which a point is an inlier.

    Returns
    -------
    numpy.ndarray, shape (4, 4)
        ``target2cam``, refined on the inliers only.

    Raises
    ------
    CalibrationError
        On wrong shapes, fewer than 4 points, or fewer than 4 inliers.
    """
    obj = check_shape("object_points", object_points, (None, 3))
    uv = check_shape("image_uv", image_uv, (obj.shape[0], 2))
    k = _check_camera_matrix(k)
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise CalibrationError(f"threshold_px must be positive and finite; got {threshold_px}")
    if obj.shape[0] < 4:
        raise CalibrationError(f"RANSAC-PnP needs at least 4 points; got {obj.shape[0]}")
    check_not_collinear("object points", obj)
    try:
        return _pnp_ransac(obj, uv, k, threshold_px)
    except cv2.error as exc:
        raise CalibrationError(f"RANSAC-PnP failed on {obj.shape[0]} points: {exc.err}") from None


def _pnp_ransac(obj, uv, k, threshold_px):
    cv2.setRNGSeed(0)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        obj,
        uv,
        k,
        None,
        reprojectionError=threshold_px,
        iterationsCount=500,
        confidence=0.999,
        flags=cv2.SOLVEPNP_AP3P,
    )
    if not ok or inliers is None or len(inliers) < 4:
        raise CalibrationError(f"RANSAC-PnP found no pose for the {obj.shape[0]} points")
    keep = inliers.ravel()
    ok, rvec, tvec = cv2.solvePnP(obj[keep], uv[keep], k, None, flags=cv2.SOLVEPNP_IPPE)
    proj = cv2.projectPoints(obj, rvec, tvec, k, None)[0].reshape(-1, 2)
    good = np.linalg.norm(proj - uv, axis=1) < threshold_px
    if not ok or good.sum() < 4:
        raise CalibrationError(
            f"RANSAC-PnP kept {int(good.sum())} of {obj.shape[0]} points within "
            f"{threshold_px:g} px; PnP needs 4"
        )
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-16)
    rvec, tvec = cv2.solvePnPRefineLM(obj[good], uv[good], k, None, rvec, tvec, criteria=criteria)
    return make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())


__all__ = [
    "fit_homography",
    "fit_rigid",
    "fit_rotation",
    "fit_sphere",
    "homography_to_pose",
    "solve_pnp",
    "solve_pnp_ransac",
]
