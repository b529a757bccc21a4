"""Input handling of hand-eye calibration: pose lists into the canonical form ``A_i X B_i = Z``.

Storage conventions, units and near-orthonormal rotations (:func:`prepare_poses`) and the spread
of the robot motions (:func:`motion_conditioning`, on a linear number of pose pairs). Whether the
declared conventions and units fit is judged after the fit
(:mod:`~calstudy.handeye.checks`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.userfile import LENGTH_UNITS
from calstudy.estimators.axxb import check_motions
from calstudy.handeye.refine import spread_subset

#: largest ``max |R^T R - I|`` re-projected to SO(3) silently: rotation entries rounded to 4
#: decimals are off by up to about 1.7e-4, single-precision ones by 1e-7
ORTHO_TOL = 1e-3
#: smallest rotation of a motion that counts, and smallest angle between two motion axes, of
#: the motion check a calibration runs (:func:`calstudy.estimators.axxb.check_motions`)
MIN_ROTATION = np.deg2rad(2.0)
#: storage forms of the robot poses (the first two are what the study uses)
ROBOT_CONVENTIONS = {
    "gripper2base": False,
    "flange2base": False,
    "base2gripper": True,
    "base2flange": True,
}
#: storage forms of the camera poses
CAMERA_CONVENTIONS = {"target2camera": False, "camera2target": True}
SETUPS = ("eye_in_hand", "eye_to_hand")


# ----------------------------------------------------------------------------------------------
# input handling


@dataclass
class PreparedPoses:
    """Pose lists in the canonical form ``A_i X B_i = Z`` (mm, proper rotations).

    Attributes
    ----------
    a : (N, 4, 4) array
        ``flange2base`` (eye-in-hand) or ``base2flange`` (eye-to-hand), mm.
    b : (N, 4, 4) array
        ``target2camera``, mm.
    ids : (N,) int array
        Pose ids (row numbers from 0 when none were given).
    max_correction : float
        Largest change of a rotation entry made by re-projecting to SO(3) (0 for exact input).
    worst_pose : int
        Id of the pose with that largest correction.
    setup, robot_convention, camera_convention : str
        What the input was declared to be.
    robot_unit, camera_unit : str
        Units of the input translations (converted to mm here).
    """

    a: np.ndarray
    b: np.ndarray
    ids: np.ndarray
    max_correction: float
    worst_pose: int
    setup: str
    robot_convention: str
    camera_convention: str
    robot_unit: str
    camera_unit: str


def parse_convention(convention: str | Sequence[str] | None) -> tuple[str, str]:
    """``(robot, camera)`` storage forms from ``"base2gripper"``, ``("base2gripper",
    "camera2target")``, ``"base2gripper,camera2target"`` or None (``gripper2base,
    target2camera``); a name given alone sets its side and keeps the default of the other."""
    robot, camera = "gripper2base", "target2camera"
    if convention is None:
        return robot, camera
    names = convention.replace("/", ",").split(",") if isinstance(convention, str) else convention
    for name in (str(n).strip() for n in names):
        if name in ROBOT_CONVENTIONS:
            robot = name
        elif name in CAMERA_CONVENTIONS:
            camera = name
        else:
            raise CalibrationError(
                f"unknown pose convention {name!r}; robot poses: {', '.join(ROBOT_CONVENTIONS)}; "
                f"camera poses: {', '.join(CAMERA_CONVENTIONS)}"
            )
    return robot, camera


def unit_factor(which: str, unit: str) -> float:
    """Millimetres per ``unit``; CalibrationError naming ``which`` side for an unknown unit."""
    if unit not in LENGTH_UNITS:
        raise CalibrationError(
            f"unknown {which} unit {unit!r}; use one of {', '.join(LENGTH_UNITS)}"
        )
    return LENGTH_UNITS[unit]


def _reorthonormalise(name: str, poses: np.ndarray, ids: np.ndarray, tol: float):
    """Project the rotations of ``poses`` to SO(3); return them and the largest correction."""
    rot = poses[:, :3, :3]
    gram = np.einsum("nji,njk->nik", rot, rot) - np.eye(3)
    dev = np.abs(gram).reshape(-1, 9).max(axis=1)
    worst = int(np.argmax(dev))
    if dev[worst] > tol:
        raise CalibrationError(
            f"{name} of pose {ids[worst]} (row {worst}) is not a rotation: max |R^T R - I| = "
            f"{dev[worst]:.3g} exceeds the re-orthonormalisation tolerance {tol:g}; check the "
            "rotation form of that pose (degrees vs radians, quaternion order, row vs column "
            "major), or pass a larger ortho_tol if the data are known to be this coarse"
        )
    det = np.linalg.det(rot)
    if np.any(det < 0):
        bad = int(np.argmax(det < 0))
        raise CalibrationError(
            f"{name} of pose {ids[bad]} (row {bad}) is a reflection (det = {det[bad]:.6g}); "
            "a left-handed frame cannot be a robot or camera pose"
        )
    u, _, vt = np.linalg.svd(rot)
    fixed = u @ vt
    out = poses.copy()
    out[:, :3, :3] = fixed
    corr = np.abs(fixed - rot).reshape(-1, 9).max(axis=1)
    k = int(np.argmax(corr))
    return out, float(corr[k]), k


def check_pose_array(name: str, poses) -> np.ndarray:
    """``poses`` as a finite ``(N, 4, 4)`` array of homogeneous transforms, or CalibrationError."""
    p = geo.check_finite(name, poses)
    if p.ndim != 3 or p.shape[1:] != (4, 4):
        raise CalibrationError(f"{name} has shape {p.shape}; expected (N, 4, 4)")
    if p.shape[0] == 0:
        raise CalibrationError(f"{name}: no poses (shape {p.shape}); hand-eye needs at least 3")
    bottom = np.abs(p[:, 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1)
    if bottom.max() > 1e-9:
        bad = int(np.argmax(bottom))
        raise CalibrationError(
            f"{name}: pose at row {bad} has bottom row {p[bad, 3]} (off [0 0 0 1] by "
            f"{bottom[bad]:.3g}); is it a 4 x 4 homogeneous transform?"
        )
    return p


def _paired_arrays(flange2base, target2camera, ids, ortho_tol: float):
    """The two pose lists as checked arrays of equal length, their ids, and a checked
    ``ortho_tol``: the first checks of :func:`prepare_poses`."""
    a = check_pose_array("robot poses", flange2base)
    b = check_pose_array("camera poses", target2camera)
    if a.shape[0] != b.shape[0]:
        raise CalibrationError(
            f"{a.shape[0]} robot poses but {b.shape[0]} camera poses; they must pair up"
        )
    ids = np.arange(a.shape[0]) if ids is None else np.asarray(ids).astype(int)
    if ids.shape != (a.shape[0],):
        raise CalibrationError(f"ids has shape {ids.shape}; expected ({a.shape[0]},)")
    if not 0 < ortho_tol < 0.1:
        raise CalibrationError(f"ortho_tol must be in (0, 0.1); got {ortho_tol:g}")
    return a, b, ids


def prepare_poses(
    flange2base,
    target2camera,
    *,
    setup: str = "eye_in_hand",
    convention: str | Sequence[str] | None = None,
    robot_unit: str = "mm",
    camera_unit: str = "mm",
    ortho_tol: float = ORTHO_TOL,
    ids=None,
) -> PreparedPoses:
    """Check, convert and re-orthonormalise two pose lists into the canonical form.

    Parameters
    ----------
    flange2base : (N, 4, 4) array
        Robot poses as stored (``convention`` says whether gripper-to-base or base-to-gripper),
        translations in ``robot_unit``.
    target2camera : (N, 4, 4) array
        Target poses measured by the camera as stored (target-to-camera or camera-to-target),
        translations in ``camera_unit``.
    setup : {"eye_in_hand", "eye_to_hand"}
        Camera on the flange (target fixed in the cell) or camera fixed (target on the flange).
    convention : str or pair of str, optional
        Storage forms, see :func:`parse_convention`; default ``("gripper2base",
        "target2camera")``.
    robot_unit, camera_unit : {"mm", "cm", "m", "in"}
        Units of the stored translations; the output is in mm.
    ortho_tol : float
        Largest ``max |R^T R - I|`` that is re-projected to SO(3); beyond it the pose is refused.
    ids : (N,) int array, optional
        Pose ids used in messages (default 0 .. N-1).

    Returns
    -------
    PreparedPoses

    Raises
    ------
    CalibrationError
        For bad shapes, unequal lengths, non-finite values, a rotation off by more than
        ``ortho_tol`` or a reflection (naming the pose), an unknown convention, setup or unit.
    """
    if setup not in SETUPS:
        raise CalibrationError(f"unknown setup {setup!r}; use one of {', '.join(SETUPS)}")
    robot_conv, camera_conv = parse_convention(convention)
    a, b, ids = _paired_arrays(flange2base, target2camera, ids, ortho_tol)
    a, corr_a, k_a = _reorthonormalise("robot rotation", a, ids, ortho_tol)
    b, corr_b, k_b = _reorthonormalise("camera rotation", b, ids, ortho_tol)
    a[:, :3, 3] *= unit_factor("robot", robot_unit)
    b[:, :3, 3] *= unit_factor("camera", camera_unit)
    if ROBOT_CONVENTIONS[robot_conv]:
        a = geo.invert(a)
    if CAMERA_CONVENTIONS[camera_conv]:
        b = geo.invert(b)
    if setup == "eye_to_hand":
        a = geo.invert(a)
    worst = ids[k_a] if corr_a >= corr_b else ids[k_b]
    return PreparedPoses(
        a=a,
        b=b,
        ids=ids,
        max_correction=max(corr_a, corr_b),
        worst_pose=int(worst),
        setup=setup,
        robot_convention=robot_conv,
        camera_convention=camera_conv,
        robot_unit=robot_unit,
        camera_unit=camera_unit,
    )


# ----------------------------------------------------------------------------------------------
# conditioning of the motions


@dataclass
class Conditioning:
    """How well the robot motions determine the calibration.

    Attributes
    ----------
    n_poses, n_distinct : int
        Poses given, and distinct robot poses among them.
    max_rotation_deg : float
        Largest rotation between two robot poses, deg.
    axis_spread : float
        Ratio of the 2nd to the 1st singular value of the relative rotation vectors (0: one
        axis; about 0.5-1 for well spread axes).
    axis_spread_3 : float
        Ratio of the 3rd to the 1st singular value.
    jacobian_condition : float
        Condition number of the refinement's whitened Jacobian (nan before refinement).
    """

    n_poses: int
    n_distinct: int
    max_rotation_deg: float
    axis_spread: float
    axis_spread_3: float
    jacobian_condition: float = float("nan")


#: pose counts up to which :func:`motion_pairs` takes every pair
ALL_PAIRS_UP_TO = 30


def motion_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A linear number of pose pairs ``(i, j)`` for ``n`` poses: every pair up to
    :data:`ALL_PAIRS_UP_TO` poses, else each pose with the poses a third, a half and two thirds
    of the series later (``3 n`` pairs; neighbours in time, which rotate least, are left out)."""
    if n <= ALL_PAIRS_UP_TO:
        return np.triu_indices(n, 1)
    i = np.tile(np.arange(n), 3)
    j = (i + np.repeat([n // 3, n // 2, (2 * n) // 3], n)) % n
    return i, j


def motion_conditioning(a: np.ndarray) -> Conditioning:
    """Measure, and refuse when degenerate, the spread of the robot motions ``a`` (N, 4, 4).

    Relative motions ``inv(A_i) A_j`` of the pairs of :func:`motion_pairs` (linear in N) and of
    every pair of the well-spread poses of :func:`spread_subset` are formed; their rotation
    vectors (in the flange frame) give the largest rotation and the axis spread.

    Raises
    ------
    CalibrationError
        Fewer than 3 poses; fewer than 3 distinct robot poses (duplicates only); no motion
        rotating by :data:`MIN_ROTATION`, or rotating motions whose axes lie within
        :data:`MIN_ROTATION` of one axis (:func:`calstudy.estimators.axxb.check_motions`). The
        message names the cause and its number.
    """
    n = a.shape[0]
    if n < 3:
        raise CalibrationError(f"hand-eye calibration needs at least 3 poses; got {n}")
    key = np.concatenate([np.round(a[:, :3, :3], 6).reshape(n, 9), np.round(a[:, :3, 3], 3)], 1)
    n_distinct = len(np.unique(key, axis=0))
    if n_distinct < 3:
        raise CalibrationError(
            f"the {n} poses are duplicates of only {n_distinct} distinct robot pose(s); "
            "hand-eye calibration needs at least 3 distinct poses rotating about 2 axes"
        )
    i, j = motion_pairs(n)
    sub = spread_subset(a)
    si, sj = np.triu_indices(len(sub), 1)
    i, j = np.concatenate([i, sub[si]]), np.concatenate([j, sub[sj]])
    rel = np.einsum("nji,njk->nik", a[i, :3, :3], a[j, :3, :3])
    rv = geo.so3_log(rel)
    check_motions(rv, n, MIN_ROTATION)
    # sign-free axes: the outer-product sum is the same for +k and -k
    s = np.sqrt(np.clip(np.linalg.eigvalsh(rv.T @ rv)[::-1], 0.0, None))
    max_rotation = float(np.rad2deg(np.linalg.norm(rv, axis=1).max()))
    return Conditioning(n, n_distinct, max_rotation, float(s[1] / s[0]), float(s[2] / s[0]))
