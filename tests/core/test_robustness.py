"""Verdict robustness maps (calstudy.core.robustness) on toy claims with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import Experiment
from calstudy.core.robustness import (
    Input,
    MapSpec,
    assign_claims,
    calibrated_input,
    claim_summary,
    ledger_inputs,
    matches,
    paper_spec,
    robustness_map,
    screened_inputs,
    select_inputs,
)
from calstudy.core.verdicts import judge

#: the toy claim "flip" is reproduced while x lies below this
THRESHOLD = 0.5
CALLS = {"n": 0, "stop_at": None}


def toy_trial(scn: dict, rng: np.random.Generator) -> dict:
    """``flip``: x plus small noise (judged below THRESHOLD); ``flat``: 1 plus noise, whatever
    x and y."""
    CALLS["n"] += 1
    if CALLS["stop_at"] is not None and CALLS["n"] >= CALLS["stop_at"]:
        raise KeyboardInterrupt  # an interrupted run
    if scn.get("fails_above") is not None and scn["x"] > scn["fails_above"]:
        raise CalibrationError(f"x = {scn['x']} cannot run")
    noise = rng.normal(size=2)
    return {"flip": scn["x"] + 0.01 * noise[0], "flat": 1.0 + 0.01 * noise[1]}


def _experiment(group: str, setting: dict, n_trials: int) -> Experiment:
    scenario = {"x": 0.3, "y": 0.5, **setting}
    return Experiment("toy", toy_trial, scenario, n_trials)


def _statistics(group: str, rows: pd.DataFrame) -> dict:
    return {"toy.flip": rows["flip"].to_numpy(), "toy.flat": rows["flat"].to_numpy()}


def _judge(group: str, rows: pd.DataFrame) -> dict:
    value = dict(kind="value", direction="lower", min_trials=10)
    return {
        "toy.flip": judge(rows["flip"], null=THRESHOLD, **value),
        "toy.flat": judge(rows["flat"], null=2.0, **value),
    }


INPUTS = (Input("x", 0.3, 0.0, 1.0), Input("y", 0.5, 0.0, 1.0))
SPEC = MapSpec({"toy.flip": "g", "toy.flat": "g"}, INPUTS, _experiment, _statistics, _judge)


@pytest.fixture(autouse=True)
def _reset_calls():
    CALLS.update(n=0, stop_at=None)


def _map(tmp_path=None, **kw):
    engine = {"n_jobs": 1, "progress": False}
    if tmp_path is not None:
        engine["cache_dir"] = tmp_path
    args = dict(n_screen=10, n_sweep=30, sweep_size=9, min_shift=0.05, engine=engine)
    return robustness_map(SPEC, 3, **{**args, **kw})


def test_a_flip_is_conditional_with_its_threshold_within_a_grid_step():
    table, _ = _map()
    summary = claim_summary(table, INPUTS).set_index("id")
    assert summary.at["toy.flip", "robustness"] == "conditional"
    assert summary.at["toy.flip", "depends_on"] == "x"
    sweep = table[(table["claim"] == "toy.flip") & (table["stage"] == "sweep")]
    values = np.sort(sweep["value"].to_numpy())
    step = float(np.max(np.diff(values)))
    below = sweep.loc[sweep["verdict"] == "reproduced", "value"].max()
    above = sweep.loc[sweep["verdict"] != "reproduced", "value"].min()
    assert below < THRESHOLD <= above
    assert above - below <= step + 1e-12
    assert "reproduced -> not reproduced between" in summary.at["toy.flip", "thresholds"]


def test_a_claim_judged_otherwise_on_its_own_trials_is_conditional_and_says_both():
    table, _ = _map()
    base = table[(table["claim"] == "toy.flat") & (table["stage"] == "base")].iloc[0]
    other = "direction only" if base["verdict"] != "direction only" else "reproduced"
    same = claim_summary(table, INPUTS, verdicts={"toy.flat": base["verdict"]}).set_index("id")
    assert same.at["toy.flat", "robustness"] == "robust"
    summary = claim_summary(table, INPUTS, verdicts={"toy.flat": other}).set_index("id")
    assert summary.at["toy.flat", "robustness"] == "conditional"
    assert summary.at["toy.flat", "verdicts"].split("; ")[:2] == [other, base["verdict"]]
    sentence = summary.at["toy.flat", "sentence"]
    assert sentence.startswith(f"toy.flat is {other} at the scenario's values on its own trials, ")
    assert f"{base['verdict']} on the {base['n']} trials of the map's point" in sentence


def test_a_flat_claim_is_robust_and_an_unused_input_does_not_matter():
    table, _ = _map()
    summary = claim_summary(table, INPUTS).set_index("id")
    assert summary.at["toy.flat", "robustness"] == "robust"
    assert summary.at["toy.flat", "depends_on"] == ""
    screen = table[(table["stage"] == "screen") & (table["input"] == "y")]
    assert set(screen["matters"]) == {"no"}
    assert not (table["stage"] == "sweep").loc[table["input"] == "y"].any()


def test_the_same_trials_run_at_every_point():
    _, trials = _map()
    flip = trials[trials["claim"] == "toy.flip"].copy()
    x = flip["value"].where(flip["input"] == "x", 0.3)
    flip["noise"] = flip["statistic"] - x
    per_trial = flip[flip["trial"] < 10].groupby("trial")["noise"]
    assert float(per_trial.agg(np.ptp).max()) < 1e-12  # the same draw at every value of x
    assert float(per_trial.mean().std()) > 1e-3  # and different draws in different trials


def test_an_interrupted_map_goes_on_where_it_stopped(tmp_path):
    full, _ = _map(tmp_path / "whole")
    total = CALLS["n"]
    CALLS.update(n=0, stop_at=total // 2)
    with pytest.raises(KeyboardInterrupt):
        _map(tmp_path / "cut")
    done = CALLS["n"] - 1  # the call that raised did not finish
    CALLS.update(n=0, stop_at=None)
    resumed, _ = _map(tmp_path / "cut")
    assert CALLS["n"] == total - done
    pd.testing.assert_frame_equal(resumed, full)


def test_too_few_trials_are_refused_and_fewer_than_the_rule_are_noted():
    with pytest.raises(CalibrationError, match="n_screen 5 and n_sweep 30"):
        robustness_map(SPEC, 3, n_screen=5)
    table, _ = _map(n_screen=6, n_sweep=8)
    sentence = claim_summary(table, INPUTS).set_index("id").at["toy.flat", "sentence"]
    assert "N = 6 per screened end, 8 per judged point: below the rule" in sentence
    table, _ = _map()
    assert "below the rule" not in claim_summary(table, INPUTS).at[0, "sentence"]


def test_an_input_outside_its_range_is_refused():
    with pytest.raises(CalibrationError, match="input x: base 2.0"):
        Input("x", 2.0, 0.0, 1.0)


def test_ledger_inputs_take_assumed_scalars_and_vector_components():
    from calstudy.papers.dualarm.scenario import load_scenario

    inputs, skipped = ledger_inputs(load_scenario())
    labels = [i.label for i in inputs]
    assert "detection.sigma_px" not in labels  # derived
    assert "sensor.points_per_scan" in labels
    derived = [i.label for i in ledger_inputs(load_scenario(), ("derived",))[0]]
    assert "detection.sigma_px" in derived and "sensor.points_per_scan" not in derived
    assert "layout.world2base1_mm[0]" in labels
    assert "layout.world2base1_rotvec[0]" not in labels  # a range of one value: fixed
    assert "global_test.n_groups" not in labels  # paper
    count = next(i for i in inputs if i.label == "sensor.points_per_scan")
    assert count.integer and count.setting(250.4) == {"sensor.points_per_scan": 250}
    assert any(s.startswith("global_test.placement_offsets_mm") for s in skipped)


def test_points_where_the_chain_fails_are_named_and_not_taken_as_verdicts():
    def failing(group, setting, n_trials):
        scenario = {"x": 0.3, "y": 0.5, "fails_above": 0.9, **setting}
        return Experiment("toy", toy_trial, scenario, n_trials)

    spec = MapSpec(SPEC.claims, INPUTS, failing, _statistics, _judge)
    engine = {"n_jobs": 1, "progress": False}
    table, _ = robustness_map(spec, 3, sweep_size=9, engine=engine)
    failed = table[table["error"] != ""]
    assert set(failed["input"]) == {"x"} and failed["value"].min() > 0.9
    assert set(failed["verdict"]) == {"chain fails"}
    summary = claim_summary(table, INPUTS).set_index("id")
    assert summary.at["toy.flat", "verdicts"] == "reproduced"
    assert "the simulated chain cannot run at x 1" in summary.at["toy.flat", "sentence"]
    assert summary.at["toy.flip", "robustness"] == "conditional"


def test_a_sweep_keeps_the_screened_ends_exactly_and_once():
    values = Input("p", 0.72, 0.605677, 0.834323).sweep_values(5)
    assert values == [0.605677, 0.6628, 0.72, 0.7772, 0.834323]
    assert Input("n", 1000, 250, 4000, integer=True).sweep_values(5) == [250, 500, 1000, 2000, 4000]


def test_a_key_matches_itself_and_the_prefixes_it_lies_under():
    assert matches("poor_start.base_mm", ["poor_start."])
    assert matches("sensor.n_points", ["sensor.n_points"])
    assert not matches("sensor.n_points_max", ["sensor.n_points"])  # a key is not a prefix
    assert not matches("poor_start_x.base_mm", ["poor_start."])
    assert not matches("a.b", [])


def test_claims_are_assigned_by_what_they_read_and_an_unread_input_is_skipped():
    inputs = [Input("a.x", 1.0, 0.0, 2.0), Input("b.y", 1.0, 0.0, 2.0), Input("c", 1.0, 0.0, 2.0)]
    skipped: list[str] = []
    not_read = {"p": ("a.", "c"), "q": ("a.x", "b.", "c")}
    out = assign_claims(inputs, ["p", "q", "r"], not_read, skipped, {"r": ("b.",)})
    assert [(i.key, i.claims) for i in out] == [("b.y", ("p", "r"))]
    # a claim with no entry reads every input
    assert [i.claims for i in assign_claims(inputs[:1], ["s"], {}, [])] == [("s",)]
    assert skipped == ["a.x: read by no claim's computation", "c: read by no claim's computation"]


def test_a_calibrated_input_spans_its_uncertainty_by_the_bound_rule():
    # a keyword: low end no lower than half the value, ends as computed
    k = calibrated_input("drift_scale", 2.0, 0.05, 2.0, bounds="half")
    assert (k.base, k.low, k.high, k.kind, k.paper) == (2.0, 1.9, 2.1, "calibrated", 2.0)
    assert calibrated_input("drift_scale", 2.0, 0.8, bounds="half").low == 1.0
    assert "± 2 standard uncertainties (0.05)" in k.paper_note
    # a ledger input: the ends to 4 digits, within its ledger range
    f = Input("sensor.optics.f_number", 5.0, 2.0, 16.0, "calibrated")
    c = calibrated_input(f, 4.0, 0.123456)
    assert (c.base, c.low, c.high, c.paper) == (4.0, 3.753, 4.247, 4.0)
    assert (calibrated_input(f, 4.0, 3.0).low, calibrated_input(f, 4.0, 3.0).high) == (2.0, 10.0)
    assert (calibrated_input(f, 10.0, 4.0).low, calibrated_input(f, 10.0, 4.0).high) == (2.0, 16.0)
    none = calibrated_input(f, 4.0, None)
    assert (none.base, none.low, none.high, none.paper) == (4.0, 2.0, 16.0, None)
    with pytest.raises(CalibrationError, match=r"f_number calibrated to 40.0: outside"):
        calibrated_input(f, 40.0, 0.1)
    with pytest.raises(CalibrationError, match="bounds 'ledger' of calibrated input 'drift_scale'"):
        calibrated_input("drift_scale", 2.0, 0.05)


def test_only_selects_inputs_and_refuses_one_the_map_does_not_screen():
    inputs = [Input("a.x", 1.0, 0.0, 2.0), Input("b.y", 1.0, 0.0, 2.0)]
    assert select_inputs(inputs, (), "toy scenario") == inputs
    assert select_inputs(inputs, ["b.y"], "toy scenario") == inputs[1:]
    with pytest.raises(CalibrationError, match=r"\['c.z'\] are not screened inputs of the toy"):
        select_inputs(inputs, ["c.z", "a.x"], "toy scenario")


def test_a_papers_spec_screens_its_ledger_and_extra_inputs_for_their_readers():
    from calstudy.papers.dualarm.scenario import load_scenario

    scn = load_scenario()
    extra = [Input("drift_scale", 2.0, 1.0, 3.0, "calibrated")]
    unused = {"sensor.points_per_scan": "read only by another route"}
    claims = {"p": "g", "q": "g"}
    not_read = {"p": ("sensor.", "drift_scale"), "q": ("layout.",)}
    inputs, skipped = screened_inputs(scn, claims, not_read, extra=extra, unused=unused)
    by_key = {i.label: i.claims for i in inputs}
    assert by_key["drift_scale"] == ("q",) and list(by_key)[-1] == "drift_scale"
    assert by_key["layout.world2base1_mm[0]"] == ("p",)
    assert "sensor.points_per_scan" not in by_key
    assert "sensor.points_per_scan: read only by another route" in skipped
    assert [i.label for i in inputs] == [
        i.label for i in assign_claims(ledger_inputs(scn)[0] + extra, claims, not_read, [])
        if i.key not in unused
    ]
    spec = paper_spec(claims, (inputs, skipped), None, None, None, only=["drift_scale"],
                      scenario="toy scenario")
    assert [i.key for i in spec.inputs] == ["drift_scale"] and spec.skipped == tuple(skipped)
    with pytest.raises(CalibrationError, match=r"\['c.z'\] are not screened inputs of the toy"):
        paper_spec(claims, (inputs, skipped), None, None, None, only=["c.z"], scenario="toy")
