"""Circle fits in the plane: the algebraic (Kasa) fit and the geometric refinement, batched.

Used by the line-laser sensor model (:mod:`calstudy.models.sensors`) to find the stripe's circle,
and by estimators that fit circles.
"""

from __future__ import annotations

import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import check_not_collinear, check_points

CIRCLE_METHODS = ("kasa", "geometric")
#: Shortest arc (deg, about the fitted centre) :func:`fit_circle_2d` accepts: on a shorter arc
#: the radius rests on the sagitta alone (``r theta^2 / 8``, 0.4 % of the radius at 10 deg) and
#: a scatter of a thousandth of the radius moves it by tens of percent.
MIN_ARC_DEG = 10.0
#: The points' bend (largest distance from their best-fit line) must reach this many RMS
#: residuals of the fitted circle, or the circle fits the scatter rather than a curvature.
MIN_BEND_TO_RESIDUAL = 5.0


def _solve_sym3(m: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``M x = rhs`` for a stack of symmetric 3 x 3 systems ``(M, 3, 3)``, ``(M, 3)``; a
    singular system (a point at the centre, coincident points) gives NaN for its set alone, which
    the caller refuses as a non-finite fit."""
    try:
        return np.linalg.solve(m, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        out = np.full(rhs.shape, np.nan)
        ok = np.abs(np.linalg.det(m)) > 0
        if ok.any():
            out[ok] = np.linalg.solve(m[ok], rhs[ok][..., None])[..., 0]
        return out


def _kasa_batch(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kasa fits of ``(M, N, 2)`` point sets through their normal equations.

    Each set is centred (so the normal equations decouple the constant term) and scaled to unit
    RMS radius; the remaining 2 x 2 system has the condition number of the point scatter.
    """
    mean = p.mean(axis=1, keepdims=True)
    q = p - mean
    scale = np.sqrt((q**2).sum(axis=2).mean(axis=1))
    u, v = q[..., 0] / scale[:, None], q[..., 1] / scale[:, None]
    b = u**2 + v**2
    suu, suv, svv = (u * u).sum(1), (u * v).sum(1), (v * v).sum(1)
    sub, svb = (u * b).sum(1), (v * b).sum(1)
    det = suu * svv - suv**2
    # x^2 + y^2 = 2 a x + 2 b y + c; as sum(u) = sum(v) = 0 the normal equations decouple:
    # 2 [suu suv; suv svv] (a, b) = (sub, svb) and c = mean(b)
    a_c = 0.5 * (svv * sub - suv * svb) / det
    b_c = 0.5 * (suu * svb - suv * sub) / det
    c = b.mean(axis=1)
    with np.errstate(invalid="ignore"):
        radii = np.sqrt(c + a_c**2 + b_c**2) * scale
    centres = mean[:, 0, :] + np.column_stack([a_c, b_c]) * scale[:, None]
    return centres, radii


def _geometric_batch(
    p: np.ndarray, centres: np.ndarray, radii: np.ndarray, max_iter: int = 50
) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton on ``sum (|p_i - c| - r)^2`` for every set, from a given start."""
    n = p.shape[1]
    c, r = centres.copy(), radii.copy()
    for _ in range(max_iter):
        diff = p - c[:, None, :]
        rho = np.sqrt((diff**2).sum(axis=2))
        ux, uy = diff[..., 0] / rho, diff[..., 1] / rho
        res = rho - r[:, None]
        # J = [-ux, -uy, -1] per point; normal equations J^T J step = -J^T res
        sx, sy = ux.sum(1), uy.sum(1)
        jtj = np.stack(
            [
                np.stack([(ux * ux).sum(1), (ux * uy).sum(1), sx], axis=1),
                np.stack([(ux * uy).sum(1), (uy * uy).sum(1), sy], axis=1),
                np.stack([sx, sy, np.full_like(sx, n)], axis=1),
            ],
            axis=1,
        )
        jtr = np.column_stack([(ux * res).sum(1), (uy * res).sum(1), res.sum(1)])
        step = _solve_sym3(jtj, jtr)
        c += step[:, :2]
        r += step[:, 2]
        if np.all(np.abs(step) <= 1e-13 * (1.0 + np.abs(r[:, None]))):
            break
    return c, r


def fit_circles_2d_batch(points, method: str = "kasa") -> tuple[np.ndarray, np.ndarray]:
    """Circle fits of ``M`` point sets at once, vectorised, without input checks.

    ``"kasa"``: the algebraic fit ``x^2 + y^2 = 2 a x + 2 b y + c`` in the least-squares sense,
    through its normal equations after centring and scaling each set (for conditioning).
    ``"geometric"``: the Kasa fit refined by Gauss-Newton on the orthogonal distances
    ``|p_i - c| - r`` until the step is below 1e-13 of the radius: the maximum-likelihood circle
    for i.i.d. isotropic Gaussian point noise. It removes the Kasa fit's bias on arcs (the Kasa
    radius shrinks and its centre moves towards the arc, by an amount of order ``sigma^2 / r``
    that grows as the arc gets shorter).

    Parameters
    ----------
    points : numpy.ndarray, shape (M, N, 2)
        ``M`` sets of ``N >= 3`` non-collinear points each (the caller guarantees it).
    method : {"kasa", "geometric"}

    Returns
    -------
    centres : numpy.ndarray, shape (M, 2)
    radii : numpy.ndarray, shape (M,)
        In the unit of ``points``. ``nan`` where ``r^2`` came out negative (cannot happen for
        points that fit a circle).
    """
    if method not in CIRCLE_METHODS:
        raise CalibrationError(f"circle fit method must be one of {CIRCLE_METHODS}; got {method!r}")
    p = np.asarray(points, dtype=float)
    centres, radii = _kasa_batch(p)
    if method == "geometric":
        centres, radii = _geometric_batch(p, centres, radii)
    return centres, radii


def fit_circle_2d(points, method: str = "kasa") -> tuple[np.ndarray, float]:
    """Circle through 2-D points by the algebraic (Kasa) linear least-squares fit.

    Minimises ``sum (x^2 + y^2 - 2 a x - 2 b y - c)^2``; centre ``(a, b)``, radius
    ``sqrt(c + a^2 + b^2)``. Exact for points on a circle; under noise it is biased towards
    smaller radii on arcs (a known property of the Kasa fit). ``method="geometric"`` refines it
    to the orthogonal-distance (maximum-likelihood) circle; see :func:`fit_circles_2d_batch`.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        ``N >= 3`` points, not all on a line, in any length unit (mm here).
    method : {"kasa", "geometric"}

    Returns
    -------
    centre : numpy.ndarray, shape (2,)
    radius : float

    Raises
    ------
    CalibrationError
        On wrong shapes, non-finite values, fewer than 3 points or collinear points; when the
        circle is ill-conditioned: the points span less than :data:`MIN_ARC_DEG` about its
        centre, or their bend away from a line is below :data:`MIN_BEND_TO_RESIDUAL` times the
        circle's RMS residual (an arc too short for its scatter); or when the geometric
        refinement does not give a finite circle (a point at the centre).
    """
    p = check_points("points", points, 2, 3, "circle fit")
    check_not_collinear("points", p)
    if method not in CIRCLE_METHODS:
        raise CalibrationError(f"circle fit method must be one of {CIRCLE_METHODS}; got {method!r}")
    with np.errstate(divide="ignore", invalid="ignore"):
        centres, radii = fit_circles_2d_batch(p[None], method)
    centre, radius = centres[0], float(radii[0])
    if not (np.all(np.isfinite(centre)) and np.isfinite(radius) and radius > 0):
        raise CalibrationError(
            f"{method} circle fit of {len(p)} points gave no finite circle (centre {centre}, "
            f"radius {radius}): a point lies at the centre, or the points fit no circle"
        )
    _check_conditioning(p, centre, radius)
    return centre, radius


def _check_conditioning(p: np.ndarray, centre: np.ndarray, radius: float) -> None:
    """Refuse a circle that the points ``(N, 2)`` do not determine (see :func:`fit_circle_2d`)."""
    d = p - centre
    angles = np.sort(np.arctan2(d[:, 1], d[:, 0]))
    gaps = np.diff(np.append(angles, angles[0] + 2 * np.pi))
    arc = np.degrees(2 * np.pi - gaps.max())
    if arc < MIN_ARC_DEG:
        raise CalibrationError(
            f"the {len(p)} points span an arc of {arc:.3g} deg about the fitted centre (radius "
            f"{radius:.4g}); a circle fit needs at least {MIN_ARC_DEG:g} deg: the radius of a "
            "shorter arc is ill-conditioned"
        )
    q = p - p.mean(axis=0)
    normal = np.linalg.svd(q, full_matrices=False)[2][-1]
    bend = float(np.abs(q @ normal).max())
    residual = float(np.sqrt(np.mean((np.linalg.norm(d, axis=1) - radius) ** 2)))
    if bend < MIN_BEND_TO_RESIDUAL * residual:
        raise CalibrationError(
            f"the {len(p)} points do not determine a circle: they bend {bend:.3g} away from a "
            f"line, only {bend / residual:.3g} times the RMS residual {residual:.3g} of the "
            f"fitted circle (radius {radius:.4g}; {MIN_BEND_TO_RESIDUAL:g} needed): an arc too "
            "short for its scatter (the radius is ill-conditioned), or points not on a circle"
        )
