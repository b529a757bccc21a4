"""Verdicts of the claims register and the rows that carry them.

A claim is judged from its register row (``data/claims.csv``: kind and direction) and the
columns of a table of trials that carry its figure, its paired baseline and its two controls
(:class:`ClaimColumns`, one declaration per claim in its paper's report module):
:func:`judge_claim` applies the v2 rule (:func:`calstudy.core.verdicts.judge`, the controls and
the oracle gate), :func:`null_gate` records a claim whose null control passes as not testable,
:func:`judge_along` applies the rule at each point of a sweep (where its verdict changes:
:func:`calstudy.core.robustness.verdict_changes`). :func:`claim_row` and :func:`control_rows`
turn a verdict into the rows of ``claims.csv`` and ``controls.csv``.
Notebooks never type a verdict in. Writing the rows to files is :mod:`calstudy.io.results`.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError, TooFewTrials
from calstudy.core.paths import DATA_DIR
from calstudy.core.verdicts import Verdict as RuleVerdict
from calstudy.core.verdicts import (
    check_null_control,
    judge,
    judge_controls,
    judge_rms_ratio,
    not_testable,
    oracle_gate,
)

#: The four verdicts of the claims register, in the order the book counts them.
VERDICTS = ("reproduced", "direction only", "not reproduced", "not testable")

#: Where a claim's criterion comes from (column ``criterion`` of ``data/claims.csv``): the paper's
#: own figure or requirement, or the study's (rule 15), with ``criterion_source`` saying where in
#: the paper, or why the study's.
CRITERIA = ("published", "study")

CLAIM_COLUMNS = (
    "id",
    "published",
    "criterion",
    "reproduced",
    "ci_low",
    "ci_high",
    "unit",
    "n",
    "replication_rate",
    "verdict",
    "null_control",
    "oracle_control",
    "notebook",
    "note",
)

#: Columns of ``results/<notebook>/controls.csv``: the null and oracle control of each claim.
CONTROL_COLUMNS = (
    "id",
    "control",
    "definition",
    "reproduced",
    "ci_low",
    "ci_high",
    "n",
    "replication_rate",
    "verdict",
    "note",
)

# ----------------------------------------------------------------------------------------------
# claim rows


@dataclass
class ClaimRow:
    """One row of ``results/<notebook>/claims.csv``.

    Attributes
    ----------
    id : str
        Claim id, exactly as in ``data/claims.csv``.
    published : str
        The paper's figure as text (``""`` if the paper gives none).
    reproduced : float
        The reproduced figure (NaN for ``"not testable"``).
    ci_low, ci_high : float
        Its 95 % interval over Monte Carlo trials.
    unit : str
        Unit of ``published`` and ``reproduced`` (``"ratio"``, ``"mm"``, ``"%"``, ...).
    verdict : str
        One of :data:`VERDICTS`.
    notebook : str
        Stem of the notebook that computed it.
    note : str
        One short line: why this verdict.
    n : int
        Trials the verdict rests on (0: not computed from trials).
    replication_rate : float
        Share of trials whose own effect has the claimed direction (NaN if not applicable).
    null_control, oracle_control : str
        Verdicts of the two controls of the v2 rule (empty where the claim has none).
    """

    id: str
    published: str
    reproduced: float
    ci_low: float
    ci_high: float
    unit: str
    verdict: str
    notebook: str
    note: str = ""
    n: int = 0
    replication_rate: float = float("nan")
    null_control: str = ""
    oracle_control: str = ""


class Judged(NamedTuple):
    """A claim's verdict after the oracle gate and its two controls (None where it has none)."""

    claim: RuleVerdict
    null: RuleVerdict | None = None
    oracle: RuleVerdict | None = None


