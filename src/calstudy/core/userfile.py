"""Reading the CSV files a user hands in: one tokeniser, one cell parser, one unit table.

Every reader of a user's table (pose lists, fixed-sphere measurements, the hybrid station's
measurement tables, a self-calibration cell's spheres and measurements) goes through
:func:`read_csv_table`, so the same file is read the same way and the same fault gives the same
error everywhere:

- a spreadsheet's export is accepted: a UTF-8 byte-order mark, ``;`` as the separator (when the
  header has no ``,``), ``#`` comment lines and blank lines;
- a missing file is a :class:`FileNotFoundError` naming it;
- malformed content is a :class:`~calstudy.core.errors.CalibrationError` naming the file, the
  row (1-based, as a spreadsheet shows it) and the column: a cell that is not a finite number
  (:func:`parse_number`; a decimal comma such as ``12,5`` is refused as such), a row with more
  or fewer cells than the header, a repeated or non-integer id (:func:`check_ids`).

A column states its unit by a suffix (``x_mm``, ``q1_deg``); :data:`LENGTH_UNITS` and
:data:`ANGLE_UNITS` are the units every reader accepts.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from calstudy.core.errors import CalibrationError

#: the length units a user's file may state, in mm per unit
LENGTH_UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: the angle units a user's file may state, in rad per unit
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}

_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+$")


def number_problem(text: str) -> str:
    """Why a cell's ``text`` is not a finite number, in words (for messages).

    Parameters
    ----------
    text : str
        The stripped cell.

    Returns
    -------
    str
        ``""`` for a finite number; else the reason (an empty cell, a decimal comma with the
        number as it should be written, not a number, not finite).
    """
    if text == "":
        return "is not a number (empty cell)"
    if _DECIMAL_COMMA.match(text):
        return f"is not a number (decimal comma? write {text.replace(',', '.')})"
    try:
        value = float(text)
    except ValueError:
        return "is not a number"
    return "is not finite" if not math.isfinite(value) else ""


def parse_number(path: str | Path, line: int, column: str, text: str) -> float:
    """The number in one cell of a CSV file.

    Parameters
    ----------
    path : str or pathlib.Path
        The file, for the message.
    line : int
        The cell's row (1-based file line, as :func:`read_csv_table` gives it).
    column : str
        The cell's column name.
    text : str
        The stripped cell.

    Returns
    -------
    float
        ``float(text)``.

    Raises
    ------
    CalibrationError
        If ``text`` is not a finite number, naming the file, row, column, text and why
        (:func:`number_problem`; a decimal comma such as ``12,5`` is named as such).
    """
    problem = number_problem(text)
    if problem:
        raise CalibrationError(f"{path}: row {line}, column {column!r}: {text!r} {problem}")
    return float(text)


def read_csv_table(path: str | Path, what: str) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and rows of a spreadsheet-written CSV file.

    Accepts a UTF-8 byte-order mark, ``,`` or ``;`` as the separator (``;`` when the header has
    no ``,``, as European spreadsheets write it), ``#`` comment lines and blank lines.

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file.
    what : str
        What the file holds, for the messages (``"pose list"``).

    Returns
    -------
    header : list of str
        Stripped column names.
    rows : list of (int, list of str)
        File line number (1-based, as a spreadsheet shows it) and stripped cells of each row.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file (naming it and ``what``).
    CalibrationError
        For a file without data rows (empty or a header only), a file that is not UTF-8 text,
        or a row whose cell count differs from the header's (naming the row; a decimal comma is
        the usual cause).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (the {what})")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CalibrationError(
            f"{path}: not a UTF-8 text file (byte {exc.start}: {exc.reason}); save it as "
            "CSV UTF-8"
        ) from None
    lines = [
        (i, ln)
        for i, ln in enumerate(text.splitlines(), start=1)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if len(lines) < 2:
        raise CalibrationError(
            f"{path}: no data rows (the {what} {'has a header only' if lines else 'is empty'})"
        )
    first = lines[0][1]
    delimiter = ";" if ";" in first and "," not in first else ","
    parsed = list(csv.reader(io.StringIO("\n".join(ln for _, ln in lines)), delimiter=delimiter))
    header = [h.strip() for h in parsed[0]]
    rows = []
    for (line, _), cells in zip(lines[1:], parsed[1:], strict=True):
        if len(cells) != len(header):
            hint = (
                " (a decimal comma such as 12,5 splits a cell in two: write 12.5)"
                if len(cells) > len(header) and delimiter == ","
                else ""
            )
            raise CalibrationError(
                f"{path}: row {line} has {len(cells)} cells; the header has {len(header)}{hint}"
            )
        rows.append((line, [c.strip() for c in cells]))
    return header, rows


def require_columns(path: str | Path, header: Iterable[str], columns: Iterable[str]) -> None:
    """Refuse a header that lacks any of ``columns``.

    Parameters
    ----------
    path : str or pathlib.Path
        The file, for the message.
    header : iterable of str
        The column names of the file.
    columns : iterable of str
        The column names required.

    Raises
    ------
    CalibrationError
        Naming the file, the missing columns and the header found.
    """
    have = set(header)
    missing = [c for c in columns if c not in have]
    if missing:
        raise CalibrationError(
            f"{path}: missing column(s) {', '.join(missing)} (the header has "
            f"{', '.join(header) or 'nothing'})"
        )


def check_ids(
    path: str | Path, ids: np.ndarray, lines, column: str = "id", unique: bool = True
) -> np.ndarray:
    """An id column of a CSV file, checked to hold integers, distinct ones if ``unique``.

    Parameters
    ----------
    path : str or pathlib.Path
        The file, for the messages.
    ids : numpy.ndarray, shape (N,)
        The parsed column, first data row first.
    lines : sequence of int, length N
        The file line of each row (as :func:`read_csv_table` gives it), for the messages.
    column : str
        The column's name, for the messages.
    unique : bool
        Refuse a value that appears more than once.

    Returns
    -------
    numpy.ndarray of int, shape (N,)
        The ids.

    Raises
    ------
    CalibrationError
        Naming the row of a value that is not an integer, or the id that appears more than once.
    """
    if np.any(ids != np.round(ids)):
        bad = int(np.argmax(ids != np.round(ids)))
        raise CalibrationError(
            f"{path}: row {lines[bad]}, column {column!r}: {ids[bad]} is not an integer"
        )
    uniq, counts = np.unique(ids, return_counts=True)
    if unique and np.any(counts > 1):
        raise CalibrationError(
            f"{path}: {column} {int(uniq[counts > 1][0])} appears more than once"
        )
    return ids.astype(int)
