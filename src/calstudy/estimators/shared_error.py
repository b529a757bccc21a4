"""Least-squares parameters whose residual errors are partly shared: the two variances by
restricted maximum likelihood, the covariance they give, and the quantiles of the intervals and
regions built on it.

The errors ``e`` of a least-squares fit ``r = J x + e`` are modelled as
``cov(e) = s_own^2 I + s_shared^2 S``: every entry has its own error, and the entries of one group
share one more (``S[i, j] = 1`` when entries ``i`` and ``j`` are in the same group), as the views
of one sphere share the error of its one tracker reading. :func:`shared_error_fit` estimates the
two variances from the residuals by REML (the likelihood of the residual contrasts, one
variance ratio searched, the other profiled) and returns the sandwich covariance of the
least-squares parameters, ``A J^T V J A`` with ``A = (J^T J)^-1``.

Two variances estimated from a few groups are uncertain, and ``c^T x / sqrt(c^T C c)`` with an
estimated ``C`` is neither normal nor Student's t. With a few groups the ratio
``s_shared^2 / s_own^2`` is often estimated at zero, where Satterthwaite's degrees of freedom,
computed at the estimate, collapse below 2 and give intervals several times too wide. The
quantiles of :meth:`SharedErrorFit.interval_quantiles` and :meth:`SharedErrorFit.region_quantile`
come instead from simulating those statistics: the errors are drawn with ratios drawn from the
restricted likelihood of the ratio (a uniform prior on the shared fraction
``s_shared^2 / (s_own^2 + s_shared^2)``, the own variance integrated out), both variances
re-estimated by REML in every draw and the parameter error studentised by its own estimate. The
statistics do not depend on the scale of the errors, only on the ratio, so drawing the ratio
carries its uncertainty (also above an estimate of zero) into the quantiles; re-estimating in
every draw keeps the dependence between an error and its estimated variance (the same tracker
errors move both). With one variance (no group of two) the quantiles are the exact Student's t
and F ones with ``n - p`` degrees of freedom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import stats
from scipy.optimize import minimize_scalar
from scipy.special import logsumexp

from calstudy.core.errors import CalibrationError

#: the variance ratio ``s_shared^2 / s_own^2`` is searched on this log10 range (and at 0)
RATIO_LOG10_RANGE = (-6.0, 6.0)
_GRID = 61
#: simulated draws behind the quantiles (a 95 % interval quantile to about 1.5 %, a region bound
#: to 2-3 %), from a fixed seed so that a fit's intervals are reproducible
DRAWS = 4000
SEED = 20260
#: points of the log-spaced grid (and 0) on which the ratio is drawn from its likelihood
_RATIO_DRAW_GRID = 241
#: golden-section steps refining each draw's REML ratio within its grid bracket
_GOLDEN_STEPS = 16


@dataclass(frozen=True)
class _Simulation:
    """What drawing the errors again needs, in the coordinates of the fit.

    ``c_own`` (p, p): the parameter error of unit own errors is ``c_own @ z``, z standard
    normal (p,), independent of the contrasts; ``k_shared`` (p, G): that of the group errors;
    ``w_shared`` (m, G): the rotated residual contrasts of the group errors (those of the own
    errors are standard normal (m,)); ``g`` (m,) the eigenvalues of the contrasts' group sums;
    ``w2`` (m,) the squared rotated contrasts of the observed residuals."""

    c_own: np.ndarray
    k_shared: np.ndarray
    w_shared: np.ndarray
    g: np.ndarray
    w2: np.ndarray


@dataclass(frozen=True)
class SharedErrorFit:
    """The two variances of the residual errors and the covariance of the parameters.

    Attributes
    ----------
    variances : (2,) the own and the shared variance, units of the residuals squared.
    parts : (2, p, p) ``A`` and ``A J^T S J A``: the covariance of the parameters is
        ``variances[0] parts[0] + variances[1] parts[1]``.
    dof : int
        Residual degrees of freedom ``n - p``.
    one_variance : bool
        True when only the own variance is estimated (no group of two, or contrasts that cannot
        tell the two apart): the quantiles are then Student's t and F with :attr:`dof`.
    """

    variances: np.ndarray
    parts: np.ndarray
    dof: int
    one_variance: bool
    _simulation: _Simulation

    @property
    def covariance(self) -> np.ndarray:
        """(p, p) covariance of the least-squares parameters (the sandwich)."""
        return np.tensordot(self.variances, self.parts, axes=1)

    @cached_property
    def _draws(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:data:`DRAWS` simulated parameter errors (DRAWS, p) and their re-estimated own and
        shared variances (DRAWS,), with unit own variance and ratios drawn from the
        restricted likelihood."""
        sim = self._simulation
        rng = np.random.default_rng(SEED)
        ratio = _draw_ratios(sim.w2, sim.g, rng)
        p, n_groups, m = sim.c_own.shape[0], sim.k_shared.shape[1], len(sim.g)
        shared = rng.standard_normal((DRAWS, n_groups)) * np.sqrt(ratio)[:, None]
        error = rng.standard_normal((DRAWS, p)) @ sim.c_own.T + shared @ sim.k_shared.T
        w2 = (rng.standard_normal((DRAWS, m)) + shared @ sim.w_shared.T) ** 2
        ratio_hat = best_ratios(w2, sim.g)
        own_hat = np.sum(w2 / (1.0 + ratio_hat[:, None] * sim.g), axis=1) / m
        return error, own_hat, own_hat * ratio_hat

    def interval_quantiles(self, level: float = 0.95, directions=None) -> np.ndarray:
        """Quantiles ``q`` of the intervals ``c^T x +- q sqrt(c^T C c)`` of the ``level``.

        Parameters
        ----------
        level : float
            Coverage of each interval, strictly between 0 and 1.
        directions : array_like, shape (k, p), optional
            Rows ``c``; default the ``p`` parameters themselves.

        Returns
        -------
        (k,) the ``level`` quantile of ``|c^T (x_hat - x)| / sqrt(c^T C_hat c)``: Student's t
        with :attr:`dof` for one variance, else from the simulation (module docstring).

        Raises
        ------
        CalibrationError
            Directions whose column count is not ``p``.
        """
        d = self._directions(directions)
        if self.one_variance:
            return np.full(len(d), stats.t.ppf(0.5 + level / 2, self.dof))
        error, own, shared = self._draws
        a = np.sum((d @ self.parts[0]) * d, axis=1)
        b = np.sum((d @ self.parts[1]) * d, axis=1)
        t = np.abs(error @ d.T) / np.sqrt(own[:, None] * a + shared[:, None] * b)
        return np.quantile(t, level, axis=0)

    def region_quantile(self, level: float = 0.95) -> float:
        """Bound of ``(x_hat - x)^T C_hat^-1 (x_hat - x)`` of the joint ``level`` region.

        Parameters
        ----------
        level : float
            Coverage of the region, strictly between 0 and 1.

        Returns
        -------
        float
            ``p F(p, dof)`` for one variance, else the simulated quantile (module docstring).
        """
        p = self.parts.shape[1]
        if self.one_variance:
            return float(p * stats.f.ppf(level, p, self.dof))
        error, own, shared = self._draws
        chol = np.linalg.cholesky(self.parts[0])
        half = np.linalg.solve(chol, np.eye(p))  # chol^-1: parts[0] becomes the identity
        mu, vec = np.linalg.eigh(half @ self.parts[1] @ half.T)
        y = error @ (vec.T @ half).T
        form = np.sum(y**2 / (own[:, None] + shared[:, None] * mu), axis=1)
        return float(np.quantile(form, level))

    def _directions(self, directions) -> np.ndarray:
        p = self.parts.shape[1]
        d = np.eye(p) if directions is None else np.atleast_2d(np.asarray(directions, float))
        if d.shape[1] != p:
            raise CalibrationError(f"directions have {d.shape[1]} columns; the fit has {p}")
        return d


