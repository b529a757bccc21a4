"""Summary statistics over Monte Carlo trials: RMSE and the two intervals of the study.

The intervals: :func:`median_interval`, the order-statistic confidence interval of the median
that every verdict uses (rule 2), and :func:`median_and_spread`, the central spread of the
trials that the tables show beside a median. Every verdict of the study rests on these few
functions, so they check their input and raise :class:`calstudy.CalibrationError` rather than
return NaN.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from calstudy.core.errors import CalibrationError, TooFewTrials


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


def trial_values(name: str, values: object) -> np.ndarray:
    """``values`` as a finite float array of shape (N,), N >= 1, one value per trial.

    Raises
    ------
    CalibrationError
        Naming ``name``, if the shape is not (N,) with N >= 1 or a value is not finite.
    """
    shape = np.shape(values) if not isinstance(values, str) else ()
    if len(shape) != 1 or shape[0] == 0:
        raise CalibrationError(f"{name} has shape {shape}; expected (N,), one value per trial")
    return finite_samples(name, values)


def interval_level(level: object) -> float:
    """``level`` as a float, checked to be a coverage strictly between 0 and 1.

    Raises
    ------
    CalibrationError
        If ``level`` is not a finite number in (0, 1).
    """
    try:
        x = float(level)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"level is {level!r}; expected a finite number") from exc
    if not 0.0 < x < 1.0:  # NaN fails too
        raise CalibrationError(f"level is {level!r}; expected strictly between 0 and 1")
    return x


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


@lru_cache(maxsize=512)
def median_ranks(n: int, level: float = 0.95) -> tuple[int, int, float]:
    """Ranks of the order-statistic confidence interval for the median of ``n`` samples.

    With ``B ~ Binomial(n, 1/2)`` the number of samples below the true median (of a continuous
    distribution), ``P(x_(j) < median < x_(k)) = P(j <= B < k)``. The ranks are symmetric,
    ``k = n + 1 - j``, and ``j`` is the largest with ``P(j <= B < k) >= level``: the narrowest
    symmetric interval that reaches the level. The coverage is exact, hence conservative.

    Parameters
    ----------
    n : int
        Number of samples.
    level : float, default 0.95
        Required coverage, in (0, 1).

    Returns
    -------
    (int, int, float)
        1-based ranks ``j < k`` of the bounds and the exact coverage ``1 - 2 P(B <= j - 1)``.

    Raises
    ------
    CalibrationError
        If ``level`` is not in (0, 1) or ``n`` cannot reach it (below 6 for 95 %: the full
        range of 5 samples covers 93.75 %).
    """
    level = interval_level(level)
    if int(n) != n or n < 1:
        raise CalibrationError(f"n is {n!r}; expected a positive sample count")
    from scipy.stats import binom  # lazy: scipy.stats takes about 1 s to import

    alpha_half = (1.0 - level) / 2.0
    cdf = binom.cdf(np.arange(n // 2 + 1), n, 0.5)  # cdf at n // 2 is >= 1/2 > alpha_half
    j = int(np.count_nonzero(cdf <= alpha_half))
    if j == 0:
        n_min = next(m for m in range(1, 2000) if binom.cdf(0, m, 0.5) <= alpha_half)
        raise TooFewTrials(
            f"{n} samples cannot give a {100 * level:g} % interval for the median "
            f"(the full range covers {100 * (1 - 2 * 0.5**n):.3g} %); at least {n_min} needed"
        )
    return j, n + 1 - j, float(1.0 - 2.0 * cdf[j - 1])


def median_interval(samples: object, level: float = 0.95) -> tuple[float, float, float]:
    """Median of ``samples`` and its distribution-free order-statistic confidence interval.

    The interval is ``[x_(j), x_(k)]`` of the sorted samples with the binomial ranks of
    :func:`median_ranks` (symmetric, the narrowest reaching ``level``). This is the interval
    used for every verdict; no bootstrap, so no resampling generator and no Monte Carlo error.

    Parameters
    ----------
    samples : array_like, shape (N,)
        One value per trial.
    level : float, default 0.95
        Coverage of the interval.

    Returns
    -------
    (float, float, float)
        Median (``numpy.median``), lower bound, upper bound.

    Raises
    ------
    CalibrationError
        If ``samples`` is not (N,), holds NaN or infinity, or N is below the smallest count that
        reaches ``level`` (6 for 95 %).
    """
    x = np.sort(trial_values("samples", samples))
    j, k, _ = median_ranks(x.size, interval_level(level))
    return float(np.median(x)), float(x[j - 1]), float(x[k - 1])


def median_and_spread(samples, level: float = 0.95) -> tuple[float, float, float]:
    """Median of ``samples`` and their central ``level`` percentile interval: a spread over
    trials, not a confidence interval of the median (that is :func:`median_interval`).

    Parameters
    ----------
    samples : array_like
        Values over trials (flattened).
    level : float, default 0.95
        Probability mass inside the interval; the bounds are the ``(1 - level) / 2`` and
        ``(1 + level) / 2`` quantiles (linear interpolation, numpy's default).

    Returns
    -------
    (float, float, float)
        Median, lower and upper bound; one sample gives ``(x, x, x)``.

    Raises
    ------
    CalibrationError
        On no or non-finite values, or ``level`` not in (0, 1).
    """
    level = interval_level(level)
    a = finite_samples("samples", samples, min_count=1).reshape(-1)
    lo, hi = np.quantile(a, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(np.median(a)), float(lo), float(hi)


#: fewest paired trials for :func:`rms_ratio_interval` (the median's 95 % interval needs as many)
MIN_POOLED_TRIALS = 6


def rms_ratio_interval(after, before, level: float = 0.95) -> tuple[float, float, float]:
    """Ratio of the RMS of ``after`` to the RMS of ``before`` over paired trials, with its
    confidence interval.

    The estimate is ``sqrt(mean(after**2) / mean(before**2))``, a pooled statistic: no single
    trial's small denominator can dominate it. The interval is the delta-method interval of the
    ratio of the two mean squares, paired (the variance is that of
    ``after_i**2 - R**2 before_i**2`` over trials, so an error both share cancels), mapped
    through the square root; deterministic, no resampling.

    Parameters
    ----------
    after, before : array_like, shape (N,)
        One error per trial of the method and of its baseline on the same trial (any unit,
        the same for both); ``before`` not all zero.
    level : float, default 0.95
        Two-sided coverage of the normal approximation.

    Returns
    -------
    (float, float, float)
        Ratio, lower and upper bound (the lower clipped at 0).

    Raises
    ------
    CalibrationError
        If the arrays are not (N,) of the same N >= :data:`MIN_POOLED_TRIALS`, hold NaN or
        infinity, ``before`` is all zero, or ``level`` is not in (0, 1).
    """
    a = trial_values("after", after)
    b = trial_values("before", before)
    if a.size != b.size:
        raise CalibrationError(
            f"after has {a.size} trials and before {b.size}; expected the same N (paired)"
        )
    if a.size < MIN_POOLED_TRIALS:
        raise TooFewTrials(
            f"{a.size} trials cannot give an interval of the RMS ratio; at least "
            f"{MIN_POOLED_TRIALS} needed (as for the median's)"
        )
    from scipy.stats import norm  # lazy, as in median_ranks

    z = float(norm.ppf(0.5 + interval_level(level) / 2.0))
    mb = float(np.mean(b**2))
    if not mb > 0.0:
        raise CalibrationError("before is zero in every trial; the RMS ratio is undefined")
    r2 = float(np.mean(a**2)) / mb
    se = float(np.std(a**2 - r2 * b**2, ddof=1)) / (np.sqrt(a.size) * mb)
    return float(np.sqrt(r2)), float(np.sqrt(max(0.0, r2 - z * se))), float(np.sqrt(r2 + z * se))


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
