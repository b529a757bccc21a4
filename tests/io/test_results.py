"""Tests of the results layer: atomic, deterministic files; verdicts; the claims page."""

from __future__ import annotations

import base64
import json

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy.claims import (
    CLAIM_COLUMNS,
    ClaimRow,
    Judged,
    claim_ids,
    claim_register,
    claim_row,
    control_rows,
)
from calstudy.core.paths import DATA_DIR, RESULTS_DIR
from calstudy.core.stats import median_and_spread, rmse
from calstudy.core.verdicts import judge_controls
from calstudy.io.results import (
    PINNED_PACKAGES,
    aggregate_claims,
    notebook_writers,
    read_claims,
    source_digest,
    write_claims,
    write_controls,
    write_figure,
    write_run_json,
    write_table,
)

REGISTER_IDS = [
    "hybrid.handeye",
    "hybrid.stationary",
    "hybrid.rps",
    "hybrid.systematic",
    "hybrid.deviation",
    "hybrid.correlation",
    "selfcal.identification",
    "selfcal.convergence",
    "selfcal.robot_params",
    "selfcal.residual",
    "selfcal.one_step",
    "binocular.coc",
    "binocular.observed_error",
    "binocular.transformation",
    "binocular.field",
    "dualarm.icp",
    "dualarm.global",
    "dualarm.vs_circular",
]


def leftovers(folder):
    """Temporary files an atomic write would leave behind if it failed to clean up."""
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]


def sample_table():
    return pd.DataFrame(
        {"trial": [0, 1, 2], "error_mm": [0.1234567891, 1e-9, 12345.678], "name": ["a", "b", ""]}
    )


def make_figure():
    fig, ax = plt.subplots(figsize=(3, 2))
    x = np.linspace(0.0, 1.0, 50)
    ax.plot(x, x**2, label="x squared")
    ax.set_xlabel("x (mm)")
    ax.legend()
    return fig


def row(claim_id="binocular.coc", verdict="reproduced", notebook="03_binocular"):
    return ClaimRow(
        id=claim_id,
        published="0.041/0.049",
        reproduced=0.84,
        ci_low=0.8,
        ci_high=0.88,
        unit="ratio",
        verdict=verdict,
        notebook=notebook,
        note="a note",
    )


# ----------------------------------------------------------------------------------------------
# tables, figures, run.json


def test_write_table_format_and_bytes(tmp_path):
    path = write_table(sample_table(), tmp_path / "sub" / "t.csv")
    first = path.read_bytes()
    assert first == b"trial,error_mm,name\n0,0.123457,a\n1,1e-09,b\n2,12345.7,\n"
    write_table(sample_table(), path)
    assert path.read_bytes() == first
    assert leftovers(path.parent) == []
    assert (path.stat().st_mode & 0o777) == 0o644


def test_write_table_is_atomic(tmp_path, monkeypatch):
    path = write_table(sample_table(), tmp_path / "t.csv")
    before = path.read_bytes()

    def broken(self, target, *args, **kwargs):
        with open(target, "w") as f:
            f.write("half a ta")
        raise OSError("disk full")

    monkeypatch.setattr(pd.DataFrame, "to_csv", broken)
    with pytest.raises(OSError, match="disk full"):
        write_table(sample_table(), path)
    assert path.read_bytes() == before
    assert leftovers(tmp_path) == []


def test_write_table_rejects_non_frame(tmp_path):
    with pytest.raises(CalibrationError, match="DataFrame"):
        write_table([[1, 2]], tmp_path / "t.csv")


def test_write_figure_deterministic_and_closed(tmp_path):
    fig = make_figure()
    a = write_figure(fig, tmp_path / "a.png")
    assert not plt.fignum_exists(fig.number)
    b = write_figure(make_figure(), tmp_path / "b.png")
    write_figure(make_figure(), a)
    data = a.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data == b.read_bytes()
    assert b"Software" not in data and b"matplotlib" not in data.lower()
    assert leftovers(tmp_path) == []


