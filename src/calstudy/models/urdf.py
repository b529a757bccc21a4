"""A serial robot read from a URDF file (through Pinocchio) as a standard DH table.

The URDF gives each revolute joint's axis as a line in space at the zero configuration; the DH
table follows from those lines (Khalil and Dombre, ch. 3): frame 0 on the first axis, each next
frame's z on the next axis and its x along the common normal of the two, its origin where the
normal meets the next axis. Where two consecutive axes are parallel the normal is taken through
the previous origin (``d = 0`` on that link, the form Hayati's ``beta`` needs); where they
intersect, x is their cross product. The last link carries only ``d`` along the last axis; what
is left to the flange frame is the table's ``tool`` transform, and the placement of frame 0 in
the URDF's root frame its ``base``. Lengths are converted from metres to millimetres.
:func:`robot_from_urdf` checks that the table reproduces the URDF's flange pose.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin

from calstudy.core.errors import CalibrationError
from calstudy.models.kinematics import Link, Robot

#: lines closer to parallel than this (sine of the angle) are parallel; points closer than this
#: (mm) coincide
PARALLEL_SIN = 1e-9
COINCIDENT_MM = 1e-9
#: largest flange-pose difference (mm, or rad) between the table and the URDF accepted
AGREEMENT_TOL = 1e-6
#: configurations drawn to check the table against the URDF
CHECK_CONFIGURATIONS = 20


def _axis_lines(model: pin.Model, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) mm and unit directions (n, 3) of the joint axes at the zero configuration."""
    q0 = np.zeros(model.nq)
    pin.computeJointJacobians(model, data, q0)
    points, dirs = [], []
    for j in range(1, model.njoints):
        jac = pin.getJointJacobian(model, data, j, pin.WORLD)[:, model.joints[j].idx_v]
        v, w = jac[:3] * 1000.0, jac[3:]
        points.append(np.cross(w, v) / float(w @ w))  # the point of the axis nearest the origin
        dirs.append(w / np.linalg.norm(w))
    return np.array(points), np.array(dirs)


def _frame(origin, x, z) -> np.ndarray:
    t = np.eye(4)
    t[:3, 0], t[:3, 2] = x, z
    t[:3, 1] = np.cross(z, x)
    t[:3, 3] = origin
    return t


def _angle(a, b, axis) -> float:
    """Angle from ``a`` to ``b`` about ``axis`` (unit vectors perpendicular to it)."""
    return math.atan2(float(np.cross(a, b) @ axis), float(a @ b))


def _next_frame(prev: np.ndarray, point, direction) -> tuple[np.ndarray, Link]:
    """The DH frame on the axis line ``(point, direction)`` after frame ``prev`` and its link."""
    o, x0, z0 = prev[:3, 3], prev[:3, 0], prev[:3, 2]
    z = direction
    cross = np.cross(z0, z)
    if np.linalg.norm(cross) < PARALLEL_SIN:
        foot_a = o  # parallel: d = 0
        foot_b = point + ((o - point) @ z) * z
    else:
        # closest points of the two lines
        w0 = o - point
        b, d, e = float(z0 @ z), float(z0 @ w0), float(z @ w0)
        den = 1.0 - b * b
        s, t = (b * e - d) / den, (e - b * d) / den
        foot_a, foot_b = o + s * z0, point + t * z
    normal = foot_b - foot_a
    if np.linalg.norm(normal) > COINCIDENT_MM:
        x = normal / np.linalg.norm(normal)
    elif np.linalg.norm(cross) >= PARALLEL_SIN:
        x = cross / np.linalg.norm(cross)
    else:
        x = x0
    link = Link(
        "dh",
        a=float(normal @ x),
        alpha=_angle(z0, z, x),
        d=float((foot_a - o) @ z0),
        theta=_angle(x0, x, z0),
    )
    return _frame(foot_b, x, z), link


