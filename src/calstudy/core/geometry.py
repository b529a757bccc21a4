"""Rigid transforms as 4 x 4 numpy arrays, and the checks every estimator runs on its input.

Conventions (see DESIGN): a transform is named for what it maps, ``sensor2flange`` takes points
in the sensor frame to the flange frame, ``p_flange = sensor2flange @ p_sensor``. Millimetres and
radians throughout. Rotations are converted with :mod:`scipy.spatial.transform` and rigid motions
with :mod:`pinocchio` where a library already does the job.

Checks: the ``check_*`` functions below are what estimators run at their entry. The elementary
kernels (:func:`make_transform`, :func:`invert`, :func:`apply`, :func:`rotvec_to_matrix`,
:func:`matrix_to_rotvec`, :func:`pose_from_vector`, :func:`pose_to_vector`,
:func:`rotation_angle`) run inside solvers' residuals, thousands of times per fit, and do not
check: they return finite values for finite input and pass NaN through; their callers check
their own input once. The converters a user calls directly (:func:`euler_zyx_to_matrix`,
:func:`matrix_to_euler_zyx`, :func:`project_to_so3`, :func:`mean_transform`) refuse non-finite
input.
"""

from __future__ import annotations

import math

import numpy as np

from calstudy.core.errors import CalibrationError

ORTHONORMAL_TOL = 1e-6


# ----------------------------------------------------------------------------------------------
# checks


