"""Reading the TOML files that describe a scenario, with errors that name the file and key.

Every paper's ``scenario.load_scenario(path=None)`` reads its file through :func:`read_toml`
(default: the paper's file under ``data/``) and its values through :func:`require`, so a missing
file, a malformed file and a missing key are reported the same way in all four papers.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from calstudy.core import schema
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path


def scenario_file(paper: str, name: str, path: str | Path | None = None) -> Path:
    """``path`` if given, else ``data/<paper>/<name>`` (which must exist)."""
    return data_path(paper, name) if path in (None, "") else Path(path)


def read_toml(path: str | Path, what: str) -> dict:
    """Read the TOML file ``path`` that holds ``what`` (for the messages).

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file (the message names it and ``what``).
    CalibrationError
        If the file is not valid TOML (the message gives the parser's line and column).
    """
    return schema.read_toml(path, what)


def require(table: dict, dotted_key: str, source: str | Path) -> Any:
    """The value at ``dotted_key`` ("a.b.c") of ``table``; a :class:`CalibrationError` naming
    ``source`` and the key if it is missing."""
    node: Any = table
    for i, part in enumerate(dotted_key.split(".")):
        if not isinstance(node, dict) or part not in node:
            where = ".".join(dotted_key.split(".")[: i + 1])
            raise CalibrationError(f"{source}: missing key '{where}'")
        node = node[part]
    return node
