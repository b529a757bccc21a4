"""Hand-eye calibration of a cell from measured pose lists: AX = XB and AX = ZB.

The input a researcher usually has is two lists of poses taken at the same instants: the robot
flange in the base frame (from the controller) and a calibration target in the camera frame (from
the camera's pose estimation). This module turns them into a calibration with its uncertainty.

Problem form. With ``A_i = flange2base_i``, ``B_i = target2camera_i``, the unknown
``X = camera2flange`` and the fixed target ``Z = target2base``, every pose satisfies

.. math:: A_i X B_i = Z,

the robot-world-hand-eye form AX = ZB (OpenCV's ``calibrateRobotWorldHandEye``). The classic
AX = XB form (``calibrateHandEye``) eliminates ``Z`` from pairs of poses; both lead to the same
maximum-likelihood problem in ``(X, Z)``. For a camera fixed in the cell and a target on the
flange (``setup="eye_to_hand"``) the robot poses are inverted, ``A_i = base2flange_i``, and the
unknowns become ``X = camera2base`` and ``Z = target2flange``.

Steps of :func:`calibrate_handeye` and :func:`calibrate_robot_world_handeye`:

1. :func:`prepare_poses`: storage convention, units, near-orthonormal rotations re-projected to
   SO(3) (largest correction reported), beyond ``ortho_tol`` a :class:`CalibrationError`.
2. :func:`motion_conditioning`: refuses too few or duplicate poses, pure translations and rotations
   about a single axis, naming the cause.
3. Closed forms (OpenCV's Tsai, Park, Horaud, Andreff, Daniilidis; or Shah, Li), each scored by
   its per-pose residual; a result far above the best (factor :data:`REFUSE_FACTOR`) is refused.
4. :func:`convention_check`: the other storage conventions and a factor-1000 unit mix are tried;
   if one fits far better, the call refuses (or warns) and says which.
5. :func:`refine_ml`: maximum likelihood on SE(3) residuals of the target pose (per-pose weights,
   analytic Jacobian), optionally robust (Huber or Cauchy by iterative reweighting, or RANSAC over
   pose triplets), or on the reprojection error when target points and pixels are given.

Noise model of the refinement: the measured target pose is ``B_i exp(xi_i)`` with a rotation
error ``N(0, sigma_rot^2 I)`` (rad) and a translation error ``N(0, sigma_trans^2 I)`` (mm); robot
poses are exact. The residuals are whitened with these, so the covariance at the truth,
``(J^T J)^-1``, is the Cramer-Rao bound (:func:`handeye_crb`).
"""

from __future__ import annotations

import csv
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.estimation import Estimate, covariance_from_jacobian
from calstudy.estimators.handeye import OPENCV_METHODS, opencv_handeye

#: OpenCV's AX = ZB (robot-world-hand-eye) solvers
OPENCV_RWHE_METHODS = {
    "Shah": cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    "Li": cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI,
}
#: largest ``max |R^T R - I|`` re-projected to SO(3) silently (rounded or single-precision data)
ORTHO_TOL = 1e-4
#: a closed form whose residual score exceeds the best one's by this factor is refused
REFUSE_FACTOR = 10.0
#: another convention (or unit factor) must fit this much better to be reported
CONVENTION_FACTOR = 5.0
#: largest rotation between two poses below which the motions count as pure translations
MIN_ROTATION = np.deg2rad(2.0)
#: declared readings fitting better than this (rad, or mm per mm of distance) are never questioned
CONVENTION_FLOOR = 1e-6
#: smallest ratio of the 2nd to the 1st singular value of the relative rotation vectors
MIN_AXIS_SPREAD = 0.05
#: condition number of the whitened Jacobian above which the refinement is refused
MAX_JACOBIAN_CONDITION = 1e10
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
ROBUST = (None, "huber", "cauchy", "ransac")
#: median of the chi-square distribution with 3 degrees of freedom (robust noise estimate)
_CHI2_3_MEDIAN = float(chi2.median(3))
PARAM_NAMES = ["X_rx", "X_ry", "X_rz", "X_tx", "X_ty", "X_tz"] + [
    "Z_rx",
    "Z_ry",
    "Z_rz",
    "Z_tx",
    "Z_ty",
    "Z_tz",
]


# ----------------------------------------------------------------------------------------------
# SO(3) Jacobians, batched


def _so3_jr(phi: np.ndarray) -> np.ndarray:
    """Right Jacobian of SO(3), ``exp(phi + e) = exp(phi) exp(Jr(phi) e)``: (N, 3) -> (N, 3, 3)."""
    phi = np.atleast_2d(phi)
    th = np.linalg.norm(phi, axis=1)
    k = geo.skew(phi)
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5, (1.0 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0, (ths - np.sin(ths)) / ths**3)
    return np.eye(3) - a[:, None, None] * k + b[:, None, None] * (k @ k)


def _so3_jr_inv(phi: np.ndarray) -> np.ndarray:
    """Inverse of the right Jacobian of SO(3): (N, 3) -> (N, 3, 3)."""
    phi = np.atleast_2d(phi)
    th = np.linalg.norm(phi, axis=1)
    k = geo.skew(phi)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    c = np.where(small, 1.0 / 12.0, 1.0 / ths**2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths)))
    return np.eye(3) + 0.5 * k + c[:, None, None] * (k @ k)


