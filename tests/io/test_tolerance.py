"""The tolerances of "the same result" across machines (calstudy.io.tolerance)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from calstudy.io.tolerance import TABLE_RTOL, TRIAL_RTOL, column_unit, compare_tables


@pytest.mark.parametrize(
    ("name", "unit"),
    [
        ("dy_mm", "mm"),
        ("rotation_error_deg", "deg"),
        ("rot_err_preliminary_mrad", "mrad"),
        ("shift_px_rms", "px"),
        ("after_ci_low", "1"),
        ("t2_without", "mm"),
        ("fig13_exact_p7_true", "mm"),
        ("id_a3", "mm"),
        ("ml_theta2", "rad"),
        ("within_0p3", "%"),
        ("ratio", "1"),
    ],
)
def test_units_are_read_from_the_names(name, unit):
    assert column_unit(name) == unit


def test_a_nanometre_passes_and_a_micrometre_fails():
    want = pd.DataFrame({"dy_mm": [0.000352293, 10.0], "method": ["a", "b"], "n": [3, 4]})
    # the difference another CPU gave on a third of a micrometre: 1.3e-8 mm, relative 3.6e-5
    got = want.assign(dy_mm=[0.000352306, 10.0 * (1 + 0.5 * TRIAL_RTOL)])
    assert compare_tables(got, want, TRIAL_RTOL) == []
    far = want.assign(dy_mm=[0.000352293 + 1e-3, 10.0])
    (bad,) = compare_tables(far, want, TRIAL_RTOL)
    assert (bad.column, bad.row) == ("dy_mm", 0) and "difference" in str(bad)


def test_angles_by_the_nanoradian():
    want = pd.DataFrame({"err_rad": [1e-7], "err_deg": [1e-5]})
    ok = pd.DataFrame({"err_rad": [1e-7 + 5e-10], "err_deg": [1e-5 + math.degrees(5e-10)]})
    assert compare_tables(ok, want, TRIAL_RTOL) == []
    bad = pd.DataFrame({"err_rad": [1e-7 + 5e-9], "err_deg": [1e-5 + math.degrees(5e-9)]})
    assert [m.column for m in compare_tables(bad, want, TRIAL_RTOL)] == ["err_rad", "err_deg"]


def test_counts_text_and_nan_exactly():
    want = pd.DataFrame({"iterations": [4.0, np.nan], "verdict": ["reproduced", None]})
    assert compare_tables(want.copy(), want, TABLE_RTOL) == []
    one_more = want.assign(iterations=[5.0, np.nan])
    assert [m.tolerance for m in compare_tables(one_more, want, TABLE_RTOL)] == [None]
    other = want.assign(verdict=["direction only", None])
    assert [m.column for m in compare_tables(other, want, TABLE_RTOL)] == ["verdict"]
    filled = want.assign(iterations=[4.0, 4.0])
    assert [m.column for m in compare_tables(filled, want, TABLE_RTOL)] == ["iterations"]


def test_shape_differences_are_reported():
    a = pd.DataFrame({"x": [1.0]})
    assert compare_tables(a.rename(columns={"x": "y"}), a, TABLE_RTOL)[0].column == "<columns>"
    assert compare_tables(pd.DataFrame({"x": [1.0, 2.0]}), a, TABLE_RTOL)[0].column == "<rows>"


def test_a_solver_may_take_one_step_more_and_no_other_count_may():
    want = pd.DataFrame({"good_solver_iterations": [4.0], "iterations": [4.0], "rounds": [2]})
    one_more = pd.DataFrame({"good_solver_iterations": [5.0], "iterations": [4.0], "rounds": [3]})
    assert compare_tables(one_more, want, TRIAL_RTOL) == []
    two_more = pd.DataFrame({"good_solver_iterations": [6.0], "iterations": [5.0], "rounds": [2]})
    bad = compare_tables(two_more, want, TRIAL_RTOL)
    assert [m.column for m in bad] == ["good_solver_iterations", "iterations"]
