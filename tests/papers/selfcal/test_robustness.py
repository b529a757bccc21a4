"""The selfcal robustness map: inputs set by their dotted keys, the inputs each claim reads, the
adapter that judges a point by the report's rule."""

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
from calstudy.papers.selfcal import experiments, report, robustness
from calstudy.papers.selfcal.scenario import load_scenario

STEM = "03_selfcal_one_step_identification"


def test_overrides_reach_the_factory_and_key_the_trial_cache():
    a = experiments.robustness_experiment(n_trials=1)
    b = experiments.robustness_experiment(n_trials=1, overrides={"scanner.sigma_point_mm": 0.04})
    assert b.scenario.scanner.sigma_point_mm == 0.04 and a.name == b.name
    assert a.scenario.scanner.sigma_point_mm != 0.04
    keys = [TrialCache(Path("/nonexistent"), e, 1, ["{}"]).dirs[0] for e in (a, b)]
    assert keys[0] != keys[1]
    with pytest.raises(CalibrationError, match=r"scanner.sigma_point_mm = 0.5: outside"):
        experiments.robustness_experiment(overrides={"scanner.sigma_point_mm": 0.5})


def _statistics(setting: dict) -> dict:
    spec = robustness.map_spec("")
    rows = trial_rows(spec.experiment(robustness.GROUP, setting, 1), 1, 0, 0)
    return robustness.claim_statistics(rows)


def test_a_claim_does_not_read_the_inputs_it_is_not_screened_for():
    """The very poor start leaves the four other claims' figures exactly as they are and moves
    the convergence claim's; an input every claim reads moves them (the check can fail)."""
    spec = robustness.map_spec("")
    claims = {item.key: item.claims for item in spec.inputs}
    unread = ("poor_start.base_mm", 500.0)
    assert claims[unread[0]] == ("selfcal.convergence",)
    assert set(claims["scanner.sigma_point_mm"]) == set(report.CLAIMS)
    base = _statistics({})
    moved = _statistics(dict([unread]))
    for cid, value in base.items():
        if cid in claims[unread[0]]:
            continue
        np.testing.assert_array_equal(moved[cid], value)
    read = _statistics({"scanner.sigma_point_mm": 0.05})
    assert all(not np.array_equal(read[c], base[c]) for c in base if c != "selfcal.convergence")


def test_the_adapter_gives_the_reports_verdicts():
    scenario = load_scenario()
    exp = experiments.calibration_experiment(n_trials=8)
    rows = pd.concat([trial_rows(exp, 1, 0, t) for t in range(8)], ignore_index=True)
    whole = report.selfcal_verdicts(rows, scenario)
    verdicts = robustness.judge_claims(rows, scenario)
    assert set(verdicts) == set(report.CLAIMS)
    stats = robustness.claim_statistics(rows)
    for cid, v in verdicts.items():
        assert v == whole[cid].claim
        assert np.median(stats[cid]) == pytest.approx(v.median, rel=1e-12)


def test_only_refuses_an_input_the_map_does_not_screen():
    with pytest.raises(CalibrationError, match=r"\['scanner.nothing'\]"):
        robustness.map_spec("", only=["scanner.nothing"])
    spec = robustness.map_spec("", only=["tracker.u0_mm"])
    assert [item.key for item in spec.inputs] == ["tracker.u0_mm"]


def _same_value(column: pd.Series, value) -> pd.Series:
    """Rows of ``column`` equal to ``value``, NaN (no second input) equal to NaN."""
    return column.isna() if pd.isna(value) else column.eq(value)


def spot_check(folder, count: int = 3) -> int:
    """Recompute ``count`` points of the map in ``folder`` (chosen by the seed), all their
    trials (one-step's figure divides by the route best over the point's trials), and compare
    trial 0's statistic of each claim with the stored one; the number of points checked."""
    params = json.loads((folder / "run.json").read_text())["parameters"]
    trials = pd.read_csv(folder / "trials_robustness.csv", keep_default_na=False,
                         na_values={"value": [""], "value2": [""]})
    spec = robustness.map_spec(params["scenario_toml"], params["robustness_inputs"])
    first = trials[trials["trial"] == 0].reset_index(drop=True)
    rng = np.random.default_rng(params["seed"])
    for _, row in first.iloc[rng.choice(len(first), size=count, replace=False)].iterrows():
        setting = point_setting(
            spec, [row["input"], row["input2"]], [row["value"], row["value2"]]
        )
        same = (
            (trials["stage"] == row["stage"])
            & (trials["input"] == row["input"])
            & (trials["input2"] == row["input2"])
            & _same_value(trials["value"], row["value"])
            & _same_value(trials["value2"], row["value2"])
            & (trials["claim"] == row["claim"])
        )
        n = int(trials.loc[same, "trial"].max()) + 1
        experiment = spec.experiment(robustness.GROUP, setting, n)
        rows = pd.concat(
            [pd.DataFrame(trial_rows(experiment, params["seed"], 0, t)) for t in range(n)],
            ignore_index=True,
        )
        got = robustness.claim_statistics(rows)[row["claim"]][0]
        assert got == pytest.approx(row["statistic"], rel=1e-8), dict(row)
    return count


def test_spot_check_of_a_map(tmp_path):
    """A map written as the notebook writes it, recomputed point by point; a changed stored
    statistic is found."""
    from calstudy.core.robustness import robustness_map
    from calstudy.io import results
    from calstudy.io.runs import TRIALS_FLOAT_FORMAT

    inputs = ["tracker.u0_mm"]
    spec = robustness.map_spec("", inputs)
    _, trials = robustness_map(spec, 3, n_screen=6, n_sweep=6, sweep_size=2,
                               engine={"n_jobs": 1, "cache_dir": tmp_path / "cache"})
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    run = {"parameters": {"seed": 3, "scenario_toml": "", "robustness_inputs": inputs}}
    (tmp_path / "run.json").write_text(json.dumps(run))
    assert spot_check(tmp_path, count=len(trials[trials["trial"] == 0])) > 0
    trials.loc[trials["trial"] == 0, "statistic"] *= 1.01
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    with pytest.raises(AssertionError):
        spot_check(tmp_path, count=len(trials[trials["trial"] == 0]))


def test_spot_check_of_the_committed_map():
    """A few stored trials of the committed map, chosen by the seed, recomputed and compared."""
    folder = RESULTS_DIR / STEM
    if not (folder / "trials_robustness.csv").is_file():
        pytest.skip("no committed robustness map yet")
    assert spot_check(folder) == 3
