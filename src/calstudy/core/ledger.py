"""The assumption ledger: where each input of a scenario file comes from.

Every input of a scenario table carries its provenance beside its value, as a dotted key of the
same table::

    [sensor]
    standoff_mm = 250.0
    provenance.standoff_mm = { kind = "assumed", range = [100.0, 400.0], why = "..." }

The kinds (:class:`Provenance`):

``paper``
    stated by the paper: ``ref`` names it by its bibliography key and the place
    (``"hybrid, sec. 4.2"``).
``derived``
    computed from what the paper states: ``ref`` as above, ``how`` the derivation; a ``range``
    when the derivation reads a statement one of several ways.
``calibrated``
    fitted by code to baseline figures of the paper: ``target`` names the figure(s) and their
    place, ``code`` the function that fits it (``module:function``).
``assumed``
    not given by the paper: ``range = [lo, hi]`` is its plausible range (per component for a
    vector: ``[[lo, hi], [lo, hi], [lo, hi]]``), ``why`` the reason for the ends.
``study``
    a choice of the study's method, not a property of the paper's station (a sweep grid, a
    criterion the paper does not state): ``why`` says why.
``user``
    a value of one's own cell, in one's own scenario file (refused in the study's files). A
    table of one's own may write ``provenance = "user"`` for all its inputs.

A scenario table's schema derives from :class:`Inputs`; the file's schema from
:class:`Ledgered`, whose validator refuses an input without provenance, an ``assumed`` input
without a range, a ``user`` input in a study file (validation context ``{"study": True}``, set
by :func:`calstudy.core.schema.load_model` for the files of ``data/``) and a value outside its
range. A noise level marked :data:`OFF` may also be 0 (an oracle switches its error source off).
Before the ledger, the file's :meth:`Ledgered.plausibility` checks that the scenario can exist.
:func:`ledger_rows` lists a validated file's ledger for the book.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from typing import Annotated, Any, ClassVar, Literal, get_args

import numpy as np
from pydantic import BaseModel, Field, ValidationInfo, model_validator

from calstudy.core.schema import Documented, Schema

#: the kinds of provenance, in the order the book lists them
KINDS = ("paper", "derived", "calibrated", "assumed", "study", "user")
#: bibliography keys of the four papers (book/references.bib)
PAPER_KEYS = ("hybrid", "selfcal", "binocular", "dualarm")
#: the key of ``provenance = "user"`` (a whole table of one's own)
ALL = "*"
#: most ledger problems listed in one message
MAX_LISTED = 6
#: the keys each kind requires
REQUIRED = {
    "paper": ("ref",),
    "derived": ("ref", "how"),
    "calibrated": ("target", "code"),
    "assumed": ("range", "why"),
    "study": ("why",),
    "user": (),
}


class _Off:
    """Metadata of a noise level: the value 0 (its error source switched off, an oracle) is
    accepted outside its ledger range."""

    def __repr__(self) -> str:
        return "OFF"


#: marks a field (``Annotated[float, ..., OFF]``) as a noise level an oracle may set to 0
OFF = _Off()


def noise_level(bounds: Mapping[str, float], name: str):
    """The type of a noise level: finite, >= 0 and <= ``bounds[name]`` (its physical bound, from
    a schema's table of bounds), and 0 accepted outside its ledger range (:data:`OFF`)."""
    return Annotated[float, Field(ge=0, le=bounds[name], allow_inf_nan=False), OFF]


Bound = Annotated[float, Field(allow_inf_nan=False)]
Interval = Annotated[list[Bound], Field(min_length=2, max_length=2)]


class Provenance(Schema):
    """Where one input comes from (module docstring)."""

    kind: Literal["paper", "derived", "calibrated", "assumed", "study", "user"]
    #: paper, derived: the bibliography key and the place in the paper
    ref: str = ""
    #: derived: the derivation
    how: str = ""
    #: calibrated: the baseline figure(s) it is fitted to, with their place
    target: str = ""
    #: calibrated: the code that fits it, ``module:function``
    code: str = ""
    #: assumed: the reason for the ends of the range; study: the reason for the choice
    why: str = ""
    #: the plausible range: ``[lo, hi]``, or one ``[lo, hi]`` per component of a vector, or for
    #: a list of tables one such range per numeric key (``{ xyz_mm = [[..], [..], [..]] }``)
    range: Interval | list[Interval] | dict[str, Interval | list[Interval]] | None = None
    #: user: free text
    note: str = ""

    @model_validator(mode="after")
    def _complete(self) -> Provenance:
        missing = [k for k in REQUIRED[self.kind] if not getattr(self, k)]
        if missing:
            hint = " = [lo, hi]" if missing == ["range"] else ""
            article = "an" if self.kind[0] in "aeiou" else "a"
            raise ValueError(f"{article} {self.kind} input needs {' and '.join(missing)}{hint}")
        if self.kind in ("paper", "derived"):
            key = self.ref.replace(",", " ").split()[0]
            if key not in PAPER_KEYS:
                raise ValueError(
                    f"ref = {self.ref!r} does not start with the paper's bibliography key "
                    f"({', '.join(PAPER_KEYS)})"
                )
        if self.kind == "calibrated" and ":" not in self.code:
            raise ValueError(f"code = {self.code!r} is not module:function")
        parts = self.range.values() if isinstance(self.range, dict) else [self.range]
        for part in parts:
            for lo, hi in _intervals(part):
                if lo > hi:
                    raise ValueError(f"range [{lo}, {hi}] is not [lo, hi]")
        return self

    def range_text(self) -> str:
        """The range in words, ``""`` if none."""
        if isinstance(self.range, dict):
            return "; ".join(f"{k} {_interval_text(v)}" for k, v in self.range.items())
        return _interval_text(self.range)

    def source_text(self) -> str:
        """The provenance in one line: its place, derivation, target or reason."""
        if self.kind == "paper":
            return self.ref
        if self.kind == "derived":
            return f"{self.ref}; {self.how}"
        if self.kind == "calibrated":
            return f"to {self.target} ({self.code})"
        return self.why or self.note


def _num(value: float) -> str:
    return f"{value:g}"


def _intervals(part) -> list[tuple[float, float]]:
    """``[lo, hi]`` or ``[[lo, hi], ...]`` as a list of ``(lo, hi)``; ``[]`` for None."""
    if part is None:
        return []
    if isinstance(part[0], list):
        return [(float(lo), float(hi)) for lo, hi in part]
    return [(float(part[0]), float(part[1]))]


def _interval_text(part) -> str:
    texts = [f"[{_num(lo)}, {_num(hi)}]" for lo, hi in _intervals(part)]
    if not texts:
        return ""
    return texts[0] if len(texts) == 1 else "per component " + ", ".join(texts)


class Inputs(Documented):
    """A scenario table whose inputs carry their provenance (module docstring). Every field is
    an input except ``provenance``, nested tables and the names in :attr:`NOT_INPUTS`."""

    #: fields of the table that are texts for the reader, not inputs
    NOT_INPUTS: ClassVar[frozenset[str]] = frozenset()

    provenance: dict[str, Provenance] | None = None

    @model_validator(mode="before")
    @classmethod
    def _whole_table(cls, data: Any) -> Any:
        """``provenance = "user"``: every input of the table is the user's (key ``*``)."""
        if isinstance(data, dict) and isinstance(data.get("provenance"), str):
            if data["provenance"] != "user":
                raise ValueError(
                    f'provenance = {data["provenance"]!r}: a whole table can only be "user"; '
                    "give each input its own provenance.<input> = { kind = ..., ... }"
                )
            data = {**data, "provenance": {ALL: {"kind": "user"}}}
        return data

    @classmethod
    def input_names(cls) -> list[str]:
        """The names of the table's inputs, in the order of the schema."""
        return [
            name
            for name, info in cls.model_fields.items()
            if name != "provenance"
            and name not in cls.NOT_INPUTS
            and not _is_table(info.annotation)
        ]


def _is_table(annotation) -> bool:
    """True if ``annotation`` is (or holds) a Documented table: a nested table, not an input."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return issubclass(annotation, Documented)
    return any(_is_table(arg) for arg in get_args(annotation))


def _off(model: type[BaseModel], name: str) -> bool:
    return any(meta is OFF for meta in model.model_fields[name].metadata)


def tables(model: BaseModel, prefix: str = "") -> Iterator[tuple[str, Inputs]]:
    """Every :class:`Inputs` table of a validated file, the file itself first.

    Parameters
    ----------
    model : pydantic.BaseModel
        A validated scenario file (or table).
    prefix : str
        Dotted name of ``model`` in its file, ``""`` for the file.

    Returns
    -------
    iterator of (str, Inputs)
        The dotted prefix of each table's keys (``"sensor."``) and the table.
    """
    if isinstance(model, Inputs):
        yield prefix, model
    for name in type(model).model_fields:
        value = getattr(model, name)
        if isinstance(value, BaseModel) and isinstance(value, Documented):
            yield from tables(value, f"{prefix}{name}.")


def _value_text(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _outside(value: Any, prov: Provenance) -> str:
    """Why ``value`` lies outside the range of ``prov``, ``""`` if it does not."""
    if isinstance(prov.range, dict):
        if not (isinstance(value, list) and all(isinstance(v, BaseModel) for v in value)):
            return "a range per key is given for an input that is not a list of tables"
        for key, part in prov.range.items():
            if not all(hasattr(v, key) for v in value):
                return f"the range names {key!r}, which its entries do not have"
            problem = _outside_part([getattr(v, key) for v in value], part)
            if problem:
                return f"{key} {problem}"
        return ""
    return _outside_part(value, prov.range)


def _outside_part(value: Any, part) -> str:
    intervals = _intervals(part)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return "a range is given for an input that is not numeric"
    if len(intervals) > 1:
        if arr.ndim == 0 or arr.shape[-1] != len(intervals):
            return f"{len(intervals)} component ranges for a value of shape {arr.shape}"
        cols = [arr[..., i] for i in range(len(intervals))]
    else:
        cols = [arr]
    for col, (lo, hi) in zip(cols, intervals, strict=True):
        if col.size and (float(col.min()) < lo or float(col.max()) > hi):
            return f"outside its plausible range {_interval_text(part)}"
    return ""


def ledger_problems(model: BaseModel, study: bool, ranges: bool = True) -> list[str]:
    """Every breach of the ledger rules in a validated scenario file (module docstring).

    Parameters
    ----------
    model : pydantic.BaseModel
        The validated file.
    study : bool
        True for a file of the study's own ``data/``, where ``user`` is refused.
    ranges : bool
        Check each value against its plausible range (False: a sweep's copy, which goes beyond
        them on purpose).

    Returns
    -------
    list of str
        One message per breach, naming the dotted input and its value: an input without
        provenance, a provenance entry for no input, ``user`` in a study file, a value outside
        its range. Empty if the ledger is complete.
    """
    problems: list[str] = []
    for prefix, table in tables(model):
        names = table.input_names()
        prov = table.provenance or {}
        where = f"[{prefix[:-1]}]" if prefix else "the top level"
        if ALL in prov:
            if study:
                problems.append(
                    f"{prefix}provenance = 'user': the study's own files give every input its "
                    "paper, derived, calibrated, assumed or study provenance"
                )
            continue
        for name in prov:
            if name not in names:
                problems.append(
                    f"{prefix}provenance.{name}: {where} has no input {name!r} (misspelt?)"
                )
        for name in names:
            value = getattr(table, name)
            if name not in prov:
                problems.append(
                    f"{prefix}{name} = {_value_text(value)}: no provenance (write "
                    f"provenance.{name} = {{ kind = ..., ... }} beside it in {where}; kinds: "
                    f"{', '.join(KINDS)})"
                )
                continue
            entry = prov[name]
            if study and entry.kind == "user":
                problems.append(
                    f"{prefix}provenance.{name}: kind 'user' is for one's own scenario files, "
                    "not the study's"
                )
                continue
            if entry.range is None or not ranges:
                continue
            if value == 0 and _off(type(table), name):
                continue  # an oracle switches this error source off
            problem = _outside(value, entry)
            if problem:
                problems.append(
                    f"{prefix}{name} = {_value_text(value)}: {problem} (its {entry.kind} range; "
                    'in a scenario of your own cell, mark it kind = "user")'
                )
    return problems


class Ledgered(Documented):
    """A scenario file whose tables are :class:`Inputs`: its validator runs
    :meth:`plausibility` (can the scenario exist?) and then the ledger rules."""

    def plausibility(self) -> None:
        """Raise ValueError naming the input and the number if the scenario cannot exist; a
        file schema overrides it (the default checks nothing)."""

    @model_validator(mode="after")
    def _ledger(self, info: ValidationInfo) -> Ledgered:
        self.plausibility()
        context = info.context or {}
        problems = ledger_problems(self, bool(context.get("study")), context.get("ranges", True))
        if len(problems) > MAX_LISTED:
            more = len(problems) - MAX_LISTED
            problems = [*problems[:MAX_LISTED], f"and {more} more"]
        if problems:
            raise ValueError("; ".join(problems))
        return self


def ledger_rows(model: BaseModel) -> list[dict[str, str]]:
    """The ledger of a validated scenario file, for the book.

    Parameters
    ----------
    model : pydantic.BaseModel
        The validated file (its ledger complete: :func:`ledger_problems` empty).

    Returns
    -------
    list of dict
        One row per input, in the order of the schema: ``input`` (dotted name), ``value`` (a
        number, a short list, or its size), ``kind``, ``range`` (in words, ``""`` if none) and
        ``source`` (the place, derivation, target or reason).
    """
    rows = []
    for prefix, table in tables(model):
        prov = table.provenance or {}
        for name in table.input_names():
            entry = prov.get(name, prov.get(ALL))
            value = getattr(table, name)
            rows.append(
                {
                    "input": f"{prefix}{name}",
                    "value": _short(value),
                    "kind": entry.kind if entry else "user",
                    "range": entry.range_text() if entry else "",
                    "source": entry.source_text() if entry else "",
                }
            )
    return rows


def _short(value: Any) -> str:
    """A value for a table cell: a number, a short list, or its size."""
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    if isinstance(value, list):
        flat = np.asarray(value, dtype=object).ravel() if value else []
        if len(value) and isinstance(value[0], BaseModel):
            return f"{len(value)} entries"
        if len(flat) <= 6 and all(isinstance(v, int | float) for v in flat):
            return repr(value)
        shape = np.asarray(value, dtype=object).shape
        return " x ".join(str(n) for n in shape) + " values"
    return str(value)


__all__ = [
    "KINDS",
    "OFF",
    "PAPER_KEYS",
    "Inputs",
    "Ledgered",
    "Provenance",
    "ledger_problems",
    "ledger_rows",
    "tables",
]