def _rotation():
    """scipy's ``Rotation``, imported on first use (scipy.spatial takes most of a second)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _pin():
    """Pinocchio, imported on first use."""
    import pinocchio

    return pinocchio


def _as_float(name: str, array) -> np.ndarray:
    """``array`` as a float array; CalibrationError if it is ragged or holds non-numbers."""
    try:
        return np.asarray(array, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"{name} is not an array of numbers ({exc})") from None


def check_finite(name: str, array) -> np.ndarray:
    """Return ``array`` as float array; raise if it holds NaN or infinity (naming the first)."""
    a = _as_float(name, array)
    bad = ~np.isfinite(a)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise CalibrationError(
            f"{name} holds a non-finite value ({float(a[idx])!r}) at index {idx}"
        )
    return a


def check_shape(name: str, array, shape: tuple) -> np.ndarray:
    """Return ``array`` as a finite float array of ``shape``; ``None`` entries match any length.

    Raises
    ------
    CalibrationError
        If the number of axes or a fixed length differs, or a value is not finite.
    """
    a = _as_float(name, array)
    ok = a.ndim == len(shape) and all(
        s is None or s == n for s, n in zip(shape, a.shape, strict=True)
    )
    if not ok:
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise CalibrationError(f"{name} has shape {a.shape}; expected {want}")
    return check_finite(name, a)


def check_rotation(name: str, rotation, tol: float = ORTHONORMAL_TOL) -> np.ndarray:
    """Return ``rotation`` (3 x 3 or N x 3 x 3) after checking it is a proper rotation.

    Raises
    ------
    CalibrationError
        If ``R^T R`` differs from the identity by more than ``tol`` or ``det R`` is not +1.
    """
    r = np.asarray(rotation, dtype=float)
    if r.shape[-2:] != (3, 3):
        raise CalibrationError(f"{name} has shape {r.shape}; expected (3, 3) or (N, 3, 3)")
    check_finite(name, r)
    gram = np.einsum("...ji,...jk->...ik", r, r) - np.eye(3)
    dev = np.abs(gram).reshape(-1, 9).max(axis=1)
    det = np.linalg.det(r.reshape(-1, 3, 3))
    worst = int(np.argmax(np.maximum(dev, np.abs(det - 1.0))))
    if dev[worst] > tol:
        raise CalibrationError(
            f"{name} is not orthonormal (max |R^T R - I| = {dev[worst]:.3g} at item {worst}, "
            f"tolerance {tol:g}); if the rotations are rounded values, re-project them to SO(3) "
            "(project_to_so3), as calibrate_handeye does up to its ortho_tol"
        )
    if det[worst] < 0:
        raise CalibrationError(f"{name} is a reflection (det = {det[worst]:.6g} at item {worst})")
    if abs(det[worst] - 1.0) > tol:
        raise CalibrationError(
            f"{name} is not orthonormal (det = {det[worst]:.9g} at item {worst}, tolerance "
            f"{tol:g}); if the rotations are rounded values, re-project them to SO(3) "
            "(project_to_so3), as calibrate_handeye does up to its ortho_tol"
        )
    return r


def _is_rigid_4x4(t: np.ndarray, tol: float) -> bool:
    """True if the single ``(4, 4)`` float array ``t`` is finite, has the bottom row
    ``[0 0 0 1]`` and a rotation block with ``|R^T R - I| <= tol`` and ``|det R - 1| <= tol``.

    The same tests as :func:`check_transform`, on Python floats: a dozen numpy calls on a 4 x 4
    array cost several times more than the arithmetic, and a Monte Carlo trial checks hundreds of
    transforms. False sends the caller to the full check, which says what is wrong.
    """
    v = t.ravel().tolist()
    if not math.isfinite(sum(v)):  # a NaN or infinity (or a sum past 1e308: the full check)
        return False
    if max(abs(v[12]), abs(v[13]), abs(v[14]), abs(v[15] - 1.0)) > tol:
        return False
    cols = ((v[0], v[4], v[8]), (v[1], v[5], v[9]), (v[2], v[6], v[10]))
    for i in range(3):
        a = cols[i]
        for j in range(i, 3):
            b = cols[j]
            dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
            if abs(dot - (1.0 if i == j else 0.0)) > tol:
                return False
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = cols
    det = a0 * (b1 * c2 - b2 * c1) - b0 * (a1 * c2 - a2 * c1) + c0 * (a1 * b2 - a2 * b1)
    return abs(det - 1.0) <= tol


def check_transform(name: str, transform, tol: float = ORTHONORMAL_TOL) -> np.ndarray:
    """Return ``transform`` (4 x 4 or N x 4 x 4) after checking shape, bottom row and rotation."""
    single = isinstance(transform, np.ndarray) and transform.shape == (4, 4)
    if single and transform.dtype == np.float64 and _is_rigid_4x4(transform, tol):
        return transform
    t = np.asarray(transform, dtype=float)
    if t.shape[-2:] != (4, 4):
        raise CalibrationError(f"{name} has shape {t.shape}; expected (4, 4) or (N, 4, 4)")
    if t.size == 0:
        raise CalibrationError(f"{name} holds no transforms (shape {t.shape})")
    check_finite(name, t)
    bottom = np.abs(t[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max()
    if bottom > tol:
        raise CalibrationError(f"{name} has bottom row different from [0 0 0 1] (by {bottom:.3g})")
    check_rotation(name + " rotation", t[..., :3, :3], tol)
    return t


# ----------------------------------------------------------------------------------------------
# construction and algebra


def skew(v) -> np.ndarray:
    """Cross-product matrices ``[v]x`` with ``[v]x w = v x w``, batched: (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _so3_terms(rotvec, small_angle: float):
    """Cross-product matrices, the mask of angles below ``small_angle`` and the angles (1 where
    small) of rotation vectors: (N, 3) -> (N, 3, 3), (N,), (N,)."""
    rotvec = np.atleast_2d(rotvec)
    theta = np.linalg.norm(rotvec, axis=1)
    small = theta < small_angle
    return skew(rotvec), small, np.where(small, 1.0, theta)


def so3_left_jacobian(rotvec) -> np.ndarray:
    """Left Jacobian ``(N, 3, 3)`` of SO(3): ``exp(w + d) = exp(J_l(w) d) exp(w)``, first order.

    The right Jacobian, ``exp(w + d) = exp(w) exp(J_r(w) d)``, is ``J_l(-w)``.
    """
    k, small, th = _so3_terms(rotvec, 1e-8)
    a = np.where(small, 0.5, (1 - np.cos(th)) / th**2)
    b = np.where(small, 1.0 / 6.0, (th - np.sin(th)) / th**3)
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * (k @ k)


def so3_right_jacobian_inverse(rotvec) -> np.ndarray:
    """Inverse of the right Jacobian of SO(3) (:func:`so3_left_jacobian` of ``-w``): (N, 3) ->
    (N, 3, 3)."""
    k, small, th = _so3_terms(rotvec, 1e-6)
    c = np.where(small, 1.0 / 12.0, 1.0 / th**2 - (1.0 + np.cos(th)) / (2.0 * th * np.sin(th)))
    return np.eye(3) + 0.5 * k + c[:, None, None] * (k @ k)


def make_transform(rotation, translation) -> np.ndarray:
    """Build 4 x 4 transforms from rotations ``(..., 3, 3)`` and translations ``(..., 3)`` in mm."""
    r = np.asarray(rotation, dtype=float)
    t = np.asarray(translation, dtype=float)
    shape = np.broadcast_shapes(r.shape[:-2], t.shape[:-1])
    out = np.zeros(shape + (4, 4))
    out[..., :3, :3] = r
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def invert(transform) -> np.ndarray:
    """Inverse of rigid transforms ``(..., 4, 4)``, using ``R^T`` rather than a general inverse."""
    t = np.asarray(transform, dtype=float)
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    return make_transform(rt, -np.einsum("...ij,...j->...i", rt, t[..., :3, 3]))


def apply(transform, points) -> np.ndarray:
    """Map points ``(..., 3)`` by a transform ``(4, 4)``: ``R p + t``."""
    t = np.asarray(transform, dtype=float)
    p = np.asarray(points, dtype=float)
    return p @ t[:3, :3].T + t[:3, 3]


def rotvec_to_matrix(rotvec) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` (axis x angle, rad)."""
    rv = np.asarray(rotvec, dtype=float)
    return _rotation().from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(rv.shape[:-1] + (3, 3))


def matrix_to_rotvec(rotation) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` of rotation matrices ``(..., 3, 3)``."""
    r = np.asarray(rotation, dtype=float)
    return _rotation().from_matrix(r.reshape(-1, 3, 3)).as_rotvec().reshape(r.shape[:-2] + (3,))


def pose_from_vector(vec) -> np.ndarray:
    """Transform from a 6-vector ``[tx, ty, tz, rx, ry, rz]`` (mm, rotation vector in rad)."""
    v = np.asarray(vec, dtype=float)
    return make_transform(rotvec_to_matrix(v[..., 3:]), v[..., :3])


def pose_to_vector(transform) -> np.ndarray:
    """Inverse of :func:`pose_from_vector`."""
    t = np.asarray(transform, dtype=float)
    return np.concatenate([t[..., :3, 3], matrix_to_rotvec(t[..., :3, :3])], axis=-1)


def exp6(twist) -> np.ndarray:
    """SE(3) exponential of a twist ``[v, w]`` (Pinocchio's ``exp6``), as a 4 x 4 array."""
    return _pin().exp6(np.asarray(twist, dtype=float)).homogeneous


def log6(transform) -> np.ndarray:
    """SE(3) logarithm ``[v, w]`` of a 4 x 4 transform (Pinocchio's ``log6``)."""
    t = np.asarray(transform, dtype=float)
    return np.asarray(_pin().log6(_pin().SE3(t[:3, :3], t[:3, 3])).vector)


def euler_zyx_to_matrix(a, b, c) -> np.ndarray:
    """Rotation ``Rz(a) Ry(b) Rx(c)`` from angles in degrees (the KUKA A, B, C convention).

    Parameters
    ----------
    a, b, c : float or array_like, broadcastable
        The angles A, B, C in degrees.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)

    Raises
    ------
    CalibrationError
        If an angle is not a finite number.
    """
    try:
        angles = np.stack(np.broadcast_arrays(a, b, c), axis=-1).astype(float, copy=False)
    except (ValueError, TypeError) as exc:
        raise CalibrationError(
            f"Euler angles A, B, C are not numbers of one shape: {exc}"
        ) from None
    if not np.isfinite(angles).all():
        check_finite("Euler angles (A, B, C) in deg", angles)
    flat = angles.reshape(-1, 3)
    mats = _rotation().from_euler("ZYX", flat, degrees=True).as_matrix()
    return mats.reshape(angles.shape[:-1] + (3, 3))


def matrix_to_euler_zyx(rotation) -> np.ndarray:
    """Angles ``(A, B, C)`` in degrees with ``R = Rz(A) Ry(B) Rx(C)``; inverse of the above.

    Raises
    ------
    CalibrationError
        If ``rotation`` is not ``(..., 3, 3)`` or holds a non-finite value.
    """
    r = check_finite("rotation", rotation)
    if r.shape[-2:] != (3, 3):
        raise CalibrationError(f"rotation has shape {r.shape}; expected (..., 3, 3)")
    out = _rotation().from_matrix(r.reshape(-1, 3, 3)).as_euler("ZYX", degrees=True)
    return out.reshape(r.shape[:-2] + (3,))


def project_to_so3(matrix) -> np.ndarray:
    """Nearest rotation (Frobenius norm) to a 3 x 3 matrix, by SVD with a determinant fix.

    Raises
    ------
    CalibrationError
        If ``matrix`` holds a non-finite value.
    """
    u, _, vt = np.linalg.svd(check_finite("matrix to project to SO(3)", matrix))
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def mean_transform(transforms) -> np.ndarray:
    """Average ``(4, 4)`` of rigid transforms ``(N, 4, 4)``: the mean translation and the mean
    rotation matrix projected to SO(3) (:func:`project_to_so3`), a good average of rotations
    that differ little.

    Raises
    ------
    CalibrationError
        On a bad shape, non-finite values or non-orthonormal rotations.
    """
    t = check_transform("transforms", transforms)
    return make_transform(project_to_so3(t[:, :3, :3].mean(axis=0)), t[:, :3, 3].mean(0))


# ----------------------------------------------------------------------------------------------
# errors and random draws


def rotation_angle(rotation) -> np.ndarray:
    """Angle in rad of rotations ``(..., 3, 3)``, robust near 0 and pi.

    ``atan2(|v|, tr R - 1)`` with ``v = (R32 - R23, R13 - R31, R21 - R12)``: ``|v| = 2 sin a``
    and ``tr R - 1 = 2 cos a``, each known to a few ulps, so the angle is accurate to about
    1e-16 rad at every angle (an arccos of the trace alone loses half the digits near 0). It
    agrees with scipy's ``Rotation.from_matrix(R).magnitude()`` to 1e-14 rad (a test checks it)
    at a sixth of the cost, which matters for the hundreds of errors a Monte Carlo trial scores.
    """
    r = np.asarray(rotation, dtype=float)
    if r.shape[-2:] != (3, 3):
        raise CalibrationError(f"rotations have shape {r.shape}; expected (..., 3, 3)")
    v = np.stack(
        [r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]],
        axis=-1,
    )
    cos2 = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2] - 1.0
    return np.arctan2(np.sqrt(np.sum(v * v, axis=-1)), cos2)


