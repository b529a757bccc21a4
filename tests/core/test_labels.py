"""Plain words for claim ids, inputs and column names (calstudy.core.labels)."""

from __future__ import annotations

import pytest

from calstudy.claims import claim_register
from calstudy.core.labels import CLAIM_LABELS, label, plain, scenario_tables


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("within_0p3_pct", "within 0.3 mm (%)"),
        ("bin_le_0p1_pct", "bin ≤ 0.1 (%)"),
        ("t2_without_mm", "Table 2 without (mm)"),
        ("rot_err_updated_mrad", "rot err updated (mrad)"),
        ("translation_range_mm", "range of the pure translations (mm)"),
        ("err", "err"),
        ("rot_err_deg", "rot err (deg)"),
        ("sigma_um", "sigma (µm)"),
        ("trials", "trials"),
        ("hybrid.handeye", "hand-eye calibration"),
    ],
)
def test_label(name, words):
    assert label(name) == words


def test_label_with_a_unit_given():
    assert label("err", "mm") == "err (mm)"
    assert label("part_sigma_mm", "µm") == "part-to-part scatter (µm)"


def test_plain_rewrites_ids_and_keeps_file_names():
    text = "hybrid.handeye against part_sigma_mm: see robot_sweep.csv and results/a_b/"
    assert plain(text) == (
        "hand-eye calibration against part-to-part scatter (mm): see robot_sweep.csv and "
        "results/a_b/"
    )
    assert plain("no identifier here.") == "no identifier here."


def test_every_claim_of_the_register_has_words():
    ids = set(claim_register()["id"])
    assert ids <= set(CLAIM_LABELS), sorted(ids - set(CLAIM_LABELS))
    assert len(set(CLAIM_LABELS.values())) == len(CLAIM_LABELS)  # no two claims alike


def test_plain_writes_scenario_inputs_by_their_dotted_keys_as_words():
    assert plain("scanner.sigma_point_mm: holds") == "scanner sigma point (mm): holds"
    assert plain("sensor.design_zyx_deg[1]") == "sensor design zyx [1] (deg)"
    assert plain("station.workpiece.datum_A_slot_mm[0] matters") == (
        "station workpiece datum A slot [0] (mm) matters"
    )
    kept = "see robustness.csv, data/dualarm/scenario.toml, e.g. this, calstudy.io.tolerance"
    assert plain(kept) == kept


def test_plain_rewrites_only_dotted_names_of_a_scenario_table():
    """A dotted name is an input only when its first part is a table (or file) of a scenario:
    a module's name stays as it is."""
    assert {"station", "sensor", "scanner", "poor_start", "production"} <= scenario_tables()
    assert "scipy" not in scenario_tables()
    text = "see scipy.stats.ksone and cv2.solvePnP; station.workpiece.datum_A_slot_mm[0] moves"
    assert plain(text) == (
        "see scipy.stats.ksone and cv2.solvePnP; station workpiece datum A slot [0] (mm) moves"
    )
