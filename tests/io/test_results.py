"""Tests of the results layer: atomic, deterministic files; verdicts; the claims page."""

from __future__ import annotations

import json

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy.claims import (
    CLAIM_COLUMNS,
    ClaimRow,
    claim_ids,
    verdict_direction,
    verdict_vs_ml,
    verdict_vs_published,
)
from calstudy.core.paths import DATA_DIR
from calstudy.core.stats import bootstrap_interval, percentile_interval, rmse
from calstudy.io.book import main as book_main
from calstudy.io.book import render_claims_page
from calstudy.io.results import (
    PINNED_PACKAGES,
    aggregate_claims,
    notebook_writers,
    read_claims,
    source_digest,
    write_claims,
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
    monkeypatch.setattr("IPython.display.display", shown.append)
    save_table, show_figure = notebook_writers(tmp_path / "nb")
    df = sample_table()
    assert save_table(df, "t") is df
    assert (tmp_path / "nb" / "t.csv").read_bytes() == write_table(
        df, tmp_path / "t.csv"
    ).read_bytes()
    assert show_figure(make_figure(), "f") is None  # a cell ending with it shows no path
    assert shown[0].data == (tmp_path / "nb" / "f.png").read_bytes()


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


def test_rmse_and_percentile_interval():
    assert rmse([3.0, -4.0]) == pytest.approx(np.sqrt(12.5))
    np.testing.assert_allclose(rmse([[3.0, 4.0], [0.0, 0.0]], axis=1), [np.sqrt(12.5), 0.0])
    lo, hi = percentile_interval(np.arange(101.0))
    assert (lo, hi) == pytest.approx((2.5, 97.5))
    with pytest.raises(CalibrationError, match="empty"):
        rmse([])
    with pytest.raises(CalibrationError, match="non-finite"):
        percentile_interval([1.0, np.nan, 2.0])
    with pytest.raises(CalibrationError, match="at least 2"):
        percentile_interval([1.0])
    with pytest.raises(CalibrationError, match="level"):
        percentile_interval([1.0, 2.0], level=1.0)


def test_bootstrap_interval_vectorised_and_seeded():
    x = np.random.default_rng(1).normal(10.0, 1.0, 400)

    def mean(s):
        return s.mean(axis=1)

    est, lo, hi = bootstrap_interval(x, mean, np.random.default_rng(2), n_boot=1000)
    assert est == pytest.approx(x.mean())
    assert lo < est < hi
    assert hi - lo == pytest.approx(2 * 1.96 / np.sqrt(400), rel=0.2)
    again = bootstrap_interval(x, mean, np.random.default_rng(2), n_boot=1000)
    assert again == (est, lo, hi)
    with pytest.raises(CalibrationError, match="Generator"):
        bootstrap_interval(x, mean, 2)
    with pytest.raises(CalibrationError, match="shape"):
        bootstrap_interval(x, lambda s: s, np.random.default_rng(0), n_boot=10)


# ----------------------------------------------------------------------------------------------
# verdicts


def paired(ratio, spread, n=400, seed=0):
    """Baseline errors around 0.049 mm and method errors ``ratio`` times them, with noise."""
    rng = np.random.default_rng(seed)
    base = rng.normal(0.049, 0.002, n)
    return base * ratio * (1.0 + spread * rng.standard_normal(n)), base


def test_ratio_reproduced():
    method, base = paired(0.84, 0.02)
    v = verdict_vs_published(0.041 / 0.049, method, base, kind="ratio", direction="lower")
    assert v.verdict == "reproduced"
    assert v.reproduced == pytest.approx(0.84, abs=0.01)
    assert v.ci_low < v.reproduced < v.ci_high < 1.0
    assert v.significant and v.in_band and v.null == 1.0


def test_ratio_direction_only():
    method, base = paired(0.3, 0.02)
    v = verdict_vs_published(0.041 / 0.049, method, base, kind="ratio", direction="lower")
    assert v.verdict == "direction only"
    assert v.significant and not v.in_band


def test_ratio_interval_crossing_no_effect_is_not_reproduced():
    # the median ratio is right on the published one, but single trials often show no gain
    method, base = paired(0.84, 0.15)
    v = verdict_vs_published(0.041 / 0.049, method, base, kind="ratio", direction="lower")
    assert v.ci_high > 1.0 and v.in_band
    assert v.verdict == "not reproduced"


def test_ratio_opposite_direction_is_not_reproduced():
    method, base = paired(1.3, 0.02)
    v = verdict_vs_published(0.8, method, base, kind="ratio", direction="lower")
    assert v.verdict == "not reproduced"
    v = verdict_vs_published(1.3, method, base, kind="ratio", direction="higher")
    assert v.verdict == "reproduced"


def test_interval_touching_no_effect_is_not_significant():
    v = verdict_vs_published(1.0, np.ones(50), kind="ratio", direction="lower")
    assert v.verdict == "not reproduced"
    assert not v.significant


def test_ratio_samples_without_baseline():
    ratios = np.random.default_rng(3).normal(0.42, 0.03, 300)
    v = verdict_vs_published(0.080 / 0.192, ratios, kind="ratio", direction="lower")
    assert v.verdict == "reproduced"
    assert v.reproduced == pytest.approx(np.median(ratios))


def test_value_against_paired_baseline():
    rng = np.random.default_rng(4)
    circular = rng.normal(0.556, 0.05, 300)
    ours = rng.normal(0.12, 0.01, 300)
    v = verdict_vs_published(0.100, ours, circular, kind="value", direction="lower")
    assert v.verdict == "reproduced"
    assert v.null == 0.0 and v.effect_high < 0.0
    v = verdict_vs_published(0.100, ours + 0.1, circular, kind="value", direction="lower")
    assert v.verdict == "direction only"  # 0.22 mm is beyond 1.5 x 0.100 mm


def test_value_factor_band_edges_and_sign():
    samples = np.full(20, 0.15)
    assert verdict_vs_published(0.1, samples, kind="value", direction="higher").in_band
    assert not verdict_vs_published(0.099, samples, kind="value", direction="higher").in_band
    neg = verdict_vs_published(2.5, -np.full(20, 2.5), kind="value", direction="lower")
    assert neg.verdict == "direction only" and not neg.in_band


def test_percent_band():
    rng = np.random.default_rng(5)
    within = np.clip(rng.normal(88.0, 2.0, 300), 0, 100)
    v = verdict_vs_published(96.55, within, 50.0, kind="percent", direction="higher")
    assert v.verdict == "reproduced"  # 8.6 points below, inside the 10-point band
    v = verdict_vs_published(96.55, within - 3.0, 50.0, kind="percent", direction="higher")
    assert v.verdict == "direction only"  # 11.6 points below
    edge = verdict_vs_published(90.0, np.full(30, 80.0), 50.0, kind="percent", direction="higher")
    assert edge.verdict == "reproduced"  # exactly 10 points counts as inside
    # compared with a paired baseline (before compensation) instead of a fixed null value
    before = np.clip(rng.normal(5.0, 2.0, 300), 0, 100)
    v = verdict_vs_published(96.55, within, before, kind="percent", direction="higher")
    assert v.verdict == "reproduced" and v.effect_low > 0.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"kind": "rate"}, "kind"),
        ({"direction": "down"}, "direction"),
        ({"published": 0.0, "kind": "value"}, "factor band around 0"),
        ({"published": -0.5}, "positive"),
        ({"samples": [0.8, np.nan, 0.9]}, "non-finite"),
        ({"samples": [0.8]}, "at least 2"),
        ({"baseline": [1.0, 1.0]}, "pair them"),
        ({"baseline": [1.0, 0.0, 1.0]}, "ratio is undefined"),
    ],
)
def test_verdict_vs_published_rejects_bad_input(kwargs, match):
    args = {
        "published": 0.8,
        "samples": [0.8, 0.85, 0.9],
        "kind": "ratio",
        "direction": "lower",
    }
    args.update(kwargs)
    with pytest.raises(CalibrationError, match=match):
        verdict_vs_published(**args)


