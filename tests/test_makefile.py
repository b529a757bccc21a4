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


# ----------------------------------------------------------------------------------------------
# what an edit reruns: a copy of the repository whose executed notebooks are up to date

OLD, NEW = 1_600_000_000, 1_700_000_000  # modification times (s): inputs, executed notebooks
#: (touched file, the notebooks it reruns)
EDITS = [
    ("src/calstudy/papers/dualarm/report_design.py", {"05"}),
    ("src/calstudy/papers/hybrid/compensation.py", {"01", "02"}),
    ("src/calstudy/papers/selfcal/__init__.py", {"03"}),
    ("src/calstudy/selfcal/measured.py", {"03"}),
    ("data/selfcal/scenario.toml", {"03"}),
    ("data/dualarm/published.toml", {"05"}),
    ("data/robots/kuka_kr16_2.toml", {"01", "02", "03", "04"}),
    ("notebooks/06_handeye_your_cell.ipynb", {"06"}),
    ("src/calstudy/io/handeye_report.py", {"06"}),
    ("src/calstudy/handeye/calibrate.py", {"01", "02", "06"}),
    ("src/calstudy/estimators/axxb.py", {"01", "02", "04", "05", "06"}),
    ("src/calstudy/core/errors.py", {"01", "02", "03", "04", "05", "06"}),
    ("src/calstudy/io/book.py", set()),
]


@pytest.fixture(scope="module")
def checkout(tmp_path_factory):
    """A copy of the sources, data and notebooks, every notebook executed after its inputs."""
    root = tmp_path_factory.mktemp("checkout")
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info")
    for name in ("src", "data", "notebooks"):
        shutil.copytree(REPO_ROOT / name, root / name, symlinks=True, ignore=skip)
    for name in ("Makefile", "environment.txt", "pyproject.toml"):
        shutil.copy2(REPO_ROOT / name, root / name)
    for path in root.rglob("*"):
        os.utime(path, (OLD, OLD), follow_symlinks=False)
    stamp = root / ".venv" / ".installed"
    stamp.parent.mkdir()
    executed = root / "book" / "notebooks"
    executed.mkdir(parents=True)
    for path in [stamp, *(executed / p.name for p in (root / "notebooks").glob("*.ipynb"))]:
        path.touch()
        os.utime(path, (NEW, NEW))
    return root


def _reruns(root) -> set[str]:
    out = subprocess.run(
        ["make", "-n", "--no-print-directory", "NOTEBOOK_LINES=1", "run-notebooks"],
        cwd=root, capture_output=True, text=True, check=True,
    ).stdout
    return set(re.findall(r"papermill .*?notebooks/(\d\d)_\w+\.ipynb", out))


@pytest.mark.parametrize(("edited", "expected"), EDITS, ids=[e for e, _ in EDITS])
def test_an_edit_reruns_the_notebooks_that_depend_on_it(checkout, edited, expected):
    from calstudy.io.dependencies import label, notebook_inputs

    assert _reruns(checkout) == set(), "nothing changed, nothing runs"
    path = checkout / edited
    os.utime(path, (NEW + 10, NEW + 10))
    try:
        assert _reruns(checkout) == expected
    finally:
        os.utime(path, (OLD, OLD))
    # the notebooks whose run.json digest covers the file
    covered = {
        nb.name[:2]
        for nb in sorted((REPO_ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
        if edited in {label(p) for p in notebook_inputs(nb)}
    }
    assert covered == expected
    assert (checkout / "book" / "notebooks" / ".inputs.mk").is_file()


def test_without_the_rules_every_notebook_depends_on_everything(checkout):
    """If the rules cannot be written, make says so and falls back to the whole library."""
    rules = checkout / "book" / "notebooks" / ".inputs.mk"
    rules.unlink(missing_ok=True)
    path = checkout / "src" / "calstudy" / "io" / "book.py"
    os.utime(path, (NEW + 10, NEW + 10))
    try:
        run = subprocess.run(
            ["make", "-n", "PYTHON=false", "NOTEBOOK_LINES=1", "run-notebooks"],
            cwd=checkout, capture_output=True, text=True, check=True,
        )
    finally:
        os.utime(path, (OLD, OLD))
    assert "every notebook depends on all of src and data" in run.stderr
    assert len(set(re.findall(r"papermill .*?notebooks/(\d\d)_\w+\.ipynb", run.stdout))) == 6
    assert not rules.exists()
