"""Tests of calstudy.papers.binocular.experiments: trials, hold-out check, sweeps, defocus shift."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.core.stats import median_interval
from calstudy.estimators import binocular as bino
from calstudy.papers.binocular import experiments as ex
from calstudy.papers.binocular.scenario import load_scenario
from calstudy.papers.binocular.simulate import (
    Imaging,
    World,
    draw_world,
    reimage,
    view_calibrator,
    viewpoints,
)
from calstudy.papers.binocular.simulate import exact_points as sim_exact_points


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


@pytest.fixture(scope="module")
def rim_scenario():
    return load_scenario(None, {"sensor.optics.mechanism": "rim"})


def test_defocus_shift_is_zero_in_focus_and_flips_sign_across_the_focus(rim_scenario):
    table = ex.defocus_shift(rim_scenario, [850.0, 800.0, 900.0], tilts_deg=(0.0,))
    assert table["coc_radius_px"].iloc[0] == 0.0
    # in focus, fronto-parallel: only pixel sampling (and the tiny eccentricity) act
    assert table["shift_px"].iloc[0] < 0.05
    near, far = table["radial_shift_px"].iloc[1], table["radial_shift_px"].iloc[2]
    # the rim's cut moves a nearer dot outwards and a farther one inwards, by a share of delta
    assert near > 0.2 and far < -0.2
    assert abs(near) > 10 * table["shift_px"].iloc[0]


def test_a_symmetric_blur_moves_the_detected_centre_through_the_8_bit_chain_only(scenario):
    """Eq. 7's Gaussian (the file's mechanism) barely moves the ellipse centre of the blurred
    float image, but through the exposures, saturation, fusion and detector it does."""
    assert scenario.sensor.optics.mechanism == "gaussian"
    sc = ex.with_optics(scenario, f_number=4.0)
    table = ex.defocus_shift(sc, [750.0, 850.0, 950.0], tilts_deg=(0.0, 20.0))
    blurred = table[table["coc_radius_px"] > 0]
    focused = table[table["coc_radius_px"] == 0]
    assert blurred["float_shift_px"].max() < 0.15
    assert blurred["shift_px"].max() > 5 * focused["shift_px"].max()
    assert blurred["shift_px"].max() > 3 * blurred["float_shift_px"].max()
    assert (table["mechanism"] == "gaussian").all()


def test_the_defocus_shift_does_not_depend_on_the_blas_threads(scenario):
    """One noise-free dot is one draw of the 8-bit quantisation: with BLAS on two threads the
    rendered image moves in its last bits, ten fused pixels of this dot by up to 21 grey levels,
    and the detected centre by 0.14 px; the study computes it on one thread whatever the
    caller's setting (on one core both calls are single-threaded anyway)."""
    from threadpoolctl import threadpool_limits

    sc = ex.with_optics(scenario, f_number=4.0)
    tables = []
    for threads in (1, 2):
        with threadpool_limits(threads):
            tables.append(ex.defocus_shift(sc, [950.0], tilts_deg=(40.0,)))
    pd.testing.assert_frame_equal(*tables, check_exact=True)


def test_the_mechanism_switch_changes_the_blur_spot_off_axis(scenario, rim_scenario):
    """The same off-axis dot blurred by each mechanism: Eq. 7's spot is symmetric (the blurred
    image's centroid stays where the sharp one's is), the rim's moves it."""
    from calstudy.papers.binocular.simulate import render_blurred_dot

    camera = scenario.rig.left
    centre = 760.0 * np.array([0.2, 0.15, 1.0])
    normal = np.array([0.0, 0.0, -1.0])
    shifts = {}
    for name, sc in (("gaussian", scenario), ("rim", rim_scenario)):
        centroids = []
        for delta in (None, 0.0):
            _, origin, w = render_blurred_dot(sc, camera, centre, normal, delta_px=delta)
            ys, xs = np.indices(w.shape)
            centroids.append(origin + [np.sum(w * xs) / w.sum(), np.sum(w * ys) / w.sum()])
        shifts[name] = float(np.hypot(*np.subtract(*centroids)))
    assert shifts["gaussian"] < 0.02
    assert shifts["rim"] > 0.3


