"""Base parameters by column-pivoted QR (known answers) and pose selection."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.papers.selfcal.simulate import view_geometry
from calstudy.selfcal import design
from calstudy.selfcal.model import IS_LENGTH, PARAM_NAMES, GlobalModel, params_to_pose
from calstudy.selfcal.planning import candidate_views


def _planar_jacobian(Q, p):
    """Numerical Jacobian of a planar 2R arm with two parallel z axes and offsets along them.

    Parameters (t1, l1, t2, l2, d1, d2): joint offsets, link lengths, offsets along the axes.
    """

    def point(q, p):
        t1, l1, t2, l2, d1, d2 = p
        a, b = q[0] + t1, q[0] + t1 + q[1] + t2
        return np.array(
            [l1 * math.cos(a) + l2 * math.cos(b), l1 * math.sin(a) + l2 * math.sin(b), d1 + d2]
        )

    rows = []
    for q in Q:
        cols = []
        for i in range(6):
            h = np.zeros(6)
            h[i] = 1e-6
            cols.append((point(q, p + h) - point(q, p - h)) / 2e-6)
        rows.append(np.array(cols).T)
    return np.vstack(rows)


def test_parallel_axis_pair_offsets_only_in_combination():
    rng = np.random.default_rng(0)
    names = ("t1", "l1", "t2", "l2", "d1", "d2")
    length = np.array([False, True, False, True, True, True])
    jac = _planar_jacobian(rng.uniform(-2, 2, (8, 2)), np.array([0.1, 500.0, -0.2, 400.0, 5, 7]))
    out = design.base_parameters(jac, names, length)
    assert out.rank == 5
    status = dict(zip(out.table["name"], out.table["status"], strict=True))
    assert {n for n, s in status.items() if s == design.ALONE} == {"t1", "l1", "t2", "l2"}
    assert status["d1"] == status["d2"] == design.COMBINED
    combo = out.table.set_index("name").loc["d1", "combination"]
    assert combo in ("d1 + d2", "d2 + d1")


def _with_first_joint_offset(params, Q, C):
    """The global model's Jacobian with one more column: an offset theta1 of joint 1."""
    model = GlobalModel()
    _, jac = model.points_and_jacobian(params, Q, C)
    h = 1e-7
    dq = np.zeros_like(Q)
    dq[:, 0] = h
    extra = (model.points(params, Q + dq, C) - model.points(params, Q - dq, C)).ravel() / (2 * h)
    return np.column_stack([jac, extra])


def test_base_yaw_and_first_joint_offset_only_combined(noise_free):
    station, meas, _ = noise_free
    params = station.true_params.copy()
    params[4:6] = 0.0  # base z axis along the part z axis: gamma2 and theta1 turn about one axis
    jac = _with_first_joint_offset(params, meas.Q, meas.C_true)
    out = design.base_parameters(jac, (*PARAM_NAMES, "theta1"), np.append(IS_LENGTH, False))
    assert out.rank == 30
    table = out.table.set_index("name")
    assert table.loc["gamma2", "status"] == table.loc["theta1", "status"] == design.COMBINED
    assert table.loc["theta1", "combination"] in ("gamma2 + theta1", "theta1 + gamma2")
    others = table.drop(index=["gamma2", "theta1"])
    assert (others["status"] == design.ALONE).all()


def test_scanner_design_identifies_all_30_alone_and_a_zero_column_none(noise_free):
    station, meas, _ = noise_free
    _, jac = GlobalModel().points_and_jacobian(station.true_params, meas.Q, meas.C_true)
    out = design.base_parameters(jac)
    assert out.rank == 30 and (out.table["status"] == design.ALONE).all()
    padded = np.column_stack([jac, np.zeros(len(jac))])
    out = design.base_parameters(padded, (*PARAM_NAMES, "nothing"), np.append(IS_LENGTH, True))
    assert out.table.set_index("name").loc["nothing", "status"] == design.NONE


