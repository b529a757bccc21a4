"""AX = XB by OpenCV's closed forms, and the motion-diversity check every hand-eye solver runs.

:func:`opencv_handeye` wraps ``cv2.calibrateHandEye`` (Tsai, Park, Horaud, Andreff, Daniilidis):
the pose of the sensor on the flange from flange poses and the poses of a fixed target in the
sensor frame. Before OpenCV sees the poses, :func:`check_rotation_diversity` refuses motions that
leave the rotation undetermined (pure translations, rotations about one axis, repeated poses) by
the library's one motion-diversity rule, :func:`check_motions`, which the hand-eye calibration of
a cell runs on its own choice of motions too.
"""

from __future__ import annotations

from contextlib import contextmanager

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError

#: smallest rotation (rad) of a motion between two poses that counts for Tsai-Lenz, and smallest
#: angle between the axes of two such motions (the dualarm chain's rotation diversity check)
MIN_PAIR_ROTATION = np.deg2rad(0.5)
#: Rotation (rad) below which a motion counts as none, and axes this close as one axis, in every
#: call of :func:`opencv_handeye`: 0.01 deg (36 arc seconds), below the orientation repeatability
#: of an industrial robot, so such motions carry no information on the hand-eye rotation.
DEGENERATE_ROTATION = np.deg2rad(0.01)

OPENCV_METHODS = {
    "Tsai": cv2.CALIB_HAND_EYE_TSAI,
    "Park": cv2.CALIB_HAND_EYE_PARK,
    "Horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "Andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "Daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}


def check_rotation_diversity(
    flange2base: np.ndarray, min_rotation: float, tol: float = geo.ORTHONORMAL_TOL
) -> None:
    """Refuse flange poses that do not rotate enough to determine a hand-eye rotation.

    Tsai-Lenz (as ``cv2.calibrateHandEye`` runs it) uses the motion between every pair of poses;
    a pair that does not rotate adds an equation that holds for any rotation and harms nothing.
    The hand-eye rotation is determined once at least two motions rotate by ``min_rotation``
    (rad) or more about axes at least ``min_rotation`` apart (each axis in the frame of the
    motion's first flange, as the method uses it). This is the library's one motion-diversity
    check: :func:`opencv_handeye` and the preliminary AX = XB of the binocular paper run it.

    Parameters
    ----------
    flange2base : array_like, shape (N, 4, 4)
        Flange poses in the base frame (translations in any unit), ``N >= 3``.
    min_rotation : float
        Smallest rotation of a motion, and smallest angle between two motion axes, rad (> 0).
    tol : float
        Orthonormality tolerance of the rotations.

    Returns
    -------
    None

    Raises
    ------
    CalibrationError
        For bad shapes, fewer than 3 poses or a ``min_rotation`` that is not a positive angle;
        when no pair of poses rotates by ``min_rotation`` (the largest rotation named), or all
        rotating motions turn about one axis (the spread of the axes named).
    """
    poses = geo.check_transform("flange poses", flange2base, tol)
    if poses.ndim != 3 or poses.shape[0] < 3:
        raise CalibrationError(
            f"flange poses of shape {poses.shape}: the rotation check needs (N, 4, 4) with N >= 3"
        )
    if not (np.isfinite(min_rotation) and min_rotation > 0.0):
        raise CalibrationError(f"min_rotation must be a positive angle in rad, got {min_rotation}")
    _check_diversity(poses[:, :3, :3], min_rotation)


def _check_diversity(r: np.ndarray, min_rotation: float) -> None:
    """:func:`check_rotation_diversity` on checked rotations ``(N, 3, 3)``, ``N >= 3``: the
    motions of every pair of poses."""
    i, j = np.triu_indices(len(r), 1)
    check_motions(geo.matrix_to_rotvec(np.swapaxes(r[i], -1, -2) @ r[j]), len(r), min_rotation)


def check_motions(rotvec: np.ndarray, n_poses: int, min_rotation: float) -> None:
    """Refuse motions that leave a hand-eye rotation undetermined: the one motion-diversity rule.

    At least one motion must rotate by ``min_rotation`` or more, and the axes of the rotating
    motions must spread by ``min_rotation`` or more (the largest angle between two of them).

    Parameters
    ----------
    rotvec : numpy.ndarray, shape (M, 3)
        Rotation vectors of motions between pairs of poses, each in the frame of the motion's
        first pose, rad.
    n_poses : int
        Poses the motions were formed from (named in the messages).
    min_rotation : float
        Smallest rotation of a motion, and smallest angle between two motion axes, rad (> 0).

    Returns
    -------
    None

    Raises
    ------
    CalibrationError
        When no motion rotates by ``min_rotation`` (the largest rotation named), or all rotating
        motions turn about one axis (the spread of the axes named).
    """
    angles = np.linalg.norm(rotvec, axis=1)
    moving = angles >= min_rotation
    if not np.any(moving):
        raise CalibrationError(
            f"no pair of the {n_poses} poses rotates by {np.degrees(min_rotation):.3g} deg or "
            f"more (largest {np.degrees(angles.max()):.3g} deg): pure translations or repeated "
            "orientations leave the hand-eye rotation undetermined; include rotating motions"
        )
    axes = rotvec[moving] / angles[moving, None]
    # the largest angle between two axes; an axis far enough from the first one settles it
    # without the (M, M) matrix of every pair (M ~ N^2 / 2 motions)
    spread = float(np.arccos(np.clip(np.abs(axes @ axes[0]), 0.0, 1.0).min()))
    if spread < min_rotation:
        spread = max(
            float(np.arccos(np.clip(np.abs(axes[k : k + 512] @ axes.T), 0.0, 1.0).min()))
            for k in range(0, len(axes), 512)
        )
    if spread < min_rotation:
        raise CalibrationError(
            f"the {int(moving.sum())} rotating motions of the {n_poses} poses turn about one "
            f"axis (axes within {np.degrees(spread):.3g} deg, minimum "
            f"{np.degrees(min_rotation):.3g} deg): the hand-eye rotation about that axis and the "
            "translation along it are undetermined; include motions about two axes"
        )


@contextmanager
def quiet_opencv():
    """OpenCV's log silenced within the block (its hand-eye solvers log failures on stderr,
    which the callers report as :class:`CalibrationError` instead), the level restored after."""
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)