def test_optics_trial_oracle_removes_the_defocus_error(rim_scenario):
    # at f/2.8 the defocus error dominates each trial (at f/5.6 it is below the trial's noise)
    setup = ex.Setup(ex.with_optics(rim_scenario, f_number=2.8), (), ())
    rows = pd.DataFrame([ex.optics_trial(setup, np.random.default_rng(i)) for i in range(3)])
    assert (rows["t2_oracle"] < rows["t2_without"]).all()
    again = ex.optics_trial(setup, np.random.default_rng(0))
    assert again == rows.iloc[0].to_dict()


def test_with_optics_replaces_values_and_rejects_unknown_or_bad_ones(scenario):
    s = ex.with_optics(scenario, f_number=4.0, dot_diameter_mm=3.0)
    assert s.sensor.optics.f_number == 4.0
    assert s.dot_radius_mm == 1.5
    assert scenario.sensor.optics.f_number == 8.0  # the original is untouched
    with pytest.raises(CalibrationError, match="unknown optics inputs"):
        ex.with_optics(scenario, aperture=4.0)
    with pytest.raises(CalibrationError, match="must be a positive number"):
        ex.with_optics(scenario, f_number=-1.0)


def small_setup(scenario):
    return ex.Setup(scenario, (0.0, 1.0), (0.0, 1.0))


def test_one_trial_runs_is_seeded_and_shares_its_draws_across_scales(scenario):
    setup = small_setup(scenario)
    rows = pd.DataFrame(ex.binocular_trial(setup, np.random.default_rng(5)))
    assert sorted(zip(rows["robot_scale"], rows["calibration_scale"], strict=True)) == [
        (0.0, 1.0),
        (1.0, 0.0),
        (1.0, 1.0),
    ]
    assert np.isfinite(rows.drop(columns=[]).to_numpy(float)).all()
    assert (rows.filter(regex="^err_").abs() < 0.5).all().all()
    again = pd.DataFrame(ex.binocular_trial(setup, np.random.default_rng(5)))
    pd.testing.assert_frame_equal(rows, again)
    # the robot scale changes only the hand-eye steps: Tables 2-3 are the same rows
    d = rows.set_index(["robot_scale", "calibration_scale"])
    np.testing.assert_array_equal(
        d.loc[(0.0, 1.0)].filter(like="t2_"), d.loc[(1.0, 1.0)].filter(like="t2_")
    )
    assert d.loc[(0.0, 1.0), "fig13_preliminary"] != d.loc[(1.0, 1.0), "fig13_preliminary"]
    # the exact-camera oracle is the scale-0 hold-out without modification
    assert d.loc[(1.0, 1.0), "t3_holdout_truecam"] == d.loc[(1.0, 0.0), "t3_holdout_without"]


def test_holdout_modification_does_not_see_the_evaluated_target(scenario):
    pairs = bino.all_pairs(8)
    layout = scenario.layout
    standard = np.linalg.norm(layout[pairs[:, 0]] - layout[pairs[:, 1]], axis=1)
    world = World(0, 0, np.zeros((6, 3)), pairs, standard, 0.0)
    measured = layout.copy()
    measured[0] += 0.05 * (layout[0] - layout[6]) / np.linalg.norm(layout[0] - layout[6])
    measured = bino.with_virtual(measured[:6])
    held = ex.holdout_distances(measured, world)
    want = bino.distances_to_p7(layout)[:6]
    assert held[0, 1] - want[0] == pytest.approx(0.05, abs=1e-4)  # P1 kept its error
    full, _ = bino.modify_observed_error(measured, pairs, standard)
    assert abs(bino.distances_to_p7(full)[0] - want[0]) < 0.01  # the circular reading fixes it
    # several sets of points at once: each the check it gets alone
    rng = np.random.default_rng(2)
    sets = bino.with_virtual(measured[:6] + rng.normal(0, 0.02, (3, 6, 3)))
    batch = ex.holdout_distances(sets, world)
    assert batch.shape == (3, 6, 2)
    for one, got in zip(sets, batch, strict=True):
        np.testing.assert_array_equal(got, ex.holdout_distances(one, world))


