"""Notebook 02's robustness map: inputs set by their dotted keys, the inputs each claim reads,
the adapter that judges a point by the report's rule; the part-variation finding."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import trial_rows
from calstudy.core.paths import RESULTS_DIR
from calstudy.core.robustness import point_setting
from calstudy.core.trialcache import TrialCache
from calstudy.papers.hybrid import experiments, report
from calstudy.papers.hybrid import production_robustness as robustness
from calstudy.papers.hybrid.scenario import load_scenario

STEM = "02_hybrid_production_compensation"
PART = "production.variation.part_sigma_mm"
DRIFT = "production.drift.sigma_mm"


def test_overrides_reach_the_factory_and_key_the_trial_cache():
    a = experiments.robustness_experiment(n_trials=1)
    b = experiments.robustness_experiment(n_trials=1, overrides={PART: 0.1})
    assert b.scenario["scenario"].production.variation.part_sigma_mm == 0.1 and a.name == b.name
    assert a.scenario["scenario"].production.variation.part_sigma_mm != 0.1
    keys = [TrialCache(Path("/nonexistent"), e, 1, ["{}"]).dirs[0] for e in (a, b)]
    assert keys[0] != keys[1]
    outside = r"part_sigma_mm = 2.0: outside its plausible range \[0.05, 0.67\]"
    with pytest.raises(CalibrationError, match=outside):
        experiments.robustness_experiment(overrides={PART: 2.0})
    # a station input reaches the stations of the trial
    c = experiments.robustness_experiment(overrides={"station.sensor.sigma_point_mm": 0.05})
    assert c.scenario["scenario"].station.sensor.sigma_point_mm == 0.05


def _statistics(setting: dict, n: int = 2) -> dict:
    spec = robustness.map_spec("")
    exp = spec.experiment(robustness.GROUP, setting, n)
    rows = pd.concat([pd.DataFrame(trial_rows(exp, 1, 0, t)) for t in range(n)])
    return robustness.claim_statistics(rows)


def test_a_claim_does_not_read_the_inputs_it_is_not_screened_for():
    """The drift and the products in the offset leave the systematic size and the correlation
    distance exactly as they are and move the deviation's shortfall; an input every claim reads
    moves the systematic size (the check can fail)."""
    spec = robustness.map_spec("")
    claims = {item.key: item.claims for item in spec.inputs}
    assert claims[DRIFT] == ("hybrid.deviation",)
    assert claims["production.protocol.n_compensation"] == ("hybrid.deviation",)
    assert set(claims[PART]) == set(robustness.CLAIMS)
    base = _statistics({})
    moved = _statistics({DRIFT: 0.3, "production.protocol.n_compensation": 20})
    for cid in ("hybrid.systematic", "hybrid.correlation"):
        np.testing.assert_array_equal(moved[cid], base[cid])
    assert not np.array_equal(moved["hybrid.deviation"], base["hybrid.deviation"])
    read = _statistics({"station.sensor.sigma_point_mm": 0.05})
    assert not np.array_equal(read["hybrid.systematic"], base["hybrid.systematic"])


def test_the_adapter_gives_the_reports_verdicts():
    exp = experiments.robustness_experiment(n_trials=8)
    rows = pd.concat([pd.DataFrame(trial_rows(exp, 1, 0, t)) for t in range(8)], ignore_index=True)
    verdicts = robustness.judge_claims(rows)
    assert list(verdicts) == list(robustness.CLAIMS)
    stats = robustness.claim_statistics(rows)
    # every claim is testable here: each median is compared
    assert all(np.isfinite(v.median) and v.n == 8 for v in verdicts.values())
    for cid, v in verdicts.items():
        assert np.median(stats[cid]) == pytest.approx(v.median, rel=1e-12)


def test_only_refuses_an_input_the_map_does_not_screen():
    with pytest.raises(CalibrationError, match=r"\['production.nothing'\]"):
        robustness.map_spec("", only=["production.nothing"])
    spec = robustness.map_spec("", only=[PART])
    assert [item.key for item in spec.inputs] == [PART]


def test_the_part_variation_range_is_not_set_by_the_bins():
    """The range's ends are the stated tolerance at Cp = 1 and the stated robot repeatability."""
    sc = load_scenario()
    low, high = sc.production.variation.provenance["part_sigma_mm"].range
    assert high == pytest.approx(2.0 / 3.0, abs=0.005)  # +-2 mm at Cp = 1: 6 sigma = 4 mm
    assert low == pytest.approx(0.05)  # +-0.05 mm robot repeatability, sec. 4.3


