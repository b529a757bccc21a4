"""The simulated hybrid station: exact recovery without noise, and what the nominal model costs."""

import numpy as np
import pytest
from support import ideal_station

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.estimators import handeye as he
from calstudy.papers.hybrid import station as st


def test_noise_free_station_recovers_everything_exactly():
    s, rng = ideal_station()
    meas, _ = st.simulate_sphere_measurements(s, 4, 6, rng)
    s2f = he.sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    assert geo.rotation_error(s2f, s.sensor2flange_true) < 1e-9
    assert geo.translation_error(s2f, s.sensor2flange_true) < 1e-7
    rows = st.stationary_trial(s, s2f, rng)
    worst_rot = max(r["rotation_error_deg"] for r in rows)
    worst_trans = max(r["translation_error_mm"] for r in rows)
    assert worst_rot < 1e-6 and worst_trans < 1e-6
    calibrated = np.array([r["estimate"] for r in rows if r["variant"] == "homography"])
    s = st.with_overrides(s, datum_sigma=0.0)
    for r in st.rps_trial(s, calibrated, rng, penalties=(1.0, 1e4)):
        assert r["frame_error_mm"] < 1e-6


def test_systematic_error_disappears_when_true_and_nominal_robots_coincide():
    """Noise-free, the whole chain is exact with a perfect robot and mm-wrong with a real one."""
    errors = {}
    for robot_errors in (False, True):
        s, rng = ideal_station(seed=3, robot_errors=robot_errors)
        meas, _ = st.simulate_sphere_measurements(s, 4, 6, rng)
        s2f = he.sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
        rows = st.stationary_trial(s, s2f, rng)
        errors[robot_errors] = max(r["field_error_mm"] for r in rows if r["variant"] == "pnp")
    assert errors[False] < 1e-6
    assert errors[True] > 0.1


def test_ml_reaches_the_cramer_rao_bound_in_the_noise_only_scenario():
    df = st.handeye_monte_carlo(5, 60, "sensor noise only", baselines=False)
    summary = st.summarise_errors(df, ["method"]).set_index("method")
    ratio = summary.loc["ML", "trans_mm_rms"] / summary.loc["CRB", "trans_mm_rms"]
    assert 0.7 < ratio < 1.4


def test_monte_carlo_is_deterministic_per_seed():
    a = st.handeye_monte_carlo(2, 3, "station", baselines=False)
    b = st.handeye_monte_carlo(2, 3, "station", baselines=False)
    c = st.handeye_monte_carlo(3, 3, "station", baselines=False)
    assert a.equals(b)
    assert not a.equals(c)


def test_unknown_scenario_rejected():
    with pytest.raises(CalibrationError, match="unknown scenario 'lab'"):
        st.handeye_monte_carlo(1, 1, "lab")


def test_calibrate_from_user_csv(tmp_path):
    s, rng = ideal_station(seed=4)
    meas, _ = st.simulate_sphere_measurements(s, 4, 6, rng)
    path = tmp_path / "mine.csv"
    he.write_sphere_measurements(meas, path)
    source, _, paper, ml, table = st.calibrate_handeye(str(path), 0, [0.01, 0.02, 0.01])
    assert source.startswith(f"user measurements from {path}")
    assert "truth" not in table
    assert geo.translation_error(paper.value, s.sensor2flange_true) < 1e-6
    assert geo.translation_error(ml.value, s.sensor2flange_true) < 1e-6
