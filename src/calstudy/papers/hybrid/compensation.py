"""Offset compensation and its statistics (hybrid paper, section 4.3, Eq. 24-26, Table 1).

The paper

1. looks at the deviations hybrid minus CMM of 10 panels before compensation (Fig. 6): systematic,
   a few millimetres, normal by the Lilliefors test (:func:`before_compensation`);
2. learns one offset per feature coordinate from ``n`` products (Eq. 24, :func:`offsets`) and adds
   it to later measurements (Eq. 25, :func:`compensate`);
3. bins the compensated deviations and the hybrid-CMM correlation coefficients (Eq. 26,
   :func:`correlations`) of the 174 coordinates ("vectors", 58 points x 3 axes) over 30 later
   products (Table 1, :func:`analyse_run`); the deviation bins are judged as a whole by how far
   they fall short of the published cumulative shares (:func:`shortfall_distance`).

The functions take measurement arrays ``(products, points, 3)``, or the long tables of
:data:`MEASUREMENT_COLUMNS` through :func:`measurements_from_frames`, so measured CSVs can be fed
in. Every deviation is hybrid minus CMM, in mm, in the workpiece frame (WF).

Coordinates that the 3-2-1 rule fixes (A: y, z; B: x, y, z; C: z) are the same on every panel in
both systems, by the definition of the frame: their deviation is 0 and their correlation is
undefined. They are found by :func:`frame_fixed` and reported as such, never as NaN.

These statistics stay with the paper rather than in :mod:`calstudy.core.stats`: they are its
Eq. 24-26 on its (products, points, axes) arrays with its products-and-frame checks, and Table 1's
bins; only the Lilliefors test is general (:func:`calstudy.core.stats.lilliefors_test`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.schema import validate_rows
from calstudy.core.stats import lilliefors_tests
from calstudy.core.userfile import LENGTH_UNITS, read_csv_table, require_columns
from calstudy.papers.hybrid.scenario import AXES, PHASES, load_published
from calstudy.papers.hybrid.schema import MeasurementRow

MEASUREMENT_COLUMNS = ("product", "phase", "point_id", "x_mm", "y_mm", "z_mm")


# ---------------------------------------------------------------------------------------------
# measurement tables (the user's CSVs or the simulation)


def measurements_frame(ids, run: dict, which: int) -> pd.DataFrame:
    """A long table (:data:`MEASUREMENT_COLUMNS`) of the hybrid (``which=0``) or CMM (1) readings
    of a run ``{phase: (hybrid, cmm)}``; products are numbered from 1 across phases."""
    frames, start = [], 1
    for phase in PHASES:
        if phase not in run:
            continue
        a = run[phase][which]
        n, nf = a.shape[:2]
        frames.append(
            pd.DataFrame(
                {
                    "product": np.repeat(np.arange(start, start + n), nf),
                    "phase": phase,
                    "point_id": np.tile(np.asarray(ids, dtype=object), n),
                    "x_mm": a[..., 0].ravel(),
                    "y_mm": a[..., 1].ravel(),
                    "z_mm": a[..., 2].ravel(),
                }
            )
        )
        start += n
    return pd.concat(frames, ignore_index=True)


def _table_to_array(df: pd.DataFrame, name: str):
    """``(ids, products, phases, array (P, F, 3))`` of one long table, after checking it."""
    missing = [c for c in MEASUREMENT_COLUMNS if c not in df.columns]
    if missing:
        raise CalibrationError(
            f"the {name} table lacks columns {missing}; needs {MEASUREMENT_COLUMNS}"
        )
    if len(df) == 0:
        raise CalibrationError(f"the {name} table is empty (0 rows)")
    df = df.assign(point_id=df["point_id"].astype(str))
    dup = df[df.duplicated(["product", "point_id"], keep=False)]
    if len(dup):
        first = dup.iloc[0]
        same = (dup["product"] == first["product"]) & (dup["point_id"] == first["point_id"])
        raise CalibrationError(
            f"duplicated feature point in the {name} table: point {first['point_id']} appears "
            f"{int(same.sum())} times in product {first['product']} ({len(dup)} duplicated "
            "rows in all)"
        )
    bad_phase = sorted(set(df["phase"]) - set(PHASES))
    if bad_phase:
        raise CalibrationError(f"the {name} table has phases {bad_phase}; use {PHASES}")
    ids = list(dict.fromkeys(df["point_id"]))
    products = list(dict.fromkeys(df["product"]))
    for p, sub in df.groupby("product", sort=False):
        lacking = [i for i in ids if i not in set(sub["point_id"])]
        if lacking:
            raise CalibrationError(
                f"product {p} of the {name} table lacks {len(lacking)} feature point(s): "
                f"{lacking[:10]}"
            )
        if sub["phase"].nunique() != 1:
            raise CalibrationError(f"product {p} of the {name} table has more than one phase")
    wide = df.set_index(["product", "point_id"]).loc[pd.MultiIndex.from_product([products, ids])]
    values = wide[["x_mm", "y_mm", "z_mm"]].to_numpy(float).reshape(len(products), len(ids), 3)
    if not np.all(np.isfinite(values)):
        raise CalibrationError(
            f"the {name} table holds {int((~np.isfinite(values)).sum())} non-finite coordinates"
        )
    phases = df.drop_duplicates("product").set_index("product").loc[products, "phase"].tolist()
    return ids, products, phases, values


def measurements_from_frames(hybrid: pd.DataFrame, cmm: pd.DataFrame):
    """Pair a hybrid and a CMM table (:data:`MEASUREMENT_COLUMNS`): ``(ids, run)``.

    ``run`` is ``{phase: (hybrid (P, F, 3), cmm (P, F, 3))}`` with the points in the order of
    ``ids``, as :func:`simulate_run` returns it.

    Raises
    ------
    CalibrationError
        On missing columns, duplicated or missing feature points, point ids or products that
        differ between the two tables, unknown phases or non-finite coordinates.
    """
    ids_h, prod_h, ph_h, h = _table_to_array(hybrid, "hybrid")
    ids_c, prod_c, ph_c, c = _table_to_array(cmm, "CMM")
    if set(ids_h) != set(ids_c):
        raise CalibrationError(
            "point ids differ between the hybrid and CMM tables: only in hybrid "
            f"{sorted(set(ids_h) - set(ids_c))[:10]}, only in CMM "
            f"{sorted(set(ids_c) - set(ids_h))[:10]}"
        )
    if set(prod_h) != set(prod_c):
        raise CalibrationError(
            f"products differ between the hybrid and CMM tables: only in hybrid "
            f"{sorted(set(prod_h) - set(prod_c))[:10]}, only in CMM "
            f"{sorted(set(prod_c) - set(prod_h))[:10]}"
        )
    order_p = [prod_c.index(p) for p in prod_h]
    order_f = [ids_c.index(i) for i in ids_h]
    c = c[order_p][:, order_f]
    ph_c = [ph_c[k] for k in order_p]
    if ph_h != ph_c:
        raise CalibrationError("a product has different phases in the hybrid and CMM tables")
    run = {}
    for phase in PHASES:
        sel = np.array([p == phase for p in ph_h])
        if sel.any():
            run[phase] = (h[sel], c[sel])
    return ids_h, run


#: coordinates all below this (in magnitude) look like metres ...
METRE_SUSPECT = 10.0
#: ... when the other table's reach this
MM_TYPICAL = 100.0
_UNITS_COMMENT = re.compile(r"^\s*#\s*units\s*[:=]\s*mm\s*$", re.IGNORECASE | re.MULTILINE)


def read_table(path, name: str) -> tuple[pd.DataFrame, bool]:
    """One hybrid or CMM table (``name``, for messages) read from CSV and checked row by row.

    The columns are those of :data:`MEASUREMENT_COLUMNS`; the coordinates may instead be
    declared in metres (``x_m, y_m, z_m``: converted to mm). Spreadsheet files are accepted
    (byte-order mark, ``;`` separator, ``#`` comments). Returns the table (mm) and whether its
    unit is declared: columns in metres, or a comment line ``# units: mm``.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file.
    CalibrationError
        On a missing or repeated column, no rows, or a bad cell, named by row and column (a
        decimal comma ``12,5`` as such; a phase that is not ``compensation`` or ``follow-up``;
        a product that is not an integer).
    """
    header, rows = read_csv_table(path, f"{name} table")
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise CalibrationError(f"{path}: column(s) {repeated} given more than once")
    units = [u for u in LENGTH_UNITS if any(f"{a}_{u}" in header for a in AXES)]
    if len(units) > 1:
        raise CalibrationError(
            f"{path}: coordinates in both mm and m columns; use x_mm, y_mm, z_mm or x_m, y_m, z_m"
        )
    unit = units[0] if units else "mm"
    coords = [f"{a}_{unit}" for a in AXES]
    require_columns(path, header, [*MEASUREMENT_COLUMNS[:3], *coords])
    if not rows:
        raise CalibrationError(f"{path}: no data rows (the {name} table is empty)")
    renamed = [f"{h[: -len(unit)]}mm" if h in coords else h for h in header]
    records = validate_rows(MeasurementRow, renamed, rows, path)
    df = pd.DataFrame([r.model_dump() for r in records], columns=list(MEASUREMENT_COLUMNS))
    if unit != "mm":
        df[list(MEASUREMENT_COLUMNS[3:])] *= LENGTH_UNITS[unit]
    declared = unit != "mm" or bool(_UNITS_COMMENT.search(Path(path).read_text("utf-8-sig")))
    return df, declared


def _check_units(tables: dict) -> None:
    """Refuse undeclared coordinates that look like metres: all below :data:`METRE_SUSPECT`
    while the other table's reach :data:`MM_TYPICAL` (both tables in metres are not caught:
    coordinates of a small part near its frame's origin are rightly below 10 mm)."""
    big = {
        k: float(np.abs(df[list(MEASUREMENT_COLUMNS[3:])].to_numpy()).max())
        for k, (df, _, _) in tables.items()
    }
    for name, (_, declared, path) in tables.items():
        other = next(k for k in tables if k != name)
        if declared or big[name] >= METRE_SUSPECT:
            continue
        if big[other] < MM_TYPICAL:
            continue
        why = f"while those of the {other} table reach {big[other]:.4g}"
        raise CalibrationError(
            f"{path}: the coordinates of the {name} table are all below {METRE_SUSPECT:g} "
            f"(largest |value| {big[name]:.4g}) {why}: they look like metres, but x_mm, y_mm, "
            "z_mm hold mm (an offset would absorb the scale and give a plausible Table 1); "
            "convert them, name the columns x_m, y_m, z_m, or, if they are millimetres, add "
            "the line '# units: mm'"
        )


def read_measurements(hybrid_csv: str, cmm_csv: str):
    """:func:`measurements_from_frames` on two CSV files read by :func:`read_table`, after
    checking that neither holds metres in its mm columns (unless its unit is declared)."""
    tables = {}
    for name, path in (("hybrid", hybrid_csv), ("CMM", cmm_csv)):
        df, declared = read_table(path, name)
        tables[name] = (df, declared, path)
    _check_units(tables)
    return measurements_from_frames(tables["hybrid"][0], tables["CMM"][0])


def station_data(hybrid_csv: str, cmm_csv: str, ids, simulated_run: dict):
    """The measurements of one station: the user's CSVs if both are given, else a simulated run.

    Returns ``(source, ids, run)`` with ``run = {phase: (hybrid, cmm)}``.
    """
    if bool(hybrid_csv) != bool(cmm_csv):
        raise CalibrationError("give both hybrid_csv and cmm_csv, or neither")
    if hybrid_csv:
        ids, run = read_measurements(hybrid_csv, cmm_csv)
        n = {p: run[p][0].shape[0] for p in run}
        if set(run) != set(PHASES):
            raise CalibrationError(f"the tables hold products of phases {list(run)}; need {PHASES}")
        return f"measured tables {hybrid_csv} and {cmm_csv} ({n} products)", ids, run
    return "one simulated station (trial 0)", list(ids), simulated_run


# ---------------------------------------------------------------------------------------------
# statistics of the paper (section 4.3)


def _as_products(name: str, a, minimum: int, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim == 0 or a.shape[0] < minimum:
        n = 0 if a.ndim == 0 else a.shape[0]
        raise CalibrationError(f"{what} needs at least {minimum} products; {name} holds {n}")
    geo.check_finite(name, a)
    return a


def _constant(a: np.ndarray) -> np.ndarray:
    """Which series (axis 0) are constant (range below 1e-12 of their size)."""
    return np.ptp(a, axis=0) <= 1e-12 * np.maximum(1.0, np.abs(a).max(axis=0))


def offsets(hybrid, cmm) -> np.ndarray:
    """The offset of each coordinate from ``n`` products (Eq. 24): ``mean(cmm - hybrid)``.

    Parameters
    ----------
    hybrid, cmm : (n, F, 3) arrays
        Readings of the same products and points, mm.

    Raises
    ------
    CalibrationError
        With fewer than 3 products, different shapes or non-finite values.
    """
    h = _as_products("hybrid", hybrid, 3, "an offset estimate")
    c = _as_products("cmm", cmm, 3, "an offset estimate")
    if h.shape != c.shape:
        raise CalibrationError(f"hybrid has shape {h.shape} and cmm {c.shape}; they must match")
    return np.mean(c - h, axis=0)


def compensate(hybrid, offset) -> np.ndarray:
    """Compensated readings (Eq. 25): ``hybrid + offset``, the offset broadcast over products.

    Parameters
    ----------
    hybrid : (n, ...) array
        Readings, products on axis 0, mm.
    offset : (...) array
        The offset of each coordinate (:func:`offsets`), mm.

    Returns
    -------
    numpy.ndarray, the shape of ``hybrid``

    Raises
    ------
    CalibrationError
        If the shapes do not match or a value is not finite.
    """
    h = geo.check_finite("hybrid readings", hybrid)
    o = geo.check_finite("offset", offset)
    if h.ndim == 0 or h.shape[1:] != o.shape:
        raise CalibrationError(f"offset has shape {o.shape}; readings {h.shape} need {h.shape[1:]}")
    return h + o


def correlations(hybrid, cmm) -> np.ndarray:
    """Pearson correlation of hybrid and CMM readings of each coordinate over products (Eq. 26).

    Parameters
    ----------
    hybrid, cmm : (n, ...) arrays
        Readings, products on axis 0.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``r`` per coordinate.

    Raises
    ------
    CalibrationError
        With fewer than 3 products, different shapes, or a constant series (``r`` is undefined;
        the message names the coordinates).
    """
    h = _as_products("hybrid", hybrid, 3, "a correlation coefficient")
    c = _as_products("cmm", cmm, 3, "a correlation coefficient")
    if h.shape != c.shape:
        raise CalibrationError(f"hybrid has shape {h.shape} and cmm {c.shape}; they must match")
    flat = _constant(h) | _constant(c)
    if np.any(flat):
        where = [tuple(int(i) for i in w) for w in np.argwhere(np.atleast_1d(flat))[:5]]
        raise CalibrationError(
            f"{int(flat.sum())} coordinate(s) are constant over the {h.shape[0]} products (first "
            f"at index {where}): the correlation coefficient is undefined there"
        )
    hc, cc = h - h.mean(axis=0), c - c.mean(axis=0)
    return np.sum(hc * cc, axis=0) / np.sqrt(np.sum(hc**2, axis=0) * np.sum(cc**2, axis=0))


def frame_fixed(hybrid, cmm) -> np.ndarray:
    """Coordinates ``(F, 3)`` fixed by the workpiece frame: constant and equal in both systems."""
    h, c = np.asarray(hybrid, dtype=float), np.asarray(cmm, dtype=float)
    return _constant(h) & _constant(c) & np.all(h == c, axis=0)


def deviation_bins(deviation) -> np.ndarray:
    """Counts ``(..., 5)`` of |deviation| (mm, last axis = coordinates) in Table 1's bins:
    <= 0.1, (0.1, 0.2], (0.2, 0.3], (0.3, 0.5], > 0.5 (edges from ``published.toml``)."""
    d = np.abs(np.asarray(deviation, dtype=float))
    idx = np.digitize(d, load_published().table1.deviation_edges_mm, right=True)
    return (idx[..., None] == np.arange(5)).sum(axis=-2)


def correlation_bins(r) -> np.ndarray:
    """Counts ``(..., 5)`` of correlation coefficients in Table 1's bins:
    > 0.9, (0.8, 0.9], (0.7, 0.8], (0.6, 0.7], <= 0.6 (edges from ``published.toml``)."""
    edges = load_published().table1.correlation_edges
    idx = 4 - np.digitize(np.asarray(r, dtype=float), edges, right=True)
    return (idx[..., None] == np.arange(5)).sum(axis=-2)


def shortfall_distance(counts, published_percent) -> np.ndarray:
    """How far a station's deviations fall short of the published accuracy over all bins: per
    row of ``counts (N, 5)`` (Table 1's deviation bins, smallest |deviation| first) the largest
    amount by which the published cumulative share exceeds the station's at a bin edge (0 when
    the station has at least the published share within every edge).

    The one-sided Kolmogorov distance of the whole bin distribution: "96.55 % within 0.3 mm,
    none beyond 0.5 mm" read at every edge (21.26 % within 0.1 mm, 68.39 % within 0.2 mm, ...).

    Parameters
    ----------
    counts : (N, 5) or (5,) array_like
        Bin counts per station.
    published_percent : (5,) array_like
        The published shares of the same bins, %.

    Returns
    -------
    (N,) ndarray
        The shortfall, a share (0-1).

    Raises
    ------
    CalibrationError
        If a row has no counts or the shapes differ.
    """
    c = np.atleast_2d(np.asarray(counts, dtype=float))
    pub = np.asarray(published_percent, dtype=float)
    if c.ndim != 2 or c.shape[1] != pub.size or np.any(c.sum(axis=1) <= 0):
        raise CalibrationError(
            f"a shortfall needs counts (N, {pub.size}) with counts in every row; got shape "
            f"{c.shape}, smallest row total {c.sum(axis=1).min():g}"
        )
    share = np.cumsum(c, axis=1) / c.sum(axis=1, keepdims=True)
    return np.maximum(0.0, (np.cumsum(pub) / pub.sum() - share)[:, :-1].max(axis=1))


def shortfall_bound(n_vectors: int, level: float = 0.05) -> float:
    """Critical one-sided Kolmogorov distance for ``n_vectors`` values against a fixed
    distribution, ``sqrt(-ln(level) / 2) / sqrt(n)`` (asymptotic): a station drawn from the
    published distribution falls short by more in a share ``level`` of cases.

    Raises
    ------
    CalibrationError
        If ``n_vectors`` is below 1 or ``level`` outside (0, 1).
    """
    if n_vectors < 1 or not 0.0 < level < 1.0:
        raise CalibrationError(f"n_vectors is {n_vectors} (>= 1) and level {level} (in (0, 1))")
    return float(np.sqrt(-np.log(level) / 2.0) / np.sqrt(n_vectors))


def analyse_run(run: dict, n_compensation: int) -> dict:
    """Table 1 of one run ``{phase: (hybrid, cmm)}`` with the offset from the first
    ``n_compensation`` products.

    Returns a dict: ``deviation`` (F, 3) mean compensated deviation over the follow-up,
    ``deviation_uncompensated`` (F, 3), ``r`` (F, 3) with NaN at the coordinates fixed by the
    frame, ``fixed`` (F, 3), ``deviation_counts`` (5,), ``correlation_counts`` (5,),
    the controls' bins ``deviation_counts_uncompensated`` (no offset),
    ``deviation_counts_oracle`` (the drift of a simulated run removed; None without
    ``run["drift"]``) and ``correlation_counts_mispaired`` (each hybrid reading against the CMM
    reading of the product half the follow-up later: a station that reports another panel),
    ``n_vectors``, ``n_fixed``, and the shares (%) ``within_0p3``, ``beyond_0p5``,
    ``within_0p3_uncompensated``, ``within_0p3_oracle`` (the drift of a simulated run removed;
    NaN without ``run["drift"]``),
    ``single_within_0p3`` (all single readings) and ``r_above_0p7`` (of the coordinates where r
    is defined).
    """
    comp_h, comp_c = run["compensation"]
    fu_h, fu_c = run["follow-up"]
    if n_compensation > comp_h.shape[0]:
        raise CalibrationError(
            f"n_compensation is {n_compensation} but only {comp_h.shape[0]} compensation "
            "products were measured"
        )
    off = offsets(comp_h[:n_compensation], comp_c[:n_compensation])
    comp = compensate(fu_h, off)
    single = comp - fu_c
    dev = single.mean(axis=0)
    dev_raw = (fu_h - fu_c).mean(axis=0)
    fixed = frame_fixed(np.concatenate([comp_h, fu_h]), np.concatenate([comp_c, fu_c]))
    r = np.full(dev.shape, np.nan)
    r[~fixed] = correlations(fu_h[:, ~fixed], fu_c[:, ~fixed])
    n_vec = dev.size
    counts_r = correlation_bins(r[~fixed])
    # null control of the correlation: each hybrid reading paired with the CMM reading of the
    # product half the follow-up later (a station that reports another panel's coordinates)
    later = np.roll(fu_c, fu_c.shape[0] // 2, axis=0)
    mispaired = correlations(fu_h[:, ~fixed], later[:, ~fixed])
    drift = run.get("drift")
    return {
        "deviation": dev,
        "deviation_uncompensated": dev_raw,
        "r": r,
        "fixed": fixed,
        "deviation_counts": deviation_bins(dev.ravel()),
        "deviation_counts_uncompensated": deviation_bins(dev_raw.ravel()),
        "deviation_counts_oracle": None if drift is None else deviation_bins((dev - drift).ravel()),
        "correlation_counts": counts_r,
        "correlation_counts_mispaired": correlation_bins(mispaired),
        "n_vectors": n_vec,
        "n_fixed": int(fixed.sum()),
        "within_0p3": 100.0 * np.mean(np.abs(dev) <= 0.3),
        "beyond_0p5": 100.0 * np.mean(np.abs(dev) > 0.5),
        "within_0p3_uncompensated": 100.0 * np.mean(np.abs(dev_raw) <= 0.3),
        "single_within_0p3": 100.0 * np.mean(np.abs(single) <= 0.3),
        # oracle control: the drift removed, i.e. the follow-up's systematic error held at the
        # one the offset was learned on (simulated runs only; a measured station has no truth)
        "within_0p3_oracle": np.nan
        if drift is None
        else 100.0 * np.mean(np.abs(dev - drift) <= 0.3),
        "r_above_0p7": 100.0 * counts_r[:3].sum() / max(1, counts_r.sum()),
    }


def before_compensation(run: dict, n_before: int) -> dict:
    """Deviations of the first ``n_before`` products before compensation (Fig. 6).

    Returns ``deviations`` (n, F, 3), ``mean`` and ``std`` (F, 3), ``fixed`` (F, 3), and per
    coordinate not fixed by the frame the Lilliefors statistic and p-value and the p-value of a
    one-sample t-test of a zero mean (NaN at fixed coordinates).
    """
    from scipy.stats import ttest_1samp

    h, c = run["compensation"]
    h, c = h[:n_before], c[:n_before]
    _as_products("hybrid", h, 4, "the before-compensation analysis")
    d = h - c
    fixed = frame_fixed(h, c)
    stat = np.full(d.shape[1:], np.nan)
    p_lf = np.full(d.shape[1:], np.nan)
    stat[~fixed], p_lf[~fixed] = lilliefors_tests(d[:, ~fixed])
    p_t = np.full(d.shape[1:], np.nan)
    p_t[~fixed] = ttest_1samp(d[:, ~fixed], 0.0, axis=0).pvalue
    return {
        "deviations": d,
        "mean": d.mean(axis=0),
        "std": d.std(axis=0, ddof=1),
        "fixed": fixed,
        "lilliefors_stat": stat,
        "lilliefors_p": p_lf,
        "t_test_p": p_t,
    }
