"""Pages of the book generated from data: the claims summary.

Run as ``python -m calstudy.io.book claims book/claims.md``. The page lists every claim of
``data/claims.csv`` with the published figure (in the unit of the reproduced one, computed from
the register's figures by :mod:`calstudy.io.claims_cells`), the reproduced one (median and 95 %
interval, N), the replication rate and the verdict from ``results/claims.csv``, and links each
claim to the section of its notebook that judges it; claims no notebook has computed yet show
as pending. The output depends only on those two files, the book's ``_toc.yml`` (a notebook is
linked when the table of contents lists it) and the notebooks' headings, so it is
byte-deterministic.
"""

from __future__ import annotations

import argparse
import html
import math
import re
import shutil
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from calstudy.claims import CLAIM_COLUMNS, VERDICTS
from calstudy.core.paths import DATA_DIR, REPO_ROOT, RESULTS_DIR
from calstudy.io.claims_cells import (
    Published,
    bound_value,
    is_ratio,
    judged_in,
    published_figure,
    published_value,
    typeset,
)
from calstudy.io.results import read_claims

__all__ = [
    "FIGURE_NAME",
    "REGISTER_COPY",
    "RESULTS_COPY",
    "claims_figure",
    "main",
    "published_value",
    "read_results",
    "render_claims_page",
    "typeset",
]

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

#: Source notebooks, where a section is looked up when the book has no executed copy.
NOTEBOOK_DIR = REPO_ROOT / "notebooks"

#: Files written beside the page: the figure and copies of the two tables it is made from.
FIGURE_NAME = "claims-verdicts.png"
REGISTER_COPY = "claims-register.csv"
RESULTS_COPY = "claims-results.csv"

#: Badge and figure colour of each verdict (the CSS classes in book/_static/calstudy.css).
VERDICT_COLOURS = {
    "reproduced": "#1a7f37",
    "direction only": "#b35900",
    "not reproduced": "#c62828",
    "not testable": "#57606a",
    PENDING: "#8c959f",
}

_RULE = """\
Each verdict is computed by the notebook from its Monte Carlo trials (rule v2 of the claims
register), never typed in. The reproduced figure is the **median over N trials** with its 95 %
confidence interval; the *effect* compares it with "no effect" (a ratio after / before of 1, a
difference of 0, or a stated reference).

- **reproduced**: the interval of the effect excludes no effect on the paper's side, and the
  median is within a factor 1.5 of the published figure (10 percentage points for a percentage);
  a requirement ("within 0.42 mm") is reproduced when the 95th percentile of the trials meets it;
- **direction only**: significant on the paper's side, but outside that band (for a requirement:
  the median meets it, the 95th percentile does not);
- **not reproduced**: not significant, or significant on the wrong side;
- **not testable**: the claim needs hardware a simulation cannot stand in for, the simulation
  lacks the mechanism (its oracle control fails), or both sides are identical by construction.

The *replication rate* is the share of trials whose own effect has the paper's direction: what
one rerun of the paper's single experiment would see. The *null control* replaces the method by
doing nothing and must come out not reproduced; the *oracle control* removes the error source
the method targets and must reach significance. Claims without a published figure ("none in
the paper") are judged against a reference method on the same trials (the statement and the
note name it).

**Inputs the paper does not state** (rule 11 of the register, the *nuisance rule*) are either
calibrated by code in the notebook so that a *baseline* figure the paper reports is matched (the
uncorrected error, a competing method's error; never the claimed figure), with the target named
in `data/`, or kept as a documented assumption that the notebook sweeps, showing where the
verdict changes.
"""

def _cell(text: object) -> str:
    """Text safe inside an HTML table cell."""
    return html.escape(typeset(text).replace("\n", " "))


def _number(x: object) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return ""
    return f"{x:.3g}" if math.isfinite(x) else ""


