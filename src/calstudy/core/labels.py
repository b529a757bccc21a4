"""Plain words for the identifiers a reader of the book would otherwise meet: claims, inputs and
table columns.

The library names a claim ``hybrid.handeye`` and an input ``translation_range_mm``; the book
says "hand-eye calibration" and "range of the pure translations (mm)". :data:`CLAIM_LABELS`
and :data:`INPUT_LABELS` hold the words; :func:`plain` rewrites a generated sentence and
:func:`label` one identifier (a column name or a table cell), falling back to a rule for
names not listed: underscores become spaces, ``0p3`` becomes 0.3, ``le``/``ge`` become ≤/≥,
``t2`` becomes "Table 2" and a unit suffix goes into parentheses.
"""

from __future__ import annotations

import functools
import re
import tomllib

from calstudy.core.paths import DATA_DIR

__all__ = [
    "CLAIM_LABELS",
    "INPUT_LABELS",
    "UNIT_SUFFIXES",
    "claim_label",
    "label",
    "plain",
    "scenario_tables",
]

#: Claim id -> a short noun phrase naming what the claim is about.
CLAIM_LABELS = {
    "hybrid.handeye": "hand-eye calibration",
    "hybrid.stationary": "stationary sensors",
    "hybrid.rps": "workpiece frame",
    "hybrid.systematic": "systematic error",
    "hybrid.deviation": "deviation after compensation",
    "hybrid.correlation": "correlation with the CMM",
    "selfcal.identification": "one-step identification",
    "selfcal.convergence": "convergence",
    "selfcal.robot_params": "robot parameters",
    "selfcal.residual": "residual error",
    "selfcal.one_step": "one step against three",
    "binocular.coc": "circle-of-confusion rectification",
    "binocular.observed_error": "observed-error modification",
    "binocular.transformation": "transformation correction",
    "binocular.field": "field distances",
    "dualarm.icp": "ICP correction",
    "dualarm.global": "global calibration",
    "dualarm.vs_circular": "coded markers vs a circular plate",
}

#: Input or column name -> its words (the unit suffix is added by :func:`label`).
INPUT_LABELS = {
    "translation_range_mm": "range of the pure translations",
    "across_plane_range_mm": "range across the laser plane",
    "part_sigma_mm": "part-to-part scatter",
    "feature_sigma_mm": "feature scatter",
    "drift_sigma_mm": "drift sigma",
    "repeatability_mm": "robot repeatability",
    "sensor_sigma_mm": "sensor noise",
    "within_0p3_pct": "within 0.3 mm",
    "n_trials": "trials",
    "n": "N",
}

#: Column-name suffixes read as units: ``rot_err_deg`` is shown as ``rot err (deg)``.
UNIT_SUFFIXES = {
    "mm": "mm",
    "um": "µm",
    "deg": "deg",
    "rad": "rad",
    "mrad": "mrad",
    "px": "px",
    "pct": "%",
    "percent": "%",
    "s": "s",
    "ms": "ms",
}

_CLAIM_ID = re.compile(r"\b(?:hybrid|selfcal|binocular|dualarm)\.[a-z][a-z0-9_]*\b")
#: A bare snake_case identifier (at least one underscore), not part of a file name or path.
_IDENT = re.compile(r"(?<![\w./-])[a-z][a-z0-9]*(?:_[a-z0-9]+)+(?![\w/]|\.\w)")
_WORDS = {"le": "≤", "ge": "≥", "lt": "<", "gt": ">", "pct": "%", "n": "N"}


def claim_label(claim_id: str) -> str:
    """The words of claim ``claim_id`` (the id itself if it has none)."""
    return CLAIM_LABELS.get(claim_id, claim_id)


def _token(tok: str) -> str:
    if re.fullmatch(r"\d+p\d+", tok):
        return tok.replace("p", ".")
    if re.fullmatch(r"t\d", tok):
        return f"Table {tok[1]}"
    return _WORDS.get(tok, tok)