#: above this angle (rad) :func:`so3_log` takes the axis from scipy (the skew part vanishes
#: near pi)
SO3_LOG_NEAR_PI = np.pi - 1e-2


def so3_log(rotation) -> np.ndarray:
    """Rotation vectors ``(N, 3)`` (rad) of proper rotation matrices ``(..., 3, 3)``, fast.

    ``v * a / |v|`` with ``v`` the skew part and ``a`` the angle of :func:`rotation_angle`
    (accurate at every angle; a fifth of the cost of scipy's conversion, which an iterative
    refinement calls at every evaluation); within 0.01 rad of pi, where the skew part loses the
    axis, scipy's conversion. It agrees with :func:`matrix_to_rotvec` to about 1e-15 rad, not
    bit for bit.

    Parameters
    ----------
    rotation : array_like, shape (..., 3, 3)
        Proper rotation matrices (not checked).

    Returns
    -------
    numpy.ndarray, shape (N, 3)
        Rotation vectors (axis times angle, rad), the leading axes flattened.
    """
    r = np.asarray(rotation, dtype=float).reshape(-1, 3, 3)
    v = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], 1)
    s = np.sqrt(np.sum(v * v, axis=1))
    ang = np.arctan2(s, r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2] - 1.0)
    out = v * np.where(s > 1e-300, ang / np.maximum(s, 1e-300), 0.5)[:, None]
    far = ang > SO3_LOG_NEAR_PI
    if np.any(far):
        out[far] = _rotation().from_matrix(r[far]).as_rotvec()
    return out


