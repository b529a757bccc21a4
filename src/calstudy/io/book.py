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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from calstudy.claims import CLAIM_COLUMNS, VERDICTS, claim_register
from calstudy.core.labels import claim_label
from calstudy.core.paths import DATA_DIR, REPO_ROOT, RESULTS_DIR, atomic_write
from calstudy.core.verdicts import BAND_PP, FACTOR
from calstudy.io.claims_cells import (
    VERDICT_COLOURS,
    Published,
    bound_value,
    is_ratio,
    judged_in,
    published_figure,
    typeset,
)
from calstudy.io.results import read_claims
from calstudy.io.robustness_grid import grid_figure, read_maps

__all__ = [
    "COLUMNS",
    "FIGURE_NAME",
    "GRID_NAME",
    "HEADLINE_NAME",
    "REGISTER_COPY",
    "RESULTS_COPY",
    "chapter_fragment",
    "claim_sentence",
    "claim_target",
    "claims_figure",
    "headline",
    "main",
    "read_results",
    "render_claims_page",
    "percent",
    "verdict_box",
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
#: the robustness grid (:mod:`calstudy.io.robustness_grid`)
GRID_NAME = "claims-robustness.png"
REGISTER_COPY = "claims-register.csv"
RESULTS_COPY = "claims-results.csv"



#: The verdict rule, numbered: chapters, notebooks, data files and docstrings cite its rules as
#: "rule N" (the page's dropdown *How a verdict is computed*).
_RULE = f"""\
Each verdict is computed by the notebook from its Monte Carlo trials, never typed in. A *trial* is
one independent simulated rerun of the paper's experiment (a new station, new noise); its *figure*
is what the paper reports for that experiment (an RMSE, a ratio of RMSEs, a percentage, an
iteration count); the *effect* sets the figure against no effect: the paired ratio after / before
on the same trial (no effect: 1), a difference (no effect: 0), or the value against a stated
reference. This is version 2 of the study's verdict rule (the *v2 rule* of the chapters); its rules
are numbered, and the chapters, notebooks and data files cite them as "rule N".

1. **Trials.** An experiment that decides a claim runs at least 200 trials, each point of a sweep
   at least 30; the table gives N.
2. **Reproduced figure.** The **median over the N trials** with its 95 % confidence interval
   (order statistics of the median, or a percentile bootstrap of at least 2,000 resamples).
3. **Significance.** The interval of the median effect lies wholly on the paper's side of no
   effect.
4. **Size.** The median lies within a factor {FACTOR:g} of the published figure, or within
   {BAND_PP:g} percentage points of it for a percentage.
5. **Verdict.** **reproduced** when 3 and 4 hold; **direction only** when 3 holds and 4 does not;
   **not reproduced** when 3 fails or the effect is significant on the wrong side; **not
   testable** as rule 9 says.
6. **Replication rate.** The share of trials whose own effect points the paper's way: what one
   rerun of the paper's single experiment would see. Shown beside every verdict; it does not
   decide it.
7. **Requirements.** A claim that a requirement is met ("within 0.42 mm") is reproduced when the
   95th percentile of the per-trial figure meets it, direction only when the median meets it and
   the 95th percentile does not, not reproduced when the median misses it; no size band applies.
8. **Controls.** A claim about a correction or a comparison of methods runs twice more on the same
   trials: with the method replaced by doing nothing (the *null control*), which must come out not
   reproduced, or the test is broken; and with the error source the method targets taken out of the
   simulation (the *oracle control*), which must reach significance, or the simulation lacks the
   mechanism the paper corrects and the claim is not testable until it is modelled (the note names
   it).
9. **Not testable.** The claim needs hardware a simulation cannot stand in for, the model lacks its
   mechanism (rule 8), or the two sides are identical by construction (two solvers of an exactly
   determined system, say); the note says which.
10. **Baselines.** A claim judged against maximum likelihood uses the likelihood of the
    simulation's whole noise model (every source it draws, with its correlations), and a test shows
    that estimator reaching the Cramér-Rao bound. A method "works" only by a criterion that can
    fail: an error within a stated multiple of the bound, or within the paper's stated accuracy. A
    rival route is given its best estimator and its natural order. Claims without a published
    figure ("none in the paper") are judged against such a reference on the same trials (the
    statement and the note name it).
11. **Inputs the paper does not state** (the *nuisance rule*). Such an input is either calibrated,
    by code in the notebook, so that a *baseline* figure the paper reports is met (the uncorrected
    error, a competing method's error, the scatter before compensation; never the claimed figure),
    with the target and where the paper gives it named in `data/`, or kept as a documented
    assumption that the notebook sweeps, showing where the verdict changes.
12. **Provenance of every input (the ledger).** Each input of a scenario is *paper* (where in the
    text), *calibrated* (to which baseline figures, by which code) or *assumed* (with a plausible
    range and the reason for its ends). What the paper's stated instruments determine is derived
    from them, not assumed.
13. **Robustness.** Every assumed input that moves a claim's figure is swept over its whole range,
    at least 30 trials per point, judged by these rules at each point. A verdict that stays the same
    over the range is *robust*; otherwise it is *conditional*, reported with the verdicts it takes,
    where it changes and where the paper's own numbers put the input. No verdict is shown without
    its robustness.
14. **Joint calibration and mechanisms.** A nuisance input is calibrated to every baseline figure
    the paper reports for the experiment together. A mechanism the paper does not describe is kept
    only if it meets all of them; when none or several do, every mechanism the text allows is run,
    the paper's own model first, and the verdict is given under each.
15. **Criteria and controls.** The register says whether a claim's criterion is the paper's (and
    where) or the study's (and why); a study criterion is never presented as published. Where the
    paper gives no figure, the method is judged against the rivals the register names, on the same
    data, by a pooled or paired statistic that its oracle can pass. A null control that equals no
    effect, or fails, by construction checks nothing: the null must be one a broken method could
    plausibly pass.
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
    rule v2 get ``n = 0``, no replication rate and empty controls, rows written before the
    register said whose criterion each claim has an empty ``criterion`` (the page takes it from
    the register)."""
    res = read_claims(path)
    defaults = {"n": 0, "replication_rate": float("nan"), "null_control": "",
                "oracle_control": "", "criterion": ""}
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
            f'{number} §<span class="nb-heading"> {html.escape(short)}</span></a>')


