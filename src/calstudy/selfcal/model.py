"""The global model of the ``selfcal`` paper: robot, sensor mounting and base as one vector.

The global model of Eq. 1-6 maps a point ``C`` measured in the sensor frame to the part frame::

    P = PHS(q) C = PH1(q1) 1H2(q2) 2H3(q3) 3H4(q4) 4H5(q5) 5HS(q6) C

with 30 parameters, in the order of :data:`PARAM_NAMES`:

- ``PH1`` (Eq. 4-5):
  ``transl(x2, y2, z2) rotz(gamma2) roty(phi2) rotx(eps2) Rz(q1) Tx(a1) Rx(alpha1)`` (8 parameters);
  the robot's own ``d1`` and ``theta1`` fold into the base pose.
- ``1H2`` (Eq. 2, axes 2 and 3 nominally parallel):
  ``Rz(q2 + theta2) Tx(a2) Rx(alpha2) Ry(beta2)``, Hayati's model with ``d2 = 0`` (4 parameters).
- ``2H3``, ``3H4``, ``4H5`` (Eq. 1, DH): ``Rz(q + theta) Tz(d) Tx(a) Rx(alpha)`` (4 each).
- ``5HS`` (Eq. 3): ``Rz(q6) transl(x1, y1, z1) rotz(gamma1) roty(phi1) rotx(eps1)`` (6 parameters).
  The paper writes ``5HS = 5H6 6HS`` as one constant transform; the sixth joint must turn
  somewhere, and the only place that keeps the count at 30 is first, about the z axis of frame 5
  (the joint-6 axis), so the link-6 parameters ``theta6, d6, a6, alpha6`` fold into the sensor
  pose. :func:`parameters_from_robot` builds the vector from a DH robot and the tests check the
  two chains agree.

The model is one ``pinocchio.Model`` whose 32 one-degree-of-freedom joints are the 30 parameters
and the 6 robot joints (``theta_i`` and ``q_i`` share one revolute joint), so one call gives the
forward kinematics and the identification Jacobian: the derivative of ``P`` with respect to a
parameter is the velocity of ``P`` when that "joint" moves.

Frames: ``part`` is the laser tracker's frame in which the sphere centres are known; ``sensor``
is the scanner's frame. Millimetres and radians.

:func:`default_model` is the one instance the rest of the package shares. The identification
on this model is :mod:`calstudy.selfcal.identify`; neither module knows the simulated
scenario, so both serve measured data as well.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pinocchio as pin

from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import euler_zyx_to_matrix, make_transform, matrix_to_euler_zyx, skew
from calstudy.models.kinematics import LINK_FIELDS, Robot

# ----------------------------------------------------------------------------------------------
# the 30 parameters

BASE_NAMES = ("x2", "y2", "z2", "gamma2", "phi2", "eps2")
ROBOT_NAMES = (
    "a1",
    "alpha1",
    "theta2",
    "a2",
    "alpha2",
    "beta2",
    "theta3",
    "d3",
    "a3",
    "alpha3",
    "theta4",
    "d4",
    "a4",
    "alpha4",
    "theta5",
    "d5",
    "a5",
    "alpha5",
)
SENSOR_NAMES = ("x1", "y1", "z1", "gamma1", "phi1", "eps1")
PARAM_NAMES = BASE_NAMES + ROBOT_NAMES + SENSOR_NAMES
N_PARAMS = len(PARAM_NAMES)
BASE = slice(0, 6)
ROBOT = slice(6, 24)
SENSOR = slice(24, 30)
GROUPS = ("base",) * 6 + ("robot",) * 18 + ("sensor",) * 6
IS_LENGTH = np.array([n[:-1] in ("x", "y", "z", "a", "d") for n in PARAM_NAMES])
#: Characteristic length (mm) that turns a rotation (rad) into a displacement, for comparing
#: columns of the identification Jacobian: the arm's reach is about 2 m, the sensor sits 0.3 m
#: from the spheres; 1 m is between the two.
ANGLE_SCALE_MM = 1000.0

# the elementary chain: (kind, axis, parameter index or None, joint index or None)
_P, _R = "P", "R"
_CHAIN = (
    [(_P, "x", 0, None), (_P, "y", 1, None), (_P, "z", 2, None)]
    + [(_R, "z", 3, None), (_R, "y", 4, None), (_R, "x", 5, None)]
    + [(_R, "z", None, 0), (_P, "x", 6, None), (_R, "x", 7, None)]
    + [(_R, "z", 8, 1), (_P, "x", 9, None), (_R, "x", 10, None), (_R, "y", 11, None)]
    + [
        item
        for k, j in ((12, 2), (16, 3), (20, 4))
        for item in ((_R, "z", k, j), (_P, "z", k + 1, None), (_P, "x", k + 2, None))
        + ((_R, "x", k + 3, None),)
    ]
    + [(_R, "z", None, 5)]
    + [(_P, "x", 24, None), (_P, "y", 25, None), (_P, "z", 26, None)]
    + [(_R, "z", 27, None), (_R, "y", 28, None), (_R, "x", 29, None)]
)
_JOINT_TYPES = {
    (_P, "x"): pin.JointModelPX,
    (_P, "y"): pin.JointModelPY,
    (_P, "z"): pin.JointModelPZ,
    (_R, "x"): pin.JointModelRX,
    (_R, "y"): pin.JointModelRY,
    (_R, "z"): pin.JointModelRZ,
}


def pose_to_params(transform: np.ndarray) -> np.ndarray:
    """``(x, y, z, gamma, phi, eps)`` (mm, rad) of ``transl(x,y,z) rotz roty rotx`` (Eq. 3-4)."""
    t = np.asarray(transform, dtype=float)
    return np.concatenate([t[:3, 3], np.radians(matrix_to_euler_zyx(t[:3, :3]))])


def params_to_pose(vec) -> np.ndarray:
    """Inverse of :func:`pose_to_params`: a 4 x 4 transform from 6 numbers (mm, rad)."""
    v = np.asarray(vec, dtype=float)
    return make_transform(euler_zyx_to_matrix(*np.degrees(v[3:6])), v[:3])


class GlobalModel:
    """The 30-parameter model of Eq. 1-6 as one Pinocchio model (see the module docstring).

    Attributes
    ----------
    model, data : pinocchio.Model, pinocchio.Data
        32 one-degree-of-freedom joints; ``data`` is reused, so an instance is not thread safe.
    """

    def __init__(self) -> None:
        model = pin.Model()
        model.name = "selfcal global model"
        parent = 0
        big = np.full(1, 1e9)
        for i, (kind, axis, _, _) in enumerate(_CHAIN):
            parent = model.addJoint(
                parent, _JOINT_TYPES[kind, axis](), pin.SE3.Identity(), f"e{i}", big, big, -big, big
            )
        self.model, self.data, self._last = model, model.createData(), parent
        self._memory: tuple | None = None  # (key, points, Jacobian) of the last call
        n = len(_CHAIN)
        self._from_params = np.zeros((n, N_PARAMS))
        self._from_q = np.zeros((n, 6))
        for i, (_, _, k, j) in enumerate(_CHAIN):
            if k is not None:
                self._from_params[i, k] = 1.0
            if j is not None:
                self._from_q[i, j] = 1.0
        # the joint each parameter moves (one per parameter: a column of _from_params)
        self._param_joint = np.argmax(self._from_params, axis=0)

    def _configs(self, params, Q) -> np.ndarray:
        p = np.asarray(params, dtype=float)
        if p.shape != (N_PARAMS,) or not np.all(np.isfinite(p)):
            raise CalibrationError(
                f"parameter vector has shape {p.shape} or non-finite values; "
                f"the global model needs {N_PARAMS} finite numbers"
            )
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != 6:
            raise CalibrationError(f"joint angles have shape {Q.shape}; expected (m, 6)")
        return Q @ self._from_q.T + self._from_params @ p

    def sensor2part(self, params, Q) -> np.ndarray:
        """Sensor poses ``(m, 4, 4)`` in the part frame (Eq. 6) at joint angles ``Q`` (m, 6)."""
        out = np.empty((len(Q), 4, 4))
        model, data, last, placements = self.model, self.data, self._last, self.data.oMi
        forward = pin.forwardKinematics
        for k, cfg in enumerate(self._configs(params, Q)):
            forward(model, data, cfg)
            out[k] = placements[last].homogeneous
        return out

    def sensor_centres(self, params, Q, points_part) -> np.ndarray:
        """Where part-frame points ``(m, 3)`` lie in the sensor frame at joint angles ``Q``
        (m, 6), mm: the noise-free reading of a sphere centre, the inverse of :meth:`points`."""
        poses = self.sensor2part(params, Q)
        p = np.asarray(points_part, float)
        return np.einsum("mji,mj->mi", poses[:, :3, :3], p - poses[:, :3, 3])

    def points(self, params, Q, C) -> np.ndarray:
        """Part-frame points ``P = sensor2part(q) C`` (Eq. 9), ``(m, 3)`` mm, for ``C`` (m, 3)."""
        poses = self.sensor2part(params, Q)
        return np.einsum("mij,mj->mi", poses[:, :3, :3], np.asarray(C, float)) + poses[:, :3, 3]

    def points_and_jacobian(self, params, Q, C) -> tuple[np.ndarray, np.ndarray]:
        """Points ``(m, 3)`` and their Jacobian ``(3 m, 30)`` with respect to the parameters.

        Row ``3 k + i`` is ``dP_k[i] / dparams``: mm per mm for lengths, mm per rad for angles.
        The answer of the last call is kept (read-only arrays): a least-squares fit that takes
        its residuals from here asks for the Jacobian at the same point next.
        """
        key = tuple(np.asarray(a, dtype=float).tobytes() for a in (params, Q, C))
        if self._memory is None or self._memory[0] != key:
            points, jac = self._points_and_jacobian(params, Q, C)
            points.flags.writeable = jac.flags.writeable = False
            self._memory = (key, points, jac)
        return self._memory[1], self._memory[2]

    def _points_and_jacobian(self, params, Q, C) -> tuple[np.ndarray, np.ndarray]:
        cfgs = self._configs(params, Q)
        C = np.asarray(C, dtype=float)
        m = len(cfgs)
        jac6 = np.empty((m, 6, len(_CHAIN)))
        rot = np.empty((m, 3, 3))
        pos = np.empty((m, 3))
        model, data, last, placements = self.model, self.data, self._last, self.data.oMi
        compute, get = pin.computeJointJacobians, pin.getJointJacobian
        for k, cfg in enumerate(cfgs):
            compute(model, data, cfg)
            jac6[k] = get(model, data, last, pin.LOCAL_WORLD_ALIGNED)
            placement = placements[last]
            rot[k], pos[k] = placement.rotation, placement.translation
        lever = np.einsum("mij,mj->mi", rot, C)
        # velocity of the point P = origin + R C: v + w x (R C) = v - [R C]_x w
        dpoint = jac6[:, :3, :] - skew(lever) @ jac6[:, 3:, :]
        # each parameter moves one joint: its column, + 0.0 as the product with the 0/1 matrix
        # it replaces (a zero comes out +0.0), in the same C order (later products see the
        # same memory layout)
        jac = np.take(dpoint, self._param_joint, axis=2) + 0.0
        return lever + pos, jac.reshape(3 * m, N_PARAMS)


# ----------------------------------------------------------------------------------------------
# from a DH robot to the 30 parameters


def _check_table(robot: Robot) -> None:
    if robot.nq != 6 or robot.convention != "dh":
        raise CalibrationError(
            f"the global model needs a 6-joint DH robot; the {robot.name} has {robot.nq} "
            f"{robot.convention} links"
        )
    betas = {i + 1: link.beta for i, link in enumerate(robot.links) if i != 1 and link.beta != 0}
    if betas:
        raise CalibrationError(
            f"Hayati beta is only modelled on link 2 (axes 2 and 3); the {robot.name} has "
            f"beta on links {sorted(betas)}"
        )
    if robot.links[1].d != 0.0:
        raise CalibrationError(
            f"link 2 of Eq. 2 has no offset d; the {robot.name} has d2 = {robot.links[1].d:.6g} mm"
        )


def parameters_from_robot(robot: Robot, part2base, sensor2flange) -> np.ndarray:
    """The 30 parameters of the system made of ``robot``, its placement and its sensor.

    Parameters
    ----------
    robot : Robot
        Six DH links; ``beta`` only on link 2, ``d2 = 0`` (the form of Eq. 2).
    part2base : array_like, shape (4, 4)
        The robot base frame in the part frame (maps base coordinates to part coordinates).
    sensor2flange : array_like, shape (4, 4)
        The sensor frame in the flange frame.

    Returns
    -------
    numpy.ndarray, shape (30,)
        In the order of :data:`PARAM_NAMES`, mm and rad.

    Raises
    ------
    CalibrationError
        A robot that is not six DH links, Hayati ``beta`` on a link other than 2, or ``d2``
        not zero.
    """
    _check_table(robot)
    links = robot.links
    first = links[0]
    base = (
        np.asarray(part2base, float)
        @ robot.base
        @ make_transform(np.eye(3), [0.0, 0.0, first.d])
        @ make_transform(euler_zyx_to_matrix(math.degrees(first.theta), 0.0, 0.0), np.zeros(3))
    )
    sensor = links[5].split()[1] @ robot.tool @ np.asarray(sensor2flange, float)
    second = links[1]
    middle = [first.a, first.alpha, second.theta, second.a, second.alpha, second.beta]
    for link in links[2:5]:
        middle += [link.theta, link.d, link.a, link.alpha]
    return np.concatenate([pose_to_params(base), middle, pose_to_params(sensor)])


def _folded_base(robot: Robot) -> np.ndarray:
    """What :func:`parameters_from_robot` folds into the base pose after ``part2base``: the
    table's base frame, ``d1`` and ``theta1``."""
    first = robot.links[0]
    return (
        robot.base
        @ make_transform(np.eye(3), [0.0, 0.0, first.d])
        @ make_transform(euler_zyx_to_matrix(math.degrees(first.theta), 0.0, 0.0), np.zeros(3))
    )