def so3_exp(rotvec) -> np.ndarray:
    """Rotation matrix ``(1, 3, 3)`` of one rotation vector, fast (Rodrigues' formula, its
    series below 1e-4 rad).

    For one vector inside an iterative refinement, where scipy's conversion
    (:func:`rotvec_to_matrix`) costs more than the formula; the two agree to about 1e-16, not
    bit for bit.

    Parameters
    ----------
    rotvec : array_like, shape (3,)
        Rotation vector (axis times angle, rad).

    Returns
    -------
    numpy.ndarray, shape (1, 3, 3)
        The rotation matrix.
    """
    v = np.asarray(rotvec, dtype=float).reshape(3)
    th2 = float(v @ v)
    k = skew(v)
    if th2 < 1e-8:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = np.sqrt(th2)
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th2
    return (np.eye(3) + a * k + b * (k @ k))[None]


def rotation_error(estimate, truth) -> np.ndarray:
    """Angle in rad of ``R_truth^T R_est`` for rotations or transforms ``(..., 3|4, 3|4)``."""
    e = np.asarray(estimate, dtype=float)[..., :3, :3]
    t = np.asarray(truth, dtype=float)[..., :3, :3]
    return rotation_angle(np.swapaxes(t, -1, -2) @ e)


def translation_error(estimate, truth) -> np.ndarray:
    """Euclidean distance in mm between the translations of two transforms ``(..., 4, 4)``."""
    e = np.asarray(estimate, dtype=float)
    t = np.asarray(truth, dtype=float)
    return np.linalg.norm(e[..., :3, 3] - t[..., :3, 3], axis=-1)


