"""Rigid-transform helpers of calstudy.core.geometry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calstudy import CalibrationError
from calstudy.core import geometry as geo


def test_mean_transform_of_equal_and_nearby_transforms():
    rng = np.random.default_rng(1)
    t = geo.make_transform(geo.random_rotation(rng), rng.uniform(-100, 100, 3))
    np.testing.assert_allclose(geo.mean_transform(np.stack([t, t, t])), t, atol=1e-12)
    # two rotations +-a about one axis average to the middle one; translations to their mean
    a = geo.make_transform(geo.rotvec_to_matrix([0.0, 0.0, 0.1]), [1.0, 0.0, 0.0])
    b = geo.make_transform(geo.rotvec_to_matrix([0.0, 0.0, -0.1]), [3.0, 2.0, 0.0])
    np.testing.assert_allclose(
        geo.mean_transform(np.stack([a, b])),
        geo.make_transform(np.eye(3), [2.0, 1.0, 0.0]),
        atol=1e-12,
    )


def test_mean_transform_rejects_non_rigid():
    bad = np.tile(np.eye(4), (2, 1, 1))
    bad[1, 0, 0] = 2.0
    with pytest.raises(CalibrationError, match="not orthonormal"):
        geo.mean_transform(bad)


def _full_check_passes(t: np.ndarray, tol: float) -> bool:
    # the array path of check_transform, without the single-matrix shortcut
    try:
        geo.check_transform("t", t[None], tol)
    except CalibrationError:
        return False
    return True


@given(
    rotvec=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    scale=st.floats(1e-9, 1e-5),
    entry=st.integers(0, 15),
    sign=st.sampled_from([-1.0, 1.0]),
)
@settings(max_examples=300, deadline=None)
def test_single_transform_shortcut_agrees_with_the_full_check(rotvec, scale, entry, sign):
    tol = geo.ORTHONORMAL_TOL
    t = geo.make_transform(geo.rotvec_to_matrix(np.array(rotvec)), [10.0, -5.0, 3.0])
    t.flat[entry] += sign * scale  # around the tolerance: some pass, some fail
    fast = geo._is_rigid_4x4(t, tol)
    assert fast == _full_check_passes(t, tol) or abs(scale - tol) < 1e-9
    if fast:
        assert geo.check_transform("t", t) is t
    else:
        with pytest.raises(CalibrationError, match="bottom row|not orthonormal|reflection"):
            geo.check_transform("t", t)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda t: t.__setitem__((0, 0), np.nan), "non-finite"),
        (lambda t: t.__setitem__((2, slice(None, 3)), -t[2, :3]), "reflection"),
        (lambda t: t.__setitem__((3, 0), 0.5), "bottom row"),
    ],
)
def test_single_transform_errors_are_those_of_the_full_check(change, message):
    t = geo.make_transform(geo.rotvec_to_matrix(np.array([0.2, -0.1, 0.4])), [1, 2, 3])
    change(t)
    assert not geo._is_rigid_4x4(t, geo.ORTHONORMAL_TOL)
    with pytest.raises(CalibrationError, match=message):
        geo.check_transform("t", t)


@given(st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=6))
@settings(max_examples=200, deadline=None)
def test_cross3_is_numpy_cross_byte_for_byte(v):
    a, b = np.array(v[:3]), np.array(v[3:])
    assert geo._cross3(a, b).tobytes() == np.cross(a, b).tobytes()
    assert geo._cross3(a, list(v[3:])).tobytes() == np.cross(a, b).tobytes()


def test_rotation_angle_agrees_with_scipy_at_every_angle():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(11)
    axes = rng.normal(size=(3000, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate(
        [
            10 ** rng.uniform(-10, 0, 1000),  # near 0: an arccos of the trace would fail here
            rng.uniform(0.0, np.pi, 1000),
            np.pi - 10 ** rng.uniform(-10, -1, 1000),  # near pi
        ]
    )
    rot = Rotation.from_rotvec(axes * angles[:, None])
    ours = geo.rotation_angle(rot.as_matrix())
    np.testing.assert_allclose(ours, rot.magnitude(), rtol=1e-12, atol=1e-14)
    assert ours.shape == (3000,)
    assert geo.rotation_angle(np.eye(3)) == 0.0
    with pytest.raises(CalibrationError, match=r"expected \(\.\.\., 3, 3\)"):
        geo.rotation_angle(np.eye(4))


@pytest.mark.parametrize("rows", [1, 3, 1000])
def test_cross_rows_is_numpy_cross_byte_for_byte(rows):
    rng = np.random.default_rng(rows)
    a, b = rng.normal(size=(rows, 3)) * 100, rng.normal(size=(rows, 3))
    assert geo.cross_rows(a, b).tobytes() == np.cross(a, b).tobytes()


def _look_at_reference(eye, target, up=(0.0, 0.0, 1.0)):
    """look_at written with np.linalg.norm, np.cross and make_transform."""
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=float))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return geo.make_transform(np.stack([x, np.cross(z, x), z], axis=1), eye)


def test_look_at_is_the_plain_numpy_construction_to_the_bit():
    rng = np.random.default_rng(11)
    cases = [(np.zeros(3), np.array([0.0, 0.0, 5.0])), (np.zeros(3), np.array([0.0, 0.0, -2.0]))]
    cases += [(rng.normal(0, 500, 3), rng.normal(0, 500, 3)) for _ in range(2000)]
    for eye, target in cases:
        assert geo.look_at(eye, target).tobytes() == _look_at_reference(eye, target).tobytes()
    with pytest.raises(CalibrationError, match="eye and target coincide"):
        geo.look_at(np.ones(3), np.ones(3))


@pytest.mark.parametrize("offset", [1.0, 1e-3, 1e-6, 1e-8, 1e-10, 1e-13, 0.0])
def test_fast_collinearity_check_decides_as_the_full_one(offset):
    from calstudy.core.geometry import _check_not_collinear_svd, check_not_collinear

    t = np.linspace(-300.0, 500.0, 35)
    pts = np.column_stack([t, 0.4 * t + 7.0]) + offset * np.column_stack(
        [np.zeros_like(t), np.cos(3.0 * t)]
    )
    outcomes = []
    for check in (_check_not_collinear_svd, check_not_collinear):
        try:
            check("image points", pts)
            outcomes.append("passed")
        except CalibrationError as exc:
            outcomes.append(str(exc))
    assert outcomes[0] == outcomes[1]
    assert (outcomes[0] == "passed") == (offset >= 1e-6)
