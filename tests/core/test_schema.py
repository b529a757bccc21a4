"""Reading TOML files: the parsed-table cache never hands out stale or shared tables; inputs
replaced before validation (overrides), in a validated model (derived values follow) or in a
changed copy validated as its file."""

import os
import re
from functools import cached_property

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.schema import (
    Radians,
    Schema,
    apply_overrides,
    load_paper_file,
    one_each,
    ordered,
    read_toml,
    validate,
    with_inputs,
)
from calstudy.core.trialcache import _scenario_digest
from calstudy.papers.selfcal.scenario import load_scenario


def test_read_toml_rereads_an_edited_file_and_hands_out_copies(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text("[robot]\nname = 'a'\nreach_mm = 900.0\n")
    first = read_toml(path, "cell")
    first["robot"]["reach_mm"] = -1.0  # a caller changing its copy
    assert read_toml(path, "cell") == {"robot": {"name": "a", "reach_mm": 900.0}}
    path.write_text("[robot]\nname = 'b'\nreach_mm = 1200.0\n")
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert read_toml(path, "cell") == {"robot": {"name": "b", "reach_mm": 1200.0}}


def test_read_toml_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_toml(tmp_path / "missing.toml", "cell")
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\n")
    with pytest.raises(CalibrationError, match="bad.toml: not valid TOML"):
        read_toml(bad, "cell")


def test_apply_overrides_replaces_inputs_in_a_new_table_and_names_an_unknown_key():
    table = {"survey": {"sigma_px": 0.1, "provenance": {"sigma_px": {"kind": "study"}}}, "n": 3}
    out = apply_overrides(table, {"survey.sigma_px": 0.05, "n": 4})
    assert out == {
        "survey": {"sigma_px": 0.05, "provenance": table["survey"]["provenance"]},
        "n": 4,
    }
    assert table["survey"]["sigma_px"] == 0.1 and table["n"] == 3  # the table is not changed
    assert apply_overrides(table, None) == table
    for key in ("survey.sigma", "surveys.sigma_px", "survey", "n.m", "survey.provenance.sigma_px"):
        with pytest.raises(CalibrationError, match=rf"override '{re.escape(key)}': .* no input"):
            apply_overrides(table, {key: 1.0})


class _Lens(Schema):
    tilt_deg: float
    radius_mm: float

    tilt = Radians("tilt_deg")

    @cached_property
    def diameter_mm(self) -> float:
        return 2.0 * self.radius_mm


class _Head(Schema):
    lens: _Lens
    n: int


def test_replace_sets_dotted_inputs_and_derived_values_follow():
    head = _Head(lens=_Lens(tilt_deg=30.0, radius_mm=2.0), n=1)
    assert head.lens.diameter_mm == 4.0  # cached on the original
    other = head.replace({"lens.radius_mm": 5.0, "lens.tilt_deg": 90.0, "n": 2})
    assert other.lens.diameter_mm == 10.0 and other.n == 2
    assert other.lens.tilt == np.deg2rad(90.0) and head.lens.tilt == np.deg2rad(30.0)
    assert head.lens.radius_mm == 2.0 and head.lens.diameter_mm == 4.0
    assert head.lens.model_copy(update={"radius_mm": 1.0}).diameter_mm == 2.0
    with pytest.raises(CalibrationError, match=r"lens\.focal_mm: no such input in _Lens"):
        head.replace({"lens.focal_mm": 1.0})
    with pytest.raises(CalibrationError, match=r"n\.m: no such input in _Head"):
        head.replace({"n.m": 1.0})


def test_apply_overrides_returns_a_new_table_and_names_an_unknown_key():
    table = {"scanner": {"sigma_point_mm": 0.02, "provenance": {"sigma_point_mm": {}}}}
    out = apply_overrides(table, {"scanner.sigma_point_mm": 0.05})
    assert out == {"scanner": {"sigma_point_mm": 0.05, "provenance": {"sigma_point_mm": {}}}}
    assert table["scanner"]["sigma_point_mm"] == 0.02  # the caller's table is left as it was
    assert apply_overrides(table, None) == table and apply_overrides(table, None) is not table
    for key, named in (
        ("scanner.sigma_point", "'scanner.sigma_point'"),
        ("scaner.sigma_point_mm", "'scaner'"),
        ("scanner.sigma_point_mm.x", "'scanner.sigma_point_mm.x'"),
        ("scanner.provenance", "'scanner.provenance'"),
    ):
        with pytest.raises(CalibrationError, match=f"override '{key}': {named} names no input"):
            apply_overrides(table, {key: 1.0})


def test_overrides_are_validated_as_the_file_and_copies_go_beyond_the_ranges():
    """load_scenario(overrides=...) refuses a value outside its ledger range as the file would;
    with_inputs validates types and bounds again but lets a sweep leave the range, and builds
    the derived objects afresh."""
    scenario = load_scenario(overrides={"scanner.sigma_point_mm": 0.03})
    assert scenario.scanner.sigma_point_mm == 0.03
    with pytest.raises(CalibrationError, match=r"scanner\.sigma_point_mm = 0\.9: outside its"):
        load_scenario(overrides={"scanner.sigma_point_mm": 0.9})
    wide = with_inputs(scenario, {"scanner.sigma_point_mm": 0.9})
    assert wide.scanner.sigma_point_mm == 0.9 and scenario.scanner.sigma_point_mm == 0.03
    with pytest.raises(CalibrationError, match=r"scanner\.sigma_point_mm = 0\.9: outside its"):
        with_inputs(scenario, {"scanner.sigma_point_mm": 0.9}, ranges=True)
    with pytest.raises(CalibrationError, match=r"scanner\.sigma_point_mm = 2\.0: must be >= 0"):
        with_inputs(scenario, {"scanner.sigma_point_mm": 2.0})
    before = scenario.base.rough
    moved = with_inputs(scenario, {"base.rough_xyz_mm": [0.0, 0.0, 0.0]})
    assert np.all(moved.base.rough[:3, 3] == 0.0) and np.any(before[:3, 3] != 0.0)


def test_a_models_cache_key_is_its_fields_not_its_cached_properties():
    fresh = load_scenario(overrides={"scanner.sigma_point_mm": 0.021})
    digest = _scenario_digest(fresh, "x")
    assert fresh.nominal_robot.name  # fills a cached property
    assert _scenario_digest(fresh, "x") == digest
    assert _scenario_digest(with_inputs(fresh, {"scanner.sigma_point_mm": 0.022}), "x") != digest


def test_a_file_that_is_not_toml_is_named_once(tmp_path):
    from calstudy.core.schema import Schema, load_model

    bad = tmp_path / "bad.toml"
    bad.write_text("x = [1, \n")
    with pytest.raises(CalibrationError) as info:
        load_model(bad, Schema, "a scenario")
    assert str(info.value).count(str(bad)) == 1, str(info.value)


class _Ordered(Schema):
    low: float
    high: float
    first: float = 0.0
    last: float = 1.0
    names: list[str] = []
    xyz: list[float] = []
    tilts: list[float] = []

    _strict = ordered("low", "high")
    _loose = ordered("first", "last", strict=False)
    _counts = one_each("names", "xyz", "tilts", note="one per name")


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"low": 2.0, "high": 2.0}, r"t: low = 2\.0 is not below high = 2\.0$"),
        ({"low": 1.0, "high": 2.0, "first": 1.5}, r"t: first = 1\.5 exceeds last = 1\.0$"),
        (
            {"low": 1.0, "high": 2.0, "names": ["a", "b"], "xyz": [0.0], "tilts": [0.0, 1.0]},
            r"t: 2 names but 1 xyz; one per name$",
        ),
        (
            {"low": 1.0, "high": 2.0, "names": ["a"], "xyz": [0.0, 1.0], "tilts": []},
            r"t: 1 names but 2 xyz, 0 tilts; one per name$",
        ),
    ],
)
def test_ordered_and_one_each_name_the_inputs_and_their_values(table, message):
    with pytest.raises(CalibrationError, match=message):
        validate(_Ordered, table, "t")


def test_ordered_allows_equal_values_when_not_strict_and_one_each_equal_counts():
    table = {"low": 1.0, "high": 2.0, "first": 1.0, "names": ["a"], "xyz": [0.0], "tilts": [1.0]}
    assert validate(_Ordered, table, "t").first == 1.0


def test_load_paper_file_reads_the_papers_file_or_ones_own(tmp_path):
    own = tmp_path / "cell.toml"
    own.write_text("low = 1.0\nhigh = 3.0\n")
    assert load_paper_file("selfcal", "missing.toml", _Ordered, "cell", own).high == 3.0
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        load_paper_file("selfcal", "missing.toml", _Ordered, "cell")