@dataclass(frozen=True)
class ClaimColumns:
    """Which columns of a table of trials (one row per trial) carry one claim's figures.

    Attributes
    ----------
    figure : str
        The method's figure per trial (for a paired ratio: the numerator, after).
    baseline : str, optional
        The paired figure of the same trial without the method (before); ``""`` when the
        effect is the figure itself (against no effect or the stated reference).
    null, oracle : str, optional
        The null and the oracle control of rule 8 on the same trials; both or neither.
    mechanism : str, optional
        The error source the method targets, named in the note when the oracle control is not
        significant (required with the controls).
    pooled : bool, default False
        Judge a ``bound`` claim by the RMS of ``figure`` over the RMS of ``baseline`` pooled
        over the trials (:func:`calstudy.core.verdicts.judge_rms_ratio`) instead of the 95th
        percentile of a per-trial figure; the null control is then set against ``baseline``
        and the oracle control against ``oracle_baseline``.
    oracle_baseline : str, optional
        The rival's error in the oracle's simulation (pooled only; ``baseline`` if empty).
    """

    figure: str
    baseline: str = ""
    null: str = ""
    oracle: str = ""
    mechanism: str = ""
    pooled: bool = False
    oracle_baseline: str = ""

    def __post_init__(self) -> None:
        if bool(self.null) != bool(self.oracle) or bool(self.null) != bool(self.mechanism):
            raise CalibrationError(
                f"claim columns of {self.figure!r}: null {self.null!r}, oracle {self.oracle!r} "
                f"and mechanism {self.mechanism!r} go together (all three or none)"
            )
        if self.pooled and not self.baseline:
            raise CalibrationError(
                f"claim columns of {self.figure!r}: a pooled ratio needs its baseline column"
            )
        if self.oracle_baseline and not (self.pooled and self.oracle):
            raise CalibrationError(
                f"claim columns of {self.figure!r}: oracle_baseline {self.oracle_baseline!r} "
                "applies only to a pooled claim with an oracle control"
            )


@lru_cache(maxsize=1)
def _rules() -> dict[str, tuple[str, str]]:
    register = claim_register().set_index("id")
    return {cid: (row["kind"], row["direction"]) for cid, row in register.iterrows()}


def claim_rule(claim_id: str) -> tuple[str, str]:
    """``(kind, direction)`` of a claim, from the register ``data/claims.csv``.

    Raises
    ------
    CalibrationError
        If the id is not in the register.
    """
    rules = _rules()
    if claim_id not in rules:
        raise CalibrationError(f"claim id {claim_id!r} is not in the claims register")
    return rules[claim_id]


def judge_claim(
    claim_id: str,
    trials: Mapping[str, object],
    columns: ClaimColumns,
    *,
    published: float | None = None,
    reference: float | None = None,
    min_trials: int = 200,
) -> Judged:
    """One claim by the v2 rule: its register row, the trial columns of ``columns``.

    The claim and its controls are judged on the same trials with the kind and direction of the
    register (:func:`calstudy.core.verdicts.judge_controls`); the claim's verdict is then gated
    by its oracle control (:func:`calstudy.core.verdicts.oracle_gate`).

    Parameters
    ----------
    claim_id : str
        Id in ``data/claims.csv``.
    trials : mapping of str to array_like of shape (N,)
        A table of trials (a DataFrame or a dict of columns), one value per trial in each
        column that ``columns`` names.
    columns : ClaimColumns
        The claim's declaration.
    published : float, optional
        The paper's figure in the claim's unit (no size: significance alone decides).
    reference : float, optional
        The requirement of a ``bound`` claim, or the stated reference of a ``value`` or
        ``percent`` claim without baseline.
    min_trials : int, default 200
        Rule 1 (30 at a sweep point): fewer trials are named in the note.

    Returns
    -------
    Judged
        The claim's verdict after the oracle gate, the null and the oracle control (None for a
        claim without controls).

    Raises
    ------
    CalibrationError
        If the id is not in the register, a column is missing from ``trials``, or by the rule's
        own checks (:func:`calstudy.core.verdicts.judge`).
    """
    kind, direction = claim_rule(claim_id)
    if columns.pooled:
        return _judge_pooled(claim_id, trials, columns, kind, direction, reference, min_trials)
    rule: dict = {"kind": kind, "direction": direction, "min_trials": min_trials}
    if reference is not None:
        rule["bound" if kind == "bound" else "null"] = reference
    if columns.baseline:
        rule["baseline"] = _column(trials, columns.baseline, claim_id)
    figure = _column(trials, columns.figure, claim_id)
    if not columns.null:
        return Judged(judge(figure, published=published, **rule))
    claim, null, oracle = judge_controls(
        figure,
        _column(trials, columns.null, claim_id),
        _column(trials, columns.oracle, claim_id),
        published=published,
        **rule,
    )
    return Judged(oracle_gate(claim, oracle, columns.mechanism), null, oracle)


