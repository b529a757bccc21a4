"""Pages of the book generated from data: the claims summary.

Run as ``python -m calstudy.io.book claims book/claims.md``. The page lists every claim of
``data/claims.csv`` with the published figure, the reproduced one (value and 95 % interval) and
the verdict from ``results/claims.csv``; claims no notebook has computed yet show as pending.
The output depends only on those two files and on the book's ``_toc.yml`` (a notebook name links
to its chapter when the table of contents lists it), so it is byte-deterministic.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import pandas as pd
import yaml

from calstudy.claims import VERDICTS
from calstudy.core.paths import DATA_DIR, RESULTS_DIR
from calstudy.io.results import read_claims

#: Paper short name -> (title, bibtex key in book/references.bib), in book order.
PAPERS = {
    "hybrid": ("Rapid global calibration technology for hybrid visual inspection system", "hybrid"),
    "selfcal": (
        "Development and self-calibration of a robotic visual inspecting system",
        "selfcal",
    ),
    "binocular": (
        "Improved calibration of eye-in-hand robotic vision system based on binocular sensor",
        "binocular",
    ),
    "dualarm": (
        "A multi-view three-dimensional scanning method for a dual-arm hand-eye system with "
        "global calibration of coded marker points",
        "dualarm",
    ),
}

PENDING = "pending"

_RULE = """\
A verdict is computed by the notebook from its Monte Carlo trials, never typed in:

- **reproduced**: the effect has the paper's direction, its 95 % interval over the trials
  excludes "no effect", and the reproduced figure is within a factor 1.5 of the published one
  (for a percentage, within 10 percentage points);
- **direction only**: significant and in the paper's direction, but outside that band;
- **not reproduced**: not significant, or the opposite direction;
- **not testable**: the claim needs hardware a simulation cannot stand in for (the note says
  why).

Where the paper gives no number, the method is compared with a maximum-likelihood estimate on
the same simulated data: reproduced when its RMS error is within a factor 1.5 of it, direction
only when it works but is worse, not reproduced when it fails.

