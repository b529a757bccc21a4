"""Tests of calstudy.core.montecarlo: the same bytes for any worker count or scheduler, streams
keyed by (seed, experiment, trial), a resumable cache and atomic result folders."""

from __future__ import annotations

import dataclasses
import hashlib
import os
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
from mc_trials import (
    POINTS,
    SEED,
    Scenario,
    assert_same_bytes,
    bad_return,
    blas_threads_row,
    calls,
    clashing_row,
    expected_first,
    experiment,
    firsts,
    noisy_solve,
    one_row,
    opencv_threads_row,
    pid_row,
    stable_experiment,
)

from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import (
    Experiment,
    child_rng,
    run,
    streams,
    trial_rng,
    trial_rows,
)

# ----------------------------------------------------------------------------------------------
# rows and streams


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_trials_run_on_one_opencv_thread_and_the_setting_is_restored(n_jobs):
    """OpenCV's large filters round differently with another number of threads: every trial
    runs on one, whatever the machine, and the caller's setting is left as it was."""
    import cv2

    before = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        exp = Experiment("threads", opencv_threads_row, Scenario(), 4, [{}])
        df = run(exp, SEED, n_jobs=n_jobs, progress=False)
        assert df["opencv_threads"].tolist() == [1, 1, 1, 1]
        assert cv2.getNumThreads() == 3
    finally:
        cv2.setNumThreads(before)


def test_trials_and_their_spot_checks_run_on_one_blas_thread():
    """A multi-threaded BLAS splits its sums and moves the last digits of a trial's rows: the
    serial run, the workers and a recomputed trial (``trial_rows``) all use one thread."""
    from threadpoolctl import threadpool_info

    assert any(lib["user_api"] == "blas" for lib in threadpool_info())
    exp = Experiment("blas", blas_threads_row, Scenario(), 2, [{}])
    for n_jobs in (1, 2):
        assert run(exp, SEED, n_jobs=n_jobs, progress=False)["blas_threads"].tolist() == [1, 1]
    assert trial_rows(exp, SEED, 0, 1)["blas_threads"].tolist() == [1]


def test_rows_sorted_and_self_describing():
    exp = experiment(n_trials=5)
    df = run(exp, SEED, n_jobs=1, progress=False)
    assert list(df.columns) == ["sigma", "robot", "trial", "k", "err", "x0", "tag", "first"]
    assert df["trial"].dtype == np.int64
    assert isinstance(df.index, pd.RangeIndex)
    order = [
        (POINTS.index({"sigma": s, "robot": r}), t, k)
        for s, r, t, k in df[["sigma", "robot", "trial", "k"]].itertuples(index=False)
    ]
    assert order == sorted(order)
    for (_sigma, r, _trial), rows in df.groupby(["sigma", "robot", "trial"], sort=False):
        assert list(rows["k"]) == list(range(len(rows)))
        assert (rows["tag"] == r).all()
    assert df.groupby(["sigma"])["trial"].nunique().tolist() == [5, 5]


def test_rows_follow_trial_rng():
    df = run(experiment(n_trials=4), SEED, n_jobs=1, progress=False)
    for point in POINTS:
        rows = df[(df["sigma"] == point["sigma"]) & (df["k"] == 0)]
        assert rows["first"].tolist() == [expected_first(SEED, "solve", point, t) for t in range(4)]


def test_different_trials_names_and_seeds_get_different_streams():
    draws = [
        expected_first(seed, name, {}, t)
        for seed in (0, 1)
        for name in ("solve", "solve2")
        for t in range(20)
    ]
    assert len(set(draws)) == len(draws)


def test_every_point_of_a_sweep_sees_the_same_draws():
    """Common random numbers: the point does not key the stream, so a calibrated point value
    whose last bit differs on another machine draws the same numbers."""
    value = 0.7164706571379741
    nudged = np.nextafter(value, 1.0)
    for point in (*POINTS, {}, {"plate_sigma_px": value}, {"plate_sigma_px": nudged}):
        np.testing.assert_array_equal(
            trial_rng(3, "x", point, 2).random(4), trial_rng(3, "x", {}, 2).random(4)
        )
    df = run(experiment(n_trials=3), SEED, n_jobs=1, progress=False)
    firsts_by_point = df[df["k"] == 0].groupby("sigma")["first"].apply(list).tolist()
    assert firsts_by_point[0] == firsts_by_point[1]
    # the point is still checked
    with pytest.raises(CalibrationError, match="use a scalar"):
        trial_rng(3, "x", {"sigma": np.ones(2)}, 2)


