"""Input handling of hand-eye calibration: pose lists into the canonical form ``A_i X B_i = Z``.

Storage conventions, units and near-orthonormal rotations (:func:`prepare_poses`), the spread of
the robot motions (:func:`motion_conditioning`) and the check that the declared convention and
units fit the data better than the alternatives (:func:`convention_check`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.handeye import opencv_handeye
from calstudy.estimators.handeye_refine import (
    check_proper,
    log_so3,
    pose_residuals,
    pose_scale,
    target_in_world,
)

#: largest ``max |R^T R - I|`` re-projected to SO(3) silently (rounded or single-precision data)
ORTHO_TOL = 1e-4
#: another convention (or unit factor) must fit this much better to be reported
CONVENTION_FACTOR = 5.0
#: largest rotation between two poses below which the motions count as pure translations
MIN_ROTATION = np.deg2rad(2.0)
#: declared readings fitting better than this (rad, or mm per mm of distance) are never questioned
CONVENTION_FLOOR = 1e-6
#: smallest ratio of the 2nd to the 1st singular value of the relative rotation vectors
MIN_AXIS_SPREAD = 0.05
#: translation units accepted, in mm
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
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
    if unit not in UNITS_MM:
        raise CalibrationError(f"unknown {which} unit {unit!r}; use one of {', '.join(UNITS_MM)}")
    return UNITS_MM[unit]


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


def motion_conditioning(a: np.ndarray) -> Conditioning:
    """Measure, and refuse when degenerate, the spread of the robot motions ``a`` (N, 4, 4).

    Relative motions ``inv(A_i) A_j`` of all pairs are formed; their rotation vectors (in the
    flange frame) give the largest rotation and the axis spread.

    Raises
    ------
    CalibrationError
        Fewer than 3 poses; fewer than 3 distinct robot poses (duplicates only); pure
        translations (largest rotation below :data:`MIN_ROTATION`); rotations about one axis
        (axis spread below :data:`MIN_AXIS_SPREAD`). The message names the cause and its number.
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
    i, j = np.triu_indices(n, 1)
    rel = np.einsum("nji,njk->nik", a[i, :3, :3], a[j, :3, :3])
    rv = log_so3(rel)
    ang = np.linalg.norm(rv, axis=1)
    if ang.max() < MIN_ROTATION:
        raise CalibrationError(
            f"pure translations: the largest rotation between two of the {n} robot poses is "
            f"{np.rad2deg(ang.max()):.3g} deg (below {np.rad2deg(MIN_ROTATION):g} deg), so the "
            "camera translation is undetermined; add poses that rotate the flange about at "
            "least two non-parallel axes"
        )
    # sign-free axes: the outer-product sum is the same for +k and -k
    s = np.sqrt(np.clip(np.linalg.eigvalsh(rv.T @ rv)[::-1], 0.0, None))
    spread, spread3 = float(s[1] / s[0]), float(s[2] / s[0])
    if spread < MIN_AXIS_SPREAD:
        raise CalibrationError(
            f"rotations about one axis only: the relative rotation axes of the {n} poses are "
            f"parallel (axis spread {spread:.3g}, below {MIN_AXIS_SPREAD:g}), so the camera "
            "translation along that axis is undetermined; add poses rotating about another axis"
        )
    return Conditioning(n, n_distinct, float(np.rad2deg(ang.max())), spread, spread3)


# ----------------------------------------------------------------------------------------------
# convention and unit check


@dataclass
class ConventionCheck:
    """Residual scores of the declared storage convention and of the alternatives.

    Attributes
    ----------
    scores : dict
        ``{(robot_inverted, camera_inverted, camera_factor): score}``; ``(False, False, 1.0)`` is
        the declared reading.
    message : str
        What fits better, or "" if the declared reading fits best.
    """

    scores: dict
    message: str = ""


def convention_check(a: np.ndarray, b: np.ndarray) -> ConventionCheck:
    """Compare the declared reading of the canonical poses with the other storage conventions.

    Each alternative (robot poses inverted, camera poses inverted, both; camera translations
    times 1000 or 1/1000) is solved by OpenCV's Park method and scored by
    :func:`residual_score` over the median per-pose residual (robust to an outlier pose). If an
    alternative beats the declared reading by :data:`CONVENTION_FACTOR`, ``message`` says which.

    Inverting *both* lists is not tried: it fits exactly as well (``A_i^-1 Z B_i^-1 = X``, the
    roles of ``X`` and ``Z`` swap), so the data cannot tell it apart; :func:`calibrate_handeye`
    notes instead when the camera offset comes out larger than the target distance.
    """
    # OpenCV's solvers use all pose pairs; 20 poses tell conventions apart as well as 100
    pick = np.unique(np.linspace(0, len(a) - 1, min(len(a), 20)).astype(int))
    a, b = a[pick], b[pick]
    scores = {}
    for r_inv, c_inv in ((False, False), (True, False), (False, True)):
        for factor in (1.0, 1000.0, 0.001):
            if True:
                aa = geo.invert(a) if r_inv else a
                bb = geo.invert(b) if c_inv else b.copy()
                bb[:, :3, 3] *= factor
                try:
                    x = check_proper("Park", opencv_handeye(aa, bb, "Park"))
                    res = pose_residuals(aa, bb, x, target_in_world(aa, bb, x))
                    per = np.sqrt(
                        np.sum(res[:, 3:] ** 2, 1)
                        + np.sum(res[:, :3] ** 2, 1) / pose_scale(bb) ** 2
                    )
                    scores[(r_inv, c_inv, factor)] = float(np.median(per))
                except (CalibrationError, cv2.error):
                    scores[(r_inv, c_inv, factor)] = np.inf
    declared = scores[(False, False, 1.0)]
    best_key = min(scores, key=scores.get)
    fine = declared < CONVENTION_FLOOR or scores[best_key] * CONVENTION_FACTOR >= declared
    if fine or not np.isfinite(scores[best_key]):
        return ConventionCheck(scores)
    r_inv, c_inv, factor = best_key
    what = []
    if r_inv:
        what.append("the robot poses inverted (base-to-gripper instead of gripper-to-base?)")
    if c_inv:
        what.append("the camera poses inverted (camera-to-target instead of target-to-camera?)")
    if factor != 1.0:
        what.append(
            f"the camera translations times {factor:g} (robot and camera in different units, "
            "mm and m?)"
        )
    msg = (
        f"the poses fit {declared / scores[best_key]:.3g} times better with "
        + " and ".join(what)
        + f" (residual score {scores[best_key]:.3g} against {declared:.3g} as declared); "
        "set convention=, robot_unit= or camera_unit= to what the data are"
    )
    return ConventionCheck(scores, msg)
