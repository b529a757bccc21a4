"""Tables and claims of the hybrid study: verdicts from trial tables, Table 1 over trials and of
one station."""

import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy.papers.hybrid import compensation, report, report_sweeps

PUBLISHED_R = np.array([28, 58, 63, 10, 15])  # the paper's correlation counts (Table 1)


PUBLISHED_DEV = np.array([37, 82, 49, 6, 0])  # the paper's deviation counts (Table 1)
RAW_DEV = np.array([10, 20, 30, 40, 74])  # uncompensated: mostly beyond 0.3 mm
EXACT_DEV = np.array([174, 0, 0, 0, 0])  # the drift removed: every deviation within 0.1 mm
OTHER_PANEL_R = np.array([0, 0, 0, 1, 167])  # readings against another panel: r near 0


def _bins(trials, prefix, counts):
    counts = np.broadcast_to(np.asarray(counts), (len(trials), 5))
    for k in range(5):
        trials[f"{prefix}_bin{k}"] = counts[:, k]


def _claim_inputs(
    size_mm, scatter_mm, dev, r_counts, n=200, dev_null=RAW_DEV, r_null=OTHER_PANEL_R
):
    rng = np.random.default_rng(11)
    trials = pd.DataFrame(
        {
            "trial": np.arange(n),
            "n_compensation": 10,
            "systematic_coord_median_mm": size_mm + rng.normal(0, 0.01, n),
            "systematic_median_mm": 1.7 * size_mm + rng.normal(0, 0.01, n),
            "coord_above_2mm": 50.0,
            "scatter_median_mm": scatter_mm + rng.normal(0, 0.001, n),
            # the robot's error off: the same stations and an independent one (the floor)
            "systematic_coord_robot_off_mm": 0.1 + rng.normal(0, 0.02, n),
            "scatter_robot_off_mm": scatter_mm + rng.normal(0, 0.001, n),
            "systematic_coord_floor_mm": 0.1 + rng.normal(0, 0.02, n),
            "lilliefors_not_rejected": 95.0,
            "mean_nonzero": 90.0,
            "within_0p3": 96.0,
            "within_0p3_uncompensated": 30.0,
            "within_0p3_oracle": 100.0,
            "r_above_0p7": 85.0,
            "beyond_0p5": 0.0,
            "n_vectors": 174,
            "n_fixed": 6,
        }
    )
    _bins(trials, "deviation", dev)
    _bins(trials, "deviation_null", dev_null)
    _bins(trials, "deviation_oracle", EXACT_DEV)
    _bins(trials, "correlation", r_counts)
    _bins(trials, "correlation_null", r_null)
    return trials


def test_claims_reproduced_when_the_trials_match_the_paper():
    rows, controls = report.production_claims(
        _claim_inputs(3.0, 0.06, PUBLISHED_DEV, PUBLISHED_R), 10, "nb"
    )
    assert [r.id for r in rows] == ["hybrid.systematic", "hybrid.deviation", "hybrid.correlation"]
    assert [r.verdict for r in rows] == ["reproduced"] * 3
    assert rows[1].reproduced == pytest.approx(0.0, abs=1e-12)
    assert rows[2].reproduced == pytest.approx(0.0, abs=1e-3)
    assert [r.null_control for r in rows] == ["not reproduced"] * 3
    assert [(c["id"], c["control"], c["verdict"]) for c in controls] == [
        ("hybrid.systematic", "null", "not reproduced"),
        ("hybrid.deviation", "null", "not reproduced"),
        ("hybrid.deviation", "oracle", "reproduced"),
        ("hybrid.correlation", "null", "not reproduced"),
    ]


