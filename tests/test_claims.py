"""A claim judged from its register row and the trial columns declared for it.

:func:`calstudy.claims.judge_claim` takes the kind and direction from ``data/claims.csv``, the
figures from the columns of :class:`calstudy.claims.ClaimColumns`, and applies the controls and
the oracle gate; :func:`judge_along` does the same at each point of a sweep, and
:func:`calstudy.core.robustness.verdict_runs` and ``verdict_changes`` say where a verdict changes
along one.
"""

from __future__ import annotations

import ast

import numpy as np
import pandas as pd
import pytest

from calstudy.claims import (
    TOO_FEW,
    ClaimColumns,
    Judged,
    claim_row,
    claim_rule,
    control_rows,
    judge_along,
    judge_claim,
)
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import REPO_ROOT
from calstudy.core.robustness import verdict_changes, verdict_runs
from calstudy.core.verdicts import judge

COC = ClaimColumns(
    "after", baseline="before", null="before", oracle="oracle", mechanism="defocus"
)


def corrections(n: int = 200, ratio: float = 0.84, oracle: float = 0.5, seed: int = 0):
    """Trials of a correction: ``after`` about ``ratio`` times ``before``, ``oracle`` about
    ``oracle`` times it."""
    rng = np.random.default_rng(seed)
    before = rng.lognormal(np.log(0.049), 0.2, n)
    noise = lambda: np.exp(rng.normal(0.0, 0.05, n))  # noqa: E731
    return pd.DataFrame(
        {"before": before, "after": ratio * before * noise(), "oracle": oracle * before * noise()}
    )


def test_the_rule_comes_from_the_register():
    assert claim_rule("binocular.coc") == ("ratio", "lower")
    assert claim_rule("hybrid.deviation") == ("bound", "lower")
    assert claim_rule("hybrid.systematic") == ("value", "higher")
    assert claim_rule("selfcal.residual") == ("bound", "lower")
    with pytest.raises(CalibrationError, match="'binocular.nope' is not in the claims register"):
        claim_rule("binocular.nope")


def test_judge_claim_is_the_rule_with_its_controls_on_the_declared_columns():
    t = corrections()
    got = judge_claim("binocular.coc", t, COC, published=0.837)
    rule = {"kind": "ratio", "direction": "lower", "baseline": t["before"]}
    assert got.claim == judge(t["after"], published=0.837, **rule)
    assert got.null == judge(t["before"], **rule)
    assert got.oracle == judge(t["oracle"], **rule)
    assert (got.claim.verdict, got.null.verdict) == ("reproduced", "not reproduced")
    # the same trials under a claim whose register says "higher": significant on the wrong side
    wrong = judge_claim("hybrid.systematic", t, ClaimColumns("after", baseline="before"))
    assert wrong.claim.verdict == "not reproduced" and "the wrong side" in wrong.claim.note


def test_a_bound_or_a_stated_reference_is_the_reference():
    t = corrections()
    bound = judge_claim("selfcal.residual", t, ClaimColumns("after"), reference=0.06)
    assert bound.claim == judge(t["after"], kind="bound", direction="lower", bound=0.06)
    value = judge_claim("dualarm.global", t, ClaimColumns("after"), reference=0.06)
    assert value.claim == judge(t["after"], kind="value", direction="lower", null=0.06)


def test_the_oracle_gate_makes_a_claim_without_its_mechanism_not_testable():
    t = corrections(oracle=1.0)
    got = judge_claim("binocular.coc", t, COC, published=0.837)
    assert got.claim.verdict == "not testable" and "the model lacks defocus" in got.claim.note
    assert got.oracle.verdict == "not reproduced"


def test_declarations_and_columns_are_checked():
    with pytest.raises(CalibrationError, match="null 'b', oracle '' and mechanism ''"):
        ClaimColumns("a", null="b")
    with pytest.raises(CalibrationError, match="binocular.coc: the trials have no column 'after'"):
        judge_claim("binocular.coc", {"before": [1.0] * 10}, COC)


def test_rows_of_a_judged_claim_with_and_without_controls():
    judged = judge_claim("binocular.coc", corrections(), COC, published=0.837)
    row = claim_row("binocular.coc", judged, published="0.837", unit="ratio", notebook="04_x")
    assert (row.verdict, row.null_control, row.oracle_control) == (
        "reproduced",
        "not reproduced",
        "reproduced",
    )
    assert row.note == judged.claim.note
    noted = claim_row("binocular.coc", judged, published="", unit="", notebook="", note="n")
    assert noted.note == "n"
    assert [r["control"] for r in control_rows("binocular.coc", judged)] == ["null", "oracle"]
    assert control_rows("binocular.coc", Judged(judged.claim)) == []