def _short(statement: str, limit: int = 64) -> str:
    """The first clause of ``statement``, cut at a word before ``limit`` characters."""
    s = typeset(statement)
    for stop in (": ", "; ", ". "):
        if stop in s:
            s = s.split(stop)[0]
    if len(s) <= limit:
        return s.rstrip(".")
    return s[:limit].rsplit(" ", 1)[0].rstrip(",;:") + " …"


def _toc_files(node) -> set[str]:
    """Every ``file``/``root`` entry of a parsed ``_toc.yml``."""
    if isinstance(node, dict):
        found = {v for k, v in node.items() if k in ("file", "root") and isinstance(v, str)}
        return found.union(*(_toc_files(v) for v in node.values()))
    if isinstance(node, list):
        return set().union(*(_toc_files(v) for v in node))
    return set()


def _badge(verdict: str) -> str:
    cls = verdict.replace(" ", "-")
    return f'<span class="verdict verdict-{cls}">{html.escape(verdict)}</span>'


def read_results(path: str | Path) -> pd.DataFrame:
    """``results/claims.csv`` with every column of :data:`CLAIM_COLUMNS`; rows written before
    rule v2 get ``n = 0``, no replication rate and empty controls."""
    res = read_claims(path)
    defaults = {"n": 0, "replication_rate": float("nan"), "null_control": "",
                "oracle_control": ""}
    for col, value in defaults.items():
        if col not in res.columns:
            res[col] = value
    res["n"] = pd.to_numeric(res["n"], errors="coerce").fillna(0).astype(int)
    return res[list(CLAIM_COLUMNS)]


def _published(claim: pd.Series, row: pd.Series | None) -> Published:
    """The published figure in the unit of the reproduced one (the register's own unit while
    the claim is pending)."""
    unit = typeset(row["unit"]) if row is not None else typeset(claim["unit"])
    return published_figure(claim, unit)


def _published_html(pub: Published) -> str:
    main = html.escape(pub.text)
    if pub.value is None:
        main = f'<span class="why">{main}</span>'
    extra = f'<br><span class="why">{html.escape(pub.detail)}</span>' if pub.detail else ""
    return main + extra


def _reproduced_html(row: pd.Series) -> str:
    value, lo, hi = _number(row["reproduced"]), _number(row["ci_low"]), _number(row["ci_high"])
    if not value:
        if row["verdict"] == "not testable":
            return '<span class="why">no figure: not testable (see the note)</span>'
        return '<span class="why">not computed</span>'
    unit = html.escape(typeset(row["unit"]))
    interval = f" [{lo}, {hi}]" if lo and hi else ""
    n = int(row["n"])
    trials = f'<br><span class="why">N = {n}</span>' if n > 0 else ""
    return f"{value} {unit}<span class=\"ci\">{interval}</span>{trials}"


def _rate_html(row: pd.Series) -> str:
    rate = row["replication_rate"]
    if rate is None or not math.isfinite(float(rate)):
        return '<span class="why" title="no per-trial effect: not testable or no trials">—</span>'
    return f"{100 * float(rate):.0f} %"


def _controls_text(row: pd.Series) -> str:
    parts = [
        f"{name} control: {typeset(row[col])}"
        for name, col in (("null", "null_control"), ("oracle", "oracle_control"))
        if typeset(row[col])
    ]
    return "; ".join(parts)


def _details(claim: pd.Series, row: pd.Series | None) -> str:
    parts = [f"<p>{_cell(claim['statement'])}</p>"]
    published = _cell(claim["published"])
    published = f"{published} {_cell(claim['unit'])}" if published else "no figure"
    parts.append(f"<p><em>Where in the paper:</em> {_cell(claim['where'])}. "
                 f"<em>Published:</em> {published}.</p>")
    if typeset(claim.get("comparison", "")):
        parts.append(f"<p><em>Compared:</em> {_cell(claim['comparison'])}</p>")
    if row is not None and _controls_text(row):
        parts.append(f"<p><em>Controls:</em> {html.escape(_controls_text(row))}.</p>")
    if row is not None and typeset(row["note"]):
        parts.append(f"<p><em>Note:</em> {_cell(row['note'])}</p>")
    return "".join(parts)


