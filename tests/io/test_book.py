"""The claims page: figure, compact table, dropdowns, verdict counts from results/claims.csv."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from calstudy.claims import CLAIM_COLUMNS, ClaimRow, claim_register
from calstudy.io.book import (
    FIGURE_NAME,
    REGISTER_COPY,
    RESULTS_COPY,
    main,
    published_value,
    read_results,
    render_claims_page,
    typeset,
)
from calstudy.io.results import aggregate_claims, write_claims


def row(claim_id="binocular.coc", verdict="reproduced", notebook="04_binocular", **kw):
    values = dict(
        id=claim_id, published="0.837 (0.041/0.049 mm)", reproduced=0.84, ci_low=0.8,
        ci_high=0.88, unit="ratio", verdict=verdict, notebook=notebook, note="a note",
        n=200, replication_rate=0.71, null_control="not reproduced", oracle_control="reproduced",
    )
    values.update(kw)
    return ClaimRow(**values)


@pytest.fixture
def results(tmp_path):
    write_claims(
        tmp_path / "results" / "04_binocular",
        [
            row(),
            row("binocular.field", "not reproduced", reproduced=1.0, ci_low=0.9, ci_high=1.1),
        ],
    )
    write_claims(
        tmp_path / "results" / "01_hybrid",
        [
            row("hybrid.handeye", "direction only", notebook="01_hybrid", published="",
                reproduced=3.5, ci_low=2.1, ci_high=5.5, unit="RMS ratio", null_control="",
                oracle_control="", replication_rate=float("nan")),
            row("hybrid.systematic", "direction only", notebook="01_hybrid", published="2-4",
                reproduced=1.6, ci_low=0.7, ci_high=3.6, unit="mm"),
        ],
    )
    aggregate_claims(tmp_path / "results")
    return tmp_path / "results" / "claims.csv"


def rows_of(text: str) -> dict[str, str]:
    return {
        line.split("<code>")[1].split("</code>")[0]: line
        for line in text.splitlines()
        if line.startswith("<tr><td><details>")
    }


def test_page_has_counts_figure_table_and_dropdowns(tmp_path, results):
    book = tmp_path / "book"
    (book).mkdir()
    (book / "_toc.yml").write_text(
        "format: jb-book\nroot: intro\nchapters:\n  - file: notebooks/04_binocular\n"
    )
    text = render_claims_page(book / "claims.md", results=results).read_text()
    n = len(claim_register())
    assert text.startswith("# Claims and verdicts\n")
    assert f"<strong>{n} claims:</strong>" in text
    assert 'verdict-reproduced">reproduced</span> 1' in text
    assert 'verdict-direction-only">direction only</span> 2' in text
    assert f'verdict-pending">pending</span> {n - 4}' in text
    for name in (FIGURE_NAME, REGISTER_COPY, RESULTS_COPY):
        assert (book / name).is_file(), name
    assert (book / FIGURE_NAME).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"```{{figure}} {FIGURE_NAME}\n:alt: Published against reproduced" in text
    assert f"{{download}}`data/claims.csv <{REGISTER_COPY}>`" in text
    rows = rows_of(text)
    assert set(rows) == set(claim_register()["id"])
    coc = rows["binocular.coc"]
    assert "0.837 ratio" in coc and "(0.041/0.049 mm)" in coc  # published in the unit
    assert "0.84 ratio" in coc and "[0.8, 0.88]" in coc
    assert "71 %" in coc and "<td class=\"num\">200</td>" in coc
    assert "null: not reproduced<br>oracle: reproduced" in coc
    assert '<a href="notebooks/04_binocular.html"' in coc  # listed in the toc: linked
    assert "<p><em>Note:</em> a note</p>" in coc  # the note one click away
    assert "none in the paper" in rows["hybrid.handeye"]  # an empty published cell says why
    assert "<td>—</td>" in rows["hybrid.handeye"]  # no controls, no replication rate
    assert '<a href="' not in rows["hybrid.handeye"]  # 01_hybrid is not in the toc
    assert "verdict-pending" in rows["selfcal.residual"]
    assert "±0.3 mm" in rows["hybrid.deviation"] and "+-" not in text
    assert "nan" not in text.lower().replace("nanc", "")


def test_page_is_deterministic_and_all_pending_without_results(tmp_path):
    out = tmp_path / "claims.md"
    assert main(["claims", str(out), "--results", str(tmp_path / "none.csv")]) == 0
    first = out.read_bytes()
    text = first.decode()
    n = len(claim_register())
    assert f'verdict-pending">pending</span> {n}' in text
    assert text.count('class="verdict verdict-pending"') == n + 1
    assert not (tmp_path / FIGURE_NAME).exists()
    render_claims_page(out, results=tmp_path / "none.csv")
    assert out.read_bytes() == first


def test_figure_is_byte_deterministic(tmp_path, results):
    render_claims_page(tmp_path / "a" / "claims.md", results=results)
    render_claims_page(tmp_path / "b" / "claims.md", results=results)
    a, b = (tmp_path / d / FIGURE_NAME for d in "ab")
    assert a.read_bytes() == b.read_bytes()


def test_v1_results_read_with_v2_columns(tmp_path):
    v1 = tmp_path / "claims.csv"
    v1.write_text(
        "id,published,reproduced,ci_low,ci_high,unit,verdict,notebook,note\n"
        "hybrid.rps,,1,1,1,RMS ratio,reproduced,01_hybrid,n\n"
    )
    res = read_results(v1)
    assert list(res.columns) == list(CLAIM_COLUMNS)
    assert res.loc[0, "n"] == 0 and math.isnan(res.loc[0, "replication_rate"])
    assert res.loc[0, "null_control"] == ""


def test_typeset_and_published_value():
    assert typeset("within +-0.3 mm, 5 um, a <= b -> c") == "within ±0.3 mm, 5 µm, a ≤ b → c"
    assert typeset(float("nan")) == ""
    assert published_value("0.837 (0.041/0.049 mm)") == (0.837, 0.837)
    assert published_value("2-4") == (2.0, 4.0)
    assert published_value("") is None and published_value("about four") is None


def test_results_frame_roundtrip(results):
    res = read_results(results)
    assert isinstance(res, pd.DataFrame) and len(res) == 4


def test_book_extension_keeps_one_copy_of_each_head_script():
    import importlib.util

    from calstudy.core.paths import REPO_ROOT

    spec = importlib.util.spec_from_file_location(
        "calstudy_book", REPO_ROOT / "book" / "_ext" / "calstudy_book.py"
    )
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)
    page = (
        "<head>\n<script>const A = 1;</script>\n<script src='x.js'></script>\n"
        "<script>const A = 1;</script>\n</head>\n<body><script>const A = 1;</script></body>"
    )
    fixed = ext.dedupe_head(page)
    assert fixed.count("const A = 1;") == 2  # one in the head, the body's untouched
    assert fixed.startswith("<head>\n<script>const A = 1;</script>\n<script src='x.js'>")
    assert ext.dedupe_head("no head") == "no head"