def null_gate(judged: Judged) -> Judged:
    """A claim judged ``not testable`` where its null control does not come out ``not
    reproduced`` (rule 8 read for a paper that records such a claim rather than refusing it: the
    test cannot tell the method from its null control there); the controls as they came out.

    Parameters
    ----------
    judged : Judged
        The claim (after its oracle gate) and its controls, with a null control.

    Returns
    -------
    Judged
        ``judged`` itself when the null control comes out ``not reproduced``; else the claim
        :func:`~calstudy.core.verdicts.not_testable` with its kind and N, the note naming the
        null control's verdict and the claim's own.

    Raises
    ------
    CalibrationError
        If ``judged`` has no null control.
    """
    claim, null, oracle = judged
    if null is None:
        raise CalibrationError(f"a null gate needs a null control; {claim.note!r} has none")
    if null.verdict == "not reproduced":
        return judged
    reason = (
        f"the null control comes out {null.verdict} ({null.note}): the test cannot tell the "
        f"method from its null control here (the claim alone came out {claim.verdict})"
    )
    return Judged(not_testable(reason, kind=claim.kind, n=claim.n), null, oracle)


def _judge_pooled(claim_id, trials, columns, kind, direction, bound, min_trials) -> Judged:
    """:func:`judge_claim` for ``columns.pooled``: the RMS ratios of the claim and its controls
    (:func:`calstudy.core.verdicts.judge_rms_ratio`), the claim gated by its oracle."""
    if kind != "bound" or bound is None:
        raise CalibrationError(
            f"{claim_id}: a pooled RMS ratio is judged against a bound (register kind 'bound' "
            f"and reference); the register says kind {kind!r}, reference {bound!r}"
        )
    rule = {"bound": bound, "direction": direction, "min_trials": min_trials}
    base = _column(trials, columns.baseline, claim_id)
    claim = judge_rms_ratio(_column(trials, columns.figure, claim_id), base, **rule)
    if not columns.null:
        return Judged(claim)
    null = judge_rms_ratio(_column(trials, columns.null, claim_id), base, **rule)
    oracle_base = _column(trials, columns.oracle_baseline or columns.baseline, claim_id)
    oracle = judge_rms_ratio(_column(trials, columns.oracle, claim_id), oracle_base, **rule)
    return Judged(oracle_gate(claim, oracle, columns.mechanism), null, oracle)


def _column(trials: Mapping[str, object], name: str, claim_id: str) -> np.ndarray:
    if name not in trials:
        raise CalibrationError(
            f"{claim_id}: the trials have no column {name!r}; they have {sorted(map(str, trials))}"
        )
    return np.asarray(trials[name], dtype=float)


