"""Cells of the claims page that are computed, not typed: the published figure in the unit of
the reproduced one, and the notebook section where a claim is judged.

The claims register (``data/claims.csv``) transcribes what a paper prints, in the paper's unit:
``0.049 -> 0.041`` mm for an RMSE before and after a correction. A notebook judges such a claim
by the ratio after / before, so :func:`published_figure` computes the published ratio from those
figures (0.041 / 0.049 = 0.837) and the page shows published and reproduced side by side in the
same unit. Where the paper gives no figure in that unit the cell says why.

:func:`judged_in` finds the section of an executed notebook that holds the experiment behind a
claim (:data:`JUDGED_IN`) and returns the anchor Sphinx gives that heading, so the page links to
the section itself rather than to the top of the notebook.
"""

from __future__ import annotations

import json
import math
import re
import unicodedata
from dataclasses import dataclass
from pathlib import Path

#: Badge and figure colour of each verdict, and of a claim still pending (the CSS classes in
#: book/_static/calstudy.css).
VERDICT_COLOURS = {
    "reproduced": "#1a7f37",
    "direction only": "#b35900",
    "not reproduced": "#c62828",
    "not testable": "#57606a",
    "pending": "#8c959f",
}
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?")
_LEADING_NUMBER = re.compile(r"^\s*([-+]?\d+(?:\.\d+)?)(?:\s*-\s*(\d+(?:\.\d+)?))?(.*)$")
_UNICODE = (
    (r"\+-", "±"),
    (r"(?<=\d)\s?um\b", " µm"),
    (r"<=", "≤"),
    (r">=", "≥"),
    (r"->", "→"),
    (r"(?<=\d) x (?=\S)", " × "),
    (r"^x (?=[A-Z])", "× "),
    (r"\bCramer\b", "Cramér"),
    (r"\bsqrt\((\w+)\)", r"√\1"),
)


def typeset(text: object) -> str:
    """Plain text with ``+-``, ``um``, ``<=``, ``>=``, ``->`` and ``3 x`` written as
    ± µm ≤ ≥ → ×; an empty string for None or NaN."""
    s = "" if text is None or (isinstance(text, float) and math.isnan(text)) else str(text)
    for pattern, repl in _UNICODE:
        s = re.sub(pattern, repl, s)
    return s.strip()


def published_value(text: object) -> tuple[float, float] | None:
    """The figure a text starts with as ``(low, high)`` (equal unless a range ``"2-4"``), or
    None if the text does not start with a number."""
    m = _LEADING_NUMBER.match(typeset(text).replace("±", "+-"))
    if not m:
        return None
    low = float(m.group(1))
    return low, float(m.group(2)) if m.group(2) else low


def is_ratio(unit: object) -> bool:
    """True for the units of a paired ratio: ``ratio``, ``RMS ratio``, ``field error ratio``."""
    u = typeset(unit)
    return u == "ratio" or u.endswith(" ratio")


def _sig(x: float) -> str:
    """Three significant digits, trailing zeros kept (0.150, not 0.15)."""
    return f"{x:#.3g}".rstrip(".")


@dataclass(frozen=True)
class Published:
    """The published figure of one claim, as the claims page shows it.

    Attributes
    ----------
    value : tuple of float or None
        ``(low, high)`` in the unit of the reproduced figure (equal unless a range); None
        when the paper gives no figure in that unit.
    text : str
        The cell's main line: the figure and its unit, or why there is none.
    detail : str
        A second line: the paper's figures a ratio is computed from, or the bound the claim is
        judged against ("" if none).
    """

    value: tuple[float, float] | None
    text: str
    detail: str = ""


def ratio_of(text: object) -> tuple[float, str] | None:
    """The ratio after / before that a published text states, with the figures it is made of.

    ``"0.049 -> 0.041"`` gives 0.041 / 0.049; several values on each side (``"0.064 / 0.063
    -> 0.055 / 0.054"``, or ``;``-separated groups with a label before a colon) give mean after
    / mean before; ``"0.100 vs 0.556"`` gives 0.100 / 0.556. Text in parentheses is ignored.

    Returns
    -------
    tuple of (float, str) or None
        The ratio and its formula ("0.041 / 0.049", or "mean 0.0740 / mean 0.492 of 4"); None
        if the text is neither form.
    """
    s = re.sub(r"\([^)]*\)", "", typeset(text))
    before, after = [], []
    if "→" in s:
        for group in s.split(";"):
            group = group.split(":", 1)[1] if ":" in group else group
            if "→" not in group:
                return None
            left, right = group.split("→", 1)
            before += _NUMBER.findall(left)
            after += _NUMBER.findall(right)
    elif " vs " in s:
        left, right = s.split(" vs ", 1)
        after, before = _NUMBER.findall(left)[:1], _NUMBER.findall(right)[:1]
    if not before or len(before) != len(after):
        return None
    a = sum(map(float, after)) / len(after)
    b = sum(map(float, before)) / len(before)
    if b == 0:
        return None
    if len(before) == 1:
        formula = f"{after[0]} / {before[0]}"
    else:
        formula = f"{_sig(a)} / {_sig(b)} (means of {len(before)})"
    return a / b, formula


def _reference(claim) -> str:
    """The register's reference without its parenthetical remark."""
    return re.sub(r"\s*\([^)]*\)\s*$", "", typeset(claim.get("reference", ""))).strip()


def _bound(claim) -> str:
    """``"bound ≤ 3 × CRB RMS"`` from the register's reference of a bound claim, else ""."""
    reference = _reference(claim)
    if typeset(claim.get("kind", "")) != "bound" or not reference:
        return ""
    sign = "≥" if typeset(claim.get("direction", "")) == "higher" else "≤"
    return f"bound {sign} {reference}"