def _section_link(claim_id: str, stem: str, book_dir: Path, toc: set[str]) -> str:
    """Link to the notebook section where the claim is judged (the notebook number and the
    start of the heading), or the notebook number alone if its page is not in the book."""
    number = html.escape(stem.split("_")[0]) if stem else "—"
    if not stem or f"notebooks/{stem}" not in toc:
        return number
    page = f"notebooks/{html.escape(stem)}.html"
    found = None
    for notebook in (book_dir / "notebooks" / f"{stem}.ipynb", NOTEBOOK_DIR / f"{stem}.ipynb"):
        if notebook.is_file():
            found = judged_in(claim_id, notebook)
            break
    if found is None:
        return f'<a href="{page}" title="{html.escape(stem)}">{number}</a>'
    anchor, heading = found
    heading = re.sub(r"^\d+\.\s*", "", heading)
    short = heading.split(": ")[0].split(" (")[0]
    if len(short) > 28:
        short = short[:28].rsplit(" ", 1)[0].rstrip(",;:(") + " …"
    return (f'<a class="section-link" href="{page}#{anchor}" title="{html.escape(heading)}">'
            f"{number} § {html.escape(short)}</a>")


def _table(group: pd.DataFrame, computed: dict, toc: set[str], book_dir: Path) -> list[str]:
    lines = [
        '<table class="claims">',
        '<colgroup><col class="c-claim"><col class="c-pub"><col class="c-rep">'
        '<col class="c-rate"><col class="c-verdict"><col class="c-nb"></colgroup>',
        "<thead><tr><th>claim (click for the statement)</th><th>published</th>"
        "<th>reproduced [95 % CI]</th><th>repl. rate</th><th>verdict</th>"
        "<th>judged in</th></tr></thead>",
        "<tbody>",
    ]
    for _, claim in group.iterrows():
        row = computed.get(claim["id"])
        short = html.escape(_short(claim["statement"]))
        summary = f"<code>{html.escape(claim['id'])}</code> {short}"
        # the summary toggles the full-width row below it (book/_static/calstudy.css)
        claim_cell = f"<details><summary>{summary}</summary></details>"
        published = _published_html(_published(claim, row))
        if row is None:
            cells = [claim_cell, published, '<span class="why">not computed yet</span>', "—",
                     _badge(PENDING), "—"]
        else:
            stem = typeset(row["notebook"])
            cells = [claim_cell, published, _reproduced_html(row), _rate_html(row),
                     _badge(typeset(row["verdict"])),
                     _section_link(claim["id"], stem, book_dir, toc)]
        classes = ["", "", "num", "num", "", ""]
        tds = "".join(f'<td class="{c}">{v}</td>' if c else f"<td>{v}</td>"
                      for c, v in zip(classes, cells, strict=True))
        more = f'<tr class="claim-more"><td colspan="{len(cells)}">{_details(claim, row)}</td></tr>'
        lines.append(f"<tr>{tds}</tr>{more}")
    lines += ["</tbody>", "</table>"]
    return lines


def _kind(unit: str) -> str:
    return "ratio" if is_ratio(unit) else typeset(unit) or "value"