def test_verdict_vs_ml():
    rng = np.random.default_rng(6)
    ml = np.abs(rng.normal(0.0, 0.1, 300))
    close = ml * 1.1 + np.abs(rng.normal(0.0, 0.005, 300))
    v = verdict_vs_ml(close, ml, works=True, rng=np.random.default_rng(0))
    assert v.verdict == "reproduced"
    assert v.ci_low < v.reproduced < v.ci_high
    assert v.reproduced == pytest.approx(rmse(close) / rmse(ml))
    again = verdict_vs_ml(close, ml, works=True, rng=np.random.default_rng(0))
    assert again == v

    worse = verdict_vs_ml(ml * 3.0, ml, works=True, rng=np.random.default_rng(0))
    assert worse.verdict == "direction only" and worse.reproduced == pytest.approx(3.0)
    failed = verdict_vs_ml(close, ml, works=False, rng=np.random.default_rng(0))
    assert failed.verdict == "not reproduced"
    broken = verdict_vs_ml(np.full(300, np.nan), ml, works=False, rng=np.random.default_rng(0))
    assert broken.verdict == "not reproduced" and np.isnan(broken.reproduced)


def test_verdict_vs_ml_rejects_bad_input():
    rng = np.random.default_rng(0)
    with pytest.raises(CalibrationError, match="shape"):
        verdict_vs_ml([1.0, 2.0], [1.0, 2.0, 3.0], works=True, rng=rng)
    with pytest.raises(CalibrationError, match="non-finite"):
        verdict_vs_ml([1.0, np.nan], [1.0, 2.0], works=True, rng=rng)
    with pytest.raises(CalibrationError, match="RMS error is 0"):
        verdict_vs_ml([1.0, 2.0], [0.0, 0.0], works=True, rng=rng)
    with pytest.raises(TypeError):
        verdict_vs_ml([1.0, 2.0], [1.0, 2.0], works=True)  # rng is required


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
    ]
    assert reg["id"].tolist() == REGISTER_IDS
    assert claim_ids() == REGISTER_IDS
    assert (reg["id"].str.split(".").str[0] == reg["paper"]).all()
    assert (reg[["where", "statement", "unit", "comparison"]] != "").all().all()


