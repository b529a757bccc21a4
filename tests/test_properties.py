# ruff: noqa: E501  (property tables: one case per line)
"""Property tests of the shared layers on random valid and invalid input, continued from
``test_bad_inputs.py``: the rest of ``core.geometry``, the solvers of ``core.estimation``, the
hand-eye helpers, ``models.sensors``, ``models.targets``, the rendering of ``models.optics``,
``models.exposure`` and ``models.urdf``; and the overflow of finite values near 1e300.

Each test draws input with hypothesis (derandomized, no example database) and asserts three
kinds of thing: a finite result (never NaN or inf) for finite input, or a CalibrationError;
a CalibrationError naming the input for invalid input; and a real property (a known answer, an
identity, or agreement with scipy, OpenCV or Pinocchio).
"""

from __future__ import annotations

import atexit
import dataclasses
import math
import re
import shutil
import tempfile

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

from calstudy import CalibrationError
from calstudy.core import estimation, stats
from calstudy.core import geometry as geo

# the hand-eye helpers, imported in this one place from where they live
from calstudy.estimators import axxb
from calstudy.estimators import binocular as bino
from calstudy.handeye import checks as hchk
from calstudy.handeye import diagnose as hdiag
from calstudy.handeye import inputs as hin
from calstudy.handeye import plan as hplan
from calstudy.handeye import refine as hr
from calstudy.handeye import robust as hrob
from calstudy.handeye import simulate as hsim
from calstudy.handeye import sphere
from calstudy.models import exposure, optics, reach, sensors, targets, urdf
from calstudy.models.robots import load_robot
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import stereo_rig
from calstudy.papers.dualarm.experiments import base_to_base
from calstudy.papers.hybrid.experiments import stationary_sensor_to_base

_HOME = tempfile.mkdtemp(prefix="calstudy-hypothesis-")
set_hypothesis_home_dir(_HOME)
atexit.register(shutil.rmtree, _HOME, ignore_errors=True)
settings.register_profile(
    "properties",
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=30,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
PROFILE = settings.get_profile("properties")

FLOATS = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False, width=64)
#: any finite double, from the subnormals to 1.8e308
WIDE = st.floats(allow_nan=False, allow_infinity=False, width=64)
BAD = st.sampled_from([math.nan, math.inf, -math.inf])
SEEDS = st.integers(0, 2**32 - 1)


def _arrays(shape, elements=FLOATS):
    return hnp.arrays(np.float64, shape, elements=elements)


def _finite(out) -> bool:
    """Every number in ``out`` (arrays, numbers, tuples, lists, dicts, dataclass fields) is
    finite; strings, booleans and None are not numbers."""
    if isinstance(out, estimation.Estimate):
        out = [out.value, out.params, out.covariance, out.residuals]
    if dataclasses.is_dataclass(out) and not isinstance(out, type):
        out = [getattr(out, f.name) for f in dataclasses.fields(out)]
    if isinstance(out, dict):
        out = list(out.values())
    if isinstance(out, tuple | list):
        return all(_finite(v) for v in out)
    if isinstance(out, bool | str | None) or callable(out):
        return True
    if isinstance(out, int | float | np.number | np.ndarray):
        a = np.asarray(out)
        return a.dtype == object or not np.issubdtype(a.dtype, np.floating) or bool(np.isfinite(a).all())
    return True


def _result(fn, *args, **kw):
    """``fn(*args, **kw)`` checked finite, or None if it refused the input."""
    try:
        out = fn(*args, **kw)
    except CalibrationError:
        return None
    assert _finite(out), f"{getattr(fn, '__name__', fn)} returned a non-finite value: {out!r}"
    return out


def _rotations(n):
    """``n`` rotation matrices drawn from rotation vectors of angle up to about 3 rad."""
    return _arrays((n, 3), st.floats(-1.7, 1.7)).map(geo.rotvec_to_matrix)


def _poses(n, scale=500.0):
    """``n`` rigid transforms with translations up to ``scale`` mm."""
    return st.tuples(_rotations(n), _arrays((n, 3), st.floats(-scale, scale))).map(lambda rt: geo.make_transform(*rt))


def _rigid(rotvec, translation):
    return geo.make_transform(geo.rotvec_to_matrix(rotvec), translation)


# ----------------------------------------------------------------------------------------------
# overflow: finite values near 1e300


KR16 = load_robot("kuka_kr16_2")
BOUND = reach.reach_bound(KR16)


@PROFILE
@given(st.lists(WIDE, min_size=1, max_size=12), st.floats(1e-3, 1e3))
def test_rmse_is_finite_and_scales_for_every_finite_input(values, factor):
    """rmse of any finite values is finite, and rmse(c x) = |c| rmse(x) far past 1e154."""
    x = np.array(values)
    out = stats.rmse(x)
    assert math.isfinite(out) and 0.0 <= out <= np.abs(x).max() * (1 + 1e-12)
    big = x / max(np.abs(x).max(), 1e-300) * 1e300  # the same values, the largest at 1e300
    assert math.isclose(stats.rmse(big * factor / 1e3), stats.rmse(big) * factor / 1e3, rel_tol=1e-12)
    np.testing.assert_allclose(stats.rmse(np.stack([big, big / 4]), axis=1), [stats.rmse(big), stats.rmse(big) / 4], rtol=1e-13)


def test_rmse_known_answers_near_the_largest_float():
    assert stats.rmse([3e300, 4e300]) == pytest.approx(math.sqrt(12.5) * 1e300, rel=1e-15)
    assert stats.rmse([1.7e308, 1.7e308]) == pytest.approx(1.7e308, rel=1e-15)
    assert stats.rmse([3.0, 4.0]) == math.sqrt(12.5)  # the plain formula, byte for byte


@PROFILE
@given(_arrays((8, 3), WIDE.filter(lambda v: abs(v) < 8e307)))
def test_distances_to_p7_finite_and_equal_to_hypot(points):
    """Every finite layout whose differences are floats gives finite distances, equal to the
    distance by math.hypot (which never squares)."""
    d = bino.distances_to_p7(points)
    ref = [math.hypot(*(points[i] - points[6])) for i in (0, 1, 2, 3, 4, 5, 7)]
    np.testing.assert_allclose(d, ref, rtol=1e-14)


def test_distances_to_p7_that_overflow_are_refused_with_the_number():
    p = np.zeros((8, 3))
    p[0], p[6] = 1.7e308, -1.7e308
    with pytest.raises(CalibrationError, match=r"calibrator targets: a distance to P7 overflows \(largest \|coordinate\| 1.7e\+308 mm\)"):
        bino.distances_to_p7(p)


@PROFILE
@given(_rotations(1), _arrays((3,), WIDE.filter(lambda v: abs(v) < 1e307)))
def test_reach_excess_finite_and_at_least_the_distance_bound(rotation, translation):
    """The excess of any finite pose is finite; far away it is the wrist point's distance from
    the shoulder circle less the reach, which is at least |d| - r - L."""
    pose = geo.make_transform(rotation[0], translation)
    e = BOUND.excess(pose)
    assert math.isfinite(e)
    d = rotation[0] @ BOUND.wrist + translation - BOUND.centre
    dist = math.hypot(math.hypot(d[0], d[1]), d[2])
    assert e >= (dist - BOUND.radius - BOUND.reach) * (1 - 1e-12) - 1e-9
    assert BOUND.unreachable(pose) == (e > BOUND.margin_mm())


def test_reach_excess_of_far_poses_known_answer_and_non_finite_refused():
    far = geo.make_transform(np.eye(3), [1e300, 0.0, 0.0])
    assert BOUND.excess(far) == pytest.approx(1e300, rel=1e-12)
    assert BOUND.unreachable(far)
    for bad in (math.nan, math.inf):
        with pytest.raises(CalibrationError, match=r"flange2base: translation \[.*\] mm has no finite distance"):
            BOUND.excess(geo.make_transform(np.eye(3), [bad, 0.0, 0.0]))


@settings(PROFILE, max_examples=15)
@given(_rotations(1), _arrays((3,), st.floats(1e154, 1e307)), _arrays((3,), st.sampled_from([1.0, -1.0])), _arrays((6,), st.floats(-3, 3)))
def test_ik_far_poses_are_refused_never_nan(rotation, magnitude, sign, q0):
    """IK of a pose whose error overflows is refused naming the translation; never NaN."""
    pose = geo.make_transform(rotation[0], magnitude * sign)
    with pytest.raises(CalibrationError, match=r"flange2base: translation \[.*\] mm lies too far"):
        KR16.ik(pose, q0)


