"""Least-squares parameters whose residual errors are partly shared: the two variances by
restricted maximum likelihood, the covariance they give, and the degrees of freedom of the
intervals and regions built on it.

The errors ``e`` of a least-squares fit ``r = J x + e`` are modelled as
``cov(e) = s_own^2 I + s_shared^2 S``: every entry has its own error, and the entries of one group
share one more (``S[i, j] = 1`` when entries ``i`` and ``j`` are in the same group), as the views
of one sphere share the error of its one tracker reading. :func:`shared_error_fit` estimates the
two variances from the residuals by REML (the likelihood of the residual contrasts, one
variance ratio searched, the other profiled) and returns the sandwich covariance of the
least-squares parameters, ``A J^T V J A`` with ``A = (J^T J)^-1``.

Two variances estimated from a few groups are uncertain, and ``x^T C^-1 x`` with an estimated
``C`` is not chi-square: :meth:`SharedErrorFit.dof` gives Satterthwaite's degrees of freedom of
the variance of any direction (Student's t for its interval) and :meth:`SharedErrorFit.region_dof`
the denominator degrees of freedom of the F approximation of Fai and Cornelius (1996) for the
joint region (``x^T C^-1 x / p`` against ``F(p, dof)``). Their uncertainty comes from the inverse
expected REML information of the two variances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from calstudy.core.errors import CalibrationError

#: degrees of freedom below which Satterthwaite's are not used for an interval: Student's t has
#: no variance at 2 or fewer, and the approximation breaks down when the shared variance sits at
#: zero (it can return less than 1, an interval hundreds of times the normal one)
MIN_DOF = 2.0
#: the variance ratio ``s_shared^2 / s_own^2`` is searched on this log10 range (and at 0)
RATIO_LOG10_RANGE = (-6.0, 6.0)
_GRID = 61


@dataclass(frozen=True)
class SharedErrorFit:
    """The two variances of the residual errors and the covariance of the parameters.

    Attributes
    ----------
    variances : (2,) the own and the shared variance, units of the residuals squared.
    variances_covariance : (2, 2) their covariance (inverse expected REML information); zero in
        the shared row and column when no group holds two entries (one variance then).
    parts : (2, p, p) ``A`` and ``A J^T S J A``: the covariance of the parameters is
        ``variances[0] parts[0] + variances[1] parts[1]``.
    """

    variances: np.ndarray
    variances_covariance: np.ndarray
    parts: np.ndarray

    @property
    def covariance(self) -> np.ndarray:
        """(p, p) covariance of the least-squares parameters (the sandwich)."""
        return np.tensordot(self.variances, self.parts, axes=1)

    def _satterthwaite(self, directions: np.ndarray) -> np.ndarray:
        g = np.stack([np.sum((directions @ part) * directions, axis=1) for part in self.parts], 1)
        var = g @ self.variances
        spread = np.einsum("kc,cd,kd->k", g, self.variances_covariance, g)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(spread > 0, 2.0 * var**2 / spread, math.inf)

    def dof(self, directions=None) -> np.ndarray:
        """Satterthwaite degrees of freedom of the estimated variance of each direction.

        Parameters
        ----------
        directions : array_like, shape (k, p), optional
            Rows ``c``: the variance of ``c^T x``; default the ``p`` parameters themselves.

        Returns
        -------
        (k,) degrees of freedom, at least :data:`MIN_DOF`; inf when neither variance is
        uncertain in that direction.
        """
        p = self.parts.shape[1]
        d = np.eye(p) if directions is None else np.atleast_2d(np.asarray(directions, float))
        if d.shape[1] != p:
            raise CalibrationError(f"directions have {d.shape[1]} columns; the fit has {p}")
        return np.maximum(self._satterthwaite(d), MIN_DOF)

    def region_dof(self) -> float:
        """Denominator degrees of freedom of the joint region (Fai and Cornelius, 1996).

        Satterthwaite's ``nu_m`` of each eigenvector of the covariance; ``E = sum nu_m /
        (nu_m - 2)`` over those with ``nu_m > 2``; ``2 E / (E - p)`` if ``E > p``, else
        :data:`MIN_DOF`. Equal ``nu_m`` give ``nu`` back (one variance: ``n - p``).
        """
        _, vec = np.linalg.eigh(self.covariance)
        nu = self._satterthwaite(vec.T)
        if np.all(np.isinf(nu)):
            return math.inf
        big = nu > 2.0
        e = float(np.sum(np.where(np.isinf(nu[big]), 1.0, nu[big] / (nu[big] - 2.0))))
        p = len(nu)
        return 2.0 * e / (e - p) if e > p else MIN_DOF


def _group_sums(rows: np.ndarray, inverse: np.ndarray, n_groups: int) -> np.ndarray:
    out = np.zeros((n_groups, rows.shape[1]))
    np.add.at(out, inverse, rows)
    return out


def _profile(ratio: float, w2: np.ndarray, g: np.ndarray) -> tuple[float, float]:
    """-2 log restricted likelihood (up to a constant) at the variance ratio, with the own
    variance profiled out; and that variance."""
    own = float(np.sum(w2 / (1.0 + ratio * g))) / len(w2)
    return float(np.sum(np.log1p(ratio * g))) + len(w2) * math.log(own), own


def _best_ratio(w2: np.ndarray, g: np.ndarray) -> float:
    """The variance ratio of largest restricted likelihood: a log grid (and 0), then Brent."""
    grid = np.concatenate([[0.0], np.logspace(*RATIO_LOG10_RANGE, _GRID)])
    scale = 1.0 + grid[:, None] * g  # (grid, n - p)
    own = np.sum(w2 / scale, axis=1) / len(w2)
    values = np.sum(np.log(scale), axis=1) + len(w2) * np.log(own)
    k = int(np.argmin(values))
    if k == 0:
        return 0.0
    lo, hi = math.log(grid[max(k - 1, 1)]), math.log(grid[min(k + 1, _GRID)])
    if k == 1:
        lo -= math.log(grid[2] / grid[1])
    res = minimize_scalar(
        lambda u: _profile(math.exp(u), w2, g)[0],
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 1e-9},
    )
    return math.exp(res.x) if res.fun < values[k] else float(grid[k])


def shared_error_fit(jac, residuals, groups) -> SharedErrorFit:
    """REML estimate of the own and the shared error variance from least-squares residuals, and
    the covariance of the parameters they give.

    Parameters
    ----------
    jac : array_like, shape (n, p)
        Jacobian of the residuals in the parameters at the solution (full column rank).
    residuals : array_like, shape (n,)
        Residuals at the least-squares solution.
    groups : array_like, shape (n,)
        A label per residual entry; entries with the same label share an error.

    Returns
    -------
    SharedErrorFit
        With one variance (the shared one zero and certain) when no group holds two entries or
        the residual contrasts cannot tell the two apart.

    Raises
    ------
    CalibrationError
        Shapes that disagree, non-finite values, no residual degrees of freedom (``n <= p``) or a
        Jacobian that is not of full column rank.
    """
    jac = np.asarray(jac, float)
    r = np.asarray(residuals, float)
    groups = np.asarray(groups)
    if jac.ndim != 2 or r.shape != (jac.shape[0],) or groups.shape != r.shape:
        raise CalibrationError(
            f"Jacobian {jac.shape}, residuals {r.shape} and groups {groups.shape} must be "
            "(n, p), (n,) and (n,) for one n"
        )
    if not (np.isfinite(jac).all() and np.isfinite(r).all()):
        raise CalibrationError("the Jacobian or the residuals hold non-finite values")
    n, p = jac.shape
    if n <= p:
        raise CalibrationError(
            f"{n} residuals for {p} parameters leave no degrees of freedom to estimate the noise "
            "from: measure more or declare the noise"
        )
    q, rr = np.linalg.qr(jac, mode="complete")
    diag = np.abs(np.diag(rr[:p]))
    if diag.min() <= diag.max() * 1e-12:
        raise CalibrationError(
            f"the Jacobian ({n} x {p}) is not of full column rank (|R| diagonal ratio "
            f"{diag.min() / diag.max():.3g}): fix the parameters it does not identify first"
        )
    contrasts = q[:, p:]  # (n, n - p) orthonormal, orthogonal to the columns of jac
    _, inverse = np.unique(groups, return_inverse=True)
    n_groups = int(inverse.max()) + 1
    zk = _group_sums(contrasts, inverse, n_groups)
    g, u = np.linalg.eigh(zk.T @ zk)
    g = np.clip(g, 0.0, None)
    w2 = (u.T @ (contrasts.T @ r)) ** 2
    m = n - p
    r_inv = np.linalg.inv(rr[:p])
    a = r_inv @ r_inv.T
    ja = _group_sums(jac, inverse, n_groups) @ a
    parts = np.stack([a, ja.T @ ja])
    if not np.any(w2 > 0):  # residuals exactly zero: nothing to estimate, nothing uncertain
        return SharedErrorFit(np.zeros(2), np.zeros((2, 2)), parts)
    one = n_groups == n or float(np.ptp(g)) <= 1e-9 * max(float(g.max()), 1.0)
    ratio = 0.0 if one else _best_ratio(w2, g)
    own = _profile(ratio, w2, g)[1]
    variances = np.array([own, own * ratio])
    if one:
        variances_cov = np.diag([2.0 * own**2 / m, 0.0])
    else:
        lam = own + variances[1] * g
        d = np.stack([np.ones_like(g), g]) / lam
        variances_cov = np.linalg.inv(0.5 * d @ d.T)
    return SharedErrorFit(variances, variances_cov, parts)
