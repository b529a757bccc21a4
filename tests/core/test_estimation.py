"""The lean MINPACK call against scipy's least_squares, which wraps the same routine."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from calstudy.core.estimation import minpack_lm


def _exp_model(x, t, y):
    return x[0] * np.exp(-x[1] * t) + x[2] - y


def _exp_jac(x, t, y):
    e = np.exp(-x[1] * t)
    return np.column_stack([e, -x[0] * t * e, np.ones_like(t)])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("tol", [1e-8, 1e-15])
def test_minpack_lm_is_least_squares_lm_byte_for_byte(seed, tol):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 4.0, 40)
    y = _exp_model(np.array([2.0, 1.3, 0.5]), t, 0.0) + rng.normal(0.0, 0.01, t.size)
    x0 = np.array([1.0, 0.5, 0.0])
    ours = minpack_lm(_exp_model, x0, _exp_jac, (t, y), xtol=tol, ftol=tol, gtol=tol)
    ref = least_squares(
        _exp_model, x0, jac=_exp_jac, args=(t, y), method="lm", xtol=tol, ftol=tol, gtol=tol
    ).x
    assert ours.tobytes() == ref.tobytes()
    # and it is the fit: the truth within a few noise-sized standard errors
    assert np.allclose(ours, [2.0, 1.3, 0.5], atol=0.05)
    assert np.array_equal(x0, [1.0, 0.5, 0.0])  # the start is not overwritten


def test_minpack_lm_respects_the_evaluation_limit():
    t = np.linspace(0.0, 4.0, 40)
    y = _exp_model(np.array([2.0, 1.3, 0.5]), t, 0.0)
    x0 = np.array([1.0, 0.5, 0.0])
    capped = minpack_lm(_exp_model, x0, _exp_jac, (t, y), max_nfev=2)
    ref = least_squares(
        _exp_model, x0, jac=_exp_jac, args=(t, y), method="lm", max_nfev=2,
        xtol=1e-12, ftol=1e-12, gtol=1e-12,
    ).x
    assert capped.tobytes() == ref.tobytes()
    assert not np.allclose(capped, [2.0, 1.3, 0.5], atol=1e-6)