def bound_value(claim) -> float | None:
    """The number of a bound claim's reference when it is a plain multiple or value
    (``"3 x CRB RMS"`` -> 3.0), else None (``"1.36/sqrt(n)"`` depends on the trial)."""
    reference = _reference(claim)
    if typeset(claim.get("kind", "")) != "bound":
        return None
    m = re.match(r"^(\d+(?:\.\d+)?)(?:\s+\S.*)?$", reference)
    return float(m.group(1)) if m else None


def published_figure(claim, unit: object) -> Published:
    """The published figure of a register row ``claim`` in the reproduced figure's ``unit``.

    Parameters
    ----------
    claim : mapping
        A row of ``data/claims.csv`` (``published``, ``unit``, ``kind``, ``direction``,
        ``reference``).
    unit : str
        Unit of the reproduced figure (``results/claims.csv``).

    Returns
    -------
    Published
        The figure in ``unit``: the paper's own when the units agree, the ratio after / before
        computed from the paper's figures when the claim is judged as a ratio; otherwise no
        value and a text saying why.
    """
    text, unit = typeset(claim.get("published", "")), typeset(unit)
    paper_unit = typeset(claim.get("unit", ""))
    bound = _bound(claim)
    if not text:
        reference = typeset(claim.get("reference", ""))
        why = bound or (
            f"judged against {reference}" if reference else "the claim states a method only"
        )
        return Published(None, "none in the paper", why)
    if is_ratio(unit) and not is_ratio(paper_unit):
        ratio = ratio_of(text)
        if ratio is not None:
            value, formula = ratio
            if formula.endswith(")"):
                head, _, tail = formula.partition(" (")
                detail = f"{head} {paper_unit} ({tail}"
            else:
                detail = f"{formula} {paper_unit}"
            return Published((value, value), f"{_sig(value)} {unit}", detail)
    elif paper_unit == unit and (value := published_value(text)) is not None:
        m = _LEADING_NUMBER.match(text.replace("±", "+-"))
        shown = m.group(1) if not m.group(2) else f"{m.group(1)}–{m.group(2)}"
        if typeset(claim.get("kind", "")) == "bound":
            sign = "≥" if typeset(claim.get("direction", "")) == "higher" else "≤"
            shown = f"{sign} {shown}"
        return Published(value, f"{shown} {unit}")
    first = published_value(text)
    paper = f"{first[0]:g} {paper_unit}" if first else text
    why = f"paper: {paper}"
    return Published(None, f"none in {unit}", f"{why}; {bound}" if bound else why)


# ----------------------------------------------------------------------------------------------
# where a claim is judged

#: Claim id -> words of the heading of the notebook section that holds its experiment (matched
#: case-insensitively against the headings; the first match wins). A claim not listed, or whose
#: words match no heading, links to the notebook's "Claims" section.
JUDGED_IN = {
    "hybrid.handeye": "flexible sensor",
    "hybrid.stationary": "stationary sensors",
    "hybrid.rps": "workpiece frame",
    "hybrid.systematic": "before compensation",
    "hybrid.deviation": "offset compensation",
    "hybrid.correlation": "offset compensation",
    "selfcal.identification": "monte carlo",
    "selfcal.convergence": "convergence",
    "selfcal.robot_params": "identified robot parameters",
    "selfcal.residual": "residual errors",
    "selfcal.one_step": "monte carlo",
    "binocular.coc": "table 2",
    "binocular.observed_error": "table 3",
    "binocular.transformation": "table 4",
    "binocular.field": "table 5",
    "dualarm.icp": "icp",
    "dualarm.global": "global calibration:",
    "dualarm.vs_circular": "circular calibration plate",
}


def section_id(title: str) -> str:
    """The HTML id Sphinx gives a section headed ``title`` (docutils' ``make_id``): lower case,
    runs of other characters as one hyphen, no leading digits or hyphens."""
    text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", title)
    text = unicodedata.normalize("NFKD", text.lower()).encode("ascii", "ignore").decode()
    text = re.sub(r"[^a-z0-9]+", "-", text)
    return re.sub(r"^[^a-z]+", "", text).rstrip("-")


def headings(notebook: str | Path) -> list[tuple[int, str]]:
    """``(level, title)`` of every markdown heading of a notebook, in order (not the title)."""
    nb = json.loads(Path(notebook).read_text(encoding="utf-8"))
    found = []
    for cell in nb.get("cells", []):
        if cell.get("cell_type") != "markdown":
            continue
        source = cell.get("source", "")
        source = "".join(source) if isinstance(source, list) else source
        fenced = False
        for line in source.splitlines():
            if line.lstrip().startswith(("```", "~~~")):
                fenced = not fenced
            m = re.match(r"^(#{2,6})\s+(.+?)\s*#*\s*$", line)
            if m and not fenced:
                found.append((len(m.group(1)), m.group(2)))
    return found


def judged_in(claim_id: str, notebook: str | Path) -> tuple[str, str] | None:
    """``(anchor, heading)`` of the section of ``notebook`` where ``claim_id`` is judged, or
    None if the notebook has no such section (nor a "Claims" section)."""
    titles = [t for _, t in headings(notebook)] if Path(notebook).is_file() else []
    plain = [re.sub(r"[`*]", "", t).strip() for t in titles]
    bare = [re.sub(r"^\d+\.\s*", "", p).lower() for p in plain]
    words = JUDGED_IN.get(claim_id)
    tests = [lambda b: b == "claims"]
    if words:
        # a heading that starts with the words, then one that holds them, then "Claims"
        tests = [lambda b: b.startswith(words), lambda b: words in b, *tests]
    for test in tests:
        for title, shown, b in zip(titles, plain, bare, strict=True):
            if test(b):
                return section_id(title), shown
    return None