def claims_figure(
    res: pd.DataFrame, path: str | Path, register: pd.DataFrame | None = None
) -> tuple[Path, str]:
    """Draw published against reproduced, one panel per unit (ratios on a log axis around 1).

    Each claim is a row: the reproduced median with its 95 % interval, coloured by verdict,
    and the published figure in the same unit (a black diamond, a bar for a published range),
    computed from the register's figures (:func:`~calstudy.io.claims_cells.published_figure`).

    Returns
    -------
    tuple of (pathlib.Path, str)
        The PNG written and a one-sentence description of it (the image's alt text).
    """
    # a bare Figure, not pyplot: no backend is chosen or switched for the caller
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, NullFormatter

    from calstudy.io.results import write_figure

    if register is None:
        register = pd.read_csv(DATA_DIR / "claims.csv", dtype=str, keep_default_na=False)
    claims = {c["id"]: c for _, c in register.iterrows()}
    res = res[np.isfinite(res["reproduced"].astype(float))].copy()
    res["kind"] = res["unit"].map(_kind)
    order = [k for k in ("ratio", "mm", "%") if k in set(res["kind"])]
    order += sorted(set(res["kind"]) - set(order))
    sizes = [int((res["kind"] == k).sum()) for k in order]
    bounds = False
    fig = Figure(figsize=(7.8, 0.9 + 0.3 * sum(sizes) + 0.55 * len(order)))
    axes = fig.subplots(
        len(order), 1, gridspec_kw={"height_ratios": [s + 1.2 for s in sizes]}, squeeze=False
    )
    for ax, kind in zip(axes[:, 0], order, strict=True):
        group = res[res["kind"] == kind].sort_values("id", ascending=False)
        y = np.arange(len(group))
        values = []
        for yi, (_, row) in zip(y, group.iterrows(), strict=True):
            colour = VERDICT_COLOURS.get(row["verdict"], "#000000")
            med, lo, hi = (float(row[c]) for c in ("reproduced", "ci_low", "ci_high"))
            if math.isfinite(lo) and math.isfinite(hi):
                ax.plot([lo, hi], [yi, yi], color=colour, lw=2.2, solid_capstyle="butt")
                values += [lo, hi]
            ax.plot(med, yi, "o", color=colour, ms=6)
            values.append(med)
            claim = claims.get(row["id"])
            pub = None if claim is None else published_figure(claim, row["unit"]).value
            bound = None if claim is None or pub is not None else bound_value(claim)
            if bound is not None:
                ax.plot(bound, yi, "|", color="black", ms=13, mew=1.6)
                values.append(bound)
                bounds = True
            if pub is not None:
                if pub[1] > pub[0]:
                    ax.plot(pub, [yi, yi], color="black", lw=5, alpha=0.25)
                ax.plot(np.mean(pub), yi, "D", mfc="none", mec="black", ms=6, mew=1.3)
                values += list(pub)
        ax.set_yticks(y, group["id"].tolist(), fontsize=8)
        ax.set_ylim(-0.7, len(group) - 0.3)
        ax.tick_params(axis="x", labelsize=8)
        values = np.array([v for v in values if math.isfinite(v)])
        if kind == "ratio":
            ax.set_xscale("log")
            ax.axvline(1.0, color="0.5", lw=0.8, ls="--")
            span = max(abs(np.log10(values[values > 0])).max(initial=0.3), 0.3) * 1.15
            ax.set_xlim(10 ** -span, 10 ** span)
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel("ratio (log scale; 1 = no effect or as good as the reference)",
                          fontsize=8)
        else:
            pad = 0.08 * (values.max() - min(values.min(), 0.0) or 1.0)
            ax.set_xlim(min(values.min(), 0.0) - pad, values.max() + pad)
            ax.set_xlabel(f"{kind}", fontsize=8)
        ax.grid(axis="x", color="0.9", lw=0.6)
        ax.set_axisbelow(True)
    handles = [Line2D([], [], color=VERDICT_COLOURS[v], marker="o", lw=2.2, label=v)
               for v in VERDICTS if v in set(res["verdict"])]
    handles.append(Line2D([], [], color="black", marker="D", mfc="none", lw=0,
                          label="published"))
    if bounds:
        handles.append(Line2D([], [], color="black", marker="|", ms=10, mew=1.6, lw=0,
                              label="bound (no published figure)"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8,
               frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    out = write_figure(fig, path, dpi=150)
    alt = (
        f"Published against reproduced figure for the {len(res)} computed claims, one panel "
        f"per unit ({', '.join(order)}; ratios on a log axis with 1 marked): the reproduced "
        "median as a dot with its 95 % interval as a bar, coloured by verdict, the published "
        "figure as an open diamond, a bound the claim is judged against as a vertical bar."
    )
    return out, alt


def render_claims_page(
    out_path: str | Path,
    register: str | Path | None = None,
    results: str | Path | None = None,
) -> Path:
    """Write the MyST page summarising every claim and its verdict.

    Beside the page it writes the figure (:data:`FIGURE_NAME`) and copies of the register and
    the results table (:data:`REGISTER_COPY`, :data:`RESULTS_COPY`), which the page offers
    for download.

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
    out_path.parent.mkdir(parents=True, exist_ok=True)
    reg_path = DATA_DIR / "claims.csv" if register is None else Path(register)
    reg = pd.read_csv(reg_path, dtype=str, keep_default_na=False)
    res_path = RESULTS_DIR / "claims.csv" if results is None else Path(results)
    res = read_results(res_path) if res_path.is_file() else None
    computed = {} if res is None else {r["id"]: r for _, r in res.iterrows()}

    toc_path = out_path.parent / "_toc.yml"
    toc = _toc_files(yaml.safe_load(toc_path.read_text())) if toc_path.is_file() else set()

    counts = Counter(res["verdict"]) if res is not None else Counter()
    counts[PENDING] = sum(1 for i in reg["id"] if i not in computed)
    badges = " ".join(
        f"{_badge(v)} {counts.get(v, 0)}" for v in (*VERDICTS, PENDING) if counts.get(v, 0)
    )
    _copy(reg_path, out_path.parent / REGISTER_COPY)
    lines = [
        "# Claims and verdicts",
        "",
        "Every claim of the four papers that this study checks: the figure the paper publishes,",
        "the figure reproduced on synthetic data and the verdict. Generated by `make reproduce`",
        f"from the claims register {{download}}`data/claims.csv <{REGISTER_COPY}>` and the",
        "results",
        f"{{download}}`results/claims.csv <{RESULTS_COPY}>`." if res is not None else
        "(none computed yet).",
        "",
        f'<p class="verdict-counts"><strong>{len(reg)} claims:</strong> {badges}</p>',
        "",
    ]
    if res is not None and len(res):
        _copy(res_path, out_path.parent / RESULTS_COPY)
        figure, alt = claims_figure(res, out_path.parent / FIGURE_NAME, reg)
        lines += [
            f"```{{figure}} {figure.name}",
            f":alt: {alt}",
            ":width: 100%",
            "",
            "Published (open diamond; a grey bar for a range) against reproduced (dot: median over "
            "the trials, bar: 95 % confidence interval), coloured by verdict; a black tick marks "
            "the bound a claim without a published figure is judged against. The published "
            "ratios are computed from the paper's figures (the table gives them).",
            "```",
            "",
        ]
    lines += ["## How a verdict is computed", "", _RULE.rstrip(), ""]
    papers = list(PAPERS) + sorted(set(reg["paper"]) - set(PAPERS))
    for paper in papers:
        group = reg[reg["paper"] == paper]
        if group.empty:
            continue
        title, key = PAPERS.get(paper, (paper, ""))
        cite = f" {{cite:p}}`{key}`" if key else ""
        lines += [f"## {paper}", "", f"*{title}*{cite}.", ""]
        lines += _table(group, computed, toc, out_path.parent)
        lines.append("")

    text = "\n".join(lines).rstrip("\n") + "\n"
    tmp = out_path.with_name(f".{out_path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(out_path)
    return out_path


def _copy(src: Path, dest: Path) -> None:
    if src.resolve() != dest.resolve():
        tmp = dest.with_name(f".{dest.name}.tmp")
        shutil.copyfile(src, tmp)
        tmp.replace(dest)


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
