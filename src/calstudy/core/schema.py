"""Validation of the files a user hands in: pydantic schemas with messages that name the place.

A file's schema is a :class:`Schema` (a pydantic model that forbids unknown keys, so a misspelt
key is reported rather than ignored). :func:`validate` checks a parsed TOML table or a CSV row
against it and turns pydantic's :class:`~pydantic.ValidationError` into one
:class:`~calstudy.core.errors.CalibrationError` whose message names the file, every bad key (or
row and column), the value found and the allowed range::

    data/robots/my_robot.toml: link #2.a_mm = 68000.0: must be <= 10000.0
    my_handeye.csv: row 7, column 'sz': '12,5' is not a number (decimal comma? write 12.5)

:func:`load_toml` reads and validates a TOML file in one call; :func:`read_csv_table` reads a CSV
the way a spreadsheet writes it (byte-order mark, ``;`` as separator, ``#`` comment lines) and
:func:`validate_rows` checks its rows. The range types (:data:`Finite`, :data:`PositiveFinite`,
...) are the building blocks of the schemas.

A paper's ``scenario.py`` uses it as::

    class Station(Schema):
        sphere_radius_mm: PositiveFinite
        views_per_sphere: PositiveInt
        loss_rate: Fraction

    class ScenarioFile(Schema):
        station: Station
        robot: str

    raw = load_toml(path, ScenarioFile, "hybrid scenario")   # CalibrationError naming key
"""

from __future__ import annotations

import copy
import csv
import io
import math
import re
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, TypeVar, get_args

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import DATA_DIR

M = TypeVar("M", bound=BaseModel)

#: a finite float (NaN and infinity refused)
Finite = Annotated[float, Field(allow_inf_nan=False)]
#: a finite float > 0
PositiveFinite = Annotated[float, Field(gt=0, allow_inf_nan=False)]
#: a finite float >= 0
NonNegativeFinite = Annotated[float, Field(ge=0, allow_inf_nan=False)]
#: a probability or rate in [0, 1]
Fraction = Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]
#: an integer >= 1
PositiveInt = Annotated[int, Field(ge=1)]
#: an integer >= 0
NonNegativeInt = Annotated[int, Field(ge=0)]
#: largest image side of any camera of the scenarios, px (today's sensors reach about 14,000)
MAX_PIXELS = 20000
#: an image side in pixels
Pixels = Annotated[int, Field(ge=1, le=MAX_PIXELS)]


class Schema(BaseModel):
    """Base of every file schema: unknown keys are errors, values are checked strictly (a
    quoted ``"12"`` or ``true`` is not silently a number in a TOML file, ``6.0`` not a count)
    but a float may be written as an int. CSV rows, whose cells are text, are validated with
    the text parsed (:func:`validate_rows`). An array of fixed positions (``tuple[...]``)
    must be declared with :data:`Row` so that a TOML array passes."""

    model_config = ConfigDict(extra="forbid", frozen=True, str_strip_whitespace=True, strict=True)


def _as_tuple(value: Any) -> Any:
    return tuple(value) if isinstance(value, list) else value


#: marks a ``tuple[...]`` type as a TOML array of fixed positions: ``Annotated[tuple[int,
#: float], Row]`` (strict validation takes tuples only)
Row = BeforeValidator(_as_tuple)

#: three finite numbers (a position, a direction, a rotation vector)
Vec3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
#: two finite numbers
Vec2 = Annotated[list[Finite], Field(min_length=2, max_length=2)]
#: an angle in degrees, within one turn either way (a value within +-pi everywhere is not refused
#: here: a scenario file declares degrees in its key names)
Degrees = Annotated[float, Field(ge=-360, le=360, allow_inf_nan=False)]

_DOC_KEY = re.compile(r"^(source|assumption|note|reason)s?$|_(source|assumption|note|reason)s?$")


