"""Coded markers seen by a binocular sensor: the detections of one stereo image pair and their
triangulation (Eq. 7 of the ``dualarm`` paper).

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
from calstudy.models.stereo import StereoRig


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


# ----------------------------------------------------------------------------------------------
# triangulation (Eq. 7)


def check_ideal(*cameras: PinholeCamera) -> None:
    """Raise if a camera has lens distortion, which these steps do not model."""
    for camera in cameras:
        if camera.distorted:
            raise CalibrationError(
                f"the camera has lens distortion {camera.dist}; structure from motion here "
                "models ideal pinhole cameras: undistort the image points first"
            )


def _projection_matrix(camera: PinholeCamera, world2cam: np.ndarray) -> np.ndarray:
    check_ideal(camera)
    return camera.K @ world2cam[:3, :]


def triangulate(rig: StereoRig, uv_left, uv_right) -> np.ndarray:
    """Points ``(N, 3)`` in the left camera frame from matched centres (Eq. 7, linear).

    Each point solves the four linear equations ``(u m_3 - m_1) X = 0``, ``(v m_3 - m_2) X = 0``
    of both cameras' projection matrices ``M`` in the least-squares sense.
    """
    ul = geo.check_shape("uv_left", uv_left, (None, 2))
    ur = geo.check_shape("uv_right", uv_right, (ul.shape[0], 2))
    rows = []
    for m, uv in (
        (_projection_matrix(rig.left, np.eye(4)), ul),
        (_projection_matrix(rig.right, rig.left2right), ur),
    ):
        rows.append(uv[:, 0:1, None] * m[None, 2:3, :] - m[None, 0:1, :])
        rows.append(uv[:, 1:2, None] * m[None, 2:3, :] - m[None, 1:2, :])
    a = np.concatenate(rows, axis=1)  # (N, 4, 4)
    lhs, rhs = a[:, :, :3], -a[:, :, 3]
    ata = np.einsum("nki,nkj->nij", lhs, lhs)
    atb = np.einsum("nki,nk->ni", lhs, rhs)
    cond = np.linalg.cond(ata) if len(ata) else np.zeros(0)
    if np.any(cond > 1e14):
        i = int(np.argmax(cond))
        raise CalibrationError(f"point {i} cannot be triangulated (condition number {cond[i]:.3g})")
    return np.linalg.solve(ata, atb[..., None])[..., 0]


__all__ = ["View", "check_ideal", "make_view", "triangulate"]