def random_rotation(rng: np.random.Generator, size: int | None = None) -> np.ndarray:
    """Uniformly distributed rotations, ``(3, 3)`` or ``(size, 3, 3)``.

    Raises
    ------
    CalibrationError
        If ``size`` is not None or an integer >= 0.
    """
    if size is not None and not (isinstance(size, int | np.integer) and size >= 0):
        raise CalibrationError(f"random_rotation: size = {size!r} must be None or an integer >= 0")
    return _rotation().random(size, random_state=rng).as_matrix()


def perturb(transform, sigma_rot: float, sigma_trans: float, rng: np.random.Generator):
    """Right-multiply by a small random motion: rotation vector ~ N(0, sigma_rot^2 I) in rad,
    translation ~ N(0, sigma_trans^2 I) in mm. Works on ``(4, 4)`` or ``(N, 4, 4)``.

    Raises
    ------
    CalibrationError
        If a sigma is negative or not finite.
    """
    if not (math.isfinite(sigma_rot) and sigma_rot >= 0):
        raise CalibrationError(f"perturb: sigma_rot = {sigma_rot} rad must be finite and >= 0")
    if not (math.isfinite(sigma_trans) and sigma_trans >= 0):
        raise CalibrationError(f"perturb: sigma_trans = {sigma_trans} mm must be finite and >= 0")
    t = np.asarray(transform, dtype=float)
    lead = t.shape[:-2]
    d = make_transform(
        rotvec_to_matrix(rng.normal(0.0, sigma_rot, lead + (3,))),
        rng.normal(0.0, sigma_trans, lead + (3,)),
    )
    return t @ d