@settings(PROFILE, max_examples=15)
@given(_rotations(1), _arrays((3,), WIDE.filter(lambda v: abs(v) < 1e154)), _arrays((6,), st.floats(-3, 3)), _arrays((6,), st.floats(-0.05, 0.05)))
def test_ik_of_any_finite_pose_is_finite_or_refused(rotation, translation, q0, dq):
    """IK of any finite pose is finite or refused; of a pose the arm reaches (fk of q0), from
    a start near q0, it puts the flange on the pose."""
    pose = geo.make_transform(rotation[0], translation)
    q = _result(KR16.ik, pose, q0, max_iter=30)
    if q is not None:
        assert geo.translation_error(KR16.fk(q), pose) < 1e-6
    target = KR16.fk(np.clip(q0, KR16.qmin + 0.1, KR16.qmax - 0.1))
    q = KR16.ik(target, np.clip(q0, KR16.qmin + 0.1, KR16.qmax - 0.1) + dq)
    assert geo.translation_error(KR16.fk(q), target) < 1e-6 and geo.rotation_error(KR16.fk(q), target) < 1e-9


def test_ik_known_answer_is_unchanged():
    q = np.array([0.1, -1.2, 1.1, 0.2, 0.5, -0.3])
    np.testing.assert_allclose(KR16.fk(KR16.ik(KR16.fk(q), q + 0.05)), KR16.fk(q), atol=1e-8)


# ----------------------------------------------------------------------------------------------
# core.geometry: the algebra, the SO(3) Jacobians, the errors, random draws and the checks


@PROFILE
@given(_arrays((4, 3), st.floats(-3.0, 3.0)), _arrays((4, 3)), _arrays((5, 3)))
def test_transform_algebra_identities(rotvec, translation, points):
    """make_transform, invert, apply, the pose vectors and log6/exp6 against Pinocchio and
    scipy: T^-1 T = I, apply(T, p) = R p + t, pose_from_vector(pose_to_vector(T)) = T."""
    t = _rigid(rotvec, translation)
    assert _finite(t) and _finite(geo.invert(t))
    np.testing.assert_allclose(geo.invert(t) @ t, np.broadcast_to(np.eye(4), t.shape), atol=1e-9)
    np.testing.assert_allclose(geo.apply(t[0], points), points @ t[0, :3, :3].T + t[0, :3, 3], atol=1e-9)
    np.testing.assert_allclose(geo.pose_from_vector(geo.pose_to_vector(t)), t, atol=1e-9)
    np.testing.assert_allclose(geo.matrix_to_rotvec(t[:, :3, :3]), Rotation.from_matrix(t[:, :3, :3]).as_rotvec(), atol=1e-12)
    np.testing.assert_allclose(geo.exp6(geo.log6(t[0])), t[0], atol=1e-8)
    np.testing.assert_allclose(geo.skew(rotvec) @ translation[..., None], np.cross(rotvec, translation)[..., None], atol=1e-9)


@PROFILE
@given(_arrays((3,), st.floats(-3.0, 3.0)), _arrays((3,), st.floats(-1.0, 1.0)))
def test_so3_jacobians_are_derivatives(w, d):
    """exp(w + e d) = exp(e J_l(w) d) exp(w) to first order, and J_r^-1 inverts J_l(-w)."""
    assume(0.05 < np.linalg.norm(w) < 3.0)
    eps = 1e-6
    lhs = geo.rotvec_to_matrix(w + eps * d)
    rhs = geo.rotvec_to_matrix(eps * geo.so3_left_jacobian(w)[0] @ d) @ geo.rotvec_to_matrix(w)
    assert np.abs(lhs - rhs).max() < 1e-9
    np.testing.assert_allclose(geo.so3_right_jacobian_inverse(w)[0] @ geo.so3_left_jacobian(-w)[0], np.eye(3), atol=1e-9)
    assert _finite(geo.so3_left_jacobian(np.zeros(3))) and _finite(geo.so3_right_jacobian_inverse(np.zeros(3)))


@PROFILE
@given(_arrays((6, 3), st.floats(-3.0, 3.0)), _arrays((6, 3)), _arrays((6, 3), st.floats(-3.0, 3.0)))
def test_pose_errors_against_scipy(rv1, t1, rv2):
    a, b = _rigid(rv1, t1), _rigid(rv2, t1 * 0.5)
    np.testing.assert_allclose(geo.rotation_error(a, b), (Rotation.from_matrix(b[:, :3, :3]).inv() * Rotation.from_matrix(a[:, :3, :3])).magnitude(), atol=1e-9)
    np.testing.assert_allclose(geo.translation_error(a, b), np.linalg.norm(t1 * 0.5, axis=1), atol=1e-9)
    assert np.all(geo.rotation_angle(a[:, :3, :3]) <= math.pi)


@PROFILE
@given(SEEDS, st.integers(0, 20), st.floats(0.0, 1.0), st.floats(0.0, 100.0))
def test_random_draws_are_rigid_and_perturb_moves_by_sigma(seed, n, s_rot, s_trans):
    rng = np.random.default_rng(seed)
    r = geo.random_rotation(rng, n)
    if n:
        geo.check_rotation("drawn", r)
    t = geo.make_transform(geo.random_rotation(rng, max(n, 1)), rng.uniform(-500, 500, (max(n, 1), 3)))
    moved = geo.perturb(t, s_rot, s_trans, rng)
    geo.check_transform("perturbed", moved)
    assert np.all(geo.translation_error(moved, t) <= 8 * s_trans * math.sqrt(3) + 1e-9)
    assert np.all(geo.rotation_error(moved, t) <= 8 * s_rot * math.sqrt(3) + 1e-9)
    assert np.array_equal(geo.perturb(t, 0.0, 0.0, rng), t)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: geo.random_rotation(np.random.default_rng(0), -1), r"size = -1 must be None or an integer >= 0"),
        (lambda: geo.random_rotation(np.random.default_rng(0), 2.5), r"size = 2.5 must be"),
        (lambda: geo.perturb(np.eye(4), math.nan, 1.0, np.random.default_rng(0)), r"sigma_rot = nan rad must be finite and >= 0"),
        (lambda: geo.perturb(np.eye(4), 0.1, -1.0, np.random.default_rng(0)), r"sigma_trans = -1.0 mm must be finite and >= 0"),
        (lambda: geo.look_at([0, 0, 0], [0, 0, 0]), r"eye and target coincide"),
        (lambda: geo.look_at([0, 0, math.inf], [0, 0, 0]), r"look_at: eye .* must be finite"),
        (lambda: geo.check_finite("tool", [1.0, math.nan]), r"tool holds a non-finite value \(nan\) at index \(1,\)"),
        (lambda: geo.check_shape("tool", np.zeros((2, 4)), (None, 3)), r"tool has shape \(2, 4\); expected \(N, 3\)"),
        (lambda: geo.check_rotation("R", 2 * np.eye(3)), r"R is not orthonormal \(max \|R\^T R - I\| = 3"),
        (lambda: geo.check_rotation("R", np.diag([1.0, 1.0, -1.0])), r"R is a reflection \(det = -1"),
        (lambda: geo.check_transform("T", np.zeros((0, 4, 4))), r"T holds no transforms"),
        (lambda: geo.check_points("pts", np.zeros((2, 3)), 3, 3, "a plane"), r"a plane needs at least 3 points; got 2"),
        (lambda: geo.check_same_length("a", np.zeros(2), "b", np.zeros(3)), r"a has 2 rows but b has 3"),
        (lambda: geo.check_not_collinear("points", np.outer(np.arange(5.0), [1.0, 2.0, 3.0])), r"the 5 points are collinear \(singular values"),
        (lambda: geo.rotation_angle(np.zeros((3, 4))), r"rotations have shape \(3, 4\)"),
    ],
)
def test_geometry_refusals_name_the_input_and_number(call, message):
    with pytest.raises(CalibrationError, match=message):
        call()


@PROFILE
@given(_arrays((3,)), _arrays((3,)), _arrays((3,), st.floats(-1.0, 1.0)))
def test_look_at_points_the_optical_axis_at_the_target(eye, target, up):
    """The camera is at ``eye``, its +z axis towards ``target``, its frame rigid; or refused
    (coincident points, or a distance whose square underflows: below 1e-154 mm)."""
    t = _result(geo.look_at, eye, target, up if np.linalg.norm(up) > 0 else (0.0, 0.0, 1.0))
    if t is None:  # refused: the points coincide, or their distance squared underflows
        assert float(np.sum((target - eye) ** 2)) == 0.0
        return
    geo.check_transform("look_at", t, tol=1e-9)
    np.testing.assert_array_equal(t[:3, 3], eye)
    direction = (target - eye) / np.linalg.norm(target - eye)
    np.testing.assert_allclose(t[:3, 2], direction, atol=1e-12)