@dataclass(frozen=True)
class Target:
    """What a claim's reproduced figure is set against, in the reproduced figure's unit.

    Attributes
    ----------
    value : float or None
        The published figure (the middle of a published range), the bound, or 1 for a ratio
        judged against no effect; None when there is nothing to set it against.
    kind : str
        ``"published"``, ``"bound"`` or ``"no effect"`` ("" without a value).
    band : tuple of float
        The accepted region of reproduced / target: the factor-1.5 band (10 percentage points
        for a percentage) around a published figure, the side of the bound or of no effect
        that the paper claims.
    """

    value: float | None
    kind: str = ""
    band: tuple[float, float] = (0.0, 0.0)


_NOTE_BOUND = re.compile(r"\bbound\s*(?:<=|≤|>=|≥)\s*([0-9.]+(?:e[-+]?\d+)?)")


def claim_target(claim, row: pd.Series | None) -> Target:
    """The target of ``claim`` (a register row) for the reproduced ``row`` (results/claims.csv);
    a bound the register states as a formula (``1.36/sqrt(n)``) is the value the notebook
    computed and wrote into the row's note ("bound <= 0.105")."""
    unit = typeset(row["unit"]) if row is not None else typeset(claim["unit"])
    higher = typeset(claim.get("direction", "")) == "higher"
    side = (1.0, math.inf) if higher else (0.0, 1.0)
    pub = published_figure(claim, unit).value
    if typeset(claim.get("kind", "")) == "bound":
        bound = bound_value(claim)
        if bound is None and pub is not None:
            bound = float(np.mean(pub))
        if bound is None and row is not None and (m := _NOTE_BOUND.search(typeset(row["note"]))):
            bound = float(m.group(1))
        return Target(bound, "bound", side) if bound is not None else Target(None)
    if pub is not None:
        value = float(np.mean(pub))
        if unit == "%":
            return Target(value, "published", ((value - BAND_PP) / value,
                                               (value + BAND_PP) / value))
        return Target(value, "published", (1 / FACTOR, FACTOR))
    if is_ratio(unit):
        return Target(1.0, "no effect", side)
    return Target(None)


