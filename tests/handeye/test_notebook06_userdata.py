"""Notebook 06 calibrates from a user's pose list when one is given, and says so."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from support import ci_parameters, run

from calstudy.core import geometry as geo
from calstudy.handeye.posefile import write_pose_list
from calstudy.handeye.simulate import simulate_cell

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOK = ROOT / "notebooks" / "06_handeye_your_cell.ipynb"


@pytest.mark.slow
def test_notebook06_runs_on_user_pose_list(tmp_path):
    cell = simulate_cell(np.random.default_rng(3), 12, 1e-3, 0.2)
    csv = write_pose_list(
        tmp_path / "my_cell.csv",
        cell.flange2base,
        cell.target2camera,
        robot_convention="base2gripper",
        unit="m",
    )
    params = ci_parameters(NOTEBOOK.stem) | {
        "poses_csv": str(csv),
        "results_dir": str(tmp_path / "out"),
    }
    run(NOTEBOOK, params, tmp_path)
    out_nb = tmp_path / NOTEBOOK.name
    text = json.dumps(json.loads(out_nb.read_text()))
    assert f"calibrated from: user pose list {csv} (12 poses)" in text
    out = tmp_path / "out" / NOTEBOOK.stem
    methods = pd.read_csv(out / "methods.csv")
    assert "rot_err_deg" not in methods.columns  # no truth for a user's cell
    est = pd.read_csv(out / "estimate.csv").set_index(["transform", "parameter"])
    t = [est.loc[("camera2flange", f"t{a}_mm"), "value"] for a in "xyz"]
    assert geo.translation_error(geo.make_transform(np.eye(3), t), cell.camera2flange) < 1.5