def _group_sums(rows: np.ndarray, inverse: np.ndarray, n_groups: int) -> np.ndarray:
    out = np.zeros((n_groups, rows.shape[1]))
    np.add.at(out, inverse, rows)
    return out


def _profile(ratio: float, w2: np.ndarray, g: np.ndarray) -> tuple[float, float]:
    """-2 log restricted likelihood (up to a constant) at the variance ratio, with the own
    variance profiled out; and that variance."""
    own = float(np.sum(w2 / (1.0 + ratio * g))) / len(w2)
    return float(np.sum(np.log1p(ratio * g))) + len(w2) * math.log(own), own


def _ratio_grid(size: int = _GRID) -> np.ndarray:
    """0 and ``size`` log-spaced ratios over :data:`RATIO_LOG10_RANGE`: (size + 1,)."""
    return np.concatenate([[0.0], np.logspace(*RATIO_LOG10_RANGE, size)])


def best_ratio(w2: np.ndarray, g: np.ndarray) -> float:
    """The variance ratio ``s_shared^2 / s_own^2`` of largest restricted likelihood: a log grid
    (and 0) over :data:`RATIO_LOG10_RANGE`, then Brent's bounded search around its best point.

    Parameters
    ----------
    w2 : (m,) ndarray
        The squared residual contrasts in the eigenbasis of the shared part (any units).
    g : (m,) ndarray
        The eigenvalues of the shared part of the contrasts' covariance (``>= 0``).

    Returns
    -------
    float
        The ratio (0 when the boundary is the best).
    """
    grid = _ratio_grid()
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


