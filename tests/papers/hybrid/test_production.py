"""The station in production: Table 1 statistics, offset compensation, bad input, the simulation."""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import pearsonr
from statsmodels.stats.diagnostic import lilliefors
from support import ideal_station

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.estimators.workpiece import rps_frame_so3
from calstudy.models import kinematics as kin
from calstudy.papers.hybrid import production as pr
from calstudy.papers.hybrid import station as st

# ---------------------------------------------------------------------------------------------
# bins against hand-counted cases


def test_deviation_bins_hand_counted():
    d = np.array([0.0, -0.1, 0.1, 0.1001, -0.2, 0.25, -0.3, 0.31, -0.5, 0.5001, -2.0])
    # <= 0.1: 0, -0.1, 0.1 | (0.1, 0.2]: 0.1001, -0.2 | (0.2, 0.3]: 0.25, -0.3 | (0.3, 0.5]: 0.31,
    # -0.5 | > 0.5: 0.5001, -2
    assert pr.deviation_bins(d).tolist() == [3, 2, 2, 2, 2]


def test_correlation_bins_hand_counted():
    r = np.array([0.95, 0.9, 0.85, 0.8, 0.75, 0.7, 0.65, 0.6, 0.1, -0.9])
    # > 0.9: 0.95 | (0.8, 0.9]: 0.9, 0.85 | (0.7, 0.8]: 0.8, 0.75 | (0.6, 0.7]: 0.7, 0.65 | rest
    assert pr.correlation_bins(r).tolist() == [1, 2, 2, 2, 3]


def test_bins_vectorise_over_trials():
    rng = np.random.default_rng(0)
    d = rng.normal(0, 0.3, (4, 174))
    counts = pr.deviation_bins(d)
    assert counts.shape == (4, 5)
    assert (counts.sum(axis=1) == 174).all()
    assert counts[2].tolist() == pr.deviation_bins(d[2]).tolist()


def test_published_table1_counts_match_its_percentages():
    for counts, percent in (
        (pr.PUBLISHED_DEVIATION_COUNTS, pr.PUBLISHED_DEVIATION_PERCENT),
        (pr.PUBLISHED_CORRELATION_COUNTS, pr.PUBLISHED_CORRELATION_PERCENT),
    ):
        assert sum(counts) == 174
        # the paper prints 10 / 174 = 5.747 % as 5.74 (truncated), hence 0.01 and not 0.005
        np.testing.assert_allclose(100 * np.array(counts) / 174, percent, atol=0.01)


# ---------------------------------------------------------------------------------------------
# Lilliefors wrapper and correlation against the libraries


def test_lilliefors_matches_statsmodels():
    x = np.random.default_rng(1).normal(2.0, 0.3, 10)
    stat, p = pr.lilliefors_test(x)
    ref = lilliefors(x, dist="norm", pvalmethod="table")
    assert stat == pytest.approx(ref[0]) and p == pytest.approx(ref[1])


def test_lilliefors_statistic_by_hand():
    x = np.array([-1.0, 0.0, 0.0, 1.0, 3.0])
    z = np.sort((x - x.mean()) / x.std(ddof=1))
    from scipy.stats import norm

    cdf = norm.cdf(z)
    n = x.size
    d = max((np.arange(1, n + 1) / n - cdf).max(), (cdf - np.arange(n) / n).max())
    assert pr.lilliefors_test(x)[0] == pytest.approx(d)


def test_lilliefors_rejects_a_clearly_non_normal_sample():
    x = np.r_[np.zeros(15), np.ones(5) * 10] + np.linspace(0, 1e-3, 20)
    assert pr.lilliefors_test(x)[1] < 0.01


