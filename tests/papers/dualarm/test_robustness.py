"""The dualarm robustness map: inputs set by their dotted keys, the parts each claim reads, the
adapter that judges a point, and a spot check of the committed map."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import trial_rows
from calstudy.core.paths import RESULTS_DIR
from calstudy.core.robustness import point_setting
from calstudy.core.schema import apply_overrides
from calstudy.papers.dualarm import experiments, report, robustness
from calstudy.papers.dualarm.scenario import load_published, load_scenario

STEM = "05_dualarm_global_calibration"


def test_apply_overrides_returns_a_new_table_and_refuses_an_unknown_key():
    table = {"detection": {"sigma_px": 0.1}, "name": "x"}
    out = apply_overrides(table, {"detection.sigma_px": 0.05})
    assert out == {"detection": {"sigma_px": 0.05}, "name": "x"}
    assert table["detection"]["sigma_px"] == 0.1
    assert apply_overrides(table, None) == table
    with pytest.raises(CalibrationError, match="'detection.sigma'"):
        apply_overrides(table, {"detection.sigma": 0.05})
    with pytest.raises(CalibrationError, match="'detection'"):
        apply_overrides(table, {"detection": 0.05})  # a table, not an input


def test_an_override_is_validated_against_its_ledger_range():
    assert load_scenario(overrides={"detection.sigma_px": 0.05}).detection.sigma_px == 0.05
    with pytest.raises(
        CalibrationError, match=r"detection.sigma_px = 0.5: outside .*0.0204, 0.0532"
    ):
        load_scenario(overrides={"detection.sigma_px": 0.5})
    with pytest.raises(CalibrationError, match="'sensor.points'"):
        load_scenario(overrides={"sensor.points": 300})


def test_overrides_reach_the_factory_and_key_the_trial_cache():
    from calstudy.core.trialcache import TrialCache

    a = experiments.robustness_experiment(n_trials=1)
    b = experiments.robustness_experiment(n_trials=1, overrides={"detection.sigma_px": 0.05})
    assert b.scenario.detection.sigma_px == 0.05 and a.name == b.name
    keys = [TrialCache(__import__("pathlib").Path("/nonexistent"), e, 1, ["{}"]).dirs[0]
            for e in (a, b)]
    assert keys[0] != keys[1]


def _spec():
    return robustness.map_spec("", load_published(), (2.0, 0.05), (0.7, 0.05))


def _rows(part: str, setting: dict):
    spec = _spec()
    return trial_rows(spec.experiment(part, setting, 1), 1, 0, 0)


@pytest.mark.parametrize(
    ("part", "unread", "read"),
    [
        ("icp", ("survey.bridge_views", 16), ("detection.sigma_px", 0.05)),
        ("icp", ("design.base_sigma_mm", 3.0), ("sensor.sphere_fit_sigma_mm", 0.0295)),
        ("icp", ("detection.loss_rate", 0.3), ("handeye.n_poses", 6)),
        ("icp", ("circular_plate.tilt_deg", 50.0), ("icp.n_views", 3)),
        ("global", ("icp.n_views", 3), ("survey.bridge_views", 16)),
    ],
)
def test_a_part_does_not_read_the_inputs_it_is_not_screened_for(part, unread, read):
    """The relevance of the map: an input a part is declared not to read leaves its rows
    exactly as they are; an input it reads changes them (the check can fail)."""
    spec = _spec()
    labels = {item.key: item.claims for item in spec.inputs}
    claims = [c for c, p in robustness.CLAIM_PARTS.items() if p == part]
    assert not set(claims) & set(labels[unread[0]])
    assert set(claims) <= set(labels[read[0]])
    base = _rows(part, {})
    pd.testing.assert_frame_equal(_rows(part, dict([unread])), base)
    assert not _rows(part, dict([read])).equals(base)


def test_the_adapter_judges_each_part_by_the_notebook_rule():
    trials = pd.read_csv(RESULTS_DIR / STEM / "trials_station.csv").query("trial < 30")
    published = load_published()
    whole = {cid: v[0] for cid, v in report.dualarm_verdicts(trials, published).items()}
    for part in ("icp", "global"):
        rows = trials[trials["part"].isin([part, "calibration", "bundle"])]
        verdicts = robustness.judge_claims(rows, published)
        assert set(verdicts) == {c for c, p in robustness.CLAIM_PARTS.items() if p == part}
        for cid, v in verdicts.items():
            assert v == whole[cid]
            stat = report.claim_statistics(rows)[cid]
            assert np.median(stat) == pytest.approx(v.median, rel=1e-12)


def test_the_map_inputs_carry_where_the_paper_puts_them():
    spec = _spec()
    by_key = {item.key: item for item in spec.inputs}
    sigma = by_key["detection.sigma_px"]
    # 0.029 mm depth error at 500 mm with f = 2000 px, B = 200 mm: 0.029 * 4e5 / (sqrt 2 * 2.5e5)
    assert sigma.paper == pytest.approx(0.029 * 2000 * 200 / (np.sqrt(2) * 500**2), rel=2e-3)
    assert sigma.kind == "derived" and (sigma.low, sigma.high) == (0.0204, 0.0532)
    # the count of points screened up to what the cameras give on sphere B
    assert by_key["sensor.points_per_scan"].high == by_key["sensor.points_per_scan"].paper
    assert by_key["drift_scale"].kind == "calibrated"
    assert by_key["drift_scale"].low == pytest.approx(1.9)
    assert by_key["drift_scale"].claims == ("dualarm.icp",)
    with pytest.raises(CalibrationError, match=r"\['sensor.nothing'\]"):
        robustness.map_spec("", load_published(), (2.0, 0.05), (0.7, 0.05), only=["sensor.nothing"])


def spot_check(folder, count: int = 3) -> int:
    """Recompute trial 0 of ``count`` points of the map in ``folder`` (chosen by the seed) and
    compare each claim's statistic with the stored one; the number of points checked."""
    params = json.loads((folder / "run.json").read_text())["parameters"]
    trials = pd.read_csv(folder / "trials_robustness.csv", keep_default_na=False,
                         na_values={"value": [""], "value2": [""]})
    spec = robustness.map_spec(
        params["scenario_toml"], load_published(), (params["drift_scale"], 1e-9),
        (params["plate_sigma_px"], 1e-9), params["robustness_caps"], params["robustness_inputs"],
    )
    first = trials[trials["trial"] == 0].reset_index(drop=True)
    rng = np.random.default_rng(params["seed"])
    for _, row in first.iloc[rng.choice(len(first), size=count, replace=False)].iterrows():
        setting = point_setting(
            spec, [row["input"], row["input2"]], [row["value"], row["value2"]]
        )
        part = robustness.CLAIM_PARTS[row["claim"]]
        rows = trial_rows(spec.experiment(part, setting, 1), params["seed"], 0, 0)
        got = report.claim_statistics(rows)[row["claim"]][0]
        assert got == pytest.approx(row["statistic"], rel=1e-8), dict(row)
    return count


def test_spot_check_of_the_committed_map():
    """A few stored trials of the map, chosen by the seed, recomputed and compared."""
    folder = RESULTS_DIR / STEM
    if not (folder / "trials_robustness.csv").is_file():
        pytest.skip("no committed robustness map yet")
    assert spot_check(folder) == 3


def test_committed_map_names_no_path_of_a_machine():
    """A map point whose setting cannot be loaded records the file from the repository
    (``data/dualarm/scenario.toml``), not by an absolute path of the machine that ran it."""
    import re

    absolute = re.compile(r"(^|[\s'\"(,])/\w[\w.-]*/[\w./-]*\.toml")
    for name in ("robustness.csv", "robustness_claims.csv"):
        path = RESULTS_DIR / STEM / name
        if path.is_file():
            assert not absolute.search(path.read_text()), name