def test_claims_fail_without_an_effect_or_with_another_distribution():
    # a mean deviation below the calibration-noise floor is not systematic; deviations mostly
    # beyond 0.3 mm fall short of the published bins; every r above 0.9 is not the paper's spread
    rows, _ = report.production_claims(
        _claim_inputs(0.05, 0.06, RAW_DEV, np.array([168, 0, 0, 0, 0])), 10, "nb"
    )
    assert [r.verdict for r in rows] == ["not reproduced"] * 3
    # one station in ten falls short: the median meets the bound, the 95th percentile does not
    mixed = np.where(np.arange(200)[:, None] % 10 == 0, RAW_DEV, PUBLISHED_DEV)
    rows, _ = report.production_claims(_claim_inputs(1.0, 0.06, mixed, PUBLISHED_R), 10, "nb")
    assert [r.verdict for r in rows[:2]] == ["direction only"] * 2


def test_each_null_control_can_pass_and_then_the_claim_is_not_testable():
    """The nulls are not failing by construction: a broken station or a setting lets each pass,
    and the claim is then not testable rather than reproduced."""
    # deviation: a station without systematic error needs no offset (its raw bins are the paper's)
    rows, controls = report.production_claims(
        _claim_inputs(3.0, 0.06, PUBLISHED_DEV, PUBLISHED_R, dev_null=PUBLISHED_DEV), 10, "nb"
    )
    assert rows[1].null_control == "reproduced" and rows[1].verdict == "not testable"
    # correlation: a station that reports the panel measured half a month later passes when the
    # panels follow a slow trend (another panel's reading then correlates just as well)
    rows, _ = report.production_claims(
        _claim_inputs(3.0, 0.06, PUBLISHED_DEV, PUBLISHED_R, r_null=PUBLISHED_R), 10, "nb"
    )
    assert rows[2].null_control == "reproduced" and rows[2].verdict == "not testable"
    # systematic: a calibration that leaves its own bias keeps a systematic error with the
    # robot's error off: the null passes and the claim is not testable
    broken = _claim_inputs(3.0, 0.06, PUBLISHED_DEV, PUBLISHED_R)
    broken["systematic_coord_robot_off_mm"] += 0.5
    rows, _ = report.production_claims(broken, 10, "nb")
    assert rows[0].null_control == "reproduced" and rows[0].verdict == "not testable"


def test_correlation_distance_of_stations_drawn_from_the_published_bins():
    """Stations whose 168 coefficients are drawn from the published bins meet the 5 % critical
    distance in at least 95 % of cases: the bound is a test that a faithful station passes."""
    rng = np.random.default_rng(4)
    counts = rng.multinomial(168, PUBLISHED_R / PUBLISHED_R.sum(), size=2000)
    d = report_sweeps.bin_distance(counts, PUBLISHED_R / PUBLISHED_R.sum() * 100)
    assert np.mean(d <= report_sweeps.kolmogorov_bound(168)) >= 0.95  # binned: conservative


def test_robot_error_sweep_summary_uses_the_claims_verdicts():
    parts = []
    for scale, size in ((0.0, 0.1), (1.0, 1.0), (1.5, 3.0)):
        trials = _claim_inputs(size, 0.06, PUBLISHED_DEV, PUBLISHED_R, n=20)
        parts.append(trials.assign(robot_error_scale=scale))
    summary = report.summarise_robot_error_sweep(pd.concat(parts))
    assert summary["robot_error_scale"].tolist() == [0.0, 1.0, 1.5]
    # the floor is each station's own size with the robot's error off (factor 0)
    verdicts = ["not reproduced", "direction only", "reproduced"]
    assert summary["systematic_verdict"].tolist() == verdicts
    assert summary["deviation_verdict"].tolist() == ["reproduced"] * 3
    expected = np.median(parts[2]["systematic_coord_median_mm"])
    assert summary["systematic_coord_median_mm"].iloc[2] == pytest.approx(expected)
    no_floor = pd.concat(parts[1:]).drop(columns="systematic_coord_floor_mm")
    without = report.summarise_robot_error_sweep(no_floor)
    assert without["systematic_verdict"].tolist() == ["no robot-off point"] * 2
    assert (summary["stations"] == 20).all()


