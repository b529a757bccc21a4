"""Validation of the files a user hands in: pydantic schemas with messages that name the place.

A file's schema is a :class:`Schema` (a pydantic model that forbids unknown keys, so a misspelt
key is reported rather than ignored). :func:`validate` checks a parsed TOML table or a CSV row
against it and turns pydantic's :class:`~pydantic.ValidationError` into one
:class:`~calstudy.core.errors.CalibrationError` whose message names the file, every bad key (or
row and column), the value found and the allowed range::

    data/robots/my_robot.toml: link #2.a_mm = 68000.0: must be <= 10000.0
    my_handeye.csv: row 7, column 'sz': '12,5' is not a number (decimal comma? write 12.5)

:func:`load_model` reads and validates a TOML file in one call, with :func:`apply_overrides`
replacing some of its inputs first (checked as if the file held them); the validated model is
then the scenario itself, frozen, its derived values cached on it. :meth:`Schema.replace` makes a
changed copy without validation (an oracle, a sweep point beyond the file's ranges),
:func:`with_inputs` one validated again. :func:`validate_rows` checks the rows of a CSV file
that :func:`calstudy.core.userfile.read_csv_table` read. The range types (:data:`Finite`,
:data:`PositiveFinite`, ...), :func:`rigid_transform` (:data:`Rigid4x4`), :class:`Pinhole`,
:class:`Radians` and :class:`Texts` are the building blocks of the schemas; :func:`ordered`,
:func:`one_each` and :func:`distinct` their rules across keys (two inputs in order, lists of one
length, names given once), and :func:`load_paper_file` loads a paper's file or one's own copy.

A paper's ``scenario.py`` uses it as::

    class Station(Schema):
        sphere_radius_mm: PositiveFinite
        views_per_sphere: PositiveInt
        loss_rate: Fraction

    class ScenarioFile(Schema):
        station: Station
        robot: str

    scenario = load_model(path, ScenarioFile, "hybrid scenario")   # CalibrationError naming key
    scenario.station.views_per_sphere   # the validated file is the scenario
"""

from __future__ import annotations

import copy
import re
import tomllib
from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Self, TypeVar, get_args

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import DATA_DIR, scenario_file
from calstudy.core.userfile import number_problem

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


class Radians:
    """A derived attribute of a table: its degree input ``key`` in radians (``tilt =
    Radians("tilt_deg")``)."""

    def __init__(self, key: str) -> None:
        self.key = key

    def __get__(self, table: Any, owner: type | None = None) -> Any:
        return self if table is None else np.deg2rad(getattr(table, self.key))