def test_write_claims_round_trip(tmp_path):
    v = verdict_vs_published(0.8, [0.7, 0.75, 0.8, 0.78], kind="ratio", direction="lower")
    rows = [row(), v.row("binocular.field", "0.86", "ratio", "03_binocular")]
    rows.append(
        ClaimRow("dualarm.vs_circular", "", np.nan, np.nan, np.nan, "mm", "not testable", "04_x")
    )
    path = write_claims(tmp_path, rows)
    first = path.read_bytes()
    assert write_claims(tmp_path, rows).read_bytes() == first
    df = read_claims(path)
    assert list(df.columns) == list(CLAIM_COLUMNS)
    assert df["published"].tolist() == ["0.041/0.049", "0.86", ""]
    assert np.isnan(df["reproduced"].iloc[2])
    assert df["verdict"].tolist() == ["reproduced", "reproduced", "not testable"]


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


def test_write_claims_custom_register(tmp_path):
    reg = tmp_path / "register.csv"
    reg.write_text("id,paper\nx.one,x\n")
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
    df = aggregate_claims(tmp_path)
    assert df.empty
    assert (tmp_path / "claims.csv").read_text() == ",".join(CLAIM_COLUMNS) + "\n"


# ----------------------------------------------------------------------------------------------
# claims page


def test_claims_page_pending_and_computed(tmp_path):
    write_claims(tmp_path / "results" / "03_binocular", [row("binocular.coc")])
    results = tmp_path / "results" / "claims.csv"
    aggregate_claims(tmp_path / "results")
    page = render_claims_page(tmp_path / "book" / "claims.md", results=results)
    text = page.read_text()
    assert text.startswith("# Claims and verdicts\n")
    assert f"**{len(REGISTER_IDS)} claims: 1 reproduced, 0 direction only" in text
    assert f"{len(REGISTER_IDS) - 1} pending" in text
    lines = {ln.split("`")[1]: ln for ln in text.splitlines() if ln.startswith("| `")}
    assert set(lines) == set(REGISTER_IDS)
    assert "**reproduced**" in lines["binocular.coc"]
    assert "0.84 [0.8, 0.88] ratio" in lines["binocular.coc"]
    assert "`03_binocular`" in lines["binocular.coc"]  # not in a toc: plain name, no link
    for claim_id in set(REGISTER_IDS) - {"binocular.coc"}:
        assert "*pending*" in lines[claim_id]
    for paper in ("hybrid", "selfcal", "binocular", "dualarm"):
        assert f"\n## {paper}\n" in text and f"{{cite:p}}`{paper}`" in text

    toc = "format: jb-book\nroot: intro\nchapters:\n  - file: notebooks/03_binocular\n"
    (tmp_path / "book" / "_toc.yml").write_text(toc)
    linked = render_claims_page(tmp_path / "book" / "claims.md", results=results).read_text()
    assert "{doc}`03_binocular <notebooks/03_binocular>`" in linked


def test_claims_page_without_results_is_all_pending(tmp_path):
    out = tmp_path / "claims.md"
    assert book_main(["claims", str(out), "--results", str(tmp_path / "none.csv")]) == 0
    first = out.read_bytes()
    text = first.decode()
    assert f"0 not testable, {len(REGISTER_IDS)} pending" in text
    assert text.count("*pending*") == len(REGISTER_IDS)
    render_claims_page(out, results=tmp_path / "none.csv")
    assert out.read_bytes() == first
    assert leftovers(tmp_path) == []



def test_verdict_direction():
    lower = verdict_direction(np.full(10, 1.0) + np.arange(10) * 0.01, np.full(10, 3.0))
    assert lower.verdict == "reproduced" and lower.reproduced < 1
    same = verdict_direction(np.linspace(1, 3, 10), np.full(10, 2.0))
    assert same.verdict == "not reproduced"
    with pytest.raises(CalibrationError, match="must be equal"):
        verdict_direction(np.ones(3), np.ones(4))
