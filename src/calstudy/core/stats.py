"""Summary statistics over Monte Carlo trials: RMSE, percentile and bootstrap intervals.

Every verdict of the study rests on these few functions, so they check their input and raise
:class:`calstudy.CalibrationError` rather than return NaN.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from calstudy.core.errors import CalibrationError


def finite_samples(name: str, samples, min_count: int = 1) -> np.ndarray:
    """Return ``samples`` as a float array with at least one axis (one row per trial), after
    checking that it is numeric, holds ``min_count`` rows and no NaN or inf (the message names
    the first bad trial)."""
    try:
        a = np.asarray(samples, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"{name} is not numeric ({exc}); expected floats") from exc
    if a.ndim == 0:
        a = a[None]
    if a.shape[0] < min_count:
        raise CalibrationError(f"{name} holds {a.shape[0]} samples; at least {min_count} needed")
    bad = ~np.isfinite(a)
    if bad.any():
        first = np.argwhere(bad)[0]
        where = int(first[0]) if a.ndim == 1 else tuple(int(i) for i in first)
        raise CalibrationError(
            f"{name} holds {int(bad.sum())} non-finite value(s) of {a.size} (first at trial "
            f"{where}); drop or explain failed trials first"
        )
    return a


def round_to_uncertainty(value: float, std: float) -> float:
    """``value`` rounded to the decade of its standard uncertainty ``std``.

    A value computed from Monte Carlo trials (a nuisance input calibrated to a baseline figure)
    knows nothing below its standard uncertainty; its last bits depend on the machine (BLAS and
    OpenCV kernels). Rounded to ``10**floor(log10(std))`` it is the same number on every machine,
    except in the rare case that it falls on a rounding boundary, and the rounding moves it by
    at most half a decade below ``std``.

    Parameters
    ----------
    value : float
        The computed value.
    std : float
        Its standard uncertainty, > 0, same unit.

    Returns
    -------
    float
        The rounded value.

    Raises
    ------
    CalibrationError
        If either is not finite or ``std`` is not positive.

    Examples
    --------
    >>> round_to_uncertainty(0.7164706571379741, 0.031)
    0.72
    """
    if not (np.isfinite(value) and np.isfinite(std)) or std <= 0:
        raise CalibrationError(
            f"cannot round {value!r} to its uncertainty {std!r}: expected finite numbers, std > 0"
        )
    digits = -int(np.floor(np.log10(std)))
    return float(round(float(value), digits))


def _check_level(level: float) -> float:
    if not 0.0 < level < 1.0:
        raise CalibrationError(f"interval level {level!r} is not strictly between 0 and 1")
    return float(level)


def rmse(x, axis: int | None = None) -> float | np.ndarray:
    """Root mean square of ``x``, ``sqrt(mean(x**2))``.

    Parameters
    ----------
    x : array_like
        Errors (any unit; the result has the same unit). For vector errors pass their norms.
    axis : int, optional
        Axis to reduce; ``None`` (default) reduces all values to one number.

    Returns
    -------
    float or numpy.ndarray
        The RMS value(s).

    Raises
    ------
    CalibrationError
        If ``x`` is empty or holds NaN or infinity.

    Notes
    -----
    Values whose squares overflow (beyond about 1e154) are scaled by the largest magnitude
    first, so every finite input gives a finite RMS; other inputs take the plain formula.
    """
    a = np.asarray(x, dtype=float)
    if a.size == 0:
        raise CalibrationError("rmse of an empty array (0 values)")
    finite_samples("rmse input", a)
    with np.errstate(over="ignore"):
        out = np.sqrt(np.mean(np.square(a), axis=axis))
    if not np.isfinite(out).all():  # squares past 1e308: the same in units of the largest value
        scale = np.max(np.abs(a), axis=axis, keepdims=True)
        scale = np.where(scale > 0.0, scale, 1.0)
        out = np.sqrt(np.mean(np.square(a / scale), axis=axis)) * np.squeeze(scale, axis=axis)
    return float(out) if np.ndim(out) == 0 else out


def percentile_interval(samples, level: float = 0.95) -> tuple[float, float]:
    """Central percentile interval of ``samples`` (for example over Monte Carlo trials).

    Parameters
    ----------
    samples : array_like, shape (N,)
        One value per trial.
    level : float, default 0.95
        Probability mass inside the interval; the bounds are the ``(1 - level) / 2`` and
        ``(1 + level) / 2`` quantiles (linear interpolation, numpy's default).

    Returns
    -------
    (float, float)
        Lower and upper bound.

    Raises
    ------
    CalibrationError
        If there are fewer than 2 samples, a sample is not finite, or ``level`` is not in (0, 1).
    """
    level = _check_level(level)
    a = finite_samples("samples", samples, min_count=2)
    if a.ndim != 1:
        raise CalibrationError(f"samples has shape {a.shape}; expected (N,)")
    lo, hi = np.quantile(a, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(lo), float(hi)


def bootstrap_interval(
    samples,
    statistic: Callable[[np.ndarray], np.ndarray],
    rng: np.random.Generator,
    n_boot: int = 2000,
    level: float = 0.95,
) -> tuple[float, float, float]:
    """Percentile bootstrap interval of ``statistic`` over resampled trials, vectorised.

    Trials (the first axis of ``samples``) are drawn with replacement ``n_boot`` times in one
    index array; rows stay together, so paired values (say a method's and a baseline's error on
    the same simulated data) are resampled as pairs.

    Parameters
    ----------
    samples : array_like, shape (N, ...)
        One row per trial.
    statistic : callable
        Takes an array of shape ``(B, N, ...)`` and returns shape ``(B,)``: the statistic of each
        of ``B`` resampled data sets, reducing axis 1. Example for an RMS:
        ``lambda s: np.sqrt(np.mean(s**2, axis=1))``.
    rng : numpy.random.Generator
        Source of the resampling indices (required; no default, so runs are reproducible).
    n_boot : int, default 2000
        Number of bootstrap resamples.
    level : float, default 0.95
        Probability mass inside the interval.

    Returns
    -------
    (float, float, float)
        The statistic on the original samples, then the lower and upper bound.

    Raises
    ------
    CalibrationError
        If there are fewer than 2 trials, a value is not finite, ``n_boot < 1``, ``level`` is
        not in (0, 1), or ``statistic`` does not return one finite value per resample.
    """
    level = _check_level(level)
    if not isinstance(rng, np.random.Generator):
        raise CalibrationError(f"rng is a {type(rng).__name__}; expected numpy.random.Generator")
    if int(n_boot) < 1:
        raise CalibrationError(f"n_boot is {n_boot}; at least 1 resample needed")
    a = finite_samples("samples", samples, min_count=2)
    n = a.shape[0]
    estimate = np.asarray(statistic(a[None, ...]), dtype=float).reshape(-1)
    idx = rng.integers(0, n, size=(int(n_boot), n))
    values = np.asarray(statistic(a[idx]), dtype=float)
    if estimate.shape != (1,) or values.shape != (int(n_boot),):
        raise CalibrationError(
            f"statistic returned shape {values.shape} for {int(n_boot)} resamples; it must reduce "
            "axis 1 of a (B, N, ...) array to shape (B,)"
        )
    if not np.all(np.isfinite(values)) or not np.isfinite(estimate[0]):
        raise CalibrationError(
            f"statistic is not finite on {int((~np.isfinite(values)).sum())} of {int(n_boot)} "
            "resamples (a division by a zero error?)"
        )
    lo, hi = np.quantile(values, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(estimate[0]), float(lo), float(hi)


def median_and_spread(samples, level: float = 0.95) -> tuple[float, float, float]:
    """Median of ``samples`` and their central ``level`` percentile interval (a spread over
    trials, not a confidence interval of the median: that is
    :func:`calstudy.core.verdicts.median_interval`).

    One sample gives ``(x, x, x)``. Raises :class:`CalibrationError` on no or non-finite values.
    """
    a = finite_samples("samples", samples, min_count=1).reshape(-1)
    lo, hi = percentile_interval(a, level) if a.size >= 2 else (float(a[0]), float(a[0]))
    return float(np.median(a)), lo, hi


def lilliefors_test(samples) -> tuple[float, float]:
    """Lilliefors test for normality (statsmodels, table p-values): ``(statistic, p_value)``.

    The Kolmogorov-Smirnov distance of the samples from the normal distribution with their own
    mean and standard deviation, with the p-value of Lilliefors' table (hybrid paper, section
    4.3, tests the deviations of each coordinate before compensation this way).

    Parameters
    ----------
    samples : array_like, shape (n,)
        At least 4 values (statsmodels' minimum).

    Returns
    -------
    (float, float)
        The statistic and its p-value.

    Raises
    ------
    CalibrationError
        With fewer than 4 samples, a shape other than (n,), non-finite values, or constant data
        (the normal fit has zero spread).
    """
    from statsmodels.stats.diagnostic import lilliefors

    x = np.asarray(samples, dtype=float)
    n = 0 if x.ndim == 0 else x.shape[0]
    if n < 4:
        raise CalibrationError(f"a Lilliefors test needs at least 4 samples; samples holds {n}")
    finite_samples("samples", x)
    if x.ndim != 1:
        raise CalibrationError(f"samples has shape {x.shape}; expected (n,)")
    if np.ptp(x) <= 1e-12 * max(1.0, float(np.abs(x).max())):
        raise CalibrationError(
            f"all {x.size} samples equal {x[0]:.6g}: a normal fit and the Lilliefors test are "
            "undefined for constant data"
        )
    stat, p = lilliefors(x, dist="norm", pvalmethod="table")
    return float(stat), float(p)


def lilliefors_tests(samples) -> tuple[np.ndarray, np.ndarray]:
    """Lilliefors tests of every column at once: ``(statistics (m,), p_values (m,))``.

    The vectorised sibling of :func:`lilliefors_test`: the Kolmogorov-Smirnov distance of each
    column from the normal distribution with its own mean and standard deviation (ddof 1),
    computed in NumPy for all columns together, with the p-values of statsmodels' own Lilliefors
    table (``get_lilliefors_table("norm").prob``, what ``pvalmethod="table"`` uses). Same
    figures as calling :func:`lilliefors_test` per column.

    Parameters
    ----------
    samples : array_like, shape (n, m)
        ``m`` columns of ``n >= 4`` values each.

    Raises
    ------
    CalibrationError
        With fewer than 4 rows, a shape other than (n, m), non-finite values, or a constant
        column (named by its index).
    """
    from scipy.stats import norm
    from statsmodels.stats._lilliefors import get_lilliefors_table

    x = np.asarray(samples, dtype=float)
    if x.ndim != 2:
        raise CalibrationError(f"samples has shape {x.shape}; expected (n, m), one test a column")
    n = x.shape[0]
    if n < 4:
        raise CalibrationError(f"a Lilliefors test needs at least 4 samples; columns hold {n}")
    finite_samples("samples", x)
    flat = np.ptp(x, axis=0) <= 1e-12 * np.maximum(1.0, np.abs(x).max(axis=0))
    if flat.any():
        j = int(np.flatnonzero(flat)[0])
        raise CalibrationError(
            f"column {j} is constant ({x[0, j]:.6g}): a normal fit and the Lilliefors test are "
            "undefined for constant data"
        )
    z = np.sort((x - x.mean(axis=0)) / x.std(axis=0, ddof=1), axis=0)
    cdf = norm.cdf(z)
    d_plus = (np.arange(1.0, n + 1)[:, None] / n - cdf).max(axis=0)
    d_minus = (cdf - np.arange(0.0, n)[:, None] / n).max(axis=0)
    stat = np.maximum(d_plus, d_minus)
    p = np.asarray(get_lilliefors_table(dist="norm").prob(stat, n), dtype=float).reshape(-1)
    return stat, p