def test_rendered_pipeline_without_noise_or_defocus(scenario):
    """Rendered, sharp, noise-free dots with an exactly calibrated sensor: distances to a few
    micrometres (pixel-level Canny edges limit a rendered centre to a few hundredths of a pixel)."""
    rng = np.random.default_rng(2)
    imaging = Imaging(noise=False, defocus=False)
    world = draw_world(scenario, rng, imaging)
    model = world.model(scenario, 0.0)
    views = view_calibrator(scenario, world, 3, rng, imaging, model)
    raw, rect = views.points(model, 0.5)
    np.testing.assert_array_equal(raw, rect)
    err = bino.distances_to_p7(bino.with_virtual(raw)) - bino.distances_to_p7(scenario.layout)
    assert np.abs(err).max() < 0.01


def test_factories_rebuild_the_same_experiment():
    a = ex.binocular_experiment(n_trials=3, robot_scales=[1.0], calibration_scales=[0.0, 1.0])
    b = ex.binocular_experiment(n_trials=3, robot_scales=[1.0], calibration_scales=[0.0, 1.0])
    assert a.name == "binocular" and a.n_trials == 3 and a.scenario_key == b.scenario_key
    c = ex.binocular_experiment(n_trials=3, robot_scales=[1.0], calibration_scales=[1.0])
    assert c.scenario_key != a.scenario_key
    assert ex.field_experiment(n_trials=2).name == "field"
    with pytest.raises(CalibrationError, match="n_trials"):
        ex.binocular_experiment(n_trials=0)


def test_a_scenario_without_the_lens_rim_is_refused_by_name(tmp_path):
    for name in ("sensor", "calibrator", "station"):
        text = data_path("binocular", f"{name}.toml").read_text()
        if name == "sensor":
            assert "\nrim_radius_mm = " in text
            text = text.replace("\nrim_radius_mm = ", "\n# rim_radius_mm = ", 1)
        (tmp_path / f"{name}.toml").write_text(text)
    with pytest.raises(
        CalibrationError, match=r"sensor.toml: optics.rim_radius_mm: missing \(required\)"
    ):
        load_scenario(tmp_path)


def _perfect_robot(scenario):
    """The scenario with a robot whose true model is its nominal one (tolerances 0)."""
    import copy

    robot = copy.copy(scenario.robot)
    robot.tolerances = {k: 0.0 for k in scenario.robot.tolerances}
    return scenario.model_copy(update={"robot": robot})


def _chain(scenario, imaging, seed=7):
    rng = np.random.default_rng(seed)
    world = draw_world(scenario, rng, imaging)
    model = world.model(scenario, 0.0)
    cal = view_calibrator(scenario, world, 6, rng, imaging, model)
    sharp = reimage(scenario, cal, rng, Imaging(noise=False, defocus=False), model)
    return ex.handeye_chain(scenario, world, cal, sharp, model, 0.5, rng)


def test_handeye_chain_is_exact_without_defocus_noise_or_robot_error(scenario):
    """Known answer: sharp, noise-free dots, exact cameras and a perfect robot: only the pixel
    grid acts (Canny edges limit a rendered centre to a few hundredths of a pixel), so the
    hand-eye matrix is right to a tenth of a millimetre, Fig. 13 to a few hundredths, and the
    true matrix gives exactly the tracker's distance."""
    row = _chain(_perfect_robot(scenario), Imaging(noise=False, defocus=False))
    assert row["shift_px_rms"] < 0.1
    assert row["point_err_normal_mm"] < 0.03 and row["point_err_inplane_mm"] < 0.03
    assert row["pose_rot_err_mrad"] < 0.15
    assert row["trans_err_preliminary_mm"] < 0.3 and row["rot_err_preliminary_mrad"] < 0.4
    assert row["trans_err_preliminary_mm"] == row["trans_err_sharp_mm"]
    assert row["fig13_exact_p7_true"] < 1e-9
    assert row["fig13_exact_p7_preliminary"] < 0.05