def robot_from_urdf(path, flange: str | None = None, name: str | None = None) -> Robot:
    """A 6-joint serial robot of a URDF file as a standard DH :class:`Robot` (lengths in mm).

    Parameters
    ----------
    path : str or Path
        The URDF file (meshes are not read).
    flange : str, optional
        Name of the URDF frame (link) that is the flange; default: the frame of the last joint.
    name : str, optional
        Display name; default the URDF's robot name.

    Returns
    -------
    Robot
        DH links with the joint limits of the URDF; ``base`` is frame 0 in the URDF's root
        frame, ``tool`` the flange in the last link's frame.

    Raises
    ------
    CalibrationError
        A missing or unreadable file, a joint that is not a one-degree-of-freedom revolute
        joint, an unknown flange frame, or a table that does not reproduce the URDF (the
        largest difference in the message).
    """
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"{path}: no such URDF file")
    try:
        model = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as err:
        raise CalibrationError(f"{path}: not a readable URDF ({err})") from None
    kinds = [model.joints[j].shortname() for j in range(1, model.njoints)]
    bad = [k for k in kinds if not k.startswith("JointModelR") or "Unbounded" in k]
    if bad or model.nq != model.nv:
        raise CalibrationError(
            f"{path}: the chain needs revolute joints of one degree of freedom each; found {kinds}"
        )
    data = model.createData()
    points, dirs = _axis_lines(model, data)
    q0 = np.zeros(model.nq)
    pin.forwardKinematics(model, data, q0)
    fid = _flange_id(model, path, flange)
    pin.updateFramePlacements(model, data)
    flange0 = _flange_pose(model, data, fid)
    base = _frame(points[0], _first_x(dirs[0]), dirs[0])
    frames, links = [base], []
    for i in range(1, len(dirs)):
        frame, link = _next_frame(frames[-1], points[i], dirs[i])
        frames.append(frame)
        links.append(link)
    last = frames[-1]
    d_last = float((flange0[:3, 3] - last[:3, 3]) @ last[:3, 2])
    links.append(Link("dh", a=0.0, alpha=0.0, d=d_last, theta=0.0))
    end = last.copy()
    end[:3, 3] += d_last * last[:3, 2]
    robot = Robot(
        name or model.name,
        links,
        model.lowerPositionLimit.copy(),
        model.upperPositionLimit.copy(),
        base=base,
        tool=np.linalg.inv(end) @ flange0,
        source={"urdf": path.name},
    )
    _check_agreement(robot, model, data, fid, path)
    return robot


def _flange_pose(model: pin.Model, data: pin.Data, fid) -> np.ndarray:
    """The flange in the root frame (mm) after forward kinematics and frame placements."""
    placement = data.oMf[fid] if fid is not None else data.oMi[model.njoints - 1]
    out = np.array(placement.homogeneous, dtype=float)
    out[:3, 3] *= 1000.0
    return out


def _first_x(z: np.ndarray) -> np.ndarray:
    """An x axis perpendicular to ``z``: the root frame's x (or y) with its z part removed."""
    for axis in np.eye(3):
        x = axis - (axis @ z) * z
        if np.linalg.norm(x) > 1e-6:
            return x / np.linalg.norm(x)
    raise AssertionError("unreachable: no axis of the root frame is off z")


def _flange_id(model: pin.Model, path: Path, flange: str | None):
    if flange is None:
        return None
    if not model.existFrame(flange):
        names = [f.name for f in model.frames]
        raise CalibrationError(f"{path}: no frame {flange!r} for the flange; frames: {names}")
    return model.getFrameId(flange)


def _check_agreement(robot: Robot, model: pin.Model, data: pin.Data, fid, path: Path) -> None:
    rng = np.random.default_rng(0)
    lo = np.maximum(model.lowerPositionLimit, -math.pi)
    hi = np.minimum(model.upperPositionLimit, math.pi)
    worst = 0.0
    for _ in range(CHECK_CONFIGURATIONS):
        q = rng.uniform(lo, hi)
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        ref = _flange_pose(model, data, fid)
        worst = max(worst, float(np.abs(robot.fk(q) - ref).max()))
    if worst > AGREEMENT_TOL:
        raise CalibrationError(
            f"{path}: the DH table derived from the URDF differs from it by {worst:.3g} "
            f"(mm or rad) at the flange; the chain is not the serial chain of its joints"
        )
