"""Tests of calstudy.models.optics: circle of confusion, rendering, exposure fusion (binocular)."""

from __future__ import annotations

import numpy as np
import pytest
from support import disk_image

from calstudy.core.errors import CalibrationError
from calstudy.estimators.coc import detect_centre
from calstudy.models import optics


def test_coc_radius_zero_at_focus_and_far_field_limit():
    assert optics.coc_radius_mm(850.0, 850.0, 55.5, 8.0) == 0.0
    # Eq. 5 is the limit of Eq. 4 for d >> f: ratio (d_A - f) / d_A
    near = optics.coc_radius_mm(900.0, 850.0, 55.5, 8.0)
    far = optics.coc_radius_far_mm(900.0, 850.0, 55.5, 8.0)
    assert far / near == pytest.approx((850.0 - 55.5) / 850.0, rel=1e-12)
    # textbook value: |dB - dA| f^2 / (dB (dA - f) N) is the blur diameter
    assert 2 * near == pytest.approx(50 * 55.5**2 / (900 * 794.5 * 8), rel=1e-12)
    with pytest.raises(CalibrationError, match="exceed the focal length"):
        optics.coc_radius_mm(40.0, 850.0, 55.5, 8.0)


def test_coc_radius_rejects_a_non_finite_distance():
    with pytest.raises(CalibrationError, match="not finite"):
        optics.coc_radius_px(np.nan, 850.0, 55.5, 8.0, 0.0046)


def test_fusion_of_equal_images_is_the_image_and_checks_shapes():
    img = (disk_image() * 255).astype(np.uint8)
    np.testing.assert_allclose(optics.fuse_exposures([img, img]), img / 255.0, atol=1e-6)
    with pytest.raises(CalibrationError, match="one shape"):
        optics.fuse_exposures([img, img[:-1]])


def test_dot_touching_the_image_border():
    with pytest.raises(CalibrationError, match="touches the border of the 7904 x 6004 image"):
        optics.roi_around([7890.0, 3000.0], 30.0, 10.0, 7904, 6004)


# ----------------------------------------------------------------------------------------------
# off-axis blur spots and the perspective centre of a tilted dot


def test_rim_shadow_geometry():
    centre, radius = optics.rim_shadow([0.0, 0.0], 4.0, 50.0, 12.0, 40.0)
    assert radius == pytest.approx(12.0 / (50.0 / 8.0))
    np.testing.assert_array_equal(centre, [0.0, 0.0])
    centre, _ = optics.rim_shadow([0.2, -0.1], 4.0, 50.0, 12.0, 40.0)
    np.testing.assert_allclose(centre, [-40.0 * 0.2 / 6.25, 40.0 * 0.1 / 6.25])
    with pytest.raises(CalibrationError, match="must be positive"):
        optics.rim_shadow([0.0, 0.0], 0.0, 50.0, 12.0, 40.0)


def test_uncut_blur_spot_is_the_gaussian_of_eq7():
    img = np.zeros((61, 61), np.float32)
    img[20:40, 25:45] = 1.0
    # a rim far outside the spot cuts nothing: the result is the symmetric Gaussian blur
    got = optics.defocus_vignetted(img, 2.5, 1.0, (0.5, 0.0), 10.0)
    np.testing.assert_array_equal(got, optics.defocus(img, 2.5))
    k = optics.defocus_kernel(2.5)
    y, x = np.mgrid[: k.shape[0], : k.shape[1]] - k.shape[0] // 2
    assert abs(float((k * x).sum())) < 1e-6 and abs(float((k * y).sum())) < 1e-6


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_half_cut_blur_spot_centroid_is_the_half_gaussian_mean(side):
    # a rim whose edge passes through the pupil centre keeps the half x >= 0 of the pupil: the
    # spot's centroid is the mean of a half-Gaussian, delta sqrt(2 / pi), upright beyond the
    # focus (side +1) and inverted nearer (side -1)
    delta, big = 12.0, 1e5
    k = optics.defocus_kernel(delta, side, (big, 0.0), big)
    y, x = np.mgrid[: k.shape[0], : k.shape[1]] - k.shape[0] // 2
    assert float((k * x).sum()) == pytest.approx(side * delta * np.sqrt(2 / np.pi), rel=0.01)
    assert abs(float((k * y).sum())) < 1e-6
    # the blurred image of a point moves by the same amount
    img = np.zeros((121, 121), np.float32)
    img[60, 60] = 1.0
    out = optics.defocus_vignetted(img, delta, side, (big, 0.0), big)
    yy, xx = np.mgrid[:121, :121]
    assert float((out * xx).sum() / out.sum()) - 60 == pytest.approx(
        side * delta * np.sqrt(2 / np.pi), rel=0.01
    )


def _conic_centre(k, centre, normal, radius):
    """Centre of the image ellipse of a circle (closed form): the conic ``H^-T Q0 H^-1``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    h = k @ np.column_stack([u, v, centre])
    hi = np.linalg.inv(h)
    q = hi.T @ np.diag([1.0, 1.0, -(radius**2)]) @ hi
    return -np.linalg.solve(q[:2, :2], q[:2, 2])


@pytest.mark.parametrize(
    "centre, normal, min_shift",
    [
        ([40.0, 30.0, 200.0], [0.0, np.sin(0.8), -np.cos(0.8)], 1.0),  # tilted 46 deg, off axis
        ([0.0, 0.0, 200.0], [0.0, 0.0, -1.0], None),  # fronto-parallel on the axis
    ],
)
def test_perspective_centre_of_a_circle_matches_its_closed_form(centre, normal, min_shift):
    k = np.array([[2000.0, 0.0, 1000.0], [0.0, 2000.0, 800.0], [0.0, 0.0, 1.0]])
    c = np.array(centre)
    radius = 15.0
    proj = (k @ c)[:2] / c[2]
    origin, shape = optics.roi_around(proj, 2000.0 * radius / c[2], 40.0, 2000, 1600)
    img = optics.render_dot(k, np.zeros(4), c, np.array(normal), radius, origin, shape)
    got = detect_centre(img, origin)
    want = _conic_centre(k, c, normal, radius)
    np.testing.assert_allclose(got, want, atol=0.05)
    shift = float(np.hypot(*(want - proj)))
    if min_shift is None:  # no eccentricity: the centre is the projected centre
        assert shift < 1e-9
        np.testing.assert_allclose(got, proj, atol=0.05)
    else:  # the ellipse centre is not the image of the circle's centre
        assert shift > min_shift
