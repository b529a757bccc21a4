"""Circle fits in the plane: the algebraic (Kasa) fit and the geometric refinement, batched.

Used by the line-laser sensor model (:mod:`calstudy.models.sensors`) to find the stripe's circle,
and by estimators that fit circles.
"""

from __future__ import annotations

import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import check_not_collinear, check_points

CIRCLE_METHODS = ("kasa", "geometric")


def _solve_sym3(m: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``M x = rhs`` for a stack of symmetric 3 x 3 systems ``(M, 3, 3)``, ``(M, 3)``."""
    return np.linalg.solve(m, rhs[..., None])[..., 0]


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
        On wrong shapes, non-finite values, fewer than 3 points or collinear points.
    """
    p = check_points("points", points, 2, 3, "circle fit")
    check_not_collinear("points", p)
    centres, radii = fit_circles_2d_batch(p[None], method)
    return centres[0], float(radii[0])