def judge_along(
    trials: pd.DataFrame,
    by: str | list[str],
    claim_id: str,
    columns: ClaimColumns,
    *,
    min_trials: int = 30,
    **figures: float | None,
) -> list[tuple[Hashable, pd.DataFrame, Judged | None]]:
    """The v2 rule at each point of a sweep: :func:`judge_claim` on each point's own trials.

    Parameters
    ----------
    trials : pandas.DataFrame
        One row per trial and sweep point, with the columns of ``columns``.
    by : str or list of str
        The swept input(s): one point per value (per combination), in ascending order.
    claim_id, columns
        As for :func:`judge_claim`.
    min_trials : int, default 30
        Rule 1 at a sweep point.
    **figures
        ``published`` and ``reference`` of :func:`judge_claim`.

    Returns
    -------
    list of (value, pandas.DataFrame, Judged or None)
        Per point: the value of ``by``, its trials, and the verdicts, or None where the point
        has too few trials for a 95 % interval of the median.
    """
    out = []
    for value, sub in trials.groupby(by, sort=True):
        judged = verdict_or_none(
            lambda s=sub: judge_claim(claim_id, s, columns, min_trials=min_trials, **figures)
        )
        out.append((value, sub, judged))
    return out


#: What a sweep table says at a point with too few trials for a 95 % interval of the median.
TOO_FEW = "too few trials"


def verdict_text(judged: Judged | None) -> str:
    """The verdict of a sweep point as its table writes it: the claim's verdict, or
    :data:`TOO_FEW` where the point has too few trials (``judged`` None, as
    :func:`verdict_or_none` and :func:`judge_along` give it)."""
    return TOO_FEW if judged is None else judged.claim.verdict


def verdict_or_none(make):
    """``make()``, or None when there are too few trials for an interval of the median (or of
    a pooled RMS ratio).

    Parameters
    ----------
    make : callable
        Takes no argument and judges (for example a sweep point with a handful of trials).

    Returns
    -------
    object or None
        What ``make`` returns; None when it refused for too few trials (written
        :data:`TOO_FEW` in a table).

    Raises
    ------
    CalibrationError
        Any other refusal of ``make``.
    """
    try:
        return make()
    except TooFewTrials:
        return None


def claim_row(
    claim_id: str,
    judged: Judged,
    *,
    published: str,
    unit: str,
    notebook: str,
    note: str | None = None,
) -> ClaimRow:
    """The claims-table row of a verdict of the v2 rule (:func:`judge_claim`).

    Parameters
    ----------
    claim_id : str
        Id in ``data/claims.csv``.
    judged : Judged
        The claim's verdict and its controls: ``reproduced``/``ci_low``/``ci_high`` are the
        median over trials and its 95 % confidence interval; the controls' verdicts go in the
        row, their figures in ``controls.csv`` (see :func:`control_rows`).
    published, unit : str
        The paper's figure as text and the unit of the reproduced figure.
    notebook : str
        Stem of the notebook that computed it.
    note : str, optional
        Replaces the verdict's own note (which it usually quotes).

    Returns
    -------
    ClaimRow
    """
    verdict, null, oracle = judged
    controls = {
        "null_control": "" if null is None else null.verdict,
        "oracle_control": "" if oracle is None else oracle.verdict,
    }
    return ClaimRow(
        claim_id,
        published,
        verdict.median,
        verdict.ci_low,
        verdict.ci_high,
        unit,
        verdict.verdict,
        notebook,
        verdict.note if note is None else note,
        verdict.n,
        verdict.replication_rate,
        **controls,
    )