def label(name: object, unit: str | None = None) -> str:
    """A column name or identifier as words: ``"within_0p3_pct"`` -> ``"within 0.3 mm (%)"``,
    ``"bin_le_0p1_pct"`` -> ``"bin ≤ 0.1 (%)"``, ``"t2_without_mm"`` -> ``"Table 2 without
    (mm)"``; a claim id -> its :data:`CLAIM_LABELS` entry; ``unit`` overrides the suffix.

    Parameters
    ----------
    name : object
        The identifier (anything else is returned as its text).
    unit : str, optional
        Unit to show in parentheses; default the one the name's suffix gives.

    Returns
    -------
    str
        The label.
    """
    text = str(name)
    if text in CLAIM_LABELS:
        return CLAIM_LABELS[text]
    words = INPUT_LABELS.get(text)
    if words is None:
        stem, _, suffix = text.rpartition("_")
        if unit is None and stem and suffix.lower() in UNIT_SUFFIXES:
            text, unit = stem, UNIT_SUFFIXES[suffix.lower()]
        words = INPUT_LABELS.get(text) or " ".join(
            _token(t) for t in text.replace("_", " ").split()
        )
    elif unit is None:
        suffix = text.rpartition("_")[2].lower()
        unit = UNIT_SUFFIXES.get(suffix) if "_" in text else None
    words = words.strip()
    return f"{words} ({unit})" if unit else words


#: a dotted name (``scanner.sigma_point_mm``, ``sensor.design_zyx_deg[1]``): rewritten when it is
#: a scenario input (:func:`scenario_tables`); single letters (``e.g.``), longer dotted names and
#: file names are left alone
_DOTTED = re.compile(
    r"(?<![\w./-])([a-z][a-z0-9_]+(?:\.[a-z][a-z0-9_]+)?)\.([a-z][A-Za-z0-9_]+)(\[\d+\])?"
    r"(?![\w/]|\.\w)"
)
#: endings of file names, not inputs
_FILE_ENDINGS = {"csv", "toml", "png", "json", "py", "ipynb", "md", "html", "yml", "yaml", "txt"}


@functools.cache
def scenario_tables() -> frozenset[str]:
    """The first parts of the dotted keys of the scenario files in ``data/``: each file's name
    (a scenario of several files prefixes its keys with it: ``station.sensor.sigma_point_mm``)
    and its top-level tables (``scanner.sigma_point_mm``).

    Returns
    -------
    frozenset of str
        The names; a dotted name whose first part is not one of them (``scipy.stats.ksone``) is
        not a scenario input.
    """
    names = set()
    for path in DATA_DIR.rglob("*.toml"):
        table = tomllib.loads(path.read_text(encoding="utf-8"))
        names |= {path.stem} | {key for key, value in table.items() if isinstance(value, dict)}
    return frozenset(names)


def _input_words(m: re.Match) -> str:
    table, name, index = m.group(1), m.group(2), m.group(3) or ""
    if name in _FILE_ENDINGS or table.split(".")[0] not in scenario_tables():
        return m.group(0)
    words = label(name)
    if index:
        stem, paren, unit = words.partition(" (")
        words = f"{stem} {index}{' (' + unit if paren else ''}"
    return f"{table.replace('_', ' ').replace('.', ' ')} {words}"


def plain(text: object) -> str:
    """A generated sentence with claim ids, scenario inputs by their dotted keys and bare
    snake_case identifiers as words: ``"hybrid.handeye against translation_range_mm: ..."`` ->
    ``"hand-eye calibration against range of the pure translations (mm): ..."``,
    ``"scanner.sigma_point_mm"`` -> ``"scanner sigma point (mm)"``; file names (``x_y.csv``)
    stay as they are."""
    s = _CLAIM_ID.sub(lambda m: claim_label(m.group(0)), str(text))
    s = _DOTTED.sub(_input_words, s)
    return _IDENT.sub(lambda m: label(m.group(0)), s)
