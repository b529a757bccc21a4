"""The lean MINPACK call against scipy's least_squares, which wraps the same routine."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from calstudy.core.errors import CalibrationError
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


def test_minpack_lm_names_improper_input():
    t = np.linspace(0.0, 4.0, 2)  # two residuals for three parameters
    y = _exp_model(np.array([2.0, 1.3, 0.5]), t, 0.0)
    x0 = np.array([1.0, 0.5, 0.0])
    with pytest.raises(CalibrationError, match=r"MINPACK rejected the problem \(3 parameters\)"):
        minpack_lm(_exp_model, x0, _exp_jac, (t, y))
    t = np.linspace(0.0, 4.0, 40)
    y = _exp_model(np.array([2.0, 1.3, 0.5]), t, 0.0)
    with pytest.raises(CalibrationError, match="MINPACK rejected.*Improper input"):
        minpack_lm(_exp_model, x0, _exp_jac, (t, y), xtol=-1.0)


def _noisy_exp(seed):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 4.0, 40)
    return t, _exp_model(np.array([2.0, 1.3, 0.5]), t, 0.0) + rng.normal(0.0, 0.01, t.size)


def _lmder_against_least_squares(t, y, x0, jac, max_nfev):
    """``_lmder`` and ``least_squares(method="lm")`` on the same problem: asserts the same
    solution, residuals, Jacobian, cost, evaluation count and status, and the same evaluations
    in the same order (the history an Estimate keeps); returns ours and its evaluations."""
    from calstudy.core import estimation

    calls = {"ours": [], "ref": []}

    def fun_for(key):
        def fun(x):
            calls[key].append(x.copy())
            return _exp_model(x, t, y)

        return fun

    tols = {"xtol": 1e-12, "ftol": 1e-12, "gtol": 1e-12, "max_nfev": max_nfev}
    ours = estimation._lmder(fun_for("ours"), x0, jac, **tols)
    ref = least_squares(fun_for("ref"), x0, jac=jac, method="lm", **tols)
    for field in ("x", "fun", "jac"):
        assert getattr(ours, field).tobytes() == np.asarray(getattr(ref, field)).tobytes(), field
    assert (ours.cost, ours.nfev, ours.status) == (ref.cost, ref.nfev, ref.status)
    assert [c.tobytes() for c in calls["ours"]] == [c.tobytes() for c in calls["ref"]]
    return ours, calls["ours"]


@pytest.mark.parametrize("max_nfev", [None, 3])
def test_levenberg_marquardt_minpack_path_is_least_squares(max_nfev):
    from calstudy.core import estimation

    t, y = _noisy_exp(5)
    x0 = np.array([1.0, 0.5, 0.0])

    def jac(x):
        return _exp_jac(x, t, y)

    ours, calls = _lmder_against_least_squares(t, y, x0, jac, max_nfev)
    if max_nfev == 3:
        assert ours.status == 0
        with pytest.raises(CalibrationError, match="did not converge after 3 evaluations"):
            estimation.levenberg_marquardt(
                lambda x: _exp_model(x, t, y), x0, jac=jac, max_nfev=3, label="fit"
            )


@pytest.mark.parametrize("start", [[1.0, 0.5, 0.0], [-2.0, 3.0, -1e-3], [0.0, 0.0, 0.0]])
def test_levenberg_marquardt_two_point_path_is_least_squares(start):
    """The forward-difference Jacobian of the MINPACK path is least_squares' "2-point" one:
    the same evaluations in the same order, the same iterates, the same bytes."""
    from calstudy.core import estimation

    t, y = _noisy_exp(11)
    x0 = np.array(start)
    ours, calls = _lmder_against_least_squares(t, y, x0, "2-point", None)
    assert len(calls) >= ours.nfev + x0.size  # the differences were taken
    assert np.allclose(ours.x, [2.0, 1.3, 0.5], atol=0.05)
    with pytest.raises(CalibrationError, match="only '2-point'"):
        estimation._lmder(
            lambda x: _exp_model(x, t, y), x0, "3-point",
            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=None,
        )
