"""Tests of calstudy.io.runs: experiments run by named factories, rows and manifest stored, and
a stored trial recomputed from the manifest alone."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from mc_trials import toy_experiment

from calstudy import CalibrationError
from calstudy.core.montecarlo import trial_rows
from calstudy.io.runs import TRIALS_FLOAT_FORMAT, rebuild, run_experiments


def test_rows_and_manifest_rebuild_the_same_trials(tmp_path):
    frames = run_experiments(
        tmp_path, 7, [(toy_experiment, {"n_trials": 3, "scale": 2.0})], n_jobs=1, progress=False
    )
    stored = pd.read_csv(tmp_path / "trials_toy.csv")
    assert len(stored) == len(frames["toy"]) and list(stored.columns) == list(frames["toy"].columns)
    record = json.loads((tmp_path / "experiments.json").read_text())
    assert record["seed"] == 7
    entry = record["experiments"]["toy"]
    assert entry["factory"] == "mc_trials:toy_experiment" and entry["kwargs"]["scale"] == 2.0
    exp = rebuild(entry, extra=[toy_experiment])
    fresh = trial_rows(exp, 7, 1, 2)
    want = frames["toy"][(frames["toy"]["trial"] == 2) & (frames["toy"]["robot"] == "kuka")]
    pd.testing.assert_frame_equal(fresh, want.reset_index(drop=True))
    assert TRIALS_FLOAT_FORMAT % fresh["err"].iloc[0] in (tmp_path / "trials_toy.csv").read_text()


def test_bad_specs_are_refused(tmp_path):
    with pytest.raises(CalibrationError, match="module-level function"):
        run_experiments(tmp_path, 1, [(lambda: toy_experiment(), {})], n_jobs=1, progress=False)
    with pytest.raises(CalibrationError, match="not JSON-able"):
        run_experiments(tmp_path, 1, [(toy_experiment, {"scale": object()})], progress=False)
    spec = (toy_experiment, {"n_trials": 2})
    with pytest.raises(CalibrationError, match="two experiments are named 'toy'"):
        run_experiments(tmp_path, 1, [spec, spec], n_jobs=1, progress=False)


def test_registry_holds_every_committed_factory_and_each_resolves():
    """Every factory a committed experiments.json names is in the registry, and every registered
    name is a function of the study's own modules."""
    from calstudy.core.paths import RESULTS_DIR
    from calstudy.io.runs import FACTORIES, factory_name, load_factory

    named = {
        entry["factory"]
        for manifest in RESULTS_DIR.glob("*/experiments.json")
        for entry in json.loads(manifest.read_text())["experiments"].values()
    }
    assert named and named <= FACTORIES
    for name in FACTORIES:
        assert name.startswith("calstudy.")
        factory = load_factory(name)
        assert callable(factory) and factory_name(factory) == name


def test_own_factory_is_passed_not_imported():
    from calstudy.io.runs import load_factory

    assert load_factory("mc_trials:toy_experiment", extra=[toy_experiment]) is toy_experiment
    with pytest.raises(CalibrationError, match="'mc_trials:toy_experiment' is not one of"):
        load_factory("mc_trials:toy_experiment")
