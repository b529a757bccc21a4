"""Tests of calstudy.papers.binocular.report: tables beside the published values, claim rows."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.papers.binocular import report
from calstudy.papers.binocular.scenario import load_scenario, published


def fake_metrics(ratio: float, n: int = 8) -> pd.DataFrame:
    """Trial metrics whose every step has RMSE(with) = ``ratio`` RMSE(without)."""
    without = np.linspace(0.05, 0.08, n)
    cols = {}
    for a, b in (
        ("t2_without", "t2_with"),
        ("t3_without", "t3_with"),
        ("t3_holdout_without", "t3_holdout_with"),
        ("fig13_preliminary", "fig13_updated"),
        ("field_preliminary_base", "field_updated_base"),
        ("field_preliminary_flange", "field_updated_flange"),
    ):
        cols[a], cols[b] = without, ratio * without
    return pd.DataFrame({"trial": np.arange(n), **cols})


def test_rmse_summary_puts_the_ratio_beside_the_paper():
    summary = report.rmse_summary(fake_metrics(0.5))
    assert len(summary) == 6
    np.testing.assert_allclose(summary["ratio"], 0.5)
    np.testing.assert_allclose(summary["ratio_low"], 0.5)
    t2 = published("calibrator", "table2_rmse")
    assert summary["published_ratio"].iloc[0] == pytest.approx(t2[1] / t2[0])
    one = report.rmse_summary(fake_metrics(0.5, n=1))  # a single trial: its ratio thrice
    np.testing.assert_allclose(one[["ratio", "ratio_low", "ratio_high"]].to_numpy(), 0.5)


def test_claim_rows_name_the_four_claims():
    rows = report.claim_rows(fake_metrics(0.5), "04_binocular_correction")
    assert [r.id for r in rows] == [
        "binocular.coc",
        "binocular.observed_error",
        "binocular.transformation",
        "binocular.field",
    ]


def test_layout_table_lists_the_eight_targets():
    table = report.layout_table(load_scenario())
    assert table["target"].tolist() == ["P1", "P2", "P3", "P4", "P5", "P6", "P7", "P8"]
    assert np.abs(table["residual_mm"]).max() < 1e-9
