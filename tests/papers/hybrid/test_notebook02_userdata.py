"""Notebook 02 analyses a user's hybrid and CMM tables when both are given, and says so."""

import json

import numpy as np
import pandas as pd
import pytest
from support import NOTEBOOK_DIR, ci_parameters
from support import run as run_notebook

from calstudy.papers.hybrid import compensation, experiments, report, scenario, simulate_production

NOTEBOOK = NOTEBOOK_DIR / "02_hybrid_production_compensation.ipynb"


@pytest.mark.slow
def test_notebook02_runs_on_user_csvs(tmp_path):
    notebook = NOTEBOOK
    rng = np.random.default_rng(12)
    ps = experiments.calibrated_station(rng)
    run = simulate_production.simulate_run(ps, scenario.load_scenario(), rng)
    paths = {}
    for which, name in ((0, "hybrid"), (1, "cmm")):
        paths[name] = tmp_path / f"{name}.csv"
        compensation.measurements_frame(ps.features.ids, run, which).to_csv(
            paths[name], index=False
        )
    params = ci_parameters(notebook.stem)
    params |= {
        "hybrid_csv": str(paths["hybrid"]),
        "cmm_csv": str(paths["cmm"]),
        "results_dir": str(tmp_path / "out"),
    }
    run_notebook(notebook, params, tmp_path)
    out_nb = tmp_path / notebook.name
    text = json.dumps(json.loads(out_nb.read_text()))
    assert "Measurements: your tables." in text
    assert "one simulated station" not in text
    table = pd.read_csv(tmp_path / "out" / notebook.stem / "table1_station.csv")
    n = scenario.load_scenario().production.protocol.n_compensation
    expected = report.station_table1(run, n)
    assert table["count"].tolist() == expected["count"].tolist()