def cell_from_parameters(robot: Robot, params) -> tuple[Robot, np.ndarray, np.ndarray]:
    """The robot table, base placement and sensor mounting that the 30 parameters describe.

    The inverse of :func:`parameters_from_robot` for the quantities the model folds together:
    ``d1``, ``theta1`` and the table's base frame stay those of ``robot`` and the rest of the
    base pose goes to ``part2base``; link 6 and the table's tool frame stay those of ``robot``
    and the rest of the sensor pose goes to ``sensor2flange``.

    Parameters
    ----------
    robot : Robot
        The nominal robot (six DH links of the form of Eq. 2).
    params : array_like, shape (30,)
        Parameters in the order of :data:`PARAM_NAMES`, mm and rad.

    Returns
    -------
    robot : Robot
        ``robot`` with ``a1, alpha1``, link 2's ``theta, a, alpha, beta`` and links 3-5's
        ``theta, d, a, alpha`` from ``params``.
    part2base : numpy.ndarray, shape (4, 4)
        The robot base frame in the part frame, mm.
    sensor2flange : numpy.ndarray, shape (4, 4)
        The sensor frame in the flange frame, mm.

    Raises
    ------
    CalibrationError
        A robot that is not a six-joint DH table of the form of Eq. 2, or ``params`` not 30
        finite numbers.
    """
    _check_table(robot)
    p = np.asarray(params, float)
    if p.shape != (N_PARAMS,) or not np.isfinite(p).all():
        raise CalibrationError(f"parameters have shape {p.shape}; 30 finite numbers are needed")
    table = robot.parameters().reshape(robot.nq, -1)
    for k, name in enumerate(ROBOT_NAMES):
        table[int(name[-1]) - 1, LINK_FIELDS.index(name[:-1])] = p[ROBOT][k]
    identified = robot.with_parameters(table.ravel())
    part2base = params_to_pose(p[BASE]) @ np.linalg.inv(_folded_base(robot))
    link6 = robot.links[5].split()[1] @ robot.tool
    sensor2flange = np.linalg.solve(link6, params_to_pose(p[SENSOR]))
    return identified, part2base, sensor2flange


@cache
def default_model() -> GlobalModel:
    """The package's shared :class:`GlobalModel` (built once; not thread safe, see the class)."""
    return GlobalModel()


# ----------------------------------------------------------------------------------------------
# parameter errors


def angle_wrap(d: np.ndarray) -> np.ndarray:
    """A parameter difference (30,) with its angles wrapped into ``[-pi, pi)``, lengths as given."""
    out = d.copy()
    out[~IS_LENGTH] = (out[~IS_LENGTH] + math.pi) % (2 * math.pi) - math.pi
    return out


def scaled_error(est, truth, part=slice(None)) -> float:
    """RMS of the parameter error, angles as mm at ``ANGLE_SCALE_MM`` (see ``scaled_jacobian``).

    ``part`` selects the parameters (a slice such as :data:`ROBOT`; all by default).
    """
    d = angle_wrap(np.asarray(est, float) - truth)
    d = np.where(IS_LENGTH, d, d * ANGLE_SCALE_MM)[part]
    return float(np.sqrt(np.mean(d**2)))
