"""Joint calibration of a nuisance input to several baseline figures of a paper at once.

A nuisance input ``x`` (one the paper does not state) is calibrated so that the medians over
trials of every baseline figure the paper reports for the experiment, ``m_k(x)``, meet the
paper's values ``b_k`` together (rule 14 of the verdict rule, *How a verdict is
computed* on the book's claims page). Each paper figure is one
experiment's value: it carries a relative standard uncertainty ``s_k`` (for an RMSE of ``n``
independent errors about ``1 / sqrt(2 n)``, :func:`rmse_spread`), and the fit is weighted least
squares in logarithms::

    x_hat = argmin_x  sum_k ((ln m_k(x) - ln b_k) / s_k)^2

over the range of a grid of trial runs (piecewise-linear interpolation of ``ln m_k`` in
``ln x``). A baseline is *met* at ``x_hat`` when ``|ln(m_k / b_k)| <= coverage * s_k`` (the
stated tolerance); the mechanism behind ``m_k`` is *identified* by the paper when every
baseline is met. The standard uncertainty of ``x_hat`` carries both the paper figures' own
uncertainty and the Monte Carlo uncertainty of the medians: the fit is repeated on draws of
both (:data:`DRAWS`, a fixed seed) and its standard deviation taken.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import norm

from calstudy.core.errors import CalibrationError
from calstudy.core.stats import median_interval

#: draws of the paper figures and the medians behind the standard uncertainty of a fit
DRAWS = 400
#: values of the input at which the objective is evaluated between the grid's ends
FINE = 2001
#: z of the 95 % interval of a median (its standard error is the interval's half width / z)
Z95 = float(norm.ppf(0.975))


@dataclass(frozen=True)
class Baseline:
    """One baseline figure of the paper.

    Attributes
    ----------
    name : str
        The figure's key in what the trial function returns.
    target : float
        The paper's value, > 0 (in the figure's unit).
    spread : float
        Its relative standard uncertainty as one experiment's value, > 0 (:func:`rmse_spread`).
    coverage : float, default 2
        The tolerance in standard uncertainties: met when the median lies within a factor
        ``exp(coverage * spread)`` of ``target``.
    """

    name: str
    target: float
    spread: float
    coverage: float = 2.0

    def __post_init__(self) -> None:
        for key in ("target", "spread", "coverage"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise CalibrationError(f"baseline {self.name!r}: {key} is {value}; need > 0")

    @property
    def tolerance(self) -> float:
        """The largest ``|ln(median / target)|`` that meets the baseline."""
        return self.coverage * self.spread


def rmse_spread(n_errors: int) -> float:
    """Relative standard deviation of one experiment's RMSE of ``n_errors`` independent errors
    of equal variance, ``1 / sqrt(2 n)`` (the large-sample spread of a chi distribution with
    ``n`` degrees of freedom over its mean).

    Raises
    ------
    CalibrationError
        If ``n_errors < 1``.
    """
    if int(n_errors) < 1:
        raise CalibrationError(f"an RMSE of {n_errors} errors; need at least 1")
    return 1.0 / math.sqrt(2.0 * int(n_errors))


@dataclass(frozen=True)
class JointFit:
    """The result of :func:`joint_calibration`.

    Attributes
    ----------
    value : float
        The fitted input.
    uncertainty : float
        Its standard uncertainty (paper figures and Monte Carlo medians), same unit.
    at_edge : bool
        True when the fit lies at an end of the grid (the baselines pull beyond the range).
    agreement : pandas.DataFrame
        One row per baseline: ``baseline``, ``target``, ``spread`` (its relative standard
        uncertainty), ``coverage`` (the tolerance in spreads), ``tolerance`` (relative,
        ``exp(tol) - 1``), ``median`` at the fit, ``ratio`` (median / target), ``met`` at the
        joint fit, and ``alone`` (the value that meets it best on its own) with ``met_alone``
        (whether any value of the range meets it).
    grid : pandas.DataFrame
        Per grid value and baseline: ``value``, ``baseline``, ``median``, ``ci_low``,
        ``ci_high``, ``n``.
    """

    value: float
    uncertainty: float
    at_edge: bool
    agreement: pd.DataFrame
    grid: pd.DataFrame

    @property
    def identified(self) -> bool:
        """True when the fit meets every baseline at once."""
        return bool(self.agreement["met"].all())

    def met(self) -> list[str]:
        """Names of the baselines met at the joint fit."""
        return self.agreement.loc[self.agreement["met"], "baseline"].tolist()


def _grid_medians(figures, values, baselines) -> pd.DataFrame:
    rows = []
    for v in values:
        out = figures(v)
        for b in baselines:
            if b.name not in out:
                raise CalibrationError(
                    f"the trial function gives no {b.name!r} at {v:g} (it gives {sorted(out)})"
                )
            med, lo, hi = median_interval(np.asarray(out[b.name], dtype=float))
            if not (med > 0 and lo > 0):
                raise CalibrationError(
                    f"baseline {b.name!r} at {v:g}: median {med:g} (interval low {lo:g}); a "
                    "figure calibrated in logarithms must be > 0"
                )
            rows.append(
                {
                    "value": float(v),
                    "baseline": b.name,
                    "median": med,
                    "ci_low": lo,
                    "ci_high": hi,
                    "n": len(out[b.name]),
                }
            )
    return pd.DataFrame(rows)


def joint_calibration(
    figures: Callable[[float], Mapping[str, Sequence[float]]],
    values: Sequence[float],
    baselines: Sequence[Baseline],
) -> JointFit:
    """Calibrate one positive nuisance input to all ``baselines`` at once (module docstring).

    Parameters
    ----------
    figures : callable
        ``figures(x)`` gives, for the input at ``x``, each baseline's per-trial figures
        (``{name: (N,) array_like}``, > 0); the same trials at every ``x`` keep the fit smooth.
    values : sequence of float, length >= 2
        The grid of the input, > 0, distinct (its plausible range: the fit stays inside it).
    baselines : sequence of Baseline
        The paper's baseline figures with their spreads; at least one.

    Returns
    -------
    JointFit

    Raises
    ------
    CalibrationError
        If the grid has fewer than two distinct positive values, there is no baseline, or a
        figure is missing or not positive.
    """
    grid = np.unique(np.asarray(values, dtype=float))
    if grid.size < 2 or not np.all(np.isfinite(grid)) or grid[0] <= 0:
        raise CalibrationError(
            f"the grid of the input is {list(values)}; need two or more distinct values > 0"
        )
    if not baselines:
        raise CalibrationError("no baseline figure to calibrate to")
    table = _grid_medians(figures, grid, baselines)
    lx = np.log(grid)
    fine = np.linspace(lx[0], lx[-1], FINE)
    logs, ses = [], []
    for b in baselines:
        t = table[table["baseline"] == b.name].sort_values("value")
        logs.append(np.log(t["median"].to_numpy()))
        ses.append((np.log(t["ci_high"]) - np.log(t["ci_low"])).to_numpy() / (2 * Z95))
    logs, ses = np.array(logs), np.array(ses)  # (K, grid)
    targets = np.log([b.target for b in baselines])
    spreads = np.array([b.spread for b in baselines])

    def fit(y: np.ndarray, goal: np.ndarray) -> float:
        curves = np.array([np.interp(fine, lx, row) for row in y])  # (K, FINE)
        cost = (((curves - goal[:, None]) / spreads[:, None]) ** 2).sum(axis=0)
        return float(fine[int(np.argmin(cost))])

    best = fit(logs, targets)
    rng = np.random.default_rng(0)
    draws = [
        fit(
            logs + ses * rng.standard_normal(logs.shape),
            targets + spreads * rng.standard_normal(len(baselines)),
        )
        for _ in range(DRAWS)
    ]
    value = math.exp(best)
    uncertainty = float(np.std(np.exp(draws), ddof=1))
    rows = []
    for k, b in enumerate(baselines):
        curve = np.interp(fine, lx, logs[k])
        at = float(np.interp(best, lx, logs[k]))
        miss = np.abs(curve - targets[k])
        rows.append(
            {
                "baseline": b.name,
                "target": b.target,
                "spread": b.spread,
                "coverage": b.coverage,
                "tolerance": math.exp(b.tolerance) - 1.0,
                "median": math.exp(at),
                "ratio": math.exp(at - targets[k]),
                "met": bool(abs(at - targets[k]) <= b.tolerance),
                "alone": math.exp(float(fine[int(np.argmin(miss))])),
                "met_alone": bool(miss.min() <= b.tolerance),
            }
        )
    edge = bool(best <= fine[0] or best >= fine[-1])
    return JointFit(value, uncertainty, edge, pd.DataFrame(rows), table)


def joint_calibration_rows(rows: pd.DataFrame, x: str, baselines: Sequence[Baseline]) -> JointFit:
    """:func:`joint_calibration` on the rows of a sweep: at each value of column ``x`` the
    trials' figures are the columns named by the baselines, in ``trial`` order.

    Parameters
    ----------
    rows : pandas.DataFrame
        One row per trial and value: ``x``, ``trial`` and one column per baseline (> 0).
    x : str
        The input's column; its distinct values are the grid.
    baselines : sequence of Baseline
        As for :func:`joint_calibration`.

    Returns
    -------
    JointFit

    Raises
    ------
    CalibrationError
        If ``rows`` has no column ``x``, or as :func:`joint_calibration`.
    """
    if x not in rows:
        raise CalibrationError(f"the sweep rows have no column {x!r} (they have {list(rows)})")

    def figures(value: float) -> dict:
        at = rows[rows[x] == value].sort_values("trial")
        return {b.name: at[b.name].to_numpy(float) for b in baselines if b.name in at}

    return joint_calibration(figures, sorted(rows[x].unique()), baselines)