class Schema(BaseModel):
    """Base of every file schema: unknown keys are errors, values are checked strictly (a
    quoted ``"12"`` or ``true`` is not silently a number in a TOML file, ``6.0`` not a count)
    but a float may be written as an int. CSV rows, whose cells are text, are validated with
    the text parsed (:func:`validate_rows`). An array of fixed positions (``tuple[...]``)
    must be declared with :data:`Row` so that a TOML array passes.

    A validated file is frozen; what is derived from its inputs (a camera model, an array in
    radians) is a :class:`functools.cached_property` or a :class:`Radians` of its table, and
    :meth:`replace` makes a changed copy whose derived values follow its inputs."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        str_strip_whitespace=True,
        strict=True,
        ignored_types=(Radians,),
    )

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False) -> Self:
        """pydantic's copy (``update`` not validated), without the derived values cached on
        ``self``: the copy computes them again from its own inputs."""
        copied = super().model_copy(update=update, deep=deep)
        for cls in type(self).__mro__:
            for name, attr in vars(cls).items():
                if isinstance(attr, cached_property):
                    copied.__dict__.pop(name, None)
        return copied

    def replace(self, changes: Mapping[str, Any]) -> Self:
        """A copy with the inputs at the dotted keys of ``changes`` set, e.g.
        ``{"detection.sigma_px": 0.0}``.

        The values are not validated: the copy may hold what a file may not (an oracle's zero
        bias, a sweep point beyond the plausible range). To check a value as a file's would be,
        load the file with overrides (:func:`apply_overrides`).

        Raises
        ------
        CalibrationError
            If a key names no field of the table (naming the key).
        """
        return self._replaced(changes, "")

    def _replaced(self, changes: Mapping[str, Any], prefix: str) -> Self:
        """:meth:`replace` of a table whose dotted name in its file is ``prefix``."""
        nested: dict[str, dict[str, Any]] = {}
        update: dict[str, Any] = {}
        for key, value in changes.items():
            head, _, rest = key.partition(".")
            if head not in type(self).model_fields or (
                rest and not isinstance(getattr(self, head), Schema)
            ):
                raise CalibrationError(f"{prefix}{key}: no such input in {type(self).__name__}")
            if rest:
                nested.setdefault(head, {})[rest] = value
            else:
                update[head] = value
        for head, sub in nested.items():
            update[head] = getattr(self, head)._replaced(sub, f"{prefix}{head}.")
        return self.model_copy(update=update)


class Texts(Schema):
    """A table of texts only (a file's ``[source]`` notes): any key, every value a string."""

    model_config = ConfigDict(extra="allow", frozen=True, str_strip_whitespace=True)
    __pydantic_extra__: dict[str, str]


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



def _low_high(pair: Sequence[float]) -> Sequence[float]:
    if pair[0] > pair[1]:
        raise ValueError(f"{list(pair)} is not [low, high]")
    return pair


#: marks a pair of numbers as a range written ``[low, high]`` (the first not above the second):
#: ``Annotated[list[Finite], Field(min_length=2, max_length=2), LowHigh]``
LowHigh = AfterValidator(_low_high)

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
    if isinstance(value, tuple):  # a TOML array that Row made a tuple: show it as written
        value = list(value)
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
    model: type[M],
    data: Any,
    source: str | Path,
    prefix: str = "",
    study: bool = False,
    ranges: bool = True,
) -> M:
    """``model`` validated from ``data``; a :class:`CalibrationError` naming ``source``, each bad
    key (with ``prefix`` in front, e.g. ``"station."``), its value and the allowed range.
    ``study`` marks a file of the study's own ``data/`` (its validators see it in the context:
    :mod:`calstudy.core.ledger` refuses inputs marked ``user`` there); ``ranges=False`` leaves
    out the ledger's plausible ranges (a sweep goes beyond them on purpose)."""
    try:
        return model.model_validate(data, context={"study": study, "ranges": ranges})
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


def _existing(path: str | Path, what: str) -> Path:
    """``path`` as a Path; FileNotFoundError naming it and ``what`` if it is not a file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (the {what})")
    return path


def read_toml(path: str | Path, what: str) -> dict:
    """The TOML table of ``path``; FileNotFoundError naming the path and ``what`` if missing,
    CalibrationError with the parser's line and column if it is not valid TOML."""
    path = _existing(path, what)
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


#: the key of a table's ledger entries (:mod:`calstudy.core.ledger`)
PROVENANCE = "provenance"


def apply_overrides(table: dict, overrides: Mapping[str, object] | None) -> dict:
    """A copy of the TOML table ``table`` with some of its inputs replaced.

    Parameters
    ----------
    table : dict
        A parsed TOML file (:func:`read_toml`); left unchanged.
    overrides : mapping of str to object, or None
        Dotted keys of the file (``"survey.marker_sigma_px"``) and their new values, in the
        file's own units.

    Returns
    -------
    dict
        A new table, to be validated as the file would be (so a value outside its type's bounds
        or its ledger range is refused the same way).

    Raises
    ------
    CalibrationError
        If a key names no entry of the table, a whole table or a ``provenance`` entry (none is
        an input), naming it.
    """
    out = copy.deepcopy(table)
    for key, value in (overrides or {}).items():
        parts = str(key).split(".")
        node = out
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            if (
                not isinstance(node, dict)
                or part not in node
                or part == PROVENANCE
                or (last and isinstance(node[part], dict))
            ):
                raise CalibrationError(
                    f"override {key!r}: {'.'.join(parts[: i + 1])!r} names no input of the "
                    "scenario file (misspelt?)"
                )
            if not last:
                node = node[part]
        node[parts[-1]] = copy.deepcopy(value)
    return out