@PROFILE
@given(st.integers(2, 9).flatmap(lambda n: _arrays((n, 3))), st.sampled_from([2, 3]))
def test_collinearity_check_agrees_with_the_rank(points, dim):
    """check_not_collinear refuses exactly the sets whose centred rank is below 2 (by the
    singular values at RANK_RTOL), and a point set on a line is always refused."""
    p = points[:, :dim]
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    degenerate = s[0] == 0.0 or s[1] <= geo.RANK_RTOL * s[0]
    try:
        geo.check_not_collinear("points", p)
    except CalibrationError as exc:
        assert degenerate and f"the {len(p)} points are collinear" in str(exc)
    else:
        assert not degenerate
    line = np.outer(points[:, 0], np.ones(dim)) * np.arange(1, dim + 1)
    with pytest.raises(CalibrationError, match="collinear"):
        geo.check_not_collinear("points", line)


# ----------------------------------------------------------------------------------------------
# core.estimation: the least-squares solvers


def _linear_problem(seed, m, n, cond):
    """A well-posed linear least-squares problem ``A x = b`` (m x n, condition ``cond``)."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(m, n)))
    v, _ = np.linalg.qr(rng.normal(size=(n, n)))
    a = q @ np.diag(np.geomspace(1.0, 1.0 / cond, n)) @ v.T
    return a, rng.normal(size=m) * 10.0


@PROFILE
@given(SEEDS, st.integers(1, 6).flatmap(lambda n: st.tuples(st.integers(n, n + 6), st.just(n))), st.floats(1.0, 1e3), st.sampled_from(["lm", "trf"]))
def test_levenberg_marquardt_solves_linear_least_squares(seed, size, cond, method):
    """On ``A x - b`` the solution is numpy's lstsq, the covariance ``sigma^2 (A^T A)^-1``, the
    condition number that of ``A``; minpack_lm finds the same solution."""
    m, n = size
    a, b = _linear_problem(seed, m, n, cond)
    ref = np.linalg.lstsq(a, b, rcond=None)[0]
    est = estimation.levenberg_marquardt(lambda x: a @ x - b, np.zeros(n), jac=lambda x: a, sigma=0.5, method=method)
    assert _finite(est)
    np.testing.assert_allclose(est.params, ref, atol=1e-7 * cond * (1 + np.abs(ref).max()))
    np.testing.assert_allclose(est.covariance, 0.25 * np.linalg.inv(a.T @ a), rtol=1e-6, atol=1e-12)
    assert est.condition_number == pytest.approx(np.linalg.cond(a), rel=1e-6)
    assert estimation.condition_number(a) == pytest.approx(np.linalg.cond(a), rel=1e-9)
    x = estimation.minpack_lm(lambda x: a @ x - b, np.zeros(n), lambda x: a)
    np.testing.assert_allclose(x, ref, atol=1e-7 * cond * (1 + np.abs(ref).max()))


@PROFILE
@given(st.integers(1, 12).flatmap(lambda m: st.tuples(_arrays((m, 3), st.floats(-1e6, 1e6)), _arrays((m,), st.floats(-1e6, 1e6)))), st.sampled_from([None, 1.0]))
def test_covariance_from_jacobian_is_finite_with_degrees_of_freedom(data, sigma):
    """Any finite Jacobian gives a finite covariance (the pseudo-inverse drops the directions
    it does not determine) and a condition number >= 1 or inf; without degrees of freedom
    and without ``sigma`` the covariance is NaN, as documented."""
    jac, res = data
    cov, cond = estimation.covariance_from_jacobian(jac, res, sigma)
    assert cond >= 1.0  # inf for a rank-deficient Jacobian
    if sigma is not None or jac.shape[0] > jac.shape[1]:
        assert np.isfinite(cov).all()
        np.testing.assert_allclose(cov, cov.T, atol=1e-12 * (1 + np.abs(cov).max()))
    else:
        assert np.isnan(cov).all()


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: estimation.levenberg_marquardt(lambda x: x, np.array([1.0, math.nan]), label="fit"), r"fit: the starting point is not finite \(\[ *1\. +nan\]\)"),
        (lambda: estimation.levenberg_marquardt(lambda x: x / 0.0, np.zeros(2), label="fit"), r"fit: residuals are not finite at the starting point"),
        (lambda: estimation.levenberg_marquardt(lambda x: x[:2], np.zeros(3), label="fit"), r"fit: 2 equations for 3 unknowns"),
        (lambda: estimation.levenberg_marquardt(lambda x: np.array([x[0], 0.0]), np.zeros(2), label="fit", max_condition=1e6), r"fit: the estimate is not determined by these data: condition number inf \(limit 1e\+06\)"),
        (lambda: estimation.levenberg_marquardt(lambda x: np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]]), np.array([-1.2, 1.0]), label="fit", max_nfev=3), r"fit did not converge after 3 evaluations \(cost 2.19907\)"),
        (lambda: estimation.minpack_lm(lambda x: x[:1], np.zeros(2), lambda x: np.eye(2)[:1]), r"MINPACK rejected the problem \(2 parameters\)"),
        (lambda: estimation.check_condition(1e9, 1e6, "the tool", "move more"), r"the tool is not determined by these data: condition number 1e\+09 \(limit 1e\+06\); move more"),
        (lambda: estimation.apply_fit_check(estimation.Estimate(np.zeros(1), np.zeros(1)), estimation.goodness_of_fit(np.zeros(5), 1, label="fit"), "loud"), r"misfit policy 'loud' is not one of"),
    ],
)
def test_estimation_refusals_name_the_input_and_number(call, message):
    with pytest.raises(CalibrationError, match=message):
        call()


@PROFILE
@given(SEEDS, st.integers(3, 200), st.floats(0.1, 10.0))
def test_goodness_of_fit_brackets_chi2_of_the_stated_noise(seed, m, scale):
    """Residuals drawn at the stated noise pass at the 5 % level about 95 % of the time; the
    bounds bracket 1 and are those of scipy's chi-square; residuals 10 times the noise fail."""
    from scipy.stats import chi2

    r = np.random.default_rng(seed).normal(size=m)
    check = estimation.goodness_of_fit(r, 2, label="fit", alpha=0.05)
    assert check.low <= 1.0 <= check.high
    assert check.low == pytest.approx(chi2.ppf(0.025, m - 2) / (m - 2), rel=1e-12)
    assert check.ok == (check.low <= float(r @ r) / (m - 2) <= check.high)
    loud = estimation.goodness_of_fit(r * 10.0 * scale + 10.0, 2, label="fit", alpha=0.05)
    assert loud.too_large and loud.message.startswith("fit: whitened residual chi2/dof")


# ----------------------------------------------------------------------------------------------
# the hand-eye helpers: simulation, inputs, closed forms, refinement, robust statistics, checks,
# diagnosis and pose planning (canonical poses: a = flange2base, b = target2camera, x =
# camera2flange, z = target2base, A X B = Z)

LIMITS = hchk.CellLimits()


def _cell(seed, n=12, sigma_rot=0.0, sigma_trans=0.0):
    return hsim.simulate_cell(np.random.default_rng(seed), n, sigma_rot, sigma_trans)


@settings(PROFILE, max_examples=12)
@given(SEEDS, st.integers(4, 20))
def test_noise_free_cell_closes_and_every_method_finds_the_truth(seed, n):
    """A simulated noise-free cell satisfies A X B = Z; its residuals vanish at the truth;
    OpenCV's closed forms (the ones not refused), the ML refinement and the chordal target
    mean all return the truth; the Cramer-Rao bound is symmetric positive definite."""
    cell = _cell(seed, n)
    a, b, x, z = cell.flange2base, cell.target2camera, cell.camera2flange, cell.target2base
    assert _finite(cell) and not cell.outliers.any()
    np.testing.assert_allclose(a @ x @ b, np.broadcast_to(z, a.shape), atol=1e-9)
    assert np.abs(hr.pose_residuals(a, b, x, z)).max() < 1e-9
    np.testing.assert_allclose(hr.target_in_world(a, b, x), z, atol=1e-9)
    forms = hr.closed_forms(a, b, ["Tsai", "Park", "Daniilidis"])
    for form in forms:
        if not form.refused:
            assert geo.translation_error(form.x, x) < 1e-6 and geo.rotation_error(form.x, x) < 1e-9
    est = hr.refine_ml(a, b, x @ _rigid([0.01, 0, 0], [1.0, 0, 0]), z, 1e-3, 0.1)
    assert _finite(est)
    assert geo.translation_error(est.value[0], x) < 1e-6 and geo.translation_error(est.value[1], z) < 1e-6
    crb = hr.handeye_crb(a, b, x, z, 1e-3, 0.1)
    np.testing.assert_allclose(crb, crb.T, atol=1e-12 * np.abs(crb).max())
    assert np.linalg.eigvalsh(crb).min() > 0.0