def test_trial_rng_follows_documented_formula():
    def words(text):
        digest = hashlib.sha256(text.encode()).digest()
        return [int(w) for w in np.frombuffer(digest, dtype="<u4")]

    sequence = np.random.SeedSequence(entropy=11, spawn_key=(*words("noise_sweep"), 7))
    want = np.random.Generator(np.random.PCG64(sequence)).random(5)
    np.testing.assert_array_equal(trial_rng(11, "noise_sweep", {"sigma": 0.05}, 7).random(5), want)


def test_child_streams_do_not_depend_on_draws_elsewhere():
    rng = trial_rng(5, "station", {}, 4)
    survey = child_rng(rng, "survey").random(6)
    scans = child_rng(rng, "scans").random(6)
    rng.random(1000)  # the parent draws: a data-dependent number of draws
    np.testing.assert_array_equal(child_rng(rng, "survey").random(6), survey)
    np.testing.assert_array_equal(child_rng(rng, "scans").random(6), scans)
    assert not np.array_equal(survey, scans)
    # children of other trials, seeds and experiments differ; a grandchild differs from its parent
    others = [
        child_rng(trial_rng(5, "station", {}, 5), "survey").random(6),
        child_rng(trial_rng(6, "station", {}, 4), "survey").random(6),
        child_rng(trial_rng(5, "pilot", {}, 4), "survey").random(6),
        child_rng(child_rng(rng, "survey"), "survey").random(6),
        trial_rng(5, "station", {}, 4).random(6),
    ]
    assert len({tuple(x) for x in [survey, *others]}) == 6
    # a user's default_rng(seed) has a seed sequence too
    np.testing.assert_array_equal(
        child_rng(np.random.default_rng(3), "a").random(2),
        child_rng(np.random.default_rng(3), "a").random(2),
    )


@pytest.mark.parametrize(
    ("rng", "component", "match"),
    [
        (np.random.default_rng(1), "", "non-empty str"),
        (np.random.default_rng(1), 3, "non-empty str"),
        (np.random.Generator(np.random.PCG64(5)), "a", None),
        (np.random.RandomState(1), "a", "SeedSequence"),
    ],
)
def test_child_rng_refuses_what_it_cannot_derive(rng, component, match):
    if match is None:  # an integer seed goes through a SeedSequence too
        child_rng(rng, component)
        return
    with pytest.raises(CalibrationError, match=match):
        child_rng(rng, component)


