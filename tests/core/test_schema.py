"""Reading TOML files: the parsed-table cache never hands out stale or shared tables; inputs
replaced before validation (overrides) or in a validated model (derived values follow)."""

import os
import re
from functools import cached_property

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core.schema import Radians, Schema, apply_overrides, read_toml


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
        with pytest.raises(CalibrationError, match=rf"override '{re.escape(key)}': the scenario"):
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
