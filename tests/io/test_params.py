# ruff: noqa: E501  (the table of bad values: one case per line)
"""Tests of calstudy.io.params: each notebook checks its parameters in the cell after its
parameters cell, against a schema that lists exactly the notebook's parameters; the defaults
and the CI values pass, values outside their domain are refused naming the parameter."""

from __future__ import annotations

import json

import papermill as pm
import pytest
from support import NOTEBOOK_DIR, REPRODUCIBLE_ENV, ci_parameters

from calstudy import CalibrationError
from calstudy.io.params import SCHEMAS, check_parameters

STEMS = sorted(p.stem for p in NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))


def _cells(stem):
    return json.loads((NOTEBOOK_DIR / f"{stem}.ipynb").read_text())["cells"]


def _defaults(stem) -> dict:
    cells = _cells(stem)
    cell = next(c for c in cells if "parameters" in c.get("metadata", {}).get("tags", []))
    namespace: dict = {}
    exec("".join(cell["source"]), namespace)
    return {k: v for k, v in namespace.items() if not k.startswith("__")}


def test_every_notebook_has_a_schema():
    assert STEMS and sorted(SCHEMAS) == STEMS


@pytest.mark.parametrize("stem", STEMS)
def test_schema_lists_the_parameters_and_the_next_cell_checks_them(stem):
    defaults = _defaults(stem)
    assert set(SCHEMAS[stem].model_fields) == set(defaults)
    cells = _cells(stem)
    i = next(i for i, c in enumerate(cells) if "parameters" in c["metadata"].get("tags", []))
    after = "".join(cells[i + 1]["source"])
    assert cells[i + 1]["cell_type"] == "code"
    assert f'check_parameters("{stem}", globals())' in after
    check_parameters(stem, defaults)
    check_parameters(stem, defaults | ci_parameters(stem))


# one or more bad values per notebook: (notebook, changes, message)
BAD = [
    ("01_hybrid_global_calibration", {"n_trials": 0}, r"n_trials = 0: must be >= 1"),
    ("01_hybrid_global_calibration", {"noise_levels_mm": [0.01, -0.02]}, r"noise_levels_mm #2 = -0.02: must be > 0"),
    ("01_hybrid_global_calibration", {"sensor_sigma_mm": [0.01, 0.02]}, "sensor_sigma_mm"),
    ("01_hybrid_global_calibration", {"misfit": "warn"}, r"misfit = 'warn': is not one of"),
    ("02_hybrid_production_compensation", {"n_values": [2, 10]}, r"n_values #1 = 2: must be >= 3"),
    ("02_hybrid_production_compensation", {"hybrid_csv": "mine.csv"}, "give both files"),
    ("03_selfcal_one_step_identification", {"requirement_mm": float("nan")}, "requirement_mm = nan: must be a finite number"),
    ("03_selfcal_one_step_identification", {"n_trials": 10**9}, r"n_trials = 1000000000: must be >= 1 and <= 100000"),
    ("04_binocular_correction", {"f_numbers": [4.0]}, r"f_numbers = \[4.0\]: must have at least 2 entries"),
    ("04_binocular_correction", {"defocus_tilts_deg": [0.0, 95.0]}, r"defocus_tilts_deg #2 = 95.0: must be < 90"),
    ("05_dualarm_global_calibration", {"sweep_poses": [2]}, r"sweep_poses #1 = 2: must be >= 3"),
    ("05_dualarm_global_calibration", {"n_jobs": 0}, r"n_jobs = 0: must be None or -1"),
    ("06_handeye_your_cell", {"n_trials": -5}, r"n_trials = -5: must be >= 0"),
    ("06_handeye_your_cell", {"sigma_rot_rad": -0.001}, r"sigma_rot_rad = -0.001: must be >= 0"),
    ("06_handeye_your_cell", {"sigma_rot_rad": 0.001}, r"sigma_rot_rad = 0.001 and sigma_trans_mm = 0.0: give both"),
    ("06_handeye_your_cell", {"setup": "eye-in-hand"}, "setup = 'eye-in-hand': is not one of"),
    ("06_handeye_your_cell", {"seed": 1.5}, "seed = 1.5"),
    ("06_handeye_your_cell", {"progress": "yes"}, "progress = 'yes'"),
]


@pytest.mark.parametrize(("stem", "changes", "match"), BAD, ids=[f"{b[0][:2]}-{next(iter(b[1]))}" for b in BAD])
def test_bad_parameters_are_refused(stem, changes, match):
    with pytest.raises(CalibrationError, match=f"notebook {stem} parameters: .*{match}"):
        check_parameters(stem, _defaults(stem) | changes)


def test_unknown_notebook_and_missing_parameter():
    with pytest.raises(CalibrationError, match="no parameter schema for notebook '07_mine'"):
        check_parameters("07_mine", {})
    defaults = _defaults("06_handeye_your_cell")
    del defaults["n_trials"]
    with pytest.raises(CalibrationError, match=r"parameter\(s\) \['n_trials'\] are not defined"):
        check_parameters("06_handeye_your_cell", defaults)


def test_notebook_stops_at_its_parameter_check(tmp_path, monkeypatch):
    """A bad value passed by papermill stops the run in the cell after the parameters, before
    any computation."""
    for key, value in REPRODUCIBLE_ENV.items():
        monkeypatch.setenv(key, value)
    stem = "06_handeye_your_cell"
    notebook = NOTEBOOK_DIR / f"{stem}.ipynb"
    params = ci_parameters(stem) | {"n_trials": -5, "results_dir": str(tmp_path / "out")}
    with pytest.raises(pm.PapermillExecutionError) as info:
        pm.execute_notebook(
            str(notebook),
            str(tmp_path / "out.ipynb"),
            parameters=params,
            cwd=str(notebook.parent),
            progress_bar=False,
        )
    assert info.value.ename == "CalibrationError"
    assert "n_trials = -5: must be >= 0" in info.value.evalue
    assert not (tmp_path / "out").exists()
