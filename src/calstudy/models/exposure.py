"""Exposure and fusion of the dot images: the last steps of the optics model of the binocular
paper (Section 3.1, Eq. 3), re-exported by :mod:`calstudy.models.optics`.

- :func:`expose`: exposure time, saturation, shot and read noise, quantisation;
- :func:`fuse_exposures`: exposure fusion with contrast and well-exposedness weights (Eq. 3);
- :func:`expose_and_fuse`: both in one pass over a stack of ROIs (the same numbers).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from calstudy.core.errors import CalibrationError


def expose(
    radiance,
    exposure_ms: float,
    peak_at_100ms: float,
    background_at_100ms: float,
    read_noise_dn: float,
    electrons_per_dn: float,
    rng: np.random.Generator,
    bits: int = 8,
) -> np.ndarray:
    """One exposure of a dot image: scale with time, add shot and read noise, saturate, quantise.

    Parameters
    ----------
    radiance : array
        Defocused dot image in [0, 1] (1 = the dot's peak brightness).
    exposure_ms : float
        Exposure time; the signal scales with ``exposure_ms / 100``.
    peak_at_100ms, background_at_100ms : float
        Dot peak and background at 100 ms, in units of full scale.
    read_noise_dn, electrons_per_dn : float
        Read noise (DN, >= 0) and conversion gain (> 0; ``inf`` for no shot noise); shot noise
        is ``sqrt(DN / electrons_per_dn)`` DN.
    rng : numpy.random.Generator
        Noise source.
    bits : int, default 8
        Output bit depth.

    Returns
    -------
    uint8 or uint16 array

    Raises
    ------
    CalibrationError
        If the radiance holds a value that is not finite, the exposure time is not a finite
        number > 0, the conversion gain is not > 0, a level or the read noise is negative or
        not finite,
        or ``bits`` is not an integer from 1 to 16.
    """
    _check_exposure(
        exposure_ms, peak_at_100ms, background_at_100ms, read_noise_dn, electrons_per_dn, bits
    )
    rad = np.asarray(radiance, dtype=np.float32)
    if not np.isfinite(rad).all():
        raise CalibrationError(
            f"radiance holds {int((~np.isfinite(rad)).sum())} NaN or inf pixel(s); it must be a "
            "finite image in [0, 1]"
        )
    full = 2**bits - 1
    levels = _exposed(
        rad,
        exposure_ms,
        peak_at_100ms,
        background_at_100ms,
        read_noise_dn,
        electrons_per_dn,
        rng,
        full,
    )
    return levels.astype(np.uint8 if bits <= 8 else np.uint16)


def _check_exposure(exposure_ms, peak, background, read_noise_dn, electrons_per_dn, bits) -> None:
    """Refuse exposure settings outside their domain (scalars only: cheap, once per call)."""
    if not (isinstance(bits, (int, np.integer)) and not isinstance(bits, bool) and 1 <= bits <= 16):
        raise CalibrationError(f"bit depth bits = {bits!r} must be an integer from 1 to 16")
    if not (np.isfinite(exposure_ms) and exposure_ms > 0):
        raise CalibrationError(f"exposure_ms = {exposure_ms} must be a finite number > 0")
    # an infinite gain is allowed: no shot noise (the noise-free control)
    if not electrons_per_dn > 0:
        raise CalibrationError(
            f"conversion gain electrons_per_dn = {electrons_per_dn} must be > 0 (inf: no shot "
            "noise)"
        )
    for name, value in (
        ("peak_at_100ms", peak),
        ("background_at_100ms", background),
        ("read_noise_dn", read_noise_dn),
    ):
        if not (np.isfinite(value) and value >= 0):
            raise CalibrationError(f"{name} = {value} must be a finite number >= 0")


def _exposed(rad, exposure_ms, peak, background, read_noise_dn, electrons_per_dn, rng, full):
    """:func:`expose` before the cast to integers: float32 levels ``0 .. full``."""
    scale = exposure_ms / 100.0
    dn = np.float32(full * scale * (peak - background)) * rad
    dn += np.float32(full * scale * background)
    # sigma = sqrt(read^2 + max(dn, 0) / gain); noisy = rint(dn + sigma z), in place
    sigma = np.maximum(dn, filled(0.0, dn.shape))
    sigma /= np.float32(electrons_per_dn)
    sigma += np.float32(read_noise_dn**2)
    np.sqrt(sigma, out=sigma)
    noisy = rng.standard_normal(dn.shape, dtype=np.float32)
    noisy *= sigma
    noisy += dn
    np.rint(noisy, out=noisy)
    # np.clip(noisy, 0, full) without its checks (and with +0 for -0, as np.maximum gives)
    np.maximum(noisy, filled(0.0, noisy.shape), out=noisy)
    return np.minimum(noisy, filled(full, noisy.shape), out=noisy)


_FILLED: dict = {}


def filled(value: float, shape) -> np.ndarray:
    """A read-only float32 array of ``shape`` holding ``value`` (a view of a buffer kept per
    value). ``np.maximum`` and ``np.minimum`` give the same numbers against it as against the
    scalar (NaN, infinities and signed zeros included), but take a vectorised loop that is about
    three times faster."""
    n = math.prod(shape)
    buffer = _FILLED.get(float(value))
    if buffer is None or buffer.size < n:
        buffer = np.full(max(n, 1 << 16), value, dtype=np.float32)
        buffer.flags.writeable = False
        _FILLED[float(value)] = buffer
    return buffer[:n].reshape(shape)


def expose_and_fuse(
    radiance,
    exposures_ms,
    peak_at_100ms: float,
    background_at_100ms: float,
    read_noise_dn: float,
    electrons_per_dn: float,
    rng: np.random.Generator,
    bits: int = 8,
    weight_contrast: float = 1.0,
    weight_exposure: float = 1.0,
    sigma: float = 0.2,
) -> np.ndarray:
    """:func:`expose` at each of ``exposures_ms``, then :func:`fuse_exposures` (Eq. 3).

    The same numbers as the two steps (the same noise draws in the same order, the same float32
    operations), in one pass: the quantised levels are used as they are instead of going
    through integer images, and the well-exposedness weight, a function of the level, is read
    from a table of its ``2**bits`` values.

    Parameters
    ----------
    radiance : (rows, cols) or (m, rows, cols) array
        Defocused dot image(s) in [0, 1]; a stack is fused ROI by ROI.
    exposures_ms : sequence of float
        Exposure times, in the order the exposures are taken (and the noise drawn).

    The other parameters are those of :func:`expose` and :func:`fuse_exposures`.

    Returns
    -------
    float32 array in [0, 1], the shape of ``radiance``

    Raises
    ------
    CalibrationError
        On settings outside their domain, as :func:`expose` and :func:`fuse_exposures`. The
        radiance itself is not scanned here (this runs once per simulated image pair; its
        producer, :func:`calstudy.models.optics.defocus`, refuses NaN and inf pixels).
    """
    _check_fusion(weight_contrast, weight_exposure, sigma)
    times = list(exposures_ms)
    if not times:
        raise CalibrationError("fusion needs at least one exposure time")
    for t in times:
        _check_exposure(
            t, peak_at_100ms, background_at_100ms, read_noise_dn, electrons_per_dn, bits
        )
    rad = np.asarray(radiance, dtype=np.float32)
    full = 2**bits - 1
    # one image is filtered as it is, a stack ROI by ROI (_laplacian: the same numbers)
    stack = rad if rad.ndim == 2 else rad.reshape((-1,) + rad.shape[-2:])
    # fuse_exposures scales an integer image by its type's maximum (255 or 65535)
    scale = np.float32(np.iinfo(np.uint8 if bits <= 8 else np.uint16).max)
    well = _well_table(int(bits), float(sigma), float(weight_exposure))
    num = den = None
    for t in times:
        raw = _exposed(
            stack,
            t,
            peak_at_100ms,
            background_at_100ms,
            read_noise_dn,
            electrons_per_dn,
            rng,
            full,
        )
        if bits <= 8:  # a table look-up of 8-bit levels (OpenCV's is the fastest)
            flat = raw.astype(np.uint8).reshape(-1, raw.shape[-1])
            well_s = cv2.LUT(flat, well).reshape(raw.shape)
        else:
            well_s = np.take(well, raw.astype(np.uint16))
        img = np.divide(raw, scale, out=raw)  # the level / the integer type's maximum
        w = _fusion_weight(img, weight_contrast, well_s)
        if num is None:
            num, den = w * img, w
        else:
            num += np.multiply(w, img, out=img)
            den += w
    return np.divide(num, den, out=num).reshape(rad.shape)


# ----------------------------------------------------------------------------------------------
# fusion (Eq. 3)


def fuse_exposures(
    images,
    weight_contrast: float = 1.0,
    weight_exposure: float = 1.0,
    sigma: float = 0.2,
    bits: int | None = None,
) -> np.ndarray:
    """Fuse exposures by contrast and well-exposedness weights (Eq. 3).

    ``W_s = C_s^wc * E_s^we`` with ``C_s = |Laplacian(I_s)|`` and
    ``E_s = exp(-(I_s - 0.5)^2 / (2 sigma^2))``; ``R = sum_s W_s I_s / sum_s W_s``. The pixel
    positions are unchanged (the paper's remark under Eq. 3).

    Parameters
    ----------
    images : sequence of arrays, same shape
        Raw exposures (uint8/uint16 or float in [0, 1]): images ``(rows, cols)`` or stacks
        ``(m, rows, cols)`` of ROIs, each fused on its own.
    bits : int, optional
        Bit depth of integer images: full scale ``2**bits - 1``. A 10- or 12-bit camera stores
        its images in ``uint16``; without ``bits`` they would be scaled by 65535 and all look
        nearly black to the well-exposedness weight. Default: the full range of the dtype.

    Raises
    ------
    CalibrationError
        On images of different shapes, bad weights, a bit depth outside 1 to the dtype's width,
        integer values above ``2**bits - 1``, or float values that are NaN, inf or outside
        [0, 1].

    Returns
    -------
    float32 array in [0, 1]
    """
    stack = []
    for i, img in enumerate(images):
        a = np.asarray(img)
        if np.issubdtype(a.dtype, np.integer):
            full = _full_scale(a, bits)
        elif not np.issubdtype(a.dtype, np.floating):
            raise CalibrationError(f"image {i} has dtype {a.dtype}; expected integers or floats")
        else:
            full = 1.0
            ok = np.isfinite(a) & (a >= 0) & (a <= 1)
            if not ok.all():
                idx = tuple(int(k) for k in np.argwhere(~ok)[0])
                raise CalibrationError(
                    f"image {i} holds {float(a[idx])!r} at pixel {idx}: a float image must "
                    "hold finite values in [0, 1]"
                )
        stack.append(a.astype(np.float32) / full)
    if len(stack) < 1 or any(s.shape != stack[0].shape for s in stack):
        raise CalibrationError(f"fusion needs >= 1 images of one shape, got {len(stack)}")
    _check_fusion(weight_contrast, weight_exposure, sigma)
    num = np.zeros_like(stack[0])
    den = np.zeros_like(stack[0])
    for img in stack:
        w = _fusion_weight(img, weight_contrast, _well_exposed(img, sigma, weight_exposure))
        num += w * img
        den += w
    return num / den


def _full_scale(a: np.ndarray, bits: int | None) -> float:
    """Full scale of the integer image ``a``: ``2**bits - 1``, or its dtype's maximum."""
    width = np.iinfo(a.dtype).bits
    if bits is None:
        return float(np.iinfo(a.dtype).max)
    if not (isinstance(bits, (int, np.integer)) and 1 <= bits <= width):
        raise CalibrationError(
            f"bit depth {bits!r} must be an integer from 1 to {width} for {a.dtype} images"
        )
    full = 2 ** int(bits) - 1
    if a.size and int(a.max()) > full:
        raise CalibrationError(
            f"an image holds the value {int(a.max())}, above the {full} of {bits}-bit data: is "
            "the bit depth right?"
        )
    return float(full)


def _check_fusion(weight_contrast: float, weight_exposure: float, sigma: float) -> None:
    if not (np.isfinite(sigma) and sigma > 0):
        raise CalibrationError(f"well-exposedness sigma = {sigma} must be a finite number > 0")
    if not all(np.isfinite(w) and w >= 0 for w in (weight_contrast, weight_exposure)):
        raise CalibrationError(
            f"fusion weights {weight_contrast}, {weight_exposure} must be finite numbers >= 0"
        )


@functools.lru_cache(maxsize=16)
def _well_table(bits: int, sigma: float, weight_exposure: float) -> np.ndarray:
    """:func:`_well_exposed` of every level of a ``bits``-bit image, scaled as
    :func:`fuse_exposures` scales it (by 255 or 65535; read-only: cached)."""
    scale = np.float32(np.iinfo(np.uint8 if bits <= 8 else np.uint16).max)
    table = _well_exposed(np.arange(2**bits, dtype=np.float32) / scale, sigma, weight_exposure)
    table.flags.writeable = False
    return table


def _well_exposed(img: np.ndarray, sigma: float, weight_exposure: float) -> np.ndarray:
    """``E^we``, ``E = exp(-(I - 0.5)^2 / (2 sigma^2))`` (float32)."""
    e = np.exp(-((img - 0.5) ** 2) / (2.0 * sigma**2))
    return e if weight_exposure == 1.0 else e**weight_exposure


def _fusion_weight(img: np.ndarray, weight_contrast: float, well: np.ndarray) -> np.ndarray:
    """``W = C^wc E^we + 1e-12`` of Eq. 3 from the image and its ``E^we`` (a new array)."""
    w = np.abs(_laplacian(img))
    if weight_contrast != 1.0:
        w **= weight_contrast
    w *= well
    w += np.float32(1e-12)
    return w


def _laplacian(img: np.ndarray) -> np.ndarray:
    """``cv2.Laplacian`` (3 x 3 aperture, replicated border) of an image or of each image of an
    ``(m, rows, cols)`` stack.

    The images of a stack are laid one above the other with a copy of their first and last row
    around each (the replicated border of a 3 x 3 aperture), so that one call filters them all;
    each pixel is computed as for the image alone.
    """
    if img.ndim == 2:
        return cv2.Laplacian(img, cv2.CV_32F, borderType=cv2.BORDER_REPLICATE)
    m, rows, cols = img.shape
    tall = np.empty((m, rows + 2, cols), dtype=np.float32)
    tall[:, 1:-1] = img
    tall[:, 0] = img[:, 0]
    tall[:, -1] = img[:, -1]
    out = cv2.Laplacian(tall.reshape(-1, cols), cv2.CV_32F, borderType=cv2.BORDER_REPLICATE)
    return out.reshape(tall.shape)[:, 1:-1]