def test_handeye_chain_carries_the_defocus_error_to_fig13(rim_scenario):
    """With the rim's defocus on (f/3.53) and nothing else: the triangulated
    points err more along the plate normal than across it, the calibrator poses tilt, and the
    preliminary matrix is millimetres off while the same views without defocus give it exactly."""
    sc = ex.with_optics(_perfect_robot(rim_scenario), f_number=3.53)
    row = _chain(sc, Imaging(noise=False, defocus=True))
    assert row["shift_px_max"] > 1.0
    assert row["point_err_normal_mm"] > row["point_err_inplane_mm"]
    assert row["pose_rot_err_mrad"] > 0.5
    assert row["trans_err_preliminary_mm"] > 1.0
    assert row["trans_err_sharp_mm"] < 0.3
    assert row["fig13_exact_p7_preliminary"] > 10 * row["fig13_exact_p7_sharp"]


@pytest.mark.parametrize("trial", ["binocular_trial", "field_trial", "optics_trial"])
def test_trials_run_on_one_opencv_thread_and_restore_the_setting(scenario, trial, monkeypatch):
    seen = []

    def stop(*args, **kwargs):
        seen.append(cv2.getNumThreads())
        raise RuntimeError("stopped after the world")

    monkeypatch.setattr(ex, "draw_world", stop)
    before = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        with pytest.raises(RuntimeError, match="stopped after the world"):
            getattr(ex, trial)(ex.Setup(scenario), np.random.default_rng(0))
        assert seen == [1]
        assert cv2.getNumThreads() == 3
    finally:
        cv2.setNumThreads(before)


def test_the_observed_error_null_catches_a_modification_that_sees_the_scored_distance(scenario):
    """The null control runs the modification on the exact sphere centres, where only the CMM's
    error is left: the leave-one-target-out modification cannot improve them, but a broken one
    that also uses the scored distance (the paper's circular reading) pulls them towards the
    CMM standards and passes the null."""
    rng = np.random.default_rng(5)
    n, ratios_holdout, ratios_circular = 60, [], []
    views = type("V", (), {})()
    for _ in range(n):
        world = draw_world(scenario, rng)
        poses = [viewpoints(scenario, scenario.calibrator2base, 1, rng)[1][0] for _ in range(3)]
        views.sensor2base = np.array([p @ scenario.sensor2flange for p in poses])
        exact8 = bino.with_virtual(sim_exact_points(scenario, views))
        hold = ex.exact_figures(world, exact8)
        ratios_holdout.append(hold["t3_null_with"] / hold["t3_holdout_exact"])
        std = ex.standard_to_p7(world)[:6]
        # the paper's circular modification (it scores the distances it is fitted to)
        modified = bino.modify_observed_errors(
            exact8, world.standard_pairs, world.standard_mm, combine=bino.virtual_weights()
        )[0]
        circular = bino.distances_to_p7(modified).mean(0)[:6]
        unmodified = bino.distances_to_p7(exact8).mean(0)[:6]
        ratios_circular.append(
            np.sqrt(np.mean((circular - std) ** 2)) / np.sqrt(np.mean((unmodified - std) ** 2))
        )
    # the null control's rule: significant when the median ratio's 95 % interval lies below 1
    assert median_interval(ratios_holdout)[2] > 1.0  # nothing to modify: the null holds
    assert median_interval(ratios_circular)[2] < 1.0  # the broken method passes it: caught
