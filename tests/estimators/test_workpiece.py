"""The 3-2-1 workpiece frame (Eq. 3-5): penalty LM against the SO(3)-constrained solution."""

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.estimators import workpiece as wp

DATUMS_WORK = np.array([[1100.0, 250.0, 0.0], [300.0, 250.0, 0.0], [700.0, 1050.0, 0.0]])
NOMINAL = geo.invert(geo.make_transform(np.eye(3), [300.0, -500.0, 0.0]))  # base2work


def _truth(rng):
    return geo.perturb(NOMINAL, np.deg2rad(0.5), 3.0, rng)


def _measured(base2work, rng, free=2.0):
    """Datums in base; A may slide along the slot (x), C anywhere in its plane (x, y)."""
    slide = np.zeros((3, 3))
    slide[0, 0] = rng.uniform(-free, free)
    slide[2, :2] = rng.uniform(-free, free, 2)
    return geo.apply(geo.invert(base2work), DATUMS_WORK + slide)


@pytest.mark.parametrize("solver", ["penalty", "so3"])
def test_noise_free_exact_recovery(solver):
    rng = np.random.default_rng(1)
    truth = _truth(rng)
    datums = _measured(truth, rng)
    if solver == "penalty":
        est = wp.rps_frame_penalty(datums, DATUMS_WORK, NOMINAL, penalty=1e4)
    else:
        est = wp.rps_frame_so3(datums, DATUMS_WORK, NOMINAL)
    np.testing.assert_allclose(est.value, truth, atol=1e-9)
    assert np.abs(wp.orthogonality(est.value[:3, :3])).max() < 1e-12


def test_penalty_and_so3_agree_with_noise_for_any_penalty():
    rng = np.random.default_rng(2)
    truth = _truth(rng)
    datums = _measured(truth, rng) + rng.normal(0, 0.05, (3, 3))
    so3 = wp.rps_frame_so3(datums, DATUMS_WORK, NOMINAL).value
    for m in (1.0, 1e2, 1e4, 1e6):
        pen = wp.rps_frame_penalty(datums, DATUMS_WORK, NOMINAL, penalty=m).value
        assert geo.translation_error(pen, so3) < 1e-6
        assert np.abs(pen[:3, :3] - so3[:3, :3]).max() < 1e-9


def test_equations_vanish_at_truth():
    rng = np.random.default_rng(3)
    truth = _truth(rng)
    assert np.abs(wp.rps_equations(truth, _measured(truth, rng), DATUMS_WORK)).max() < 1e-9


def test_bad_input():
    rng = np.random.default_rng(4)
    truth = _truth(rng)
    datums = _measured(truth, rng)
    on_line = DATUMS_WORK.copy()
    on_line[2] = [700.0, 250.0, 0.0]
    with pytest.raises(CalibrationError, match=r"datum C lies 0 mm from the line through A and B"):
        wp.rps_frame_so3(datums, on_line, NOMINAL)
    with pytest.raises(CalibrationError, match=r"shape \(2, 3\); expected \(3, 3\)"):
        wp.rps_frame_penalty(datums[:2], DATUMS_WORK, NOMINAL)
    with pytest.raises(CalibrationError, match="penalty factor M must be positive"):
        wp.rps_frame_penalty(datums, DATUMS_WORK, NOMINAL, penalty=0.0)
    bad = datums.copy()
    bad[0, 0] = np.inf
    with pytest.raises(CalibrationError, match="non-finite"):
        wp.rps_frame_so3(bad, DATUMS_WORK, NOMINAL)


def test_rps_batch_matches_the_so3_solver():
    rng = np.random.default_rng(7)
    work2base = geo.perturb(np.broadcast_to(geo.invert(NOMINAL), (5, 4, 4)), 0.01, 2.0, rng)
    datums = np.einsum("nij,kj->nki", work2base[:, :3, :3], DATUMS_WORK) + work2base[:, None, :3, 3]
    datums += rng.normal(0, 0.05, datums.shape)
    batch = wp.rps_frame_batch(datums, DATUMS_WORK, NOMINAL)
    for k in range(5):
        ref = wp.rps_frame_so3(datums[k], DATUMS_WORK, NOMINAL).value
        np.testing.assert_allclose(batch[k], ref, atol=1e-7)
