"""Tables and verdicts of the dualarm notebook on made-up trials."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.papers.dualarm import report
from calstudy.papers.dualarm.scenario import load_published


def fake_trials(n=30, after=0.15, ours=0.100, circ=0.556):
    rng = np.random.default_rng(18)
    icp_rows = [
        {
            "part": "icp",
            "arm": a,
            "sphere": s,
            "view": v,
            "trial": t,
            "before_mm": b,
            "after_mm": b * after,
            "null_mm": 10.0 * b,
            "oracle_mm": 0.01 * b,
        }
        for t in range(n)
        for a in (1, 2)
        for s in ("A", "B")
        for v in (1, 2)
        for b in [1.0 + 0.1 * rng.random()]
    ]
    glob = [
        {
            "part": "global",
            "method": m,
            "group": g,
            "pose": k,
            "trial": t,
            "dx_mm": e / 2,
            "dy_mm": e / 2,
            "dz_mm": e / 2,
            "euclid_mm": e,
            "euclid_truth_mm": e,
        }
        for t in range(n)
        for m, base in (
            ("coded markers", ours),
            ("circular plate", circ),
            ("design drawing", 1.5),
            ("plate retake", circ),
            ("true calibration", 0.005),
        )
        for g in (1, 2, 3)
        for k in (1, 2, 3)
        for e in [base * (1 + 0.05 * rng.standard_normal())]
    ]
    return pd.DataFrame(icp_rows + glob)


def test_claims_reproduce_the_published_numbers_when_the_data_do():
    published = load_published()
    rows, controls = report.dualarm_claims(fake_trials(), published, "nb")
    assert [r.id for r in rows] == ["dualarm.icp", "dualarm.global", "dualarm.vs_circular"]
    assert [r.verdict for r in rows] == ["reproduced"] * 3
    assert rows[2].reproduced == pytest.approx(0.18, rel=0.1)
    assert [c["verdict"] for c in controls if c["control"] == "null"] == ["not reproduced"] * 3
    assert [c["verdict"] for c in controls if c["control"] == "oracle"] == ["reproduced"] * 3
    worse, _ = report.dualarm_claims(fake_trials(after=1.2, ours=0.9), published, "nb")
    assert [r.verdict for r in worse] == ["not reproduced"] * 3
    near, _ = report.dualarm_claims(fake_trials(after=0.5, ours=0.17), published, "nb")
    assert [r.verdict for r in near] == ["direction only", "direction only", "direction only"]


def test_table3_marks_the_instruments_not_testable():
    t3 = report.table3(report.part(fake_trials(), "global"), load_published())
    assert t3["testable"].tolist() == ["not testable", "not testable", "yes", "yes"]
    assert t3.loc[t3["method"] == "circular plate", "published_euclid_mm"].item() == 0.556
    assert np.isnan(t3.loc[0, "euclid_mm"])