def test_notebook_writers_write_into_the_folder_and_show_the_saved_file(tmp_path, monkeypatch):
    shown = []
    monkeypatch.setattr("IPython.display.display", lambda obj, **kw: shown.append(obj))
    save_table, show_figure = notebook_writers(tmp_path / "nb")
    df = sample_table()
    assert save_table(df, "t") is df
    assert (tmp_path / "nb" / "t.csv").read_bytes() == write_table(
        df, tmp_path / "t.csv"
    ).read_bytes()
    # a cell ending with it shows no path; the image carries its description as alt text
    assert show_figure(make_figure(), "f", alt="A line rising from 0 to 1.") is None
    png = base64.b64encode((tmp_path / "nb" / "f.png").read_bytes()).decode()
    assert png in shown[0]["text/html"]
    assert 'alt="A line rising from 0 to 1."' in shown[0]["text/html"]
    assert str(tmp_path) not in str(shown[0])
    # without one, the alt text is read from the figure's labels, never its path
    show_figure(make_figure(), "noise_sweep")
    assert 'alt="Figure &quot;noise sweep&quot;: x (mm)"' in shown[1]["text/html"]


def test_write_figure_is_atomic(tmp_path, monkeypatch):
    path = write_figure(make_figure(), tmp_path / "f.png")
    before = path.read_bytes()
    fig = make_figure()

    def broken(*args, **kwargs):
        raise RuntimeError("renderer died")

    monkeypatch.setattr(fig, "savefig", broken)
    with pytest.raises(RuntimeError, match="renderer died"):
        write_figure(fig, path)
    assert path.read_bytes() == before
    assert leftovers(tmp_path) == []
    assert not plt.fignum_exists(fig.number)


def test_run_json_content_and_bytes(tmp_path):
    notebook = tmp_path / "99_demo.ipynb"
    notebook.write_text("{}")
    params = {"seed": np.int64(7), "noise_mm": np.float64(0.05), "results_dir": "", "n": 3,
              "n_jobs": 2, "scheduler": "tcp://head:8786", "cache_dir": "/x", "progress": True}
    path = write_run_json(tmp_path / "out", params, seed=np.int64(7), notebook=notebook)
    first = path.read_bytes()
    assert first.endswith(b"}\n")
    record = json.loads(first)
    assert list(record) == sorted(record)
    assert record["seed"] == 7
    assert record["notebook"] == "99_demo"
    # how the run was executed is left out: same bytes on one core, two, or a cluster
    assert record["parameters"] == {"n": 3, "noise_mm": 0.05, "seed": 7}
    assert set(record["versions"]) == set(PINNED_PACKAGES)
    assert record["versions"]["numpy"] == np.__version__
    assert record["source_digest"].startswith("sha256:")
    assert not {"commit", "git", "time", "timestamp", "date"} & set(record)
    write_run_json(tmp_path / "out", params, seed=7, notebook=notebook)
    assert path.read_bytes() == first
    assert leftovers(path.parent) == []


def test_source_digest_follows_the_notebook(tmp_path):
    notebook = tmp_path / "99_demo.ipynb"
    notebook.write_text("{}")
    d1 = source_digest(notebook)
    assert source_digest(notebook) == d1
    notebook.write_text('{"cells": []}')
    assert source_digest(notebook) != d1
    assert source_digest() != d1


def test_run_json_rejects_bad_input(tmp_path):
    with pytest.raises(CalibrationError, match="seed"):
        write_run_json(tmp_path, {}, seed=1.5)
    with pytest.raises(CalibrationError, match="JSON"):
        write_run_json(tmp_path, {"f": object()}, seed=1)
    with pytest.raises(FileNotFoundError, match="notebook"):
        write_run_json(tmp_path, {}, seed=1, notebook="no_such_notebook.ipynb")
    assert not (tmp_path / "run.json").exists()


# ----------------------------------------------------------------------------------------------
# stats


def test_rmse_and_the_spread_over_trials():
    assert rmse([3.0, -4.0]) == pytest.approx(np.sqrt(12.5))
    np.testing.assert_allclose(rmse([[3.0, 4.0], [0.0, 0.0]], axis=1), [np.sqrt(12.5), 0.0])
    assert median_and_spread(np.arange(101.0)) == pytest.approx((50.0, 2.5, 97.5))
    with pytest.raises(CalibrationError, match="empty"):
        rmse([])
    with pytest.raises(CalibrationError, match="non-finite"):
        median_and_spread([1.0, np.nan, 2.0])
    with pytest.raises(CalibrationError, match="level is 1.0; expected strictly between 0 and 1"):
        median_and_spread([1.0, 2.0], level=1.0)


# ----------------------------------------------------------------------------------------------
# v2 claim rows and controls


def paired(ratio, spread, n=200, seed=0):
    """Baseline errors around 0.049 mm and method errors ``ratio`` times them, with noise."""
    rng = np.random.default_rng(seed)
    base = rng.normal(0.049, 0.002, n)
    return base * ratio * (1.0 + spread * rng.standard_normal(n)), base