def percent(rate: object) -> str:
    """A share as the book writes it everywhere: whole percent (``0.445`` -> ``"45 %"``,
    Python's ``.0%`` rounding), "" for a missing value."""
    try:
        x = float(rate)
    except (TypeError, ValueError):
        return ""
    return f"{x:.0%}".replace("%", " %") if math.isfinite(x) else ""


def _control_badges(row: pd.Series | None) -> str:
    """Small badges of the null and oracle controls: passed (the null not reproduced, the oracle
    significant), failed, or absent."""
    if row is None:
        return ""
    out = []
    for name, col, wanted in (("null", "null_control", ("not reproduced",)),
                              ("oracle", "oracle_control", ("reproduced", "direction only"))):
        got = typeset(row[col])
        if not got:
            continue
        ok = got in wanted
        mark, cls = ("✓", "pass") if ok else ("✗", "fail")
        out.append(f'<span class="control control-{cls}" title="{name} control: '
                   f'{html.escape(got)}">{name} {mark}</span>')
    return " ".join(out) or '<span class="why" title="no control for this claim">—</span>'


def _target_html(claim, row: pd.Series | None) -> str:
    target = claim_target(claim, row)
    pub = _published(claim, row)
    tip = html.escape(" ".join(p for p in (pub.text, pub.detail) if p), quote=True)
    if target.kind == "bound":
        sign = "≥" if target.band[1] == math.inf else "≤"
        return f'<span title="bound: {tip}">{sign} {_number(target.value)}</span>'
    if target.kind == "published":
        shown = pub.text.removesuffix(typeset(row["unit"]) if row is not None else "").strip()
        return f'<span title="{tip}">{html.escape(shown)}</span>'
    if target.kind == "no effect":
        return f'<span class="why" title="{tip}">none; vs 1</span>'
    return f'<span class="why" title="{tip}">none</span>'


def _criterion_tag(claim) -> str:
    """A small tag saying whose criterion the claim is judged by: the paper's (``paper``) or the
    study's (``study``, rule 15), its source in the title."""
    source = html.escape(typeset(claim.get("criterion_source", "")), quote=True)
    if typeset(claim.get("criterion", "")) == "study":
        return (f' <span class="crit crit-study" title="criterion of the study: {source}">'
                "study</span>")
    return f' <span class="crit crit-paper" title="published: {source}">paper</span>'


def _reproduced_cell(row: pd.Series | None) -> str:
    if row is None:
        return '<span class="why">not computed yet</span>'
    value, lo, hi = _number(row["reproduced"]), _number(row["ci_low"]), _number(row["ci_high"])
    if not value:
        return '<span class="why">no figure</span>'
    interval = f' <span class="ci">[{lo}, {hi}]</span>' if lo and hi else ""
    n = int(row["n"])
    return f'<span title="median of N = {n} trials">{value}</span>{interval}'


def _unit_cell(claim, row: pd.Series | None) -> str:
    return html.escape(UNIT_LABELS.get(u := typeset(row["unit"] if row is not None
                                                    else claim["unit"]), u))


#: Units as the claims table writes them (short words).
UNIT_LABELS = {"x CRB RMS": "× CRB", "× CRB RMS": "× CRB", "Kolmogorov distance": "K-S distance",
               "model error / CRB": "× CRB", "field error ratio": "ratio",
               "frame error ratio": "ratio", "iterations": "iterations"}


@dataclass(frozen=True)
class Column:
    """One column of the claims table: header, CSS class and the cell of a claim.

    ``cell(claim, row, context)`` gets the register row, the results row (None while pending)
    and a dict with ``toc`` and ``book_dir``; it returns HTML.
    """

    key: str
    header: str
    cell: object
    css: str = ""


def _claim_cell(claim, row, context) -> str:
    words = html.escape(claim_label(claim["id"]))
    return (f'<details><summary title="{html.escape(claim["id"])}">{words}</summary>'
            "</details>")


def _verdict_cell(claim, row, context) -> str:
    return _badge(PENDING if row is None else typeset(row["verdict"])) + _robustness_tag(row)


