"""Circle-of-confusion rectification and dot-centre detection (binocular paper, Section 3.1).

The inverse steps of the imaging model of :mod:`calstudy.models.optics`:

- :func:`rectify_coc`: the rectification of Eq. 8-11 (Fig. 5), vectorised over the image, and
  :func:`rectify_coc_reference`, the same computation as a per-pixel double loop that follows the
  flowchart literally (for tests and the speed ratio of the benchmark);
- :func:`detect_centre`: Canny boundary and direct least-squares ellipse fit (Eq. 12, OpenCV's
  ``fitEllipseDirect``, Fitzgibbon's Lagrange formulation).

Images are float arrays with values in [0, 1]; coordinates are in px with pixel centres at
integers (OpenCV's convention); a region of interest (ROI) is given by the image coordinates of
its top-left pixel, ``origin = (u0, v0)``.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.models.exposure import filled

# ----------------------------------------------------------------------------------------------
# circle-of-confusion rectification (Eq. 8-11, Fig. 5)

# rectify_coc spreads an image of more rows than this over threads by default
_ROWS_PER_THREAD = 512


def _disk(radius: float) -> np.ndarray:
    r = int(math.floor(radius))
    a = np.arange(-r, r + 1)
    return (a[None, :] ** 2 + a[:, None] ** 2 <= radius**2).astype(np.float32)


def _check_rectify(image, delta_px: float) -> np.ndarray:
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 3:
        raise CalibrationError(f"rectification needs a 2-D image of >= 3 x 3 px, got {img.shape}")
    if not np.isfinite(img.sum()):  # a NaN or inf pixel makes the sum non-finite
        raise CalibrationError(
            f"the {img.shape[1]} x {img.shape[0]} px image has NaN or inf pixels"
        )
    if not (np.isfinite(delta_px) and delta_px >= 1.0 / 3.0):
        raise CalibrationError(
            f"circle-of-confusion radius {delta_px} px is below 1/3 px: the 3-delta window "
            "holds a single pixel and there is nothing to rectify"
        )
    if 3.0 * delta_px > sum(img.shape):  # the window would dwarf the image (and the memory)
        raise CalibrationError(
            f"circle-of-confusion radius {delta_px} px: its 3-delta window of radius "
            f"{3.0 * delta_px:.4g} px exceeds the {img.shape[1]} x {img.shape[0]} px image"
        )
    return img


def rectify_coc(
    image, delta_px: float, strip_rows: int = 32, workers: int | None = None
) -> np.ndarray:
    """Circle-of-confusion rectification of a whole image (Eq. 8-11, Fig. 5), vectorised.

    At pixel ``u``: ``E_u0`` is the mean over the disc of radius ``3 delta`` (``t`` pixels) and
    ``E_0 = t E_u0`` the energy in it; Eq. 9 reads ``[a a] [dx^2 dy^2]^T = E_u - E_u0`` with
    ``a = -E_0 / (4 pi delta^4)``; its Moore-Penrose (least-norm) solution is
    ``X = dx^2 = dy^2 = (E_u - E_u0) / (2 a)``, positive where the pixel is darker than its
    neighbourhood (the outer flank of a bright dot), negative where brighter.

    Eq. 11 gives at each pixel ``|dx| = |dy| = sqrt|X|``: how far the pixel's content was
    spread by the blur. The paper does not say in which direction the pixel is moved; the reading
    implemented here moves it along the intensity gradient (the only direction a rotationally
    symmetric blur spreads energy), by ``sqrt(dx^2 + dy^2)``, undoing the spread: a pixel darker
    than its neighbourhood (outer flank) takes the value from further out, a brighter one from
    further in. The result is resampled bilinearly (``cv2.remap``, which quantises sub-pixel
    positions to 1/32 px), in float32.

    The image is processed in horizontal strips of ``strip_rows`` rows (with a halo of the
    ``3 delta`` window) so that the working arrays stay in cache; strips are independent and run
    on ``workers`` threads (numpy and OpenCV release the interpreter lock). Each strip writes its
    own rows, so the result does not depend on the number of workers. The strip height can
    move the last bit of a few pixels (below 1e-7): ``cv2.remap`` and ``cv2.magnitude`` round
    the vector body and the scalar tail of their loops differently, and where the tails fall
    depends on the shape they are given.

    Parameters
    ----------
    image : (rows, cols) array
        Fused image in [0, 1].
    delta_px : float
        Circle-of-confusion radius in px (Eq. 4), >= 1/3.
    strip_rows : int, default 32
        Rows per strip, >= 1.
    workers : int, optional
        Threads; by default the number of CPUs for an image of more than 512 rows, one
        otherwise (a region of interest is not worth a thread).

    Returns
    -------
    float32 array, same shape
    """
    img = _check_rectify(image, delta_px)
    if int(strip_rows) < 1:
        raise CalibrationError(f"strip_rows must be at least 1, got {strip_rows}")
    strip_rows = int(strip_rows)
    rows, cols = img.shape
    starts = range(0, rows, strip_rows)
    if workers is None:
        workers = (os.cpu_count() or 1) if rows > _ROWS_PER_THREAD else 1
    if int(workers) < 1:
        raise CalibrationError(f"workers must be at least 1, got {workers}")
    setup = _rectify_setup(delta_px)
    out = np.empty_like(img)

    def strip(y0: int) -> None:
        _rectify_strip(img, y0, min(rows, y0 + strip_rows), setup, out)

    if workers == 1:
        for y0 in starts:
            strip(y0)
    else:
        with ThreadPoolExecutor(int(workers)) as pool:
            for done in pool.map(strip, starts):  # re-raises a strip's error here
                del done
    return out


def rectify_cocs(images, deltas_px, gradients=None, strip_rows: int | None = None) -> list:
    """:func:`rectify_coc` of each of ``m`` ROIs (a list or a stack) with its own radius: the
    list of rectified ROIs.

    The same numbers as :func:`rectify_coc` ROI by ROI with the same ``strip_rows`` (one
    thread); by default each ROI is one strip (a region of interest fits in cache).
    ``gradients``, the ROIs' :func:`image_gradients` when the caller has them (the centre
    detection computes them), spares computing the Sobel derivatives again.

    Raises
    ------
    CalibrationError
        As :func:`rectify_coc`, for the first ROI (in order) that cannot be rectified.
    """
    deltas = np.asarray(deltas_px, dtype=float).reshape(-1)
    if deltas.shape != (len(images),):
        raise CalibrationError(f"{deltas.size} radii given for {len(images)} ROIs")
    if strip_rows is not None and int(strip_rows) < 1:
        raise CalibrationError(f"strip_rows must be at least 1, got {strip_rows}")
    stack = [_check_rectify(img, delta) for img, delta in zip(images, deltas, strict=True)]
    out = []
    for i, (img, delta) in enumerate(zip(stack, deltas, strict=True)):
        gx, gy = image_gradients(img) if gradients is None else gradients[i]
        setup = _rectify_setup(float(delta))
        fixed = np.empty_like(img)
        step = img.shape[0] if strip_rows is None else int(strip_rows)
        for y0 in range(0, img.shape[0], step):
            y1 = min(img.shape[0], y0 + step)
            _rectify_strip(img, y0, y1, setup, fixed, gx[y0:y1], gy[y0:y1])
        out.append(fixed)
    return out


# OpenCV's filter2D filters a float kernel of this many cells or more through the DFT, at a
# cost that does not fall with the kernel's zeros; a smaller kernel is summed directly, tap by
# non-zero tap, the same numbers at every position.
_DFT_CELLS = 130


class _Split(NamedTuple):
    """A disc as the box of its full-width rows (a row sum, then a column sum) plus its top
    and bottom caps; each cap is anchored on its row next to the box and its sums are then
    moved by ``shift`` rows."""

    row: np.ndarray  # ones (1, 2r + 1)
    column: np.ndarray  # ones (rows of the box, 1)
    top: np.ndarray
    bottom: np.ndarray
    shift: int
    inv_t: np.float32  # 1 / (cells of the disc)


@dataclass(frozen=True)
class _Disc:
    """The ``3 delta`` disc of :func:`rectify_coc` and how to sum an image over it.

    ``kernel``: the disc normalised to a unit sum (one ``filter2D``). ``split``: the disc cut
    into pieces that are each summed directly, when the whole disc would go through the DFT
    and the pieces would not (13-19 px wide discs, that of a full frame among them; 1.2-2.5x
    faster, and the same numbers whatever the strip); ``None`` otherwise.
    """

    kernel: np.ndarray
    halo: int  # rows of context a strip needs on each side: the disc's radius and one
    coef: np.float32  # Eq. 9-11's 2 pi delta^4 / t
    split: _Split | None


def _rectify_setup(delta_px: float) -> _Disc:
    """The ``3 delta`` disc of radius ``delta_px``: see :class:`_Disc`."""
    disk = _disk(3.0 * delta_px)
    r = disk.shape[0] // 2
    t = float(disk.sum())
    split = None
    if disk.size >= _DFT_CELLS:
        full = np.flatnonzero(disk.all(axis=1))  # the full-width rows: r - h .. r + h
        lo = int(full[0])
        if lo * disk.shape[1] < _DFT_CELLS:
            split = _Split(
                row=np.ones((1, disk.shape[1]), np.float32),
                column=np.ones((full.size, 1), np.float32),
                top=disk[:lo].copy(),
                bottom=disk[-lo:].copy(),
                shift=r - lo + 1,  # from a cap's anchor row to the disc's centre row
                inv_t=np.float32(1.0 / t),
            )
    return _Disc(
        disk / np.float32(t), r + 1, np.float32(2.0 * math.pi * delta_px**4 / t), split
    )


def _disc_mean(src, keep: slice, disc: _Disc) -> np.ndarray:
    """Mean of ``src`` over the disc at the rows ``keep`` (with ``disc.halo`` rows of context
    on each side when the disc is split; columns: replicated border)."""
    if disc.split is None:
        return cv2.filter2D(src, cv2.CV_32F, disc.kernel, borderType=cv2.BORDER_REPLICATE)[keep]
    split = disc.split
    r, lo, shift = split.row.shape[1] // 2, split.top.shape[0], split.shift
    a, b = keep.start, keep.stop
    h = split.column.shape[0] // 2
    # each piece filtered on the rows its kept sums read, no more: the rows of the box, then
    # its column sums; each cap from its anchor row back (top) or on (bottom)
    rows = cv2.filter2D(src[a - h : b + h], cv2.CV_32F, split.row, borderType=cv2.BORDER_REPLICATE)
    mean = cv2.filter2D(rows, cv2.CV_32F, split.column, borderType=cv2.BORDER_REPLICATE)
    mean = mean[h : h + b - a]
    mean += cv2.filter2D(
        src[a - shift - lo + 1 : b - shift],
        cv2.CV_32F,
        split.top,
        anchor=(r, lo - 1),
        borderType=cv2.BORDER_REPLICATE,
    )[lo - 1 :]
    mean += cv2.filter2D(
        src[a + shift : b + shift + lo - 1],
        cv2.CV_32F,
        split.bottom,
        anchor=(r, 0),
        borderType=cv2.BORDER_REPLICATE,
    )[: b - a]
    mean *= split.inv_t
    return mean


def _rectify_strip(img, y0: int, y1: int, disc: _Disc, out, gx=None, gy=None) -> None:
    """Rows ``y0:y1`` of :func:`rectify_coc` into ``out``; ``gx, gy``: the image's Sobel
    derivatives on those rows if known (the strip's own are the same numbers: a 3 x 3 aperture
    inside the halo)."""
    halo = disc.halo
    rows, cols = img.shape
    a, b = max(0, y0 - halo), min(rows, y1 + halo)
    src = img[a:b]
    keep = slice(y0 - a, y1 - a)
    if disc.split is not None and (a > y0 - halo or b < y1 + halo):
        # the split disc's caps are moved by whole rows: give them the replicated rows
        src = cv2.copyMakeBorder(src, a - (y0 - halo), y1 + halo - b, 0, 0, cv2.BORDER_REPLICATE)
        keep = slice(halo, halo + y1 - y0)
    mean = _disc_mean(src, keep, disc)
    own = gx is None  # derivatives of this strip, free to be overwritten
    if own:  # on the kept rows and one more on each side where there is one
        s0, s1 = max(keep.start - 1, 0), min(keep.stop + 1, src.shape[0])
        gx, gy = (g[keep.start - s0 : keep.stop - s0] for g in image_gradients(src[s0:s1]))
    here = src[keep]
    # X = 2 pi delta^4 (E_u0 - E_u) / (t E_u0); step = sign(X) sqrt(2 |X|) / |grad|
    x = np.subtract(mean, here)
    x *= disc.coef
    np.maximum(mean, filled(1e-6, mean.shape), out=mean)
    x /= mean
    step = np.abs(x, out=mean)
    step *= 2.0
    np.sqrt(step, out=step)
    np.copysign(step, x, out=step)
    norm = cv2.magnitude(gx, gy)
    norm += np.float32(1e-12)
    step /= norm
    map_x = np.multiply(gx, step, out=gx if own else None)
    map_y = np.multiply(gy, step, out=gy if own else step)
    np.subtract(np.arange(cols, dtype=np.float32)[None, :], map_x, out=map_x)
    np.subtract(np.arange(y0, y1, dtype=np.float32)[:, None], map_y, out=map_y)
    out[y0:y1] = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def rectify_coc_reference(image, delta_px: float) -> np.ndarray:
    """The rectification of :func:`rectify_coc` as the paper's flowchart (Fig. 5): per pixel.

    A two-layer loop over the pixels (column order): the mean and the energy of the
    ``3 delta`` disc, the 1 x 2 system of Eq. 9, its Moore-Penrose inverse (Eq. 10, by
    ``numpy.linalg.pinv``), the least-norm solution (Eq. 11) and its square root; the pixel is
    then moved along the gradient and resampled bilinearly. Slow: for tests and the benchmark.
    """
    img = _check_rectify(image, delta_px).astype(np.float64)
    rows, cols = img.shape
    r = int(math.floor(3.0 * delta_px))
    pad = np.pad(img, r + 1, mode="edge")
    disk = _disk(3.0 * delta_px).astype(bool)
    t = disk.sum()
    out = np.empty_like(img)
    for j in range(cols):
        for i in range(rows):
            window = pad[i + 1 : i + 2 * r + 2, j + 1 : j + 2 * r + 2][disk]
            e0 = window.sum()
            eu0 = e0 / t
            a = np.array([[-max(e0, 1e-6 * t) / (4 * math.pi * delta_px**4)] * 2])
            b = np.array([img[i, j] - eu0])
            x = np.linalg.pinv(a) @ b
            shift = math.copysign(math.sqrt(abs(x[0]) + abs(x[1])), x[0])
            pi, pj = i + r + 1, j + r + 1
            gx = (pad[pi - 1 : pi + 2, pj + 1] @ [1, 2, 1]) - (
                pad[pi - 1 : pi + 2, pj - 1] @ [1, 2, 1]
            )
            gy = (pad[pi + 1, pj - 1 : pj + 2] @ [1, 2, 1]) - (
                pad[pi - 1, pj - 1 : pj + 2] @ [1, 2, 1]
            )
            g = math.hypot(gx, gy) + 1e-12
            out[i, j] = _bilinear(pad, pi - shift * gy / g, pj - shift * gx / g)
    return out.astype(np.float32)


def _bilinear(img: np.ndarray, y: float, x: float) -> float:
    y = min(max(y, 0.0), img.shape[0] - 1.0)
    x = min(max(x, 0.0), img.shape[1] - 1.0)
    y0, x0 = min(int(y), img.shape[0] - 2), min(int(x), img.shape[1] - 2)
    fy, fx = y - y0, x - x0
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bottom = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return float(top * (1 - fy) + bottom * fy)


# ----------------------------------------------------------------------------------------------
# boundary and centre (Eq. 12)


def detect_centre(
    image,
    origin=(0, 0),
    low: float = 0.25,
    high: float = 0.5,
    min_points: int = 20,
    gradients=None,
) -> np.ndarray:
    """Centre of a bright dot in an ROI: Canny boundary, then a direct ellipse fit (Eq. 12).

    Canny runs on Sobel derivatives of the float image with hysteresis thresholds ``low`` and
    ``high`` relative to the largest gradient magnitude in the ROI; the edge pixels are fitted by
    ``cv2.fitEllipseDirect`` (Fitzgibbon's direct least squares: the Lagrange problem of Eq. 12
    with the constraint ``4ac - b^2 = 1``). The ellipse centre is the dot centre.

    Parameters
    ----------
    image : (rows, cols) array
        The ROI (float in [0, 1], or integer).
    origin : (2,) array_like
        Image coordinates of the ROI's top-left pixel.
    low, high : float
        Canny thresholds as fractions of the largest gradient magnitude.
    min_points : int
        Fewest edge pixels accepted for the ellipse fit (>= 5).
    gradients : (gx, gy), optional
        The image's :func:`image_gradients`, if the caller has them.

    Returns
    -------
    (2,) array
        ``(u, v)`` in image px.

    Raises
    ------
    CalibrationError
        If no dot is found (a flat ROI), the boundary touches the ROI border, there are fewer
        than ``min_points`` edge pixels, or the fit fails.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 5:
        raise CalibrationError(f"ROI must be a 2-D image of >= 5 x 5 px, got shape {img.shape}")
    if min_points < 5:
        raise CalibrationError(f"an ellipse needs >= 5 edge points; min_points is {min_points}")
    if not 0 < low < high <= 1:
        raise CalibrationError(
            f"Canny thresholds low = {low}, high = {high}: need 0 < low < high <= 1"
        )
    span = float(img.max() - img.min())
    if not np.isfinite(span) or span < 0.02:
        raise CalibrationError(
            f"no dot found in the {img.shape[1]} x {img.shape[0]} px ROI at {_where(origin)}: "
            f"intensity range {span:.3g} of full scale"
        )
    gx, gy = image_gradients(img) if gradients is None else gradients
    scale = 16000.0 / cv2.minMaxLoc(cv2.magnitude(gx, gy))[1]
    edges = cv2.Canny(
        (gx * scale).astype(np.int16),
        (gy * scale).astype(np.int16),
        low * 16000.0,
        high * 16000.0,
        L2gradient=True,
    )
    found = cv2.findNonZero(edges)  # (x, y) of the edge pixels, row by row
    pts = np.zeros((0, 2), np.int32) if found is None else found.reshape(-1, 2)
    if len(pts) < min_points:
        raise CalibrationError(
            f"ellipse fit from {len(pts)} edge points in the ROI at {_where(origin)}; "
            f"at least {min_points} are needed"
        )
    # the edge pixels' extent in one pass: first column and row, width and height
    c0, r0, width, height = cv2.boundingRect(pts)
    r1, c1 = r0 + height - 1, c0 + width - 1  # last row and column
    if r0 <= 1 or c0 <= 1 or r1 >= img.shape[0] - 2 or c1 >= img.shape[1] - 2:
        raise CalibrationError(
            f"the dot's boundary touches the border of the {img.shape[1]} x {img.shape[0]} px ROI "
            f"at {_where(origin)}: the dot is cut off"
        )
    (cu, cv), axes, _ = cv2.fitEllipseDirect(pts.astype(np.float32))
    if not (np.isfinite(cu) and np.isfinite(cv) and min(axes) > 0):
        raise CalibrationError(f"ellipse fit failed on {len(pts)} edge points at {_where(origin)}")
    return np.array([cu + origin[0], cv + origin[1]], dtype=float)


