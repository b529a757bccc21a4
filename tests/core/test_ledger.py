"""The assumption ledger: every input of the four papers' scenario files carries its provenance,
a file with an input lacking it is refused, an assumed input needs a range, ``user`` is for
one's own files only, and a value outside its range is refused (a noise level may be 0)."""

from __future__ import annotations

import importlib
import re
import shutil

import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.ledger import PAPER_KEYS
from calstudy.core.paths import REPO_ROOT, data_path
from calstudy.io.ledger import SCENARIO_FILES, ledger_tables, render_ledger_page
from calstudy.papers.dualarm.scenario import load_scenario as load_dualarm
from calstudy.papers.selfcal.scenario import load_scenario as load_selfcal

SELFCAL = data_path("selfcal", "scenario.toml").read_text()
DUALARM = data_path("dualarm", "scenario.toml").read_text()


def _own(tmp_path, text, name="scenario.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_every_study_input_has_provenance():
    """The four papers' scenario files pass, and their ledgers list every input once."""
    tables = ledger_tables()
    assert set(tables) == set(SCENARIO_FILES) == {"hybrid", "selfcal", "binocular", "dualarm"}
    for paper, rows in tables.items():
        assert rows, paper
        names = [(r["file"], r["input"]) for r in rows]
        assert len(names) == len(set(names)), paper
        kinds = ("paper", "derived", "calibrated", "assumed", "study")
        assert all(r["kind"] in kinds for r in rows)
        assert all(r["range"] for r in rows if r["kind"] == "assumed"), paper


def test_paper_keys_are_the_bibliography_keys():
    bib = (REPO_ROOT / "book" / "references.bib").read_text()
    assert set(re.findall(r"@\w+\{(\w+),", bib)) >= set(PAPER_KEYS)


def test_calibrated_inputs_name_code_that_exists():
    for rows in ledger_tables().values():
        for row in rows:
            if row["kind"] == "calibrated":
                module, func = re.search(r"\(([\w.]+):(\w+)\)$", row["source"]).groups()
                assert callable(getattr(importlib.import_module(module), func)), row


def test_input_without_provenance_is_refused(tmp_path):
    line = 'provenance.standoff_mm = { kind = "assumed"'
    assert line in SELFCAL
    text = "\n".join(ln for ln in SELFCAL.splitlines() if not ln.startswith(line))
    with pytest.raises(CalibrationError, match=r"scanner\.standoff_mm = 300\.0: no provenance"):
        load_selfcal(_own(tmp_path, text))


def test_assumed_input_without_range_is_refused(tmp_path):
    old = 'provenance.standoff_mm = { kind = "assumed", range = [150.0, 500.0], why'
    assert old in SELFCAL
    text = SELFCAL.replace(old, 'provenance.standoff_mm = { kind = "assumed", why')
    with pytest.raises(CalibrationError, match=r"scanner\.provenance\.standoff_mm.*needs range"):
        load_selfcal(_own(tmp_path, text))


def test_user_accepted_in_a_user_file_refused_in_the_study_file(tmp_path, monkeypatch):
    old = 'provenance.standoff_mm = { kind = "assumed", range = [150.0, 500.0],'
    text = SELFCAL.replace(old, 'provenance.standoff_mm = { kind = "user", note = "my cell",')
    text = text.replace("standoff_mm = 300.0", "standoff_mm = 700.0", 1)  # outside the range
    own = _own(tmp_path, text)
    assert load_selfcal(own).scanner.standoff_mm == 700.0
    # a whole table of one's own
    start = text.index("[tracker]")
    table = text[start : text.index("[protocol]")]
    mine = "\n".join(ln for ln in table.splitlines() if not ln.startswith("provenance."))
    text2 = text.replace(table, mine.replace("[tracker]", '[tracker]\nprovenance = "user"') + "\n")
    load_selfcal(_own(tmp_path, text2, "table.toml"))
    # the same file as a study file: user refused
    study = tmp_path / "data"
    study.mkdir()
    shutil.copy(own, study / "scenario.toml")
    monkeypatch.setattr("calstudy.core.schema.DATA_DIR", study.resolve())
    with pytest.raises(CalibrationError, match=r"provenance\.standoff_mm: kind 'user' is for"):
        load_selfcal(study / "scenario.toml")


def test_value_outside_its_range_is_refused_zero_noise_is_not(tmp_path):
    text = DUALARM.replace("sigma_px = 0.0328", "sigma_px = 0.5", 1)
    with pytest.raises(
        CalibrationError, match=r"detection\.sigma_px = 0\.5: outside its plausible range"
    ):
        load_dualarm(_own(tmp_path, text))
    text = DUALARM.replace("sigma_px = 0.0328", "sigma_px = 0.0", 1)  # an oracle
    assert load_dualarm(_own(tmp_path, text, "oracle.toml")).detection.sigma_px == 0.0
    text = DUALARM.replace("baseline_mm = 200.0", "baseline_mm = 0.0", 1)  # not a noise level
    with pytest.raises(CalibrationError, match=r"stereo\.baseline_mm = 0\.0: must be > 0"):
        load_dualarm(_own(tmp_path, text, "zero.toml"))


def test_misspelt_provenance_key_is_refused(tmp_path):
    text = SELFCAL.replace("provenance.standoff_mm =", "provenance.standof_mm =", 1)
    with pytest.raises(CalibrationError, match=r"scanner\.provenance\.standof_mm: \[scanner\] has"):
        load_selfcal(_own(tmp_path, text))


def test_ledger_page_lists_four_tables():
    page = render_ledger_page()
    for paper in SCENARIO_FILES:
        assert f"({paper}-ledger)=" in page
    assert page.count('<table class="ledger">') == 4