def test_one_point_sensor_leaves_three_sensor_combinations(noise_free):
    station, meas, _ = noise_free
    C = np.tile([0.0, 0.0, 300.0], (len(meas), 1))
    _, jac = GlobalModel().points_and_jacobian(station.true_params, meas.Q, C)
    out = design.base_parameters(jac)
    assert out.rank == 27
    combined = set(out.table.loc[out.table["status"] == design.COMBINED, "name"])
    assert combined <= {"x1", "y1", "z1", "gamma1", "phi1", "eps1"} and len(combined) >= 4


def test_selection_beats_random_and_runs_within_5_s(quiet, noise_free):
    station, _, _ = noise_free
    rng = np.random.default_rng(3)
    Q, sphere = candidate_views(
        quiet.nominal_robot,
        quiet.sensor.design,
        view_geometry(quiet),
        station.spheres_base,
        50,
        rng,
    )
    # 5,000 candidates: the 200 planned views, each turned about joint 6 in 25 steps
    turns = np.linspace(-math.pi, math.pi, 25, endpoint=False)
    Q = np.repeat(Q, 25, axis=0)
    Q[:, 5] += np.tile(turns, len(Q) // 25)
    sphere = np.repeat(sphere, 25)
    assert len(Q) == 5000
    start = time.perf_counter()
    blocks, _ = design.candidate_jacobians(station.nominal_params, Q, station.spheres_part, sphere)
    chosen = design.select_poses(blocks, 24)
    elapsed = time.perf_counter() - start
    assert elapsed <= 5.0, f"{elapsed:.2f} s"
    assert len(set(chosen)) == 24
    best = design.observability(blocks[chosen])
    randoms = [
        design.observability(blocks[rng.choice(len(Q), 24, replace=False)]) for _ in range(20)
    ]
    assert best["log_det"] > max(r["log_det"] for r in randoms)
    assert best["min_sv"] > np.median([r["min_sv"] for r in randoms])


def test_greedy_then_exchange_is_no_worse_than_greedy():
    rng = np.random.default_rng(1)
    blocks = rng.normal(size=(300, 3, 8))
    greedy = design.select_poses(blocks, 6, exchange_rounds=0)
    swapped = design.select_poses(blocks, 6)
    assert (
        design.observability(blocks[swapped])["log_det"]
        >= design.observability(blocks[greedy])["log_det"] - 1e-12
    )


def test_sizes_at_once_are_the_selections_one_by_one():
    """The shared greedy steps and the exchange rounds of one size leave the others alone."""
    rng = np.random.default_rng(2)
    blocks = rng.normal(size=(80, 3, 12))
    together = design.select_poses_sizes(blocks, [4, 9, 15, 30])
    for n, chosen in together.items():
        alone = design.select_poses_sizes(blocks, [n])[n]
        assert chosen.tobytes() == alone.tobytes(), n
    # the greedy prefix: without exchange, a size's choice is the start of a larger one's
    greedy = design.select_poses_sizes(blocks, [4, 15], exchange_rounds=0)
    assert set(greedy[4]) < set(greedy[15])
    with pytest.raises(CalibrationError, match="cannot choose 81 poses"):
        design.select_poses_sizes(blocks, [4, 81])


def test_a_size_asked_twice_gets_the_selection_of_one_call():
    rng = np.random.default_rng(3)
    for _ in range(40):
        blocks = rng.normal(size=(30, 3, 12))
        twice = design.select_poses_sizes(blocks, [6, 6], exchange_rounds=1)[6]
        assert twice.tobytes() == design.select_poses(blocks, 6, exchange_rounds=1).tobytes()


def test_selection_refuses_impossible_sizes():
    blocks = np.zeros((20, 3, 30))
    with pytest.raises(CalibrationError, match="cannot choose 5 poses"):
        design.select_poses(blocks, 5)
    with pytest.raises(CalibrationError, match="cannot choose 21 poses"):
        design.select_poses(blocks, 21)


def test_candidate_centres_are_the_spheres_seen_from_the_pose(noise_free):
    station, meas, _ = noise_free
    _, C = design.candidate_jacobians(
        station.true_params, meas.Q, station.spheres_part, meas.sphere
    )
    pose = params_to_pose(np.zeros(6))
    assert pose.shape == (4, 4)
    np.testing.assert_allclose(C, meas.C_true, atol=1e-6)