def load_model(
    path: str | Path, model: type[M], what: str, overrides: Mapping[str, object] | None = None
) -> M:
    """The TOML file ``path`` (the ``what``, for messages) validated against ``model``, with the
    dotted ``overrides`` (:func:`apply_overrides`) applied first.

    A file of the study's ``data/`` is validated as one (:func:`is_study_file`). The validated
    model is kept by (file, modification time, size, model, overrides): a Monte Carlo trial
    loads the same few files again and again; the model is frozen, so it is shared.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file.
    CalibrationError
        If the file is not TOML, an override names no input, or the table breaks ``model``
        (the message names the file, the key, the value and the allowed range).
    """
    path = _existing(path, what)
    key = (*file_key(path), model, repr(sorted((overrides or {}).items())))
    if key not in _MODELS:
        table = read_toml(path, what)  # its errors name the file
        try:
            table = apply_overrides(table, overrides)
        except CalibrationError as exc:
            raise CalibrationError(f"{path}: {exc}") from None
        loaded = validate(model, table, path, study=is_study_file(path))
        if len(_MODELS) >= 64:
            _MODELS.clear()
        _MODELS[key] = loaded
    return _MODELS[key]


#: validated models of :func:`load_model` by (resolved path, modification time, size, model,
#: overrides): validating a scenario costs more than the rest of loading it (an edited file has
#: a new key, so it is checked again)
_MODELS: dict[tuple, BaseModel] = {}


def with_inputs(model: M, changes: Mapping[str, object], ranges: bool = False) -> M:
    """A copy of the validated ``model`` with the inputs at dotted keys changed, validated
    again: types, bounds and the rules across keys and tables hold as in a file.

    Parameters
    ----------
    model : pydantic.BaseModel
        A validated scenario (or table).
    changes : mapping of str to object
        Dotted keys of ``model`` (``"scanner.sigma_point_mm"``) and their new values.
    ranges : bool
        Also hold the values to their ledger ranges (:mod:`calstudy.core.ledger`); off by
        default, as a sweep goes beyond them on purpose.

    Returns
    -------
    pydantic.BaseModel
        A new model of the same type.

    Raises
    ------
    CalibrationError
        If a key names no input or a value breaks the model (naming the key and the value).
    """
    table = apply_overrides(model.model_dump(), changes)
    source = f"{type(model).__name__} with changed inputs"
    return validate(type(model), table, source, ranges=ranges)


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


def _rigid(matrix: list, rotation_tol: float) -> list:
    m = np.array(matrix, dtype=float)
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"the last row is {m[3].tolist()}; a rigid transform has [0, 0, 0, 1]")
    problem = rotation_problem(m, rotation_tol)
    if problem:
        raise ValueError(f"its 3 x 3 block is not a rotation: {problem}")
    return matrix


def rigid_transform(rotation_tol: float = 1e-4):
    """The type of a rigid transform written as its 4 rows of 4 numbers: the last row
    ``[0, 0, 0, 1]``, the upper-left 3 x 3 block a rotation within ``rotation_tol``
    (:func:`rotation_problem`; a matrix printed to 4 decimals needs about 2e-3)."""
    row = Annotated[list[Finite], Field(min_length=4, max_length=4)]
    check = AfterValidator(lambda matrix: _rigid(matrix, rotation_tol))
    return Annotated[list[row], Field(min_length=4, max_length=4), check]


def check_principal_point(cx: float, cy: float, width: int, height: int) -> None:
    """For a camera schema's validator: raise ValueError unless the principal point ``(cx, cy)``
    lies inside the ``width`` x ``height`` px image."""
    if not (0 <= cx < width and 0 <= cy < height):
        raise ValueError(
            f"principal point ({cx}, {cy}) lies outside the {width} x {height} px image"
        )


def ordered(low: str, high: str, strict: bool = True):
    """A table's rule that its input ``low`` lies below its input ``high`` (``strict``) or at
    most at it, for the table's class body: ``_order = ordered("canny_low", "canny_high")``.

    Parameters
    ----------
    low, high : str
        Names of two numeric fields of the table, in the file's units.
    strict : bool
        Refuse ``low == high`` too.

    Returns
    -------
    pydantic model validator
        Raises ValueError ``"low = 0.75 is not below high = 0.5"`` (``strict``) or ``"low = 40.0
        exceeds high = 30.0"``, which :func:`validate` reports with the file and the table.
    """

    def check(table):
        a, b = getattr(table, low), getattr(table, high)
        if a >= b if strict else a > b:
            raise ValueError(f"{low} = {a} {'is not below' if strict else 'exceeds'} {high} = {b}")
        return table

    return model_validator(mode="after")(check)