def best_ratios(w2: np.ndarray, g: np.ndarray) -> np.ndarray:
    """:func:`best_ratio` of every row of ``w2`` at once: the same grid, then golden-section
    steps within the bracket of the best grid point (to about 1e-3 of the ratio).

    Parameters
    ----------
    w2 : (draws, m) ndarray
        Squared residual contrasts, one set per row.
    g : (m,) ndarray
        The eigenvalues of the shared part (as for :func:`best_ratio`).

    Returns
    -------
    (draws,) ndarray
        The ratio of each row.
    """
    grid = _ratio_grid()
    m = w2.shape[1]
    scale = 1.0 + grid[:, None] * g
    values = np.sum(np.log(scale), axis=1) + m * np.log(w2 @ (1.0 / scale).T / m)
    k = np.argmin(values, axis=1)
    log_grid = np.log(grid[1:])
    step = log_grid[1] - log_grid[0]
    lo = log_grid[np.clip(k - 2, 0, _GRID - 1)] - np.where(k == 1, step, 0.0)
    hi = log_grid[np.clip(k, 0, _GRID - 1)]
    shared = g > 1e-12 * max(float(g.max()), 1.0)  # the other contrasts do not see the ratio
    g_s, w2_s, w2_own = g[shared], w2[:, shared], np.sum(w2[:, ~shared], axis=1)

    def f(u):
        s = 1.0 + np.exp(u)[:, None] * g_s
        return np.sum(np.log(s), axis=1) + m * np.log((w2_own + np.sum(w2_s / s, axis=1)) / m)

    golden = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = hi - golden * (hi - lo), lo + golden * (hi - lo)
    fc, fd = f(c), f(d)
    for _ in range(_GOLDEN_STEPS):
        left = fc < fd  # the minimum lies in [lo, d]: d becomes hi, c the inner point kept
        hi, lo = np.where(left, d, hi), np.where(left, lo, c)
        kept, f_kept = np.where(left, c, d), np.where(left, fc, fd)
        new = np.where(left, hi - golden * (hi - lo), lo + golden * (hi - lo))
        f_new = f(new)
        c, fc = np.where(left, new, kept), np.where(left, f_new, f_kept)
        d, fd = np.where(left, kept, new), np.where(left, f_kept, f_new)
    u = (lo + hi) / 2.0
    best = np.where(f(u) < values[np.arange(len(k)), k], np.exp(u), grid[k])
    return np.where(k == 0, 0.0, best)


def _draw_ratios(w2: np.ndarray, g: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """:data:`DRAWS` variance ratios from the restricted likelihood of the observed contrasts,
    the own variance integrated out (prior ``1 / s_own^2``), with a uniform prior on the shared
    fraction ``ratio / (1 + ratio)``: on a log grid (and 0) with trapezoid weights."""
    m = len(w2)
    ratio = _ratio_grid(_RATIO_DRAW_GRID)
    scale = 1.0 + ratio[:, None] * g
    log_like = -0.5 * (np.sum(np.log(scale), axis=1) + m * np.log(np.sum(w2 / scale, axis=1)))
    width = np.zeros_like(ratio)
    width[:-1] += np.diff(ratio) / 2.0
    width[1:] += np.diff(ratio) / 2.0
    log_post = log_like + np.log(width) - 2.0 * np.log1p(ratio)
    return rng.choice(ratio, size=DRAWS, p=np.exp(log_post - logsumexp(log_post)))


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
    r_inv = np.linalg.inv(rr[:p])
    a = r_inv @ r_inv.T
    ja = _group_sums(jac, inverse, n_groups) @ a
    parts = np.stack([a, ja.T @ ja])
    simulation = _Simulation(r_inv, ja.T, (zk @ u).T, g, w2)
    one = n_groups == n or float(np.ptp(g)) <= 1e-9 * max(float(g.max()), 1.0)
    if not np.any(w2 > 0):  # residuals exactly zero: nothing to estimate
        return SharedErrorFit(np.zeros(2), parts, n - p, True, simulation)
    ratio = 0.0 if one else best_ratio(w2, g)
    own = _profile(ratio, w2, g)[1]
    return SharedErrorFit(np.array([own, own * ratio]), parts, n - p, one, simulation)
