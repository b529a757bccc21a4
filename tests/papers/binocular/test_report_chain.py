"""Tests of calstudy.papers.binocular.report_chain: the defocus-to-Fig. 13 chain table and its
sentences, on synthetic sweep rows with known medians."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.papers.binocular import report_chain as rc
from calstudy.papers.binocular.report import loglog_crossing
from calstudy.papers.binocular.scenario import published


def fake_sweep(fig13_by_f: dict, n: int = 5) -> pd.DataFrame:
    """Sweep rows: per F-number ``n`` trials, every chain column 1..n times a constant, the
    preliminary Fig. 13 RMSE ``fig13_by_f[F]`` in every trial, hand-eye error 3 mm per mrad."""
    rows = []
    for f, fig13 in fig13_by_f.items():
        for i in range(n):
            row = {"trial": i, "f_number": f, "focus_distance_mm": 0.0, "dot_diameter_mm": 0.0}
            row.update({c: float(i + 1) for c in rc.CHAIN_MEDIANS})
            row["pose_rot_err_mrad"] = 0.5 * (i + 1)
            row["trans_err_preliminary_mm"] = 1.5 * (i + 1)
            row["fig13_exact_p7_preliminary"] = fig13
            rows.append(row)
    # a point of another sweep, which the F-number table must leave out
    rows.append({**rows[0], "f_number": 0.0, "focus_distance_mm": 800.0})
    return pd.DataFrame(rows)


def test_chain_table_medians_and_lever():
    t = rc.chain_table(fake_sweep({4.0: 2.0, 8.0: 0.5}))
    assert t["f_number"].tolist() == [4.0, 8.0]
    assert t["n"].tolist() == [5, 5]
    assert t["shift_px_rms"].tolist() == [3.0, 3.0]  # median of 1..5
    assert t["mm_per_mrad"].tolist() == pytest.approx([3.0, 3.0])


def test_chain_text_finds_where_the_baseline_meets_the_paper():
    goal = published("station", "fig13_rmse")[0]
    # the Fig. 13 baseline falls from 4 goal at f/4 to goal / 4 at f/16: log-log midpoint f/8
    t = rc.chain_table(fake_sweep({4.0: 4 * goal, 16.0: goal / 4}))
    trials = pd.DataFrame({"fig13_preliminary": [2.5], "trans_err_preliminary_mm": [3.5]})
    text = rc.chain_text(t, trials, 5.42)
    assert "near f/8," in text
    assert "At f/4," in text  # the swept F-number nearest f/5.42 (log scale)
    never = rc.chain_text(rc.chain_table(fake_sweep({4.0: 9 * goal, 8.0: 3 * goal})), trials, 5.42)
    assert "No swept F-number brings the Fig. 13 baseline down" in never


def test_crossing_is_none_outside_the_swept_range():
    assert loglog_crossing([4.0, 8.0], [2.0, 1.0], 0.1) is None
    assert loglog_crossing([4.0, 16.0], [2.0, 0.5], 1.0) == pytest.approx(8.0)
    assert np.isfinite(loglog_crossing([4.0, 16.0], [0.5, 2.0], 1.0))
