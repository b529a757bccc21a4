"""Coded markers seen by a binocular sensor: the detections of one stereo image pair, which
the rig triangulates (Eq. 7 of the ``dualarm`` paper, :meth:`StereoRig.triangulate`).

The observations that :mod:`calstudy.estimators.bundle` (the adjustment, Eq. 9-10) and
:mod:`calstudy.estimators.sfm` (image graph, clusters, splice, the whole reconstruction) share.

Frames: points are triangulated in the *left* (reference) camera frame; the right camera sees
``left2right @ p_left``. Pixels in px, lengths in mm. The rig
(:class:`calstudy.models.stereo.StereoRig`) must have ideal cameras: these steps model no lens
distortion, and refuse a rig whose cameras have one (undistort the image points first).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.models.sensors import PinholeCamera


@dataclass(frozen=True)
class View:
    """The markers detected in one stereo image pair.

    Attributes
    ----------
    ids : numpy.ndarray of int, shape (N,)
        Marker indices, sorted, unique.
    uv_left, uv_right : numpy.ndarray, shape (N, 2)
        Detected centres in the left and right images, px.
    """

    ids: np.ndarray
    uv_left: np.ndarray
    uv_right: np.ndarray


def make_view(ids, uv_left, uv_right) -> View:
    """A :class:`View` after checking shapes, finiteness and unique ids (sorted by id)."""
    i = np.asarray(ids)
    if i.ndim != 1 or (i.size and not np.issubdtype(i.dtype, np.integer)):
        raise CalibrationError(f"marker ids must be a 1-D integer array; got {i.dtype} {i.shape}")
    ul = geo.check_shape("uv_left", uv_left, (i.size, 2))
    ur = geo.check_shape("uv_right", uv_right, (i.size, 2))
    if np.unique(i).size != i.size:
        raise CalibrationError(f"marker ids repeat within one view: {i.tolist()}")
    order = np.argsort(i)
    return View(i[order].astype(int), ul[order], ur[order])


def check_ideal(*cameras: PinholeCamera) -> None:
    """Raise if a camera has lens distortion, which these steps do not model."""
    for camera in cameras:
        if camera.distorted:
            raise CalibrationError(
                f"the camera has lens distortion {camera.dist}; structure from motion here "
                "models ideal pinhole cameras: undistort the image points first"
            )


__all__ = ["View", "check_ideal", "make_view"]
