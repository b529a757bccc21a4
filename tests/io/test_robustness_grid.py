"""The claims page's robustness grid: which inputs get a row, and what a cell shows."""

from __future__ import annotations

import pandas as pd

from calstudy.io.robustness_grid import OTHERS, cell_verdicts


def _map() -> pd.DataFrame:
    """Two claims; input ``a.x`` changes claim c1's verdict along its sweep, ``a.y`` matters
    (moves c2's figure) but keeps every verdict, ``a.z`` does not matter; a failing sweep point
    is not a verdict."""
    rows = []
    for claim, base in (("c1", "reproduced"), ("c2", "not reproduced")):
        rows.append(dict(claim=claim, stage="base", input="", verdict=base, matters="", error=""))
        for label, matters in (("a.x", "yes"), ("a.y", "yes"), ("a.z", "no")):
            rows.append(
                dict(
                    claim=claim,
                    stage="screen",
                    input=label,
                    verdict=base,
                    matters=matters,
                    error="",
                )
            )
    rows += [
        dict(
            claim="c1", stage="sweep", input="a.x", verdict="direction only", matters="", error=""
        ),
        dict(
            claim="c2", stage="sweep", input="a.y", verdict="not reproduced", matters="", error=""
        ),
        dict(
            claim="c2",
            stage="sweep",
            input="a.x",
            verdict="chain fails",
            matters="",
            error="the chain cannot run",
        ),
    ]
    return pd.DataFrame(rows)


def test_a_row_per_input_that_changes_a_verdict_the_rest_pooled():
    cells, claims, inputs = cell_verdicts(_map())
    assert claims == ["c1", "c2"]
    assert inputs == ["a.x", OTHERS]  # a.y moves a figure only, a.z does not matter
    assert cells[("c1", "a.x")] == ["reproduced", "direction only"]
    assert cells[("c2", "a.x")] == ["not reproduced"]  # the failing point is no verdict
    assert cells[("c1", OTHERS)] == ["reproduced"]
    assert cells[("c2", OTHERS)] == ["not reproduced"]