def test_the_robot_off_control_sees_the_cause_and_catches_a_test_that_cannot():
    trials = _claim_inputs(3.0, 0.06, PUBLISHED_DEV, PUBLISHED_R)
    floor, scatter, sentence = report.systematic_robot_off(trials)
    assert not floor.significant and "not significant, so the test sees its cause" in sentence
    # the same robot-off stations judged against the panel scatter pass without the cause
    assert scatter.significant and "passes without the cause" in sentence
    assert f"{floor.median:.3g} mm" in sentence
    # a systematic error that stays with the robot's error off (a biased calibration, say):
    # the test cannot see its cause, and the claim is not testable
    biased = trials["systematic_coord_robot_off_mm"] + 0.3
    broken = trials.assign(systematic_coord_robot_off_mm=biased)
    rows, _ = report.production_claims(broken, 10, "nb")
    assert rows[0].verdict == "not testable"
    assert rows[0].note.startswith("the test cannot see its cause")
    assert "so the test cannot see its cause" in report.systematic_robot_off(broken)[2]


def test_table1_from_csv_files_equals_table1_from_arrays(tmp_path):
    rng = np.random.default_rng(10)
    c = rng.normal(0, 0.5, (25, 4, 3))
    h = c + rng.normal(0, 0.1, c.shape) + 1.5
    run = {"compensation": (h[:10], c[:10]), "follow-up": (h[10:], c[10:])}
    ids = ["A", "B", "C", "D"]
    compensation.measurements_frame(ids, run, 0).to_csv(tmp_path / "h.csv", index=False)
    compensation.measurements_frame(ids, run, 1).to_csv(tmp_path / "c.csv", index=False)
    source, ids_read, run_read = compensation.station_data(
        tmp_path / "h.csv", tmp_path / "c.csv", [], {}
    )
    assert "measured tables" in source and ids_read == ids
    pd.testing.assert_frame_equal(
        report.station_table1(run_read, 10), report.station_table1(run, 10)
    )


def _trials(dev_counts, corr_counts, n_fixed):
    rows = []
    for t, (d, c, f) in enumerate(zip(dev_counts, corr_counts, n_fixed, strict=True)):
        row = {"trial": t, "n_compensation": 10, "n_vectors": sum(d), "n_fixed": f}
        row |= {f"deviation_bin{k}": d[k] for k in range(5)}
        row |= {f"correlation_bin{k}": c[k] for k in range(5)}
        rows.append(row)
    return pd.DataFrame(rows)


def test_table1_shares_are_of_the_station_coordinates_not_a_fixed_174():
    # a 10-point station: 30 coordinates, 6 of them fixed by the frame
    trials = _trials([(20, 6, 2, 1, 1)] * 3, [(15, 5, 2, 1, 1)] * 3, [6] * 3)
    deviation, correlation = report.table1(trials, 10)
    assert deviation["percent_median"].tolist() == pytest.approx(
        [100 * c / 30 for c in (20, 6, 2, 1, 1)]
    )
    assert correlation["percent_median"].iloc[-1] == pytest.approx(20.0)


def test_table1_rejects_trials_with_different_coordinate_counts():
    trials = _trials([(20, 6, 2, 1, 1), (20, 6, 2, 1, 2)], [(15, 5, 2, 1, 1)] * 2, [6, 6])
    with pytest.raises(CalibrationError, match="disagree on the number of coordinates"):
        report.table1(trials, 10)


def test_whole_deviation_distribution_distances_and_where_a_verdict_changes():
    from calstudy.papers.hybrid import report_sweeps

    published = np.array([21.26, 47.13, 28.16, 3.45, 0.0])
    paper = np.array([[37, 82, 49, 6, 0]])
    assert report_sweeps.chi_square_distance(paper, published)[0] < 0.05
    assert report_sweeps.CHI2_CRITICAL == pytest.approx(7.815, abs=1e-3)
    all_first = np.array([[174, 0, 0, 0, 0]])
    assert report_sweeps.chi_square_distance(all_first, published)[0] > 100
    with pytest.raises(CalibrationError, match="needs counts in every row"):
        report_sweeps.chi_square_distance(np.zeros((1, 5)), published)
    text = report_sweeps.where_verdict_changes(
        [0.3, 0.0, 0.1], ["not reproduced", "reproduced", "reproduced"], 0.1, "x", "mm"
    )
    assert text == (
        "x: the verdict changes from reproduced at 0.1 mm to not reproduced at 0.3 mm "
        "(swept 0-0.3 mm, reproduced at the default 0.1 mm)"
    )
    same = report_sweeps.where_verdict_changes([1, 2], ["reproduced"] * 2, 1, "y")
    assert same == "y: reproduced at every value swept (1-2)"
    # claim ids and input names in words
    words = report_sweeps.where_verdict_changes(
        [5, 60], ["reproduced"] * 2, 15, "hybrid.handeye against translation_range_mm", "mm")
    assert words.startswith("hand-eye calibration against range of the pure translations (mm):")


