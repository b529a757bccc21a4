"""How `make reproduce` schedules the notebooks: every notebook exactly once, longest first, each
of the notebooks at work given its share of the cores (read from `make -n`, nothing runs)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import pytest
from support import REPO_ROOT

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs GNU make")


def _planned(*variables: str) -> list[tuple[str, str]]:
    """(LOKY_MAX_CPU_COUNT default, notebook stem) of each papermill run, in the planned order."""
    out = subprocess.run(
        ["make", "-n", "-B", "--no-print-directory", *variables, "run-notebooks"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return re.findall(
        r"LOKY_MAX_CPU_COUNT=\$\{LOKY_MAX_CPU_COUNT:-(\d+)\} \S*papermill .*?"
        r"notebooks/(\d\d_\w+)\.ipynb",
        out,
    )


def _makefile_order() -> list[str]:
    text = (REPO_ROOT / "Makefile").read_text()
    block = re.search(r"^LONGEST_FIRST := ((?:.*\\\n)*.*)$", text, re.MULTILINE)
    assert block, "the Makefile lists its notebooks in LONGEST_FIRST"
    return block.group(1).replace("\\\n", " ").split()


def test_every_notebook_runs_once_in_the_listed_order():
    stems = sorted(p.stem for p in (REPO_ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
    planned = [stem for _, stem in _planned("NOTEBOOK_LINES=1")]
    assert sorted(planned) == stems, "each notebook is run exactly once"
    listed = [s for s in _makefile_order() if s in stems]
    assert planned[: len(listed)] == listed, "the listed notebooks start longest first"
    assert set(_makefile_order()) <= set(stems), "LONGEST_FIRST names a notebook that is gone"


@pytest.mark.parametrize("jobs", [1, 2])
def test_each_notebook_gets_its_share_of_the_cores(jobs):
    cores = os.cpu_count() or 1
    shares = {int(share) for share, _ in _planned("NOTEBOOK_LINES=1", f"NOTEBOOK_JOBS={jobs}")}
    assert shares == {max(1, cores // jobs)}


def _fake_path(tmp_path, uid: int) -> str:
    """A PATH with bash and a fake ``id`` reporting ``uid`` and no Chromium."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("bash", "make"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    fake_id = bin_dir / "id"
    fake_id.write_text(f"#!/bin/sh\necho {uid}\n")
    fake_id.chmod(0o755)
    return str(bin_dir)


def test_make_browser_without_chromium_and_root_stops_with_the_command(tmp_path):
    out = subprocess.run(
        ["make", "--no-print-directory", "browser"],
        cwd=REPO_ROOT,
        env={"PATH": _fake_path(tmp_path, 1000), "HOME": str(tmp_path)},
        capture_output=True,
        text=True,
    )
    assert out.returncode != 0
    assert "apt-get install -y -qq chromium" in out.stderr
    assert "found none" in out.stderr


def test_make_browser_accepts_a_named_chromium(tmp_path):
    env = {"PATH": _fake_path(tmp_path, 1000), "HOME": str(tmp_path), "CHROMIUM": "bash"}
    out = subprocess.run(
        ["make", "--no-print-directory", "browser"], cwd=REPO_ROOT, env=env, capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