@settings(PROFILE, max_examples=10)
@given(SEEDS, st.floats(1e-4, 5e-3), st.floats(0.01, 1.0))
def test_robust_noise_estimate_recovers_the_simulated_noise(seed, sigma_rot, sigma_trans):
    """On residuals at the truth of a cell with 150 poses, the robust sigmas are within 25 % of
    the simulated ones, the scores are chi-square(6) (median within 25 % of 5.35), and the
    weights are 1 for the inliers of the Huber loss and in (0, 1]."""
    cell = _cell(seed, 150, sigma_rot, sigma_trans)
    res = hr.pose_residuals(cell.flange2base, cell.target2camera, cell.camera2flange, cell.target2base)
    s_r, s_t = hrob.robust_sigmas(res)
    assert s_r == pytest.approx(sigma_rot, rel=0.25) and s_t == pytest.approx(sigma_trans, rel=0.25)
    score = hrob.outlier_scores(res, sigma_rot, sigma_trans)
    assert np.median(score) == pytest.approx(5.348, rel=0.25)
    for loss in ("huber", "cauchy"):
        w = hrob.robust_weights(score, loss)
        assert np.all((w > 0) & (w <= 1))
    assert np.all(hrob.robust_weights(score, "huber")[np.sqrt(score / 6) <= 2.0] == 1.0)
    g_t, g_r = hr.robot_error_map(cell.flange2base, cell.camera2flange, cell.target2base)
    assert _finite(hrob.eiv_sigmas(res, g_t, g_r))


@PROFILE
@given(st.floats(1e-12, 0.5))
def test_outlier_limit_is_the_chi2_quantile(alpha):
    from scipy.stats import chi2

    assert hrob.outlier_limit(alpha) == pytest.approx(chi2.isf(alpha, 6), rel=1e-9)


@settings(PROFILE, max_examples=15)
@given(SEEDS, st.integers(3, 30), st.sampled_from(["eye_in_hand", "eye_to_hand"]), st.sampled_from(["mm", "cm", "m", "in"]), st.booleans(), st.booleans())
def test_prepare_poses_undoes_the_storage_forms(seed, n, setup, unit, robot_inverted, camera_inverted):
    """Poses stored inverted, in another unit or as an eye-to-hand cell come back as the same
    canonical poses."""
    cell = _cell(seed, n)
    a, b = cell.flange2base.copy(), cell.target2camera.copy()
    factor = hin.unit_factor("robot", unit)
    robot = geo.invert(a) if setup == "eye_to_hand" else a
    robot = geo.invert(robot) if robot_inverted else robot
    camera = geo.invert(b) if camera_inverted else b
    robot, camera = robot.copy(), camera.copy()
    robot[:, :3, 3] /= factor
    camera[:, :3, 3] /= factor
    convention = ("base2gripper" if robot_inverted else "gripper2base", "camera2target" if camera_inverted else "target2camera")
    prep = hin.prepare_poses(robot, camera, setup=setup, convention=convention, robot_unit=unit, camera_unit=unit)
    np.testing.assert_allclose(prep.a, a, atol=1e-9)
    np.testing.assert_allclose(prep.b, b, atol=1e-9)
    cond = hin.motion_conditioning(prep.a)
    assert cond.n_poses == n and 0.0 <= cond.max_rotation_deg <= 180.0
    assert _finite([cond.n_distinct, cond.max_rotation_deg, cond.axis_spread, cond.axis_spread_3])
    i, j = hin.motion_pairs(n)
    assert np.all(i < j) and len(set(zip(i.tolist(), j.tolist(), strict=True))) == len(i)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda c: hin.prepare_poses(c.flange2base, c.target2camera, setup="eye_on_wall"), r"unknown setup 'eye_on_wall'"),
        (lambda c: hin.prepare_poses(c.flange2base, c.target2camera, robot_unit="ft"), r"robot"),
        (lambda c: hin.prepare_poses(c.flange2base, c.target2camera, convention="gripper2world"), r"gripper2world"),
        (lambda c: hin.prepare_poses(c.flange2base[:5], c.target2camera), r"5 .*12|12 .*5"),
        (lambda c: hin.check_pose_array("robot poses", np.full((3, 4, 4), np.nan)), r"robot poses"),
        (lambda c: hin.check_pose_array("robot poses", np.zeros((3, 3, 3))), r"robot poses.*\(3, 3, 3\)"),
        (lambda c: hr.check_pose_weights([1.0, -1.0, 1.0], 3), r"-1"),
        (lambda c: hr.check_pose_weights([1.0, np.nan, 1.0], 3), r"nan"),
        (lambda c: hr.check_pose_weights([1.0, 1.0], 3), r"2.*3|3.*2"),
        (lambda c: hr.check_proper("X", np.full((4, 4), np.nan)), r"X"),
        (lambda c: hsim.simulate_cell(np.random.default_rng(0), 2), r"at least 3 poses; got 2"),
        (lambda c: axxb.check_rotation_diversity(c.flange2base, -1.0), r"min_rotation must be a positive angle in rad, got -1.0"),
        (lambda c: axxb.check_rotation_diversity(c.flange2base[:2], 0.1), r"flange poses of shape \(2, 4, 4\)"),
        (lambda c: base_to_base(c.flange2base, c.camera2flange, c.target2camera[:3], c.flange2base, c.camera2flange, c.target2camera), r"12 flange poses but 3 camera poses"),
        (lambda c: base_to_base(c.flange2base, c.camera2flange * [[2.0], [2.0], [2.0], [1.0]], c.target2camera, c.flange2base, c.camera2flange, c.target2camera), r"cam2flange rotation is not orthonormal \(max \|R\^T R - I\| = 3"),
        (lambda c: stationary_sensor_to_base(np.eye(4), np.eye(4), np.eye(4), np.full((4, 4), np.inf), np.eye(4)), r"non-finite value \(inf\)"),
        (lambda c: hplan.plan_poses(c.flange2base, c.camera2flange, c.target2base, 40, 1e-3, 0.1, [0.0, 0.0, 500.0]), r"40"),
        pytest.param(lambda c: hplan.plan_poses(c.flange2base, c.camera2flange, c.target2base, 6, -1e-3, 0.1, [0.0, 0.0, 500.0]), r"sigma_rot.*-0.001"),
        (lambda c: hplan.plan_poses(c.flange2base, c.camera2flange, c.target2base, 6, 1e-3, 0.1, [0.0, np.nan, 500.0]), r"tool|point"),
    ],
)
def test_handeye_helper_refusals_name_the_input_and_number(call, message):
    with pytest.raises(CalibrationError, match=message):
        call(CELL)


# helper kernels of the hand-eye fit (they take the checked poses of prepare_poses) refuse what
# they cannot compute, naming it


@pytest.mark.parametrize(
    "call, message",
    [
        pytest.param(lambda: hrob.outlier_limit(2.0), r"alpha.*2", id="outlier_limit-alpha_2_gives_nan"),
        pytest.param(lambda: hrob.robust_weights(np.array([1.0, 100.0]), "l2"), r"'l2'", id="robust_weights-unknown_loss_is_cauchy"),
        pytest.param(lambda: hrob.outlier_scores(np.ones((2, 6)), 0.0, 0.0), r"sigma.*0", id="outlier_scores-zero_sigma_gives_inf"),
        pytest.param(lambda: hrob.robust_sigmas(np.zeros((0, 6))), r"0 poses|empty", id="robust_sigmas-no_pose_divides_by_zero"),
        pytest.param(lambda: hr.pose_residuals(np.full((2, 4, 4), np.nan), np.tile(np.eye(4), (2, 1, 1)), np.eye(4), np.eye(4)), r"nan", id="pose_residuals-nan_passes_through"),
        pytest.param(lambda: hchk.check_cell(*np.tile(np.eye(4), (2, 3, 1, 1)), np.eye(4), np.zeros((3, 6)), None, LIMITS), r"weights", id="check_cell-weights_none_is_a_type_error"),
    ],
)
def test_handeye_kernels_refuse_what_they_cannot_compute(call, message):
    out = None
    try:
        out = call()
    except CalibrationError as exc:
        assert re.search(message, str(exc)), str(exc)
        return
    assert _finite(out), f"non-finite result {out!r}"
    raise AssertionError(f"accepted: {out!r}")


CELL = _cell(3)


@settings(PROFILE, max_examples=15)
@given(SEEDS, st.integers(3, 12), _arrays((3,)))
def test_pose_plan_improves_with_every_pose(seed, n_poses, tool):
    """The planned poses are distinct candidates; the predicted RMS error of the tool point
    never rises with another pose and equals point_rms of the chosen poses' information."""
    cell = _cell(seed, 14)
    plan = _result(hplan.plan_poses, cell.flange2base, cell.camera2flange, cell.target2base, n_poses, 1e-3, 0.1, tool)
    assert plan is not None
    assert len(set(plan.chosen.tolist())) == n_poses
    curve = plan.predicted_curve_mm
    assert np.all(np.diff(curve) <= 1e-9 * curve[:-1])
    info = hplan.pose_information(cell.flange2base, cell.camera2flange, cell.target2base, 1e-3, 0.1)
    pj = hplan.point_jacobian(cell.camera2flange, tool)
    assert hplan.point_rms(info[plan.chosen].sum(axis=0), pj) == pytest.approx(plan.predicted_rms_mm, rel=1e-9)


