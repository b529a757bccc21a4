"""Notebook 03 identifies a cell from a measurement folder when one is given, and says so."""

import json
import shutil

import pandas as pd
import pytest
from support import NOTEBOOK_DIR, REPRODUCIBLE_ENV, ci_parameters, run

from calstudy.core.paths import data_path
from calstudy.papers.selfcal.experiments import EXAMPLE_OUTLIERS

NOTEBOOK = NOTEBOOK_DIR / "03_selfcal_one_step_identification.ipynb"


@pytest.mark.slow
def test_notebook03_runs_on_the_example_measurements(tmp_path, monkeypatch):
    for key, value in REPRODUCIBLE_ENV.items():
        monkeypatch.setenv(key, value)
    folder = tmp_path / "my_cell"
    shutil.copytree(data_path("selfcal", "example_measurements"), folder)
    params = ci_parameters(NOTEBOOK.stem)
    params |= {"measurements_dir": str(folder), "results_dir": str(tmp_path / "out")}
    run(NOTEBOOK, params, tmp_path)
    out_nb = tmp_path / NOTEBOOK.name
    text = json.dumps(json.loads(out_nb.read_text()))
    assert f"calibrated from: {folder} (24 calibration, 10 validation measurements)" in text
    assert "covariance from the residual variances (per view and per sphere) (no noise" in text
    out = tmp_path / "out" / NOTEBOOK.stem
    residuals = pd.read_csv(out / "cell_residuals.csv")
    assert set(residuals.loc[residuals["outlier"], "pose"]) == {r + 1 for r, _ in EXAMPLE_OUTLIERS}
    summary = pd.read_csv(out / "cell_validation_summary.csv")
    assert bool(summary["meets_requirement"][0])
    base = pd.read_csv(out / "cell_base_parameters.csv")
    assert len(base) == 30
    versus = pd.read_csv(out / "cell_planned_vs_random.csv")
    assert versus["replications"][0] == params["n_pose_replications"]
    assert versus["measured_ratio_ci_low"][0] <= versus["measured_ratio_median"][0]
    assert "simulated re-measurements of your cell" in text
    for name in ("cell_suggested_poses.csv", "pose_selection.csv", "pose_selection.png"):
        assert (out / name).is_file(), name