def _log_so3(rot: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_rotvec()


def _exp_so3(rotvec: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(np.atleast_2d(rotvec)).as_matrix()


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


def _unit_factor(which: str, unit: str) -> float:
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


def _check_pose_array(name: str, poses) -> np.ndarray:
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
    a = _check_pose_array("robot poses", flange2base)
    b = _check_pose_array("camera poses", target2camera)
    if a.shape[0] != b.shape[0]:
        raise CalibrationError(
            f"{a.shape[0]} robot poses but {b.shape[0]} camera poses; they must pair up"
        )
    ids = np.arange(a.shape[0]) if ids is None else np.asarray(ids).astype(int)
    if ids.shape != (a.shape[0],):
        raise CalibrationError(f"ids has shape {ids.shape}; expected ({a.shape[0]},)")
    if not 0 < ortho_tol < 0.1:
        raise CalibrationError(f"ortho_tol must be in (0, 0.1); got {ortho_tol:g}")
    a, corr_a, k_a = _reorthonormalise("robot rotation", a, ids, ortho_tol)
    b, corr_b, k_b = _reorthonormalise("camera rotation", b, ids, ortho_tol)
    a[:, :3, 3] *= _unit_factor("robot", robot_unit)
    b[:, :3, 3] *= _unit_factor("camera", camera_unit)
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
    rv = _log_so3(rel)
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
# residuals and closed forms


def target_in_world(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Chordal mean of ``A_i X B_i`` over the poses: the fixed target ``Z`` given ``X`` (4, 4)."""
    zs = a @ x @ b
    return geo.make_transform(geo.project_to_so3(zs[:, :3, :3].mean(axis=0)), zs[:, :3, 3].mean(0))


def pose_residuals(a, b, x, z) -> np.ndarray:
    """Per-pose residuals ``(N, 6)``: ``[t_B - t_pred (mm, camera frame), log(R_pred^T R_B) (rad)]``
    of the measured ``B_i`` against the prediction ``inv(X) inv(A_i) Z``."""
    pred = geo.invert(x) @ geo.invert(a) @ z
    rot = _log_so3(np.einsum("nji,njk->nik", pred[:, :3, :3], b[:, :3, :3]))
    return np.concatenate([b[:, :3, 3] - pred[:, :3, 3], rot], axis=1)


def residual_score(res: np.ndarray, scale_mm: float) -> float:
    """Scale-free size of per-pose residuals ``(N, 6)``: RMS rotation (rad) and RMS translation
    divided by ``scale_mm`` (the camera-target distance), combined as ``sqrt(a^2 + b^2)``.

    A rotation error ``theta`` moves the target by about ``theta * distance``, so the two parts
    weigh alike whatever the units and size of the cell.
    """
    rot = np.mean(np.sum(res[:, 3:] ** 2, axis=1))
    trans = np.mean(np.sum(res[:, :3] ** 2, axis=1)) / scale_mm**2
    return float(np.sqrt(rot + trans))


def _scale(b: np.ndarray) -> float:
    return max(float(np.median(np.linalg.norm(b[:, :3, 3], axis=1))), 1e-9)


@dataclass
class ClosedForm:
    """One closed-form solution and its fit to the data.

    Attributes
    ----------
    method : str
    x, z : (4, 4) arrays or None
        The solution (None if the solver failed).
    rms_rot_deg, rms_trans_mm : float
        RMS per-pose residual of the target pose, deg and mm.
    score : float
        :func:`residual_score` (dimensionless).
    seconds : float
        Wall time of the solver call.
    refused : str
        Why it was refused ("" if accepted).
    """

    method: str
    x: np.ndarray | None
    z: np.ndarray | None
    rms_rot_deg: float
    rms_trans_mm: float
    score: float
    seconds: float
    refused: str = ""


def _proper(name: str, t: np.ndarray) -> np.ndarray:
    """``t`` if it is a finite rigid transform; else CalibrationError (OpenCV's solvers can return
    a reflection or NaN on inconsistent data)."""
    if not np.all(np.isfinite(t)):
        raise CalibrationError(f"{name} returned a non-finite result")
    r = t[:3, :3]
    dev = np.abs(r.T @ r - np.eye(3)).max()
    if dev > 1e-6 or np.linalg.det(r) < 0:
        raise CalibrationError(
            f"{name} returned no rotation (max |R^T R - I| = {dev:.3g}, det {np.linalg.det(r):.3g})"
        )
    return t


def _opencv_rwhe(a: np.ndarray, b: np.ndarray, method: str) -> tuple[np.ndarray, np.ndarray]:
    """``(X, Z)`` by ``cv2.calibrateRobotWorldHandEye``: it solves ``B = inv(X) inv(A) Z`` and
    returns ``inv(Z)`` ("base2world") and ``inv(X)`` ("gripper2cam")."""
    ainv = geo.invert(a)
    r_w, t_w, r_g, t_g = cv2.calibrateRobotWorldHandEye(
        list(b[:, :3, :3]),
        list(b[:, :3, 3:]),
        list(ainv[:, :3, :3]),
        list(ainv[:, :3, 3:]),
        method=OPENCV_RWHE_METHODS[method],
    )
    x = geo.invert(geo.make_transform(r_g, t_g.ravel()))
    z = geo.invert(geo.make_transform(r_w, t_w.ravel()))
    return x, z


def closed_forms(a: np.ndarray, b: np.ndarray, methods: Sequence[str]) -> list[ClosedForm]:
    """Run OpenCV closed forms on canonical poses and score them; refuse the inconsistent ones.

    Parameters
    ----------
    a, b : (N, 4, 4) arrays
        Canonical poses (:class:`PreparedPoses`), mm.
    methods : sequence of str
        Names from :data:`OPENCV_METHODS` (AX = XB; ``Z`` then follows by a chordal mean) and
        :data:`OPENCV_RWHE_METHODS` (AX = ZB).

    Returns
    -------
    list of ClosedForm
        In the order of ``methods``; a result whose score exceeds the best by
        :data:`REFUSE_FACTOR`, or that failed or is not finite, has ``refused`` set.
    """
    import time

    scale = _scale(b)
    out = []
    for m in methods:
        start = time.perf_counter()
        reason = ""
        try:
            if m in OPENCV_RWHE_METHODS:
                x, z = _opencv_rwhe(a, b, m)
                _proper(m, z)
            else:
                x = opencv_handeye(a, b, m)
            x = _proper(m, x)
            if m not in OPENCV_RWHE_METHODS:
                z = target_in_world(a, b, x)
            res = pose_residuals(a, b, x, z)
        except (CalibrationError, cv2.error) as exc:
            x = z = None
            res = None
            reason = f"solver failed: {str(exc).splitlines()[0]}"
        seconds = time.perf_counter() - start
        if res is None or not np.all(np.isfinite(res)):
            out.append(ClosedForm(m, None, None, np.inf, np.inf, np.inf, seconds, reason or "nan"))
            continue
        out.append(
            ClosedForm(
                m,
                x,
                z,
                float(np.rad2deg(np.sqrt(np.mean(np.sum(res[:, 3:] ** 2, 1))))),
                float(np.sqrt(np.mean(np.sum(res[:, :3] ** 2, 1)))),
                residual_score(res, scale),
                seconds,
            )
        )
    best = min((c.score for c in out), default=np.inf)
    for c in out:
        if not c.refused and c.score > REFUSE_FACTOR * max(best, 1e-12):
            c.refused = (
                f"inconsistent with the data: residual score {c.score:.3g} is "
                f"{c.score / max(best, 1e-300):.3g} times the best ({best:.3g})"
            )
    return out


def _choose(forms: list[ClosedForm], method: str) -> ClosedForm:
    if method == "best":
        ok = [c for c in forms if not c.refused]
        if not ok:
            raise CalibrationError(
                "every closed form failed or was refused: "
                + "; ".join(f"{c.method}: {c.refused}" for c in forms)
            )
        return min(ok, key=lambda c: c.score)
    chosen = next(c for c in forms if c.method == method)
    if chosen.refused:
        raise CalibrationError(
            f"OpenCV {method} result refused, {chosen.refused}; use method='best' or another method"
        )
    return chosen


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
                    x = _proper("Park", opencv_handeye(aa, bb, "Park"))
                    res = pose_residuals(aa, bb, x, target_in_world(aa, bb, x))
                    per = np.sqrt(
                        np.sum(res[:, 3:] ** 2, 1) + np.sum(res[:, :3] ** 2, 1) / _scale(bb) ** 2
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


# ----------------------------------------------------------------------------------------------
# maximum-likelihood refinement


@dataclass
class _PoseProblem:
    """Whitened SE(3) residuals of ``B_i`` against ``inv(X) inv(A_i) Z``.

    Internal parameters ``[phi_y, t_y, phi_z, t_z]``: ``Y = inv(X)`` with ``R_Y = exp(phi_y)
    R_Y0`` and translation ``t_y``; ``Z`` with ``R_Z = R_Z0 exp(phi_z)`` and translation ``t_z``.
    """

    c: np.ndarray  # inv(A_i), (N, 4, 4)
    b: np.ndarray
    ry0: np.ndarray
    rz0: np.ndarray
    w_rot: np.ndarray  # (N,) sqrt(weight) / sigma_rot
    w_trans: np.ndarray

    @classmethod
    def build(cls, a, b, x, z, sigma_rot, sigma_trans, weights):
        sw = np.sqrt(weights)
        y = geo.invert(x)
        return cls(geo.invert(a), b, y[:3, :3], z[:3, :3], sw / sigma_rot, sw / sigma_trans)

    def x0(self, x, z) -> np.ndarray:
        return np.concatenate([np.zeros(3), geo.invert(x)[:3, 3], np.zeros(3), z[:3, 3]])

    def unpack(self, p) -> tuple[np.ndarray, np.ndarray]:
        ry = _exp_so3(p[0:3])[0] @ self.ry0
        rz = self.rz0 @ _exp_so3(p[6:9])[0]
        x = geo.invert(geo.make_transform(ry, p[3:6]))
        return x, geo.make_transform(rz, p[9:12])

    def _predict(self, p):
        ry = _exp_so3(p[0:3])[0] @ self.ry0
        rz = self.rz0 @ _exp_so3(p[6:9])[0]
        rc, tc = self.c[:, :3, :3], self.c[:, :3, 3]
        r_hat = np.einsum("ij,njk,kl->nil", ry, rc, rz)
        u = np.einsum("ij,nj->ni", ry, np.einsum("nij,j->ni", rc, p[9:12]) + tc)
        return ry, r_hat, u, u + p[3:6]

    def residuals(self, p) -> np.ndarray:
        _, r_hat, _, t_hat = self._predict(p)
        e = _log_so3(np.einsum("nji,njk->nik", r_hat, self.b[:, :3, :3]))
        r = np.concatenate(
            [(self.b[:, :3, 3] - t_hat) * self.w_trans[:, None], e * self.w_rot[:, None]], 1
        )
        return r.ravel()

    def jacobian(self, p) -> np.ndarray:
        ry, r_hat, u, _ = self._predict(p)
        n = r_hat.shape[0]
        e = _log_so3(np.einsum("nji,njk->nik", r_hat, self.b[:, :3, :3]))
        jl_y = _so3_jr(p[0:3])[0].T
        jr_z = _so3_jr(p[6:9])[0]
        jl_inv_e = np.swapaxes(_so3_jr_inv(e), 1, 2)
        jac = np.zeros((n, 6, 12))
        jac[:, :3, 0:3] = geo.skew(u) @ jl_y
        jac[:, :3, 3:6] = -np.eye(3)
        jac[:, :3, 9:12] = -np.einsum("ij,njk->nik", ry, self.c[:, :3, :3])
        jac[:, 3:, 0:3] = -jl_inv_e @ np.swapaxes(r_hat, 1, 2) @ jl_y
        jac[:, 3:, 6:9] = -jl_inv_e @ jr_z
        jac[:, :3] *= self.w_trans[:, None, None]
        jac[:, 3:] *= self.w_rot[:, None, None]
        return jac.reshape(n * 6, 12)

    def to_public(self, x: np.ndarray) -> np.ndarray:
        """Linear map ``(12, 12)`` at ``p = 0`` from internal parameters to ``[theta_X, t_X,
        theta_Z, t_Z]`` (``R_X = R_X0 exp(theta_X)``, ``t_X`` in mm)."""
        y = geo.invert(x)
        g = np.zeros((12, 12))
        g[0:3, 0:3] = -np.eye(3)
        g[3:6, 0:3] = -y[:3, :3].T @ geo.skew(y[:3, 3])
        g[3:6, 3:6] = -y[:3, :3].T
        g[6:12, 6:12] = np.eye(6)
        return g


def _solve(problem: _PoseProblem, x, z) -> tuple[np.ndarray, np.ndarray, int]:
    sol = least_squares(
        problem.residuals,
        problem.x0(x, z),
        jac=problem.jacobian,
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    if sol.status <= 0:
        raise CalibrationError(
            f"ML hand-eye refinement did not converge after {sol.nfev} evaluations "
            f"(cost {sol.cost:.6g}): {sol.message}"
        )
    x1, z1 = problem.unpack(sol.x)
    return x1, z1, int(sol.nfev)


def _whitened_at(a, b, x, z, sigma_rot, sigma_trans, weights):
    """Whitened residuals ``(6N,)`` and Jacobian ``(6N, 12)`` in public coordinates at (x, z)."""
    prob = _PoseProblem.build(a, b, x, z, sigma_rot, sigma_trans, weights)
    p0 = prob.x0(x, z)
    jac = prob.jacobian(p0) @ np.linalg.inv(prob.to_public(x))
    return prob.residuals(p0), jac


def refine_ml(
    a,
    b,
    x0,
    z0,
    sigma_rot: float,
    sigma_trans: float,
    weights=None,
) -> Estimate:
    """Maximum-likelihood ``(X, Z)`` from canonical poses: whitened SE(3) residuals, LM.

    Minimises ``sum_i w_i (|t_Bi - t_pred,i|^2 / sigma_trans^2 + |log(R_pred,i^T R_Bi)|^2 /
    sigma_rot^2)`` with the prediction ``inv(X) inv(A_i) Z``, by scipy's Levenberg-Marquardt with
    an analytic Jacobian (vectorised over poses).

    Parameters
    ----------
    a, b : (N, 4, 4) arrays
        Canonical poses ``A_i`` and ``B_i`` (:class:`PreparedPoses`), mm.
    x0, z0 : (4, 4) arrays
        Start, e.g. a closed form.
    sigma_rot, sigma_trans : float
        Noise of a measured target pose: rad per axis and mm per axis.
    weights : (N,) array, optional
        Per-pose weights (1 by default; 0 removes a pose).

    Returns
    -------
    Estimate
        ``value`` is ``(X, Z)``; ``params`` ``[theta_X, t_X, theta_Z, t_Z]`` (rad, mm) where
        ``R_X = R_X,est exp(theta_X)`` (so the estimate itself has theta = 0); ``covariance``
        ``(J^T J)^-1`` of these coordinates with the given sigmas (not rescaled); ``residuals``
        the whitened residuals ``(6N,)``, per pose ``[t (3), rot (3)]``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    w = np.ones(a.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (a.shape[0],) or np.any(w < 0) or not np.all(np.isfinite(w)):
        raise CalibrationError(
            f"weights must be {a.shape[0]} finite values >= 0; got shape {w.shape}"
        )
    if not (sigma_rot > 0 and sigma_trans > 0):
        raise CalibrationError(
            f"sigma_rot and sigma_trans must be positive; got {sigma_rot:g}, {sigma_trans:g}"
        )
    prob = _PoseProblem.build(a, b, x0, z0, sigma_rot, sigma_trans, w)
    x1, z1, nfev = _solve(prob, x0, z0)
    r, jac = _whitened_at(a, b, x1, z1, sigma_rot, sigma_trans, w)
    cov, cond = covariance_from_jacobian(jac, r, sigma=1.0)
    return Estimate(
        value=(x1, z1),
        params=np.zeros(12),
        covariance=cov,
        residuals=r,
        iterations=nfev,
        condition_number=cond,
        method="ML (SE(3) residuals)",
        names=list(PARAM_NAMES),
    )


def handeye_crb(a, b_true, x, z, sigma_rot: float, sigma_trans: float, weights=None):
    """Cramer-Rao bound ``(12, 12)`` of ``[theta_X, t_X, theta_Z, t_Z]`` at the truth.

    ``(J^T J)^-1`` of the whitened residuals of :func:`refine_ml` evaluated at the true ``X``,
    ``Z`` and noise-free ``B_i`` (rad, mm). Per-pose ``weights`` scale the information as in
    :func:`refine_ml` (a weight w means a noise ``sigma / sqrt(w)`` for that pose).
    """
    w = np.ones(len(a)) if weights is None else np.asarray(weights, dtype=float)
    _, jac = _whitened_at(
        np.asarray(a, float), np.asarray(b_true, float), x, z, sigma_rot, sigma_trans, w
    )
    return np.linalg.inv(jac.T @ jac)


# ----------------------------------------------------------------------------------------------
# reprojection refinement


def _project(camera_matrix, pts):
    uvw = pts @ camera_matrix.T
    return uvw[..., :2] / uvw[..., 2:3]


def refine_reprojection(
    a, b0, x0, z0, target_points, pixels, camera_matrix, pixel_sigma: float, weights=None
) -> Estimate:
    """Maximum-likelihood ``(X, Z)`` on the reprojection error of the target points.

    The pixel of target point ``P_k`` in image ``i`` is predicted as ``K (R P_k + t)`` (pinhole,
    undistorted pixels) with ``[R | t] = inv(X) inv(A_i) Z``; residuals are the pixel differences
    divided by ``pixel_sigma``. Finite-difference-free: the Jacobian is analytic.

    Parameters
    ----------
    a : (N, 4, 4) array
        Canonical robot poses, mm.
    b0 : (N, 4, 4) array
        Measured target poses (used only for the rotation-free starting values).
    x0, z0 : (4, 4) arrays
        Start.
    target_points : (M, 3) array
        Target points in the target frame, mm.
    pixels : (N, M, 2) array
        Their measured (undistorted) pixels; NaN marks a point not seen in that image.
    camera_matrix : (3, 3) array
        Pinhole intrinsics ``K``.
    pixel_sigma : float
        Pixel noise per axis, px.
    weights : (N,) array, optional
        Per-pose weights.

    Returns
    -------
    Estimate
        As :func:`refine_ml`, with residuals in whitened pixels.
    """
    n = a.shape[0]
    pts = geo.check_shape("target points", target_points, (None, 3))
    px = np.asarray(pixels, dtype=float)
    if px.shape != (n, pts.shape[0], 2):
        raise CalibrationError(f"pixels has shape {px.shape}; expected ({n}, {pts.shape[0]}, 2)")
    k = geo.check_shape("camera matrix", camera_matrix, (3, 3))
    seen = np.isfinite(px).all(axis=2)
    if seen.sum() < 6:
        raise CalibrationError(f"only {int(seen.sum())} pixels are given; need at least 6")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    sw = (np.sqrt(w)[:, None] * seen / pixel_sigma)[..., None]
    pxf = np.where(seen[..., None], px, 0.0)
    prob = _PoseProblem.build(a, b0, x0, z0, 1.0, 1.0, w)

    def parts(p):
        ry, r_hat, u, t_hat = prob._predict(p)
        cam = np.einsum("nij,mj->nmi", r_hat, pts) + t_hat[:, None, :]
        return ry, r_hat, u, cam

    def fun(p):
        cam = parts(p)[3]
        return ((pxf - _project(k, cam)) * sw).ravel()

    def jac(p):
        ry, r_hat, _, cam = parts(p)
        jl_y = _so3_jr(p[0:3])[0].T
        jr_z = _so3_jr(p[6:9])[0]
        m = pts.shape[0]
        dcam = np.zeros((n, m, 3, 12))
        dcam[..., 0:3] = -geo.skew(cam - p[3:6]) @ jl_y
        dcam[..., 3:6] = np.eye(3)
        dcam[..., 6:9] = -np.einsum("nij,mjk->nmik", r_hat, geo.skew(pts)) @ jr_z
        dcam[..., 9:12] = np.einsum("ij,njk->nik", ry, prob.c[:, :3, :3])[:, None]
        x_, y_, z_ = cam[..., 0], cam[..., 1], cam[..., 2]
        dproj = np.zeros((n, m, 2, 3))
        dproj[..., 0, 0] = k[0, 0] / z_
        dproj[..., 0, 1] = k[0, 1] / z_
        dproj[..., 0, 2] = -(k[0, 0] * x_ + k[0, 1] * y_) / z_**2
        dproj[..., 1, 1] = k[1, 1] / z_
        dproj[..., 1, 2] = -k[1, 1] * y_ / z_**2
        out = -(dproj @ dcam) * sw[..., None]
        return out.reshape(-1, 12)

    sol = least_squares(fun, prob.x0(x0, z0), jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    if sol.status <= 0:
        raise CalibrationError(
            f"reprojection refinement did not converge after {sol.nfev} evaluations"
        )
    x1, z1 = prob.unpack(sol.x)
    # re-centre the rotations on the solution, so the covariance refers to theta = 0
    centred = _PoseProblem.build(a, b0, x1, z1, 1.0, 1.0, w)
    prob.ry0, prob.rz0 = centred.ry0, centred.rz0
    p0 = centred.x0(x1, z1)
    jac_pub = jac(p0) @ np.linalg.inv(centred.to_public(x1))
    cov, cond = covariance_from_jacobian(jac_pub, fun(p0), sigma=1.0)
    return Estimate(
        value=(x1, z1),
        params=np.zeros(12),
        covariance=cov,
        residuals=fun(p0),
        iterations=int(sol.nfev),
        condition_number=cond,
        method="ML (reprojection)",
        names=list(PARAM_NAMES),
    )


# ----------------------------------------------------------------------------------------------
# the result and the public entry points


@dataclass
class HandEyeResult:
    """A hand-eye calibration with its uncertainty and diagnostics.

    Attributes
    ----------
    x : (4, 4) array
        ``camera2flange`` (eye-in-hand) or ``camera2base`` (eye-to-hand), mm.
    z : (4, 4) array
        ``target2base`` (eye-in-hand) or ``target2flange`` (eye-to-hand), mm.
    x_name, z_name : str
        Those names.
    covariance : (12, 12) array
        Covariance of ``[theta_X, t_X, theta_Z, t_Z]`` (rad, mm), ``R_X = R_X,est exp(theta_X)``
        (rotation error in the camera frame, target frame for Z).
    covariance_basis : str
        ``"given noise level"`` or ``"scaled by residual chi2 (s^2 = ...)"``.
    estimate : Estimate
        The refinement's (or the closed form's) result record.
    method : str
        Closed form used as the start, and the refinement (``"Park + ML"``).
    residuals : (N, 6) array
        Per-pose residuals ``[t (mm, camera frame), rot (rad)]`` of the measured target pose.
    outlier_score : (N,) array
        Whitened squared residual of each pose (chi-square with 6 degrees of freedom for an
        inlier).
    flagged : list of int
        Ids of poses whose score exceeds the ``1 - outlier_alpha`` quantile.
    weights : (N,) array
        Final per-pose weights (user weights times robust weights).
    sigma_rot, sigma_trans : float
        Noise level used (given, or estimated robustly from the residuals), rad and mm.
    conditioning : Conditioning
    closed_forms : list of ClosedForm
    convention : ConventionCheck
    prepared : PreparedPoses
        The canonical input, with the largest re-orthonormalisation correction.
    """

    x: np.ndarray
    z: np.ndarray
    x_name: str
    z_name: str
    covariance: np.ndarray
    covariance_basis: str
    estimate: Estimate
    method: str
    residuals: np.ndarray
    outlier_score: np.ndarray
    flagged: list
    weights: np.ndarray
    sigma_rot: float
    sigma_trans: float
    conditioning: Conditioning
    closed_forms: list
    convention: ConventionCheck
    prepared: PreparedPoses
    notes: list = field(default_factory=list)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations ``(12,)`` of ``[theta_X, t_X, theta_Z, t_Z]`` (rad, mm)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def point_covariance(self, point_camera) -> np.ndarray:
        """Covariance ``(3, 3)`` (mm^2) of ``X @ p`` for a point ``p`` (mm) in the camera frame:
        the predicted uncertainty of a tool or measured point mapped to the flange (or base)."""
        p = geo.check_shape("point", point_camera, (3,))
        jac = np.zeros((3, 12))
        jac[:, 0:3] = -self.x[:3, :3] @ geo.skew(p)
        jac[:, 3:6] = np.eye(3)
        return jac @ self.covariance @ jac.T


def outlier_limit(alpha: float = 1e-3) -> float:
    """Outlier flag limit: the ``1 - alpha`` quantile of chi-square with 6 degrees of freedom."""
    return float(chi2.ppf(1.0 - alpha, 6))


def _robust_sigmas(res: np.ndarray, alpha: float = 1e-3) -> tuple[float, float]:
    """Noise level ``(sigma_rot, sigma_trans)`` from per-pose residuals ``(N, 6)``, robustly.

    A median-based start (each part is ``sigma^2 chi2(3)`` for an inlier) marks the poses beyond
    the ``1 - alpha`` quantile; the RMS of the others, corrected for the 12 fitted parameters,
    is the estimate (reweighted least-median: efficient on clean data, robust to outliers).
    """
    n = res.shape[0]
    rr = np.sum(res[:, 3:] ** 2, 1)
    tt = np.sum(res[:, :3] ** 2, 1)
    keep = (n - 2.0) / n  # 12 parameters take 2 of the 6 N degrees of freedom per pose
    s_r = np.sqrt(max(np.median(rr) / (_CHI2_3_MEDIAN * keep), 1e-30))
    s_t = np.sqrt(max(np.median(tt) / (_CHI2_3_MEDIAN * keep), 1e-30))
    inl = rr / s_r**2 + tt / s_t**2 <= chi2.ppf(1.0 - alpha, 6)
    m = int(inl.sum())
    if m > 2:
        s_r = np.sqrt(max(rr[inl].sum() / (3.0 * (m - 2)), 1e-30))
        s_t = np.sqrt(max(tt[inl].sum() / (3.0 * (m - 2)), 1e-30))
    return float(s_r), float(s_t)


def _scores(res, sigma_rot, sigma_trans):
    return np.sum(res[:, :3] ** 2, 1) / sigma_trans**2 + np.sum(res[:, 3:] ** 2, 1) / sigma_rot**2


def _robust_weights(score: np.ndarray, loss: str, c: float = 2.0) -> np.ndarray:
    u = np.sqrt(score / 6.0)
    if loss == "huber":
        return np.where(u <= c, 1.0, c / np.maximum(u, 1e-300))
    return 1.0 / (1.0 + (u / c) ** 2)


def _ransac(a, b, rng, n_samples: int) -> np.ndarray:
    """Inlier mask by least-median-of-squares over random pose triplets (Park closed form)."""
    n = a.shape[0]
    scale = _scale(b)
    best, best_med = None, np.inf
    for _ in range(n_samples):
        idx = rng.choice(n, 3, replace=False)
        try:
            x = _proper("Park", opencv_handeye(a[idx], b[idx], "Park"))
            z = target_in_world(a[idx], b[idx], x)
            res = pose_residuals(a, b, x, z)
        except (CalibrationError, cv2.error):
            continue
        per = np.sum(res[:, 3:] ** 2, 1) + np.sum(res[:, :3] ** 2, 1) / scale**2
        med = float(np.median(per))
        if np.isfinite(med) and med < best_med:
            best, best_med = per, med
    if best is None:
        raise CalibrationError(f"RANSAC: none of the {n_samples} pose triplets gave a solution")
    # LMedS scale with the small-sample correction of Rousseeuw and Leroy
    s0 = 1.4826 * (1.0 + 5.0 / max(n - 3, 1)) * np.sqrt(best_med)
    return best <= (2.5 * s0) ** 2


def _calibrate(
    prep: PreparedPoses,
    forms: list[ClosedForm],
    method: str,
    *,
    refine: bool,
    sigma_rot,
    sigma_trans,
    weights,
    robust,
    outlier_alpha: float,
    check_convention: str,
    rng,
    ransac_samples: int,
    target_points,
    pixels,
    camera_matrix,
    pixel_sigma,
) -> HandEyeResult:
    a, b, n = prep.a, prep.b, prep.a.shape[0]
    cond = motion_conditioning(a)
    if robust not in ROBUST:
        raise CalibrationError(f"unknown robust option {robust!r}; use one of {ROBUST}")
    if check_convention not in ("raise", "warn", "off"):
        raise CalibrationError(
            f"check_convention must be raise, warn or off; got {check_convention!r}"
        )
    if (sigma_rot is None) != (sigma_trans is None):
        raise CalibrationError("give both sigma_rot and sigma_trans, or neither")
    if not 0 < outlier_alpha < 1:
        raise CalibrationError(f"outlier_alpha must be in (0, 1); got {outlier_alpha:g}")
    notes: list[str] = []
    conv = ConventionCheck({})
    if check_convention != "off":
        conv = convention_check(a, b)
        if conv.message and check_convention == "raise":
            raise CalibrationError(conv.message)
        if conv.message:
            warnings.warn(conv.message, stacklevel=3)
            notes.append(conv.message)
    start = _choose(forms, method)
    w_user = np.ones(n) if weights is None else geo.check_shape("weights", weights, (n,))
    if np.any(w_user < 0):
        raise CalibrationError(f"weights must be >= 0; got {w_user.min():g}")
    w = w_user.copy()
    if robust == "ransac":
        if rng is None:
            raise CalibrationError("robust='ransac' draws pose triplets: pass rng")
        inl = _ransac(a, b, rng, ransac_samples)
        w = w_user * inl
        notes.append(f"RANSAC kept {int(inl.sum())} of {n} poses")
    x, z = start.x, start.z
    if robust == "ransac" or (weights is not None):
        z = target_in_world(a[w > 0], b[w > 0], x)
    given = sigma_rot is not None
    if given:
        s_rot, s_trans = float(sigma_rot), float(sigma_trans)
        if not (s_rot > 0 and s_trans > 0):
            raise CalibrationError(f"sigmas must be positive; got {s_rot:g}, {s_trans:g}")
    else:
        s_rot, s_trans = _robust_sigmas(pose_residuals(a, b, x, z)[w > 0])
    label = start.method
    if not refine:
        res = pose_residuals(a, b, x, z)
        r, jac = _whitened_at(a, b, x, z, s_rot, s_trans, w)
        est = Estimate(
            value=(x, z), params=np.zeros(12), residuals=r, method=label, names=list(PARAM_NAMES)
        )
        cov, jc = covariance_from_jacobian(jac, r, sigma=1.0)
    else:
        label = f"{start.method} + ML"
        reweight = robust in ("huber", "cauchy")
        # the noise level (if estimated) and robust weights depend on the fit: iterate to a fixed
        # point (a few rounds suffice; the refinement itself is warm-started)
        for _ in range(30 if reweight else (3 if not given else 0)):
            est = refine_ml(a, b, x, z, s_rot, s_trans, w)
            x, z = est.value
            res = pose_residuals(a, b, x, z)
            old = (s_rot, s_trans, w)
            if not given:
                s_rot, s_trans = _robust_sigmas(res[w_user > 0])
            if reweight:
                w = w_user * _robust_weights(_scores(res, s_rot, s_trans), robust)
            if np.max(np.abs(w - old[2])) < 1e-6 and abs(s_rot / old[0] - 1) < 1e-6:
                break
        est = refine_ml(a, b, x, z, s_rot, s_trans, w)
        x, z = est.value
        if target_points is not None:
            if pixel_sigma is None or camera_matrix is None or pixels is None:
                raise CalibrationError(
                    "the reprojection refinement needs target_points, pixels, camera_matrix and "
                    "pixel_sigma together"
                )
            est = refine_reprojection(
                a, b, x, z, target_points, pixels, camera_matrix, pixel_sigma, w
            )
            x, z = est.value
            label = f"{start.method} + ML (reprojection)"
        cov, jc = est.covariance, est.condition_number
    cond.jacobian_condition = float(jc)
    if not np.isfinite(jc) or jc > MAX_JACOBIAN_CONDITION:
        raise CalibrationError(
            f"the calibration is undetermined by these poses: condition number of the "
            f"refinement's Jacobian {jc:.3g} (limit {MAX_JACOBIAN_CONDITION:g}); add poses "
            "rotating about other axes"
        )
    res = pose_residuals(a, b, x, z)
    score = _scores(res, s_rot, s_trans)
    if target_points is not None:
        basis = "given noise level (pixel_sigma)"
    elif given:
        basis = "given noise level"
    else:
        m = int(np.count_nonzero(w)) * 6
        chi = float(np.sum(est.residuals**2))
        s2 = chi / max(m - 12, 1)
        cov = cov * s2
        basis = f"scaled by residual chi2 (s^2 = {s2:.3g})"
    limit = outlier_limit(outlier_alpha)
    flagged = [int(i) for i in prep.ids[score > limit]]
    if flagged:
        notes.append(f"{len(flagged)} pose(s) flagged as outliers (chi2 > {limit:.3g}): {flagged}")
    if np.linalg.norm(x[:3, 3]) > np.linalg.norm(z[:3, 3]):
        notes.append(
            f"the camera offset |t_X| = {np.linalg.norm(x[:3, 3]):.4g} mm exceeds the target "
            f"offset |t_Z| = {np.linalg.norm(z[:3, 3]):.4g} mm: if both lists are stored inverted, "
            "X and Z swap roles and the data cannot tell (check convention=)"
        )
    eye_in_hand = prep.setup == "eye_in_hand"
    return HandEyeResult(
        x=x,
        z=z,
        x_name="camera2flange" if eye_in_hand else "camera2base",
        z_name="target2base" if eye_in_hand else "target2flange",
        covariance=cov,
        covariance_basis=basis,
        estimate=est,
        method=label,
        residuals=res,
        outlier_score=score,
        flagged=flagged,
        weights=w,
        sigma_rot=s_rot,
        sigma_trans=s_trans,
        conditioning=cond,
        closed_forms=forms,
        convention=conv,
        prepared=prep,
        notes=notes,
    )


_COMMON_DOC = """
    Parameters
    ----------
    flange2base : (N, 4, 4) array
        Robot flange poses as stored (see ``convention``), translations in ``robot_unit``.
    target2camera : (N, 4, 4) array
        Target poses from the camera as stored, translations in ``camera_unit``.
    method : str
        Closed form used as the start; ``"best"`` (default) tries all of them and starts from the
        one with the smallest residual.
    setup : {"eye_in_hand", "eye_to_hand"}
    convention : str or pair of str, optional
        Storage forms: ``"gripper2base"`` (default) or ``"base2gripper"``; ``"target2camera"``
        (default) or ``"camera2target"``.
    robot_unit, camera_unit : {"mm", "cm", "m", "in"}
    ortho_tol : float
        Rotations off SO(3) by at most this (``max |R^T R - I|``) are re-projected; worse ones are
        refused.
    refine : bool
        Run the maximum-likelihood refinement (default) or return the closed form.
    sigma_rot, sigma_trans : float, optional
        Noise of a measured target pose (rad, mm per axis). When omitted they are estimated
        robustly from the residuals and the covariance is scaled by the residual chi-square.
    weights : (N,) array, optional
        Per-pose weights (0 drops a pose).
    robust : {None, "huber", "cauchy", "ransac"}
        Down-weight outlier poses by iterative reweighting, or keep the poses consistent with the
        best of ``ransac_samples`` random pose triplets (needs ``rng``).
    outlier_alpha : float
        False-alarm probability per pose of the outlier flag.
    check_convention : {"raise", "warn", "off"}
        What to do when another storage convention or a unit factor 1000 fits far better.
    rng : numpy.random.Generator, optional
        Needed for ``robust="ransac"``.
    target_points, pixels, camera_matrix, pixel_sigma : optional
        Target points (M, 3) mm, their pixels (N, M, 2), K (3, 3) and the pixel noise (px): refine
        on the reprojection error instead of the target poses.

    Returns
    -------
    HandEyeResult

    Raises
    ------
    CalibrationError
        Bad input (named pose and number), degenerate motions (duplicates, pure translations, one
        rotation axis), a convention or unit mismatch (``check_convention="raise"``), a requested
        closed form inconsistent with the data, or a refinement that does not converge.
"""


def calibrate_handeye(
    flange2base,
    target2camera,
    *,
    method: str = "best",
    setup: str = "eye_in_hand",
    convention: str | Sequence[str] | None = None,
    robot_unit: str = "mm",
    camera_unit: str = "mm",
    ortho_tol: float = ORTHO_TOL,
    refine: bool = True,
    sigma_rot: float | None = None,
    sigma_trans: float | None = None,
    weights=None,
    robust: str | None = None,
    outlier_alpha: float = 1e-3,
    check_convention: str = "raise",
    rng: np.random.Generator | None = None,
    ransac_samples: int = 200,
    ids=None,
    target_points=None,
    pixels=None,
    camera_matrix=None,
    pixel_sigma: float | None = None,
) -> HandEyeResult:
    prep = prepare_poses(
        flange2base,
        target2camera,
        setup=setup,
        convention=convention,
        robot_unit=robot_unit,
        camera_unit=camera_unit,
        ortho_tol=ortho_tol,
        ids=ids,
    )
    if method != "best" and method not in OPENCV_METHODS:
        raise CalibrationError(
            f"unknown AX = XB method {method!r}; use 'best' or one of {list(OPENCV_METHODS)}"
        )
    motion_conditioning(prep.a)
    forms = closed_forms(prep.a, prep.b, list(OPENCV_METHODS))
    return _calibrate(
        prep,
        forms,
        method,
        refine=refine,
        sigma_rot=sigma_rot,
        sigma_trans=sigma_trans,
        weights=weights,
        robust=robust,
        outlier_alpha=outlier_alpha,
        check_convention=check_convention,
        rng=rng,
        ransac_samples=ransac_samples,
        target_points=target_points,
        pixels=pixels,
        camera_matrix=camera_matrix,
        pixel_sigma=pixel_sigma,
    )


calibrate_handeye.__doc__ = (
    """Hand-eye calibration AX = XB from measured robot and camera poses, with uncertainty.

    Eye-in-hand: the camera is on the flange and sees a fixed target; returns ``camera2flange``
    (and the target pose ``target2base`` as a by-product). Eye-to-hand: the camera is fixed and
    the target is on the flange; returns ``camera2base`` (and ``target2flange``). The start is an
    OpenCV ``calibrateHandEye`` closed form (Tsai, Park, Horaud, Andreff, Daniilidis), then
    maximum likelihood on the SE(3) residuals of the target poses (:func:`refine_ml`).
"""
    + _COMMON_DOC
)


def calibrate_robot_world_handeye(
    flange2base,
    target2camera,
    *,
    method: str = "best",
    setup: str = "eye_in_hand",
    convention: str | Sequence[str] | None = None,
    robot_unit: str = "mm",
    camera_unit: str = "mm",
    ortho_tol: float = ORTHO_TOL,
    refine: bool = True,
    sigma_rot: float | None = None,
    sigma_trans: float | None = None,
    weights=None,
    robust: str | None = None,
    outlier_alpha: float = 1e-3,
    check_convention: str = "raise",
    rng: np.random.Generator | None = None,
    ransac_samples: int = 200,
    ids=None,
    target_points=None,
    pixels=None,
    camera_matrix=None,
    pixel_sigma: float | None = None,
) -> HandEyeResult:
    prep = prepare_poses(
        flange2base,
        target2camera,
        setup=setup,
        convention=convention,
        robot_unit=robot_unit,
        camera_unit=camera_unit,
        ortho_tol=ortho_tol,
        ids=ids,
    )
    if method != "best" and method not in OPENCV_RWHE_METHODS:
        raise CalibrationError(
            f"unknown AX = ZB method {method!r}; use 'best' or one of {list(OPENCV_RWHE_METHODS)}"
        )
    motion_conditioning(prep.a)
    forms = closed_forms(prep.a, prep.b, list(OPENCV_RWHE_METHODS))
    return _calibrate(
        prep,
        forms,
        method,
        refine=refine,
        sigma_rot=sigma_rot,
        sigma_trans=sigma_trans,
        weights=weights,
        robust=robust,
        outlier_alpha=outlier_alpha,
        check_convention=check_convention,
        rng=rng,
        ransac_samples=ransac_samples,
        target_points=target_points,
        pixels=pixels,
        camera_matrix=camera_matrix,
        pixel_sigma=pixel_sigma,
    )


calibrate_robot_world_handeye.__doc__ = (
    """Robot-world-hand-eye calibration AX = ZB: camera and target poses together.

    Solves ``A_i X = Z inv(B_i)`` for ``X = camera2flange`` and ``Z = target2base`` (eye-in-hand;
    ``camera2base`` and ``target2flange`` eye-to-hand) without forming relative motions. The start
    is OpenCV's ``calibrateRobotWorldHandEye`` (Shah, Li), then the same maximum-likelihood
    refinement as :func:`calibrate_handeye`.
"""
    + _COMMON_DOC
)


# ----------------------------------------------------------------------------------------------
# a simulated cell


@dataclass
class SimulatedCell:
    """Synthetic hand-eye data with the truth, as :func:`simulate_cell` draws them.

    Attributes
    ----------
    flange2base : (N, 4, 4) array
        Robot poses as the controller reports them (gripper-to-base, mm).
    target2camera : (N, 4, 4) array
        Measured target poses (noisy), mm.
    target2camera_true : (N, 4, 4) array
        Noise-free target poses.
    camera2flange, target2base : (4, 4) arrays
        The truth (eye-in-hand).
    outliers : (N,) bool array
        Poses made gross outliers.
    """

    flange2base: np.ndarray
    target2camera: np.ndarray
    target2camera_true: np.ndarray
    camera2flange: np.ndarray
    target2base: np.ndarray
    outliers: np.ndarray


#: true camera2flange of the simulated cell: camera 120 mm ahead of the flange, tilted 15 deg
CELL_CAMERA2FLANGE = geo.make_transform(
    geo.euler_zyx_to_matrix(90.0, 15.0, 0.0), np.array([40.0, -25.0, 120.0])
)
#: true target2base: a target on the table 800 mm in front of the robot
CELL_TARGET2BASE = geo.make_transform(
    geo.euler_zyx_to_matrix(30.0, 0.0, 180.0), np.array([800.0, 100.0, 20.0])
)


def simulate_cell(
    rng: np.random.Generator,
    n_poses: int = 15,
    sigma_rot: float = 1e-3,
    sigma_trans: float = 0.2,
    *,
    distance_mm: float = 500.0,
    max_tilt_deg: float = 30.0,
    max_roll_deg: float = 45.0,
    n_duplicate_orientations: int = 0,
    outlier: tuple[float, float] | None = None,
    round_rotations: int | None = None,
) -> SimulatedCell:
    """Draw an eye-in-hand cell: a camera on the flange looking at a fixed target.

    The camera looks at the target centre from ``distance_mm`` (+-10 %), from directions within
    ``max_tilt_deg`` of the target normal, rolled by up to ``max_roll_deg``. The measured target
    poses are the true ones times ``exp(xi)`` with a rotation ``N(0, sigma_rot^2 I)`` (rad) and
    a translation ``N(0, sigma_trans^2 I)`` (mm): the noise model of :func:`refine_ml`. This is
    the study's standard hand-eye scenario (15 poses, 1e-3 rad, 0.2 mm) at its defaults.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_poses : int
    sigma_rot, sigma_trans : float
        Camera pose noise, rad and mm per axis.
    distance_mm, max_tilt_deg, max_roll_deg : float
        Viewing geometry.
    n_duplicate_orientations : int
        That many extra poses repeat the orientation of earlier ones with the flange moved by up to
        50 mm (common in taught pose lists).
    outlier : (translation_mm, rotation_deg), optional
        Make the last pose a gross outlier: its measured target pose is moved by this much.
    round_rotations : int, optional
        Round rotation-matrix entries of both lists to this many decimals (as files do).

    Returns
    -------
    SimulatedCell
    """
    if n_poses < 3:
        raise CalibrationError(f"a simulated cell needs at least 3 poses; got {n_poses}")
    x, z = CELL_CAMERA2FLANGE, CELL_TARGET2BASE
    centre = z[:3, 3]
    normal = z[:3, :3] @ np.array([0.0, 0.0, -1.0])  # the target's z points into the table
    tilt = np.deg2rad(max_tilt_deg) * np.sqrt(rng.uniform(0, 1, n_poses))
    azim = rng.uniform(0, 2 * np.pi, n_poses)
    axis = np.stack([np.cos(azim), np.sin(azim), np.zeros(n_poses)], 1)
    dirs = geo.rotvec_to_matrix(axis * tilt[:, None]) @ np.array([0.0, 0.0, 1.0])
    frame = geo.look_at(np.zeros(3), normal)[:3, :3]
    dirs = dirs @ frame.T
    dist = distance_mm * rng.uniform(0.9, 1.1, n_poses)
    cams = []
    for d, r, roll in zip(dirs, dist, rng.uniform(-1, 1, n_poses) * max_roll_deg, strict=True):
        cam = geo.look_at(centre + r * d, centre + rng.normal(0, 20, 3))
        cams.append(cam @ geo.make_transform(geo.euler_zyx_to_matrix(roll, 0, 0), np.zeros(3)))
    cam2base = np.array(cams)
    flange = cam2base @ geo.invert(x)
    if n_duplicate_orientations:
        src = rng.choice(n_poses, n_duplicate_orientations, replace=True)
        dup = flange[src].copy()
        dup[:, :3, 3] += rng.uniform(-50, 50, (len(src), 3))
        flange = np.concatenate([flange, dup])
    b_true = geo.invert(flange @ x) @ z
    b = geo.perturb(b_true, sigma_rot, sigma_trans, rng)
    out = np.zeros(len(b), dtype=bool)
    if outlier is not None:
        d = rng.normal(size=(2, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        b[-1] = b[-1] @ geo.make_transform(
            geo.rotvec_to_matrix(d[1] * np.deg2rad(outlier[1])), d[0] * outlier[0]
        )
        out[-1] = True
    if round_rotations is not None:
        flange[:, :3, :3] = np.round(flange[:, :3, :3], round_rotations)
        b[:, :3, :3] = np.round(b[:, :3, :3], round_rotations)
    return SimulatedCell(flange, b, b_true, x, z, out)


# ----------------------------------------------------------------------------------------------
# pose-list files

#: rotation forms of a pose-list file: column suffixes after ``<prefix>_``
ROTATION_FORMS = {
    "quaternion": ("qw", "qx", "qy", "qz"),
    "rotvec_rad": ("rx_rad", "ry_rad", "rz_rad"),
    "zyx_deg": ("a_deg", "b_deg", "c_deg"),
    "matrix": ("r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"),
}


@dataclass
class PoseList:
    """Robot and camera poses read from a pose-list file, as stored (not yet converted).

    Attributes
    ----------
    ids : (N,) int array
    robot : (N, 4, 4) array
        Robot poses in the file's convention and unit.
    camera : (N, 4, 4) array
        Camera poses in the file's convention and unit.
    robot_convention, camera_convention : str
        Named by the column prefixes (e.g. ``flange2base``, ``target2camera``).
    robot_unit, camera_unit : str
        Named by the translation columns (e.g. ``_x_mm``).
    """

    ids: np.ndarray
    robot: np.ndarray
    camera: np.ndarray
    robot_convention: str
    camera_convention: str
    robot_unit: str
    camera_unit: str

    def arguments(self) -> dict:
        """Keyword arguments for :func:`calibrate_handeye` and
        :func:`calibrate_robot_world_handeye`."""
        return {
            "flange2base": self.robot,
            "target2camera": self.camera,
            "convention": (self.robot_convention, self.camera_convention),
            "robot_unit": self.robot_unit,
            "camera_unit": self.camera_unit,
            "ids": self.ids,
        }

    def __len__(self) -> int:
        return len(self.ids)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of scalar-first quaternions, without normalising (a non-unit quaternion
    gives a scaled matrix that the orthonormality check then reports)."""
    w, x, y, z = q.T
    return np.stack(
        [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
    ).transpose(2, 0, 1)


def _find_prefix(path, header, names, what):
    found = [p for p in names if any(h.startswith(p + "_") for h in header)]
    if len(found) != 1:
        raise CalibrationError(
            f"{path}: header must name the {what} poses by exactly one prefix of "
            f"{', '.join(names)} (e.g. {names[0]}_x_mm); found {found or 'none'}"
        )
    return found[0]


def _pose_columns(path, header, prefix):
    units = [u for u in UNITS_MM if f"{prefix}_x_{u}" in header]
    if len(units) != 1:
        raise CalibrationError(
            f"{path}: no translation columns {prefix}_x_<unit>, {prefix}_y_<unit>, "
            f"{prefix}_z_<unit> with one unit of {', '.join(UNITS_MM)}"
        )
    unit = units[0]
    trans = [f"{prefix}_{c}_{unit}" for c in "xyz"]
    forms = [f for f, cols in ROTATION_FORMS.items() if f"{prefix}_{cols[0]}" in header]
    if len(forms) != 1:
        raise CalibrationError(
            f"{path}: the {prefix} rotation must be given in exactly one form, columns "
            + "; ".join(f"{prefix}_" + f", {prefix}_".join(c) for c in ROTATION_FORMS.values())
            + f"; found {forms or 'none'}"
        )
    rot = [f"{prefix}_{c}" for c in ROTATION_FORMS[forms[0]]]
    missing = [c for c in trans + rot if c not in header]
    if missing:
        raise CalibrationError(f"{path}: missing column(s) {', '.join(missing)}")
    return unit, forms[0], trans, rot


def _rotations(form: str, v: np.ndarray) -> np.ndarray:
    if form == "quaternion":
        return _quat_matrix(v)
    if form == "rotvec_rad":
        return geo.rotvec_to_matrix(v)
    if form == "zyx_deg":
        return geo.euler_zyx_to_matrix(v[:, 0], v[:, 1], v[:, 2])
    return v.reshape(-1, 3, 3)


def read_pose_list(path) -> PoseList:
    """Read a pose-list CSV (schema in the README and :func:`write_pose_list`).

    One row per pose: ``id``; the robot pose as ``<robot>_x_<unit>, _y_<unit>, _z_<unit>`` and a
    rotation in one self-naming form; the camera pose likewise. ``<robot>`` is one of
    ``gripper2base, flange2base, base2gripper, base2flange`` and ``<camera>`` one of
    ``target2camera, camera2target``: the prefixes state the storage convention. ``<unit>`` is
    ``mm, cm, m`` or ``in``. Rotation forms (:data:`ROTATION_FORMS`): ``_qw, _qx, _qy, _qz``
    (unit quaternion, scalar first), ``_rx_rad, _ry_rad, _rz_rad`` (rotation vector),
    ``_a_deg, _b_deg, _c_deg`` (``R = Rz(a) Ry(b) Rx(c)``, KUKA) or ``_r11 ... _r33`` (matrix,
    row by row). Lines starting with ``#`` are comments.

    Returns
    -------
    PoseList
        The poses as stored; :meth:`PoseList.arguments` passes them with their convention and
        units to the calibration.

    Raises
    ------
    CalibrationError
        For a header that names no or two conventions, units or rotation forms, a missing
        column, no rows, a cell that is empty, not a number or not finite (naming the row, 1-based
        with the header as row 1, and the column), a non-integer or repeated id.
    """
    path = Path(path)
    with open(path, newline="") as handle:
        lines = [ln for ln in handle if not ln.lstrip().startswith("#")]
    reader = csv.reader(lines)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise CalibrationError(f"{path}: the file is empty") from None
    if "id" not in header:
        raise CalibrationError(f"{path}: missing column 'id'")
    rprefix = _find_prefix(path, header, list(ROBOT_CONVENTIONS), "robot")
    cprefix = _find_prefix(path, header, list(CAMERA_CONVENTIONS), "camera")
    runit, rform, rtrans, rrot = _pose_columns(path, header, rprefix)
    cunit, cform, ctrans, crot = _pose_columns(path, header, cprefix)
    cols = ["id"] + rtrans + rrot + ctrans + crot
    index = [header.index(c) for c in cols]
    rows = [r for r in reader if any(cell.strip() for cell in r)]
    if not rows:
        raise CalibrationError(f"{path}: no pose rows")
    values = np.zeros((len(rows), len(cols)))
    for i, row in enumerate(rows):
        line = i + 2
        if len(row) != len(header):
            raise CalibrationError(
                f"{path}: row {line} has {len(row)} cells; the header has {len(header)}"
            )
        for j, (col, k) in enumerate(zip(cols, index, strict=True)):
            text = row[k].strip()
            try:
                values[i, j] = float(text)
            except ValueError:
                raise CalibrationError(
                    f"{path}: row {line}, column {col!r}: {text!r} is not a number"
                ) from None
            if not np.isfinite(values[i, j]):
                raise CalibrationError(
                    f"{path}: row {line}, column {col!r}: {text!r} is not finite"
                )
    ids = values[:, 0]
    if np.any(ids != np.round(ids)):
        bad = int(np.argmax(ids != np.round(ids)))
        raise CalibrationError(f"{path}: row {bad + 2}, column 'id': {ids[bad]} is not an integer")
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        raise CalibrationError(f"{path}: id {int(uniq[counts > 1][0])} appears more than once")
    nr = len(rrot)
    robot = geo.make_transform(_rotations(rform, values[:, 4 : 4 + nr]), values[:, 1:4])
    c0 = 4 + nr
    camera = geo.make_transform(_rotations(cform, values[:, c0 + 3 :]), values[:, c0 : c0 + 3])
    return PoseList(ids.astype(int), robot, camera, rprefix, cprefix, runit, cunit)


def write_pose_list(
    path,
    flange2base,
    target2camera,
    *,
    ids=None,
    rotation: str = "quaternion",
    robot_convention: str = "flange2base",
    camera_convention: str = "target2camera",
    unit: str = "mm",
    digits: int = 10,
    comment: str = "",
) -> Path:
    """Write poses as a pose-list CSV that :func:`read_pose_list` reads.

    Parameters
    ----------
    path : str or pathlib.Path
    flange2base, target2camera : (N, 4, 4) arrays
        Poses in the study's convention (mm); written in ``robot_convention`` /
        ``camera_convention`` (inverted if those say so) and ``unit``.
    ids : (N,) int array, optional
    rotation : str
        One of :data:`ROTATION_FORMS`.
    digits : int
        Significant digits of every number.
    comment : str
        Written as ``#`` lines above the header.
    """
    if rotation not in ROTATION_FORMS:
        raise CalibrationError(
            f"unknown rotation form {rotation!r}; use one of {list(ROTATION_FORMS)}"
        )
    robot = _check_pose_array("robot poses", flange2base)
    camera = _check_pose_array("camera poses", target2camera)
    if ROBOT_CONVENTIONS.get(robot_convention) is None:
        raise CalibrationError(f"unknown robot convention {robot_convention!r}")
    if CAMERA_CONVENTIONS.get(camera_convention) is None:
        raise CalibrationError(f"unknown camera convention {camera_convention!r}")
    robot = geo.invert(robot) if ROBOT_CONVENTIONS[robot_convention] else robot
    camera = geo.invert(camera) if CAMERA_CONVENTIONS[camera_convention] else camera
    factor = _unit_factor("file", unit)
    ids = np.arange(1, len(robot) + 1) if ids is None else np.asarray(ids, dtype=int)
    header = ["id"]
    blocks = [ids[:, None].astype(float)]
    for prefix, poses in ((robot_convention, robot), (camera_convention, camera)):
        header += [f"{prefix}_{c}_{unit}" for c in "xyz"]
        header += [f"{prefix}_{c}" for c in ROTATION_FORMS[rotation]]
        rot = poses[:, :3, :3]
        if rotation == "quaternion":
            q = Rotation.from_matrix(rot).as_quat()  # scalar last
            r = np.concatenate([q[:, 3:], q[:, :3]], 1)
            r *= np.where(r[:, :1] < 0, -1.0, 1.0)
        elif rotation == "rotvec_rad":
            r = geo.matrix_to_rotvec(rot)
        elif rotation == "zyx_deg":
            r = geo.matrix_to_euler_zyx(rot)
        else:
            r = rot.reshape(-1, 9)
        blocks += [poses[:, :3, 3] / factor, r]
    table = np.concatenate(blocks, 1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        for line in comment.splitlines():
            handle.write(f"# {line}\n")
        handle.write(",".join(header) + "\n")
        for row in table:
            cells = [str(int(row[0]))] + [f"{v:.{digits}g}" for v in row[1:]]
            handle.write(",".join(cells) + "\n")
    return path