def _robustness_tag(row: pd.Series | None) -> str:
    """A small tag under the verdict: *robust* or *conditional* over the inputs the map screened
    (the inputs and thresholds in its title), or *not mapped* while the claim has no map."""
    state = typeset(row.get("robustness", "")) if row is not None else ""
    if not state:
        return ""
    depends = typeset(row.get("depends_on", ""))
    thresholds = typeset(row.get("thresholds", ""))
    tip = {
        "robust": "the same verdict over the plausible range of every input screened",
        "conditional": f"the verdict depends on {depends}" + (f": {thresholds}" if thresholds
                                                              else ""),
    }.get(state, "no robustness map yet for this claim")
    css = state.replace(" ", "-")
    return (f' <span class="rob rob-{html.escape(css)}" title="{html.escape(tip, quote=True)}">'
            f"{html.escape(state)}</span>")


def _notebook_cell(claim, row, context) -> str:
    if row is None:
        return "—"
    return _section_link(claim["id"], typeset(row["notebook"]), context["book_dir"],
                         context["toc"])


#: The columns of the claims table, in order; a column is added by adding an entry.
COLUMNS = [
    Column("claim", "claim", _claim_cell, "claim"),
    Column("published", "criterion", lambda c, r, x: _target_html(c, r) + _criterion_tag(c), "num"),
    Column("reproduced", "reproduced [95 % CI]", lambda c, r, x: _reproduced_cell(r), "num"),
    Column("unit", "unit", lambda c, r, x: _unit_cell(c, r), "unit"),
    Column("rate", "replic.", lambda c, r, x: (
        percent(r["replication_rate"]) if r is not None and percent(r["replication_rate"])
        else '<span class="why" title="no per-trial effect">—</span>'), "num"),
    Column("controls", "controls", lambda c, r, x: _control_badges(r), "controls"),
    Column("verdict", "verdict", _verdict_cell, "verdict-cell"),
    Column("notebook", "where", _notebook_cell, "nb"),
]


def _table(reg: pd.DataFrame, computed: dict, toc: set[str], book_dir: Path) -> list[str]:
    """The one table of every claim, grouped by paper; a claim's statement, controls and note
    open below its row (its summary toggles them)."""
    context = {"toc": toc, "book_dir": book_dir}
    head = "".join(f'<th class="{c.css}">{html.escape(c.header)}</th>' for c in COLUMNS)
    lines = ['<table class="claims">', f"<thead><tr>{head}</tr></thead>", "<tbody>"]
    papers = list(PAPERS) + sorted(set(reg["paper"]) - set(PAPERS))
    for paper in papers:
        group = reg[reg["paper"] == paper]
        if group.empty:
            continue
        title = PAPERS.get(paper, (paper, ""))[0]
        lines.append(f'<tr class="paper-row"><th colspan="{len(COLUMNS)}">'
                     f"{html.escape(PAPER_NAMES.get(paper, paper))}"
                     f' <span class="why">{html.escape(title)}</span></th></tr>')
        for _, claim in group.iterrows():
            row = computed.get(claim["id"])
            tds = "".join(
                f'<td class="{c.css}" data-label="{html.escape(c.header)}">'
                f"{c.cell(claim, row, context)}</td>"
                for c in COLUMNS
            )
            more = (f'<tr class="claim-more"><td colspan="{len(COLUMNS)}">'
                    f"{_details(claim, row)}</td></tr>")
            lines.append(f'<tr class="claim" id="claim-{claim["id"].replace(".", "-")}">'
                         f"{tds}</tr>{more}")
    lines += ["</tbody>", "</table>"]
    return lines


#: Paper short name -> the subject of its chapter (the book's part titles).
PAPER_NAMES = {
    "hybrid": "Hybrid visual inspection station",
    "selfcal": "Robotic visual inspection, self-calibration",
    "binocular": "Eye-in-hand binocular sensor",
    "dualarm": "Dual-arm hand-eye scanning",
}

#: Marker of each verdict in the figures (shape as well as colour).
VERDICT_MARKERS = {"reproduced": "o", "direction only": "D", "not reproduced": "X",
                   "not testable": "s", PENDING: "."}


