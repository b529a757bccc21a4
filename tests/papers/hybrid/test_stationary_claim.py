"""hybrid.stationary judged by a pooled, paired RMS ratio: the interval against a paired bootstrap,
an oracle that passes where a per-trial bound cannot, and controls that catch broken methods."""

import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy.claims import control_rows, judge_claim
from calstudy.core.paths import RESULTS_DIR
from calstudy.core.stats import rms_ratio_interval
from calstudy.core.verdicts import judge_rms_ratio
from calstudy.papers.hybrid import report
from calstudy.papers.hybrid.report_sweeps import CLAIMS, ML_MULTIPLE, station_against_design

TRIALS = RESULTS_DIR / "01_hybrid_global_calibration" / "trials_stationary.csv"


def _chains(n=200, excess=1.2, seed=3):
    """Per trial RMS errors of two chains that share a target error (3-D, per trial) and differ
    in their own noise, the homography's ``excess`` times the PnP's: the structure of the
    stationary trials."""
    rng = np.random.default_rng(seed)
    target = rng.normal(0.0, 0.05, (n, 3))
    own = rng.normal(0.0, 0.05, (n, 3))
    pnp = np.linalg.norm(target + own, axis=1)
    hom = np.linalg.norm(target + excess * own + rng.normal(0, 0.03, (n, 3)), axis=1)
    return hom, pnp


@pytest.mark.parametrize("excess", [1.2, 3.0])
def test_rms_ratio_interval_agrees_with_a_paired_bootstrap(excess):
    hom, pnp = _chains(excess=excess)
    ratio, lo, hi = rms_ratio_interval(hom, pnp)
    assert ratio == pytest.approx(np.sqrt(np.mean(hom**2) / np.mean(pnp**2)))
    idx = np.random.default_rng(0).integers(0, hom.size, (4000, hom.size))
    boot = np.sqrt(np.mean(hom[idx] ** 2, axis=1) / np.mean(pnp[idx] ** 2, axis=1))
    b_lo, b_hi = np.quantile(boot, [0.025, 0.975])
    assert lo == pytest.approx(b_lo, abs=0.1 * (b_hi - b_lo))
    assert hi == pytest.approx(b_hi, abs=0.1 * (b_hi - b_lo))