@PROFILE
@given(_arrays((3,), st.floats(-0.5, 0.5)), _arrays((3,)), _arrays((3,)))
def test_point_jacobian_is_the_derivative(rotvec, translation, point):
    """point_jacobian is the derivative of X p by the public [theta_X, t_X] (a rotation
    right-multiplied to R_X, the translation), and zero in Z's columns."""
    x = _rigid(rotvec, translation)
    pj = hplan.point_jacobian(x, point)
    eps = 1e-6
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        moved = geo.apply(geo.make_transform(x[:3, :3] @ geo.rotvec_to_matrix(d), x[:3, 3]), point)
        np.testing.assert_allclose((moved - geo.apply(x, point)) / eps, pj[:, k], atol=1e-5 * (1 + np.abs(point).max()))
    np.testing.assert_allclose(pj[:, 3:6], np.eye(3), atol=1e-12)
    assert np.all(pj[:, 6:] == 0.0)


@settings(PROFILE, max_examples=10)
@given(SEEDS, st.floats(1e-4, 2e-3), st.floats(0.01, 0.3))
def test_cell_checks_and_diagnosis_pass_a_good_cell(seed, sigma_rot, sigma_trans):
    """A simulated cell within the limits passes check_cell; its motions agree (the angle
    disagreement is at the noise level); the transposed readings diagnose does not beat the
    cell as given; a reading's score is finite or inf (none fits)."""
    cell = _cell(seed, 20, sigma_rot, sigma_trans)
    a, b, x, z = cell.flange2base, cell.target2camera, cell.camera2flange, cell.target2base
    res = hr.pose_residuals(a, b, x, z)
    check = hchk.check_cell(a, b, x, res, np.ones(len(a)), LIMITS)
    assert _finite([check.camera_distance_mm, check.robot_distance_mm, check.noise_ratio]) and not check.failures
    assert hdiag.motion_angle_disagreement(a, b) < 20 * math.degrees(sigma_rot)  # deg
    score = hdiag.reading_score(a, b, LIMITS)
    assert math.isfinite(score) and score < 1.0
    for ra, rb in hdiag.readings(a, b).values():
        s = hdiag.reading_score(ra, rb, LIMITS)
        assert s == math.inf or s >= 0.0
    step = hchk.series_break(a, b, x, hr.pose_scale(b))
    assert _finite(step)


@PROFILE
@given(st.integers(4, 12).flatmap(lambda n: st.tuples(_poses(n), _poses(n))))
def test_handeye_kernels_on_random_poses_are_finite(data):
    """The kernels on any finite rigid poses: finite residuals, scores, weights, scale,
    subsets and motion angles."""
    a, b = data
    x = z = np.eye(4)
    res = hr.pose_residuals(a, b, x, z)
    assert _finite(res) and _finite(hr.residual_score(res, hr.pose_scale(b))) and hr.pose_scale(b) >= 1e-9
    sub = hr.spread_subset(a, 3)
    assert len(sub) <= 3 and np.all(np.diff(sub) > 0)
    assert _finite(hdiag.motion_angle_disagreement(a, b))
    assert _finite(hrob.robust_sigmas(res))
    assert _finite(geo.so3_log(a[:, :3, :3])) and np.allclose(geo.so3_log(a[:, :3, :3]), geo.matrix_to_rotvec(a[:, :3, :3]), atol=1e-7)


@settings(PROFILE, max_examples=10)
@given(SEEDS, st.integers(4, 10))
def test_sphere_handeye_steps_known_answers(seed, n):
    """The two steps of the fixed-sphere hand-eye on noise-free data: R_F from translations,
    T_F from rotations, and the sphere centre in base, each the truth."""
    rng = np.random.default_rng(seed)
    s2f = _rigid(rng.uniform(-0.5, 0.5, 3), rng.uniform(-100, 100, 3))
    x_b = np.array([1000.0, 350.0, 0.0])
    base = geo.euler_zyx_to_matrix(20.0, 170.0, 5.0)
    trans = geo.make_transform(np.broadcast_to(base, (n, 3, 3)), [900.0, 300.0, 700.0] + rng.uniform(-30, 30, (n, 3)))
    rot = geo.make_transform(base @ geo.rotvec_to_matrix(rng.normal(0, 0.3, (n, 3))), [900.0, 300.0, 700.0] + rng.uniform(-30, 30, (n, 3)))

    def centres(f2b):
        s2b = f2b @ s2f
        return np.einsum("nji,nj->ni", s2b[:, :3, :3], x_b - s2b[:, :3, 3])

    r_f = sphere.rotation_from_translations(trans, centres(trans))
    np.testing.assert_allclose(r_f, s2f[:3, :3], atol=1e-9)
    t_f, _ = sphere.translation_from_rotations(rot, centres(rot), r_f)
    np.testing.assert_allclose(t_f, s2f[:3, 3], atol=1e-6)
    np.testing.assert_allclose(sphere.sphere_centre_in_base(rot, centres(rot), s2f), x_b, atol=1e-9)
    w2c = geo.invert(rot @ s2f)  # the base frame located by the camera at each pose
    np.testing.assert_allclose(base_to_base(rot, s2f, w2c, trans, s2f, geo.invert(trans @ s2f)), np.eye(4), atol=1e-9)


# ----------------------------------------------------------------------------------------------
# models.sensors and models.targets

CAMERAS = st.builds(
    PinholeCamera,
    fx=st.floats(100.0, 5000.0), fy=st.floats(100.0, 5000.0), cx=st.floats(0.0, 1000.0), cy=st.floats(0.0, 1000.0),
    width=st.just(1280), height=st.just(1024),
    dist=st.sampled_from([(), (-0.1, 0.02, 0.0, 0.0), (0.05, -0.01, 1e-4, -1e-4, 0.001)]),
)


@PROFILE
@given(CAMERAS, _arrays((6, 3), st.floats(-1.0, 1.0)), st.floats(100.0, 3000.0))
def test_camera_project_and_normalise_are_inverse(camera, xy, depth):
    """Points in front of the camera project to finite pixels; normalise takes them back to
    x / z, y / z (OpenCV's undistortion inverts its distortion); in_image agrees with the
    image bounds; the ideal camera's projection is K p / z."""
    p = np.column_stack([xy[:, :2] * 0.4 * depth, np.full(6, depth)])
    uv = camera.project(p)
    assert _finite(uv)
    np.testing.assert_allclose(camera.normalise(uv), p[:, :2] / p[:, 2:], atol=1e-7)
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= 1279.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= 1023.5)
    np.testing.assert_array_equal(camera.in_image(uv), inside)
    if not camera.distorted:
        q = p @ camera.K.T
        np.testing.assert_allclose(uv, q[:, :2] / q[:, 2:], rtol=1e-12)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: PinholeCamera(fx=math.nan, fy=800.0, cx=320.0, cy=240.0, width=640, height=480), r"camera parameters must be finite; got \[nan"),
        (lambda: PinholeCamera(fx=-800.0, fy=800.0, cx=320.0, cy=240.0, width=640, height=480), r"focal lengths must be positive; got -800.0, 800.0 px"),
        (lambda: PinholeCamera(fx=800.0, fy=800.0, cx=320.0, cy=240.0, width=0, height=480), r"image size must be positive; got 0 x 480"),
        (lambda: PinholeCamera(fx=800.0, fy=800.0, cx=320.0, cy=240.0, width=640, height=480, dist=(0.1, 0.2, 0.3)), r"distortion must be 0, 4, 5, 8, 12 or 14 finite OpenCV coefficients; got \(0.1, 0.2, 0.3\)"),
        (lambda: CAM.project([[0.0, 0.0, -5.0]]), r"target behind the camera: point 0 at z = -5.0 mm"),
        (lambda: CAM.project([[0.0, math.inf, 5.0]]), r"points_cam holds a non-finite value \(inf\)"),
        (lambda: CAM.observe(np.eye(4), [[0.0, 0.0, 500.0]], -1.0, np.random.default_rng(0)), r"sigma_px must be >= 0; got -1.0"),
        (lambda: CAM.observe(np.eye(4), [[5000.0, 0.0, 500.0]], 0.1, np.random.default_rng(0)), r"1 of 1 points fall outside the 640 x 480 image \(points 0; point 0 at u = 8320.0, v = 240.0 px\)"),
        (lambda: sensors.stripe_offset_recommended(-3.0), r"sphere radius must be positive; got -3.0 mm"),
        (lambda: sensors.LineLaserSensor(sigma_point_mm=-0.1), r"sigma_point_mm must be >= 0; got -0.1"),
        (lambda: sensors.LineLaserSensor(n_points=2), r"a circle fit needs at least 3 points; got 2"),
        (lambda: sensors.LineLaserSensor(arc_half_angle_deg=200.0), r"arc_half_angle_deg must be in \(0, 180\]; got 200.0"),
        (lambda: sensors.LineLaserSensor(side=0), r"side must be \+1 or -1; got 0"),
        (lambda: LASER.measure_sphere_centre([0.0, 3.0, -100.0], 12.7, np.random.default_rng(0)), r"sphere centre is behind the sensor: z = -100.0 mm at shot 0"),
        (lambda: LASER.measure_sphere_centre([0.0, 13.0, 100.0], 12.7, np.random.default_rng(0)), r"laser plane misses the sphere: \|y\| = 13.0 mm >= radius 12.7 mm"),
        (lambda: LASER.measure_sphere_centre([0.0, 3.0, 5.0], 12.7, np.random.default_rng(0)), r"the sensor is inside the sphere at shot 0"),
        (lambda: LASER.centre_covariance([0.0, 3.0, 100.0], math.nan), r"sphere radius must be positive; got nan mm"),
        (lambda: targets.Sphere(radius_mm=0.0), r"sphere radius must be positive; got 0.0 mm"),
        (lambda: targets.Sphere(centre=[0.0, math.nan, 0.0]), r"centre holds a non-finite value \(nan\) at index \(1,\)"),
        (lambda: targets.HoleTarget(rows=1), r"hole target needs at least 2 x 2 holes; got 1 x 7"),
        (lambda: targets.HoleTarget(pitch_mm=-10.0), r"hole target pitch_mm must be positive; got -10.0"),
        (lambda: targets.HoleTarget(hole_tolerance_mm=6.0), r"hole_tolerance_mm must be in \[0, pitch/2\); got 6.0 \(pitch 10.0\)"),
        (lambda: targets.circle_image_centres(CAM.K, [[0.0, 0.0, 5.0]], [[1.0, 0.0, 0.0]], 10.0), r"circle 0 reaches depth -5 mm: a circle must lie wholly in front of the camera"),
        (lambda: targets.circle_image_centres(CAM.K, [[0.0, 0.0, 500.0]], [[0.0, 0.0, 0.0]], 10.0), r"circle normal 0 is zero"),
        (lambda: targets.circle_image_centres(CAM.K, [[0.0, 0.0, 500.0]], [[0.0, 0.0, 1.0]], -1.0), r"circle radius -1.0 mm must be finite and >= 0"),
        (lambda: targets.circle_image_centres(CAM.K, [[0.0, 0.0, 500.0]], [[1.0, 0.0, 0.0]], 1.0), r"circle 0 is seen edge-on"),
        (lambda: targets.circle_centre_bias(CAM.K, [[0.0, 0.0, 500.0]], [[0.0, math.nan, 1.0]], 1.0), r"circle normals holds a non-finite value \(nan\)"),
    ],
)
def test_sensor_and_target_refusals_name_the_input_and_number(call, message):
    with pytest.raises(CalibrationError, match=message):
        call()


