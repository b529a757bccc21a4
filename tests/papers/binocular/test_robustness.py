"""The binocular robustness map: inputs set by their dotted keys, the inputs each claim reads, the
calibrated input over its uncertainty, a new ledger entry screened without code, the adapter
that judges a point by the report's rule."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import trial_rows
from calstudy.core.paths import RESULTS_DIR, data_path
from calstudy.core.robustness import point_setting
from calstudy.core.trialcache import TrialCache
from calstudy.papers.binocular import experiments, report, robustness

STEM = "04_binocular_correction"
F_NUMBER = "sensor.optics.f_number"


def test_overrides_reach_the_factory_and_key_the_trial_cache():
    a = robustness.robustness_experiment(n_trials=1)
    b = robustness.robustness_experiment(n_trials=1, overrides={"sensor.optics.rim_radius_mm": 9})
    assert b.scenario.scenario.sensor.optics.rim_radius_mm == 9 and a.name == b.name
    assert a.scenario.scenario.sensor.optics.rim_radius_mm != 9
    keys = [TrialCache(Path("/nonexistent"), e, 1, ["{}"]).dirs[0] for e in (a, b)]
    assert keys[0] != keys[1]
    with pytest.raises(
        CalibrationError, match=r"rim_radius_mm = 30.0: outside its plausible range \[8, 20\]"
    ):
        robustness.robustness_experiment(overrides={"sensor.optics.rim_radius_mm": 30})
    with pytest.raises(CalibrationError, match=r"group 'table5' is not one of"):
        robustness.robustness_experiment(group="table5")


def _statistics(group: str, setting: dict, n: int = 1) -> dict:
    spec = robustness.map_spec("")
    exp = spec.experiment(group, setting, n)
    return robustness.claim_statistics(group, _rows(exp, n))


def _rows(exp, n: int, seed: int = 1) -> pd.DataFrame:
    """The rows of the first ``n`` trials of ``exp``, as the engine returns them."""
    return pd.concat([trial_rows(exp, seed, 0, t) for t in range(n)], ignore_index=True)


def test_a_claim_does_not_read_the_inputs_it_is_not_screened_for():
    """Where the field regions lie leaves the chain's three statistics exactly as they are; the
    field check's ratio stays 1 at the end of an input it is not screened for; inputs they
    read move them (the checks can fail)."""
    spec = robustness.map_spec("")
    claims = {item.label: item.claims for item in spec.inputs}
    field_key = "station.field.faces_point_mm"
    assert claims[f"{field_key}[0]"] == ("binocular.field",)
    assert "binocular.field" not in claims["sensor.optics.f_number"]
    # the rim's geometry is read only under the rim mechanism; the study runs the paper's blur
    assert "sensor.optics.rim_radius_mm" not in claims
    assert any(
        s.startswith("sensor.optics.rim_radius_mm: read only under the rim") for s in spec.skipped
    )
    item = next(i for i in spec.inputs if i.label == f"{field_key}[2]")
    base = _statistics("chain", {})
    moved = _statistics("chain", item.setting(item.low))
    for cid, value in base.items():
        np.testing.assert_array_equal(moved[cid], value)
    read = _statistics("chain", {"sensor.optics.f_number": 2.5})
    assert all(not np.array_equal(read[c], base[c]) for c in base)
    field = _statistics("field", {"sensor.optics.f_number": 2.5})["binocular.field"]
    np.testing.assert_allclose(field, 1.0, atol=1e-9)


def test_the_adapter_gives_the_reports_verdicts():
    chain = experiments.binocular_experiment(
        n_trials=8, robot_scales=(1.0,), calibration_scales=(1.0,)
    )
    field = experiments.field_experiment(n_trials=6)
    trials, rows_field = _rows(chain, 8), _rows(field, 6)
    whole = report.verdicts(trials, rows_field)
    verdicts = {
        **robustness.judge_claims("chain", trials),
        **robustness.judge_claims("field", rows_field),
    }
    assert set(verdicts) == set(report.CLAIMS) == set(robustness.CLAIM_PARTS)
    stats = {
        **robustness.claim_statistics("chain", trials),
        **robustness.claim_statistics("field", rows_field),
    }
    for cid, v in verdicts.items():
        # the report adds to some notes what the map does not need; every figure is the same
        assert dataclasses.replace(v, note=".") == dataclasses.replace(whole[cid].claim, note=".")
        if np.isfinite(v.median):
            assert np.median(stats[cid]) == pytest.approx(v.median, rel=1e-12)


def test_a_calibrated_input_is_screened_over_its_uncertainty_within_its_ledger_range():
    inputs, skipped = robustness.map_inputs("", {F_NUMBER: (4.0, 0.25)})
    f = next(i for i in inputs if i.key == F_NUMBER)
    assert (f.kind, f.base, f.low, f.high, f.paper) == ("calibrated", 4.0, 3.5, 4.5, 4.0)
    f = next(i for i in robustness.map_inputs("", {F_NUMBER: (2.2, 0.25)})[0] if i.key == F_NUMBER)
    assert (f.low, f.high) == (2.0, 2.7)  # the ledger's lower end
    f = next(i for i in robustness.map_inputs("")[0] if i.key == F_NUMBER)
    assert (f.low, f.high, f.paper) == (2.0, 16.0, None) and "not calibrated" in f.paper_note
    assert any(s.startswith("station.field.centres_mm") for s in skipped)
    with pytest.raises(CalibrationError, match=r"focus_distance_mm'\] are not calibrated"):
        robustness.map_inputs("", {"sensor.optics.focus_distance_mm": (850.0, 10.0)})
    with pytest.raises(CalibrationError, match=r"f_number calibrated to 20.0: outside"):
        robustness.map_inputs("", {F_NUMBER: (20.0, 1.0)})


def test_the_calibrated_value_is_applied_at_every_point_and_a_file_value_is_the_base():
    spec = robustness.map_spec("", {F_NUMBER: (4.0, 0.25)})
    base = spec.experiment("chain", {}, 1)
    assert base.scenario.scenario.sensor.optics.f_number == 4.0
    point = spec.experiment("chain", {"sensor.optics.rim_radius_mm": 9.0}, 1)
    assert point.scenario.scenario.sensor.optics.f_number == 4.0
    plain = robustness.map_spec("")
    same = plain.experiment("chain", {"sensor.optics.rim_radius_mm": 12.0}, 1)  # the file's
    assert same.scenario_key == plain.experiment("chain", {}, 1).scenario_key


def test_a_new_ledger_entry_is_screened_without_a_change_of_code(tmp_path):
    """An input the study's files give as stated by the paper, marked assumed with a range in a
    folder of one's own, is screened for the chain's claims."""
    folder = tmp_path / "scenario"
    shutil.copytree(data_path("binocular"), folder)
    text = (folder / "sensor.toml").read_text()
    ref = next(line for line in text.splitlines() if line.startswith("provenance.pixel_pitch_mm"))
    text = text.replace(
        ref,
        'provenance.pixel_pitch_mm = { kind = "assumed", range = [0.004, 0.006], why = "a test" }',
    )
    (folder / "sensor.toml").write_text(text)
    keys = {i.key: i.claims for i in robustness.map_inputs(str(folder))[0]}
    assert keys["sensor.image.pixel_pitch_mm"] == tuple(
        c for c, g in robustness.CLAIM_PARTS.items() if g == "chain"
    )
    assert "sensor.image.pixel_pitch_mm" not in {i.key for i in robustness.map_inputs("")[0]}


def test_a_calibrated_input_no_claim_reads_is_accepted_and_not_screened(tmp_path):
    """A ledger input marked calibrated with a range but read only under the other defocus
    mechanism is a calibrated input of the ledger: its value is accepted, and it is not
    screened."""
    folder = tmp_path / "scenario"
    shutil.copytree(data_path("binocular"), folder)
    text = (folder / "sensor.toml").read_text()
    ref = next(line for line in text.splitlines() if line.startswith("provenance.rim_radius_mm"))
    text = text.replace(
        ref,
        'provenance.rim_radius_mm = { kind = "calibrated", target = "a test", code = "a:test", '
        "range = [8.0, 20.0] }",
    )
    (folder / "sensor.toml").write_text(text)
    rim = "sensor.optics.rim_radius_mm"
    inputs, skipped = robustness.map_inputs(str(folder), {rim: (10.0, 1.0)})
    assert rim not in {i.key for i in inputs}
    assert any(s.startswith(rim) and "rim mechanism" in s for s in skipped)
    with pytest.raises(CalibrationError, match=r"those are \['sensor.optics.f_number', 'sensor"):
        robustness.map_inputs(str(folder), {"sensor.optics.focus_distance_mm": (850.0, 10.0)})


def test_only_refuses_an_input_the_map_does_not_screen():
    with pytest.raises(CalibrationError, match=r"\['sensor.nothing'\]"):
        robustness.map_spec("", only=["sensor.nothing"])
    spec = robustness.map_spec("", only=["station.field.faces_point_mm"])
    assert [item.label for item in spec.inputs] == [
        f"station.field.faces_point_mm[{i}]" for i in range(3)
    ]


def _same_value(column: pd.Series, value) -> pd.Series:
    """Rows of ``column`` equal to ``value``, NaN (no second input) equal to NaN."""
    return column.isna() if pd.isna(value) else column.eq(value)


def spot_check(folder, count: int = 3) -> int:
    """Recompute ``count`` trial-0 statistics of the map in ``folder`` (points chosen by the
    seed) and compare them with the stored ones; the number of points checked."""
    params = json.loads((folder / "run.json").read_text())["parameters"]
    trials = pd.read_csv(
        folder / "trials_robustness.csv",
        keep_default_na=False,
        na_values={"value": [""], "value2": [""]},
    )
    calibrated = {F_NUMBER: (params["f_number"], None)}  # the ends are in the stored rows
    spec = robustness.map_spec(params["scenario_dir"], calibrated, params["robustness_inputs"])
    first = trials[trials["trial"] == 0].reset_index(drop=True)
    rng = np.random.default_rng(params["seed"])
    for _, row in first.iloc[rng.choice(len(first), size=count, replace=False)].iterrows():
        setting = point_setting(spec, [row["input"], row["input2"]], [row["value"], row["value2"]])
        group = robustness.CLAIM_PARTS[row["claim"]]
        rows = _rows(spec.experiment(group, setting, 1), 1, params["seed"])
        got = robustness.claim_statistics(group, rows)[row["claim"]][0]
        assert got == pytest.approx(row["statistic"], rel=1e-8), dict(row)
    return count


def test_spot_check_of_a_map(tmp_path):
    """A map written as the notebook writes it, recomputed point by point; a changed stored
    statistic is found."""
    from calstudy.core.robustness import robustness_map
    from calstudy.io import results
    from calstudy.io.runs import TRIALS_FLOAT_FORMAT

    inputs = ["sensor.exposure.bits"]  # its low end is the base: a point without overrides
    spec = robustness.map_spec("", {F_NUMBER: (4.0, 0.25)}, inputs)
    _, trials = robustness_map(
        spec,
        3,
        n_screen=6,
        n_sweep=6,
        sweep_size=2,
        engine={"n_jobs": 1, "cache_dir": tmp_path / "cache", "progress": False},
    )
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    params = {
        "seed": 3,
        "scenario_dir": "",
        "f_number": 4.0,
        "robustness_inputs": inputs,
    }
    (tmp_path / "run.json").write_text(json.dumps({"parameters": params}))
    n = len(trials[trials["trial"] == 0])
    assert spot_check(tmp_path, count=n) == n
    trials.loc[trials["trial"] == 0, "statistic"] *= 1.01
    results.write_table(trials, tmp_path / "trials_robustness.csv", TRIALS_FLOAT_FORMAT)
    with pytest.raises(AssertionError):
        spot_check(tmp_path, count=n)


def test_spot_check_of_the_committed_map():
    """A few stored trials of the committed map, chosen by the seed, recomputed and compared."""
    folder = RESULTS_DIR / STEM
    if not (folder / "trials_robustness.csv").is_file():
        pytest.skip("no committed robustness map yet")
    assert spot_check(folder) == 3
