"""Binocular triangulation, multi-target calibrator, observed-error modification and hand-eye
update.

The geometric half of the `binocular` paper (Sections 2 and 3.2); the imaging half is
:mod:`calstudy.models.optics` (the circle-of-confusion model) and :mod:`calstudy.estimators.coc`
(rectification, ellipse centres), the sensor :class:`calstudy.models.stereo.StereoRig`.

- :func:`triangulate`: Eq. 1 by the rig's triangulation (``cv2.undistortPointsIter`` and
  ``cv2.triangulatePoints``) with a check that the two rays meet.
- :func:`solve_calibrator_layout`: a 3D layout of targets P1-P6 and the virtual P7, P8 consistent
  with the standard distances of Table 2.
- :func:`modify_observed_error`: the distance-constraint adjustment of Eq. 23-25 (least norm).
- :func:`preliminary_handeye`: AX = XB (Eq. 13) after the library's check of the rotation axes.
- :func:`correct_transformation`: the transformation error correction of Eq. 14-22.

Frames: the sensor frame is the left camera frame. ``sensor2flange`` is the paper's ``H_gc``,
``flange2base`` its ``H_g``. Millimetres and radians.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.optimize import least_squares

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.axxb import OPENCV_METHODS, opencv_handeye
from calstudy.models.stereo import StereoRig

#: Indices (0-based) of the physical targets averaged into the virtual P7 and P8 (Section 3.2).
P7_FROM = (1, 2, 4)
P8_FROM = (0, 3, 5)
TARGET_NAMES = ("P1", "P2", "P3", "P4", "P5", "P6", "P7", "P8")


# ----------------------------------------------------------------------------------------------
# triangulation (Eq. 1)


def triangulate(rig: StereoRig, uv_left, uv_right, tol_mm: float = 0.5) -> np.ndarray:
    """Sensor-frame points ``(N, 3)`` from matched image points (Eq. 1), undistorted first.

    Both cameras' points are undistorted to normalised coordinates
    (:meth:`calstudy.models.stereo.StereoRig.normalise`) and triangulated by the rig
    (:meth:`~calstudy.models.stereo.StereoRig.triangulate_normalised`, ``cv2.triangulatePoints``
    with its ``left2right``). The distance between the two back-projected rays at their
    closest approach is checked against ``tol_mm``.

    Parameters
    ----------
    rig : StereoRig
        The calibrated sensor (its cameras with their distortion); the sensor frame is the left
        camera frame.
    uv_left, uv_right : (N, 2) array_like
        Matched image points, px.
    tol_mm : float, default 0.5
        Largest accepted ray gap, mm.

    Raises
    ------
    CalibrationError
        If the arrays differ in shape or are not finite, ``tol_mm`` is not > 0, or a pair of
        rays misses by more than ``tol_mm`` (a wrong match or a wrong calibration).
    """
    a = geo.check_finite("left image points", uv_left).reshape(-1, 2)
    b = geo.check_finite("right image points", uv_right).reshape(-1, 2)
    if a.shape != b.shape or a.shape[0] == 0:
        raise CalibrationError(f"left {a.shape} and right {b.shape} points must match, N >= 1")
    return triangulate_sets(rig, a[None], b[None], tol_mm)[0]


def triangulate_sets(rig: StereoRig, uv_left, uv_right, tol_mm: float = 0.5) -> np.ndarray:
    """:func:`triangulate` of ``k`` sets of matched image points ``(k, N, 2)`` in one pass:
    points ``(k, N, 3)``, each the number :func:`triangulate` gives it alone (every step is per
    point). Raises as :func:`triangulate` for the first set (in order) whose rays miss."""
    if not (math.isfinite(tol_mm) and tol_mm > 0):
        raise CalibrationError(f"ray tolerance tol_mm = {tol_mm} must be a finite number > 0")
    a = geo.check_finite("left image points", uv_left)
    b = geo.check_finite("right image points", uv_right)
    if a.shape != b.shape or a.ndim != 3 or a.shape[2] != 2 or a.shape[1] == 0:
        raise CalibrationError(f"left {a.shape} and right {b.shape} points must match, N >= 1")
    k, n = a.shape[:2]
    xl, xr = rig.normalise(a.reshape(-1, 2), "left"), rig.normalise(b.reshape(-1, 2), "right")
    gap = ray_gap(xl, xr, rig.rotation, rig.translation).reshape(k, n)
    points = rig.triangulate_normalised(xl, xr).reshape(k, n, 3)
    missed = np.flatnonzero(gap.max(axis=1) > tol_mm)
    if missed.size:
        worst = int(np.argmax(gap[missed[0]]))
        raise CalibrationError(
            f"rays of point {worst} miss each other by {gap[missed[0], worst]:.3g} mm "
            f"(tolerance {tol_mm:g} mm): wrong match or calibration"
        )
    return points


def ray_gap(x_left, x_right, rotation, translation) -> np.ndarray:
    """Closest distance (mm) between the rays of normalised points ``(N, 2)`` of both cameras.

    Parameters
    ----------
    x_left, x_right : array_like, shape (N, 2)
        Normalised image points of the left and the right camera.
    rotation : array_like, shape (3, 3)
        Rotation of ``left2right``.
    translation : array_like, shape (3,)
        Translation of ``left2right``, mm.

    Returns
    -------
    numpy.ndarray, shape (N,)
        Gap between the two rays of each point, mm.

    Raises
    ------
    CalibrationError
        Wrong shapes, NaN or inf, or a left and a right ray are parallel.
    """
    x_left = geo.check_shape("x_left", x_left, (None, 2))
    x_right = geo.check_shape("x_right", x_right, (x_left.shape[0], 2))
    rotation = geo.check_shape("rotation", rotation, (3, 3))
    translation = geo.check_shape("translation", translation, (3,))
    d1 = np.column_stack([x_left, np.ones(len(x_left))])
    d2 = np.column_stack([x_right, np.ones(len(x_right))]) @ rotation  # R^T d, row-wise
    c2 = -rotation.T @ translation
    n = np.cross(d1, d2)
    norm = np.linalg.norm(n, axis=1)
    if np.any(norm < 1e-12):
        raise CalibrationError("a left and a right ray are parallel: no intersection")
    return np.abs(n @ c2) / norm


# ----------------------------------------------------------------------------------------------
# the calibrator


def with_virtual(points) -> np.ndarray:
    """P1-P6 ``(..., 6, 3)`` extended by the virtual P7 (centroid of P2, P3, P5) and P8 (of P1,
    P4, P6): ``(..., 8, 3)``."""
    p = geo.check_finite("calibrator targets", points)
    if p.shape[-2:] != (6, 3):
        raise CalibrationError(f"the calibrator has 6 physical targets; got points {p.shape}")
    p7 = p[..., P7_FROM, :].mean(axis=-2, keepdims=True)
    p8 = p[..., P8_FROM, :].mean(axis=-2, keepdims=True)
    return np.concatenate([p, p7, p8], axis=-2)


def virtual_weights() -> np.ndarray:
    """``(8, 6)`` weights ``W`` with ``with_virtual(p) == W @ p``: P1-P6 themselves, P7 and P8
    the centroids of their three targets."""
    w = np.zeros((8, 6))
    w[np.arange(6), np.arange(6)] = 1.0
    w[6, list(P7_FROM)] = 1.0 / len(P7_FROM)
    w[7, list(P8_FROM)] = 1.0 / len(P8_FROM)
    return w


def distances_to_p7(points8) -> np.ndarray:
    """Distances P1P7 ... P6P7 and P8P7 (Table 2's rows) of ``(..., 8, 3)`` points (mm).

    Raises
    ------
    CalibrationError
        If the points are not ``(..., 8, 3)``, hold NaN or infinity, or lie so far apart (near
        1e308 mm) that a distance overflows.
    """
    p = geo.check_finite("calibrator targets", points8)
    if p.ndim < 2 or p.shape[-2:] != (8, 3):
        raise CalibrationError(
            f"need P1-P8 as (..., 8, 3) points; got {p.shape} (see with_virtual)"
        )
    rows = [0, 1, 2, 3, 4, 5, 7]
    d = p[..., rows, :] - p[..., 6:7, :]
    out = np.linalg.norm(d, axis=-1)
    if not np.isfinite(out).all():  # squares past 1e308: np.hypot does not square
        out = np.hypot(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
        if not np.isfinite(out).all():
            raise CalibrationError(
                "calibrator targets: a distance to P7 overflows (largest |coordinate| "
                f"{np.abs(p).max():.3g} mm)"
            )
    return out


#: smallest singular value of Eq. 21's ``U``, relative to its largest, for which all six
#: parameters of the hand-eye update are determined (:func:`correct_transformation`)
UPDATE_RCOND = 1e-9
#: relative slack of :func:`layout_problem`: a triangle of distances that closes within it is
#: a layout (a flat one)
LAYOUT_TOL = 1e-9
#: the standard distances to P7, in the order of Table 2
DISTANCE_NAMES = ("P1P7", "P2P7", "P3P7", "P4P7", "P5P7", "P6P7", "P8P7")


def _listing(lengths, names) -> str:
    """``"P2P7 = 58.853, P3P7 = 55.181, ..."``: named distances for a message."""
    return ", ".join(f"{n} = {v:g}" for n, v in zip(names, lengths, strict=True))


def layout_problem(distances_mm, names=None) -> str:
    """Why the seven standard distances to P7 admit no planar layout, in words (``""`` if they
    admit one).

    P7 is the centroid of P2, P3, P5, so the three vectors from P7 sum to zero: each of their
    lengths must be at most the sum of the other two (a triangle). P8 is the centroid of P1, P4,
    P6, so ``3 |P8P7|`` is the length of the sum of three vectors of lengths P1P7, P4P7, P6P7:
    between ``max(0, 2 max - sum)`` and ``sum``. ``names`` (7 texts) name the distances in
    the message, default :data:`DISTANCE_NAMES`.
    """
    d = np.asarray(distances_mm, dtype=float)
    names = DISTANCE_NAMES if names is None else names
    problems = []
    tri = d[list(P7_FROM)]
    slack = LAYOUT_TOL * float(tri.sum())
    k = int(np.argmax(tri))
    if tri[k] > tri.sum() - tri[k] + slack:
        problems.append(
            f"{_listing(tri, [names[i] for i in P7_FROM])} admit no layout: P7 is the centroid of "
            f"P2, P3, P5 only if each is at most the sum of the other two "
            f"({names[P7_FROM[k]]} = {tri[k]:g} > {tri.sum() - tri[k]:g})"
        )
    arms = d[list(P8_FROM)]
    lo, hi = max(0.0, 2 * float(arms.max()) - float(arms.sum())) / 3, float(arms.sum()) / 3
    slack = LAYOUT_TOL * float(arms.sum())
    if not lo - slack <= d[6] <= hi + slack:
        problems.append(
            f"{names[6]} = {d[6]:g} with {_listing(arms, [names[i] for i in P8_FROM])} admit no "
            f"layout: P8, the centroid of P1, P4, P6, lies between {lo:.6g} and {hi:.6g} from P7"
        )
    return "; ".join(problems)


def solve_calibrator_layout(distances_mm, start_angle_deg) -> tuple[np.ndarray, np.ndarray]:
    """A planar layout of P1-P6 consistent with Table 2's standard distances to P7.

    Pk lies on the circle of radius ``distances_mm[k]`` about P7 (the origin) in the plate plane
    ``z = 0``; the six angles are found by least squares (from ``start_angle_deg``) so that P7
    is the centroid of P2, P3, P5 and ``|P8 - P7|`` equals the seventh distance.

    Parameters
    ----------
    distances_mm : (7,) array_like
        P1P7 ... P6P7, P8P7.
    start_angle_deg : (6,) array_like
        Initial angles of P1-P6.

    Returns
    -------
    points : (8, 3) array
        P1-P8 in the calibrator frame (P7 at the origin, plate normal +z).
    residual : (7,) array
        Distances of the layout minus the standard ones, mm (not all ~0 if the solver stopped
        in a local minimum from ``start_angle_deg``).

    Raises
    ------
    CalibrationError
        If the distances are not 7 positive numbers, the start angles not 6 finite ones, or the
        distances admit no layout (:func:`layout_problem`, naming the distances that disagree).
    """
    d = np.asarray(distances_mm, dtype=float)
    if d.shape != (7,) or not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise CalibrationError(f"need 7 positive distances to P7, got {d}")
    start = np.asarray(start_angle_deg, dtype=float)
    if start.shape != (6,) or not np.all(np.isfinite(start)):
        raise CalibrationError(f"need 6 finite start angles of P1-P6 (deg), got {start}")
    problem = layout_problem(d)
    if problem:
        raise CalibrationError(problem)
    radii = d[:6]

    def layout(angles: np.ndarray) -> np.ndarray:
        return np.column_stack([radii * np.cos(angles), radii * np.sin(angles), np.zeros(6)])

    def residuals(angles: np.ndarray) -> np.ndarray:
        p = layout(angles)
        p7 = p[list(P7_FROM)].mean(axis=0)
        p8 = p[list(P8_FROM)].mean(axis=0)
        return np.concatenate([p7[:2], [np.linalg.norm(p8 - p7) - d[6]]])

    sol = least_squares(residuals, np.radians(start), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    p = layout(sol.x)
    p -= p[list(P7_FROM)].mean(axis=0)
    points = with_virtual(p)
    return points, distances_to_p7(points) - d


def all_pairs(n: int) -> np.ndarray:
    """Index pairs ``(k, l)``, ``k < l``, of ``n`` targets: ``(n (n - 1) / 2, 2)``."""
    return np.array(list(itertools.combinations(range(n), 2)), dtype=int)


# ----------------------------------------------------------------------------------------------
# observed-error modification (Eq. 23-25)


def modify_observed_error(
    points, pairs, standard_mm, rcond: float = 1e-3, combine=None
) -> tuple[np.ndarray, np.ndarray]:
    """Modify measured target coordinates with the calibrator's standard distances (Eq. 23-25).

    Eq. 24 linearises each distance about the measured coordinates; Eq. 25 stacks the rows
    ``[a b g -a -b -g]`` (direction cosines) against ``L_std - L_meas``. Its Moore-Penrose
    least-norm solution (``numpy.linalg.pinv``) is the modification, added to the points.

    The calibrator is (nearly) planar: moving a target across the plate plane changes the
    distances only to second order, so the coefficient matrix has singular values of the order of
    the measured points' out-of-plane scatter over their spacing (about 1e-4). A pseudo-inverse that
    kept them would turn millimetre-scale out-of-plane moves out of micrometre distance errors;
    singular values below ``rcond`` times the largest are therefore treated as zero (the
    least-norm solution on the well-determined subspace).

    Parameters
    ----------
    points : (m, 3) array
        Measured target centres (sensor frame), mm.
    pairs : (M, 2) int array
        Index pairs whose standard distance is known.
    standard_mm : (M,) array
        Standard (CMM) distances of the pairs.

    rcond : float, default 1e-3
        Relative cut-off of the pseudo-inverse's singular values.
    combine : (m, n) array, optional
        Points that are combinations of ``n`` free ones, ``points == combine @ free`` (the
        calibrator's virtual P7 and P8 are centroids: :func:`virtual_weights`). The unknowns are
        then the free points' modifications (Eq. 25 by the chain rule) and every combined point
        moves with them; ``points`` must satisfy the combination. Default: every point is free.

    Returns
    -------
    modified : (m, 3) array
        ``points`` plus the modification.
    delta : (m, 3) array
        The modification (the observed errors, with the sign that removes them).

    Raises
    ------
    CalibrationError
        If fewer than 8 distances are given (the redundancy Eq. 25 needs), shapes disagree, a
        standard distance is not > 0, ``rcond`` is outside [0, 1), a pair repeats a target or
        indexes a missing one, or two targets coincide.
    """
    p = geo.check_finite("points", points)
    if p.ndim != 2 or p.shape[1] != 3:
        raise CalibrationError(f"points must be (m, 3), got {p.shape}")
    modified, delta = modify_observed_errors(p[None], pairs, standard_mm, rcond, combine)
    return modified[0], delta[0]


def modify_observed_errors(
    points, pairs, standard_mm, rcond: float = 1e-3, combine=None
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`modify_observed_error` of ``k`` sets of measured points ``(k, m, 3)`` at once.

    ``pairs`` ``(M, 2)`` and ``standard_mm`` ``(M,)`` are shared by the sets, or given per set,
    ``(k, M, 2)`` and ``(k, M)``. The pseudo-inverses are computed as one stack; each set's
    result is the number :func:`modify_observed_error` gives it alone.

    Returns ``(modified, delta)``, ``(k, m, 3)`` each; raises as :func:`modify_observed_error`.
    """
    p = geo.check_finite("points", points)
    if p.ndim != 3 or p.shape[2] != 3:
        raise CalibrationError(f"points must be (k, m, 3), got {p.shape}")
    k, m = p.shape[:2]
    pr = np.asarray(pairs, dtype=int)
    std = geo.check_finite("standard distances", standard_mm)
    if pr.ndim == 2 and std.ndim == 1:
        pr, std = np.broadcast_to(pr, (k, *pr.shape)), np.broadcast_to(std, (k, *std.shape))
    if pr.ndim != 3 or pr.shape[0] != k or pr.shape[2] != 2 or std.shape != pr.shape[:2]:
        raise CalibrationError(
            f"pairs {np.shape(pairs)} and distances {np.shape(standard_mm)} must be (M, 2), (M,)"
        )
    if pr.shape[1] < 8:
        raise CalibrationError(
            f"{pr.shape[1]} calibrator distances given; Eq. 25 needs at least 8 for redundancy"
        )
    if np.any(std <= 0):
        bad = int(np.argmax((std <= 0).any(axis=0)))
        value = std[:, bad][std[:, bad] <= 0][0]
        raise CalibrationError(f"standard distance #{bad + 1} is {value:g} mm; distances are > 0")
    if not (math.isfinite(rcond) and 0 <= rcond < 1):
        raise CalibrationError(f"rcond = {rcond} must lie in [0, 1)")
    if np.any(pr[..., 0] == pr[..., 1]) or pr.min() < 0 or pr.max() >= m:
        raise CalibrationError(f"pairs must join two different targets among {m}")
    sets = np.arange(k)[:, None]
    diff = p[sets, pr[..., 0]] - p[sets, pr[..., 1]]
    length = np.linalg.norm(diff, axis=-1)
    if np.any(length < 1e-9):
        raise CalibrationError("two targets of a pair coincide (distance 0 mm)")
    cosines = diff / length[..., None]
    a = np.zeros((k, pr.shape[1], 3 * m))
    rows = np.arange(pr.shape[1])[None, :]
    for axis in range(3):
        a[sets, rows, 3 * pr[..., 0] + axis] = cosines[..., axis]
        a[sets, rows, 3 * pr[..., 1] + axis] = -cosines[..., axis]
    if combine is None:
        solve = np.linalg.pinv(a, rcond=rcond)
        delta = (solve @ (std - length)[..., None]).reshape(p.shape)
        return p + delta, delta
    w = np.asarray(combine, dtype=float)
    if w.ndim != 2 or w.shape[0] != m:
        raise CalibrationError(f"combine must be ({m}, n), got {w.shape}")
    a = a @ np.kron(w, np.eye(3))
    solve = np.linalg.pinv(a, rcond=rcond)
    delta_free = (solve @ (std - length)[..., None]).reshape(k, -1, 3)
    delta = w @ delta_free
    return p + delta, delta


# ----------------------------------------------------------------------------------------------
# hand-eye (Eq. 13-22)


#: smallest rotation (rad) of a move, and smallest angle between the axes of two moves, that
#: the preliminary AX = XB accepts
MIN_MOVE_ROTATION = 1e-3


def motion_axes(flange2base) -> tuple[np.ndarray, np.ndarray]:
    """Unit rotation axes ``(N - 1, 3)`` and angles (rad) of the moves from pose 0 to the others."""
    g = geo.check_transform("flange poses", flange2base)
    rel = np.einsum("ij,njk->nik", g[0, :3, :3].T, g[1:, :3, :3])
    rv = geo.matrix_to_rotvec(rel)
    angle = np.linalg.norm(rv, axis=1)
    return rv / np.maximum(angle, 1e-300)[:, None], angle


def preliminary_handeye(flange2base, calibrator2sensor, method: str = "Park") -> np.ndarray:
    """The preliminary ``sensor2flange`` from AX = XB (Eq. 13) by a closed-form solver.

    The paper cites Shiu and Ahmad's formulation; OpenCV does not implement that solver, so the
    closed-form solvers of ``cv2.calibrateHandEye`` stand in (Park-Martin by default), after
    the library's motion check (:func:`calstudy.estimators.axxb.check_rotation_diversity`): two
    moves rotating by :data:`MIN_MOVE_ROTATION` or more about axes that far apart.
    """
    if method not in OPENCV_METHODS:
        raise CalibrationError(f"unknown method {method!r}; use one of {list(OPENCV_METHODS)}")
    return opencv_handeye(flange2base, calibrator2sensor, method, MIN_MOVE_ROTATION)


def correct_transformation(
    flange2base, sensor2flange, measured, modified
) -> tuple[np.ndarray, np.ndarray]:
    """Transformation error correction (Eq. 14-22): update ``sensor2flange`` by a small motion.

    A fixed target seen in poses ``i`` and ``j`` must map to the same base point. With the
    preliminary ``H_gc``, ``X_b^i = H_g^i H_gc X_c^i`` (Eq. 14). Writing the update as
    ``H_gc (I + nu)`` with ``nu X = sigma + omega x X`` (Eq. 17) gives, for every target and pose
    pair, Eq. 21: ``V = U d_eta`` with ``V = X_b^i - X_b^j + R_bc^i dX^i - R_bc^j dX^j``,
    ``U = R_bc^j P_j - R_bc^i P_i`` and ``P = [I, -[X^R]_x]`` (Eq. 19) at the modified
    coordinates ``X^R``. ``d_eta = (sigma, omega)`` is the Moore-Penrose least-norm solution
    (Eq. 22). The update is applied as the rigid motion ``exp(d_eta)`` (equal to ``I + nu`` to
    first order and keeping the matrix a rigid transform).

    Parameters
    ----------
    flange2base : (N, 4, 4) array
        Flange poses reported by the robot, N >= 2.
    sensor2flange : (4, 4) array
        Preliminary ``H_gc``.
    measured, modified : (N, m, 3) arrays
        Target centres in the sensor frame as measured and after the observed-error
        modification (the same array twice if there is none).

    Returns
    -------
    updated : (4, 4) array
        Updated ``sensor2flange``.
    d_eta : (6,) array
        ``(sigma_x, sigma_y, sigma_z, omega_x, omega_y, omega_z)``, mm and rad.

    Raises
    ------
    CalibrationError
        If the inputs are not finite rigid poses and matching points, or the six parameters
        of the update are not all determined (the smallest singular value of ``U`` below
        :data:`UPDATE_RCOND` times the largest: identical poses, rotations about one axis,
        fewer than 3 targets off a line); the least-norm solution would then silently return
        an update of only part of the hand-eye matrix.
    """
    g = geo.check_transform("flange poses", flange2base)
    h = geo.check_transform("sensor2flange", sensor2flange)
    xc = geo.check_finite("measured points", measured)
    xr = geo.check_finite("modified points", modified)
    if g.ndim != 3 or g.shape[0] < 2 or xc.shape != xr.shape or xc.shape[:1] != g.shape[:1]:
        raise CalibrationError(
            f"need N >= 2 flange poses {g.shape} and points (N, m, 3) {xc.shape}, {xr.shape}"
        )
    sensor2base = g @ h
    rot = sensor2base[:, :3, :3]
    xb = np.einsum("nij,nmj->nmi", rot, xc) + sensor2base[:, None, :3, 3]
    dx_b = np.einsum("nij,nmj->nmi", rot, xr - xc)
    skew = geo.skew(xr)
    p = np.concatenate([np.broadcast_to(np.eye(3), skew.shape), -skew], axis=-1)  # Eq. 19
    rp = np.einsum("nij,nmjk->nmik", rot, p)
    rows_u, rows_v = [], []
    for i, j in itertools.combinations(range(g.shape[0]), 2):
        rows_v.append((xb[i] - xb[j] + dx_b[i] - dx_b[j]).reshape(-1))
        rows_u.append((rp[j] - rp[i]).reshape(-1, 6))
    u = np.concatenate(rows_u)
    v = np.concatenate(rows_v)
    sv = np.linalg.svd(u, compute_uv=False)
    if sv[0] == 0 or sv[-1] / sv[0] < UPDATE_RCOND:
        raise CalibrationError(
            f"the update of Eq. 21 is unobservable from these {g.shape[0]} poses and "
            f"{xc.shape[1]} targets (condition number "
            f"{sv[0] / sv[-1] if sv[-1] > 0 else math.inf:.3g}, allowed {1 / UPDATE_RCOND:.3g}): "
            "the poses must rotate about two axes and see at least 3 targets not on a line"
        )
    d_eta = np.linalg.pinv(u) @ v
    return h @ geo.exp6(d_eta), d_eta
