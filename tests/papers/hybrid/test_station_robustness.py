"""The robustness map of notebook 01: inputs set by their dotted keys, the inputs each claim
reads, the adapter that judges a point by the report's claim functions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import trial_rows
from calstudy.core.paths import RESULTS_DIR
from calstudy.core.robustness import matches, point_setting
from calstudy.core.trialcache import TrialCache
from calstudy.papers.hybrid import report, report_sweeps
from calstudy.papers.hybrid import station_robustness as robustness

STEM = "01_hybrid_global_calibration"


def test_overrides_reach_the_station_and_key_the_trial_cache():
    a = robustness.robustness_experiment("handeye", n_trials=1)
    b = robustness.robustness_experiment(
        "handeye", n_trials=1, overrides={"sensor.centre_floor_mm": 0.01}
    )
    assert a.name == b.name and b.scenario["overrides"] == {"sensor.centre_floor_mm": 0.01}
    assert "overrides" not in a.scenario
    keys = [TrialCache(Path("/nonexistent"), e, 1, ["{}"]).dirs[0] for e in (a, b)]
    assert keys[0] != keys[1]
    with pytest.raises(CalibrationError, match=r"cameras.pixel_sigma = 0.9: outside"):
        robustness.robustness_experiment("stationary", overrides={"cameras.pixel_sigma": 0.9})
    with pytest.raises(CalibrationError, match="unknown trial group 'rps'"):
        robustness.robustness_experiment("rps")


def _statistics(group: str, setting: dict) -> dict:
    spec = robustness.map_spec()
    rows = pd.DataFrame(trial_rows(spec.experiment(group, setting, 1), 1, 0, 0))
    return robustness.claim_statistics(group, rows)


@pytest.mark.parametrize(
    ("group", "unread", "read"),
    [
        ("handeye", ("cameras.pixel_sigma", 0.4), ("sensor.centre_floor_mm", 0.02)),
        ("stationary", ("sensor.sigma_point_mm", 0.05), ("cameras.pixel_sigma", 0.4)),
    ],
)
def test_a_claim_does_not_read_the_inputs_it_is_not_screened_for(group, unread, read):
    """An input a claim is not screened for leaves its statistic exactly as it is; an input
    it reads moves it (the check can fail)."""
    spec = robustness.map_spec()
    claims = {item.key: item.claims for item in spec.inputs}
    base = _statistics(group, {})
    moved = _statistics(group, dict([unread]))
    checked = [c for c in base if matches(unread[0], robustness.NOT_READ[c])]
    assert checked and all(c not in claims.get(unread[0], ()) for c in checked)
    for cid in checked:
        if cid == "hybrid.rps":  # reads the calibrated chain, but is 1 by construction
            np.testing.assert_allclose(moved[cid], base[cid], rtol=1e-9)
        else:
            np.testing.assert_array_equal(moved[cid], base[cid])
    other = _statistics(group, dict([read]))
    claim = {"handeye": "hybrid.handeye", "stationary": "hybrid.stationary"}[group]
    assert not np.array_equal(other[claim], base[claim])


def test_the_adapter_gives_the_reports_verdicts():
    """The map's per-trial statistic is the figure the verdict judges: its median for the
    hand-eye bound; for the pooled stationary bound, the per-trial RMS of its two chains
    pooled; the frame ratio of the not-testable ``hybrid.rps`` is 1."""
    judged = {}
    for group in ("handeye", "stationary"):
        exp = robustness.robustness_experiment(group, n_trials=6)
        rows = pd.concat([pd.DataFrame(trial_rows(exp, 1, 0, t)) for t in range(6)])
        verdicts = robustness.judge_claims(group, rows)
        assert set(verdicts) == {c for c, g in robustness.CLAIM_PARTS.items() if g == group}
        assert all(v.n == 6 for v in verdicts.values())
        judged[group] = rows, verdicts, robustness.claim_statistics(group, rows)
    _, verdicts, stats = judged["handeye"]
    v = verdicts["hybrid.handeye"]
    assert np.median(stats["hybrid.handeye"]) == pytest.approx(v.median, rel=1e-12)
    rows, verdicts, stats = judged["stationary"]
    st = report.stationary_figures(rows)
    cols = report_sweeps.CLAIMS["hybrid.stationary"]
    pooled = np.sqrt(np.mean(st[cols.figure] ** 2) / np.mean(st[cols.baseline] ** 2))
    assert cols.pooled and pooled == pytest.approx(verdicts["hybrid.stationary"].median, rel=1e-12)
    np.testing.assert_array_equal(stats["hybrid.stationary"], st["ratio"])
    assert verdicts["hybrid.rps"].verdict == "not testable"
    np.testing.assert_allclose(stats["hybrid.rps"], 1.0, rtol=1e-6)


def test_only_refuses_an_input_the_map_does_not_screen():
    with pytest.raises(CalibrationError, match=r"\['sensor.nothing'\]"):
        robustness.map_spec(only=["sensor.nothing"])
    spec = robustness.map_spec(only=["cameras.pixel_sigma"])
    assert [item.key for item in spec.inputs] == ["cameras.pixel_sigma"]


def _same_value(column: pd.Series, value) -> pd.Series:
    """Rows of ``column`` equal to ``value``, NaN (no second input) equal to NaN."""
    return column.isna() if pd.isna(value) else column.eq(value)


def spot_check(folder, count: int = 3) -> int:
    """Recompute ``count`` trials of the map in ``folder`` (chosen by the seed) and compare each
    claim's statistic with the stored one; the number checked."""
    params = json.loads((folder / "run.json").read_text())["parameters"]
    trials = pd.read_csv(folder / "trials_robustness.csv", keep_default_na=False,
                         na_values={"value": [""], "value2": [""]})
    spec = robustness.map_spec(params["robustness_inputs"])
    rng = np.random.default_rng(params["seed"])
    for _, row in trials.iloc[rng.choice(len(trials), size=count, replace=False)].iterrows():
        setting = point_setting(
            spec, [row["input"], row["input2"]], [row["value"], row["value2"]]
        )
        group = robustness.CLAIM_PARTS[row["claim"]]
        experiment = spec.experiment(group, setting, int(row["trial"]) + 1)
        rows = pd.DataFrame(trial_rows(experiment, params["seed"], 0, int(row["trial"])))
        got = robustness.claim_statistics(group, rows)[row["claim"]][0]
        assert got == pytest.approx(row["statistic"], rel=1e-8), dict(row)
    return count