def test_part_variation_finding_finds_where_the_bins_pass():
    """Stations whose distance is smallest at one part variation; the sentence names it, and
    the values where the claim's rule passes."""
    rng = np.random.default_rng(3)
    rows = []
    for value, d in ((0.05, 0.6), (0.08, 0.05), (0.5, 0.84)):
        for t in range(30):
            rows.append({"trial": t, "part_sigma_mm": value, "n_defined": 168,
                         "r_distance": d + rng.uniform(0, 0.02), "r_above_0p7": 50.0})
    summary = report.summarise_part_variation(pd.DataFrame(rows))
    assert summary["verdict"].tolist() == ["not reproduced", "reproduced", "not reproduced"]
    text = report.part_variation_sentence(summary, load_scenario(), 0.06)
    assert "smallest at 0.08 mm" in text and "reproduced at 0.08 mm" in text
    assert "the scenario's 0.5 mm (range 0.05-0.67 mm) gives a median distance of 0.8" in text
    with pytest.raises(CalibrationError, match="empty"):
        report.part_variation_sentence(summary.iloc[:0], load_scenario(), 0.06)


def _same_value(column: pd.Series, value) -> pd.Series:
    """Rows of ``column`` equal to ``value``, NaN (no second input) equal to NaN."""
    return column.isna() if pd.isna(value) else column.eq(value)


def spot_check(folder, count: int = 3) -> int:
    """Recompute ``count`` points of the map in ``folder`` (chosen by the seed), trial 0 of
    each, and compare each claim's statistic with the stored one; the number checked."""
    params = json.loads((folder / "run.json").read_text())["parameters"]
    trials = pd.read_csv(folder / "trials_robustness.csv", keep_default_na=False,
                         na_values={"value": [""], "value2": [""]})
    spec = robustness.map_spec("", params["robustness_inputs"])
    first = trials[trials["trial"] == 0].reset_index(drop=True)
    rng = np.random.default_rng(params["seed"])
    for _, row in first.iloc[rng.choice(len(first), size=count, replace=False)].iterrows():
        setting = point_setting(
            spec, [row["input"], row["input2"]], [row["value"], row["value2"]]
        )
        experiment = spec.experiment(robustness.GROUP, setting, 1)
        rows = pd.DataFrame(trial_rows(experiment, params["seed"], 0, 0))
        got = robustness.claim_statistics(rows)[row["claim"]][0]
        assert got == pytest.approx(row["statistic"], rel=1e-8, abs=1e-12), dict(row)
    return count


def test_spot_check_of_a_map(tmp_path):
    """A map written as the notebook writes it, recomputed point by point; a changed stored
    statistic is found."""
    from calstudy.core.robustness import robustness_map
    from calstudy.io import results
    from calstudy.io.runs import TRIALS_FLOAT_FORMAT

    inputs = [PART]
    spec = robustness.map_spec("", inputs)
    _, trials = robustness_map(spec, 3, n_screen=6, n_sweep=6, sweep_size=2,
                               engine={"n_jobs": 1, "cache_dir": tmp_path / "cache"})
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    run = {"parameters": {"seed": 3, "robustness_inputs": inputs}}
    (tmp_path / "run.json").write_text(json.dumps(run))
    count = len(trials[trials["trial"] == 0])
    assert spot_check(tmp_path, count=count) > 0
    trials.loc[trials["trial"] == 0, "statistic"] += 0.01
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    with pytest.raises(AssertionError):
        spot_check(tmp_path, count=count)


def test_spot_check_of_the_committed_map():
    """A few stored trials of the committed map, chosen by the seed, recomputed and compared."""
    folder = RESULTS_DIR / STEM
    if not (folder / "trials_robustness.csv").is_file():
        pytest.skip("no committed robustness map yet")
    assert spot_check(folder) == 3
