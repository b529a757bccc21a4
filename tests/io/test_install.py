"""``pip install .`` gives a library that works outside the checkout: its data ship with it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from calstudy.core.paths import REPO_ROOT


def test_installed_package_loads_a_scenario_outside_the_checkout(tmp_path):
    # build from a copy, so no build/ folder of an earlier run (or of the checkout) is reused
    source = tmp_path / "source"
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info")
    shutil.copytree(REPO_ROOT / "src", source / "src", symlinks=True, ignore=ignore)
    shutil.copytree(REPO_ROOT / "data", source / "data", ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO_ROOT / name, source / name)
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--quiet",
         "--target", str(target), str(source)],
        check=True,
        cwd=tmp_path,
    )
    assert (target / "calstudy" / "_data" / "claims.csv").is_file()
    assert not (target / "calstudy" / "_data").is_symlink()
    script = (
        "import calstudy, pathlib\n"
        "from calstudy.core.paths import DATA_DIR, IN_CHECKOUT\n"
        "from calstudy.models.robots import load_robot\n"
        "from calstudy.claims import claim_ids\n"
        "print(calstudy.__file__); print(DATA_DIR); print(IN_CHECKOUT)\n"
        "print(len(load_robot('kuka_kr16_2').links)); print(len(claim_ids()))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(target)}
    out = subprocess.run(
        [sys.executable, "-c", script], check=True, cwd=tmp_path, env=env,
        capture_output=True, text=True,
    ).stdout.split("\n")
    assert Path(out[0]).is_relative_to(target), out[0]
    assert Path(out[1]).is_relative_to(target), out[1]
    assert out[2] == "False"
    assert int(out[3]) == 6 and int(out[4]) >= 18
