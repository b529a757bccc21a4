"""Tests of calstudy.models.optics: circle of confusion, rendering, exposure fusion (binocular)."""

from __future__ import annotations

import numpy as np
import pytest
from support import disk_image

from calstudy.core.errors import CalibrationError
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