def test_correlations_match_scipy_and_the_second_form_of_eq26():
    rng = np.random.default_rng(2)
    c = rng.normal(0, 0.5, (30, 7, 3))
    h = c + rng.normal(0, 0.3, c.shape) + 2.0
    r = pr.correlations(h, c)
    assert r.shape == (7, 3)
    assert r[4, 1] == pytest.approx(pearsonr(h[:, 4, 1], c[:, 4, 1]).statistic)
    x, big_x, n = h[:, 0, 0], c[:, 0, 0], 30
    second = (n * (x * big_x).sum() - x.sum() * big_x.sum()) / (
        np.sqrt(n * (x**2).sum() - x.sum() ** 2) * np.sqrt(n * (big_x**2).sum() - big_x.sum() ** 2)
    )
    assert r[0, 0] == pytest.approx(second, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# offset compensation


def test_offset_removes_an_injected_constant_bias_exactly():
    rng = np.random.default_rng(3)
    bias = rng.normal(0, 3.0, (58, 3))
    truth = rng.normal(0, 0.5, (40, 58, 3))
    hybrid = truth + bias
    off = pr.offsets(hybrid[:10], truth[:10])
    np.testing.assert_allclose(off, -bias, atol=1e-12)
    np.testing.assert_allclose(pr.compensate(hybrid[10:], off), truth[10:], atol=1e-12)


def test_analyse_run_on_a_noise_free_bias_gives_zero_deviation_and_perfect_correlation():
    rng = np.random.default_rng(4)
    bias = rng.normal(0, 3.0, (5, 3))
    truth = rng.normal(0, 0.5, (25, 5, 3))
    run = {
        "compensation": (truth[:10] + bias, truth[:10]),
        "follow-up": (truth[10:] + bias, truth[10:]),
    }
    a = pr.analyse_run(run, 10)
    np.testing.assert_allclose(a["deviation"], 0.0, atol=1e-12)
    np.testing.assert_allclose(a["r"], 1.0, atol=1e-12)
    assert a["within_0p3"] == 100.0 and a["r_above_0p7"] == 100.0
    assert a["deviation_counts"].tolist() == [15, 0, 0, 0, 0]


# ---------------------------------------------------------------------------------------------
# bad input


def test_too_few_products_raise():
    x = np.ones((2, 4, 3))
    with pytest.raises(CalibrationError, match="at least 3 products; hybrid holds 2"):
        pr.offsets(x, x)
    with pytest.raises(CalibrationError, match="Lilliefors test needs at least 4 products"):
        pr.lilliefors_test([0.1, 0.2, 0.4])
    with pytest.raises(CalibrationError, match="correlation coefficient needs at least 3"):
        pr.correlations(x, x)


def test_constant_data_raise():
    rng = np.random.default_rng(5)
    h = rng.normal(size=(10, 4, 3))
    c = h + rng.normal(size=h.shape)
    c[:, 2, 1] = 7.0
    with pytest.raises(
        CalibrationError, match=r"1 coordinate\(s\) are constant .* index \[\(2, 1\)\].*undefined"
    ):
        pr.correlations(h, c)
    with pytest.raises(CalibrationError, match="undefined for constant data"):
        pr.lilliefors_test(np.full(10, 2.5))


def _tables(n_products=4, ids=("P1", "P2", "P3")):
    rng = np.random.default_rng(6)
    rows = [
        {
            "product": p,
            "phase": "compensation" if p <= 2 else "follow-up",
            "point_id": i,
            "x_mm": rng.normal(),
            "y_mm": rng.normal(),
            "z_mm": rng.normal(),
        }
        for p in range(1, n_products + 1)
        for i in ids
    ]
    return pd.DataFrame(rows)


def test_measurement_tables_round_trip():
    h, c = _tables(), _tables().sample(frac=1.0, random_state=1)
    ids, run = pr.measurements_from_frames(h, c)
    assert ids == ["P1", "P2", "P3"]
    assert run["compensation"][0].shape == (2, 3, 3) and run["follow-up"][1].shape == (2, 3, 3)
    # the shuffled CMM table is put back in the hybrid's order
    np.testing.assert_array_equal(run["compensation"][0], run["compensation"][1])
    back = pr.measurements_frame(ids, run, 0)
    assert back[list(pr.MEASUREMENT_COLUMNS)].equals(h[list(pr.MEASUREMENT_COLUMNS)])


def test_mismatched_point_ids_raise():
    h = _tables()
    c = _tables().replace({"point_id": {"P3": "P9"}})
    with pytest.raises(
        CalibrationError, match=r"point ids differ .* only in hybrid \['P3'\], only in CMM \['P9'\]"
    ):
        pr.measurements_from_frames(h, c)


def test_missing_and_duplicated_points_raise():
    h = _tables()
    missing = h.drop(index=h[(h["product"] == 3) & (h["point_id"] == "P2")].index)
    with pytest.raises(
        CalibrationError,
        match=r"product 3 of the hybrid table lacks 1 feature point\(s\): \['P2'\]",
    ):
        pr.measurements_from_frames(missing, _tables())
    dup = pd.concat([h, h.iloc[[4]]], ignore_index=True)
    with pytest.raises(CalibrationError, match="point P2 appears 2 times in product 2"):
        pr.measurements_from_frames(_tables(), dup)


def test_missing_columns_and_unknown_phase_raise():
    with pytest.raises(CalibrationError, match="lacks columns \\['z_mm'\\]"):
        pr.measurements_from_frames(_tables().drop(columns="z_mm"), _tables())
    with pytest.raises(CalibrationError, match="phases \\['later'\\]"):
        pr.measurements_from_frames(_tables().replace({"phase": {"follow-up": "later"}}), _tables())


def test_tables_of_other_products_or_with_bad_values_raise():
    h = _tables()
    with pytest.raises(
        CalibrationError, match=r"products differ .* only in hybrid \[4\], only in CMM \[5\]"
    ):
        pr.measurements_from_frames(h, h.replace({"product": {4: 5}}))
    with pytest.raises(CalibrationError, match="a product has different phases"):
        other = h.copy()
        other.loc[other["product"] == 2, "phase"] = "follow-up"
        pr.measurements_from_frames(h, other)
    nan = h.copy()
    nan.loc[3, "y_mm"] = np.nan
    with pytest.raises(CalibrationError, match="the CMM table holds 1 non-finite coordinates"):
        pr.measurements_from_frames(h, nan)
    with pytest.raises(CalibrationError, match="the hybrid table is empty"):
        pr.measurements_from_frames(h.iloc[:0], h)


def test_offsets_of_mismatched_runs_raise():
    x = np.zeros((10, 4, 3))
    with pytest.raises(CalibrationError, match=r"hybrid has shape \(10, 4, 3\) and cmm"):
        pr.offsets(x, x[:, :3])
    with pytest.raises(CalibrationError, match=r"offset has shape \(3, 3\)"):
        pr.compensate(x, np.zeros((3, 3)))
    run = {"compensation": (x[:5], x[:5]), "follow-up": (x, x)}
    with pytest.raises(CalibrationError, match="n_compensation is 10 but only 5"):
        pr.analyse_run(run, 10)


def test_duplicated_feature_ids_in_the_data_file_raise():
    cfg = pr.load_production_config()
    cfg["flexible"]["features"][1]["id"] = cfg["flexible"]["features"][0]["id"]
    with pytest.raises(
        CalibrationError, match=r"duplicated feature points in production.toml: \['H01'\]"
    ):
        pr.load_features(cfg)


def test_scenario_checks_its_values():
    sc = pr.default_scenario()
    with pytest.raises(CalibrationError, match="n_compensation is 2; at least 3 products"):
        sc.with_(n_compensation=2)
    with pytest.raises(CalibrationError, match="part_sigma_mm is -0.1"):
        sc.with_(part_sigma_mm=-0.1)


# ---------------------------------------------------------------------------------------------
# verdicts from trial tables


def _claim_inputs(size_mm, scatter_mm, within, uncompensated, r_above):
    n = 20
    rng = np.random.default_rng(11)
    systematic = pd.DataFrame(
        {
            "trial": np.arange(n),
            "systematic_median_mm": size_mm + rng.normal(0, 0.01, n),
            "scatter_median_mm": scatter_mm + rng.normal(0, 0.001, n),
            "lilliefors_not_rejected": 95.0,
            "mean_nonzero": 90.0,
        }
    )
    trials = pd.DataFrame(
        {
            "trial": np.arange(n),
            "n_compensation": 10,
            "within_0p3": within + rng.normal(0, 0.5, n),
            "within_0p3_uncompensated": uncompensated + rng.normal(0, 0.5, n),
            "r_above_0p7": r_above + rng.normal(0, 0.5, n),
            "beyond_0p5": 0.0,
            "n_vectors": 174,
            "n_fixed": 6,
        }
    )
    return systematic, trials


def test_claims_reproduced_when_the_trials_match_the_paper():
    rows = pr.production_claims(*_claim_inputs(3.0, 0.06, 96.0, 30.0, 86.0), 10, "nb")
    assert [r.id for r in rows] == ["hybrid.systematic", "hybrid.deviation", "hybrid.correlation"]
    assert [r.verdict for r in rows] == ["reproduced"] * 3
    assert "168 coordinates" in rows[2].note


def test_claims_not_reproduced_without_an_effect():
    # a mean deviation no larger than the scatter is not systematic; compensation that gains
    # nothing over the raw readings is no effect
    rows = pr.production_claims(*_claim_inputs(0.05, 0.06, 96.0, 96.0, 86.0), 10, "nb")
    assert [r.verdict for r in rows[:2]] == ["not reproduced", "not reproduced"]
    rows = pr.production_claims(*_claim_inputs(1.0, 0.06, 80.0, 30.0, 100.0), 10, "nb")
    assert [r.verdict for r in rows] == ["direction only"] * 3


# ---------------------------------------------------------------------------------------------
# the 3-2-1 frame in batch and the simulated station


def test_rps_batch_matches_the_so3_solver():
    rng = np.random.default_rng(7)
    s = st.make_station(rng)
    work2base = geo.perturb(
        np.broadcast_to(geo.invert(s.base2work_nominal), (5, 4, 4)), 0.01, 2.0, rng
    )
    datums = (
        np.einsum("nij,kj->nki", work2base[:, :3, :3], s.datums_work) + work2base[:, None, :3, 3]
    )
    datums += rng.normal(0, 0.05, datums.shape)
    batch = pr.rps_frame_batch(datums, s.datums_work, s.base2work_nominal)
    for k in range(5):
        ref = rps_frame_so3(datums[k], s.datums_work, s.base2work_nominal).value
        np.testing.assert_allclose(batch[k], ref, atol=1e-7)


def test_features_match_the_paper_counts():
    f = pr.load_features()
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


def _noise_free(robot_errors: bool):
    # notebook 01's noise-free station: no sensor, pixel or robot noise, a perfectly made target
    s, rng = ideal_station(seed=8, robot_errors=robot_errors)
    s = st.with_overrides(s, datum_sigma=0.0)
    sc = pr.default_scenario().with_(
        feature_sigma_mm=0.0, repeatability_mm=0.0, drift_sigma_mm=0.0, cmm_sigma_mm=0.0
    )
    return pr.calibrate(s, rng), sc, rng


def test_systematic_error_disappears_when_true_and_nominal_robots_coincide():
    ps, sc, rng = _noise_free(robot_errors=False)
    hybrid, cmm = pr.simulate_products(ps, sc, 5, rng)
    assert np.abs(hybrid - cmm).max() < 1e-5


def test_robot_model_error_gives_a_repeatable_millimetre_deviation():
    ps, sc, rng = _noise_free(robot_errors=True)
    hybrid, cmm = pr.simulate_products(ps, sc, 5, rng)
    d = hybrid - cmm
    assert np.median(np.linalg.norm(d.mean(axis=0), axis=1)) > 0.5
    # repeatable: without noise, the panels differ only by their variation and clamping
    assert np.abs(d - d.mean(axis=0)).max() < 0.02 * np.abs(d).max()


def test_simulated_run_has_the_paper_layout_and_frame_fixed_coordinates():
    rng = np.random.default_rng(9)
    ps = pr.calibrated_station(rng)
    sc = pr.default_scenario()
    run = pr.simulate_run(ps, sc, rng)
    assert run["compensation"][0].shape == (sc.n_compensation_max, 58, 3)
    assert run["follow-up"][1].shape == (sc.n_follow_up, 58, 3)
    h = np.concatenate([run[p][0] for p in pr.PHASES])
    c = np.concatenate([run[p][1] for p in pr.PHASES])
    np.testing.assert_array_equal(pr.frame_fixed(h, c), ps.features.fixed)
    # each program pose puts its feature near the middle of the sensor's field
    p = pr.sensor_pose_check(ps)
    assert np.abs(p[:, :2]).max() < 20.0 and np.abs(p[:, 2] - 250.0).max() < 20.0


# ---------------------------------------------------------------------------------------------
# the sweep of the robot's manufacturing errors


def test_robot_error_scale_multiplies_the_drawn_link_errors():
    nominal = st.make_station(np.random.default_rng(14), robot_errors=False).true.parameters()
    errors = {
        scale: st.make_station(np.random.default_rng(14), robot_error_scale=scale).true.parameters()
        - nominal
        for scale in (0.0, 1.0, 2.0)
    }
    assert np.all(errors[0.0] == 0.0)  # the nominal robot: no kinematic model error
    assert np.abs(errors[1.0]).max() > 0.1
    np.testing.assert_allclose(errors[2.0], 2.0 * errors[1.0], atol=1e-12)
    # the default is the robot of the tolerances file, draw for draw (notebook 01 unchanged)
    default = kin.perturb_robot(kin.load_robot("kuka_kr16_2"), np.random.default_rng(14))
    assert (errors[1.0] + nominal).tobytes() == default.parameters().tobytes()
    with pytest.raises(CalibrationError, match="robot_error_scale is -1.0"):
        st.make_station(np.random.default_rng(14), robot_error_scale=-1.0)


def test_robot_error_sweep_scales_the_systematic_error_of_the_same_stations():
    sc = pr.default_scenario()
    sweep = pr.robot_error_sweep(5, 2, sc, [0.0, 1.0, 2.0])
    assert sweep["robot_error_scale"].tolist() == [0.0, 0.0, 1.0, 1.0, 2.0, 2.0]

    def by_station(col):
        return sweep.pivot(index="trial", columns="robot_error_scale", values=col).to_numpy()

    # the same stations, their robot errors scaled: the systematic error grows with the factor
    # and the raw share within +-0.3 mm falls; the compensated share hardly moves
    assert (np.diff(by_station("systematic_median_mm"), axis=1) > 0).all()
    assert (np.diff(by_station("within_0p3_uncompensated"), axis=1) < 0).all()
    assert np.ptp(by_station("within_0p3"), axis=1).max() <= 2.0
    # factor 1 is the default station of the same generator
    rng = st.trial_generators(5, 2, 2)[1]
    system, (table,) = pr.trial_summary(
        pr.simulate_run(pr.calibrated_station(rng), sc, rng), sc, [sc.n_compensation]
    )
    row = sweep[(sweep["robot_error_scale"] == 1.0) & (sweep["trial"] == 1)].iloc[0]
    assert {k: row[k] for k in system | table} == system | table


def test_robot_error_sweep_summary_uses_the_claims_verdicts():
    parts = []
    for scale, size in ((1.0, 1.0), (1.5, 3.0)):
        systematic, trials = _claim_inputs(size, 0.06, 96.0, 30.0, 86.0)
        parts.append(systematic.merge(trials, on="trial").assign(robot_error_scale=scale))
    summary = pr.summarise_robot_error_sweep(pd.concat(parts), 10, "nb")
    assert summary["robot_error_scale"].tolist() == [1.0, 1.5]
    assert summary["systematic_verdict"].tolist() == ["direction only", "reproduced"]
    assert summary["deviation_verdict"].tolist() == ["reproduced"] * 2
    expected = np.median(parts[1]["systematic_median_mm"])
    assert summary["systematic_median_mm"].iloc[1] == pytest.approx(expected)
    assert (summary["stations"] == 20).all()


def test_table1_from_csv_files_equals_table1_from_arrays(tmp_path):
    rng = np.random.default_rng(10)
    c = rng.normal(0, 0.5, (25, 4, 3))
    h = c + rng.normal(0, 0.1, c.shape) + 1.5
    run = {"compensation": (h[:10], c[:10]), "follow-up": (h[10:], c[10:])}
    ids = ["A", "B", "C", "D"]
    pr.measurements_frame(ids, run, 0).to_csv(tmp_path / "h.csv", index=False)
    pr.measurements_frame(ids, run, 1).to_csv(tmp_path / "c.csv", index=False)
    source, ids_read, run_read = pr.station_data(tmp_path / "h.csv", tmp_path / "c.csv", [], {})
    assert "measured tables" in source and ids_read == ids
    pd.testing.assert_frame_equal(pr.station_table1(run_read, 10), pr.station_table1(run, 10))


def test_fig6_figure_shows_the_named_point_and_rejects_an_unknown_one():
    import matplotlib.pyplot as plt

    d = np.random.default_rng(13).normal(2.0, 0.1, (10, 2, 3))
    fig = pr.fig6_figure(d, ["A", "B"], "B")
    lines = fig.axes[0].get_lines()
    np.testing.assert_array_equal(lines[2].get_ydata(), d[:, 1, 2])
    plt.close(fig)
    with pytest.raises(CalibrationError, match="featured point 'H11' is not among the 2"):
        pr.fig6_figure(d, ["A", "B"], "H11")


def test_station_data_needs_both_tables():
    with pytest.raises(CalibrationError, match="give both hybrid_csv and cmm_csv"):
        pr.station_data("h.csv", "", [], {})


@pytest.mark.slow
def test_notebook02_runs_on_user_csvs(tmp_path):
    import json
    from pathlib import Path

    import papermill as pm
    from test_notebooks import ci_parameters

    notebook = Path(__file__).resolve().parents[1] / "notebooks"
    notebook = notebook / "02_hybrid_production_compensation.ipynb"
    rng = np.random.default_rng(12)
    ps = pr.calibrated_station(rng)
    run = pr.simulate_run(ps, pr.default_scenario(), rng)
    paths = {}
    for which, name in ((0, "hybrid"), (1, "cmm")):
        paths[name] = tmp_path / f"{name}.csv"
        pr.measurements_frame(ps.features.ids, run, which).to_csv(paths[name], index=False)
    params = ci_parameters(notebook.stem)
    params |= {
        "n_trials": 2,
        "n_sweep_trials": 2,
        "hybrid_csv": str(paths["hybrid"]),
        "cmm_csv": str(paths["cmm"]),
        "results_dir": str(tmp_path / "out"),
    }
    out_nb = tmp_path / "out.ipynb"
    pm.execute_notebook(
        str(notebook), str(out_nb), parameters=params, cwd=str(notebook.parent), progress_bar=False
    )
    assert f"measurements: measured tables {paths['hybrid']}" in json.dumps(
        json.loads(out_nb.read_text())
    )
    table = pd.read_csv(tmp_path / "out" / notebook.stem / "table1_station.csv")
    expected = pr.station_table1(run, pr.default_scenario().n_compensation)
    assert table["count"].tolist() == expected["count"].tolist()


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
    deviation, correlation = pr.table1(trials, 10)
    assert deviation["percent_median"].tolist() == pytest.approx(
        [100 * c / 30 for c in (20, 6, 2, 1, 1)]
    )
    assert correlation["percent_median"].iloc[-1] == pytest.approx(20.0)


def test_table1_rejects_trials_with_different_coordinate_counts():
    trials = _trials([(20, 6, 2, 1, 1), (20, 6, 2, 1, 2)], [(15, 5, 2, 1, 1)] * 2, [6, 6])
    with pytest.raises(CalibrationError, match="disagree on the number of coordinates"):
        pr.table1(trials, 10)
