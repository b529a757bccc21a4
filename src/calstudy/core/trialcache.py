"""The per-trial cache of the Monte Carlo engine (:mod:`calstudy.core.montecarlo`).

Layout and key are described in that module's docstring: one JSON file per finished trial under
``cache_dir/<experiment>/<point-slug>/<key>/``, written atomically, reused only when the seed,
experiment, point, trial function and scenario fingerprint all match.

The files are data, never code: a trial's rows are dicts of scalars, written as JSON with every
numpy scalar tagged by its dtype (``{"numpy": "<f4", "value": 0.5}``) so that a row read back is
the same Python or numpy scalar, bit for bit (floats are written by ``repr``, which round-trips,
and NaN and infinities as JSON's ``NaN`` and ``Infinity``). Reading one is ``json.loads`` and a
check of its form: no object is built from a name in the file, so a cache folder from elsewhere
can at worst supply wrong rows (for this seed, experiment and point), never run anything. A file
that is not such a record is refused with a :class:`CalibrationError` naming it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import hashlib
import json
import re
from collections.abc import Callable, Mapping
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from pydantic import BaseModel

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import atomic_write

#: Version of the cache file layout and key; bump it when either changes.
CACHE_FORMAT = 2

Rows = list[dict[str, Any]]

if TYPE_CHECKING:  # the engine imports this module, not the other way round
    from calstudy.core.montecarlo import Experiment


class TrialCache:
    """Per-trial row files of one experiment run (layout in the module docstring)."""

    def __init__(self, root: Path, experiment: Experiment, seed: int, point_jsons: list[str]):
        self.root = root / experiment.name
        base = {
            "format": CACHE_FORMAT,
            # how the engine derives a trial's stream (rows drawn another way are not reused)
            "streams": "seed/experiment/trial",
            "seed": seed,
            "experiment": experiment.name,
            "trial_function": _function_fingerprint(experiment.trial, experiment.name),
            "scenario": experiment.scenario_key
            if experiment.scenario_key is not None
            else _scenario_digest(experiment.scenario, experiment.name),
        }
        self.keys = [{**base, "point": point_json} for point_json in point_jsons]
        self.dirs = [
            self.root / _slug(point) / hashlib.sha256(_dumps(key).encode()).hexdigest()[:16]
            for point, key in zip(experiment.points, self.keys, strict=True)
        ]

    def remove_stale(self, started: float) -> None:
        """Delete temporary files older than ``started`` (epoch s), left by a killed run."""
        if self.root.is_dir():
            for tmp in self.root.rglob("*.tmp"):
                with contextlib.suppress(FileNotFoundError):
                    if tmp.stat().st_mtime < started:
                        tmp.unlink()

    def _path(self, point: int, trial: int) -> Path:
        return self.dirs[point] / f"trial-{trial:06d}.json"

    def load(self, point: int, trial: int) -> Rows | None:
        """The stored rows of one trial, or None if absent or stored under another key.

        Raises
        ------
        CalibrationError
            If the file is not a trial record (:func:`decode_record`).
        """
        path = self._path(point, trial)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return None
        stored = decode_record(data, path)
        if stored["key"] != self.keys[point] or stored["trial"] != trial:
            return None
        return stored["rows"]

    def load_all(self, n_trials: int) -> dict[tuple[int, int], Rows]:
        """The stored rows of trials 0 to ``n_trials - 1`` of every point, by (point, trial)."""
        stored = {}
        for point in range(len(self.dirs)):
            for trial in range(n_trials):
                if (rows := self.load(point, trial)) is not None:
                    stored[point, trial] = rows
        return stored

    def save(self, point: int, trial: int, rows: Rows) -> None:
        """Store the rows of one trial atomically."""
        key = self.dirs[point] / "key.json"
        if not key.exists():
            text = _dumps(self.keys[point]) + "\n"
            atomic_write(key, lambda tmp: tmp.write_bytes(text.encode()))
        record = encode_record({"key": self.keys[point], "trial": trial, "rows": rows})
        atomic_write(self._path(point, trial), lambda tmp: tmp.write_bytes(record))


# ----------------------------------------------------------------------------------------------
# the record file: JSON of scalars, numpy scalars tagged with their dtype

_PLAIN = (type(None), bool, int, float, str)
#: numpy scalar types a record may hold: bool, signed and unsigned integers, float16/32/64
_DTYPES = frozenset(np.dtype(t).str for t in "?bhilqBHILQefd")


def _encode_value(value: object) -> object:
    if type(value) in _PLAIN:
        return value
    if isinstance(value, np.bool_ | np.integer | np.floating) and value.dtype.str in _DTYPES:
        return {"numpy": value.dtype.str, "value": value.item()}
    if isinstance(value, str):  # numpy.str_
        return str(value)
    raise CalibrationError(
        f"a trial row holds {value!r} of type {type(value).__name__}: the trial cache stores "
        "None, bool, int, float, str and numpy scalars"
    )


def encode_record(record: Mapping[str, Any]) -> bytes:
    """The bytes of a trial record ``{"key": dict, "trial": int, "rows": [dict, ...]}``.

    Raises
    ------
    CalibrationError
        If a row holds a value other than None, bool, int, float, str or a numpy scalar.
    """
    rows = [{str(k): _encode_value(v) for k, v in row.items()} for row in record["rows"]]
    body = {"key": record["key"], "trial": record["trial"], "rows": rows}
    # the column order of a row is kept (it is the column order of the table)
    return (json.dumps(body, separators=(",", ":")) + "\n").encode()


def _decode_value(value: object, where: str) -> object:
    if type(value) in _PLAIN:
        return value
    if isinstance(value, dict) and value.keys() == {"numpy", "value"} and value["numpy"] in _DTYPES:
        dtype, item = np.dtype(value["numpy"]), value["value"]
        wanted = {"b": (bool,), "i": (int,), "u": (int,), "f": (float, int)}[dtype.kind]
        if type(item) in wanted:
            with contextlib.suppress(OverflowError):
                return dtype.type(item)
    raise CalibrationError(f"{where}: {value!r} is not a scalar the trial cache stores")


def decode_record(data: bytes, path: str | Path) -> dict[str, Any]:
    """The trial record stored in ``data`` (the bytes of the file ``path``), checked.

    Only JSON is parsed and only scalars are built (Python's, or numpy's of a bool, integer or
    float dtype): nothing named in the file is imported or called.

    Raises
    ------
    CalibrationError
        Naming ``path``, if ``data`` is not UTF-8 JSON of the form :func:`encode_record` writes.
    """
    try:
        body = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CalibrationError(
            f"trial cache file {path} is not a JSON trial record ({exc}); delete it"
        ) from None
    if not (
        isinstance(body, dict)
        and body.keys() == {"key", "trial", "rows"}
        and isinstance(body["key"], dict)
        and type(body["trial"]) is int
        and isinstance(body["rows"], list)
        and all(isinstance(row, dict) for row in body["rows"])
    ):
        raise CalibrationError(
            f"trial cache file {path} is not a trial record (a JSON object with the keys "
            "'key', 'trial' and 'rows', a list of objects); delete it"
        )
    where = f"trial cache file {path}"
    rows = [{k: _decode_value(v, where) for k, v in row.items()} for row in body["rows"]]
    return {"key": body["key"], "trial": body["trial"], "rows": rows}


def _dumps(obj: object) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _slug(point: Mapping[str, Any]) -> str:
    text = ",".join(f"{key}={value}" for key, value in point.items())
    text = re.sub(r"[^A-Za-z0-9._=,+-]", "_", text)[:80] or "_"
    return "_" + text[1:] if text.startswith(".") else text


def _qualified(obj: object) -> str | None:
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return None if module is None or qualname is None else f"{module}:{qualname}"


def _function_fingerprint(function: Callable[..., Any], name: str) -> str:
    fingerprint = _qualified(function)
    if fingerprint is None or "<" in fingerprint:
        raise CalibrationError(
            f"experiment {name!r}: the cache needs a module-level trial function, got "
            f"{fingerprint or repr(function)}"
        )
    return fingerprint


def _scenario_digest(scenario: object, name: str) -> str:
    try:
        text = _dumps(_canonical(scenario))
    except RecursionError:
        raise CalibrationError(
            f"experiment {name!r}: the scenario refers to itself; pass scenario_key"
        ) from None
    except _Unstable as exc:
        raise CalibrationError(
            f"experiment {name!r}: the scenario holds {exc}, whose repr is not stable across "
            "runs; pass Experiment(scenario_key=...) to cache it"
        ) from None
    return hashlib.sha256(text.encode()).hexdigest()


class _Unstable(Exception):
    pass


def _canonical(obj: object) -> object:
    """A JSON-ready form of ``obj`` that is the same in every process (for the cache key)."""
    if isinstance(obj, enum.Enum):
        return {"enum": _qualified(type(obj)), "name": obj.name}
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    if isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            return {
                "array": "object",
                "shape": obj.shape,
                "items": [_canonical(x) for x in obj.flat],
            }
        data = hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest()
        return {"array": obj.dtype.str, "shape": obj.shape, "sha256": data}
    if isinstance(obj, np.generic):
        return {"numpy": obj.dtype.str, "value": _canonical(obj.item())}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        fields = {f.name: _canonical(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
        return {"dataclass": _qualified(type(obj)), "fields": fields}
    if isinstance(obj, BaseModel):  # its fields, not what its cached properties hold
        fields = {name: _canonical(getattr(obj, name)) for name in type(obj).model_fields}
        return {"model": _qualified(type(obj)), "fields": fields}
    if isinstance(obj, Mapping):
        items = sorted(([_canonical(k), _canonical(v)] for k, v in obj.items()), key=_dumps)
        return {"mapping": _qualified(type(obj)), "items": items}
    if isinstance(obj, list | tuple):
        return {"sequence": _qualified(type(obj)), "items": [_canonical(x) for x in obj]}
    if isinstance(obj, set | frozenset):
        return {"set": sorted((_canonical(x) for x in obj), key=_dumps)}
    if isinstance(obj, PurePath):
        return {"path": str(obj)}
    if isinstance(obj, pd.DataFrame | pd.Series):
        data = hashlib.sha256(obj.to_csv().encode()).hexdigest()
        return {"pandas": type(obj).__name__, "csv_sha256": data}
    if callable(obj) and _qualified(obj) and "<" not in str(_qualified(obj)):
        return {"callable": _qualified(obj)}
    if (
        type(obj).__reduce_ex__ is object.__reduce_ex__
        and type(obj).__reduce__ is object.__reduce__
    ):
        # what pickle would store: __dict__ and slots, or a custom __getstate__
        state = obj.__getstate__()
        if state is not None:
            return {"object": _qualified(type(obj)), "state": _canonical(state)}
    text = repr(obj)
    if re.search(r" at 0x[0-9a-fA-F]+", text):
        raise _Unstable(text)
    return {"repr": _qualified(type(obj)), "text": text}