def test_trial_rng_same_in_another_process():
    code = (
        "from calstudy.core.montecarlo import trial_rng;"
        "print(repr(trial_rng(5, 'handeye', {'sigma': 0.05}, 12).random(3).tolist()))"
    )
    env = {**os.environ, "PYTHONHASHSEED": "random", "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == repr(trial_rng(5, "handeye", {"sigma": 0.05}, 12).random(3).tolist())


def test_serial_and_two_workers_give_identical_bytes():
    exp = experiment(n_trials=12)
    serial = run(exp, SEED, n_jobs=1, progress=False)
    parallel = run(exp, SEED, n_jobs=2, progress=False)
    assert_same_bytes(parallel, serial)
    assert_same_bytes(
        run(exp, SEED + 1, n_jobs=1, progress=False), run(exp, SEED + 1, n_jobs=2, progress=False)
    )
    assert not serial.equals(run(exp, SEED + 1, n_jobs=1, progress=False))


def test_n_jobs_one_runs_in_process_and_default_uses_workers():
    exp = Experiment("where", pid_row, None, 8)
    assert set(run(exp, SEED, n_jobs=1, progress=False)["pid"]) == {os.getpid()}
    if (os.cpu_count() or 1) > 1:
        workers = run(exp, SEED, progress=False)
        assert os.getpid() not in set(workers["pid"])
        assert set(workers["blas"]) == {"1,1,1"}  # single-threaded BLAS in every worker


def test_dask_local_cluster_gives_identical_bytes():
    distributed = pytest.importorskip("distributed")
    exp = experiment(n_trials=4)
    serial = run(exp, SEED, n_jobs=1, progress=False)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        assert_same_bytes(run(exp, SEED, scheduler=client, progress=False), serial)
        assert_same_bytes(
            run(exp, SEED, scheduler=cluster.scheduler_address, progress=False), serial
        )


# ----------------------------------------------------------------------------------------------
# cache


def test_resume_computes_only_new_trials_and_returns_first_n(tmp_path):
    state, cache = tmp_path / "state", tmp_path / "cache"
    state.mkdir()
    point = {"sigma": 0.1}

    def exp(n):
        return experiment("grow", n_trials=n, points=[point], state_dir=str(state))

    run(exp(5), SEED, n_jobs=1, cache_dir=cache, progress=False)
    assert calls(state) == firsts("grow", point, range(5))
    eight = run(exp(8), SEED, n_jobs=1, cache_dir=cache, progress=False)
    assert calls(state) == firsts("grow", point, range(5, 8))
    assert_same_bytes(eight, run(exp(8), SEED, n_jobs=1, progress=False))
    assert len(calls(state)) == 8
    three = run(exp(3), SEED, n_jobs=2, cache_dir=cache, progress=False)
    assert calls(state) == []
    assert_same_bytes(three, eight[eight["trial"] < 3].reset_index(drop=True))
    assert_same_bytes(run(exp(8), SEED, n_jobs=2, cache_dir=cache, progress=False), eight)
    assert calls(state) == []


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_interrupted_run_resumes_without_recomputing(tmp_path, n_jobs):
    state, cache = tmp_path / "state", tmp_path / "cache"
    state.mkdir()
    point = {"sigma": 0.1}
    fail = expected_first(SEED, "interrupt", point, 3)
    exp = experiment(
        "interrupt",
        n_trials=6,
        points=[point],
        state_dir=str(state),
        fail_draw=fail,
        fail_once=True,
    )
    with pytest.raises(CalibrationError, match="trial 3 failed"):
        run(exp, SEED, n_jobs=n_jobs, cache_dir=cache, progress=False)
    first_calls = calls(state)
    stored = {int(p.stem.split("-")[1]) for p in cache.rglob("trial-*.json")}
    assert 3 not in stored
    resumed = run(exp, SEED, n_jobs=n_jobs, cache_dir=cache, progress=False)
    second_calls = calls(state)
    assert second_calls == firsts("interrupt", point, set(range(6)) - stored)
    if n_jobs == 1:
        assert first_calls == firsts("interrupt", point, range(4))
        assert stored == {0, 1, 2}
    plain = dataclasses.replace(exp, scenario=Scenario())
    assert_same_bytes(resumed, run(plain, SEED, n_jobs=1, progress=False))


def test_changed_key_recomputes(tmp_path):
    state, cache = tmp_path / "state", tmp_path / "cache"
    state.mkdir()
    exp = experiment("key", n_trials=3, points=[{}], state_dir=str(state))
    run(exp, SEED, n_jobs=1, cache_dir=cache, progress=False)
    assert len(calls(state)) == 3
    run(exp, SEED + 1, n_jobs=1, cache_dir=cache, progress=False)
    assert calls(state) == firsts("key", {}, range(3), seed=SEED + 1)
    run(exp, SEED, n_jobs=1, cache_dir=cache, progress=False)
    assert calls(state) == []
    scaled = dataclasses.replace(exp, scenario=dataclasses.replace(exp.scenario, scale=2.0))
    run(scaled, SEED, n_jobs=1, cache_dir=cache, progress=False)
    assert len(calls(state)) == 3
    for key in ("v1", "v2", "v1"):
        run(
            dataclasses.replace(exp, scenario_key=key),
            SEED,
            n_jobs=1,
            cache_dir=cache,
            progress=False,
        )
    assert len(calls(state)) == 6


def test_cache_key_is_the_same_in_another_process(tmp_path):
    state, cache = tmp_path / "state", tmp_path / "cache"
    state.mkdir()
    code = (
        "import sys\n"
        "from calstudy.core.montecarlo import run\n"
        "from mc_trials import stable_experiment\n"
        "run(stable_experiment(sys.argv[1]), 1, n_jobs=1, cache_dir=sys.argv[2], progress=False)\n"
    )
    env = {**os.environ, "PYTHONHASHSEED": "random", "PYTHONPATH": os.pathsep.join(sys.path)}
    subprocess.run([sys.executable, "-c", code, str(state), str(cache)], env=env, check=True)
    assert len(calls(state)) == 3
    run(stable_experiment(str(state)), 1, n_jobs=1, cache_dir=cache, progress=False)
    assert calls(state) == []


def test_stale_temporary_files_are_removed(tmp_path):
    folder = tmp_path / "cache" / "stale" / "somewhere"
    folder.mkdir(parents=True)
    stale, kept = folder / ".trial-000001.json.999.tmp", folder / "notes.txt"
    stale.write_bytes(b"half a record")
    kept.write_text("mine")
    an_hour_ago = time.time() - 3600
    os.utime(stale, (an_hour_ago, an_hour_ago))
    exp = Experiment("stale", one_row, None, 2)
    run(exp, SEED, n_jobs=1, cache_dir=tmp_path / "cache", progress=False)
    assert not stale.exists()
    assert kept.read_text() == "mine"
    assert list((tmp_path / "cache").rglob("*.tmp")) == []


def test_unstable_scenario_needs_a_key(tmp_path):
    exp = Experiment("opaque", one_row, object(), 2)
    with pytest.raises(CalibrationError, match="scenario_key"):
        run(exp, SEED, n_jobs=1, cache_dir=tmp_path, progress=False)
    keyed = dataclasses.replace(exp, scenario_key="opaque-v1")
    assert len(run(keyed, SEED, n_jobs=1, cache_dir=tmp_path, progress=False)) == 2
    with pytest.raises(CalibrationError, match="module-level"):
        run(
            Experiment("lam", lambda s, rng: {}, None, 1),
            SEED,
            n_jobs=1,
            cache_dir=tmp_path,
            progress=False,
        )


# ----------------------------------------------------------------------------------------------
# errors, validation, progress


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_trial_exception_names_experiment_point_and_trial(tmp_path, n_jobs):
    point = {"sigma": 0.05, "robot": "ur5"}  # trial 2 of every point draws alike: the first fails
    exp = experiment(
        "boom",
        n_trials=5,
        state_dir=str(tmp_path),
        fail_draw=expected_first(SEED, "boom", point, 2),
    )
    with pytest.raises(
        CalibrationError,
        match=r"experiment 'boom', point sigma=0.05 robot=ur5, trial 2 failed: ValueError: kaboom",
    ) as info:
        run(exp, SEED, n_jobs=n_jobs, progress=False)
    assert isinstance(info.value.__cause__, ValueError)
    assert str(info.value.__cause__) == "kaboom"


@pytest.mark.parametrize(
    ("trial", "points", "match"),
    [
        (bad_return, ({},), "returned a float"),
        (clashing_row, ({"sigma": 0.1},), r"column\(s\) \['sigma'\]"),
    ],
)
def test_bad_rows_are_reported(trial, points, match):
    with pytest.raises(CalibrationError, match=match):
        run(Experiment("rows", trial, None, 2, points), SEED, n_jobs=1, progress=False)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_trials": 0}, "n_trials must be at least 1, got 0"),
        ({"n_trials": 2.5}, "n_trials must be an integer"),
        ({"n_trials": True}, "n_trials must be an integer"),
        ({"name": ""}, "experiment name"),
        ({"name": "../up"}, "experiment name"),
        ({"points": {"sigma": 0.1}}, "got one mapping"),
        ({"points": []}, "non-empty sequence"),
        ({"points": [0.1, 0.2]}, r"points\[0\] must be a mapping"),
        ({"points": [{"sigma": 0.1}, {"s": 0.2}]}, "same keys"),
        ({"points": [{"sigma": 0.1}, {"sigma": 0.1}]}, r"points\[1\] repeats points\[0\]"),
        ({"points": [{"sigma": np.ones(2)}]}, "use a scalar"),
        ({"points": [{"trial": 1}]}, "trial index"),
        ({"trial": "noisy_solve"}, "callable"),
    ],
)
def test_experiment_validation(kwargs, match):
    args = {"name": "valid", "trial": noisy_solve, "scenario": Scenario(), "n_trials": 3, **kwargs}
    with pytest.raises(CalibrationError, match=match):
        Experiment(**args)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"seed": -1}, "seed must be a non-negative integer, got -1"),
        ({"seed": 1.5}, "seed must be a non-negative integer"),
        ({"n_jobs": 0}, "n_jobs"),
        ({"scheduler": 8786}, "scheduler must be"),
    ],
)
def test_run_validation(kwargs, match):
    args = {"seed": SEED, "n_jobs": 1, "progress": False, **kwargs}
    with pytest.raises(CalibrationError, match=match):
        run(Experiment("valid", one_row, None, 1), **args)


