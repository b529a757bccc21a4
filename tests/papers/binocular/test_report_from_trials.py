"""The committed results of notebook 04 follow from its committed trial rows: every table and the
claims and controls are recomputed by the report functions (no simulation) and compared."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from support import assert_same_table

from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import read_claims
from calstudy.papers.binocular import report, report_mechanisms

STEM = "04_binocular_correction"
OUT = RESULTS_DIR / STEM


@pytest.fixture(scope="module")
def frames():
    if not (OUT / "trials_binocular.csv").is_file():
        pytest.skip("results/04_binocular_correction has not been regenerated with the engine yet")
    return pd.read_csv(OUT / "trials_binocular.csv"), pd.read_csv(OUT / "trials_field.csv")


def _run() -> dict:
    return json.loads((OUT / "run.json").read_text())["parameters"]


def _alternatives() -> dict:
    """The other mechanisms' trials under the labels the notebook gives them."""
    run = _run()
    return {
        f"{report_mechanisms.MECHANISM_LABELS[m]} (f/{run['f_numbers_fitted'][m]:.3g})": (
            pd.read_csv(OUT / f"trials_binocular_{m}.csv")
        )
        for m in run["mechanisms"][1:]
    }


def _same(got: pd.DataFrame, name: str) -> None:
    assert_same_table(got, OUT / f"{name}.csv")


def test_tables(frames):
    trials, field = frames
    _same(report.distance_table(trials, "table2"), "table2")
    _same(report.distance_table(trials, "table3"), "table3")
    _same(report.handeye_table(trials), "table4")
    _same(report.field_table(field), "table5")
    _same(report.rmse_summary(trials, field), "rmse_summary")
    _same(report.sweep_table(trials, "robot"), "robot_sweep")
    _same(report.sweep_table(trials, "calibration"), "calibration_sweep")


def test_claims_and_controls(frames):
    trials, field = frames
    claims, controls = report.claim_rows(trials, field, STEM, _alternatives())
    want = read_claims(OUT / "claims.csv")
    got = pd.DataFrame([c.__dict__ for c in claims])
    assert got["verdict"].tolist() == want["verdict"].tolist()
    assert got["note"].tolist() == want["note"].fillna("").tolist()
    for col in ("reproduced", "ci_low", "ci_high", "replication_rate"):
        pd.testing.assert_series_equal(got[col], want[col], rtol=2e-5, check_dtype=False)
    _same(pd.DataFrame(controls), "controls")


def test_optics_sweeps_and_the_joint_calibration():
    if not (OUT / "trials_optics_sweep.csv").is_file():
        pytest.skip("results/04_binocular_correction has no optics sweeps yet")
    run = _run()
    headline = run["mechanisms"][0]
    sweeps = {
        m: pd.read_csv(
            OUT / ("trials_fnumber_sweep.csv" if m == headline else f"trials_fnumber_sweep_{m}.csv")
        )
        for m in run["mechanisms"]
    }
    osweep = pd.read_csv(OUT / "trials_optics_sweep.csv")
    fnumber = report.optics_sweep_table(sweeps[headline], "f_number")
    _same(fnumber, "fnumber_sweep")
    _same(report.optics_sweep_table(osweep, "focus_distance_mm"), "focus_distance_sweep")
    _same(report.optics_sweep_table(osweep, "dot_diameter_mm"), "dot_diameter_sweep")
    assert (fnumber["n"] >= 30).all()
    geometries = [tuple(g) for g in run["rim_geometries_mm"]]
    fits = {
        (m, g): report_mechanisms.fit_mechanism(sweeps[m], g)
        for m in run["mechanisms"]
        for g in (geometries if m == "rim" else [None])
    }
    _same(report_mechanisms.joint_table(fits), "joint_calibration")
    assert run["f_number"] == round(fits[(headline, None)].value, 2)


def test_mechanism_verdicts(frames):
    trials, _ = frames
    run = _run()
    headline = run["mechanisms"][0]
    runs = {headline: (run["f_numbers_fitted"][headline], trials)}
    for label, m in zip(_alternatives().values(), run["mechanisms"][1:], strict=True):
        runs[m] = (run["f_numbers_fitted"][m], label)
    _same(report_mechanisms.mechanism_table(runs), "mechanism_verdicts")