CAM = PinholeCamera(fx=800.0, fy=800.0, cx=320.0, cy=240.0, width=640, height=480)
LASER = sensors.LineLaserSensor()


@PROFILE
@given(SEEDS, _arrays((5, 3), st.floats(-1.0, 1.0)), st.floats(5.0, 30.0), st.sampled_from([0.0, 0.02]))
def test_laser_measures_sphere_centres(seed, offsets, radius, sigma):
    """Centres the sensor can see come back within 6 standard deviations of the linearised
    covariance (exactly, to 1e-9 mm, without noise); every covariance is symmetric positive
    semi-definite; unmeasurable geometry is refused."""
    laser = sensors.LineLaserSensor(sigma_point_mm=sigma)
    c = np.column_stack([offsets[:, 0] * 50.0, radius * (0.1 + 0.4 * np.abs(offsets[:, 1])), 150.0 + offsets[:, 2] * 50.0])
    got = _result(laser.measure_sphere_centre, c, radius, np.random.default_rng(seed))
    cov = _result(laser.centre_covariance, c, radius)
    assert got is not None and cov is not None
    for k in range(len(c)):
        np.testing.assert_allclose(cov[k], cov[k].T, atol=1e-15)
        assert np.linalg.eigvalsh(cov[k]).min() >= -1e-15
    if sigma == 0.0:
        np.testing.assert_allclose(got, c, atol=1e-9)
    else:
        std = np.sqrt(np.einsum("nii->ni", cov))
        assert np.all(np.abs(got - c) <= 6 * std + 1e-9)
    assert sensors.stripe_offset_recommended(radius) == radius / 4


@PROFILE
@given(_arrays((4, 3), st.floats(-1.0, 1.0)), _arrays((4, 3), st.floats(-1.0, 1.0)), st.floats(0.5, 20.0))
def test_circle_image_centres_against_opencv_ellipse_fit(xy, normal, radius):
    """The exact ellipse centre of a projected circle agrees with cv2.fitEllipse on 720
    projected points of its rim; a circle facing the camera has no bias; no circle gives a
    non-finite centre."""
    centres = np.column_stack([xy[:, :2] * 100.0, 400.0 + 100.0 * xy[:, 2]])
    n = normal + [0.0, 0.0, 2.0]  # tilted at most about 40 deg from the optical axis
    got = _result(targets.circle_image_centres, CAM.K, centres, n, radius)
    assert got is not None
    unit = n / np.linalg.norm(n, axis=1, keepdims=True)
    angles = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    for k in range(4):
        e1 = np.cross(unit[k], [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(unit[k], e1)
        rim = centres[k] + radius * (np.outer(np.cos(angles), e1) + np.outer(np.sin(angles), e2))
        (u, v), _, _ = cv2.fitEllipse(CAM.project(rim).astype(np.float32))
        np.testing.assert_allclose(got[k], [u, v], atol=2e-3)
    facing = targets.circle_centre_bias(CAM.K, centres, np.tile([0.0, 0.0, 1.0], (4, 1)), radius)
    np.testing.assert_allclose(facing, 0.0, atol=1e-9)
    np.testing.assert_array_equal(targets.circle_centre_bias(CAM.K, centres, n, 0.0), 0.0)


@PROFILE
@given(SEEDS, st.integers(2, 7), st.integers(2, 9), st.floats(1.0, 50.0), st.floats(0.5, 20.0), st.floats(0.0, 0.49))
def test_hole_target_faces_and_manufacturing(seed, rows, cols, pitch, thickness, tol_fraction):
    """back2front maps the back points onto the front points' exits; a made target stays
    within its tolerance of the CAD positions; front2back inverts back2front."""
    t = targets.HoleTarget(rows=rows, cols=cols, pitch_mm=pitch, thickness_mm=thickness, hole_tolerance_mm=tol_fraction * pitch)
    assert t.n_holes == rows * cols == len(t.front_points())
    exits = geo.apply(t.back2front(), t.back_points())
    np.testing.assert_allclose(exits[:, :2], t.front_points()[:, :2], atol=1e-12)
    np.testing.assert_allclose(exits[:, 2], -thickness, atol=1e-12)
    np.testing.assert_allclose(t.front2back() @ t.back2front(), np.eye(4), atol=1e-12)
    made = t.manufactured(np.random.default_rng(seed))
    assert _finite(made)
    assert np.abs(made.front_points - t.front_points()).max() <= t.hole_tolerance_mm + 1e-12
    exits = geo.apply(made.back2front, made.back_points)
    np.testing.assert_allclose(exits[:, 2], -thickness, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# the rendering of models.optics and models.exposure

IDEAL = PinholeCamera(fx=2000.0, fy=2000.0, cx=640.0, cy=512.0, width=1280, height=1024)


@PROFILE
@given(_arrays((3,), st.floats(-1.0, 1.0)), st.floats(400.0, 1200.0), st.floats(2.5, 6.0))
def test_rendered_facing_dot_is_centred_on_its_projection(xy, depth, radius):
    """A dot facing an ideal camera renders as a disc: its intensity-weighted centroid (after
    removing the cos^4 fall-off) is the projected centre within 0.02 px, its area pi r^2 within
    3 % (radii from 4 px: the one-pixel anti-aliasing ramp biases smaller discs more); values in
    [0, 1]; render_dots and render_rois give each dot render_dot's pixels."""
    centre = np.array([xy[0] * 0.1 * depth, xy[1] * 0.1 * depth, depth])
    uv = IDEAL.project(centre[None])[0]
    r_px = 2000.0 * radius / depth
    origin, shape = optics.roi_around(uv, r_px, 6.0, 1280, 1024)
    img = optics.render_dot(IDEAL.K, IDEAL.dist_coeffs, centre, [0.0, 0.0, -1.0], radius, origin, shape)
    assert img.dtype == np.float32 and img.min() >= 0.0 and img.max() <= 1.0
    rows, cols = np.mgrid[: shape[0], : shape[1]]
    x, y = (cols + origin[0] - 640.0) / 2000.0, (rows + origin[1] - 512.0) / 2000.0
    cover = img * (1.0 + x**2 + y**2) ** 2
    total = cover.sum()
    np.testing.assert_allclose([(cover * (cols + origin[0])).sum() / total, (cover * (rows + origin[1])).sum() / total], uv, atol=0.02)
    assert total == pytest.approx(math.pi * r_px**2, rel=0.03)
    both = optics.render_dots(IDEAL.K, IDEAL.dist_coeffs, np.stack([centre, centre]), np.tile([0.0, 0.0, -1.0], (2, 1)), radius, np.stack([origin, origin]), shape)
    np.testing.assert_array_equal(both[1], img)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"centre": [0.0, math.nan, 800.0]}, r"dot centres: row 0 is not finite \(\[0.0, nan, 800.0\]\)"),
        ({"centre": [0.0, 0.0, -800.0]}, r"dot 0 is not in front of the camera: z = -800 mm"),
        ({"normal": [0.0, 0.0, 0.0]}, r"dot normal 0 is zero"),
        ({"normal": [0.0, math.inf, 1.0]}, r"dot normals: row 0 is not finite"),
        ({"radius": -2.0}, r"dot radius -2.0 mm must be finite and > 0"),
        ({"k": np.diag([math.nan, 2000.0, 1.0])}, r"camera matrix must be a finite \(3, 3\) with fx, fy > 0"),
        ({"dist": np.array([math.nan, 0.0, 0.0, 0.0])}, r"distortion coefficients must be finite; got \[nan"),
        ({"shape": (0, 9)}, r"ROI shape \(0, 9\) must have at least one row and column"),
    ],
)
def test_render_refusals_name_the_input_and_number(change, message):
    args = {"k": IDEAL.K, "dist": np.zeros(4), "centre": [0.0, 0.0, 800.0], "normal": [0.0, 0.0, -1.0], "radius": 2.0, "origin": (630, 502), "shape": (21, 21)} | change
    with pytest.raises(CalibrationError, match=message):
        optics.render_dot(args["k"], args["dist"], args["centre"], args["normal"], args["radius"], args["origin"], args["shape"])