def _where(origin) -> tuple:
    """The ROI's origin as the error messages give it."""
    return tuple(np.asarray(origin).tolist())


def detect_centres(
    images, origins, low: float = 0.25, high: float = 0.5, min_points: int = 20, gradients=None
) -> np.ndarray:
    """:func:`detect_centre` of each ROI of a stack ``(m, rows, cols)``, ``origins (m, 2)``;
    ``gradients``: their :func:`image_gradients`, if the caller has them.

    Returns ``(m, 2)`` centres ``(u, v)`` in image px; raises as :func:`detect_centre` for the
    first ROI (in order) whose dot is not found.
    """
    grads = gradients if gradients is not None else [None] * len(images)
    return np.array(
        [
            detect_centre(img, o, low, high, min_points, g)
            for img, o, g in zip(images, origins, grads, strict=True)
        ]
    ).reshape(-1, 2)


def image_gradients(image) -> tuple[np.ndarray, np.ndarray]:
    """Sobel derivatives ``(gx, gy)`` of an image (3 x 3 aperture, replicated border, float32):
    those of :func:`detect_centre` and :func:`rectify_coc`.

    Raises
    ------
    CalibrationError
        The image is not 2-D, is empty, or holds NaN or inf pixels.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or img.size == 0:
        raise CalibrationError(f"image gradients need a non-empty 2-D image, got {img.shape}")
    if not np.isfinite(img.sum()):
        raise CalibrationError(
            f"the {img.shape[1]} x {img.shape[0]} px image has NaN or inf pixels"
        )
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    return gx, gy