class Documented(Schema):
    """A table of a scenario file: numbers with their ``source`` / ``assumption`` / ``*_note``
    texts beside them. The texts (string values under such names) are dropped before the
    numbers are checked, so they need not be declared, while a misspelt number key is still
    refused."""

    @model_validator(mode="before")
    @classmethod
    def _drop_documentation(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        return {
            k: v
            for k, v in data.items()
            if not (isinstance(v, str) and _DOC_KEY.search(k) and k not in cls.model_fields)
        }


_BOUNDS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}


def _key(loc: Sequence[Any]) -> str:
    """``('link', 1, 'a_mm')`` -> ``link #2.a_mm`` (entries of an array counted from 1, as a
    reader of the file counts them)."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f" #{part + 1}"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def _submodel(annotation) -> type[BaseModel] | None:
    """The pydantic model inside ``annotation`` (``Model``, ``list[Model]``, ``Model | None``)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in get_args(annotation):
        found = _submodel(arg)
        if found is not None:
            return found
    return None


def _field_bounds(model: type[BaseModel] | None, loc: Sequence[Any]) -> dict[str, Any]:
    """The bounds (gt, ge, lt, le) declared on the field at ``loc`` of ``model``, if any."""
    current, info = model, None
    for part in loc:
        if isinstance(part, int):
            continue
        if current is None or part not in current.model_fields:
            return {}
        info = current.model_fields[part]
        current = _submodel(info.annotation)
    if info is None:
        return {}
    out = {}
    for meta in info.metadata:
        for key in _BOUNDS:
            if getattr(meta, key, None) is not None:
                out[key] = getattr(meta, key)
    return out


def _describe(err: dict, model: type[BaseModel] | None = None) -> str:
    """The allowed range or type of one pydantic error, in words."""
    kind, ctx = err.get("type", ""), err.get("ctx") or {}
    if any(k in ctx for k in _BOUNDS):
        ctx = {**_field_bounds(model, err["loc"]), **ctx}
    bounds = [f"{_BOUNDS[k]} {ctx[k]}" for k in _BOUNDS if k in ctx]
    if bounds:
        return "must be " + " and ".join(bounds)
    if kind == "missing":
        return "missing (required)"
    if kind == "extra_forbidden":
        return "unknown key (misspelt?)"
    if kind == "finite_number":
        return "must be a finite number"
    if kind in ("float_parsing", "int_parsing", "float_type", "int_type"):
        return "is not a number" if kind.startswith("float") else "is not an integer"
    if kind == "int_from_float":
        return "is not an integer"
    if kind in ("too_short", "too_long"):
        have = ctx.get("actual_length")
        if kind == "too_short":
            return f"must have at least {ctx.get('min_length')} entries, not {have}"
        return f"must have at most {ctx.get('max_length')} entries, not {have}"
    if kind == "string_type":
        return "is not a text (write it in quotes)"
    if kind == "literal_error":
        return f"is not one of {ctx.get('expected', '')}"
    return str(err.get("msg", kind)).replace("Value error, ", "")


def _value(err: dict) -> str:
    if err.get("type") in ("missing",):
        return ""
    value = err.get("input")
    if isinstance(value, dict | list) and len(repr(value)) > 60:
        return ""
    return f" = {value!r}"


def format_errors(
    exc: ValidationError,
    source: str | Path,
    prefix: str = "",
    model: type[BaseModel] | None = None,
) -> str:
    """One message for all errors of ``exc``: ``source: key = value: allowed range; ...``
    (the whole declared range of the key when ``model`` is given)."""
    parts = []
    for err in exc.errors(include_url=False):
        if not err["loc"] and not prefix:
            parts.append(_describe(err, model))  # a rule across tables names its own keys
            continue
        key = _key(err["loc"])
        key = f"{prefix}{key}" if prefix else key
        parts.append(f"{key}{_value(err)}: {_describe(err, model)}")
    return f"{source}: " + "; ".join(parts)


def validate(
    model: type[M], data: Any, source: str | Path, prefix: str = "", study: bool = False
) -> M:
    """``model`` validated from ``data``; a :class:`CalibrationError` naming ``source``, each bad
    key (with ``prefix`` in front, e.g. ``"station."``), its value and the allowed range.
    ``study`` marks a file of the study's own ``data/`` (its validators see it in the context:
    :mod:`calstudy.core.ledger` refuses inputs marked ``user`` there)."""
    try:
        return model.model_validate(data, context={"study": study})
    except ValidationError as exc:
        raise CalibrationError(format_errors(exc, source, prefix, model)) from None