The interval shown is the central 95 % of the reproduced figure over the trials: the spread of
the result from one simulated repetition of the paper's experiment to the next, so a verdict
does not become more favourable by running more trials (for the ratio to maximum likelihood it
is a bootstrap interval of the RMS ratio). *Pending* means no notebook has computed the claim
yet.
"""


def _cell(text: object) -> str:
    """Text safe inside a markdown table cell."""
    s = "" if text is None or (isinstance(text, float) and math.isnan(text)) else str(text)
    return s.replace("|", "\\|").replace("\n", " ").strip()


def _number(x: float) -> str:
    return "" if x is None or not math.isfinite(float(x)) else f"{float(x):.3g}"


def _reproduced(row: pd.Series) -> str:
    value, lo, hi = _number(row["reproduced"]), _number(row["ci_low"]), _number(row["ci_high"])
    if not value:
        return ""
    return f"{value} [{lo}, {hi}]" if lo and hi else value


def _toc_files(node) -> set[str]:
    """Every ``file``/``root`` entry of a parsed ``_toc.yml``."""
    if isinstance(node, dict):
        found = {v for k, v in node.items() if k in ("file", "root") and isinstance(v, str)}
        return found.union(*(_toc_files(v) for v in node.values()))
    if isinstance(node, list):
        return set().union(*(_toc_files(v) for v in node))
    return set()


def _notebook(stem: str, toc: set[str]) -> str:
    if not stem:
        return ""
    if f"notebooks/{stem}" in toc:
        return f"{{doc}}`{stem} <notebooks/{stem}>`"
    return f"`{stem}`"


def render_claims_page(
    out_path: str | Path,
    register: str | Path | None = None,
    results: str | Path | None = None,
) -> Path:
    """Write the MyST page summarising every claim and its verdict.

    Parameters
    ----------
    out_path : str or pathlib.Path
        Destination, normally ``book/claims.md``. Notebook names link to the chapter
        ``notebooks/<stem>`` when the ``_toc.yml`` beside the page lists it.
    register : str or pathlib.Path, optional
        The claims register; default ``data/claims.csv``.
    results : str or pathlib.Path, optional
        Aggregated verdicts; default ``results/claims.csv``. A missing file means every claim
        is pending.

    Returns
    -------
    pathlib.Path
        ``out_path``.
    """
    out_path = Path(out_path)
    reg = pd.read_csv(
        DATA_DIR / "claims.csv" if register is None else register, dtype=str, keep_default_na=False
    )
    res_path = RESULTS_DIR / "claims.csv" if results is None else Path(results)
    res = read_claims(res_path) if res_path.is_file() else None
    computed = {} if res is None else {r["id"]: r for _, r in res.iterrows()}

    toc_path = out_path.parent / "_toc.yml"
    toc = _toc_files(yaml.safe_load(toc_path.read_text())) if toc_path.is_file() else set()

    verdicts = [computed[i]["verdict"] if i in computed else PENDING for i in reg["id"]]
    counts = Counter(verdicts)
    summary = ", ".join(f"{counts.get(v, 0)} {v}" for v in (*VERDICTS, PENDING))

    lines = [
        "# Claims and verdicts",
        "",
        "Every claim of the four papers that this study checks, with the figure the paper",
        "publishes, the figure reproduced on synthetic data and the verdict. The table is",
        "generated from `data/claims.csv` and `results/claims.csv` by `make reproduce`.",
        "",
        f"**{len(reg)} claims: {summary}.**",
        "",
        "## How a verdict is computed",
        "",
        _RULE.rstrip(),
        "",
    ]
    papers = list(PAPERS) + sorted(set(reg["paper"]) - set(PAPERS))
    for paper in papers:
        group = reg[reg["paper"] == paper]
        if group.empty:
            continue
        title, key = PAPERS.get(paper, (paper, ""))
        cite = f" {{cite:p}}`{key}`" if key else ""
        lines += [
            f"## {paper}",
            "",
            f"*{title}*{cite}.",
            "",
            "| claim (where) | statement | published | reproduced [95 % interval] | verdict "
            "| notebook | note |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for _, claim in group.iterrows():
            row = computed.get(claim["id"])
            unit = _cell(claim["unit"])
            published = _cell(claim["published"])
            published = f"{published} {unit}" if published and unit else published
            if row is None:
                reproduced, verdict, nb, note = "", f"*{PENDING}*", "", ""
            else:
                value = _reproduced(row)
                rep_unit = _cell(row["unit"])
                reproduced = f"{value} {rep_unit}" if value and rep_unit else value
                verdict = f"**{_cell(row['verdict'])}**"
                nb = _notebook(_cell(row["notebook"]), toc)
                note = _cell(row["note"])
            cells = [
                f"`{claim['id']}` ({_cell(claim['where'])})",
                _cell(claim["statement"]),
                published,
                _cell(reproduced),
                verdict,
                nb,
                note,
            ]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")

    out_path.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join(lines).rstrip("\n") + "\n"
    tmp = out_path.with_name(f".{out_path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(out_path)
    return out_path


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m calstudy.io.book claims OUT.md``."""
    parser = argparse.ArgumentParser(prog="python -m calstudy.io.book", description=__doc__)
    sub = parser.add_subparsers(dest="page", required=True)
    claims = sub.add_parser("claims", help="render the claims summary page")
    claims.add_argument("out", type=Path, help="output markdown file, e.g. book/claims.md")
    claims.add_argument("--register", type=Path, default=None, help="default data/claims.csv")
    claims.add_argument("--results", type=Path, default=None, help="default results/claims.csv")
    args = parser.parse_args(argv)
    path = render_claims_page(args.out, register=args.register, results=args.results)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