@PROFILE
@given(hnp.arrays(np.float32, (12, 12), elements=st.floats(0.0, 1.0, width=32)), st.floats(0.0, 6.0), st.sampled_from([1.0, -1.0]), _arrays((2,), st.floats(-2.0, 2.0)), st.floats(0.2, 5.0))
def test_defocus_and_vignetted_blur(image, delta, side, rim_centre, rim_radius):
    """Blurring keeps an image finite, in the range of its pixels; defocus is OpenCV's
    Gaussian; a kernel sums to 1 and without a cut is cv2.getGaussianKernel's outer product;
    with a rim that clears the pupil the vignetted blur is the plain one."""
    out = optics.defocus(image, delta)
    assert _finite(out) and out.min() >= image.min() - 1e-6 and out.max() <= image.max() + 1e-6
    if delta >= 0.05:
        np.testing.assert_array_equal(out, cv2.GaussianBlur(image, (0, 0), sigmaX=delta, borderType=cv2.BORDER_REPLICATE))
        k = optics.defocus_kernel(delta)
        g = cv2.getGaussianKernel(k.shape[0], delta, cv2.CV_64F)[:, 0]
        np.testing.assert_allclose(k, np.outer(g, g) / np.outer(g, g).sum(), atol=1e-7)
        cut = _result(optics.defocus_kernel, delta, side, rim_centre, rim_radius)
        if cut is not None:
            assert cut.sum() == pytest.approx(1.0, abs=1e-5) and cut.min() >= 0.0
        np.testing.assert_array_equal(optics.defocus_vignetted(image, delta, side, (0.0, 0.0), 1e3), out)
    assert _finite(_result(optics.defocus_vignetted, image, delta, side, rim_centre, rim_radius))


@PROFILE
@given(_arrays((2,), st.floats(-0.5, 0.5)), st.floats(1.4, 22.0), st.floats(5.0, 100.0), st.floats(1.0, 50.0), st.floats(-30.0, 30.0), st.floats(100.0, 1e4))
def test_rim_shadow_known_answers(t, f_number, focal, rim_radius, rim_distance, depth):
    """rim_shadow's disc: centre -L t / (a (1 - L/Z)), radius R / (a (1 - L/Z)), a = f / 2F;
    on the axis its centre is 0; far away (Z = inf) the depth drops out."""
    a = focal / (2.0 * f_number)
    centre, radius = optics.rim_shadow(t, f_number, focal, rim_radius, rim_distance, depth)
    scale = a * (1.0 - rim_distance / depth)
    np.testing.assert_allclose(centre, -rim_distance * t / scale, rtol=1e-12, atol=1e-300)
    assert radius == pytest.approx(rim_radius / scale, rel=1e-12)
    np.testing.assert_array_equal(optics.rim_shadow([0.0, 0.0], f_number, focal, rim_radius, rim_distance, depth)[0], 0.0)
    far_c, far_r = optics.rim_shadow(t, f_number, focal, rim_radius, rim_distance)
    assert far_r == pytest.approx(rim_radius / a, rel=1e-12)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: optics.roi_around([math.nan, 3.0], 5.0, 2.0, 640, 480), r"dot centre \[nan  3.\] is not a finite image point"),
        (lambda: optics.roi_around([3.0, 3.0], 5.0, 2.0, 640, 480), r"dot at \(3.0, 3.0\) px with radius 5.0 px and margin 2.0 px touches the border of the 640 x 480 image"),
        (lambda: optics.roi_around([300.0, 300.0], -5.0, 2.0, 640, 480), r"dot radius -5.0 px must be > 0"),
        (lambda: optics.defocus(np.zeros((4, 4)), -1.0), r"circle-of-confusion radius -1.0 px must be finite, >= 0"),
        (lambda: optics.defocus(np.full((4, 4), np.nan), 1.0), r"the \(4, 4\) image to blur has NaN or inf pixels"),
        (lambda: optics.defocus_kernel(500.0), r"circle-of-confusion radius 500.0 px must be finite, >= 0 and <= 200.0"),
        (lambda: optics.defocus_kernel(0.0), r"circle-of-confusion radius 0.0 px must be > 0"),
        (lambda: optics.defocus_kernel(5.0, side=0.5), r"side of the focus 0.5 must be \+1"),
        (lambda: optics.defocus_kernel(5.0, rim_centre=(0.0, math.nan)), r"rim centre \(0.0, nan\) must be two finite pupil coordinates"),
        (lambda: optics.defocus_kernel(5.0, rim_radius=-1.0), r"rim radius -1.0 \(pupil radii\) must be > 0"),
        (lambda: optics.defocus_kernel(5.0, rim_centre=(10.0, 0.0), rim_radius=1.0), r"the rim blocks every ray of the blur spot"),
        (lambda: optics.rim_shadow([0.1, 0.1], -2.0, 50.0, 10.0, 5.0), r"F -2.0, focal length 50.0 mm and rim radius 10.0 mm must be finite and positive"),
        (lambda: optics.rim_shadow([0.1, 0.1], 2.0, 50.0, 10.0, 5.0, 3.0), r"object depth 3.0 mm must lie beyond the rim \(5.0 mm\)"),
        (lambda: optics.rim_shadow([0.1, math.inf], 2.0, 50.0, 10.0, 5.0), r"field direction of shape \(2,\) must be finite"),
        (lambda: exposure.expose_and_fuse(np.zeros((4, 4)), [], 0.5, 0.1, 1.0, 10.0, np.random.default_rng(0)), r"fusion needs at least one exposure time"),
        (lambda: exposure.expose_and_fuse(np.zeros((4, 4)), [10.0, -1.0], 0.5, 0.1, 1.0, 10.0, np.random.default_rng(0)), r"exposure_ms = -1.0 must be a finite number > 0"),
        (lambda: exposure.expose_and_fuse(np.zeros((4, 4)), [10.0], 0.5, 0.1, 1.0, 10.0, np.random.default_rng(0), bits=17), r"bit depth bits = 17 must be an integer from 1 to 16"),
    ],
)
def test_optics_refusals_name_the_input_and_number(call, message):
    with pytest.raises(CalibrationError, match=message):
        call()


@PROFILE
@given(SEEDS, hnp.arrays(np.float64, (2, 6, 6), elements=st.floats(0.0, 1.0, width=64)), st.lists(st.floats(1.0, 400.0), min_size=1, max_size=3), st.floats(0.0, 2.0), st.floats(0.0, 0.5), st.floats(0.0, 3.0), st.sampled_from([1.0, 30.0, math.inf]), st.sampled_from([8, 12]))
def test_expose_and_fuse_is_expose_then_fuse(seed, radiance, times, peak, background, read_noise, gain, bits):
    """expose_and_fuse gives the numbers of expose at each time followed by fuse_exposures
    (the same draws in the same order), finite, in [0, 1]."""
    args = (peak, background, read_noise, gain)
    fused = exposure.expose_and_fuse(radiance, times, *args, np.random.default_rng(seed), bits)
    assert fused.dtype == np.float32 and _finite(fused) and fused.min() >= 0.0 and fused.max() <= 1.0
    rng = np.random.default_rng(seed)
    stack = radiance.reshape(-1, 6, 6)
    shots = [exposure.expose(stack, t, *args, rng, bits) for t in times]
    ref = np.stack([exposure.fuse_exposures([s[i] for s in shots]) for i in range(len(stack))])
    np.testing.assert_allclose(fused, ref, atol=1e-6)
    assert _finite(exposure.filled(0.25, (3, 2))) and np.all(exposure.filled(0.25, (3, 2)) == np.float32(0.25))


