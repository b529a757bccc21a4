"""The claims page: figure, compact table, dropdowns, verdict counts from results/claims.csv."""

from __future__ import annotations

import math
import re

import pandas as pd
import pytest

from calstudy.claims import CLAIM_COLUMNS, ClaimRow, claim_register
from calstudy.core.paths import REPO_ROOT
from calstudy.io.book import (
    COLUMNS,
    FIGURE_NAME,
    HEADLINE_NAME,
    REGISTER_COPY,
    RESULTS_COPY,
    claim_target,
    main,
    percent,
    read_results,
    render_claims_page,
)
from calstudy.io.claims_cells import (
    bound_value,
    headings,
    judged_in,
    published_figure,
    published_value,
    ratio_of,
    section_id,
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
    """Each claim's table row with the hidden row of its details, by claim id."""
    return {
        line.split('<summary title="')[1].split('"')[0]: line
        for line in text.splitlines()
        if line.startswith('<tr class="claim" id="claim-')
    }


def test_page_has_counts_table_figure_and_rules(tmp_path, results):
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
    assert f"```{{figure}} {FIGURE_NAME}\n:name: fig-claims-forest\n:alt: Forest plot" in text
    assert f"{{download}}`data/claims.csv <{REGISTER_COPY}>`" in text
    # the counts, then the one table right under them, then the figure, the rules folded
    counts, table = text.index("verdict-counts"), text.index('<table class="claims">')
    assert counts < table < text.index("{figure}") < text.index(":class: dropdown")
    assert text.count('<table class="claims">') == 1
    head = text[table:text.index("</thead>")]
    assert [c.header for c in COLUMNS] == [
        h.rsplit(">", 1)[1] for h in head.split("</th>")[:-1]
    ]
    rows = rows_of(text)
    assert set(rows) == set(claim_register()["id"])
    coc = rows["binocular.coc"]
    # published in the unit of the reproduced figure, computed from the register's 0.049 -> 0.041
    assert ">0.837</span>" in coc and "0.041 / 0.049 mm" in coc
    assert ">0.84</span>" in coc and "[0.8, 0.88]" in coc and "N = 200" in coc
    assert ">71 %</td>" in coc
    assert "null ✓" in coc and "oracle ✓" in coc  # the controls as badges
    assert "null control: not reproduced; oracle control: reproduced" in coc  # the details
    assert 'href="notebooks/04_binocular.html' in coc  # listed in the toc: linked
    assert "<p><em>Note:</em> a note</p>" in coc  # the note one click away
    assert "verdict-reproduced" in coc and "circle-of-confusion rectification" in coc
    # a bound the claim is judged against, not a figure of the paper
    handeye = rows["hybrid.handeye"]
    assert ">≤ 3</span>" in handeye and "bound ≤ 3 × CRB RMS" in handeye
    assert "Controls:" not in handeye  # no controls, no replication rate
    assert 'title="no control for this claim">—' in handeye
    assert 'title="no per-trial effect">—</span>' in handeye
    assert '<a ' not in handeye.split('claim-more')[0]  # 01_hybrid is not in the toc
    assert ">2–4</span>" in rows["hybrid.systematic"]  # same unit: the paper's own figure
    assert "verdict-pending" in rows["selfcal.residual"]
    assert "±0.3 mm" in rows["hybrid.deviation"] and "+-" not in text
    assert "nan" not in text.lower().replace("nanc", "")


def test_fragments_for_the_intro_and_the_chapters(tmp_path, results):
    """The intro's headline counts the verdicts; each paper chapter's opening has one badge
    and one sentence per claim of its paper and its key figure with a numbered caption."""
    book = tmp_path / "book"
    figures = tmp_path / "figures" / "04_binocular_correction"
    figures.mkdir(parents=True)
    (figures / "rmse_summary.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    render_claims_page(book / "claims.md", results=results, figures=figures.parent)
    n = len(claim_register())
    headline_text = (book / HEADLINE_NAME).read_text()
    assert headline_text.startswith(
        f"Of the {n} claims of the four papers, checked over Monte Carlo trials on synthetic "
        f"data: 1 reproduced, 2 direction only, 1 not reproduced and {n - 4} pending.")
    assert f"```{{figure}} {FIGURE_NAME}\n:name: fig-intro-forest" in headline_text
    box = (book / "verdicts-binocular.md").read_text()
    n_binocular = int((claim_register()["paper"] == "binocular").sum())
    assert box.count("<li>") == box.count('class="verdict verdict-') == n_binocular
    assert ("Circle-of-confusion rectification: published 0.837 ratio, reproduced 0.84 ratio "
            "(95 % interval 0.8 to 0.88, median of 200 trials), a significant effect within "
            "the accepted band; 71 % of single reruns go the paper&#x27;s way.") in box
    assert "```{figure} key-binocular.png\n:name: fig-binocular-key" in box
    assert (book / "key-binocular.png").read_bytes() == (figures / "rmse_summary.png").read_bytes()
    hybrid = (book / "verdicts-hybrid.md").read_text()
    assert ("Hand-eye calibration: the bound is at most 3 RMS ratio; reproduced 3.5 RMS ratio"
            in hybrid)
    assert "{figure}" not in hybrid  # its notebook's figure is not there


def test_claim_target_and_percent():
    """Targets of the committed claims: the published figure with the factor-1.5 band (10
    points for a percentage), a bound with its side (one computed by the notebook, read from
    the note), no effect for a ratio without a published figure."""
    from calstudy.core.paths import RESULTS_DIR

    reg = claim_register().set_index("id", drop=False)
    res = read_results(RESULTS_DIR / "claims.csv").set_index("id", drop=False)

    def target(claim_id):
        return claim_target(reg.loc[claim_id].to_dict(), res.loc[claim_id])

    coc = target("binocular.coc")
    assert coc.kind == "published" and coc.value == pytest.approx(0.041 / 0.049)
    assert coc.band == pytest.approx((1 / 1.5, 1.5))
    dev = target("hybrid.deviation")  # the one-sided shortfall's 5 % critical value
    assert dev.kind == "bound" and dev.value == pytest.approx(0.0928, abs=5e-5)
    assert target("hybrid.systematic").value == pytest.approx(3.0)  # middle of 2-4 mm
    handeye = target("hybrid.handeye")
    assert (handeye.kind, handeye.value, handeye.band) == ("bound", 3.0, (0.0, 1.0))
    corr = target("hybrid.correlation")  # 1.36/sqrt(n): the value the notebook computed
    assert corr.kind == "bound" and corr.value == pytest.approx(0.105)
    one = target("selfcal.one_step")
    assert (one.kind, one.value, one.band) == ("no effect", 1.0, (0.0, 1.0))
    assert percent(0.445) == format(0.445, ".0%").replace("%", " %") == "44 %"
    assert percent(float("nan")) == "" and percent(None) == ""


def test_page_is_deterministic_and_all_pending_without_results(tmp_path):
    out = tmp_path / "claims.md"
    assert main(["claims", str(out), "--results", str(tmp_path / "none.csv")]) == 0
    first = out.read_bytes()
    text = first.decode()
    n = len(claim_register())
    assert f'verdict-pending">pending</span> {n}' in text
    assert text.count('class="verdict verdict-pending"') == n + 1  # a badge per claim, 1 count
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
    assert typeset("3 x CRB, 1.36/sqrt(n), Cramer-Rao") == "3 × CRB, 1.36/√n, Cramér-Rao"
    assert typeset(float("nan")) == ""
    assert published_value("0.837 (0.041/0.049 mm)") == (0.837, 0.837)
    assert published_value("2-4") == (2.0, 4.0)
    assert published_value("") is None and published_value("about four") is None


def test_results_frame_roundtrip(results):
    res = read_results(results)
    assert isinstance(res, pd.DataFrame) and len(res) == 4


def _extension():
    import importlib.util

    from calstudy.core.paths import REPO_ROOT

    spec = importlib.util.spec_from_file_location(
        "calstudy_book", REPO_ROOT / "book" / "_ext" / "calstudy_book.py"
    )
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)
    return ext


def test_book_extension_drops_progress_bars_and_keeps_warnings():
    import json

    ext = _extension()
    bar = (
        "\rcalibration:   0%|          | 0/200 [00:00<?, ?trial/s]"
        "\rcalibration: 100%|██████████| 200/200 [00:01<00:00, 150.2trial/s]\n"
    )
    assert ext.strip_progress(bar) == ""
    assert ext.strip_progress("trial 3/48\n") == ""
    warning = "CalibrationWarning: chi2/dof = 9.1 outside [0.5, 1.6]\n"
    assert ext.strip_progress(warning + bar) == warning
    assert ext.strip_progress("50%| of the poses\n") == "50%| of the poses\n"  # not a bar
    nb = {"cells": [
        {"cell_type": "code", "source": "", "outputs": [
            {"output_type": "stream", "name": "stderr", "text": ["\r", bar]},
            {"output_type": "stream", "name": "stdout", "text": "trial 1/2\n"},
            {"output_type": "stream", "name": "stderr", "text": warning + bar},
        ]},
        {"cell_type": "markdown", "source": "text"},
    ]}
    out = json.loads(ext.strip_notebook_progress(json.dumps(nb)))
    assert out["cells"][0]["outputs"] == [
        {"output_type": "stream", "name": "stdout", "text": "trial 1/2\n"},  # stdout: the check's
        {"output_type": "stream", "name": "stderr", "text": warning},
    ]
    clean = json.dumps({"cells": [nb["cells"][1]]})
    assert ext.strip_notebook_progress(clean) is clean


def test_book_extension_keeps_one_copy_of_each_head_script():
    ext = _extension()
    page = (
        "<head>\n<script>const A = 1;</script>\n<script src='x.js'></script>\n"
        "<script>const A = 1;</script>\n</head>\n<body><script>const A = 1;</script></body>"
    )
    fixed = ext.dedupe_head(page)
    assert fixed.count("const A = 1;") == 2  # one in the head, the body's untouched
    assert fixed.startswith("<head>\n<script>const A = 1;</script>\n<script src='x.js'>")
    assert ext.dedupe_head("no head") == "no head"


def test_published_figure_in_the_unit_of_the_reproduced_one():
    reg = claim_register().set_index("id", drop=False)

    def pub(claim_id, unit):
        return published_figure(reg.loc[claim_id].to_dict(), unit)

    coc = pub("binocular.coc", "ratio")  # 0.049 -> 0.041 mm
    assert coc.value == pytest.approx((0.041 / 0.049,) * 2) and coc.text == "0.837 ratio"
    assert coc.detail == "0.041 / 0.049 mm"
    icp = pub("dualarm.icp", "ratio")  # four pairs: mean after / mean before
    after, before = (0.076 + 0.088 + 0.071 + 0.061) / 4, (0.471 + 0.352 + 0.553 + 0.592) / 4
    assert icp.value[0] == pytest.approx(after / before) and icp.text == "0.150 ratio"
    assert "(means of 4)" in icp.detail
    assert pub("dualarm.vs_circular", "ratio").value[0] == pytest.approx(0.100 / 0.556)
    assert pub("dualarm.global", "mm").text == "0.100 mm"  # same unit: the paper's own
    assert pub("hybrid.systematic", "mm").value == (2.0, 4.0)
    assert pub("selfcal.residual", "mm").text == "≤ 0.42 mm"  # a requirement
    none = pub("selfcal.one_step", "ratio")
    assert none.value is None and none.text == "none in the paper"
    assert none.detail == "judged against 1 (no effect)"
    other = pub("hybrid.correlation", "Kolmogorov distance")  # no conversion: says so
    assert other.value is None and other.text == "none in Kolmogorov distance"
    assert "paper: 85.64 %" in other.detail and "bound ≤ 1.36/√n" in other.detail
    assert pub("hybrid.rps", "frame error ratio").detail  # never an empty cell without reason


def test_ratio_of_and_bound_value():
    assert ratio_of("0.049 -> 0.041")[0] == pytest.approx(0.041 / 0.049)
    assert ratio_of("a: 1 / 3 -> 1 / 1; b: 2 -> 1")[0] == pytest.approx((1 / 1) / 2)
    assert ratio_of("0.1 vs 0.5 (other 0.2)")[0] == pytest.approx(0.2)
    assert ratio_of("96.55") is None and ratio_of("1 / 2 -> 1") is None
    assert ratio_of("0 -> 1") is None  # nothing to divide by
    assert bound_value({"kind": "bound", "reference": "3 x CRB RMS (the study's multiple)"}) == 3.0
    assert bound_value({"kind": "bound", "reference": "1.36/sqrt(n) (5 %)"}) is None
    assert bound_value({"kind": "ratio", "reference": "1 (no effect)"}) is None


def test_judged_in_finds_the_section_of_each_claim(tmp_path):
    """Every computed claim links to a section that its notebook has, by the anchor Sphinx
    gives the heading; a notebook without the section falls back to its Claims section."""
    from calstudy.core.paths import REPO_ROOT, RESULTS_DIR

    computed = read_results(RESULTS_DIR / "claims.csv")
    for _, row in computed.iterrows():
        notebook = REPO_ROOT / "notebooks" / f"{row['notebook']}.ipynb"
        found = judged_in(row["id"], notebook)
        assert found is not None, row["id"]
        anchor, heading = found
        assert anchor == section_id(heading) and heading.lower() != "claims", (row["id"], found)
    assert section_id("1. Flexible sensor: hand-eye (Eq. 6)") == "flexible-sensor-hand-eye-eq-6"
    assert section_id("How `hybrid.systematic` moves") == "how-hybrid-systematic-moves"
    nb = tmp_path / "nb.ipynb"
    nb.write_text(
        '{"cells": [{"cell_type": "markdown", "source": ["# Title\\n", "## Other\\n"]},'
        ' {"cell_type": "markdown", "source": "```\\n## not a heading\\n```\\n## Claims"}]}'
    )
    assert headings(nb) == [(2, "Other"), (2, "Claims")]
    assert judged_in("binocular.coc", nb) == ("claims", "Claims")
    assert judged_in("binocular.coc", tmp_path / "missing.ipynb") is None


def test_book_packages_are_pinned():
    """The theme packages the book's look depends on are pinned exactly (a new pydata theme
    once added a second header bar)."""
    from calstudy.core.paths import REPO_ROOT

    pins = {}
    for line in (REPO_ROOT / "environment.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if "==" in line:
            name, version = line.split("==", 1)
            pins[name.strip().lower()] = version.strip()
    for package in ("jupyter-book", "sphinx-book-theme", "pydata-sphinx-theme"):
        assert pins.get(package), f"{package} is not pinned with == in environment.txt"


def test_book_extension_drops_the_icon_script():
    """Pages lose the 1.45 MB icon script (calstudy.css draws the icons), and keep the rest."""
    ext = _extension()
    page = (
        '<head>\n  <script defer src="_static/scripts/fontawesome.js?digest=1"></script>\n'
        '<script src="_static/x.js"></script>\n</head><body>fontawesome.js</body>'
    )
    light = ext.lighten(page)
    assert "scripts/fontawesome.js" not in light and '<script src="_static/x.js">' in light
    assert light.endswith("<body>fontawesome.js</body>")  # only the head's script line goes


def test_verdict_cell_carries_the_robustness_of_the_verdict():
    """Under each verdict: robust, conditional (its inputs and thresholds in the title) or not
    mapped; nothing while the claim is pending."""
    from calstudy.io.book import _verdict_cell

    base = {"verdict": "reproduced", "depends_on": "", "thresholds": ""}
    robust = _verdict_cell({}, pd.Series({**base, "robustness": "robust"}), {})
    assert 'class="rob rob-robust"' in robust and ">robust<" in robust
    cond = _verdict_cell({}, pd.Series({**base, "robustness": "conditional",
                                        "depends_on": "marker-centre noise",
                                        "thresholds": "reproduced below 0.05 px"}), {})
    assert "rob-conditional" in cond
    assert 'title="the verdict depends on marker-centre noise: reproduced below 0.05 px"' in cond
    unmapped = _verdict_cell({}, pd.Series({**base, "robustness": "not mapped"}), {})
    assert "rob-not-mapped" in unmapped and "no robustness map yet" in unmapped
    assert "rob" not in _verdict_cell({}, None, {})


def test_every_glued_text_from_a_notebook_names_its_format():
    """``{glue:text}`path::key``` without a format is read by the book as the key ``path:`` with
    the format ``key`` (no such key: the build fails late, after every notebook ran); each
    chapter's reference from a notebook carries its format (``path::key:.3g``)."""
    pattern = re.compile(r"\{glue:text\}`([^`]*)`")
    bare = [
        f"{page.name}: {ref}"
        for page in sorted((REPO_ROOT / "book").glob("*.md"))
        for ref in pattern.findall(page.read_text(encoding="utf-8"))
        if "::" in ref and ":" not in ref.split("::", 1)[1]
    ]
    assert not bare, bare
