"""Tables, claim rows and figures as a notebook shows them in the book.

The book's column is about 780 px wide: :func:`show_table` formats numbers, writes units in the
headers, keeps at most ``max_columns`` columns per table (a wide table is transposed when it has
few rows, split into several tables otherwise) and writes an em dash, with the reason if one is
given, where a value is missing. :func:`show_claims` is the compact table of a notebook's
verdicts. :func:`figure_html` embeds a saved PNG with an alt text that describes it
(``notebook_writers``' ``show_figure(fig, name, alt=...)`` uses it). Each ``show_*`` displays
and returns None, so a cell that ends with it prints no object; the ``format_*`` functions are
the pure parts, returning what would be shown.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import math
import numbers
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.claims import claim_register
from calstudy.core.labels import label, plain
from calstudy.io.claims_cells import published_figure, typeset

#: What a missing value is shown as.
MISSING = "—"

_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")

def format_value(value: object, digits: int = 4) -> str:
    """One cell as text: floats to ``digits`` significant digits (no ``1e-16`` noise shown as
    more than it is; powers of ten as ``1.2×10⁻⁵``), integers as integers, booleans as yes/no,
    missing as an em dash, text with ± µm ≤ ≥ → for ``+-``, ``um``, ``<=``, ``>=``, ``->`` and
    claim ids and bare identifiers in words (:func:`calstudy.core.labels.plain`)."""
    if value is None or value is pd.NA or value is pd.NaT:
        return MISSING
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, numbers.Integral):
        return f"{int(value):d}"
    if isinstance(value, numbers.Real):
        x = float(value)
        if math.isnan(x):
            return MISSING
        if math.isinf(x):
            return "∞" if x > 0 else "−∞"
        if x == 0.0:
            return "0"
        if float(x).is_integer() and abs(x) < 10**digits:
            return f"{int(x):d}"
        text = f"{x:.{digits}g}"
        if "e" in text:
            mantissa, exponent = text.split("e")
            return f"{mantissa}×10{str(int(exponent)).translate(_SUPERSCRIPT)}"
        return text
    text = str(value)
    if text.strip() in ("", "nan", "NaN", "None", "<NA>"):
        return MISSING
    return plain(typeset(text))


def format_table(
    df: pd.DataFrame,
    *,
    units: Mapping[str, str] | None = None,
    digits: int | Mapping[str, int] = 4,
    max_columns: int = 8,
    keys: Sequence[str] | None = None,
    missing: Mapping[str, str] | None = None,
) -> tuple[list[pd.DataFrame], list[str]]:
    """The tables :func:`show_table` displays, as string DataFrames, and its footnotes.

    Parameters
    ----------
    df : pandas.DataFrame
        The table (its index is kept only if it is named or not a plain range).
    units : mapping, optional
        Unit of a column, shown in its header; columns named ``*_mm``, ``*_deg``, ... get their
        unit from the suffix (:data:`calstudy.core.labels.UNIT_SUFFIXES`).
    digits : int or mapping, default 4
        Significant digits of floats, for all columns or per column.
    max_columns : int, default 8
        Widest table shown. A wider one with a key column and fewer than ``max_columns`` rows
        is transposed (its rows become columns, headed by the key's values, beside a column of
        the former headers headed by the key's name); otherwise it is split into tables of at
        most ``max_columns``
        columns, each repeating the key columns. In the book the tables also stay within the
        column at any width (``book/_static/calstudy.css``: long header words break).
    keys : sequence of str, optional
        Columns that identify a row; default the leading non-numeric columns (at most 2).
    missing : mapping, optional
        Why values of a column are missing, as a footnote: ``{"ci_low": "fewer than 2
        trials"}``.

    Returns
    -------
    tables : list of pandas.DataFrame
        One or more tables of text cells, each at most ``max_columns`` wide.
    notes : list of str
        Footnotes on the missing values.
    """
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"format_table needs a pandas DataFrame, got {type(df).__name__}")
    if max_columns < 2:
        raise ValueError(f"max_columns is {max_columns}; it must be at least 2")
    data = df.copy()
    if data.index.name is not None or not isinstance(data.index, pd.RangeIndex):
        data = data.reset_index()
    units = dict(units or {})
    missing = dict(missing or {})
    if keys is None:
        keys = []
        for col in data.columns:
            if pd.api.types.is_numeric_dtype(data[col]) or len(keys) == 2:
                break
            keys.append(col)
    keys = [k for k in keys if k in data.columns]

    notes = []
    for col in data.columns:
        n = int(data[col].isna().sum()) if data[col].dtype != object else int(
            sum(format_value(v) == MISSING for v in data[col])
        )
        if n:
            reason = missing.get(col, "no value")
            notes.append(f"{MISSING} in {label(col, units.get(col))}: {reason} ({n} cell(s))")

    def column_digits(col) -> int:
        return digits.get(col, 4) if isinstance(digits, Mapping) else int(digits)

    text = pd.DataFrame(
        {
            label(col, units.get(col)): [format_value(v, column_digits(col)) for v in data[col]]
            for col in data.columns
        }
    )
    key_headers = [label(k, units.get(k)) for k in keys]
    if text.shape[1] <= max_columns:
        return [text], notes
    if key_headers and len(text) + 1 <= max_columns:  # rows become columns, headed by the key
        key = key_headers[0]
        flipped = text.set_index(key).T
        flipped.columns = [str(c) for c in flipped.columns]
        flipped.insert(0, key, flipped.index)
        return [flipped.reset_index(drop=True)], notes
    rest = [c for c in text.columns if c not in key_headers]
    width = max(1, max_columns - len(key_headers))
    tables = [text[key_headers + rest[i : i + width]] for i in range(0, len(rest), width)]
    return tables, notes


#: A cell that reads as a number (right-aligned in the book): ``-1.5``, ``2×10⁻³``, ``12 %``.
_NUMERIC = re.compile(r"^[-+−]?(\d[\d,]*(\.\d+)?|\.\d+)(×10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)?( ?%)?$|^[−-]?∞$")


def _td(value: object) -> str:
    text = str(value)
    cls = ' class="num"' if _NUMERIC.match(text) or text == MISSING else ""
    return f"<td{cls}>{html.escape(text)}</td>"


def _table_html(table: pd.DataFrame, caption: str | None) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in table.columns)
    rows = "".join(
        "<tr>" + "".join(_td(v) for v in row) + "</tr>" for row in table.itertuples(index=False)
    )
    cap = f"<caption>{html.escape(plain(typeset(caption)))}</caption>" if caption else ""
    return (
        f'<table class="calstudy-table">{cap}<thead><tr>{head}</tr></thead>'
        f"<tbody>{rows}</tbody></table>"
    )


#: Rows of a table shown open; a longer one is folded into a dropdown headed by its caption.
LONG_TABLE_ROWS = 12


def table_html(
    df: pd.DataFrame, *, caption: str | None = None, **options
) -> str:
    """HTML of :func:`show_table` (the options are those of :func:`format_table`); a table of
    more than :data:`LONG_TABLE_ROWS` rows is folded into a ``<details>`` dropdown whose
    summary is its caption and row count."""
    tables, notes = format_table(df, **options)
    parts = [_table_html(t, caption if i == 0 else None) for i, t in enumerate(tables)]
    if notes:
        parts.append(
            '<p class="calstudy-table-notes"><small>'
            + "<br>".join(html.escape(n) for n in notes)
            + "</small></p>"
        )
    rows = max(len(t) for t in tables)
    if rows > LONG_TABLE_ROWS:
        title = html.escape(plain(typeset(caption)).rstrip(".")) if caption else "Table"
        parts = [f'<details class="calstudy-long"><summary>{title} ({rows} rows)</summary>',
                 *parts, "</details>"]
    return "\n".join(parts)


def _display(bundle: dict) -> None:
    from IPython.display import display

    display(bundle, raw=True)


def show_table(df: pd.DataFrame, *, caption: str | None = None, **options) -> None:
    """Display ``df`` formatted for the book's column (see :func:`format_table` for
    ``units``, ``digits``, ``max_columns``, ``keys`` and ``missing``); returns None."""
    tables, notes = format_table(df, **options)
    plain = "\n\n".join(t.to_string(index=False) for t in tables)
    if notes:
        plain += "\n" + "\n".join(notes)
    _display({"text/html": table_html(df, caption=caption, **options), "text/plain": plain})


# ----------------------------------------------------------------------------------------------
# claims


def _as_dict(row: object) -> dict:
    if dataclasses.is_dataclass(row) and not isinstance(row, type):
        return dataclasses.asdict(row)
    if isinstance(row, Mapping):
        return dict(row)
    if isinstance(row, pd.Series):
        return row.to_dict()
    raise TypeError(f"a claim row is a ClaimRow, a mapping or a Series, not {type(row).__name__}")


def _published_cell(row: dict, unit: str, register: dict) -> str:
    """The published figure in the unit of the reproduced one, computed from the register's
    figures as on the claims page; the row's own text for a claim not in the register."""
    claim = register.get(row.get("id"))
    if claim is None:
        published = typeset(row.get("published", ""))
        return f"{published} {typeset(unit)}".strip() if published else "none in the paper"
    pub = published_figure(claim, unit)
    return f"{pub.text} ({pub.detail})" if pub.detail else pub.text


def format_claims(
    rows: Iterable[object] | pd.DataFrame, register: pd.DataFrame | None = None
) -> pd.DataFrame:
    """The compact claims table of :func:`show_claims`: one row per claim, text cells.

    The published figure is that of the claims register (``register``, default
    ``data/claims.csv``) in the unit of the reproduced one (a ratio computed from the paper's
    figures), or says why there is none.
    """
    if isinstance(rows, pd.DataFrame):
        records = [r for _, r in rows.iterrows()]
    else:
        records = list(rows)
    reg = claim_register() if register is None else register
    by_id = {c["id"]: c.to_dict() for _, c in reg.iterrows()}
    out = []
    for row in map(_as_dict, records):
        unit = str(row.get("unit", "") or "")
        value = format_value(row.get("reproduced"), 3)
        lo, hi = format_value(row.get("ci_low"), 3), format_value(row.get("ci_high"), 3)
        reproduced = value if value == MISSING else f"{value} {unit}".strip()
        if value != MISSING and MISSING not in (lo, hi):
            reproduced += f" [{lo}, {hi}]"
        rate = row.get("replication_rate")
        rate_text = (
            MISSING
            if rate is None or not math.isfinite(float(rate))
            else f"{100 * float(rate):.0f} %"
        )
        n = int(row.get("n", 0) or 0)
        controls = "; ".join(
            f"{name}: {row[key]}"
            for name, key in (("null", "null_control"), ("oracle", "oracle_control"))
            if str(row.get(key, "") or "").strip()
        )
        out.append(
            {
                "claim": row.get("id", ""),
                "published": _published_cell(row, unit, by_id),
                "reproduced [95 % CI]": reproduced,
                "N": str(n) if n > 0 else MISSING,
                "repl. rate": rate_text,
                "verdict": row.get("verdict", ""),
                "controls": controls or MISSING,
            }
        )
    return pd.DataFrame(out)


def show_claims(rows: Iterable[object] | pd.DataFrame, *, caption: str | None = None) -> None:
    """Display a notebook's claim rows (``ClaimRow`` objects, mappings or a DataFrame) as one
    compact table: claim, published, reproduced with its interval, N, replication rate, verdict
    and controls; the long note stays in ``claims.csv`` and on the claims page."""
    table = format_claims(rows)
    show_table(table, caption=caption, keys=["claim"], max_columns=8)


# ----------------------------------------------------------------------------------------------
# figures


def figure_html(path: str | Path, alt: str, width: int | None = None) -> str:
    """An ``<img>`` holding the PNG ``path`` inline, with ``alt`` as its alt text."""
    if not alt or not alt.strip():
        raise ValueError("a figure needs an alt text that describes it")
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    size = f' width="{int(width)}"' if width else ""
    return (
        f'<img src="data:image/png;base64,{data}" alt="{html.escape(alt.strip(), quote=True)}"'
        f'{size} style="max-width: 100%; height: auto;">'
    )


def show_png(path: str | Path, alt: str, width: int | None = None) -> None:
    """Display the saved PNG ``path`` with its alt text; returns None."""
    _display({"text/html": figure_html(path, alt, width), "text/plain": f"[figure: {alt}]"})


def _label(text: str) -> str:
    """An axis label or title as plain words: no mathtext dollars or backslashes."""
    text = re.sub(r"\\(mathrm|mathit|mathbf|rm)\{([^}]*)\}", r"\2", text or "")
    text = text.replace("$", "").replace("\\", "").replace("{", "").replace("}", "")
    return " ".join(text.split())


def describe_figure(fig, name: str, limit: int = 400) -> str:
    """A description of a matplotlib figure read from its own labels, for an alt text when a
    notebook gives none: its name, then per panel its title and what it plots against what
    (``'Figure "pose residuals", 2 panels: "rotation" residual (deg) against pose; ...'``).
    """
    panels = []
    for ax in fig.get_axes():
        if not ax.get_visible() or not ax.axison or ax.get_label() == "<colorbar>":
            continue
        title = _label(ax.get_title() or ax.get_title(loc="left"))
        x, y = _label(ax.get_xlabel()), _label(ax.get_ylabel())
        what = f"{y} against {x}" if x and y else (y or x)
        panel = " ".join(p for p in (f'"{title}"' if title else "", what) if p)
        if panel:
            panels.append(panel)
    suptitle = fig.get_suptitle()
    head = f'Figure "{name.replace("_", " ")}"'
    if suptitle:
        head += f" ({_label(suptitle)})"
    if len(panels) > 1:
        head += f", {len(panels)} panels"
    text = f"{head}: {'; '.join(panels)}" if panels else f"{head}, a plot without axis labels"
    return text if len(text) <= limit else text[: limit - 1].rsplit(" ", 1)[0] + " …"