# ----------------------------------------------------------------------------------------------
# models.urdf

_JOINT = """  <joint name="j{i}" type="{kind}"><parent link="l{p}"/><child link="l{i}"/>
    <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
"""


def _urdf_text(joints, flange_xyz=(0.0, 0.0, 0.1), kind="revolute") -> str:
    """A URDF of six joints ``(xyz m, rpy rad, axis)`` and a fixed flange frame ``l7``."""
    words = " ".join
    links = "".join(f'  <link name="l{i}"/>\n' for i in range(8))
    body = "".join(
        _JOINT.format(i=i + 1, p=i, kind=kind if i == 2 else "revolute", xyz=words(map(str, xyz)), rpy=words(map(str, rpy)), axis=words(map(str, axis)))
        for i, (xyz, rpy, axis) in enumerate(joints)
    )
    body += f'  <joint name="flange" type="fixed"><parent link="l6"/><child link="l7"/><origin xyz="{words(map(str, flange_xyz))}" rpy="0 0 0"/></joint>\n'
    return f'<?xml version="1.0"?>\n<robot name="drawn arm">\n{links}{body}</robot>\n'


_AXES = st.sampled_from([(0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)])
_JOINTS = st.lists(st.tuples(st.tuples(*[st.floats(-0.5, 0.5)] * 3), st.tuples(*[st.floats(-3.1, 3.1)] * 3), _AXES), min_size=6, max_size=6)


@settings(PROFILE, max_examples=20)
@given(_JOINTS, _arrays((6,), st.floats(-3.0, 3.0)))
def test_urdf_table_reproduces_pinocchio(tmp_path_factory, joints, q):
    """A random 6R arm read from its URDF gives a DH table whose forward kinematics is
    Pinocchio's flange pose of the same file (mm) at random joint angles, finite; or it is
    refused naming the difference (axes nearly parallel, where DH parameters are ill-conditioned)."""
    path = tmp_path_factory.mktemp("urdf") / "arm.urdf"
    path.write_text(_urdf_text(joints))
    try:
        robot = urdf.robot_from_urdf(path, flange="l7")
    except CalibrationError as exc:  # axes nearly (not exactly) parallel: DH is ill-conditioned
        assert "the DH table derived from the URDF differs from it by" in str(exc)
        return
    _agrees_with_pinocchio(robot, path, q)


@pytest.mark.parametrize("seed", range(6))
def test_urdf_of_drawn_arms_is_read(tmp_path, seed):
    """Arms drawn at random (no two axes nearly parallel) are read, and agree with Pinocchio."""
    rng = np.random.default_rng(seed)
    axes = [(0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0)]
    joints = [(tuple(rng.uniform(-0.5, 0.5, 3)), tuple(rng.uniform(-3.1, 3.1, 3)), axes[rng.integers(3)]) for _ in range(6)]
    (tmp_path / "arm.urdf").write_text(_urdf_text(joints))
    robot = urdf.robot_from_urdf(tmp_path / "arm.urdf", flange="l7")
    _agrees_with_pinocchio(robot, tmp_path / "arm.urdf", rng.uniform(-3, 3, 6))


def _agrees_with_pinocchio(robot, path, q):
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    ref = np.array(data.oMf[model.getFrameId("l7")].homogeneous)
    ref[:3, 3] *= 1000.0
    fk = robot.fk(q)
    assert _finite(fk)
    np.testing.assert_allclose(fk, ref, atol=1e-6)


def test_urdf_refusals_name_the_file_and_fault(tmp_path):
    joints = [((0.0, 0.0, 0.3), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))] * 6
    with pytest.raises(CalibrationError, match=r"arm.urdf: no such URDF file"):
        urdf.robot_from_urdf(tmp_path / "arm.urdf")
    (tmp_path / "arm.urdf").write_text(_urdf_text(joints, kind="prismatic"))
    with pytest.raises(CalibrationError, match=r"arm.urdf: the chain needs revolute joints of one degree of freedom each; found \[.*JointModelP"):
        urdf.robot_from_urdf(tmp_path / "arm.urdf")
    (tmp_path / "arm.urdf").write_text(_urdf_text(joints))
    with pytest.raises(CalibrationError, match=r"arm.urdf: no frame 'l9' for the flange"):
        urdf.robot_from_urdf(tmp_path / "arm.urdf", flange="l9")
    (tmp_path / "arm.urdf").write_text("<robot name='x'><link name='a'/>")
    with pytest.raises(CalibrationError, match=r"arm.urdf: not a readable URDF"):
        urdf.robot_from_urdf(tmp_path / "arm.urdf")
    (tmp_path / "arm.urdf").write_text(_urdf_text([((0.0, math.nan, 0.3), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))] * 6))
    with pytest.raises(CalibrationError, match=r"arm.urdf: not a readable URDF"):  # urdfdom's reason goes to stderr
        urdf.robot_from_urdf(tmp_path / "arm.urdf")


# ----------------------------------------------------------------------------------------------
# the one stereo triangulation (models.stereo.StereoRig.triangulate) against OpenCV

DISTORTED = dataclasses.replace(IDEAL, dist=(-0.08, 0.01, 1e-4, -2e-4, 0.0))


@PROFILE
@given(_arrays((8, 3), st.floats(-1.0, 1.0)), _arrays((2, 8, 2), st.floats(-0.5, 0.5)), st.floats(100.0, 400.0), st.floats(600.0, 1200.0), st.sampled_from([IDEAL, DISTORTED]))
def test_rig_triangulation_is_opencvs(xyz, noise, baseline, convergence, camera):
    """Triangulated points are OpenCV's: cv2.undistortPoints of each image, then
    cv2.triangulatePoints with [I | 0] and [R | t], to 1e-9 mm for an ideal rig and 1e-4 mm
    with distortion (cv2.undistortPoints iterates less than the rig's undistortPointsIter);
    for an ideal rig also cv2.triangulatePoints on the pixel projection matrices K [R | t],
    to 1e-6 mm; noise-free points come back to 1e-6 mm; binocular.triangulate gives the
    same numbers."""
    rig = stereo_rig(camera, baseline, convergence)
    p = xyz * [100.0, 100.0, 100.0] + [0.0, 0.0, convergence]
    ul, ur = rig.project(p)
    ul, ur = ul + noise[0], ur + noise[1]
    got = rig.triangulate(ul, ur)
    assert _finite(got)
    xl = cv2.undistortPoints(ul.reshape(-1, 1, 2), camera.K, camera.dist_coeffs).reshape(-1, 2)
    xr = cv2.undistortPoints(ur.reshape(-1, 1, 2), camera.K, camera.dist_coeffs).reshape(-1, 2)
    h = cv2.triangulatePoints(np.eye(4)[:3], rig.left2right[:3], xl.T.copy(), xr.T.copy())
    np.testing.assert_allclose(got, (h[:3] / h[3]).T, atol=1e-4 if camera.distorted else 1e-9)
    if not camera.distorted:
        h = cv2.triangulatePoints(camera.K @ np.eye(4)[:3], camera.K @ rig.left2right[:3], ul.T.copy(), ur.T.copy())
        np.testing.assert_allclose(got, (h[:3] / h[3]).T, atol=1e-6)
    np.testing.assert_allclose(rig.triangulate(*rig.project(p)), p, atol=1e-6)
    np.testing.assert_array_equal(bino.triangulate(rig, ul, ur, tol_mm=10.0), got)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda r: r.triangulate([[640.0, math.nan]], [[600.0, 512.0]]), r"uv_left holds a non-finite value \(nan\) at index \(0, 1\)"),
        (lambda r: r.triangulate([[640.0, 512.0]], [[600.0, 512.0], [1.0, 2.0]]), r"uv_right has shape \(2, 2\); expected \(1, 2\)"),
        # the right ray along R e_z, the left ray e_z: parallel, a point at infinity
        (lambda r: r.triangulate_normalised(np.zeros((1, 2)), r.left2right[None, :2, 2] / r.left2right[2, 2]), r"point 0 cannot be triangulated: its two rays are parallel \(homogeneous scale 0\)"),
    ],
)
def test_triangulation_refusals_name_the_input_and_number(call, message):
    rig = stereo_rig(IDEAL, 300.0, 850.0)
    with pytest.raises(CalibrationError, match=message):
        call(rig)
