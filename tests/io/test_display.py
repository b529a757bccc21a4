"""Display helpers for notebooks: formatted tables in the column, claim rows, figures."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.claims import ClaimRow
from calstudy.io import display
from calstudy.io.display import (
    MISSING,
    describe_figure,
    figure_html,
    format_claims,
    format_table,
    format_value,
    show_claims,
    show_table,
    table_html,
)


@pytest.fixture
def shown(monkeypatch):
    out = []
    monkeypatch.setattr(display, "_display", out.append)
    return out


def test_format_value():
    assert format_value(0.123456789) == "0.1235"
    assert format_value(12345.678) == "1.235×10⁴"
    assert format_value(2.0) == "2" and format_value(np.int64(7)) == "7"
    assert format_value(1e-16) == "1×10⁻¹⁶"
    assert format_value(0.0) == "0"
    assert format_value(float("nan")) == MISSING and format_value(None) == MISSING
    assert format_value(np.bool_(True)) == "yes"
    assert format_value("nan") == MISSING and format_value("a") == "a"
    assert format_value("<NA>") == MISSING
    # generated text is typeset: a source column reading "+-2 mm" shows as ±2 mm
    assert format_value("assumption: +-2 mm, 15 um, a -> b") == "assumption: ±2 mm, 15 µm, a → b"


def test_narrow_table_is_formatted_with_units_and_reasons():
    df = pd.DataFrame(
        {"method": ["a", "b"], "error_mm": [0.12345, np.nan], "rate": [0.5, 0.25]}
    )
    tables, notes = format_table(df, units={"rate": "%"}, missing={"error_mm": "diverged"})
    assert len(tables) == 1
    t = tables[0]
    assert list(t.columns) == ["method", "error (mm)", "rate (%)"]
    assert t.iloc[0, 1] == "0.1235" and t.iloc[1, 1] == MISSING
    assert notes == [f"{MISSING} in error (mm): diverged (1 cell(s))"]


def test_wide_short_table_is_transposed():
    df = pd.DataFrame({"method": ["x", "y"], **{f"c{i}_mm": [i, i + 0.5] for i in range(12)}})
    (t,), _ = format_table(df)
    assert t.shape == (12, 3)
    assert list(t.columns) == ["method", "x", "y"] and t.iloc[0, 0] == "c0 (mm)"
    # without a key column the rows have no names to head columns with: split, not transposed
    tables, _ = format_table(df.drop(columns="method"))
    assert [list(t.columns)[:1] for t in tables] == [["c0 (mm)"], ["c8 (mm)"]]


def test_a_table_with_as_many_rows_as_columns_allowed_is_split_not_transposed():
    # transposed, its 8 rows would become 8 columns beside the column of labels: 9
    df = pd.DataFrame({"k": list("abcdefgh"), **{f"c{i}": np.arange(8.0) for i in range(9)}})
    tables, _ = format_table(df, max_columns=8)
    assert all(t.shape[1] <= 8 for t in tables) and tables[0].columns[0] == "k"
    seven = df.iloc[:7]
    (t,), _ = format_table(seven, max_columns=8)
    assert t.shape == (9, 8) and list(t.columns)[:2] == ["k", "a"]  # 7 rows: transposed


def test_table_html_right_aligns_numbers():
    html = table_html(pd.DataFrame({"name": ["a", "b"], "x_mm": [1.5, np.nan], "n": [1, 2]}))
    assert '<td class="num">1.5</td>' in html and f'<td class="num">{MISSING}</td>' in html
    assert "<td>a</td>" in html and '<td class="num">2</td>' in html
    assert '<td class="num">2.5×10⁻⁵</td>' in table_html(pd.DataFrame({"x": [2.5e-5]}))


def test_wide_long_table_is_split_repeating_the_keys():
    df = pd.DataFrame({"k": list("abcdefghij"), **{f"c{i}": np.arange(10.0) for i in range(16)}})
    tables, _ = format_table(df, max_columns=8)
    assert len(tables) == 3
    assert all(t.shape[1] <= 8 and t.columns[0] == "k" for t in tables)
    assert sum(t.shape[1] - 1 for t in tables) == 16


def test_show_table_displays_html_and_returns_none(shown):
    df = pd.DataFrame({"a": [1.0, np.nan]})
    assert show_table(df, caption="A <b>") is None
    html = shown[0]["text/html"]
    assert "<caption>A &lt;b&gt;</caption>" in html and "NaN" not in html and MISSING in html
    assert "NaN" not in shown[0]["text/plain"]


def test_show_claims_is_compact(shown):
    rows = [
        ClaimRow(id="binocular.coc", published="0.837", reproduced=0.999, ci_low=0.66,
                 ci_high=1.51, unit="ratio", verdict="not reproduced", notebook="04",
                 note="long " * 50, n=200, replication_rate=0.55,
                 null_control="not reproduced", oracle_control="reproduced"),
        ClaimRow(id="hybrid.rps", published="", reproduced=1.0, ci_low=1.0, ci_high=1.0,
                 unit="RMS ratio", verdict="reproduced", notebook="01"),
    ]
    t = format_claims(rows)
    assert t.shape[1] <= 8
    assert t.loc[0, "reproduced [95 % CI]"] == "0.999 ratio [0.66, 1.51]"
    assert t.loc[0, "repl. rate"] == "55 %" and t.loc[0, "N"] == "200"
    # the published figure of the register, in the unit of the reproduced one
    assert t.loc[0, "published"] == "0.837 ratio (0.041 / 0.049 mm)"
    assert t.loc[1, "published"] == "none in the paper (the claim states a method only)"
    assert t.loc[1, "N"] == MISSING
    other = format_claims([{"id": "x.new", "published": "+-2", "unit": "mm"}])
    assert other.loc[0, "published"] == "±2 mm"  # not in the register: its own text
    assert t.loc[1, "controls"] == MISSING
    assert show_claims(rows) is None
    assert "long long" not in shown[0]["text/html"]  # the note stays on the claims page
    pd.testing.assert_frame_equal(format_claims(pd.DataFrame([r.__dict__ for r in rows])), t)


def test_figure_html_needs_alt(tmp_path):
    png = tmp_path / "f.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n")
    assert 'alt="Bars &quot;a&quot;"' in figure_html(png, 'Bars "a"')
    assert str(tmp_path) not in figure_html(png, "x")
    with pytest.raises(ValueError, match="alt text"):
        figure_html(png, " ")


def test_describe_figure_reads_the_figure_labels():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2)
    a.set_title("rotation")
    a.set_xlabel("pose")
    a.set_ylabel(r"$\sigma_\mathrm{rot}$ (deg)")
    b.set_xlabel("pose")
    b.set_ylabel("residual (mm)")
    fig.colorbar(b.imshow([[0.0, 1.0]]), ax=b, label="not a panel")
    fig.suptitle("Per-pose residuals")
    text = describe_figure(fig, "pose_residuals")
    assert text == (
        'Figure "pose residuals" (Per-pose residuals), 2 panels: "rotation" sigma_rot (deg) '
        "against pose; residual (mm) against pose"
    )
    assert len(text.split()) >= 5 and ".png" not in text and "/" not in text
    plain = plt.figure()
    plain.add_subplot()
    assert describe_figure(plain, "x") == 'Figure "x", a plot without axis labels'
    long = describe_figure(fig, "a" * 500, limit=60)
    assert len(long) <= 60 and long.endswith("…")
    plt.close("all")
