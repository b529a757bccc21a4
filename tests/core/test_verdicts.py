"""Tests of the v2 verdict rule: the median interval, the verdicts, the controls.

Every random draw is seeded, and hypothesis runs derandomized without a database, so the
suite gives the same result on every run.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binom

from calstudy.core.errors import CalibrationError
from calstudy.core.stats import median_interval, median_ranks
from calstudy.core.verdicts import (
    Verdict,
    check_null_control,
    judge,
    judge_controls,
    not_testable,
    oracle_gate,
    replication_rate,
)

PROPERTY = settings(max_examples=60, deadline=None, derandomize=True, database=None)
SEEDS = st.integers(min_value=0, max_value=2**32 - 1)


def paired(rng: np.random.Generator, centre: float, n: int = 200, spread: float = 0.05):
    """(after, before) of ``n`` trials whose paired ratio is ``centre`` times log-normal noise."""
    before = rng.lognormal(0.0, 0.3, n)
    return centre * before * np.exp(rng.normal(0.0, spread, n)), before


def symmetric_ratio(rng: np.random.Generator, n: int = 200, spread: float = 0.05) -> np.ndarray:
    """Ratios ``exp(+-e)``: exactly as many above 1 as below, so no effect by construction."""
    e = np.abs(rng.normal(0.0, spread, n // 2)) + 1e-6
    return rng.permutation(np.exp(np.concatenate([e, -e])))


# ----------------------------------------------------------------------------------------------
# median_interval


def brute_force_ranks(n: int, level: float) -> tuple[int, int, float]:
    """Largest symmetric j whose coverage sum_{i=j}^{n-j} C(n, i) / 2^n reaches ``level``."""
    for j in range(n // 2, 0, -1):
        coverage = sum(math.comb(n, i) for i in range(j, n - j + 1)) / 2**n
        if coverage >= level:
            return j, n + 1 - j, coverage
    raise AssertionError(f"no rank reaches {level} with n={n}")


def enumerated_coverage(n: int, j: int, k: int) -> float:
    """Share of the 2^n below/above patterns with j <= (number below the median) < k."""
    hits = sum(j <= sum(p) < k for p in itertools.product((0, 1), repeat=n))
    return hits / 2**n


@pytest.mark.parametrize(
    ("n", "j", "k", "coverage"),
    [
        (6, 1, 6, 1 - 2 * 1 / 64),  # P(B = 0) = 1/64
        (8, 1, 8, 1 - 2 * 1 / 256),  # P(B <= 1) = 9/256 > 0.025, so j stays 1
        (9, 2, 8, 1 - 2 * 10 / 512),  # P(B <= 1) = 10/512 <= 0.025 < P(B <= 2) = 46/512
        (10, 2, 9, 1 - 2 * 11 / 1024),
        (20, 6, 15, 1 - 2 * 21700 / 2**20),  # the textbook ranks 6 and 15 of 20
    ],
)
def test_known_ranks_for_small_n(n, j, k, coverage):
    assert median_ranks(n, 0.95) == (j, k, pytest.approx(coverage, abs=1e-12))
    # by hand against scipy: rank j reaches the level, rank j + 1 does not
    assert 1 - 2 * binom.cdf(j - 1, n, 0.5) == pytest.approx(coverage, abs=1e-12)
    assert 1 - 2 * binom.cdf(j, n, 0.5) < 0.95
    x = np.random.default_rng(n).permutation(np.arange(1.0, n + 1))
    assert median_interval(x) == (pytest.approx((n + 1) / 2), j, k)


@pytest.mark.parametrize("level", [0.5, 0.8, 0.9, 0.95, 0.99])
def test_ranks_match_brute_force(level):
    n_min = next(n for n in range(1, 50) if 1 - 2 * 0.5**n >= level)
    for n in range(n_min, 80):
        assert median_ranks(n, level) == pytest.approx(brute_force_ranks(n, level), abs=1e-12)
    for n in range(n_min, 12):
        j, k, coverage = median_ranks(n, level)
        assert enumerated_coverage(n, j, k) == pytest.approx(coverage, abs=1e-12)


@pytest.mark.parametrize(
    ("n", "draw", "true_median"),
    [
        (200, lambda rng, size: rng.exponential(1.0, size), math.log(2.0)),
        (20, lambda rng, size: rng.standard_cauchy(size), 0.0),
    ],
    ids=["exponential-200", "cauchy-20"],
)
def test_coverage_by_simulation(n, draw, true_median):
    reps = 2000
    rng = np.random.default_rng(20240611)
    hits = 0
    for row in draw(rng, (reps, n)):
        _, lo, hi = median_interval(row)
        hits += lo < true_median < hi
    exact = median_ranks(n, 0.95)[2]
    assert exact >= 0.95  # conservative by construction
    tolerance = 3 * math.sqrt(exact * (1 - exact) / reps)  # binomial spread of the simulation
    assert abs(hits / reps - exact) <= tolerance


def test_too_few_samples_for_the_level():
    with pytest.raises(CalibrationError, match="5 samples cannot give a 95 % interval.*at least 6"):
        median_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    with pytest.raises(CalibrationError, match="at least 8 needed"):
        median_interval(np.arange(7.0), level=0.99)
    assert median_interval(np.arange(6.0)) == (2.5, 0.0, 5.0)


@PROPERTY
@given(st.lists(st.floats(-1e6, 1e6), min_size=6, max_size=120), SEEDS)
def test_interval_brackets_the_median_and_ignores_order(values, seed):
    med, lo, hi = median_interval(values)
    assert lo <= med <= hi
    assert lo in values and hi in values
    shuffled = np.random.default_rng(seed).permutation(values)
    assert median_interval(shuffled) == (med, lo, hi)


# ----------------------------------------------------------------------------------------------
# replication rate


def test_replication_rate_known_answer():
    effect = [0.5, 0.9, 1.0, 1.1, 0.7]  # 1.0 is no effect: on neither side
    assert replication_rate(effect, 1.0, "lower") == pytest.approx(0.6)
    assert replication_rate(effect, 1.0, "higher") == pytest.approx(0.2)
    assert replication_rate([-1.0, 2.0, 0.0, 3.0], 0.0, "higher") == pytest.approx(0.5)


# ----------------------------------------------------------------------------------------------
# the rule: ratio, value, percent


def test_effect_of_0_8_with_small_spread_is_reproduced():
    after, before = paired(np.random.default_rng(1), 0.8)
    v = judge(after, baseline=before, kind="ratio", direction="lower", published=0.8)
    assert v.verdict == "reproduced"
    assert v.significant and v.in_band
    assert v.ci_low < 0.8 < v.ci_high
    assert v.effect_high < 1.0 and v.null == 1.0
    assert v.replication_rate == 1.0
    assert v.n == 200 and math.isnan(v.p95)


def test_same_spread_centred_on_1_is_not_reproduced():
    ratio = symmetric_ratio(np.random.default_rng(2))
    v = judge(ratio, kind="ratio", direction="lower", published=0.8)
    assert v.verdict == "not reproduced"
    assert not v.significant
    assert v.effect_low < 1.0 < v.effect_high
    assert v.replication_rate == pytest.approx(0.5)
    assert "not significantly lower than 1" in v.note


def test_significant_on_the_wrong_side_is_not_reproduced():
    after, before = paired(np.random.default_rng(3), 1.25)
    v = judge(after, baseline=before, kind="ratio", direction="lower", published=1.25)
    assert v.verdict == "not reproduced"  # in band, but the paper claims the other side
    assert not v.significant and v.in_band
    assert v.effect_low > 1.0
    assert "significantly higher than 1: the wrong side" in v.note


def test_ratio_significant_but_out_of_band_is_direction_only():
    after, before = paired(np.random.default_rng(4), 0.4)
    v = judge(after, baseline=before, kind="ratio", direction="lower", published=0.8)
    assert v.verdict == "direction only"
    assert v.significant and not v.in_band
    assert "outside factor 1.5 of published 0.8" in v.note


@pytest.mark.parametrize(("centre", "verdict"), [(90.0, "reproduced"), (70.0, "direction only")])
def test_percent_band_is_10_points(centre, verdict):
    rng = np.random.default_rng(5)
    before = 50.0 + rng.normal(0.0, 2.0, 200)
    after = centre + rng.normal(0.0, 2.0, 200)
    v = judge(after, baseline=before, kind="percent", direction="higher", published=96.55)
    assert v.verdict == verdict
    assert v.significant and v.null == 0.0
    assert v.median == pytest.approx(centre, abs=0.5)
    assert v.effect_median == pytest.approx(centre - 50.0, abs=0.8)


def test_band_edges_are_inclusive():
    on_edge = judge(np.full(200, 0.75), kind="ratio", direction="lower", published=0.5)
    beyond = judge(np.full(200, 0.7500001), kind="ratio", direction="lower", published=0.5)
    assert (on_edge.verdict, beyond.verdict) == ("reproduced", "direction only")
    rule = {"kind": "percent", "direction": "higher", "null": 50.0, "published": 90.0}
    pct = [judge(np.full(200, x), **rule).verdict for x in (80.0, 79.9)]
    assert pct == ["reproduced", "direction only"]


def test_value_against_a_stated_reference():
    rng = np.random.default_rng(6)
    errors = rng.gamma(20.0, 0.1 / 20.0, 200)  # about 0.100 mm against a plate's 0.556 mm
    v = judge(errors, kind="value", direction="lower", published=0.100, null=0.556)
    assert v.verdict == "reproduced"
    assert v.null == 0.556 and v.effect_median == v.median
    far = judge(errors, kind="value", direction="lower", published=0.300, null=0.556)
    assert far.verdict == "direction only"


def test_no_published_size_lets_significance_decide():
    after, before = paired(np.random.default_rng(7), 0.3)
    v = judge(after, baseline=before, kind="ratio", direction="lower")
    assert v.verdict == "reproduced"
    assert "no published size" in v.note
    flat = judge(symmetric_ratio(np.random.default_rng(7)), kind="ratio", direction="lower")
    assert flat.verdict == "not reproduced"
    assert "no published size" in flat.note


def test_fewer_trials_than_the_rule_asks_are_noted_not_judged():
    after, before = paired(np.random.default_rng(8), 0.8, n=50)
    v = judge(after, baseline=before, kind="ratio", direction="lower", published=0.8)
    w = judge(after, baseline=before, kind="ratio", direction="lower", published=0.8, min_trials=50)
    assert v.verdict == w.verdict == "reproduced"
    assert v.n == 50
    assert v.note.endswith("only 50 trials (rule asks >= 200)")
    assert "only" not in w.note


def test_note_is_one_line_with_three_significant_digits():
    after, before = paired(np.random.default_rng(9), 0.8123456)
    v = judge(after, baseline=before, kind="ratio", direction="lower", published=0.84)
    assert "\n" not in v.note
    assert "published 0.84" in v.note and "N=200" in v.note
    for number in re.findall(r"(?<![N=\d.])\d+\.?\d*", v.note.replace("N=200", "")):
        assert len(number.replace(".", "").lstrip("0")) <= 3, number


@PROPERTY
@given(SEEDS, st.integers(7, 301).filter(lambda n: n % 2), st.floats(0.3, 3.0))
def test_ratio_verdict_is_symmetric_under_inversion(seed, n, centre):
    # with N odd the median of 1 / r is 1 / median(r), and the interval ranks swap
    after, before = paired(np.random.default_rng(seed), centre, n=n, spread=0.3)
    v = judge(after, baseline=before, kind="ratio", direction="lower", published=0.8)
    w = judge(before, baseline=after, kind="ratio", direction="higher", published=1 / 0.8)
    assert (v.verdict, v.significant, v.in_band) == (w.verdict, w.significant, w.in_band)
    assert v.replication_rate == w.replication_rate


# ----------------------------------------------------------------------------------------------
# the rule: bound


def bounded(rng: np.random.Generator, n_met: int, bound: float, direction: str) -> np.ndarray:
    """200 figures, ``n_met`` of them meeting ``bound`` (``<=`` for lower, ``>=`` for higher)."""
    inside, outside = (0.2, 0.95), (1.05, 2.0)
    if direction == "higher":
        inside, outside = (1.05, 2.0), (0.2, 0.95)
    met = bound * rng.uniform(*inside, n_met)
    missed = bound * rng.uniform(*outside, 200 - n_met)
    return rng.permutation(np.concatenate([met, missed]))


@pytest.mark.parametrize("direction", ["lower", "higher"])
@pytest.mark.parametrize(
    ("n_met", "verdict"), [(194, "reproduced"), (160, "direction only"), (80, "not reproduced")]
)
def test_bound_met_in_97_80_and_40_percent(direction, n_met, verdict):
    figures = bounded(np.random.default_rng(n_met), n_met, 0.42, direction)
    v = judge(figures, kind="bound", direction=direction, bound=0.42)
    assert v.verdict == verdict
    assert v.replication_rate == pytest.approx(n_met / 200)
    assert v.null == 0.42 and v.kind == "bound"
    expected = np.quantile(figures, 0.95 if direction == "lower" else 0.05)
    assert v.p95 == pytest.approx(expected)
    assert ("percentile" in v.note) and ("0.42" in v.note)


# ----------------------------------------------------------------------------------------------
# null control


@PROPERTY
@given(
    SEEDS,
    st.integers(6, 400),
    st.floats(1e-3, 2.0),
    st.sampled_from(["lower", "higher"]),
    st.sampled_from(["ratio", "value", "percent"]),
)
def test_exact_null_control_is_never_reproduced(seed, n, spread, direction, kind):
    before = np.random.default_rng(seed).lognormal(0.0, spread, n)
    v = judge(before.copy(), baseline=before, kind=kind, direction=direction)  # no size: worst case
    assert v.verdict == "not reproduced"
    assert not v.significant
    assert v.replication_rate == 0.0
    check_null_control(v)


def test_noisy_null_control_is_falsely_significant_at_most_5_percent():
    reps, rng = 2000, np.random.default_rng(11)
    claimed_side = either_side = 0
    for _ in range(reps):
        ratio = 1.0 + rng.normal(0.0, 0.1, 200)  # symmetric noise around no effect
        v = judge(ratio, kind="ratio", direction="lower")
        claimed_side += v.verdict != "not reproduced"
        either_side += not (v.effect_low <= 1.0 <= v.effect_high)
    assert claimed_side / reps <= 0.05
    exact = 1 - median_ranks(200, 0.95)[2]  # two-sided miss rate, 0.040
    assert abs(either_side / reps - exact) <= 3 * math.sqrt(exact * (1 - exact) / reps)


def test_check_null_control_raises_unless_not_reproduced():
    after, before = paired(np.random.default_rng(12), 0.8)
    broken = judge(after, baseline=before, kind="ratio", direction="lower")
    with pytest.raises(CalibrationError, match="came out 'reproduced'.*the test is broken"):
        check_null_control(broken)
    with pytest.raises(CalibrationError, match="'not testable'.*test is broken"):
        check_null_control(not_testable("hardware"))
    check_null_control(judge(before, baseline=before, kind="ratio", direction="lower"))


# ----------------------------------------------------------------------------------------------
# controls and the oracle gate


def test_judge_controls_on_the_same_trials():
    rng = np.random.default_rng(13)
    after, before = paired(rng, 0.84)
    oracle = 0.5 * before * np.exp(rng.normal(0.0, 0.05, 200))
    claim, null_v, oracle_v = judge_controls(
        after, before, oracle, baseline=before, kind="ratio", direction="lower", published=0.84
    )
    assert claim.verdict == "reproduced" and "published 0.84" in claim.note
    assert null_v.verdict == "not reproduced" and "no published size" in null_v.note
    assert oracle_v.significant
    check_null_control(null_v)
    assert oracle_gate(claim, oracle_v, mechanism="defocus") is claim
    with pytest.raises(CalibrationError, match="oracle control has 199 trials but the claim 200"):
        judge_controls(after, before, oracle[:-1], baseline=before, kind="ratio", direction="lower")


def test_oracle_gate_without_the_mechanism_is_not_testable():
    after, before = paired(np.random.default_rng(14), 0.84)
    claim, _, oracle_v = judge_controls(
        after, before, before, baseline=before, kind="ratio", direction="lower", published=0.84
    )
    gated = oracle_gate(claim, oracle_v, mechanism="circle-of-confusion defocus")
    assert gated.verdict == "not testable"
    assert "lacks circle-of-confusion defocus" in gated.note
    assert "claim alone came out reproduced" in gated.note
    assert (gated.kind, gated.n) == ("ratio", 200)
    assert math.isnan(gated.median) and math.isnan(gated.replication_rate)
    with pytest.raises(CalibrationError, match="needs the mechanism's name"):
        oracle_gate(claim, oracle_v, mechanism=" ")


def test_not_testable_carries_the_reason():
    v = not_testable("needs the rotary table hardware", kind="value")
    assert v.verdict == "not testable" and v.note == "needs the rotary table hardware"
    assert all(math.isnan(getattr(v, f)) for f in ("median", "ci_low", "effect_high", "p95"))
    assert not v.significant and v.n == 0
    with pytest.raises(CalibrationError, match="needs a reason"):
        not_testable("")
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.verdict = "reproduced"  # type: ignore[misc]
    with pytest.raises(CalibrationError, match="verdict is 'works'"):
        Verdict("works", "ratio", 1, *[0.0] * 7, True, True, 1.0, 0.0, "why")


# ----------------------------------------------------------------------------------------------
# input checks


GOOD = np.linspace(0.5, 1.5, 200)


@pytest.mark.parametrize(
    ("samples", "kwargs", "message"),
    [
        (GOOD, {"kind": "rate", "direction": "lower"}, "kind is 'rate'; expected one of ratio"),
        (GOOD, {"kind": "ratio", "direction": "down"}, "direction is 'down'"),
        (GOOD, {"kind": "ratio", "direction": "lower", "baseline": GOOD[:-1]},
         "baseline has 199 trials but samples 200"),
        (np.r_[GOOD[:-1], np.nan], {"kind": "ratio", "direction": "lower"},
         "samples holds 1 non-finite value.*first at trial 199"),
        (GOOD, {"kind": "ratio", "direction": "lower", "baseline": np.r_[0.0, GOOD[1:]]},
         r"baseline is zero or negative in 1 of 200 trials \(first 0 at trial 0\)"),
        (GOOD, {"kind": "ratio", "direction": "lower", "baseline": -GOOD},
         "baseline is zero or negative in 200 of 200"),
        (GOOD, {"kind": "bound", "direction": "lower"}, "a bound claim needs bound"),
        (GOOD, {"kind": "value", "direction": "lower"}, "a value claim needs null"),
        (GOOD, {"kind": "ratio", "direction": "lower", "bound": 0.4},
         "bound 0.4 applies only to kind 'bound'"),
        (GOOD, {"kind": "bound", "direction": "lower", "bound": 0.4, "published": 0.4},
         "published does not apply to a bound claim"),
        (GOOD, {"kind": "ratio", "direction": "lower", "published": -0.5},
         "published ratio is -0.5; a ratio must be positive"),
        (GOOD, {"kind": "ratio", "direction": "lower", "published": 0.0}, "published ratio is 0"),
        (GOOD, {"kind": "value", "direction": "lower", "null": 1.0, "published": 0.0},
         "factor band around 0 is empty"),
        (GOOD, {"kind": "ratio", "direction": "lower", "published": float("nan")},
         "published is nan"),
        (GOOD, {"kind": "ratio", "direction": "lower", "null": 0.0}, "no effect of a ratio is 1"),
        (GOOD, {"kind": "value", "direction": "lower", "baseline": GOOD, "null": 1.0},
         "no effect of a paired difference is 0"),
        (GOOD, {"kind": "ratio", "direction": "lower", "factor": 1.0}, "factor is 1.0"),
        (GOOD, {"kind": "ratio", "direction": "lower", "level": 1.0}, "level is 1.0"),
        (GOOD[:5], {"kind": "ratio", "direction": "lower"}, "5 samples cannot give"),
        (GOOD.reshape(100, 2), {"kind": "ratio", "direction": "lower"}, r"shape \(100, 2\)"),
        (["a", "b"], {"kind": "ratio", "direction": "lower"}, "samples is not numeric"),
    ],
)  # fmt: skip
def test_bad_input_is_refused_with_the_number(samples, kwargs, message):
    with pytest.raises(CalibrationError, match=message):
        judge(samples, **kwargs)


def test_bad_input_to_the_helpers():
    with pytest.raises(CalibrationError, match="effect holds 1 non-finite"):
        replication_rate([1.0, np.inf], 1.0, "lower")
    with pytest.raises(CalibrationError, match="direction is 'up'"):
        replication_rate([1.0], 1.0, "up")
    with pytest.raises(CalibrationError, match="n is 0"):
        median_ranks(0)
    with pytest.raises(CalibrationError, match="kind is 'bogus'"):
        not_testable("reason", kind="bogus")
