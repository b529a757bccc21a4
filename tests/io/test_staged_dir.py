"""Tests of calstudy.io.results.staged_dir: a result folder is swapped in whole or not at all,
and leftovers of a killed run are cleaned or restored."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from calstudy.io.results import staged_dir

# ----------------------------------------------------------------------------------------------
# staged_dir


def test_staged_dir_swaps_in_whole(tmp_path):
    final = tmp_path / "results" / "run"
    with staged_dir(final) as stage:
        (stage / "a.csv").write_text("1")
    assert sorted(p.name for p in final.iterdir()) == ["a.csv"]
    with staged_dir(final) as stage:
        assert stage.parent == final.parent and stage != final and not any(stage.iterdir())
        (stage / "b.csv").write_text("2")
        assert (final / "a.csv").read_text() == "1"  # untouched until the block ends
    assert sorted(p.name for p in final.iterdir()) == ["b.csv"]
    assert sorted(p.name for p in final.parent.iterdir()) == ["run"]


def test_staged_dir_exception_leaves_final_untouched(tmp_path):
    final = tmp_path / "run"
    final.mkdir()
    (final / "a.csv").write_text("old")
    with pytest.raises(KeyError), staged_dir(final) as stage:
        (stage / "a.csv").write_text("new")
        raise KeyError("half-way")
    assert (final / "a.csv").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_staged_dir_removes_leftovers_of_a_killed_run(tmp_path):
    final = tmp_path / "run"
    final.mkdir()
    (final / "a.csv").write_text("old")
    code = (
        "import os, signal, sys\n"
        "from calstudy.io.results import staged_dir\n"
        "with staged_dir(sys.argv[1]) as stage:\n"
        "    (stage / 'a.csv').write_text('half')\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    done = subprocess.run([sys.executable, "-c", code, str(final)], env=env, check=False)
    assert done.returncode == -signal.SIGKILL
    assert len(list(tmp_path.glob(".run.staging-*"))) == 1
    with staged_dir(final) as stage:
        assert [p.name for p in tmp_path.glob(".run.staging-*")] == [stage.name]
        (stage / "a.csv").write_text("new")
    assert (final / "a.csv").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_staged_dir_restores_old_results_of_a_run_killed_mid_swap(tmp_path):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    pid = int(dead.stdout)
    old = tmp_path / f".run.old-{pid}"
    old.mkdir()
    (old / "a.csv").write_text("old")
    (tmp_path / f".run.staging-{pid}").mkdir()
    with pytest.raises(RuntimeError), staged_dir(tmp_path / "run"):
        raise RuntimeError("this run fails too")
    assert (tmp_path / "run" / "a.csv").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