def is_study_file(path: str | Path) -> bool:
    """True if ``path`` is a file of the study's own ``data/`` folder (not a user's copy)."""
    return Path(path).resolve().is_relative_to(DATA_DIR)


def file_key(path: Path) -> tuple:
    """(resolved path, modification time, size) of an existing file: a changed file has a new
    key."""
    stat = path.stat()
    return (str(path.resolve()), stat.st_mtime_ns, stat.st_size)


def read_toml(path: str | Path, what: str) -> dict:
    """The TOML table of ``path``; FileNotFoundError naming the path and ``what`` if missing,
    CalibrationError with the parser's line and column if it is not valid TOML."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (the {what})")
    key = file_key(path)
    if key in _PARSED:
        return copy.deepcopy(_PARSED[key])
    try:
        with path.open("rb") as handle:
            table = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{path}: not valid TOML ({exc})") from exc
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"{path}: not a UTF-8 text file ({exc.reason})") from exc
    if len(_PARSED) >= 64:
        _PARSED.clear()
    _PARSED[key] = table
    return copy.deepcopy(table)


#: parsed TOML tables by (resolved path, modification time, size): a Monte Carlo trial builds its
#: scenario from the same few files again and again, and parsing them costs more than the copy
#: handed out (an edited file has a new key, so it is read again)
_PARSED: dict[tuple[str, int, int], dict] = {}


def check_toml(path: str | Path, model: type[BaseModel], what: str) -> dict:
    """The TOML table of ``path`` (the ``what``, for messages) after validating it against
    ``model``: for loaders that go on reading the dict (the numbers stay the bytes of the file).
    The ``provenance`` entries of the assumption ledger (:mod:`calstudy.core.ledger`) are
    dropped from it: they describe the inputs and are none themselves."""
    table = read_toml(path, what)  # a copy of the parsed file, kept by its file_key
    key = (*file_key(Path(path)), model)
    if key not in _VALIDATED:
        validate(model, table, path, study=is_study_file(path))
        if len(_VALIDATED) >= 64:
            _VALIDATED.clear()
        _VALIDATED.add(key)
    return without_provenance(table)


def without_provenance(table: Any) -> Any:
    """``table`` with the ``provenance`` entry of every (nested) table removed."""
    if isinstance(table, dict):
        return {k: without_provenance(v) for k, v in table.items() if k != PROVENANCE}
    return table


#: the key of a table's ledger entries (:mod:`calstudy.core.ledger`)
PROVENANCE = "provenance"


#: (resolved path, modification time, size, model) of the files that passed :func:`check_toml`:
#: every Monte Carlo trial draws its station from the same files, and validating them costs
#: more than the rest of the loading (an edited file has a new key, so it is checked again)
_VALIDATED: set = set()


def rotation_problem(matrix, tol: float = 1e-4) -> str:
    """Why the upper-left 3 x 3 block of ``matrix`` is not a rotation (``R^T R = I`` within
    ``tol`` per entry, ``det R = +1``), in words; ``""`` if it is one."""
    rot = np.asarray(matrix, dtype=float)[:3, :3]
    err = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if not np.isfinite(err) or err > tol:
        return f"its rotation is not orthonormal (max |R^T R - I| = {err:.3g}, allowed {tol:g})"
    det = float(np.linalg.det(rot))
    if det < 0:
        return f"its rotation is a reflection (det R = {det:.6g})"
    return ""


def check_principal_point(cx: float, cy: float, width: int, height: int) -> None:
    """For a camera schema's validator: raise ValueError unless the principal point ``(cx, cy)``
    lies inside the ``width`` x ``height`` px image."""
    if not (0 <= cx < width and 0 <= cy < height):
        raise ValueError(
            f"principal point ({cx}, {cy}) lies outside the {width} x {height} px image"
        )


def load_toml(path: str | Path, model: type[M], what: str) -> M:
    """Read the TOML file ``path`` (the ``what``, for messages) and validate it against
    ``model``."""
    return validate(model, read_toml(path, what), path, study=is_study_file(path))


def apply_overrides(table: dict, overrides: Mapping[str, object] | None) -> dict:
    """A copy of the parsed TOML ``table`` with some inputs set by their dotted keys.

    The copy is validated like the file (by the caller), so a value outside its ledger range
    is refused there as in the file itself.

    Parameters
    ----------
    table : dict
        A parsed scenario file (not changed).
    overrides : mapping of str to object, or None
        Dotted key (``"detection.sigma_px"``) to its new value; None or empty for none.

    Returns
    -------
    dict
        A new table.

    Raises
    ------
    CalibrationError
        If a dotted key names no input of ``table`` (the message names the key).
    """
    out = copy.deepcopy(table)
    for key, value in (overrides or {}).items():
        *path, name = str(key).split(".")
        node = out
        for part in path:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or name not in node or isinstance(node[name], dict):
            raise CalibrationError(f"override {key!r}: the scenario has no input of that name")
        node[name] = copy.deepcopy(value)
    return out


# ----------------------------------------------------------------------------------------------
# CSV files


_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+$")


def number_problem(text: str) -> str:
    """Why ``text`` is not a finite number, in words (for messages)."""
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
    """``float(text)`` of the cell in row ``line`` (1-based, the header is row 1) and ``column``
    of the CSV file ``path``; CalibrationError naming all three if it is not a finite number."""
    problem = number_problem(text)
    if problem:
        raise CalibrationError(f"{path}: row {line}, column {column!r}: {text!r} {problem}")
    return float(text)


def read_csv_table(path: str | Path, what: str) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and rows of a spreadsheet-written CSV file.

    Accepts a UTF-8 byte-order mark, ``,`` or ``;`` as the separator (``;`` when the header has
    no ``,``, as European spreadsheets write it), ``#`` comment lines and blank lines.

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
        For an empty file, a file that is not UTF-8 text, or a row whose cell count differs
        from the header's (naming the row; a decimal comma is the usual cause).
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
    if not lines:
        raise CalibrationError(f"{path}: the file is empty (no header)")
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
    """CalibrationError naming the file and the missing columns, if any."""
    have = set(header)
    missing = [c for c in columns if c not in have]
    if missing:
        raise CalibrationError(
            f"{path}: missing column(s) {', '.join(missing)} (the header has "
            f"{', '.join(header) or 'nothing'})"
        )


def validate_rows(
    model: type[M], header: Sequence[str], rows: Sequence[tuple[int, Sequence[str]]], path
) -> list[M]:
    """Each row (from :func:`read_csv_table`) validated against ``model``; the first bad cell is
    reported with its row, column, text and what is allowed."""
    out = []
    fields = model.model_fields
    for line, cells in rows:
        record = {h: c for h, c in zip(header, cells, strict=True) if h in fields}
        try:
            out.append(model.model_validate(record, strict=False))
        except ValidationError as exc:
            err = exc.errors(include_url=False)[0]
            column = str(err["loc"][0]) if err["loc"] else "?"
            text = record.get(column, "")
            problem = number_problem(text) if err["type"].startswith(("float", "finite")) else ""
            raise CalibrationError(
                f"{path}: row {line}, column {column!r}: {text!r} "
                f"{problem or _describe(err, model)}"
            ) from None
    return out


__all__ = [
    "apply_overrides",
    "Degrees",
    "Documented",
    "Finite",
    "Fraction",
    "MAX_PIXELS",
    "NonNegativeFinite",
    "NonNegativeInt",
    "PositiveFinite",
    "PositiveInt",
    "Pixels",
    "Row",
    "Schema",
    "Vec2",
    "Vec3",
    "check_toml",
    "file_key",
    "format_errors",
    "is_study_file",
    "load_toml",
    "number_problem",
    "parse_number",
    "read_csv_table",
    "read_toml",
    "require_columns",
    "rotation_problem",
    "validate",
    "validate_rows",
    "without_provenance",
]