def _cross3(a: np.ndarray, b) -> np.ndarray:
    """``np.cross`` of two 3-vectors with the same products and differences (the same bytes),
    without its axis handling, which costs some 20 times the arithmetic on 3 numbers."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = (b.tolist() if isinstance(b, np.ndarray) else b)
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of the rows of two ``(N, 3)`` arrays with the same products and differences
    (the same bytes) as :func:`_cross3`, without np.cross's axis handling, which dominates for a
    few rows."""
    a0, a1, a2 = a.T
    b0, b1, b2 = b.T
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def _norm3(v: np.ndarray) -> float:
    """``np.linalg.norm`` of a float 3-vector, as it computes it (``sqrt(v . v)``, the same
    bytes), without its argument handling, which costs several times the arithmetic."""
    return math.sqrt(v.dot(v))


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world transform of a camera at ``eye`` with its optical (+z) axis on ``target``.

    The camera x axis is horizontal (perpendicular to ``up``); if the viewing direction is parallel
    to ``up``, the world x axis is used as the reference instead.

    Raises
    ------
    CalibrationError
        If eye and target coincide, or eye, target or up is not finite.
    """
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    norm = _norm3(z)
    if norm == 0:
        raise CalibrationError("look_at: eye and target coincide (distance 0 mm)")
    if not (math.isfinite(norm) and math.isfinite(_norm3(np.asarray(up, dtype=float)))):
        raise CalibrationError(f"look_at: eye {eye}, target {target} and up {up} must be finite")
    z = z / norm
    x = _cross3(z, np.asarray(up, dtype=float))
    if _norm3(x) < 1e-9:
        x = _cross3(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else _cross3(z, [0.0, 1.0, 0.0])
    x /= _norm3(x)
    y = _cross3(z, x)
    out = np.zeros((4, 4))
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = x, y, z, eye
    out[3, 3] = 1.0
    return out


# ----------------------------------------------------------------------------------------------
# point sets

#: Relative size of the smallest singular value (to the largest) below which a point set is
#: treated as exactly degenerate (collinear or coplanar). It catches exact degeneracy and
#: round-off; a nearly degenerate noisy set passes and gives a poorly determined answer.
RANK_RTOL = 1e-9





def check_points(
    name: str, array, dim: int, at_least: int, what: str, noun: str = "points"
) -> np.ndarray:
    """Check an ``(N, dim)`` finite array with ``N >= at_least``."""
    a = check_shape(name, array, (None, dim))
    if a.shape[0] < at_least:
        raise CalibrationError(f"{what} needs at least {at_least} {noun}; got {a.shape[0]}")
    return a


def check_same_length(name_a: str, a: np.ndarray, name_b: str, b: np.ndarray) -> None:
    if a.shape[0] != b.shape[0]:
        raise CalibrationError(
            f"{name_a} has {a.shape[0]} rows but {name_b} has {b.shape[0]}; they must pair up"
        )


def singular_values(centred: np.ndarray) -> np.ndarray:
    return np.linalg.svd(centred, compute_uv=False)


def format_values(values) -> str:
    return ", ".join(f"{v:.3g}" for v in values)


def is_rank_deficient(s: np.ndarray, rank: int) -> bool:
    """True if fewer than ``rank`` singular values are significant."""
    return s.size < rank or s[0] == 0.0 or s[rank - 1] <= RANK_RTOL * s[0]


def check_not_collinear(name: str, points: np.ndarray) -> None:
    """Raise if the rows of ``points`` lie on one line (centred rank < 2).

    Points in the plane ``(N, 2)`` far from a line are accepted in closed form: the eigenvalues
    of the 2 x 2 scatter matrix (the squared singular values, each off by a few ulps of the
    larger); a ratio above 1e-12 (singular values 1e-6 apart, far from the ``RANK_RTOL`` of the
    check) passes at once, anything else goes through the singular values, which decide and
    word the error.
    """
    if points.ndim == 2 and points.shape[1] == 2:
        q = points - points.mean(axis=0)
        (sxx, sxy), (_, syy) = (q.T @ q).tolist()
        mid, half = 0.5 * (sxx + syy), math.hypot(0.5 * (sxx - syy), sxy)
        if mid - half > 1e-12 * (mid + half) > 0.0:
            return
    _check_not_collinear_svd(name, points)


def _check_not_collinear_svd(name: str, points: np.ndarray) -> None:
    """:func:`check_not_collinear` by the singular values of the centred points alone."""
    s = singular_values(points - points.mean(axis=0))
    if is_rank_deficient(s, 2):
        raise CalibrationError(
            f"the {points.shape[0]} {name} are collinear (singular values {format_values(s)})"
        )
