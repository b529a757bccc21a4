"""Tests of calstudy.models.exposure: exposure, fusion (Eq. 3) and the one-pass path of both."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from support import disk_image

from calstudy.core.errors import CalibrationError
from calstudy.models import exposure


def _two_steps(radiance, times, rng, bits, wc, we, sigma, read=1.5, gain=4.0):
    """Exposure then fusion written out plainly (integer images in between, one OpenCV call
    per image): the reference the one-pass path must reproduce bit for bit."""
    full = 2**bits - 1
    shots = []
    for t in times:
        s = t / 100.0
        rad = np.asarray(radiance, np.float32)
        dn = np.float32(full * s * (1.3 - 0.06)) * rad + np.float32(full * s * 0.06)
        sd = np.sqrt(np.float32(read**2) + np.maximum(dn, 0) / np.float32(gain))
        noisy = np.rint(dn + sd * rng.standard_normal(dn.shape, dtype=np.float32))
        shots.append(np.clip(noisy, 0, full).astype(np.uint8 if bits <= 8 else np.uint16))
    num = den = 0
    for shot in shots:
        img = shot.astype(np.float32) / float(np.iinfo(shot.dtype).max)
        lap = np.stack(
            [cv2.Laplacian(i, cv2.CV_32F, borderType=cv2.BORDER_REPLICATE) for i in img]
        )
        well = np.exp(-((img - 0.5) ** 2) / (2.0 * sigma**2))
        w = np.abs(lap) ** wc * well**we + 1e-12
        num, den = num + w * img, den + w
    return num / den


@pytest.mark.parametrize(("bits", "wc", "we"), [(8, 1.0, 1.0), (8, 0.5, 2.0), (12, 1.0, 1.0)])
def test_one_pass_equals_exposure_then_fusion(bits, wc, we):
    stack = np.stack([disk_image(blur=b) for b in (0.0, 1.5, 3.0)]) * 0.9
    args = ([100.0, 70.0], 1.3, 0.06, 1.5, 4.0)
    got = exposure.expose_and_fuse(stack, *args, np.random.default_rng(3), bits, wc, we, 0.2)
    want = _two_steps(stack, [100.0, 70.0], np.random.default_rng(3), bits, wc, we, 0.2)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, want)
    # the two public steps give the same numbers, and one ROI alone is its row of the stack
    rng = np.random.default_rng(3)
    shots = [exposure.expose(stack, t, 1.3, 0.06, 1.5, 4.0, rng, bits) for t in args[0]]
    np.testing.assert_array_equal(exposure.fuse_exposures(shots, wc, we, 0.2), want)
    one = exposure.expose_and_fuse(stack[1], *args, np.random.default_rng(3), bits, wc, we, 0.2)
    assert one.shape == stack[1].shape


def test_one_pass_checks_its_inputs():
    with pytest.raises(CalibrationError, match="at least one exposure time"):
        exposure.expose_and_fuse(disk_image(), [], 1.3, 0.06, 1.5, 4.0, np.random.default_rng())
    with pytest.raises(CalibrationError, match="well-exposedness sigma = 0.0"):
        exposure.expose_and_fuse(
            disk_image(), [100.0], 1.3, 0.06, 1.5, 4.0, np.random.default_rng(), sigma=0.0
        )


def test_fusion_of_12_bit_images_in_uint16_uses_their_bit_depth():
    rng = np.random.default_rng(3)
    levels = rng.uniform(0.05, 0.95, (2, 16, 16))
    twelve = np.round(levels * 4095).astype(np.uint16)
    eight = np.round(levels * 255).astype(np.uint8)
    fused12 = exposure.fuse_exposures(list(twelve), bits=12)
    fused8 = exposure.fuse_exposures(list(eight))
    # the same scene at two bit depths fuses to nearly the same image (the contrast weights see
    # the coarser 8-bit quantisation: a few levels at most)
    np.testing.assert_allclose(fused12, fused8, atol=5.0 / 255)
    assert np.abs(fused12 - fused8).mean() < 1.0 / 255
    # without the bit depth, the 12-bit data are read as 16-bit: everything below 1/16
    assert exposure.fuse_exposures(list(twelve)).max() < 1.0 / 16


def test_fusion_rejects_a_wrong_bit_depth():
    img = np.full((8, 8), 4000, dtype=np.uint16)
    with pytest.raises(CalibrationError, match="above the 255 of 8-bit data"):
        exposure.fuse_exposures([img, img], bits=8)
    with pytest.raises(CalibrationError, match="bit depth 17 must be an integer from 1 to 16"):
        exposure.fuse_exposures([img, img], bits=17)


def test_filled_arrays_give_numpy_minimum_and_maximum_the_scalars_numbers():
    rng = np.random.default_rng(5)
    x = np.rint(rng.normal(0.0, 300.0, 5000)).astype(np.float32)
    x[::7], x[::11], x[::13] = -0.0, 0.0, 255.0
    x[::17], x[::19], x[::23] = np.nan, np.inf, -np.inf
    for value in (0.0, 255.0, 1e-6):
        for shape in ((5000,), (50, 100), (2, 25, 100)):
            c = exposure.filled(value, shape)
            assert c.shape == shape and c.dtype == np.float32 and not c.flags.writeable
            assert np.all(c == np.float32(value))
            xs = x.reshape(shape)
            for op in (np.maximum, np.minimum):
                assert op(xs, c).tobytes() == op(xs, np.float32(value)).tobytes()
    # a larger request grows the buffer; earlier views keep their values
    small = exposure.filled(3.5, (4,))
    big = exposure.filled(3.5, (300, 300))
    assert big.size == 90000 and np.all(big == 3.5) and np.all(small == 3.5)