def test_claim_row_and_controls_round_trip(tmp_path):
    method, base = paired(0.84, 0.05)
    claim, null, oracle = judge_controls(
        method, base, base * 0.5, published=0.041 / 0.049, baseline=base,
        kind="ratio", direction="lower",
    )
    row = claim_row(
        "binocular.coc", Judged(claim, null, oracle), published="0.049 -> 0.041", unit="ratio",
        notebook="04_demo",
    )
    assert (row.verdict, row.null_control, row.oracle_control) == (
        "reproduced", "not reproduced", "reproduced",
    )
    assert row.n == 200 and 0.9 < row.replication_rate <= 1.0
    write_claims(tmp_path, [row])
    back = read_claims(tmp_path / "claims.csv")
    assert list(back.columns) == list(CLAIM_COLUMNS)
    assert back.loc[0, "verdict"] == "reproduced" and back.loc[0, "n"] == 200
    assert back.loc[0, "ci_low"] < back.loc[0, "reproduced"] < back.loc[0, "ci_high"]
    rows = control_rows("binocular.coc", Judged(claim, null, oracle))
    assert [r["control"] for r in rows] == ["null", "oracle"] and rows[0]["definition"]
    write_controls(tmp_path, rows)
    controls = pd.read_csv(tmp_path / "controls.csv")
    assert controls["verdict"].tolist() == ["not reproduced", "reproduced"]


def test_a_null_control_that_passes_is_refused(tmp_path):
    method, base = paired(0.84, 0.05)
    claim, null, oracle = judge_controls(
        method, base, base * 0.5, baseline=base, kind="ratio", direction="lower"
    )
    # a "null control" that is the method itself: the test would be broken
    with pytest.raises(CalibrationError, match="the test is broken"):
        control_rows("binocular.coc", Judged(claim, claim, oracle))
    rows = [{**r, "verdict": "reproduced"} if r["control"] == "null" else r
            for r in control_rows("binocular.coc", Judged(claim, null, oracle))]
    with pytest.raises(CalibrationError, match="null control of 'binocular.coc' came out"):
        write_controls(tmp_path, rows)


# ----------------------------------------------------------------------------------------------
# claims


def test_register_holds_every_claim():
    reg = pd.read_csv(DATA_DIR / "claims.csv", dtype=str, keep_default_na=False)
    assert list(reg.columns) == [
        "id",
        "paper",
        "where",
        "statement",
        "published",
        "unit",
        "comparison",
        "kind",
        "direction",
        "reference",
        "null_control",
        "oracle_control",
        "criterion",
        "criterion_source",
    ]
    assert reg["id"].tolist() == REGISTER_IDS
    assert claim_ids() == REGISTER_IDS
    assert (reg["id"].str.split(".").str[0] == reg["paper"]).all()
    assert (reg[["where", "statement", "unit", "comparison"]] != "").all().all()




def test_write_claims_rejects_bad_verdict(tmp_path):
    with pytest.raises(CalibrationError, match=r"verdict 'reproducd' of claim 'binocular.coc'"):
        write_claims(tmp_path, [row(verdict="reproducd")])
    assert not (tmp_path / "claims.csv").exists()


def test_write_claims_rejects_unknown_or_duplicate_id(tmp_path):
    with pytest.raises(CalibrationError, match=r"'binocular.cocc' is not in the claims register"):
        write_claims(tmp_path, [row(claim_id="binocular.cocc")])
    with pytest.raises(CalibrationError, match="appears twice"):
        write_claims(tmp_path, [row(), row()])
    with pytest.raises(CalibrationError, match="no claim rows"):
        write_claims(tmp_path, [])


def test_no_criterion_of_the_study_passes_for_published():
    """Rule 15: a claim whose paper gives no figure is judged by the study's criterion, and the
    register says so; the two criteria the review found shown as published are the study's."""
    reg = claim_register()
    assert set(reg["criterion"]) <= {"published", "study"}
    assert (reg.loc[reg["published"] == "", "criterion"] == "study").all()
    study = reg.set_index("id")["criterion"]
    assert study["hybrid.handeye"] == study["hybrid.stationary"] == "study"
    assert (reg["criterion_source"].str.len() > 10).all()
    # results/claims.csv carries the register's criterion (once regenerated)
    written = read_claims(RESULTS_DIR / "claims.csv")
    if "criterion" in written.columns:
        assert (written.set_index("id")["criterion"] == study[written["id"]].values).all()


