"""Verdicts of the claims register and the rows that carry them.

Verdicts follow the v2 rule of the claims register (reproduced / direction only / not
reproduced / not testable), computed from Monte Carlo trials by
:func:`calstudy.core.verdicts.judge` and its controls; this module turns them into the rows of
``claims.csv`` and ``controls.csv`` (:func:`claim_row`, :func:`control_rows`), checked against
the register ``data/claims.csv``. Notebooks never type a verdict in. Writing the rows to files is
:mod:`calstudy.io.results`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import DATA_DIR
from calstudy.core.verdicts import Verdict as RuleVerdict
from calstudy.core.verdicts import check_null_control

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


def claim_row(
    claim_id: str,
    verdict: RuleVerdict,
    *,
    published: str,
    unit: str,
    notebook: str,
    null: RuleVerdict | None = None,
    oracle: RuleVerdict | None = None,
) -> ClaimRow:
    """The claims-table row of a verdict of the v2 rule (:func:`calstudy.core.verdicts.judge`).

    ``reproduced``/``ci_low``/``ci_high`` are the median over trials and its 95 % confidence
    interval; ``null``/``oracle`` are the controls judged on the same trials (their verdicts go
    in the row, their figures in ``controls.csv``, see :func:`control_rows`).
    """
    controls = {
        "null_control": "" if null is None else null.verdict,
        "oracle_control": "" if oracle is None else oracle.verdict,
    }
    return ClaimRow(
        claim_id, published, verdict.median, verdict.ci_low, verdict.ci_high, unit,
        verdict.verdict, notebook, verdict.note, verdict.n, verdict.replication_rate, **controls,
    )


def control_rows(claim_id: str, null: RuleVerdict, oracle: RuleVerdict) -> list[dict]:
    """The two rows of ``controls.csv`` for a claim, with the control definitions of the claims
    register (columns ``null_control`` and ``oracle_control`` of ``data/claims.csv``).

    Raises
    ------
    CalibrationError
        If the null control is anything but ``not reproduced`` (the test is broken), or the
        register defines no control for the claim.
    """
    check_null_control(null)
    register = claim_register(columns=("null_control", "oracle_control")).set_index("id")
    if claim_id not in register.index:
        raise CalibrationError(f"claim id {claim_id!r} is not in the claims register")
    rows = []
    for control, v in (("null", null), ("oracle", oracle)):
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