def test_progress_goes_to_stderr_only(capsys):
    exp = Experiment("prog", one_row, None, 3, [{"sigma": 0.1}, {"sigma": 0.3}])
    quiet = run(exp, SEED, n_jobs=1, progress=False)
    captured = capsys.readouterr()
    assert (captured.out, captured.err) == ("", "")
    loud = run(exp, SEED, n_jobs=1, progress=True)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "prog sigma=0.3" in captured.err and "6/6" in captured.err
    assert_same_bytes(loud, quiet)


def test_experiments_of_other_names_draw_other_streams():
    a = Experiment("a", one_row, None, 3)
    b = Experiment("b", one_row, None, 2)
    tables = {exp.name: run(exp, SEED, n_jobs=1, progress=False) for exp in (a, b)}
    assert list(tables["a"].columns) == ["trial", "u"]
    assert tables["a"]["u"].tolist() == [trial_rng(SEED, "a", {}, t).random() for t in range(3)]
    assert not np.isin(tables["b"]["u"], tables["a"]["u"]).any()


def test_streams_are_new_at_every_call_and_independent_of_draw_counts():
    rng = trial_rng(5, "station", {}, 4)
    first = [g.random(3) for g in streams(rng, "robot", "target")]
    rng.random(777)  # draws between calls change nothing; the call count does
    second = [g.random(3) for g in streams(rng, "robot", "target")]
    assert not np.array_equal(first[0], second[0]) and not np.array_equal(first[0], first[1])
    again = trial_rng(5, "station", {}, 4)
    np.testing.assert_array_equal(streams(again, "robot", "target")[0].random(3), first[0])
    # a fresh child of the same name replays its calls: paired draws
    a = streams(child_rng(rng, "station"), "robot")[0].random(3)
    b = streams(child_rng(rng, "station"), "robot")[0].random(3)
    np.testing.assert_array_equal(a, b)
    for bad in ((), ("a", "a")):
        with pytest.raises(CalibrationError, match="distinct component names"):
            streams(rng, *bad)
    with pytest.raises(CalibrationError, match="SeedSequence"):
        streams(np.random.RandomState(1), "a")


def test_the_failure_reported_is_the_first_trial_whatever_finishes_first():
    """Every trial fails; trial 0 takes longest, so a worker finishes another one first. The
    message names trial 0 all the same (the same text with any number of workers)."""
    from mc_trials import slow_first_failure

    from calstudy.core.montecarlo import Experiment, run, trial_rng

    seed = next(
        s for s in range(100)
        if trial_rng(s, "fails", {}, 0).uniform() > 0.5
        and trial_rng(s, "fails", {}, 1).uniform() <= 0.5
    )
    exp = Experiment("fails", slow_first_failure, None, 4)
    for n_jobs in (1, 2):
        with pytest.raises(CalibrationError, match=r"trial 0 failed: ValueError"):
            run(exp, seed, n_jobs=n_jobs, progress=False)