def opencv_handeye(
    flange2base,
    target2sensor,
    method: str,
    min_pair_rotation: float = DEGENERATE_ROTATION,
    tol: float = geo.ORTHONORMAL_TOL,
) -> np.ndarray:
    """``sensor2flange`` by ``cv2.calibrateHandEye`` (AX = XB) with a named method.

    Parameters
    ----------
    flange2base : (N, 4, 4) array
        Flange poses in the base frame, mm.
    target2sensor : (N, 4, 4) array
        Pose of a fixed target in the sensor frame at each robot pose, mm.
    method : str
        One of ``"Tsai"``, ``"Park"``, ``"Horaud"``, ``"Andreff"``, ``"Daniilidis"``.
    min_pair_rotation : float, default :data:`DEGENERATE_ROTATION`
        The poses must rotate enough overall (:func:`check_rotation_diversity`): at least two
        motions between pose pairs rotating by this much (rad) or more about axes this far
        apart. Every method takes the rotation axes of the motions, undefined for a pure
        translation, and OpenCV returns a wrong answer (with a message on stderr at most) on
        degenerate motions; poses with equal orientations are fine as long as others rotate.
        :data:`MIN_PAIR_ROTATION` is a safe value for designed poses; values below
        :data:`DEGENERATE_ROTATION` are raised to it (pure translations, rotations about one
        axis and a repeated pose are always refused).
    tol : float
        Orthonormality tolerance of the input rotations. For measured poses with rounded
        rotations, :func:`calstudy.handeye.calibrate.calibrate_handeye` re-projects them.

    Returns
    -------
    (4, 4) array
        ``sensor2flange``.

    Raises
    ------
    CalibrationError
        For an unknown method, fewer than 3 poses, bad shapes, poses without two motions rotating
        by ``min_pair_rotation`` about axes that far apart (pure translations, rotations about
        one axis, repeated poses: the message names the largest rotation or the spread of the
        axes), OpenCV's own failure, or a non-finite OpenCV result.
    """
    if method not in OPENCV_METHODS:
        raise CalibrationError(
            f"unknown hand-eye method {method!r}; use one of {list(OPENCV_METHODS)}"
        )
    g2b = geo.check_transform("flange poses", flange2base, tol)
    t2c = geo.check_transform("target poses", target2sensor, tol)
    if g2b.ndim != 3 or g2b.shape != t2c.shape:
        raise CalibrationError(
            f"flange poses {g2b.shape} and target poses {t2c.shape} must both be (N, 4, 4)"
        )
    if g2b.shape[0] < 3:
        raise CalibrationError(f"AX = XB needs at least 3 poses; got {g2b.shape[0]}")
    if not (np.isfinite(min_pair_rotation) and min_pair_rotation >= 0.0):
        raise CalibrationError(
            f"min_pair_rotation = {min_pair_rotation} must be a finite angle >= 0 in rad"
        )
    # before OpenCV: on degenerate motions it prints to stderr and returns a wrong answer
    _check_diversity(g2b[:, :3, :3], max(float(min_pair_rotation), DEGENERATE_ROTATION))
    try:
        with quiet_opencv():
            rot, trans = cv2.calibrateHandEye(
                list(g2b[:, :3, :3]),
                list(g2b[:, :3, 3:]),
                list(t2c[:, :3, :3]),
                list(t2c[:, :3, 3:]),
                method=OPENCV_METHODS[method],
            )
    except cv2.error as exc:
        raise CalibrationError(
            f"OpenCV {method} hand-eye failed on {g2b.shape[0]} poses: {exc.err or exc}"
        ) from None
    if rot is None or trans is None:
        raise CalibrationError(f"OpenCV {method} hand-eye returned no result")
    out = geo.make_transform(rot, trans.ravel())
    if np.array_equal(out, np.eye(4)):
        # what OpenCV's Tsai returns (logging an error) when no motion rotates enough
        raise CalibrationError(
            f"OpenCV {method} hand-eye failed on {g2b.shape[0]} poses: not enough informative "
            "motions (include larger rotations)"
        )
    if not np.all(np.isfinite(out)):
        raise CalibrationError(f"OpenCV {method} hand-eye returned a non-finite result")
    return out