def test_deviation_oracle_removes_exactly_the_drift():
    rng = np.random.default_rng(5)
    n_f = 6
    systematic = rng.normal(0, 2.0, (n_f, 3))
    drift = rng.normal(0, 1.0, (n_f, 3))

    def products(n, shift):
        c = rng.normal(0, 0.5, (n, n_f, 3))
        return c + systematic + shift + rng.normal(0, 0.02, c.shape), c

    run = {"compensation": products(10, 0.0), "follow-up": products(30, drift), "drift": drift}
    a = compensation.analyse_run(run, 10)
    still = {"compensation": run["compensation"]}
    still["follow-up"] = (run["follow-up"][0] - drift, run["follow-up"][1])
    b = compensation.analyse_run(still, 10)
    assert a["within_0p3"] < 60.0  # a drift of 1 mm defeats the offset
    assert a["within_0p3_oracle"] == b["within_0p3"] == 100.0
    assert np.isnan(compensation.analyse_run(still, 10)["within_0p3_oracle"])


def test_the_chapter_sentences_state_the_claims_numbers():
    trials = _claim_inputs(3.0, 0.06, EXACT_DEV, np.array([168, 0, 0, 0, 0]))
    rows, controls = report.production_claims(trials, 10, "nb")
    text = report.deviation_sentence(rows, controls, trials)
    assert text.startswith("after compensation the station falls short of the published")
    assert "by a median 0 [0, 0] against the 5 % critical 0.0928: reproduced" in text
    # the raw bins miss most at 0.3 mm: 96.55 % published, 60 of 174 within
    assert f"without an offset (the null) by {0.9655 - 60 / 174:.3g} (not reproduced)" in text
    assert "narrower (100 % within ±0.1 mm against 21.26 %)" in text and "+-" not in text
    text = report.correlation_sentence(rows, trials)
    assert "is 0.839 [0.839, 0.839] against the 5 % critical 0.105: not reproduced" in text
    assert "100 % of the coefficients exceed 0.9 (published 16.09 %)" in text
    assert "the assumed part variation is large" in text
    low_r = _claim_inputs(3.0, 0.06, EXACT_DEV, np.array([0, 0, 0, 0, 168]))
    rows, _ = report.production_claims(low_r, 10, "nb")
    assert "the assumed part variation is small" in report.correlation_sentence(rows, low_r)


def test_the_systematic_scale_sentence_interpolates_the_factor():
    sweep = pd.DataFrame(
        {"robot_error_scale": [0.0, 1.0, 3.0], "systematic_coord_median_mm": [0.1, 1.0, 4.0]}
    )
    text = report.systematic_scale_sentence(sweep)
    # 2 mm (3 / 1.5) between factors 1 and 3: 1 + 2 * (2 - 1) / (4 - 1); 3 mm: 1 + 2 * 2 / 3
    assert "magnitude band (2 mm) at a factor of about 1.7" in text
    assert "middle of the published 2-4 mm at a factor of about 2.3" in text
    assert "beyond the largest factor swept (3)" in report.systematic_scale_sentence(
        sweep.assign(systematic_coord_median_mm=[0.1, 0.5, 1.5])
    )
    with pytest.raises(CalibrationError, match="1 factor"):
        report.systematic_scale_sentence(sweep.iloc[:1])
