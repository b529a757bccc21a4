"""Sweep verdicts, generated sentences and the error budget table on made-up trials."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.papers.dualarm import report_design as rd
from calstudy.papers.dualarm.experiments import BUDGET_SOURCES
from calstudy.papers.dualarm.scenario import load_published


def _sweep(scn, level_by_views):
    """Trials of every sweep point of the scenario's design; the sphere error of a point is
    ``level_by_views[bridge_views]`` (or 0.5 mm) with a little scatter."""
    from calstudy.papers.dualarm.experiments import survey_points

    rng = np.random.default_rng(3)
    rows = []
    for p in survey_points(scn, bridge_views=(4, 16)):
        level = level_by_views.get(p["bridge_views"], 0.5)
        for t in range(30):
            rows.append(
                {
                    **p,
                    "trial": t,
                    "coded_euclid_mm": level * (1 + 0.05 * rng.standard_normal()),
                    "link_deg": 0.1,
                    "marker_rms_mm": 0.03,
                }
            )
    return pd.DataFrame(rows)


def test_sweep_sentences_say_where_the_verdict_changes(scenario):
    published = load_published()
    table = rd.sweep_table(_sweep(scenario, {16: 0.1}), published)
    assert (table["n"] == 30).all()
    lines = rd.sweep_lines(table, scenario)
    views = lines["bridge_views"]
    assert views["bridge_views"].tolist() == [4, 8, 16]
    assert views["verdict"].tolist() == ["not reproduced", "not reproduced", "reproduced"]
    text = rd.sweep_sentences(table, scenario)
    assert "changes from 'not reproduced' at 8 to 'reproduced' at 16" in text
    assert (
        "Along the calibration poses per arm (3, 6, 10), the verdict stays 'not reproduced'" in text
    )
    # nowhere better than the reference: no change anywhere
    flat = rd.sweep_sentences(rd.sweep_table(_sweep(scenario, {}), published), scenario)
    assert "changes" not in flat and flat.count("stays 'not reproduced'") == 3


def test_the_paper_point_sentence_names_the_points_with_the_papers_poses(scenario):
    published = load_published()
    table = rd.sweep_table(_sweep(scenario, {16: 0.1}), published)
    text = rd.paper_point_sentence(table, scenario)
    assert "resembles the 5 sweep points with 3 poses (4, 8, 16 linking images" in text
    assert "global calibration is 'not reproduced'" in text
    assert "over them it takes 'not reproduced' and 'reproduced'" in text
    flat = rd.paper_point_sentence(rd.sweep_table(_sweep(scenario, {}), published), scenario)
    assert "it is 'not reproduced' at every one of them" in flat
    with pytest.raises(CalibrationError, match="no point with the paper's 3"):
        rd.paper_point_sentence(table[table["calibration_poses"] != 3], scenario)


def test_budget_table_orders_sources_and_shares_in_quadrature():
    rows = []
    levels = {"coded markers": 0.4, "true calibration": 0.01}
    levels.update({f"budget: {s}": 0.1 * (k + 1) for k, s in enumerate(BUDGET_SOURCES)})
    for t in range(30):
        for m, v in levels.items():
            rows.append({"part": "global", "method": m, "trial": t, "euclid_mm": v})
    table = rd.budget_table(pd.DataFrame(rows))
    assert table["source"].iloc[0].startswith("all sources")
    assert table["source"].iloc[-1].startswith("test floor")
    np.testing.assert_allclose(table["median_mm"], [0.4, 0.1, 0.2, 0.3, 0.4, 0.01])
    np.testing.assert_allclose(table["share_of_variance_pct"].iloc[1], 100 * (0.1 / 0.4) ** 2)