def claims_figure(
    res: pd.DataFrame, path: str | Path, register: pd.DataFrame | None = None,
    papers: Sequence[str] | None = None,
) -> tuple[Path, str]:
    """Draw every claim on one normalised axis: reproduced / target, grouped by paper.

    The target is the published figure, the bound, or no effect (1) for a ratio judged against
    it (:func:`claim_target`). Each row shades the region the rule accepts (the factor-1.5
    band around a published figure, the claimed side of a bound or of no effect), draws the
    target at 1 (a black tick for a bound, an open diamond for a published figure, a dashed
    line for no effect) and the reproduced median with its 95 % interval, in its verdict's
    colour and marker shape. A claim without a reproduced figure (not testable) is a grey row
    saying so. Text is 10 pt at a 7.8 in width.

    Parameters
    ----------
    res : pandas.DataFrame
        ``results/claims.csv`` (:func:`read_results`).
    path : str or pathlib.Path
        The PNG to write.
    register : pandas.DataFrame, optional
        The claims register; default ``data/claims.csv``.
    papers : sequence of str, optional
        Only these papers (default all).

    Returns
    -------
    tuple of (pathlib.Path, str)
        The PNG written and a one-sentence description of it (the image's alt text).
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from matplotlib.ticker import FixedLocator, NullFormatter
    from matplotlib.transforms import blended_transform_factory

    from calstudy.io.results import write_figure

    if register is None:
        register = claim_register()
    computed = {r["id"]: r for _, r in res.iterrows()}
    order = list(PAPERS) + sorted(set(register["paper"]) - set(PAPERS))
    order = [p for p in order if papers is None or p in papers]
    rows, groups = [], []  # (y, claim, row) and (y of the paper's label, paper)
    y = 0.0
    for paper in order:
        group = register[(register["paper"] == paper) & register["id"].isin(list(computed))]
        if group.empty:
            continue
        groups.append((y, paper))
        y += 0.9
        for _, claim in group.iterrows():
            rows.append((y, claim, computed[claim["id"]]))
            y += 1.0
        y += 0.35
    lo_x, hi_x = 0.05, 20.0
    fig = Figure(figsize=(7.8, 1.2 + 0.3 * y))
    ax = fig.add_axes((0.36, 1.0 / (1.2 + 0.3 * y) * 0.95, 0.61,
                       (0.3 * y) / (1.2 + 0.3 * y)))
    ax.set_xscale("log")
    ax.set_xlim(lo_x, hi_x)
    ax.set_ylim(y - 0.2, -0.2)
    ax.axvline(1.0, color="0.35", lw=0.8, zorder=1)
    shown = set()
    for yi, claim, row in rows:
        target = claim_target(claim, row)
        verdict = typeset(row["verdict"])
        med = float(row["reproduced"])
        label = claim_label(claim["id"])
        grey = not math.isfinite(med) or target.value is None
        ax.text(-0.02, yi, label, transform=ax.get_yaxis_transform(), ha="right",
                va="center", fontsize=10, color="0.45" if grey else "black")
        if grey:
            why = "not testable" if verdict == "not testable" else "no figure"
            ax.text(1.0, yi, f"  {why}", va="center", fontsize=10, color="0.45",
                    style="italic")
            continue
        band = (max(target.band[0], lo_x / 10), min(target.band[1], hi_x * 10))
        ax.fill_betweenx([yi - 0.42, yi + 0.42], *band, color="#d8ecd9", lw=0, zorder=0)
        if target.kind == "bound":
            ax.plot([1, 1], [yi - 0.38, yi + 0.38], color="black", lw=2.4, zorder=2)
        elif target.kind == "published":
            ax.plot(1, yi, "D", mfc="white", mec="black", ms=7, mew=1.3, zorder=3)
        colour = VERDICT_COLOURS.get(verdict, "#000000")
        lo, hi = float(row["ci_low"]) / target.value, float(row["ci_high"]) / target.value
        if math.isfinite(lo) and math.isfinite(hi) and hi > lo:
            ax.plot([lo, hi], [yi, yi], color=colour, lw=2.4, solid_capstyle="butt", zorder=4)
        ax.plot(med / target.value, yi, VERDICT_MARKERS.get(verdict, "o"), color=colour,
                mec="white", mew=0.8, ms=9, zorder=5)
        shown.add(verdict)
    for yg, paper in groups:
        ax.text(0.01, yg + 0.05, PAPER_NAMES.get(paper, paper),
                transform=blended_transform_factory(fig.transFigure, ax.transData),
                ha="left", va="center", fontsize=10, fontweight="bold")
        if yg > 0:
            ax.axhline(yg - 0.25, color="0.75", lw=0.8)
    ax.set_yticks([])
    ticks = [0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.set_xticklabels([f"{t:g}" for t in ticks], fontsize=10)
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("reproduced ÷ target (published figure, bound or no effect; log scale)",
                  fontsize=10)
    ax.grid(axis="x", color="0.9", lw=0.6)
    ax.set_axisbelow(True)
    handles = [Line2D([], [], color=VERDICT_COLOURS[v], marker=VERDICT_MARKERS[v], ms=8,
                      lw=2.2, label=v) for v in VERDICTS if v in shown]
    handles += [
        Line2D([], [], color="black", marker="D", mfc="white", lw=0, label="published"),
        Line2D([], [], color="black", marker="|", ms=12, mew=2.4, lw=0, label="bound"),
        Patch(color="#d8ecd9", label="accepted"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=10, frameon=False,
               bbox_to_anchor=(0.5, 0.0), handlelength=1.6, columnspacing=1.2)
    fig.subplots_adjust(bottom=0.9 / (1.2 + 0.3 * y))
    ax.set_position((0.36, 0.95 / (1.2 + 0.3 * y), 0.61, (0.3 * y) / (1.2 + 0.3 * y)))
    out = write_figure(fig, path, dpi=150)
    n_grey = sum(1 for _, _, r in rows if not math.isfinite(float(r["reproduced"])))
    alt = (
        f"Forest plot of {len(rows)} claims grouped by paper on one log axis, reproduced "
        "median divided by its target (the published figure, the bound, or no effect), with "
        "its 95 % interval, marker shape and colour by verdict, the accepted region shaded "
        f"green around 1; {n_grey} claims without a reproduced figure are grey rows."
    )
    return out, alt


def headline(res: pd.DataFrame, total: int) -> str:
    """One sentence of the verdict counts: "Of the 18 claims, 7 are reproduced, ..."."""
    counts = Counter(typeset(v) for v in res["verdict"])
    parts = [f"{counts[v]} {v}" for v in VERDICTS if counts.get(v)]
    pending = total - len(res)
    if pending > 0:
        parts.append(f"{pending} pending")
    text = ", ".join(parts[:-1]) + f" and {parts[-1]}" if len(parts) > 1 else parts[0]
    return (f"Of the {total} claims of the four papers, checked over Monte Carlo trials on "
            f"synthetic data: {text}.")


def claim_sentence(claim, row: pd.Series | None) -> str:
    """One plain sentence on a claim's result: published against reproduced and what the
    verdict means, or why it is not testable."""
    name = claim_label(claim["id"])
    name = name[0].upper() + name[1:]
    if row is None:
        return f"{name}: not computed yet."
    verdict = typeset(row["verdict"])
    if verdict == "not testable":
        why = re.split(r"[:;(]", typeset(row["note"]))[0].strip() or "see the notebook"
        return f"{name}: not testable, {why}."
    unit = UNIT_LABELS.get(typeset(row["unit"]), typeset(row["unit"]))
    target = claim_target(claim, row)
    rep = f"{_number(row['reproduced'])} {unit} (95 % interval {_number(row['ci_low'])} to " \
          f"{_number(row['ci_high'])}, median of {int(row['n'])} trials)"
    if target.kind == "bound":
        sign = "at least" if target.band[1] == math.inf else "at most"
        against = f"the bound is {sign} {target.value:g} {unit}; reproduced {rep}"
    elif target.kind == "published":
        shown = _published(claim, row).text.removesuffix(typeset(row["unit"])).strip()
        against = f"published {shown} {unit}, reproduced {rep}"
    else:
        against = f"the paper gives no figure; reproduced {rep}, against 1 for no effect"
    if target.kind == "bound":
        meaning = {
            "reproduced": "it meets the bound in 95 % of the trials",
            "direction only": "the median meets the bound, the 95th percentile does not",
            "not reproduced": "it misses the bound",
        }.get(verdict, verdict)
    else:
        meaning = {
            "reproduced": "a significant effect within the accepted band",
            "direction only": "a significant effect in the paper's direction, outside the band",
            "not reproduced": "no significant effect in the paper's direction",
        }.get(verdict, verdict)
    rate = percent(row["replication_rate"])
    single = f"; {rate} of single reruns go the paper's way" if rate else ""
    return f"{name}: {against}, {meaning}{single}."


def verdict_box(paper: str, reg: pd.DataFrame, computed: dict) -> str:
    """The HTML box a chapter opens with: per claim its verdict badge and one sentence."""
    group = reg[reg["paper"] == paper]
    items = []
    for _, claim in group.iterrows():
        row = computed.get(claim["id"])
        verdict = PENDING if row is None else typeset(row["verdict"])
        items.append(f"<li>{_badge(verdict)} {html.escape(claim_sentence(claim, row))}</li>")
    items = "".join(items)
    return (f'<div class="verdict-box"><p class="verdict-box-title">The verdicts of this '
            f'paper\'s {len(group)} claims</p><ul>{items}</ul></div>')


#: Paper -> (notebook, figure of results/<notebook>/ that opens its chapter, its caption).
KEY_FIGURES = {
    "hybrid": ("01_hybrid_global_calibration", "handeye_methods",
               "Hand-eye error by method, RMS over the trials, in the station and with sensor "
               "noise only: the paper's sphere method, maximum likelihood (ML), the Cramér-Rao "
               "bound (CRB), the null control and OpenCV's five solvers."),
    "selfcal": ("03_selfcal_one_step_identification", "basin",
                "Basin of convergence of the one-step identification: the share of trials that "
                "reach the same solution, and that do so within 4 iterations, against the "
                "distance of the start from the truth."),
    "binocular": ("04_binocular_correction", "rmse_summary",
                  "RMSE with / without each correction step: the paper's ratio (star) and the "
                  "simulation's median with its 95 % interval, for each table of the paper and "
                  "its oracle."),
    "dualarm": ("05_dualarm_global_calibration", "error_budget",
                "Error budget of the global calibration with coded markers: the mean "
                "sphere-centre error per trial (median over the trials) with every error "
                "source, with each source alone and with none."),
}


def chapter_fragment(paper: str, reg: pd.DataFrame, res: pd.DataFrame | None,
                     book_dir: Path, results_dir: Path) -> str:
    """The MyST text a chapter includes at its top: the verdict box and the paper's key figure
    with a numbered caption (``fig-<paper>-key``), copied beside the page as
    ``key-<paper>.png``."""
    computed = {} if res is None else {r["id"]: r for _, r in res.iterrows()}
    lines = [verdict_box(paper, reg, computed), ""]
    key = KEY_FIGURES.get(paper)
    if key is not None and (results_dir / key[0] / f"{key[1]}.png").is_file():
        stem, name, caption = key
        dest = book_dir / f"key-{paper}.png"
        _copy(results_dir / stem / f"{name}.png", dest)
        lines += [f"```{{figure}} {dest.name}", f":name: fig-{paper}-key",
                  f":alt: {caption}", ":width: 100%", "",
                  f"{caption} (Notebook {stem.split('_')[0]}.)", "```", ""]
    return "\n".join(lines)


def render_claims_page(
    out_path: str | Path,
    register: str | Path | None = None,
    results: str | Path | None = None,
    figures: str | Path | None = None,
) -> Path:
    """Write the MyST page summarising every claim and its verdict, and the fragments the
    other pages include.

    Beside the page it writes the forest plot (:data:`FIGURE_NAME`), copies of the register
    and the results table (:data:`REGISTER_COPY`, :data:`RESULTS_COPY`), which the page offers
    for download, the intro's headline (:data:`HEADLINE_NAME`) and each paper chapter's
    opening (``verdicts-<paper>.md`` and its key figure ``key-<paper>.png``).

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
    figures : str or pathlib.Path, optional
        The folder of the notebooks' result folders the chapters' key figures are copied
        from (:data:`KEY_FIGURES`); default the folder of ``results``.

    Returns
    -------
    pathlib.Path
        ``out_path``.
    """
    out_path = Path(out_path)
    book_dir = out_path.parent
    book_dir.mkdir(parents=True, exist_ok=True)
    reg_path = DATA_DIR / "claims.csv" if register is None else Path(register)
    reg = claim_register(reg_path)
    res_path = RESULTS_DIR / "claims.csv" if results is None else Path(results)
    res = read_results(res_path) if res_path.is_file() else None
    computed = {} if res is None else {r["id"]: r for _, r in res.iterrows()}

    toc_path = book_dir / "_toc.yml"
    toc = _toc_files(yaml.safe_load(toc_path.read_text())) if toc_path.is_file() else set()

    counts = Counter(res["verdict"]) if res is not None else Counter()
    counts[PENDING] = sum(1 for i in reg["id"] if i not in computed)
    badges = " ".join(
        f"{_badge(v)} {counts.get(v, 0)}" for v in (*VERDICTS, PENDING) if counts.get(v, 0)
    )
    _copy(reg_path, book_dir / REGISTER_COPY)
    lines = [
        "# Claims and verdicts",
        "",
        f'<p class="verdict-counts"><strong>{len(reg)} claims:</strong> {badges}</p>',
        "",
        *_table(reg, computed, toc, book_dir),
        "",
        "Published and reproduced figures in the unit shown (≤ or ≥: the bound a claim is",
        "judged against); reproduced: median over the trials with its 95 % interval;",
        "replic.: share of trials with the paper's direction. A claim's name opens its",
        "statement and note.",
        f"Tables: {{download}}`data/claims.csv <{REGISTER_COPY}>`"
        + (f", {{download}}`results/claims.csv <{RESULTS_COPY}>`." if res is not None else "."),
        "",
    ]
    if res is not None and len(res):
        _copy(res_path, book_dir / RESULTS_COPY)
        figure, alt = claims_figure(res, book_dir / FIGURE_NAME, reg)
        lines += [
            f"```{{figure}} {figure.name}",
            ":name: fig-claims-forest",
            f":alt: {alt}",
            ":width: 100%",
            "",
            "Every claim on one axis: the reproduced median divided by its target (the "
            "published figure, the bound, or 1 for no effect) with its 95 % interval; "
            "marker and colour give the verdict, the shaded band is what the rule accepts for "
            "the median (a bound asks the 95th percentile to meet it too).",
            "```",
            "",
        ]
    maps = read_maps(res_path.parent)
    if len(maps):
        grid, grid_alt = grid_figure(maps, book_dir / GRID_NAME, VERDICT_COLOURS)
        lines += [
            f"```{{figure}} {grid.name}",
            ":name: fig-claims-robustness",
            f":alt: {grid_alt}",
            ":width: 100%",
            "",
            "Robustness of the verdicts: each claim with a map against the inputs it was "
            "screened on (assumed inputs over their plausible range, calibrated ones over their "
            "calibration's uncertainty); a cell shows the verdicts the claim takes over that "
            "input's range, in stripes when it takes more than one. Blank: the claim's "
            "computation does not read the input.",
            "```",
            "",
        ]
    cites = ", ".join(f"*{title}* {{cite:p}}`{key}`" for title, key in PAPERS.values())
    lines += [
        ":::{admonition} How a verdict is computed",
        ":class: dropdown",
        "",
        _RULE.rstrip(),
        "",
        f"The papers: {cites}.",
        ":::",
        "",
    ]
    _write(out_path, "\n".join(lines).rstrip("\n") + "\n")
    total = len(reg)
    head = headline(res, total) if res is not None and len(res) else (
        f"None of the {total} claims has been computed yet.")
    intro = [head, ""]
    if res is not None and len(res):
        intro += [f"```{{figure}} {FIGURE_NAME}", ":name: fig-intro-forest",
                  f":alt: {alt}", ":width: 100%", "",
                  "The claims on one axis (the {doc}`claims` page gives the figures).", "```",
                  ""]
    _write(book_dir / HEADLINE_NAME, "\n".join(intro))
    for paper in PAPERS:
        _write(book_dir / f"verdicts-{paper}.md",
               chapter_fragment(paper, reg, res, book_dir,
                                Path(figures) if figures is not None else res_path.parent))
    return out_path


#: The intro's headline sentence and forest plot, written beside the claims page.
HEADLINE_NAME = "claims-headline.md"


def _write(path: Path, text: str) -> None:
    atomic_write(path, lambda tmp: tmp.write_text(text))


def _copy(src: Path, dest: Path) -> None:
    if src.resolve() != dest.resolve():
        atomic_write(dest, lambda tmp: shutil.copyfile(src, tmp))


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