def control_rows(claim_id: str, judged: Judged, *, refuse_passing_null: bool = True) -> list[dict]:
    """The rows of ``controls.csv`` for a claim, one per control it has (none for a claim
    without a null control), with the control definitions of the claims register (columns
    ``null_control`` and ``oracle_control`` of ``data/claims.csv``).

    ``refuse_passing_null=False`` is for a paper that already judged such a claim ``not
    testable`` (its null passed): the rows are then written as they came out.

    Raises
    ------
    CalibrationError
        If the null control is anything but ``not reproduced`` (the test is broken) and
        ``refuse_passing_null``, or the register defines no control for the claim.
    """
    _, null, oracle = judged
    if null is None:
        return []
    if refuse_passing_null:
        check_null_control(null)
    register = claim_register(columns=("null_control", "oracle_control")).set_index("id")
    if claim_id not in register.index:
        raise CalibrationError(f"claim id {claim_id!r} is not in the claims register")
    rows = []
    for control, v in (("null", null), ("oracle", oracle)):
        if v is None:
            continue
        definition = register.at[claim_id, f"{control}_control"]
        if not definition:
            raise CalibrationError(
                f"data/claims.csv defines no {control} control for {claim_id!r}; describe it in "
                f"the column {control}_control"
            )
        rows.append(
            {
                "id": claim_id,
                "control": control,
                "definition": definition,
                "reproduced": v.median,
                "ci_low": v.ci_low,
                "ci_high": v.ci_high,
                "n": v.n,
                "replication_rate": v.replication_rate,
                "verdict": v.verdict,
                "note": v.note,
            }
        )
    return rows


#: Columns every claims register has (``data/claims.csv``).
REGISTER_COLUMNS = (
    "id",
    "paper",
    "where",
    "statement",
    "published",
    "unit",
    "comparison",
    "kind",
    "direction",
    "reference",
    "null_control",
    "oracle_control",
    "criterion",
    "criterion_source",
)


def claim_register(
    register: str | Path | None = None, columns: tuple[str, ...] = ()
) -> pd.DataFrame:
    """The claims register ``data/claims.csv`` (or ``register``) as text, blanks as ``""``.

    Parameters
    ----------
    register : path-like, optional
        A register of one's own; ``data/claims.csv`` by default (which must have every column of
        :data:`REGISTER_COLUMNS`).
    columns : tuple of str, optional
        The columns the caller reads besides ``id``.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    CalibrationError
        Naming the file, if it is not a CSV table, lacks ``id`` or a column of ``columns``, or
        has an empty or repeated id; if a row's ``criterion`` is not one of :data:`CRITERIA` or
        has no ``criterion_source`` (no criterion of the study may pass for a published one).
    """
    path = DATA_DIR / "claims.csv" if register is None else Path(register)
    if not path.is_file():
        raise FileNotFoundError(f"claims register not found: {path.name}")
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (ValueError, UnicodeDecodeError) as exc:  # pandas' ParserError is a ValueError
        raise CalibrationError(f"claims register {path.name} is not a CSV table: {exc}") from None
    wanted = REGISTER_COLUMNS if register is None else ("id", *columns)
    missing = [c for c in dict.fromkeys(wanted) if c not in df.columns]
    if missing:
        raise CalibrationError(
            f"claims register {path.name} lacks the column(s) {missing}; its header is "
            f"{list(df.columns)}"
        )
    ids = df["id"]
    if (ids.str.strip() == "").any():
        raise CalibrationError(
            f"claims register {path.name}: row {int((ids.str.strip() == '').idxmax()) + 2} "
            "has an empty id"
        )
    if ids.duplicated().any():
        raise CalibrationError(
            f"claims register {path.name}: id {ids[ids.duplicated()].iloc[0]!r} appears more "
            "than once"
        )
    if "criterion" in df.columns:
        source = df.get("criterion_source", pd.Series("", index=df.index))
        rows = zip(ids, df["criterion"], source, strict=True)
        for line, (cid, crit, src) in enumerate(rows, start=2):
            if crit not in CRITERIA or not str(src).strip():
                raise CalibrationError(
                    f"claims register {path.name}: line {line} ({cid}): criterion {crit!r} must "
                    f"be one of {', '.join(CRITERIA)}, with criterion_source saying where in the "
                    "paper or why the study's"
                )
    return df


def claim_ids(register: str | Path | None = None) -> list[str]:
    """Ids of the claims register ``data/claims.csv`` (or ``register``), in file order."""
    return claim_register(register)["id"].tolist()
