"""One result type for every estimator, and a thin Levenberg-Marquardt wrapper.

Every calibration in the study returns an :class:`Estimate`: the value (a transform or a
parameter vector), the parameter vector it was computed from, its covariance
``sigma^2 (J^T J)^-1`` at the solution, the residuals, the iteration count and the condition
number of the Jacobian. The covariance is what the book reports as the uncertainty of a result.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calstudy.core.errors import CalibrationError, CalibrationWarning

#: false-alarm probability of the goodness-of-fit test (two-sided) of :func:`goodness_of_fit`
FIT_ALPHA = 1e-4
#: how a failed goodness-of-fit test is handled: raise, or flag the result and warn, or ignore
MISFIT_POLICIES = ("raise", "flag", "off")


@dataclass
class FitCheck:
    """Goodness of fit of a least-squares estimate with whitened residuals.

    Attributes
    ----------
    chi2 : float
        Sum of squared whitened residuals.
    dof : int
        Degrees of freedom (residuals minus parameters); 0 when nothing is redundant.
    low, high : float
        Expected range of ``chi2 / dof`` (two-sided, false-alarm probability :data:`FIT_ALPHA`).
    message : str
        Empty when the fit is within its range; else what is wrong and which measurements
        disagree most.
    """

    chi2: float
    dof: int
    low: float
    high: float
    message: str = ""

    @property
    def chi2_dof(self) -> float:
        """``chi2 / dof`` (NaN without redundancy)."""
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def ok(self) -> bool:
        """True when ``chi2 / dof`` lies in its expected range (or cannot be tested)."""
        return not self.message

    @property
    def too_large(self) -> bool:
        """True when ``chi2 / dof`` exceeds its range: the measurements contradict the model or
        the stated noise; the estimate and its covariance are then not to be trusted."""
        return self.dof > 0 and self.chi2 / self.dof > self.high


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
    fit: FitCheck | None = None
    flags: list[str] = field(default_factory=list)

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


def goodness_of_fit(
    whitened,
    n_params: int,
    *,
    label: str,
    block: int = 1,
    block_names: Sequence[str] | None = None,
    alpha: float = FIT_ALPHA,
) -> FitCheck:
    """Compare ``chi2 / dof`` of whitened residuals with its expected range.

    Parameters
    ----------
    whitened : (m,) array
        Residuals divided by their standard deviations (unit variance if the model and the
        stated noise are right).
    n_params : int
        Number of estimated parameters.
    label : str
        Name of the estimator, for the message.
    block : int
        Residuals per measurement (3 for a point); the message names the measurements whose
        blocks disagree most.
    block_names : sequence of str, optional
        Names of the measurements (``m / block`` of them), e.g. ``"id 7"``.
    alpha : float
        Two-sided false-alarm probability of the test.

    Returns
    -------
    FitCheck
    """
    r = np.asarray(whitened, dtype=float).ravel()
    dof = int(r.size - n_params)
    chi2 = float(r @ r)
    if dof <= 0:
        return FitCheck(chi2, max(dof, 0), float("nan"), float("nan"))
    from scipy.stats import chi2 as _chi2  # lazy: scipy.stats takes about 1 s to import

    low = float(_chi2.ppf(alpha / 2, dof) / dof)
    high = float(_chi2.isf(alpha / 2, dof) / dof)
    ratio = chi2 / dof
    if low <= ratio <= high:
        return FitCheck(chi2, dof, low, high)
    head = (
        f"{label}: whitened residual chi2/dof = {ratio:.3g} with {dof} degrees of freedom, "
        f"outside its expected range [{low:.3g}, {high:.3g}] (whitened RMS "
        f"{np.sqrt(chi2 / r.size):.3g})"
    )
    if ratio < low:
        return FitCheck(
            chi2, dof, low, high, head + ": the residuals are smaller than the stated noise "
            "(is sigma overstated?)"
        )
    per = (r[: r.size - r.size % block].reshape(-1, block) ** 2).mean(axis=1)
    names = (
        list(block_names) if block_names is not None and len(block_names) == per.size
        else [f"measurement {i}" for i in range(per.size)]
    )
    worst = np.argsort(per)[::-1][:3]
    which = ", ".join(f"{names[i]} (RMS {np.sqrt(per[i]):.3g})" for i in worst)
    return FitCheck(
        chi2, dof, low, high, head + f": the measurements contradict the model or the stated "
        f"noise is too small; those that disagree most: {which}"
    )


def apply_fit_check(est: Estimate, check: FitCheck, policy: str) -> Estimate:
    """Store ``check`` in ``est`` and act on residuals too large for the stated noise by
    ``policy``: ``"raise"`` a :class:`CalibrationError`, ``"flag"`` (append the message to
    ``est.flags`` and warn with :class:`CalibrationWarning`) or ``"off"``. Residuals smaller
    than expected (noise-free data, an overstated sigma) only add a note to ``est.flags``: the
    estimate is right, its covariance conservative."""
    if policy not in MISFIT_POLICIES:
        raise CalibrationError(f"misfit policy {policy!r} is not one of {MISFIT_POLICIES}")
    est.fit = check
    if check.ok or policy == "off":
        return est
    if not check.too_large:
        est.flags.append(check.message)
        return est
    if policy == "raise":
        raise CalibrationError(check.message)
    est.flags.append(check.message)
    warnings.warn(check.message, CalibrationWarning, stacklevel=3)
    return est


def check_condition(cond: float, limit: float, what: str, advice: str) -> float:
    """``cond`` if finite and at most ``limit``; else a CalibrationError saying ``what`` is
    unobservable, with the number and the ``advice``."""
    if not np.isfinite(cond) or cond > limit:
        raise CalibrationError(
            f"{what} is not determined by these data: condition number {cond:.3g} "
            f"(limit {limit:.3g}); {advice}"
        )
    return float(cond)


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
        estimated as ``sqrt(sum r^2 / (m - n))``; with no degrees of freedom (``m <= n``) it
        cannot be, and the covariance is NaN (the one NaN this function returns for finite
        input: the data say nothing about the noise).

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


def minpack_lm(
    fun: Callable[..., np.ndarray],
    x0: np.ndarray,
    jac: Callable[..., np.ndarray],
    args: tuple = (),
    *,
    xtol: float = 1e-12,
    ftol: float = 1e-12,
    gtol: float = 1e-12,
    max_nfev: int | None = None,
) -> np.ndarray:
    """The minimiser of ``sum fun(x, *args)^2`` by MINPACK's ``lmder``, the solution vector only.

    The same computation as ``scipy.optimize.least_squares(fun, x0, jac=jac, args=args,
    method="lm", ...)`` with its defaults (``x_scale="jac"``, step bound factor 100, at most
    ``100 n`` evaluations): the same MINPACK call with the same inputs, hence the same bytes, a
    test checks it. It goes through :func:`scipy.optimize.leastsq`, the thinner of scipy's two
    wrappers of that routine, and returns the solution only: for the many small fits of a Monte
    Carlo trial the wrapper is a large part of the cost (the refinement of a homography of 35
    points, best of 700 fits on a shared 2-core machine: 0.08 ms through leastsq, 0.15 ms
    through least_squares).

    Raises
    ------
    CalibrationError
        If ``fun`` returns fewer residuals than ``x0`` has parameters, ``jac`` a Jacobian of
        another shape, or a tolerance is negative (MINPACK's improper input).
    """
    x = np.asarray(x0, dtype=float).flatten()
    try:  # leastsq checks the shapes of fun(x0) and jac(x0) first (TypeError)
        x, _, _, message, ier = _leastsq(fun, x, jac, args, xtol, ftol, gtol, max_nfev)
    except TypeError as exc:
        message, ier = str(exc), 0
    if ier == 0:
        raise CalibrationError(
            f"MINPACK rejected the problem ({np.size(x0)} parameters): {message}"
        )
    return np.asarray(x, dtype=float)


def _leastsq(fun, x0: np.ndarray, jac, args: tuple, xtol, ftol, gtol, max_nfev) -> tuple:
    """:func:`scipy.optimize.leastsq` (MINPACK ``lmder``) with the settings of
    ``least_squares(method="lm")``: ``x_scale="jac"`` (no ``diag``), step bound factor 100, at
    most ``100 n`` evaluations; ``full_output`` also keeps it from warning on a stop at the
    tolerances, as least_squares does. Returns leastsq's ``(x, cov_x, info, message, ier)``."""
    from scipy.optimize import leastsq

    return leastsq(
        fun,
        x0.copy(),
        args=args,
        Dfun=jac,
        full_output=True,
        ftol=ftol,
        xtol=xtol,
        gtol=gtol,
        maxfev=100 * x0.size if max_nfev is None else max_nfev,
        factor=100.0,
        diag=None,
    )


#: relative step of scipy's 2-point finite differences for float64 (``eps ** 0.5``)
_FD_STEP = np.finfo(np.float64).eps ** 0.5

#: scipy's translation of MINPACK's exit codes into least_squares' status (<= 0: not converged)
_MINPACK_STATUS = {0: -1, 1: 2, 2: 3, 3: 4, 4: 1, 5: 0}


def _lmder(fun, x0, jac, *, xtol, ftol, gtol, max_nfev, f0=None):
    """What ``least_squares(fun, x0, jac=jac, method="lm", ...)`` returns (the fields
    :func:`levenberg_marquardt` reads: x, fun, jac, cost, nfev, status, message), computed by the
    same MINPACK call through :func:`scipy.optimize.leastsq`'s thinner wrapper. As in
    least_squares, a repeated evaluation at the last point is answered from memory, so ``fun`` is
    called at the same points in the same order (the evaluation history is the same). ``f0``,
    if given, is ``fun(x0)`` already computed: the first evaluation, at ``x0``, is answered
    from it. The Jacobian is remembered the same way: leastsq evaluates it at ``x0`` to check
    its shape before MINPACK evaluates it there again, and the result's Jacobian at the
    solution may be the one MINPACK evaluated last.

    ``jac="2-point"`` is least_squares' forward-difference Jacobian, computed as scipy's
    ``approx_derivative`` does (relative step ``sqrt(eps) max(1, |x_i|)`` signed as ``x_i``, the
    step actually taken ``(x_i + h_i) - x_i`` as divisor, the residuals at the last point as
    base) and kept until ``fun`` is evaluated elsewhere, as least_squares' ``VectorFunction``
    keeps it: the same Jacobians, hence the same MINPACK iterates, without least_squares' set-up
    and per-evaluation wrappers (a test checks the bytes).
    """
    last: list = [] if f0 is None else [np.array(x0, dtype=float), f0, None]
    last_jac: list = []

    def remembered(x):
        if last and np.array_equal(x, last[0]):
            return last[1]
        f = fun(x)
        last[:] = [np.array(x, dtype=float), f, None]
        return f

    if isinstance(jac, str):
        if jac != "2-point":
            raise CalibrationError(f"finite-difference scheme {jac!r}: only '2-point' here")

        def forward_difference(x):
            base = remembered(x)
            if last[2] is None:
                x = last[0]
                h = _FD_STEP * ((x >= 0).astype(float) * 2 - 1) * np.maximum(1.0, np.abs(x))
                columns = np.empty((x.size, base.size))
                for i in range(x.size):
                    x1 = np.copy(x)
                    x1[i] = x[i] + h[i]
                    columns[i] = (np.asarray(fun(x1), dtype=float) - base) / ((x[i] + h[i]) - x[i])
                last[2] = columns.T
            return last[2]

        jac = forward_difference
    else:
        given = jac

        def remembered_jac(x):
            if last_jac and np.array_equal(x, last_jac[0]):
                return last_jac[1]
            j = given(x)
            last_jac[:] = [np.array(x, dtype=float), j]
            return j

        jac = remembered_jac
    from scipy.optimize import OptimizeResult

    x, _, info, message, ier = _leastsq(remembered, x0, jac, (), xtol, ftol, gtol, max_nfev)
    x = np.asarray(x, dtype=float)
    f = np.asarray(info["fvec"], dtype=float)
    return OptimizeResult(
        x=x,
        fun=f,
        jac=np.asarray(jac(x), dtype=float),
        cost=0.5 * float(f @ f),
        nfev=int(info["nfev"]),
        status=_MINPACK_STATUS.get(int(ier), -1),
        message=str(message),
    )


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
    max_condition: float | None = None,
    advice: str = "add measurements that vary the undetermined parameters",
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
    max_condition
        Largest condition number of the Jacobian at the solution that is accepted (None: not
        checked); beyond it the parameters are unobservable and :class:`CalibrationError` says so
        with ``advice``.

    Raises
    ------
    CalibrationError
        If ``m < n``, if the start or the residuals there are not finite, if the solver stops
        without converging (the message gives the evaluation count and the cost), or if the
        condition number exceeds ``max_condition``.
    """
    x0 = np.asarray(x0, dtype=float)
    if not np.all(np.isfinite(x0)):
        raise CalibrationError(f"{label}: the starting point is not finite ({x0})")
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

    if method == "lm" and callable(jac):
        # the residuals at x0 are known: the solver's first evaluation is answered from r0
        history.append(0.5 * float(r0 @ r0))
        res = _lmder(wrapped, x0, jac, xtol=xtol, ftol=ftol, gtol=gtol, max_nfev=max_nfev, f0=r0)
    elif method == "lm" and jac == "2-point":
        res = _lmder(wrapped, x0, jac, xtol=xtol, ftol=ftol, gtol=gtol, max_nfev=max_nfev)
    else:
        from scipy.optimize import least_squares

        res = least_squares(
            wrapped, x0, jac=jac, method=method, xtol=xtol, ftol=ftol, gtol=gtol, max_nfev=max_nfev
        )
    if res.status <= 0:
        raise CalibrationError(
            f"{label} did not converge after {res.nfev} evaluations (cost {res.cost:.6g}): "
            f"{res.message}"
        )
    if not (np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.fun))):
        raise CalibrationError(f"{label}: the solution is not finite after {res.nfev} evaluations")
    cov, cond = covariance_from_jacobian(res.jac, res.fun, sigma)
    if max_condition is not None:
        check_condition(cond, max_condition, f"{label}: the estimate", advice)
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
