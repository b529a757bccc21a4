"""What "the same result" means across machines: a tolerance per column, tied to its unit.

Another CPU picks other BLAS and OpenCV kernels, which move the last bits of intermediate
numbers; a well-conditioned trial absorbs that, an ill-conditioned one (a hand-eye from few
poses, an identification near a rank loss) amplifies it. Two tables are the same result when

- text, boolean and integer columns (verdicts, methods, counts, bins, iteration counts, ranks)
  are equal exactly;
- every number of a float column satisfies ``|a - b| <= atol(unit) + rtol * |b|``, with
  ``atol`` one nanometre for a length, one nanoradian for an angle, a micro-pixel for an image
  coordinate and ``1e-9`` for a dimensionless number (:data:`UNIT_ATOL`), and ``rtol``
  :data:`TRIAL_RTOL` for the stored trial rows (fifty parts per million: an ill-conditioned
  solve, such as a hand-eye from few or nearly parallel motions or a rotation weighted by
  nearly singular covariances, moves its result by up to a few tens of parts per million when
  its inputs move by 1e-13) and :data:`TABLE_RTOL` for the tables (6 significant
  digits: one unit in the last digit is up to 1e-5);
- an iterative solver's step count (:data:`SOLVER_COUNTS`: ``*solver_iterations``,
  ``evaluations``, ``rounds``) within one: the solver stops when a relative reduction falls
  below its threshold, and where the two are within a last-bit difference one machine takes one
  more step than another (the values it returns agree to the tolerances above);
- NaN stands where NaN stood.

The unit of a column is read from its name: its suffix (``_mm``, ``_deg``, ``_px``, ..., also
before a statistic: ``_px_rms``) or, for
the study's columns named without one, :data:`NAMED_UNITS`. A float column whose values are all
integers in both tables (a count stored as float because some rows have none) is compared
exactly.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = [
    "NAMED_UNITS",
    "SOLVER_COUNTS",
    "TABLE_RTOL",
    "TRIAL_RTOL",
    "UNIT_ATOL",
    "Mismatch",
    "column_unit",
    "compare_tables",
]

#: absolute tolerance by unit: 1 nm, 1 nrad, 1 micro-pixel, 1e-9 of a dimensionless number
UNIT_ATOL: dict[str, float] = {
    "m": 1e-9,
    "mm": 1e-6,
    "um": 1e-3,
    "rad": 1e-9,
    "mrad": 1e-6,
    "deg": math.degrees(1e-9),
    "px": 1e-6,
    "%": 1e-7,
    "1": 1e-9,
}
#: relative tolerance of the stored trial rows and of the tables
TRIAL_RTOL, TABLE_RTOL = 5e-5, 2e-5

_SUFFIX = re.compile(
    r"_(m|mm|um|rad|mrad|deg|px)(_(rms|max|min|mean|median|std|low|high|p\d+))?$"
)
#: units of the study's columns whose names carry none (pattern on the whole name -> unit)
NAMED_UNITS: tuple[tuple[re.Pattern[str], str], ...] = tuple(
    (re.compile(pattern), unit)
    for pattern, unit in (
        # binocular: RMSEs and per-pair errors of Tables 2-3, Fig. 13 and Table 5, in mm
        (r"(t\d|fig13)_\w+|err_(raw|rect|mod)_\w+|field\d?_\w+", "mm"),
        # selfcal: robot parameters (lengths a, d in mm; angles in rad) and error histories
        (r"(id|ml|std|true)_[ad]\d", "mm"),
        (r"(id|ml|std|true)_(alpha|beta|theta)\d", "rad"),
        (r"(good|poor)_err_\d+|param_error|robot_param_error", "mm"),
        # selfcal routes: how far a route's model error lies from the one-step route's
        (r"step_from_\w+", "mm"),
        # hybrid production: shares in percent
        (r"(within|beyond|single_within)_\w+|coord_above_\w+|lilliefors_not_rejected"
         r"|mean_nonzero|r_above_\w+", "%"),
    )
)


#: columns holding an iterative solver's step count: equal within one step
SOLVER_COUNTS = re.compile(r"(\w+_)?(solver_iterations|evaluations|rounds)")


def column_unit(name: str) -> str:
    """The unit of column ``name`` (a key of :data:`UNIT_ATOL`; ``"1"`` if none is known)."""
    m = _SUFFIX.search(name)
    if m:
        return m.group(1)
    for pattern, unit in NAMED_UNITS:
        if pattern.fullmatch(name):
            return unit
    return "1"


@dataclass(frozen=True)
class Mismatch:
    """One column of two tables that differ beyond its tolerance."""

    column: str
    row: int
    got: object
    want: object
    tolerance: float | None  # None: compared exactly

    def __str__(self) -> str:
        if self.tolerance is None:
            return f"column {self.column!r} row {self.row}: {self.got!r} != {self.want!r} (exact)"
        return (
            f"column {self.column!r} row {self.row}: {self.got!r} against {self.want!r}, "
            f"difference {abs(float(self.got) - float(self.want)):.3g} > {self.tolerance:.3g}"
        )


def _integral(values: np.ndarray) -> bool:
    finite = values[np.isfinite(values)]
    return bool(np.all(finite == np.round(finite)))


def compare_tables(got: pd.DataFrame, want: pd.DataFrame, rtol: float) -> list[Mismatch]:
    """Where ``got`` differs from ``want`` beyond the tolerances of the module docstring.

    Parameters
    ----------
    got, want : pandas.DataFrame
        The fresh and the reference table; the same columns in the same order and the same
        number of rows are required (a difference there is one :class:`Mismatch` with row -1).
    rtol : float
        :data:`TRIAL_RTOL` or :data:`TABLE_RTOL`.

    Returns
    -------
    list of Mismatch
        The first differing row of every column that differs; empty when the tables agree.
    """
    if list(got.columns) != list(want.columns):
        return [Mismatch("<columns>", -1, list(got.columns), list(want.columns), None)]
    if len(got) != len(want):
        return [Mismatch("<rows>", -1, len(got), len(want), None)]
    out = []
    for col in want.columns:
        a, b = got[col], want[col]
        numeric = pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b)
        if numeric and not (pd.api.types.is_bool_dtype(a) or pd.api.types.is_bool_dtype(b)):
            x, y = a.to_numpy(float), b.to_numpy(float)
            exact = _integral(x) and _integral(y)
            atol = UNIT_ATOL[column_unit(col)]
            steps = 1.0 if exact and SOLVER_COUNTS.fullmatch(col) else 0.0
            with np.errstate(invalid="ignore"):
                limit = steps if exact else atol + rtol * np.abs(y)
                off = np.abs(x - y) > limit
            bad = (np.isnan(x) != np.isnan(y)) | (off & ~np.isnan(y) & ~np.isnan(x))
            where = np.flatnonzero(bad)
            if where.size:
                i = int(where[0])
                tol = (steps or None) if exact else float(atol + rtol * abs(y[i]))
                out.append(Mismatch(col, i, x[i], y[i], tol))
        else:
            x = [None if m else str(v) for v, m in zip(a, a.isna(), strict=True)]
            y = [None if m else str(v) for v, m in zip(b, b.isna(), strict=True)]
            where = [i for i, (p, q) in enumerate(zip(x, y, strict=True)) if p != q]
            if where:
                out.append(Mismatch(col, where[0], x[where[0]], y[where[0]], None))
    return out