def test_rms_ratio_interval_refuses_unpaired_or_zero_input():
    with pytest.raises(CalibrationError, match="after has 3 trials and before 2"):
        rms_ratio_interval([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(CalibrationError, match="before is zero in every trial"):
        rms_ratio_interval([1.0] * 6, [0.0] * 6)
    with pytest.raises(CalibrationError, match="5 trials cannot give an interval"):
        rms_ratio_interval([1.0] * 5, [1.0] * 5)


def test_pooled_ratio_passes_a_good_method_that_a_per_trial_bound_fails():
    hom, pnp = _chains(excess=1.2)
    v = judge_rms_ratio(hom, pnp, bound=ML_MULTIPLE)
    assert v.verdict == "reproduced"
    assert np.quantile(hom / pnp, 0.95) > ML_MULTIPLE  # the per-trial tail misses it


@pytest.mark.parametrize(
    ("excess", "n", "verdict"),
    [(1.2, 200, "reproduced"), (2.0, 200, "not reproduced"), (1.65, 30, "direction only")],
)
def test_pooled_ratio_catches_a_method_twice_the_rival(excess, n, verdict):
    hom, pnp = _chains(n=n, excess=excess)
    v = judge_rms_ratio(hom, pnp, bound=ML_MULTIPLE, min_trials=30)
    assert v.verdict == verdict
    assert (v.ci_low <= v.median <= ML_MULTIPLE < v.ci_high) == (verdict == "direction only")


def _table(hom, pnp, design, oracle_hom, oracle_pnp):
    return pd.DataFrame(
        {
            "images only, homography": hom,
            "images only, pnp": pnp,
            "design pose": design,
            "exact target, homography": oracle_hom,
            "exact target, pnp": oracle_pnp,
        }
    )


def test_the_null_control_fails_doing_nothing_and_catches_a_broken_test():
    hom, pnp = _chains()
    oh, op = _chains(seed=4)
    columns = CLAIMS["hybrid.stationary"]
    judged = judge_claim(
        "hybrid.stationary", _table(hom, pnp, 10 * pnp + 1, oh, op), columns,
        reference=ML_MULTIPLE,
    )
    assert judged.claim.verdict == "reproduced"
    assert judged.null.verdict == "not reproduced"
    assert len(control_rows("hybrid.stationary", judged)) == 2
    # a station without mounting error: the design pose is as good as a calibration, so the
    # null reproduces the claim and the control rows refuse the test as broken
    broken = judge_claim(
        "hybrid.stationary", _table(hom, pnp, pnp, oh, op), columns, reference=ML_MULTIPLE
    )
    assert broken.null.verdict == "reproduced"
    with pytest.raises(CalibrationError, match="null control came out 'reproduced'"):
        control_rows("hybrid.stationary", broken)


def test_the_oracle_gate_catches_a_model_without_the_mechanism():
    hom, pnp = _chains()
    oh, op = _chains(excess=2.5, seed=4)  # the exact target does not let the bound be met
    oh, op = 0.1 * oh, 0.1 * op  # judged against its own rival, not the images-only one
    judged = judge_claim(
        "hybrid.stationary", _table(hom, pnp, 10 * pnp, oh, op), CLAIMS["hybrid.stationary"],
        reference=ML_MULTIPLE,
    )
    assert judged.claim.verdict == "not testable"


@pytest.mark.skipif(not TRIALS.is_file(), reason="no committed trials")
def test_committed_trials_a_broken_homography_is_caught_and_the_design_pose_wins_the_station():
    stationary = pd.read_csv(TRIALS, keep_default_na=False, na_values=[""])
    numbers = report.stationary_numbers(stationary)
    assert numbers["stationary_oracle_ratio"] <= ML_MULTIPLE
    assert numbers["stationary_oracle_p95"] > ML_MULTIPLE  # why no per-trial bound is judged
    # the station scenario: the calibrated chain against the design pose, as the sentence says
    lo = numbers["station_design_low"]
    assert lo > 1.0 and "design pose is better" in numbers["station_design_sentence"]
    assert f"{numbers['station_design_ratio']:.3g}" in numbers["station_design_sentence"]
    # a homography chain whose field error is doubled comes out not reproduced
    images = (stationary["variant"] == "images only, homography") & (
        stationary["scenario"] == report.VERDICT_SCENARIO
    )
    broken = stationary.copy()
    broken.loc[images, "field_error_mm"] *= 2.0
    rows, _ = report.calibration_claims(
        pd.read_csv(TRIALS.with_name("trials_handeye.csv")), broken, "nb"
    )
    assert {r.id: r.verdict for r in rows}["hybrid.stationary"] == "not reproduced"


def _station(homography, design):
    """A long stationary table of the station scenario: one sensor per trial."""
    n = len(homography)
    return pd.DataFrame(
        {
            "scenario": "station",
            "step": "stationary",
            "trial": np.r_[np.arange(n), np.arange(n)],
            "sensor": 1,
            "variant": ["homography"] * n + ["design pose"] * n,
            "field_error_mm": np.r_[homography, design],
        }
    )


@pytest.mark.parametrize(
    ("scale", "finding"),
    [
        (2.0, "the uncalibrated design pose is better than the calibrated chain"),
        (0.5, "the calibrated chain is better than the uncalibrated design pose"),
        (1.0, "cannot be told apart"),
    ],
)
def test_station_against_design_says_which_is_better(scale, finding):
    rng = np.random.default_rng(5)
    design = np.abs(rng.normal(1.0, 0.3, 100))
    calibrated = scale * design * rng.uniform(0.9, 1.1, 100)
    out = station_against_design(_station(calibrated, design))
    assert finding in out["station_design_sentence"]
    assert out["station_design_low"] <= out["station_design_ratio"] <= out["station_design_high"]
