"""Tests of calstudy.models.optics: circle of confusion, rendering, exposure fusion (binocular)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from support import disk_image

from calstudy.core.errors import CalibrationError
from calstudy.estimators.coc import detect_centre
from calstudy.models import exposure, optics


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
    np.testing.assert_allclose(exposure.fuse_exposures([img, img]), img / 255.0, atol=1e-6)
    with pytest.raises(CalibrationError, match="one shape"):
        exposure.fuse_exposures([img, img[:-1]])


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
    # at depth Z the ray through pupil point p crosses the rim's plane at a p (1 - L/Z) + L t
    centre, radius = optics.rim_shadow([[0.2, -0.1]], 4.0, 50.0, 12.0, 40.0, [400.0])
    scale = 6.25 * (1.0 - 40.0 / 400.0)
    np.testing.assert_allclose(centre, [[-40.0 * 0.2 / scale, 40.0 * 0.1 / scale]])
    np.testing.assert_allclose(radius, [12.0 / scale])
    # a ray through the transmitted disc's edge grazes the rim
    p = centre[0] + radius[0] * np.array([0.6, 0.8])
    t, a = np.array([0.2, -0.1]), 6.25
    at_rim = a * p * (1.0 - 40.0 / 400.0) + 40.0 * t
    assert np.hypot(*at_rim) == pytest.approx(12.0, rel=1e-12)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (([0.0, 0.0], 0.0, 50.0, 12.0, 40.0), "must be finite and positive"),
        (([0.0, 0.0], 4.0, np.inf, 12.0, 40.0), "must be finite and positive"),
        (([0.0, 0.0], 4.0, 50.0, 12.0, np.nan), "rim distance nan mm finite"),
        (([np.nan, 0.0], 4.0, 50.0, 12.0, 40.0), "must be finite"),
        (([0.0, 0.0, 1.0], 4.0, 50.0, 12.0, 40.0), r"shape \(3,\)"),
        (([0.0, 0.0], 4.0, 50.0, 12.0, 40.0, 30.0), "must lie beyond the rim"),
    ],
)
def test_rim_shadow_refuses_bad_inputs(args, match):
    with pytest.raises(CalibrationError, match=match):
        optics.rim_shadow(*args)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"delta_px": np.nan}, "radius nan px must be finite"),
        ({"delta_px": 5000.0}, r"radius 5000\.0 px must be .* <= 200"),
        ({"side": 0.5}, r"side of the focus 0\.5 must be \+1"),
        ({"rim_centre": (0.0, 0.0, 0.0)}, "rim centre"),
        ({"rim_centre": (np.nan, 0.0)}, "rim centre"),
        ({"rim_radius": -1.0}, "rim radius -1.0"),
        ({"rim_radius": np.nan}, "rim radius nan"),
    ],
)
def test_blur_spot_refuses_bad_inputs(kwargs, match):
    args = {"delta_px": 3.0, "side": 1.0, "rim_centre": (0.5, 0.0), "rim_radius": 1.2} | kwargs
    with pytest.raises(CalibrationError, match=match):
        optics.defocus_kernel(**args)
    img = np.zeros((21, 21), np.float32)
    with pytest.raises(CalibrationError, match=match):
        optics.defocus_vignetted(img, *args.values())


def test_blur_spot_refuses_a_nan_image_and_a_rim_that_blocks_every_ray():
    img = np.zeros((21, 21), np.float32)
    img[3, 4] = np.nan
    with pytest.raises(CalibrationError, match="NaN or inf pixels"):
        optics.defocus_vignetted(img, 3.0, 1.0, (0.5, 0.0), 1.2)
    with pytest.raises(CalibrationError, match="blocks every ray"):
        optics.defocus_kernel(6.0, 1.0, (5.0, 0.0), 1.0)


@pytest.mark.parametrize("delta", [0.3, 1.0, 2.5, 7.3])
def test_uncut_blur_spot_is_the_gaussian_of_eq7(delta):
    rng = np.random.default_rng(1)
    img = rng.random((61, 67)).astype(np.float32)
    # the kernel path without a cut is cv2.GaussianBlur's kernel, same reach (4 sigma)
    k = optics.defocus_kernel(delta)
    flipped = k[::-1, ::-1].copy()
    kernel_path = cv2.filter2D(img, cv2.CV_32F, flipped, borderType=cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(kernel_path, optics.defocus(img, delta), rtol=0, atol=2e-6)
    y, x = np.mgrid[: k.shape[0], : k.shape[1]] - k.shape[0] // 2
    assert abs(float((k * x).sum())) < 1e-6 and abs(float((k * y).sum())) < 1e-6
    # a rim that clears the pupil takes the defocus shortcut; one that just touches it takes
    # the kernel path: both give the same image (no jump at the switch)
    edge = 1.0 + 1.0 / delta
    far = optics.defocus_vignetted(img, delta, 1.0, (0.3 - 1e-6, 0.0), edge + 0.3)
    np.testing.assert_array_equal(far, optics.defocus(img, delta))
    cut = optics.defocus_vignetted(img, delta, 1.0, (0.3 + 1e-6, 0.0), edge + 0.3)
    np.testing.assert_allclose(cut, far, rtol=0, atol=2e-6)


def _pupil_centroid(centre, radius, n=2001):
    """Centroid of the unit disc inside the disc (centre, radius), and its area share."""
    g = np.linspace(-1.0, 1.0, n)
    x, y = np.meshgrid(g, g)
    disc = x**2 + y**2 <= 1.0
    keep = disc & ((x - centre[0]) ** 2 + (y - centre[1]) ** 2 <= radius**2)
    return np.array([x[keep].mean(), y[keep].mean()]), keep.sum() / disc.sum()


@pytest.mark.parametrize("side", [1.0, -1.0])
@pytest.mark.parametrize(
    ("centre", "radius"),
    [((1e5, 0.0), 1e5), ((1.5, 0.0), 1.0), ((0.0, -2.5), 2.0), ((1.27, 1.27), 1.0)],
)
def test_cut_blur_spot_centroid_is_the_transmitted_pupils(side, centre, radius):
    # the centroid of the cut spot is delta times the centroid of the transmitted pupil (half
    # disc: 4 / (3 pi); a thin sliver: near its edge), upright beyond the focus (side +1) and
    # inverted nearer (side -1): the Gaussian's tail is not cut as rays
    delta = 12.0
    k = optics.defocus_kernel(delta, side, centre, radius)
    y, x = np.mgrid[: k.shape[0], : k.shape[1]] - k.shape[0] // 2
    got = np.array([(k * x).sum(), (k * y).sum()])
    want, share = _pupil_centroid(centre, radius)
    assert share < 0.6
    np.testing.assert_allclose(got, side * delta * want, rtol=0, atol=0.01 * delta)
    if centre == (1e5, 0.0):
        assert want[0] == pytest.approx(4.0 / (3.0 * np.pi), rel=1e-3)
    # the blurred image of a point moves by the same amount
    img = np.zeros((121, 121), np.float32)
    img[60, 60] = 1.0
    out = optics.defocus_vignetted(img, delta, side, centre, radius)
    yy, xx = np.mgrid[:121, :121]
    moved = np.array([(out * xx).sum(), (out * yy).sum()]) / out.sum() - 60
    np.testing.assert_allclose(moved, got, atol=1e-3)


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


def _whole_rois(k, dist, centres, normals, radius, origins, shapes):
    """The coverage of every pixel of each ROI (no box): the reference of the boxed render."""
    whole = [(0, rows, 0, cols) for rows, cols in shapes]
    return optics._render_boxes(k, dist, centres, normals, radius, origins, shapes, whole)


def test_render_rois_in_boxes_is_the_whole_roi_render_bit_for_bit(monkeypatch):
    # strong distortion, dots off axis and tilted up to 60 deg, wide margins (blurred dots)
    k = np.array([[2400.0, 0.0, 1000.0], [0.0, 2380.0, 800.0], [0.0, 0.0, 1.0]])
    dist = np.array([-0.25, 0.12, 1e-3, -8e-4, -0.02])
    rng = np.random.default_rng(7)
    centres = np.column_stack(
        [rng.uniform(-60, 60, 8), rng.uniform(-50, 50, 8), rng.uniform(300, 500, 8)]
    )
    tilt = rng.uniform(0.0, np.radians(60.0), 8)
    az = rng.uniform(0, 2 * np.pi, 8)
    normals = np.column_stack(
        [np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)]
    )
    radius = 4.0
    uv = cv2.projectPoints(centres, np.zeros(3), np.zeros(3), k, dist)[0].reshape(-1, 2)
    origins, shapes = [], []
    for p, c, margin in zip(uv, centres, rng.uniform(10, 60, 8), strict=True):
        o, s = optics.roi_around(p, 2400.0 * radius / c[2], margin, 2000, 1600)
        origins.append(o)
        shapes.append(s)
    origins = np.array(origins)
    want = _whole_rois(k, dist, centres, normals, radius, origins, shapes)
    got = optics.render_rois(k, dist, centres, normals, radius, origins, shapes)
    boxes = optics._dot_boxes(k, centres, radius, shapes)
    assert any(b != (0, s[0], 0, s[1]) for b, s in zip(boxes, shapes, strict=True))
    for g, w in zip(got, want, strict=True):
        assert g.dtype == np.float32 and w.max() > 0.5
        np.testing.assert_array_equal(g, w)
    # a box too small for its dot (the dot reaches its ring): the whole ROI is rendered
    tiny = [(s[0] // 2 - 2, s[0] // 2 + 3, s[1] // 2 - 2, s[1] // 2 + 3) for s in shapes]
    monkeypatch.setattr(optics, "_dot_boxes", lambda *args: tiny)
    for g, w in zip(
        optics.render_rois(k, dist, centres, normals, radius, origins, shapes), want, strict=True
    ):
        np.testing.assert_array_equal(g, w)


def test_undistorted_pixels_of_boxes_are_the_whole_grids_cut_bit_for_bit():
    k = np.array([[2400.0, 0.0, 1000.0], [0.0, 2380.0, 800.0], [0.0, 0.0, 1.0]])
    dist = np.array([-0.25, 0.12, 1e-3, -8e-4, -0.02])
    rng = np.random.default_rng(11)
    origins, shapes, boxes = [], [], []
    for _ in range(12):
        rows = int(rng.integers(9, 200))
        shapes.append((rows, rows))
        origins.append(rng.integers(0, 1700, 2))
        cut = int(rng.integers(0, rows // 2))
        boxes.append((cut, rows - cut, cut, rows - cut))
    whole_x, whole_y = optics._undistorted_pixels(k, dist, origins, shapes)
    x, y = optics._undistorted_pixels(k, dist, origins, shapes, boxes=boxes)
    want_x, want_y, start = [], [], 0
    for (rows, cols), (r0, r1, c0, c1) in zip(shapes, boxes, strict=True):
        want_x.append(whole_x[start : start + rows * cols].reshape(rows, cols)[r0:r1, c0:c1])
        want_y.append(whole_y[start : start + rows * cols].reshape(rows, cols)[r0:r1, c0:c1])
        start += rows * cols
    assert x.tobytes() == np.concatenate([w.ravel() for w in want_x]).tobytes()
    assert y.tobytes() == np.concatenate([w.ravel() for w in want_y]).tobytes()


@pytest.mark.parametrize(("delta", "side"), [(0.7, 1.0), (3.3, -1.0), (8.6, 1.0), (14.2, -1.0)])
def test_cut_blur_spot_pupil_from_a_quadrant_is_the_whole_grids(delta, side):
    """The kernel's pupil, computed on a quadrant and mirrored, is the one computed on every
    pixel of the kernel (the formula written out on the whole grid)."""
    centre, radius = np.array([0.9, -0.4]), 1.2
    n = optics._gaussian_size(delta)
    h = n // 2
    offsets = np.arange(-h, h + 1, dtype=np.float64)
    px, py = (side * offsets / delta)[None, :], (side * offsets / delta)[:, None]
    pupil = np.clip(0.5 + (1.0 - np.hypot(px, py)) * delta, 0.0, 1.0)
    through = np.clip(0.5 + (radius - np.hypot(px - centre[0], py - centre[1])) * delta, 0, 1)
    both = np.stack([pupil, pupil * through], axis=-1)
    share = float(both[..., 1].sum() / pupil.sum())
    spread = cv2.GaussianBlur(
        both, (0, 0), sigmaX=delta / math.sqrt(2.0), borderType=cv2.BORDER_CONSTANT
    )
    g1 = cv2.getGaussianKernel(n, delta, cv2.CV_64F)[:, 0]
    k = np.clip(spread[..., 1] + share * (np.outer(g1, g1) * pupil.sum() - spread[..., 0]), 0, None)
    want = (k / k.sum()).astype(np.float32)
    got = optics.defocus_kernel(delta, side, centre, radius)
    assert got.tobytes() == want.tobytes()