def test_a_register_without_its_criterion_is_refused(tmp_path):
    reg = claim_register()
    bad = tmp_path / "claims.csv"
    reg.assign(criterion=["published"] * (len(reg) - 1) + ["paper"]).to_csv(bad, index=False)
    with pytest.raises(CalibrationError, match=r"line 19 .*criterion 'paper' must be one of"):
        claim_register(bad)
    reg.drop(columns="criterion_source").to_csv(bad, index=False)
    with pytest.raises(CalibrationError, match=r"lacks the column\(s\) \['criterion_source'\]"):
        claim_register(bad, columns=("criterion_source",))
    with pytest.raises(CalibrationError, match="with criterion_source saying where"):
        claim_register(bad)


def test_write_claims_custom_register(tmp_path):
    reg = tmp_path / "register.csv"
    one = claim_register().iloc[:1].assign(id="x.one", paper="x")
    one.to_csv(reg, index=False)
    write_claims(tmp_path / "out", [row(claim_id="x.one")], register=reg)
    with pytest.raises(CalibrationError, match="not in the claims register"):
        write_claims(tmp_path / "out", [row()], register=reg)


def test_aggregate_claims(tmp_path):
    write_claims(tmp_path / "03_binocular", [row("binocular.field"), row("binocular.coc")])
    write_claims(tmp_path / "01_hybrid", [row("hybrid.rps", notebook="01_hybrid")])
    df = aggregate_claims(tmp_path)
    assert df["id"].tolist() == ["binocular.coc", "binocular.field", "hybrid.rps"]
    written = read_claims(tmp_path / "claims.csv")
    pd.testing.assert_frame_equal(written, df, check_dtype=False)
    first = (tmp_path / "claims.csv").read_bytes()
    aggregate_claims(tmp_path)
    assert (tmp_path / "claims.csv").read_bytes() == first

    write_claims(tmp_path / "05_other", [row("hybrid.rps", notebook="05_other")])
    with pytest.raises(CalibrationError, match="more than one notebook"):
        aggregate_claims(tmp_path)


def test_aggregate_claims_empty(tmp_path):
    from calstudy.io.results import ROBUSTNESS_COLUMNS

    df = aggregate_claims(tmp_path)
    assert df.empty
    header = ",".join([*CLAIM_COLUMNS, *ROBUSTNESS_COLUMNS]) + "\n"
    assert (tmp_path / "claims.csv").read_text() == header


def test_aggregate_claims_adds_the_robustness_of_mapped_claims(tmp_path):
    from calstudy.io.results import ROBUSTNESS_SUMMARY

    write_claims(tmp_path / "03_binocular", [row("binocular.field"), row("binocular.coc")])
    summary = pd.DataFrame(
        [{"id": "binocular.coc", "robustness": "conditional", "verdicts": "a; b",
          "depends_on": "optics.f_number", "thresholds": "a -> b between 4 and 5.6",
          "sentence": "..."}]
    )
    summary.to_csv(tmp_path / "03_binocular" / ROBUSTNESS_SUMMARY, index=False)
    df = aggregate_claims(tmp_path).set_index("id")
    assert df.at["binocular.coc", "robustness"] == "conditional"
    assert df.at["binocular.coc", "thresholds"] == "a -> b between 4 and 5.6"
    assert df.at["binocular.field", "robustness"] == "not mapped"
    assert df.at["binocular.field", "depends_on"] == ""




def test_write_figure_raises_small_text_and_records_the_smallest_size(tmp_path):
    """Text below MIN_FONT_PT is raised to it; the PNG says the smallest size, which the
    book's check turns into pixels on the page."""
    from matplotlib.figure import Figure
    from PIL import Image

    from calstudy.io.results import FONT_KEY, MIN_FONT_PT

    fig = Figure(figsize=(4, 3))
    ax = fig.add_subplot()
    ax.set_xlabel("tiny", fontsize=5)
    ax.set_title("large", fontsize=14)
    ax.tick_params(labelsize=12)
    title = ax.title
    png = Image.open(write_figure(fig, tmp_path / "f.png"))
    assert float(png.info[FONT_KEY]) == MIN_FONT_PT
    assert ax.xaxis.label.get_fontsize() == MIN_FONT_PT and title.get_fontsize() == 14
    big = Figure(figsize=(4, 3))
    big.add_subplot().set_title("large", fontsize=14)
    for t in big.axes[0].get_xticklabels() + big.axes[0].get_yticklabels():
        t.set_fontsize(11)
    assert float(Image.open(write_figure(big, tmp_path / "g.png")).info[FONT_KEY]) == 11
