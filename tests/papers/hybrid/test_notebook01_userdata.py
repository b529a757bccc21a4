"""Notebook 01 calibrates from a user's CSV when one is given, and says so."""

import json

import numpy as np
import pandas as pd
import pytest
from support import NOTEBOOK_DIR, ci_parameters, run

from calstudy import handeye as he
from calstudy.handeye import sphere_csv
from calstudy.papers.hybrid import simulate

NOTEBOOK = NOTEBOOK_DIR / "01_hybrid_global_calibration.ipynb"


@pytest.mark.slow
def test_notebook01_runs_on_user_csv(tmp_path):
    rng = np.random.default_rng(11)
    station = simulate.make_station(rng)
    meas, _ = simulate.simulate_sphere_measurements(station, 4, 6, rng)
    csv = tmp_path / "my_cell.csv"
    sphere_csv.write_sphere_measurements(meas, csv)
    params = ci_parameters(NOTEBOOK.stem)
    # the simulated robot's pose error (a few tenths of a mm) is part of a centre's scatter
    params |= {
        "measurements_csv": str(csv),
        "sensor_sigma_mm": 0.3,
        "results_dir": str(tmp_path / "out"),
    }
    run(NOTEBOOK, params, tmp_path)
    out_nb = tmp_path / NOTEBOOK.name
    text = json.dumps(json.loads(out_nb.read_text()))
    assert f"Calibrated from: user measurements from {csv} (10 rows)" in text
    table = pd.read_csv(
        tmp_path / "out" / "01_hybrid_global_calibration" / "handeye_calibration.csv"
    )
    assert "truth" not in table.columns
    expected = he.sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    np.testing.assert_allclose(
        table["paper_method"].to_numpy()[:3], expected[:3, 3], rtol=2e-6, atol=1e-6
    )