def test_judge_along_judges_each_point_on_its_own_trials():
    points = [corrections(n=40, ratio=r, seed=k) for k, r in enumerate((0.84, 1.0, 0.3))]
    sweep = pd.concat([p.assign(scale=s) for p, s in zip(points, (3.0, 1.0, 2.0), strict=True)])
    sweep = pd.concat([sweep, corrections(n=4).assign(scale=4.0)])
    along = judge_along(sweep, "scale", "binocular.coc", COC, published=0.837)
    assert [value for value, _, _ in along] == [1.0, 2.0, 3.0, 4.0]
    for (_, sub, judged), point in zip(along[:3], points[1:] + points[:1], strict=True):
        assert len(sub) == 40 and sub["after"].tolist() == point["after"].tolist()
        assert judged == judge_claim("binocular.coc", point, COC, published=0.837, min_trials=30)
    verdicts = [j.claim.verdict for _, _, j in along[:3]]
    assert verdicts == ["not reproduced", "direction only", "reproduced"]
    assert along[3][2] is None  # 4 trials: too few for a 95 % interval of the median
    assert TOO_FEW == "too few trials"


def test_verdict_runs_say_where_the_verdict_changes():
    runs = verdict_runs([1, 2, 3, 4, 5], ["a", "a", "b", "a", "a"])
    assert runs == [("a", [1, 2]), ("b", [3]), ("a", [4, 5])]
    assert verdict_runs([0.5], ["reproduced"]) == [("reproduced", [0.5])]
    with pytest.raises(CalibrationError, match="2 values but 1 verdicts"):
        verdict_runs([1, 2], ["a"])
    with pytest.raises(CalibrationError, match="0 values but 0 verdicts"):
        verdict_runs([], [])


def test_verdict_changes_name_the_values_on_either_side_of_each_change():
    verdicts = ["a", "a", "b", "a", "a"]
    changes = ["from a at 2 to b at 3", "from b at 3 to a at 4"]
    assert verdict_changes([1, 2, 3, 4, 5], verdicts) == changes
    text = "{a} -> {b} between {x} and {y}"
    assert verdict_changes([0.5, 1.25], ["a", "b"], text, "{:.2f}".format) == [
        "a -> b between 0.50 and 1.25"
    ]
    assert verdict_changes([1, 2], ["a", "a"]) == [] and verdict_changes([], []) == []
    with pytest.raises(CalibrationError, match="2 values but 1 verdicts"):
        verdict_changes([1, 2], ["a"])


def rule_imports(source: str) -> set[str]:
    """Names a module imports from the verdict rule (``calstudy.core.verdicts``)."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module == "calstudy.core.verdicts":
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module == "calstudy.core":
            names |= {a.name for a in node.names if a.name == "verdicts"}
        elif isinstance(node, ast.Import):
            names |= {a.name for a in node.names if a.name == "calstudy.core.verdicts"}
    return names


def test_paper_modules_judge_claims_through_the_register_only():
    papers = sorted((REPO_ROOT / "src" / "calstudy" / "papers").glob("*/*.py"))
    assert len(papers) > 20
    # a claim a simulation cannot test (rule 9) is recorded with its reason; nothing else of
    # the rule is called from a paper: judge_claim reads the kind and direction from the register
    found = {p.relative_to(REPO_ROOT).as_posix(): rule_imports(p.read_text()) for p in papers}
    assert {path: names for path, names in found.items() if names - {"not_testable"}} == {}
    assert rule_imports("from calstudy.core.verdicts import judge, not_testable") == {
        "judge",
        "not_testable",
    }
    assert rule_imports("from calstudy.core import verdicts") == {"verdicts"}


def test_too_few_trials_is_its_own_error_and_a_sweep_point_reads_none():
    from calstudy.claims import verdict_or_none, verdict_text
    from calstudy.core.errors import TooFewTrials
    from calstudy.core.stats import median_interval

    with pytest.raises(TooFewTrials, match="interval for the median"):
        median_interval([1.0, 2.0, 3.0])
    assert verdict_or_none(lambda: median_interval([1.0, 2.0, 3.0])) is None
    with pytest.raises(CalibrationError, match="non-finite"):
        verdict_or_none(lambda: median_interval([1.0] * 10 + [float("nan")]))
    # a sweep table writes the point's verdict, or that it has too few trials
    judged = Judged(judge(np.linspace(0.5, 0.7, 30), kind="ratio", direction="lower"))
    assert verdict_text(judged) == "reproduced" and verdict_text(None) == TOO_FEW


def test_a_claim_whose_null_control_passes_is_not_testable():
    from calstudy.claims import null_gate

    rule = {"kind": "ratio", "direction": "lower", "min_trials": 30}
    rng = np.random.default_rng(0)
    claim = judge(rng.uniform(0.5, 0.7, 30), published=0.6, **rule)
    broken = judge(rng.uniform(0.5, 0.7, 30), **rule)  # the null improves too
    sound = judge(rng.uniform(0.9, 1.1, 30), **rule)
    assert (claim.verdict, broken.verdict, sound.verdict) == (
        "reproduced",
        "reproduced",
        "not reproduced",
    )
    assert null_gate(Judged(claim, sound)) == Judged(claim, sound)
    gated = null_gate(Judged(claim, broken, sound))
    assert gated.claim.verdict == "not testable" and gated[1:] == (broken, sound)
    assert (gated.claim.kind, gated.claim.n) == ("ratio", 30)
    assert "null control comes out reproduced" in gated.claim.note
    assert "the claim alone came out reproduced" in gated.claim.note
    with pytest.raises(CalibrationError, match="a null gate needs a null control"):
        null_gate(Judged(claim))