def test_spot_check_of_a_map(tmp_path):
    """A map written as the notebook writes it, recomputed trial by trial; a changed stored
    statistic is found."""
    from calstudy.core.robustness import robustness_map
    from calstudy.io import results
    from calstudy.io.runs import TRIALS_FLOAT_FORMAT

    inputs = ["sensor.centre_floor_mm"]
    spec = robustness.map_spec(inputs)
    _, trials = robustness_map(spec, 3, n_screen=6, n_sweep=6, sweep_size=2,
                               engine={"n_jobs": 1, "cache_dir": tmp_path / "cache"})
    trials = trials[trials["claim"] == "hybrid.handeye"].reset_index(drop=True)
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    run = {"parameters": {"seed": 3, "robustness_inputs": inputs}}
    (tmp_path / "run.json").write_text(json.dumps(run))
    assert spot_check(tmp_path, count=8) == 8
    trials["statistic"] *= 1.01
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    with pytest.raises(AssertionError):
        spot_check(tmp_path, count=8)


def test_spot_check_of_the_committed_map():
    """A few stored trials of the committed map, chosen by the seed, recomputed and compared."""
    folder = RESULTS_DIR / STEM
    if not (folder / "trials_robustness.csv").is_file():
        pytest.skip("no committed robustness map yet")
    assert spot_check(folder) == 3
