"""What the hybrid study reads from data/hybrid: the published Table 1, the feature points, the
production scenario, and the errors of a missing file or key."""

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.schema import with_inputs
from calstudy.papers.hybrid import scenario

published = scenario.load_published()
table1 = published.table1


def test_published_table1_counts_match_its_percentages():
    for counts, percent in (
        (table1.deviation_counts, table1.deviation_percent),
        (table1.correlation_counts, table1.correlation_percent),
    ):
        assert sum(counts) == 174
        # the paper prints 10 / 174 = 5.747 % as 5.74 (truncated), hence 0.01 and not 0.005
        np.testing.assert_allclose(100 * np.array(counts) / 174, percent, atol=0.01)


def test_duplicated_feature_ids_in_the_data_file_raise():
    features = [f.model_dump() for f in scenario.load_production().flexible.features]
    features[1]["id"] = features[0]["id"]
    message = r"production.toml: feature point ids repeated: \['H01'\]: each point needs its own id"
    with pytest.raises(CalibrationError, match=message):
        scenario.load_production(overrides={"flexible.features": features})


def test_scenario_checks_its_values():
    sc = scenario.load_scenario()
    with pytest.raises(CalibrationError, match="protocol.n_compensation = 2: must be >= 3"):
        with_inputs(sc, {"production.protocol.n_compensation": 2})
    with pytest.raises(CalibrationError, match="part_sigma_mm = -0.1: must be >= 0"):
        with_inputs(sc, {"production.variation.part_sigma_mm": -0.1})


def test_overrides_are_validated_as_the_file():
    """An override inside the ledger's range loads; outside it, or of no input, it is refused
    naming the key and the value; a sweep's copy (with_inputs) goes beyond the range."""
    sc = scenario.load_scenario(overrides={"production.variation.part_sigma_mm": 0.2})
    assert sc.production.variation.part_sigma_mm == 0.2
    assert scenario.load_scenario().production.variation.part_sigma_mm == 0.5
    with pytest.raises(
        CalibrationError, match=r"variation\.part_sigma_mm = 1\.0: outside its plausible range"
    ):
        scenario.load_scenario(overrides={"production.variation.part_sigma_mm": 1.0})
    unknown = r"production\.toml: override 'variation\.part_sigma': .* names no"
    with pytest.raises(CalibrationError, match=unknown):
        scenario.load_scenario(overrides={"production.variation.part_sigma": 0.2})
    with pytest.raises(CalibrationError, match="begins with 'station.' or 'production.'"):
        scenario.load_scenario(overrides={"variation.part_sigma_mm": 0.2})
    wide = with_inputs(sc, {"production.variation.part_sigma_mm": 1.0})
    assert wide.production.variation.part_sigma_mm == 1.0


def test_features_match_the_paper_counts():
    f = scenario.load_scenario().features
    assert len(f.ids) == 58 and len(f.flexible) == 48 and len(f.stationary) == 10
    assert int(f.fixed.sum()) == 6
    assert [f.ids[i] for i in np.argwhere(f.fixed)[:, 0]] == [
        "S01",
        "S01",
        "S02",
        "S02",
        "S02",
        "S03",
    ]


def test_station_reads_the_move_ranges_and_the_panel_size_from_the_data():
    cfg = scenario.load_station()
    assert cfg.calibration_moves.across_plane_range_mm == 2.0
    assert cfg.calibration_moves.rotation_min_deg == 10.0
    assert cfg.workpiece.size_mm == [1500.0, 1200.0]


def test_published_numbers_are_the_papers():
    assert table1.within_0p3_percent == 96.55 and table1.r_above_0p7_percent == 85.64
    assert published.systematic.range_mm == (2.0, 4.0)
    assert published.table1.deviation_edges_mm == (0.1, 0.2, 0.3, 0.5)
    assert published.table1.correlation_edges == (0.6, 0.7, 0.8, 0.9)


def test_missing_file_and_missing_key_raise(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        scenario.load_scenario(tmp_path / "none.toml")
    path = tmp_path / "production.toml"
    path.write_text("[protocol]\nn_before = 10\n")
    with pytest.raises(CalibrationError, match=r"variation: missing \(required\)"):
        scenario.load_scenario(path)
    bad = tmp_path / "station.toml"
    bad.write_text("[robot]\nrepeatability_mm = 0.06\n")
    with pytest.raises(CalibrationError, match=r"station\.toml: handeye: missing \(required\)"):
        scenario.load_station(bad)
