"""Imaging of retro-reflective dots: the optics model of the binocular paper (Section 3.1).

The forward model, each step a function (the inverse steps, rectification and centre detection,
are :mod:`calstudy.estimators.coc`):

- :func:`coc_radius_mm` and :func:`coc_radius_far_mm`: the radius of the circle of confusion of
  an object point off the focused distance (Eq. 4, and its far-field form Eq. 5);
- :func:`render_dot`: the sharp image of a round dot on a plane (exact perspective and lens
  distortion per pixel), :func:`defocus` (the Gaussian energy model of Eq. 7) and
  :func:`defocus_vignetted` (the same blur spot cut off axis by a lens rim: :func:`rim_shadow`,
  :func:`defocus_kernel`). The image's last steps, exposure with sensor noise and the fusion of
  Eq. 3, are :mod:`calstudy.models.exposure`.

Images are float arrays with values in [0, 1] (or uint8 for raw exposures); coordinates are in px
with pixel centres at integers (OpenCV's convention); a region of interest (ROI) is given by the
image coordinates of its top-left pixel, ``origin = (u0, v0)``.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from calstudy.core.errors import CalibrationError

# ----------------------------------------------------------------------------------------------
# circle of confusion (Eq. 4-5)


def coc_radius_mm(d_b, d_a: float, focal_mm: float, f_number: float) -> np.ndarray:
    """Radius of the circle of confusion on the sensor, mm (Eq. 4).

    ``delta = |d_B - d_A| f^2 / (2 d_B (d_A - f) F)``: the blur-disc radius of a point at
    ``d_B`` when the lens is focused at ``d_A``. The paper divides further by ``max(h, v)``; a
    radius in pixels follows here by dividing by the pixel pitch instead (see
    :func:`coc_radius_px`), the reading under which Eq. 4 has a unit.

    Parameters
    ----------
    d_b : float or array_like
        Object distance(s) from the lens, mm, > f.
    d_a : float
        Focused distance, mm, > f.
    focal_mm, f_number : float
        Focal length (mm) and aperture number F, > 0.

    Raises
    ------
    CalibrationError
        If a distance is not finite or not beyond the focal length, or f, F are not positive.
    """
    d_b = np.asarray(d_b, dtype=float)
    if not (focal_mm > 0 and f_number > 0):
        raise CalibrationError(f"focal length {focal_mm} mm and F {f_number} must be positive")
    if not (np.all(np.isfinite(d_b)) and math.isfinite(d_a)):
        raise CalibrationError(f"object distance {d_b} or focused distance {d_a} is not finite")
    if d_a <= focal_mm or np.any(d_b <= focal_mm):
        raise CalibrationError(
            f"object distances ({np.min(d_b):.4g} mm) and the focused distance ({d_a:.4g} mm) "
            f"must exceed the focal length {focal_mm:.4g} mm"
        )
    return np.abs(d_b - d_a) * focal_mm**2 / (2.0 * d_b * (d_a - focal_mm) * f_number)


def coc_radius_far_mm(d_b, d_a: float, focal_mm: float, f_number: float) -> np.ndarray:
    """Far-field form of Eq. 4 (the paper's Eq. 5, ``d_A, d_B >> f``).

    ``|d_B - d_A| f^2 / (2 d_B d_A F)``, mm on the sensor.

    Parameters
    ----------
    d_b : float or array_like
        Object distance(s) from the lens, mm, > 0.
    d_a : float
        Focused distance, mm, > 0.
    focal_mm, f_number : float
        Focal length (mm) and aperture number F, > 0.

    Returns
    -------
    numpy.ndarray
        The radius, mm, the shape of ``d_b``.

    Raises
    ------
    CalibrationError
        If a distance, f or F is not a finite positive number (a distance of 0 has no image).
    """
    d_b = np.asarray(d_b, dtype=float)
    if not all(math.isfinite(v) and v > 0 for v in (focal_mm, f_number)):
        raise CalibrationError(
            f"focal length {focal_mm} mm and F {f_number} must be finite positive numbers"
        )
    if not (math.isfinite(d_a) and d_a > 0):
        raise CalibrationError(f"focused distance d_A = {d_a} mm must be a finite number > 0")
    if not (np.all(np.isfinite(d_b)) and np.all(d_b > 0)):
        bad = d_b[~(np.isfinite(d_b) & (d_b > 0))].ravel()[0]
        raise CalibrationError(f"object distance d_B = {bad} mm must be a finite number > 0")
    return np.abs(d_b - d_a) * focal_mm**2 / (2.0 * d_b * d_a * f_number)


def coc_radius_px(d_b, d_a: float, focal_mm: float, f_number: float, pitch_mm: float):
    """Eq. 4 in pixels: :func:`coc_radius_mm` divided by the pixel pitch (mm)."""
    if not pitch_mm > 0:
        raise CalibrationError(f"pixel pitch {pitch_mm} mm must be positive")
    return coc_radius_mm(d_b, d_a, focal_mm, f_number) / pitch_mm


# ----------------------------------------------------------------------------------------------
# rendering


def roi_around(uv, radius_px: float, margin_px: float, width: int, height: int):
    """Origin and shape of a square ROI around a dot, checked against the image border.

    Parameters
    ----------
    uv : (2,) array_like
        Projected dot centre, px.
    radius_px, margin_px : float
        Dot radius in the image and the margin around it (blur and edge detection), px.
    width, height : int
        Image size, px.

    Returns
    -------
    origin : (2,) int array
        Image coordinates ``(u0, v0)`` of the ROI's top-left pixel.
    shape : tuple of int
        ``(rows, cols)``.

    Raises
    ------
    CalibrationError
        If the centre is not finite or the ROI (the dot with its margin) leaves the image.
    """
    uv = np.asarray(uv, dtype=float)
    if uv.shape != (2,) or not np.all(np.isfinite(uv)):
        raise CalibrationError(f"dot centre {uv} is not a finite image point")
    if not (np.isfinite(radius_px) and radius_px > 0 and np.isfinite(margin_px) and margin_px >= 0):
        raise CalibrationError(
            f"dot radius {radius_px} px must be > 0 and margin {margin_px} px >= 0 (finite)"
        )
    half = int(math.ceil(radius_px + margin_px))
    u0, v0 = int(round(uv[0])) - half, int(round(uv[1])) - half
    if u0 < 0 or v0 < 0 or u0 + 2 * half >= width or v0 + 2 * half >= height:
        raise CalibrationError(
            f"dot at ({uv[0]:.1f}, {uv[1]:.1f}) px with radius {radius_px:.1f} px and margin "
            f"{margin_px:.1f} px touches the border of the {width} x {height} image"
        )
    return np.array([u0, v0]), (2 * half + 1, 2 * half + 1)


def render_dot(k, dist, centre, normal, radius_mm: float, origin, shape) -> np.ndarray:
    """Sharp image of a round flat dot, with exact perspective and lens distortion.

    Every pixel centre is undistorted (``cv2.undistortPointsIter``), its ray is intersected with
    the dot's plane, and the pixel's coverage is a linear ramp one pixel wide around the dot's
    edge (anti-aliasing: coverage 0.5 exactly on the edge). The brightness falls off as
    ``cos^4`` of the field angle (natural vignetting). One dot of :func:`render_dots`.

    Parameters
    ----------
    k : (3, 3) array
        Camera matrix, px.
    dist : (4,) or (5,) array
        OpenCV distortion ``k1 k2 p1 p2 [k3]`` (Eq. 6).
    centre, normal : (3,) array
        Dot centre (mm) and unit normal in the camera frame.
    radius_mm : float
        Dot radius.
    origin : (2,) int array
        Top-left pixel of the ROI; ``shape`` is ``(rows, cols)``.

    Returns
    -------
    (rows, cols) float32 array
        Values in [0, 1].
    """
    c = np.asarray(centre, dtype=float).reshape(1, 3)
    n = np.asarray(normal, dtype=float).reshape(1, 3)
    return render_dots(k, dist, c, n, radius_mm, np.reshape(origin, (1, 2)), shape)[0]


def render_dots(k, dist, centres, normals, radius_mm: float, origins, shape) -> np.ndarray:
    """Sharp images of ``m`` round flat dots, one ROI each, all ROIs of one ``shape``.

    The model of :func:`render_dot`, batched (:func:`render_rois` with one shape).

    Parameters
    ----------
    centres, normals : (m, 3) arrays
        Dot centres (mm) and unit normals in the camera frame.
    origins : (m, 2) int array
        Top-left pixel of each ROI.

    Returns
    -------
    (m, rows, cols) float32 array
    """
    m = len(np.asarray(centres))
    return np.stack(render_rois(k, dist, centres, normals, radius_mm, origins, [shape] * m))


def render_rois(k, dist, centres, normals, radius_mm: float, origins, shapes) -> list:
    """Sharp images of ``m`` round flat dots, each in its own ROI (``shapes``: ``m`` pairs
    ``(rows, cols)``): the model of :func:`render_dot`, batched. The undistortion grids of all
    ROIs go through one ``cv2.undistortPointsIter`` call and the coverage is computed on all
    their pixels at once; each pixel's value is the one :func:`render_dot` gives it. The
    coverage is computed only in a box around each dot (:func:`_dot_boxes`) and is 0 outside
    it; when the dot reaches the box's outer ring, the whole ROI is computed instead.

    Returns
    -------
    list of ``m`` float32 arrays ``(rows, cols)``

    Raises
    ------
    CalibrationError
        If the camera matrix, the distortion, a centre, a normal or an origin is not finite, a
        focal length or the radius is not > 0, a dot's centre is not in front of the camera
        (z > 0), a normal is zero, a shape is not positive, or the counts differ.
    """
    c = np.asarray(centres, dtype=float).reshape(-1, 3)
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    shapes = [tuple(int(v) for v in sh) for sh in shapes]
    origins = np.asarray(origins).reshape(-1, 2)
    _check_dots(k, dist, c, n, radius_mm, origins, shapes)
    boxes = _dot_boxes(k, c, radius_mm, shapes)
    cut = _render_boxes(k, dist, c, n, radius_mm, origins, shapes, boxes)
    out = []
    redo = []
    for i, (part, shape, (r0, r1, c0, c1)) in enumerate(zip(cut, shapes, boxes, strict=True)):
        full = (r0, r1, c0, c1) == (0, shape[0], 0, shape[1])
        if not full and _ring_lit(part):  # the dot may reach beyond the box: render it all
            redo.append(i)
        img = np.zeros(shape, dtype=np.float32)
        img[r0:r1, c0:c1] = part
        out.append(img)
    if redo:
        whole = [(0, shapes[i][0], 0, shapes[i][1]) for i in redo]
        again = _render_boxes(
            k, dist, c[redo], n[redo], radius_mm, origins[redo], [shapes[i] for i in redo], whole
        )
        for i, img in zip(redo, again, strict=True):
            out[i] = img
    return out


def _check_dots(k, dist, c: np.ndarray, n: np.ndarray, radius_mm, origins, shapes) -> None:
    """Refuse inputs of :func:`render_rois` outside their domain (once per call, vectorised)."""
    k = np.asarray(k, dtype=float)
    if k.shape != (3, 3) or not np.isfinite(k).all() or not (k[0, 0] > 0 and k[1, 1] > 0):
        raise CalibrationError(f"camera matrix must be a finite (3, 3) with fx, fy > 0; got {k}")
    if not np.isfinite(np.asarray(dist, dtype=float)).all():
        raise CalibrationError(f"distortion coefficients must be finite; got {dist}")
    if not (math.isfinite(radius_mm) and radius_mm > 0):
        raise CalibrationError(f"dot radius {radius_mm} mm must be finite and > 0")
    if not (len(c) == len(n) == len(origins) == len(shapes)):
        raise CalibrationError(
            f"{len(c)} centres, {len(n)} normals, {len(origins)} origins and {len(shapes)} "
            "shapes: one of each per dot"
        )
    for name, a in (("dot centres", c), ("dot normals", n), ("ROI origins", origins)):
        bad = ~np.isfinite(np.asarray(a, dtype=float)).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise CalibrationError(f"{name}: row {i} is not finite ({a[i].tolist()})")
    if len(c) and not (c[:, 2] > 0).all():
        i = int(np.argmin(c[:, 2]))
        raise CalibrationError(f"dot {i} is not in front of the camera: z = {c[i, 2]:.4g} mm")
    if len(n) and not (np.abs(n).max(axis=1) > 0).all():
        raise CalibrationError(f"dot normal {int(np.argmin(np.abs(n).max(axis=1)))} is zero")
    small = [sh for sh in shapes if min(sh) < 1]
    if small:
        raise CalibrationError(f"ROI shape {small[0]} must have at least one row and column")


def _dot_boxes(k, centres, radius_mm: float, shapes) -> list:
    """Per ROI, the centred box ``(r0, r1, c0, c1)`` outside which its dot's coverage is 0: a
    half-size of 1.5 times the largest image radius of the dot (its nearest edge point, at
    depth ``cz - radius``) plus 4 px, within the ROI. The renderer checks the box's outer ring
    and renders the whole ROI when the dot reaches it."""
    focal = 0.5 * (k[0, 0] + k[1, 1])
    boxes = []
    for cz, (rows, cols) in zip(centres[:, 2], shapes, strict=True):
        near = cz - radius_mm
        reach = 1.1 * focal * radius_mm / near + 3.0 if near > 0 else math.inf
        half_r, half_c = (rows - 1) // 2, (cols - 1) // 2
        keep = int(math.ceil(reach)) if math.isfinite(reach) else max(half_r, half_c)
        dr, dc = max(0, half_r - keep), max(0, half_c - keep)
        boxes.append((dr, rows - dr, dc, cols - dc))
    return boxes


def _ring_lit(img: np.ndarray) -> bool:
    """True when a pixel of the image's outermost rows or columns is not 0."""
    return bool(img[0].any() or img[-1].any() or img[:, 0].any() or img[:, -1].any())


def _render_boxes(k, dist, c, n, radius_mm: float, origins, shapes, boxes) -> list:
    """The coverage of :func:`render_rois` on the box ``(r0, r1, c0, c1)`` of each ROI (the
    ROI's own undistortion grid, cut to the box): the list of box images."""
    shapes_b = [(r1 - r0, c1 - c0) for r0, r1, c0, c1 in boxes]
    sizes = [rows * cols for rows, cols in shapes_b]
    x, y = _undistorted_pixels(k, dist, origins, shapes, boxes=boxes)
    # Ray r = (x, y, 1) meets the dot plane at s r, s = (c.n) / (r.n). The offset from the dot
    # centre is written with the ray through the centre, (xc, yc, 1), as reference, so that the
    # per-pixel work is on small numbers (float32 keeps ~1e-3 px): with dx = x - xc,
    # dy = y - yc, t = dx nx + dy ny and r.n = dn_c + t, s = cz dn_c / (r.n) and
    # s r - c = (s dx - xc cz t / (r.n), s dy - yc cz t / (r.n), -cz t / (r.n)).
    # All pixels of all ROIs are one vector (each dot's numbers repeated over its pixels), and
    # every step writes into one of a few buffers: the operations and their order are those of
    # the formulas, so the float32 result depends neither on the buffering nor on the batch.
    cz = c[:, 2]
    xc, yc = c[:, 0] / cz, c[:, 1] / cz
    dn_c = xc * n[:, 0] + yc * n[:, 1] + n[:, 2]
    f32 = np.float32
    counts = np.array(sizes)

    def col(v):
        return np.repeat(np.asarray(v, dtype=f32), counts)

    xc32, yc32 = col(xc), col(yc)
    dx = x - xc32
    dy = y - yc32
    t = dx * col(n[:, 0])
    tmp = np.multiply(dy, col(n[:, 1]))
    t += tmp
    dn = t + col(dn_c)  # r.n
    abs_dn = np.abs(dn)
    if np.any(abs_dn < 1e-9):
        raise CalibrationError("the dot is seen edge-on (its plane contains a viewing ray)")
    inv = np.divide(f32(1.0), dn, out=dn)
    s = col(cz * dn_c) * inv
    q = np.multiply(col(cz), t, out=t)
    q *= inv  # cz t / (r.n)
    px = np.multiply(s, dx, out=dx)
    px -= np.multiply(xc32, q, out=tmp)
    py = np.multiply(s, dy, out=dy)
    py -= np.multiply(yc32, q, out=tmp)
    rho = np.multiply(px, px, out=px)
    rho += np.multiply(py, py, out=py)
    rho += np.multiply(q, q, out=q)
    np.sqrt(rho, out=rho)
    len2 = np.multiply(x, x, out=x)
    len2 += np.multiply(y, y, out=y)
    len2 += f32(1.0)
    ray_len = np.sqrt(len2, out=y)
    cos_tilt = np.divide(abs_dn, ray_len, out=abs_dn)
    focal = f32(0.5 * (k[0, 0] + k[1, 1]))
    footprint = np.multiply(s, ray_len, out=s)
    root = np.sqrt(cos_tilt, out=cos_tilt)
    footprint /= np.multiply(focal, root, out=root)
    coverage = np.subtract(rho, f32(radius_mm), out=rho)
    coverage /= footprint
    np.subtract(f32(0.5), coverage, out=coverage)
    np.clip(coverage, f32(0.0), f32(1.0), out=coverage)
    coverage /= np.multiply(len2, len2, out=len2)
    parts = np.split(coverage, np.cumsum(sizes)[:-1])
    return [part.reshape(shape) for part, shape in zip(parts, shapes_b, strict=True)]


def _undistorted_pixels(k, dist, origins, shapes, step: int = 8, boxes=None):
    """Normalised undistorted coordinates of the pixel centres of ``m`` ROIs (``shapes``:
    ``(rows, cols)`` each): ``x`` and ``y``, float32, the ROIs' pixels one after the other (row
    by row).

    The distortion is undone exactly (``cv2.undistortPointsIter``) on a grid every ``step`` px
    and interpolated bilinearly in between: the distortion field is smooth enough that this
    changes the result by less than 1e-3 px for Table 1's lenses, at a tenth of the cost. One
    ``cv2.undistortPointsIter`` call for all grid nodes (each point is undistorted on its own).
    ``boxes``: per ROI, ``(r0, r1, c0, c1)``, the pixels to return (those of the whole ROI's
    interpolation, cut).

    Only the nodes next to a returned pixel are undistorted; the others are left at 0, which
    reaches no returned pixel (their interpolation weights there are 0): the numbers are those
    of the whole ROI's grid, cut. (The products keep the whole ROI's shapes: BLAS may round a
    product of a cut matrix differently.)
    """
    if boxes is None:
        boxes = [(0, rows, 0, cols) for rows, cols in shapes]
    grids, used, nodes = [], [], []
    for origin, (rows, cols), (r0, r1, c0, c1) in zip(origins, shapes, boxes, strict=True):
        n_v, n_u = -(-(rows + step) // step), -(-(cols + step) // step)  # nodes 0, step, ...
        # pixel y lies between the nodes y // step and y // step + 1
        a0, a1 = r0 // step, min(n_v, (r1 - 1) // step + 2)
        b0, b1 = c0 // step, min(n_u, (c1 - 1) // step + 2)
        grid = np.empty((a1 - a0, b1 - b0, 2))
        grid[..., 0] = np.arange(b0 * step, b1 * step, step)[None, :] + float(origin[0])
        grid[..., 1] = np.arange(a0 * step, a1 * step, step)[:, None] + float(origin[1])
        nodes.append(grid.reshape(-1, 2))
        grids.append((n_v, n_u))
        used.append((a0, a1, b0, b1))
    sizes = [len(g) for g in nodes]
    coarse = cv2.undistortPointsIter(
        np.concatenate(nodes).reshape(-1, 1, 2), k, dist, None, None, RENDER_UNDISTORT_CRITERIA
    )
    coarse = coarse.reshape(-1, 2).astype(np.float32)
    xs, ys = [], []
    for piece, (n_v, n_u), (a0, a1, b0, b1), (rows, cols), (r0, r1, c0, c1) in zip(
        np.split(coarse, np.cumsum(sizes)[:-1]), grids, used, shapes, boxes, strict=True
    ):
        part = np.zeros((n_v, n_u, 2), dtype=np.float32)
        part[a0:a1, b0:b1] = piece.reshape(a1 - a0, b1 - b0, 2)
        wy = _linear_weights(rows, n_v, step)
        wx = _linear_weights(cols, n_u, step)
        # separable bilinear interpolation, float32 (the grid values are ~0.3, error ~1e-8)
        xs.append((wy @ part[None, :, :, 0] @ wx.T)[0, r0:r1, c0:c1].reshape(-1))
        ys.append((wy @ part[None, :, :, 1] @ wx.T)[0, r0:r1, c0:c1].reshape(-1))
    return np.concatenate(xs), np.concatenate(ys)


#: Iterations of ``cv2.undistortPointsIter`` for the rendering grid: 20 fixed-point steps
#: reach the float64 solution to 2e-16 over the whole frame of Table 1's lenses (the sensors'
#: criterion, 100 steps or 1e-15 px, keeps iterating on rounding), and the grid is used in
#: float32 (resolution ~3e-8).
RENDER_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-15)


@functools.lru_cache(maxsize=512)
def _linear_weights(n: int, m: int, step: int) -> np.ndarray:
    """``(n, m)`` float32 matrix of 1-D linear interpolation from nodes every ``step`` to
    ``0..n-1`` (read-only: cached)."""
    f = np.arange(n) / step
    i = f.astype(int)
    w = np.zeros((n, m))
    w[np.arange(n), i] = 1.0 - (f - i)
    w[np.arange(n), i + 1] = f - i
    w = w.astype(np.float32)
    w.flags.writeable = False
    return w


def defocus(image, delta_px: float) -> np.ndarray:
    """Blur with the Gaussian energy model of the circle of confusion (Eq. 7), ``sigma = delta``.

    Radii below 0.05 px leave the image as it is.
    """
    img = np.asarray(image, dtype=np.float32)
    if not np.isfinite(delta_px) or delta_px < 0:
        raise CalibrationError(f"circle-of-confusion radius {delta_px} px must be finite, >= 0")
    if not np.all(np.isfinite(img)):
        raise CalibrationError(f"the {img.shape} image to blur has NaN or inf pixels")
    if delta_px < 0.05:
        return img.copy()
    return cv2.GaussianBlur(img, (0, 0), sigmaX=float(delta_px), borderType=cv2.BORDER_REPLICATE)


# ----------------------------------------------------------------------------------------------
# off-axis (vignetted) blur spots


def rim_shadow(
    field_tan,
    f_number: float,
    focal_mm: float,
    rim_radius_mm: float,
    rim_distance_mm: float,
    depth_mm=math.inf,
):
    """Where a lens rim cuts the entrance pupil for an off-axis object point, in pupil radii.

    The entrance pupil has radius ``a = f / (2 F)``. A rim of radius ``R`` at ``L`` in front of
    the pupil (towards the object; a rim behind it has ``L < 0``) lets through, from an object
    point at depth ``Z`` in the direction ``t = (X/Z, Y/Z)``, the rays whose pupil point ``p``
    (in pupil radii) satisfies ``|a p (1 - L/Z) + L t| <= R`` (the ray from the point to ``a p``
    crosses the rim's plane there): the transmitted pupil is the unit disc intersected with the
    disc of radius ``R / (a (1 - L/Z))`` centred at ``-L t / (a (1 - L/Z))`` (the "cat's eye" of
    mechanical vignetting). On the axis, or with a rim wider than ``a |1 - L/Z| + |L t|``,
    nothing is cut.

    Parameters
    ----------
    field_tan : (..., 2) array_like
        ``(X/Z, Y/Z)`` of the object point(s) in the camera frame.
    f_number, focal_mm : float
        Aperture number and focal length (mm), > 0.
    rim_radius_mm, rim_distance_mm : float
        The rim's radius (> 0) and its axial distance in front of the entrance pupil, mm.
    depth_mm : float or (...,) array_like
        Depth ``Z`` of the object point(s), mm, beyond the rim (``Z > L``); ``inf``: far field.

    Returns
    -------
    centre : (..., 2) array
        Centre of the rim's disc in pupil radii.
    radius : float or (...,) array
        Its radius in pupil radii.
    """
    values = (f_number, focal_mm, rim_radius_mm)
    if not all(math.isfinite(v) and v > 0 for v in values) or not math.isfinite(rim_distance_mm):
        raise CalibrationError(
            f"F {f_number}, focal length {focal_mm} mm and rim radius {rim_radius_mm} mm must be "
            f"finite and positive and the rim distance {rim_distance_mm} mm finite"
        )
    t = np.asarray(field_tan, dtype=float)
    if t.shape[-1:] != (2,) or not np.all(np.isfinite(t)):
        raise CalibrationError(f"field direction of shape {t.shape} must be finite (..., 2)")
    z = np.asarray(depth_mm, dtype=float)
    if np.any(np.isnan(z)) or np.any(z <= max(rim_distance_mm, 0.0)):
        raise CalibrationError(
            f"object depth {depth_mm} mm must lie beyond the rim ({rim_distance_mm} mm) and the "
            "pupil"
        )
    a = focal_mm / (2.0 * f_number)
    scale = a * (1.0 - rim_distance_mm / z)
    centre = -rim_distance_mm * t / np.asarray(scale)[..., None]
    return centre, rim_radius_mm / scale


MAX_DELTA_PX = 200.0
"""Largest circle-of-confusion radius a blur spot is built for, px (a kernel of ~1600 px)."""


def _check_delta(delta_px) -> float:
    if not (np.isfinite(delta_px) and 0 <= delta_px <= MAX_DELTA_PX):
        raise CalibrationError(
            f"circle-of-confusion radius {delta_px} px must be finite, >= 0 and <= {MAX_DELTA_PX}"
        )
    return float(delta_px)


def _check_rim(side, rim_centre, rim_radius) -> tuple[float, np.ndarray, float]:
    if side not in (1.0, -1.0):
        raise CalibrationError(f"side of the focus {side} must be +1 (beyond) or -1 (nearer)")
    c = np.asarray(rim_centre, dtype=float)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise CalibrationError(f"rim centre {rim_centre} must be two finite pupil coordinates")
    if not (rim_radius > 0) or math.isnan(rim_radius):
        raise CalibrationError(f"rim radius {rim_radius} (pupil radii) must be > 0")
    return float(side), c, float(rim_radius)


def _gaussian_size(delta_px: float) -> int:
    """Width of :func:`cv2.GaussianBlur`'s float kernel for ``sigma = delta`` (4 sigma a side)."""
    return int(round(delta_px * 4 * 2 + 1)) | 1


def _rim_clears(delta_px: float, rim_centre, rim_radius: float) -> bool:
    """True when the rim's disc contains the whole pupil (with the one-pixel soft edge)."""
    return float(np.hypot(*rim_centre)) + 1.0 + 1.0 / delta_px <= rim_radius


def defocus_kernel(
    delta_px: float, side: float = 1.0, rim_centre=(0.0, 0.0), rim_radius: float = math.inf
):
    """Blur spot of a defocused point (Eq. 7), cut by a lens rim (:func:`rim_shadow`).

    Geometrically a defocused point is imaged as the pupil scaled by the CoC radius ``delta`` px
    (a ray through pupil point ``p``, ``|p| <= 1`` in pupil radii, lands ``delta p`` from the
    chief ray), upright for a point beyond the focused distance (``side = +1``) and inverted for
    a nearer one (``side = -1``). The paper's energy model of the uncut spot is the Gaussian of
    Eq. 7, ``G_delta`` (``sigma = delta``), whose tail reaches beyond the geometric disc; it is
    read as the geometric disc ``D`` (uniform, area ``|D|``) spread by a Gaussian ``G_s``,
    ``s = delta / sqrt 2`` (the spread that gives the convolution Eq. 7's second moment). Only
    rays through the pupil carry light, so the rim keeps the transmitted pupil ``T`` (the unit
    disc inside the rim's disc, centre ``rim_centre`` and radius ``rim_radius`` in pupil radii),
    spread by ``G_s``, plus the transmitted share of the fixed difference between Eq. 7 and the
    spread disc::

        k = G_s * 1_T / |D| + (|T| / |D|) (G_delta - G_s * 1_D / |D|)   (clipped at 0, normalised)

    The difference term has no mass and no first moment, so the spot's centroid is the
    transmitted pupil's, ``delta`` times the centroid of ``T``, as a ray trace gives; the
    Gaussian's tail is spread light, not rays, and is never cut as if it were; and without a
    cut (``T = D``) the kernel is ``G_delta`` itself, the kernel :func:`cv2.GaussianBlur` (used
    by :func:`defocus`) builds. The pupil is sampled on the pixel grid with a one-pixel soft
    edge; the clipping of the few negative values left by a thin sliver of pupil moves the
    centroid by under 1 % of ``delta`` at ``delta >= 8`` px.

    Returns
    -------
    (n, n) float32 array, n the width of ``cv2.GaussianBlur``'s kernel (about 8 delta + 1),
    summing to 1
        ``k[j, i]``: the share of a point's energy landing ``(i - n//2, j - n//2)`` px from it.
    """
    delta_px = _check_delta(delta_px)
    if not delta_px > 0:
        raise CalibrationError(f"circle-of-confusion radius {delta_px} px must be > 0")
    return _defocus_kernel(delta_px, *_check_rim(side, rim_centre, rim_radius))


def _defocus_kernel(delta_px: float, side: float, c: np.ndarray, r: float) -> np.ndarray:
    """:func:`defocus_kernel` of checked inputs."""
    n = _gaussian_size(delta_px)
    g1 = cv2.getGaussianKernel(n, delta_px, cv2.CV_64F)[:, 0]
    k = np.outer(g1, g1)
    if not _rim_clears(delta_px, c, r):
        h = n // 2
        offsets = np.arange(-h, h + 1, dtype=np.float64)
        # pupil point of each landing pixel: x along the rows (1, n), y down the columns (n, 1)
        px, py = (side * offsets / delta_px)[None, :], (side * offsets / delta_px)[:, None]
        both = np.empty((n, n, 2))  # the pupil and the transmitted pupil, spread in one call
        pupil, passed = both[..., 0], both[..., 1]
        # the pupil is symmetric about both axes: computed on a quadrant, |offset| / delta, and
        # mirrored (hypot ignores the signs: the same numbers as on the whole grid)
        q = offsets[h:] / delta_px
        quadrant = np.clip(0.5 + (1.0 - np.hypot(q[None, :], q[:, None])) * delta_px, 0.0, 1.0)
        mirror = np.abs(np.arange(-h, h + 1))
        pupil[...] = quadrant[mirror[:, None], mirror[None, :]]
        through = np.clip(0.5 + (r - np.hypot(px - c[0], py - c[1])) * delta_px, 0.0, 1.0)
        np.multiply(pupil, through, out=passed)
        share = float(passed.sum() / pupil.sum())  # |T| / |D|
        if not share > 0:
            raise CalibrationError("the rim blocks every ray of the blur spot")
        s = delta_px / math.sqrt(2.0)
        spread = cv2.GaussianBlur(both, (0, 0), sigmaX=s, borderType=cv2.BORDER_CONSTANT)
        # G_s * 1_T / |D| + (|T| / |D|) (G_delta - G_s * 1_D / |D|)
        k = np.clip((spread[..., 1] + share * (k * pupil.sum() - spread[..., 0])), 0.0, None)
    return (k / k.sum()).astype(np.float32)


def defocus_vignetted(image, delta_px: float, side: float, rim_centre, rim_radius: float):
    """Blur an image by :func:`defocus_kernel` (a convolution); below 0.05 px the image is left
    as it is, and when the rim clears the pupil the result is that of :func:`defocus` (the
    kernel is then the same Gaussian)."""
    img = np.asarray(image, dtype=np.float32)
    delta_px = _check_delta(delta_px)
    side, c, r = _check_rim(side, rim_centre, rim_radius)
    if not np.all(np.isfinite(img)):
        raise CalibrationError(f"the {img.shape} image to blur has NaN or inf pixels")
    if delta_px < 0.05:
        return img.copy()
    if _rim_clears(delta_px, c, r):  # the rim passes every ray: Eq. 7's Gaussian
        return defocus(img, delta_px)
    k = _defocus_kernel(delta_px, side, c, r)
    # filter2D correlates: flip the kernel to convolve
    return cv2.filter2D(img, cv2.CV_32F, k[::-1, ::-1].copy(), borderType=cv2.BORDER_REPLICATE)
