"""The book's ledger page: every input of the four papers' scenario files with its provenance.

Run as ``python -m calstudy.io.ledger book/ledger.md``. One table per paper (input, value,
provenance, range, source), read from the scenario files of ``data/`` after validating them
(:mod:`calstudy.core.ledger`); the output depends only on those files, so it is
byte-deterministic.
"""

from __future__ import annotations

import argparse
import html
import re
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from calstudy.core.ledger import KINDS, ledger_rows
from calstudy.core.paths import data_path
from calstudy.core.schema import read_toml, validate
from calstudy.io.claims_cells import typeset
from calstudy.papers.binocular import schema as binocular
from calstudy.papers.dualarm import schema as dualarm
from calstudy.papers.hybrid import schema as hybrid
from calstudy.papers.selfcal import scenario as selfcal

#: paper -> its scenario files and their schemas, in book order
SCENARIO_FILES = {
    "hybrid": (("station.toml", hybrid.StationFile), ("production.toml", hybrid.ProductionFile)),
    "selfcal": (("scenario.toml", selfcal.Scenario),),
    "binocular": (
        ("sensor.toml", binocular.SensorFile),
        ("calibrator.toml", binocular.CalibratorFile),
        ("station.toml", binocular.StationFile),
    ),
    "dualarm": (("scenario.toml", dualarm.Scenario),),
}

#: paper -> the heading of its section
TITLES = {
    "hybrid": "Hybrid visual inspection station",
    "selfcal": "Robotic visual inspection, self-calibration",
    "binocular": "Eye-in-hand binocular sensor",
    "dualarm": "Dual-arm hand-eye scanning",
}

#: the columns of a ledger table and their shares of the page's width (%)
COLUMNS = (("input", 22), ("value", 15), ("provenance", 14), ("range", 14), ("source", 35))


def ledger_tables() -> dict[str, list[dict[str, str]]]:
    """Paper -> the rows of its ledger (:func:`calstudy.core.ledger.ledger_rows`, each with the
    ``file`` it comes from), from the validated scenario files of ``data/``.

    Raises
    ------
    CalibrationError
        If a scenario file breaks its schema or the ledger rules.
    """
    out = {}
    for paper, files in SCENARIO_FILES.items():
        rows = []
        for name, model in files:
            path = data_path(paper, name)
            parsed = validate(model, read_toml(path, f"{paper} {name}"), path, study=True)
            rows += [{"file": name, **row} for row in ledger_rows(parsed)]
        out[paper] = rows
    return out


def _cell(text: str) -> str:
    return html.escape(" ".join(str(text).split()))


#: a name of the code inside a sentence: snake_case, dotted (an input, a claim id, a module) or
#: ``module:function``
_IDENTIFIER = re.compile(r"\b[a-z][a-z0-9]*(?:[._:][a-z0-9]+)+\b")
_NOT_CODE = {"e.g", "i.e"}


def _prose(text: str) -> str:
    """A sentence of the ledger as the book writes it: ± and µm typeset
    (:func:`calstudy.io.claims_cells.typeset`), the names of the code it mentions as code."""
    s = _cell(typeset(text))
    return _IDENTIFIER.sub(
        lambda m: m.group(0) if m.group(0) in _NOT_CODE else f"<code>{_name(m.group(0))}</code>",
        s,
    )


def _name(text: str) -> str:
    """A name of the code with a line-break opportunity after every ``.``, ``_`` and ``:``: a
    long name wraps between its parts, never inside one."""
    return re.sub(r"([._:])", r"\1<wbr>", text)


def _value(text: str) -> str:
    """A value with a line-break opportunity after every ``_`` and ``,`` (a list wraps between
    its numbers, a file stem between its parts)."""
    return re.sub(r"([_,])", r"\1<wbr>", _cell(text))


def _table(paper: str, rows: list[dict[str, str]]) -> list[str]:
    """The HTML table of one paper's ledger (class ``ledger``: fixed column widths, long
    names and values wrap between their parts; on a phone each input a card whose cells carry
    their column's label; book/_static/calstudy.css)."""
    several = len(SCENARIO_FILES[paper]) > 1
    out = ['<table class="ledger">', "<colgroup>"]
    out += [f'<col style="width: {width}%">' for _, width in COLUMNS]
    out += ["</colgroup>", "<thead><tr>"]
    out += [f"<th>{name}</th>" for name, _ in COLUMNS]
    out += ["</tr></thead>", "<tbody>"]
    for r in rows:
        name = f"{r['file']}: {r['input']}" if several else r["input"]
        cells = (f"<code>{_name(_cell(name))}</code>", _value(r["value"]), r["kind"],
                 _value(r["range"]), _prose(r["source"]))
        out.append("<tr>" + "".join(
            f'<td data-label="{label}">{c}</td>'
            for (label, _), c in zip(COLUMNS, cells, strict=True)
        ) + "</tr>")
    out += ["</tbody>", "</table>"]
    return out


def render_ledger_page() -> str:
    """The Markdown of the ledger page."""
    tables = ledger_tables()
    lines = [
        "# The assumption ledger",
        "",
        "Every input of every scenario file of the four papers, with where it comes from: "
        "*paper* (stated by the paper, with the place), *derived* (computed from what the paper "
        "states), *calibrated* (fitted to a baseline figure of the paper, by the code named), "
        "*assumed* (not given by the paper: its plausible range and the reason for its ends) or "
        "*study* (a choice of the study's method: a sweep grid, a criterion the paper does not "
        "state). The files of `data/` carry this beside each value; loading a scenario refuses "
        "an input without it. Generated from those files.",
        "",
    ]
    for paper, rows in tables.items():
        counts = Counter(r["kind"] for r in rows)
        summary = ", ".join(f"{counts[k]} {k}" for k in KINDS if counts[k])
        lines += [
            f"({paper}-ledger)=",
            f"## {TITLES[paper]}",
            "",
            f"{len(rows)} inputs ({summary}) in "
            + ", ".join(f"`data/{paper}/{name}`" for name, _ in SCENARIO_FILES[paper])
            + ".",
            "",
            *_table(paper, rows),
            "",
        ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Write the ledger page: ``python -m calstudy.io.ledger book/ledger.md``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="output Markdown file, e.g. book/ledger.md")
    args = parser.parse_args(argv)
    args.out.write_text(render_ledger_page())
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["SCENARIO_FILES", "ledger_tables", "main", "render_ledger_page"]
