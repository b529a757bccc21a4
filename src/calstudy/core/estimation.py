"""One result type for every estimator, and a thin Levenberg-Marquardt wrapper.

Every calibration in the study returns an :class:`Estimate`: the value (a transform or a
parameter vector), the parameter vector it was computed from, its covariance
``sigma^2 (J^T J)^-1`` at the solution, the residuals, the iteration count and the condition
number of the Jacobian. The covariance is what the book reports as the uncertainty of a result.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from calstudy.core.errors import CalibrationError


@dataclass
class Estimate:
    """Result of an estimator.

    Attributes
    ----------
    value
        The estimate in its natural form (a 4 x 4 transform, a vector, ...).
    params
        The parameter vector ``(n,)`` the covariance refers to.
    covariance
        ``(n, n)`` covariance of ``params`` (``None`` for closed-form estimators without one).
    residuals
        Residual vector ``(m,)`` at the solution, in the units of the problem (or whitened).
    iterations
        Iterations (or function evaluations, for LM) used; 0 for closed forms.
    condition_number
        Condition number of the Jacobian or design matrix at the solution.
    method
        Short name of the estimator.
    names
        Names of the entries of ``params``.
    history
        Per-iteration record (e.g. cost), empty if not kept.
    """

    value: Any
    params: np.ndarray
    covariance: np.ndarray | None = None
    residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    iterations: int = 0
    condition_number: float = float("nan")
    method: str = ""
    names: list[str] = field(default_factory=list)
    history: list[float] = field(default_factory=list)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of ``params`` (square roots of the covariance diagonal)."""
        if self.covariance is None:
            raise CalibrationError(f"{self.method or 'this estimate'} has no covariance")
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def cost(self) -> float:
        """Half the sum of squared residuals."""
        return 0.5 * float(self.residuals @ self.residuals)


def condition_number(matrix) -> float:
    """Ratio of the largest to the smallest singular value of ``matrix`` (inf if singular)."""
    s = np.linalg.svd(np.asarray(matrix, dtype=float), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def covariance_from_jacobian(
    jac: np.ndarray, residuals: np.ndarray, sigma: float | None = None
) -> tuple[np.ndarray, float]:
    """Covariance ``s^2 (J^T J)^-1`` of least-squares parameters and the condition number of J.

    Parameters
    ----------
    jac : (m, n) array
        Jacobian of the residuals at the solution.
    residuals : (m,) array
        Residuals at the solution.
    sigma : float, optional
        Known standard deviation of the residuals (1.0 for whitened residuals). If omitted it is
        estimated as ``sqrt(sum r^2 / (m - n))``.

    Returns
    -------
    covariance : (n, n) array
    condition_number : float
        Ratio of the largest to the smallest singular value of ``jac`` (inf if rank deficient).
    """
    m, n = jac.shape
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    if sigma is None:
        dof = m - n
        sigma = float(np.sqrt(residuals @ residuals / dof)) if dof > 0 else float("nan")
    keep = s > s[0] * 1e-12
    inv_s2 = np.zeros_like(s)
    inv_s2[keep] = 1.0 / s[keep] ** 2
    cov = (vt.T * inv_s2) @ vt * sigma**2
    return cov, cond


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    *,
    jac: Callable[[np.ndarray], np.ndarray] | str = "2-point",
    sigma: float | None = None,
    names: Sequence[str] | None = None,
    max_nfev: int | None = None,
    xtol: float = 1e-12,
    ftol: float = 1e-12,
    gtol: float = 1e-12,
    method: str = "lm",
    to_value: Callable[[np.ndarray], Any] | None = None,
    label: str = "Levenberg-Marquardt",
) -> Estimate:
    """Minimise ``sum fun(x)^2`` with scipy's Levenberg-Marquardt and return an :class:`Estimate`.

    Parameters
    ----------
    fun
        Residual function ``(n,) -> (m,)``, ``m >= n``.
    x0
        Starting point ``(n,)``.
    jac
        Analytic Jacobian ``(n,) -> (m, n)`` or a finite-difference scheme name.
    sigma
        Known residual standard deviation for the covariance (1.0 if residuals are whitened);
        estimated from the residuals when omitted.
    names
        Parameter names, stored in the result.
    max_nfev
        Evaluation budget; reaching it raises :class:`CalibrationError`.
    to_value
        Maps the solution vector to the result's ``value`` (default: the vector itself).
    label
        Name used in error messages and stored as ``method``.

    Raises
    ------
    CalibrationError
        If ``m < n``, if the residuals are not finite at the start, or if the solver stops without
        converging (the message gives the evaluation count and the cost).
    """
    x0 = np.asarray(x0, dtype=float)
    r0 = np.asarray(fun(x0), dtype=float)
    if not np.all(np.isfinite(r0)):
        raise CalibrationError(f"{label}: residuals are not finite at the starting point")
    if r0.size < x0.size:
        raise CalibrationError(
            f"{label}: {r0.size} equations for {x0.size} unknowns; need at least as many equations"
        )
    history: list[float] = []

    def wrapped(x):
        r = np.asarray(fun(x), dtype=float)
        history.append(0.5 * float(r @ r))
        return r

    res = least_squares(
        wrapped, x0, jac=jac, method=method, xtol=xtol, ftol=ftol, gtol=gtol, max_nfev=max_nfev
    )
    if res.status <= 0:
        raise CalibrationError(
            f"{label} did not converge after {res.nfev} evaluations (cost {res.cost:.6g}): "
            f"{res.message}"
        )
    cov, cond = covariance_from_jacobian(res.jac, res.fun, sigma)
    value = to_value(res.x) if to_value is not None else res.x
    return Estimate(
        value=value,
        params=res.x,
        covariance=cov,
        residuals=res.fun,
        iterations=int(res.nfev),
        condition_number=cond,
        method=label,
        names=list(names) if names is not None else [],
        history=history,
    )