def one_each(first: str, *others: str, note: str = "one each"):
    """A table's rule that its lists ``others`` have as many entries as its list ``first``, for
    the table's class body: ``_one_each = one_each("methods", "rows")``.

    Parameters
    ----------
    first : str
        Name of the list field that sets the count.
    *others : str
        Names of the list fields that must have as many entries.
    note : str
        The end of the message, saying what is wanted (``"one per region"``).

    Returns
    -------
    pydantic model validator
        Raises ValueError ``"2 regions but 3 names, 3 centres_mm; one per region"``, naming each
        list whose count differs, which :func:`validate` reports with the file and the table.
    """

    def check(table):
        n = len(getattr(table, first))
        wrong = [f"{len(getattr(table, k))} {k}" for k in others if len(getattr(table, k)) != n]
        if wrong:
            raise ValueError(f"{n} {first} but {', '.join(wrong)}; {note}")
        return table

    return model_validator(mode="after")(check)


def distinct(values: list, what: str, note: str = "") -> list:
    """``values`` if no entry is given twice; for a schema's validators.

    Parameters
    ----------
    values : list
        Names or keys (hashable, sortable).
    what : str
        What the entries are, for the message (``"marker names"``).
    note : str
        Appended to the message (``"; one row each"``).

    Returns
    -------
    list
        ``values`` itself.

    Raises
    ------
    ValueError
        ``"marker names repeated: ['5817-17']"``, listing each repeated entry once, sorted.
    """
    dup = sorted({v for v in values if values.count(v) > 1})
    if dup:
        raise ValueError(f"{what} repeated: {dup}{note}")
    return values


def load_paper_file(
    paper: str,
    name: str,
    model: type[M],
    what: str,
    path: str | Path | None = None,
    overrides: Mapping[str, object] | None = None,
) -> M:
    """:func:`load_model` of ``path``, default (None or ``""``) the paper's own file
    ``data/<paper>/<name>``.

    Parameters
    ----------
    paper, name : str
        The paper's data folder and the file's name in it (``"dualarm"``, ``"scenario.toml"``).
    model : type of Schema
        The file's schema.
    what : str
        What the file is, for messages (``"dualarm scenario"``).
    path : str or Path, optional
        A file of one's own with the same keys.
    overrides : mapping of str to object, optional
        Dotted keys of the file and their values (:func:`apply_overrides`).

    Returns
    -------
    Schema
        The validated, frozen file.

    Raises
    ------
    FileNotFoundError, CalibrationError
        As :func:`load_model`.
    """
    return load_model(scenario_file(paper, name, path), model, what, overrides)


#: a rigid 4 x 4 transform written as four rows (last row ``[0, 0, 0, 1]``, an orthonormal
#: rotation of determinant +1 within :func:`rotation_problem`'s tolerance)
Rigid4x4 = rigid_transform()


class Pinhole(Schema):
    """The table of a pinhole camera: focal lengths and principal point (px) inside a
    ``width`` x ``height`` px image. A scenario's camera table derives from it (with
    :class:`calstudy.core.ledger.Inputs` for the provenance of each entry)."""

    fx: PositiveFinite
    fy: PositiveFinite
    cx: Finite
    cy: Finite
    width: Pixels
    height: Pixels

    @model_validator(mode="after")
    def _centre_in_image(self) -> Pinhole:
        check_principal_point(self.cx, self.cy, self.width, self.height)
        return self


def validate_rows(
    model: type[M], header: Sequence[str], rows: Sequence[tuple[int, Sequence[str]]], path
) -> list[M]:
    """Each row (from :func:`calstudy.core.userfile.read_csv_table`) validated against
    ``model``; the first bad cell is reported with its row, column, text and what is
    allowed."""
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
    "distinct",
    "Documented",
    "Finite",
    "Fraction",
    "LowHigh",
    "MAX_PIXELS",
    "NonNegativeFinite",
    "NonNegativeInt",
    "PositiveFinite",
    "Pinhole",
    "PositiveInt",
    "Pixels",
    "Radians",
    "Rigid4x4",
    "Row",
    "Schema",
    "Texts",
    "Vec2",
    "Vec3",
    "file_key",
    "format_errors",
    "is_study_file",
    "load_model",
    "load_paper_file",
    "one_each",
    "ordered",
    "read_toml",
    "rigid_transform",
    "rotation_problem",
    "validate",
    "validate_rows",
    "with_inputs",
]
