"""Tests of calstudy.estimators.coc: circle-of-confusion rectification and dot centres."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from support import binocular_rig, disk_image

from calstudy.core.errors import CalibrationError
from calstudy.estimators import coc
from calstudy.models import optics


@pytest.fixture(scope="module")
def sensor():
    return binocular_rig()


def test_vectorised_rectification_equals_flowchart_loop():
    img = disk_image(size=23, radius=6.0, centre=(11.2, 10.7), blur=1.5)
    fast = coc.rectify_coc(img, 1.5)
    slow = coc.rectify_coc_reference(img, 1.5)
    inner = (slice(6, -6), slice(6, -6))  # away from the border handling
    # cv2.remap quantises sub-pixel positions to 1/32 px: up to |gradient| / 64 apart
    np.testing.assert_allclose(fast[inner], slow[inner], atol=5e-3)
    assert np.abs(fast[inner] - slow[inner]).mean() < 1e-3
    assert np.abs(fast - img).max() > 0.01  # it does change the image


@pytest.mark.parametrize("delta", [2.0, 2.5647, 3.2])
def test_split_disc_equals_the_flowchart_loop(delta):
    # 13-19 px discs are summed as a box plus two caps (OpenCV would take them through the DFT)
    assert coc._rectify_setup(delta).split is not None
    img = disk_image(size=31, radius=7.0, centre=(15.2, 14.7), blur=delta)
    fast = coc.rectify_coc(img, delta)
    slow = coc.rectify_coc_reference(img, delta)
    np.testing.assert_allclose(fast, slow, atol=5e-3)  # the border rows and columns included
    assert np.abs(fast - slow).mean() < 1e-3


@pytest.mark.parametrize("delta", [0.4, 1.0, 1.9, 2.0, 2.5647, 3.2, 3.4, 5.0, 12.0])
def test_disc_mean_split_or_whole_agrees_with_one_filter(delta):
    rng = np.random.default_rng(1)
    img = rng.uniform(0.05, 1.0, (47, 53)).astype(np.float32)
    disc = coc._rectify_setup(delta)
    side = disc.kernel.shape[0]
    cells = [side * side] if disc.split is None else [disc.split.top.size, disc.split.bottom.size]
    # split exactly when the whole disc would reach OpenCV's DFT size and the caps would not
    whole = side * side >= coc._DFT_CELLS
    assert (disc.split is not None) == (whole and max(cells) < coc._DFT_CELLS)
    halo = disc.halo
    padded = cv2.copyMakeBorder(img, halo, halo, 0, 0, cv2.BORDER_REPLICATE)
    mean = coc._disc_mean(padded, slice(halo, halo + img.shape[0]), disc)
    want = cv2.filter2D(
        img.astype(np.float64), cv2.CV_64F, disc.kernel.astype(np.float64),
        borderType=cv2.BORDER_REPLICATE,
    )
    np.testing.assert_allclose(mean, want, rtol=2e-6)


def test_rectification_sharpens_and_keeps_a_symmetric_centre():
    # a dot centred on a pixel corner: the image is symmetric, so the centre must stay exactly
    blurred = disk_image(centre=(20.5, 19.5), blur=2.5)
    rect = coc.rectify_coc(blurred, 2.5)
    grad = lambda a: np.abs(np.diff(a[20])).max()  # noqa: E731
    assert grad(rect) > 1.3 * grad(blurred)
    np.testing.assert_allclose(coc.detect_centre(rect), [20.5, 19.5], atol=1e-5)


@pytest.mark.parametrize("delta", [0.5, 2.0, 2.5647, 4.0])
def test_rectification_barely_depends_on_the_strip_height(delta):
    # OpenCV's remap and magnitude round their vector and scalar loops differently, and the
    # strip's shape decides where each falls: the last bit of a few pixels, no more
    rng = np.random.default_rng(3)
    img = disk_image(size=61, radius=14.0, centre=(30.2, 29.6), blur=delta)
    img = np.clip(img + rng.normal(0, 0.02, img.shape), 0, 1).astype(np.float32)
    whole = coc.rectify_coc(img, delta, 1000)
    for rows in (1, 5, 32):
        np.testing.assert_allclose(coc.rectify_coc(img, delta, rows), whole, rtol=0, atol=1e-6)


def test_rectification_does_not_depend_on_the_number_of_threads():
    rng = np.random.default_rng(4)
    img = np.clip(disk_image(size=41, blur=2.0) + rng.normal(0, 0.02, (41, 41)), 0, 1)
    img = img.astype(np.float32)
    serial = coc.rectify_coc(img, 2.0, 3, workers=1)
    np.testing.assert_array_equal(coc.rectify_coc(img, 2.0, 3, workers=3), serial)
    np.testing.assert_array_equal(coc.rectify_coc(img, 2.0, 3), serial)


def test_rectification_rejects_bad_strip_and_worker_counts():
    with pytest.raises(CalibrationError, match="strip_rows must be at least 1, got 0"):
        coc.rectify_coc(disk_image(), 2.0, 0)
    with pytest.raises(CalibrationError, match="workers must be at least 1, got 0"):
        coc.rectify_coc(disk_image(), 2.0, workers=0)


def test_rectification_rejects_a_tiny_radius_and_nan_pixels():
    with pytest.raises(CalibrationError, match="below 1/3 px"):
        coc.rectify_coc(disk_image(), 0.2)
    img = disk_image()
    img[3, 4] = np.nan
    with pytest.raises(CalibrationError, match="NaN or inf pixels"):
        coc.rectify_coc(img, 2.0)


def test_render_and_detect_recover_the_projected_centre(sensor):
    camera = sensor.left
    centre = np.array([60.0, -40.0, 850.0])
    normal = -centre / np.linalg.norm(centre)  # facing the camera
    k, dist = camera.K, camera.dist_coeffs
    uv, _ = cv2.projectPoints(centre[None], np.zeros(3), np.zeros(3), k, dist)
    uv = uv.reshape(2)
    origin, shape = optics.roi_around(
        uv, 2.5 * camera.fx / 850.0, 10, camera.width, camera.height
    )
    img = optics.render_dot(k, dist, centre, normal, 2.5, origin, shape)
    np.testing.assert_allclose(coc.detect_centre(img, origin), uv, atol=0.05)


def test_dot_not_found():
    with pytest.raises(CalibrationError, match="no dot found"):
        coc.detect_centre(np.full((30, 30), 0.4, np.float32), origin=(100, 200))


def test_dot_touching_the_roi_border():
    img = disk_image(size=41, radius=9.0, centre=(5.0, 20.0))
    with pytest.raises(CalibrationError, match="touches the border"):
        coc.detect_centre(img)


def test_ellipse_from_too_few_edge_points():
    img = disk_image(size=21, radius=1.2, centre=(10.0, 10.0))
    with pytest.raises(CalibrationError, match="edge points"):
        coc.detect_centre(img, min_points=20)


def test_batched_detection_and_rectification_equal_roi_by_roi():
    rng = np.random.default_rng(5)
    centres = [(20.3, 19.6), (21.0, 20.2), (19.4, 20.9)]
    rois = [disk_image(centre=c, blur=b) for c, b in zip(centres, (1.0, 2.0, 3.0), strict=True)]
    rois = [np.clip(r + rng.normal(0, 0.01, r.shape), 0, 1).astype(np.float32) for r in rois]
    origins = np.array([[100, 200], [300, 50], [7, 9]])
    deltas = np.array([1.0, 2.0, 3.0])
    grads = [coc.image_gradients(r) for r in rois]
    want = np.array([coc.detect_centre(r, o) for r, o in zip(rois, origins, strict=True)])
    np.testing.assert_array_equal(coc.detect_centres(rois, origins), want)
    np.testing.assert_array_equal(coc.detect_centres(rois, origins, gradients=grads), want)
    # rectify_coc computes its own Sobel derivatives strip by strip: the reused ones must agree
    fixed = coc.rectify_cocs(rois, deltas, grads, strip_rows=16)
    for r, d, f in zip(rois, deltas, fixed, strict=True):
        np.testing.assert_array_equal(f, coc.rectify_coc(r, d, 16))
    with pytest.raises(CalibrationError, match="2 radii given for 3 ROIs"):
        coc.rectify_cocs(np.array(rois), deltas[:2])
    flat = [rois[0], np.full((41, 41), 0.4, np.float32)]
    with pytest.raises(CalibrationError, match=r"no dot found .* at \(300, 50\)"):
        coc.detect_centres(flat, origins[:2])
