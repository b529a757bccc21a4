"""Serial robots from DH and MDH link tables, built as Pinocchio models.

A robot is a chain of revolute joints described by one :class:`Link` per joint. Two table
conventions are supported, each optionally with Hayati's rotation ``beta`` about y, which keeps
the model continuous when two consecutive joint axes are nominally parallel (Hayati 1983; the
``selfcal`` paper's Eq. 2, which calls this the MDH model).

Standard DH (``convention="dh"``), row ``i`` maps frame ``i`` to frame ``i-1``::

    T_i = Rz(q_i + theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)

With ``beta_i = 0`` this is the textbook DH matrix. With ``d_i = 0`` and ``beta_i != 0`` it is
the Hayati-MDH matrix of the ``selfcal`` paper (Eq. 2).

Modified DH after Craig (``convention="mdh"``), row ``i`` maps frame ``i`` to frame ``i-1``::

    T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Ry(beta_{i-1}) Rz(q_i + theta_i) Tz(d_i)

Row ``i`` stores ``a = a_{i-1}``, ``alpha = alpha_{i-1}``, ``beta = beta_{i-1}`` (the link
*before* joint ``i``, as in Craig's table) and ``d = d_i``, ``theta = theta_i``. Because ``Rx``
and ``Tx`` commute, both conventions use the same factors ``Tx(a) Rx(alpha) Ry(beta)``: DH puts
them after the joint, MDH before it, so an MDH table is a DH table with the ``(a, alpha, beta)``
columns shifted down one row (the last DH triple becomes the constant ``tool``).

The flange pose in the robot base frame is ``flange2base = base @ T_1 ... T_n @ tool`` with two
constant transforms: ``base`` (frame 0 of the table in the base frame) and ``tool`` (the flange
in frame ``n``); both default to the identity and are not part of the parameter vector.

Units: millimetres and radians. The TOML files in ``data/robots/`` hold degrees, converted on
loading.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import check_transform

CONVENTIONS = ("dh", "mdh")
LINK_FIELDS = ("a", "alpha", "d", "theta", "beta")
PARAMS_PER_LINK = len(LINK_FIELDS)
_LENGTH_FIELDS = ("a", "d")
FLANGE = "flange"
DEFAULT_MARGIN = math.radians(5.0)
_TURN = 2.0 * math.pi
#: the default convergence threshold of :meth:`Robot.ik` (norm of the error twist)
IK_TOL = 1e-10
_MAX_IK_STEP = 0.5  # rad per joint and iteration: a trust region that keeps LM off far branches


# ----------------------------------------------------------------------------------------------
# elementary transforms


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out = np.eye(4)
    out[i, i], out[i, j], out[j, i], out[j, j] = c, -s, s, c
    return out


def _trans(axis: int, length: float) -> np.ndarray:
    out = np.eye(4)
    out[axis, 3] = length
    return out


def _se3(transform: np.ndarray) -> pin.SE3:
    return pin.SE3(transform[:3, :3].copy(), transform[:3, 3].copy())


# ----------------------------------------------------------------------------------------------
# links


@dataclass(frozen=True)
class Link:
    """One row of a DH or MDH table: the constant geometry around one revolute joint.

    Parameters
    ----------
    convention : {"dh", "mdh"}
        Standard DH or Craig's modified DH; see the module docstring for the matrices.
    a : float
        Link length in mm (``a_i`` for DH, ``a_{i-1}`` for MDH).
    alpha : float
        Link twist in rad (``alpha_i`` for DH, ``alpha_{i-1}`` for MDH).
    d : float
        Link offset along the joint axis in mm (``d_i``).
    theta : float
        Joint zero offset in rad (``theta_i``), added to the joint angle ``q_i``.
    beta : float, optional
        Hayati rotation about y in rad (``beta_i`` for DH, ``beta_{i-1}`` for MDH); 0 by default.
    parallel : bool, optional
        True where the link joins two nominally parallel joint axes. Such a link gets a
        perturbed ``beta`` in :func:`perturb_robot` even when its nominal ``beta`` is 0.
    """

    convention: str
    a: float
    alpha: float
    d: float
    theta: float
    beta: float = 0.0
    parallel: bool = False

    def __post_init__(self) -> None:
        if self.convention not in CONVENTIONS:
            raise CalibrationError(
                f"unknown link convention {self.convention!r}; expected 'dh' or 'mdh'"
            )
        for name in LINK_FIELDS:
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise CalibrationError(
                    f"link parameter {name} is not a number ({value!r})"
                ) from None
            if not math.isfinite(value):
                raise CalibrationError(f"link parameter {name} is not finite ({value!r})")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "parallel", bool(self.parallel))

    def split(self) -> tuple[np.ndarray, np.ndarray]:
        """Constant 4 x 4 transforms ``(pre, post)`` with ``T_i(q) = pre @ Rz(q) @ post``."""
        tail = _trans(0, self.a) @ _rot(0, self.alpha) @ _rot(1, self.beta)
        if self.convention == "dh":
            return np.eye(4), _rot(2, self.theta) @ _trans(2, self.d) @ tail
        return tail @ _rot(2, self.theta), _trans(2, self.d)

    def transform(self, q: float) -> np.ndarray:
        """Link matrix ``T_i(q)``, 4 x 4, mapping frame ``i`` to frame ``i-1``; ``q`` in rad."""
        pre, post = self.split()
        return pre @ _rot(2, float(q)) @ post


# ----------------------------------------------------------------------------------------------
# robots


class Robot:
    """A serial robot of revolute joints, its link table and its Pinocchio model.

    Parameters
    ----------
    name : str
        Display name, used in error messages ("the KUKA KR 16-2 has 6 joints").
    links : sequence of Link
        One link per joint, base to flange, all of the same convention.
    qmin, qmax : array_like, shape (n,)
        Joint limits in rad, finite, ``qmin < qmax``.
    base : array_like, shape (4, 4), optional
        Frame 0 of the table in the robot base frame (``link0_2base``); identity by default.
    tool : array_like, shape (4, 4), optional
        The flange in the frame of the last link (``flange2link_n``); identity by default.
    tolerances : dict, optional
        ``sigma_length_mm`` and ``sigma_angle_deg``, the defaults of :func:`perturb_robot`.
    source : dict, optional
        Where the numbers come from (the ``[source]`` table of the TOML file).

    Attributes
    ----------
    model, data : pinocchio.Model, pinocchio.Data
        One revolute-Z joint per link with the constant parts of the links folded into the joint
        placements, and a frame named ``"flange"``. ``data`` is reused by every call, so a Robot
        is not safe to share between threads.
    """

    def __init__(
        self,
        name: str,
        links: Sequence[Link],
        qmin,
        qmax,
        base=None,
        tool=None,
        tolerances: dict | None = None,
        source: dict | None = None,
    ) -> None:
        self.name = str(name)
        self.links = tuple(links)
        if not self.links or not all(isinstance(link, Link) for link in self.links):
            raise CalibrationError(
                f"the {self.name} needs at least one Link (got {len(self.links)} items)"
            )
        conventions = sorted({link.convention for link in self.links})
        if len(conventions) > 1:
            raise CalibrationError(f"the {self.name} mixes link conventions {conventions}; use one")
        self.convention = conventions[0]
        self.qmin = self._check_vector(qmin, "qmin")
        self.qmax = self._check_vector(qmax, "qmax")
        bad = np.flatnonzero(self.qmin >= self.qmax)
        if bad.size:
            j = int(bad[0])
            raise CalibrationError(
                f"joint {j + 1} of the {self.name} has an empty range "
                f"({math.degrees(self.qmin[j]):.1f} to {math.degrees(self.qmax[j]):.1f} deg)"
            )
        self.base = np.eye(4) if base is None else check_transform("base", base).copy()
        self.tool = np.eye(4) if tool is None else check_transform("tool", tool).copy()
        for label, t in (("base", self.base), ("tool", self.tool)):
            if t.shape != (4, 4):
                raise CalibrationError(f"{label} has shape {t.shape}; expected (4, 4)")
        self.tolerances = None if tolerances is None else dict(tolerances)
        self.source = {} if source is None else dict(source)
        self.model = self._build_model()
        self.data = self.model.createData()
        self._flange_id = self.model.getFrameId(FLANGE)

    # ------------------------------------------------------------------ construction helpers

    @property
    def nq(self) -> int:
        """Number of joints."""
        return len(self.links)

    def _build_model(self) -> pin.Model:
        model = pin.Model()
        model.name = self.name
        big = np.full(1, 1e9)
        parent, carry = 0, self.base
        for i, link in enumerate(self.links):
            pre, post = link.split()
            parent = model.addJoint(
                parent,
                pin.JointModelRZ(),
                _se3(carry @ pre),
                f"joint{i + 1}",
                big,
                big,
                self.qmin[i : i + 1].copy(),
                self.qmax[i : i + 1].copy(),
            )
            carry = post
        model.addFrame(pin.Frame(FLANGE, parent, _se3(carry @ self.tool), pin.FrameType.OP_FRAME))
        return model

    def _check_vector(self, values, label: str) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        if v.shape != (self.nq,):
            what = f"{v.size} values" if v.ndim == 1 else f"shape {v.shape}"
            raise CalibrationError(f"{label} has {what}; the {self.name} has {self.nq} joints")
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            j = int(bad[0])
            raise CalibrationError(
                f"{label} holds a non-finite value ({float(v[j])!r}) at joint {j + 1}"
            )
        return v

    def _check_many(self, values, label: str) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        if v.ndim != 2 or v.shape[1] != self.nq:
            raise CalibrationError(
                f"{label} has shape {v.shape}; the {self.name} needs (N, {self.nq}) joint angles"
            )
        bad = np.argwhere(~np.isfinite(v))
        if bad.size:
            k, j = (int(x) for x in bad[0])
            raise CalibrationError(
                f"{label} holds a non-finite value ({float(v[k, j])!r}) at row {k}, joint {j + 1}"
            )
        return v

    # ------------------------------------------------------------------ kinematics

    def fk(self, q) -> np.ndarray:
        """Flange pose for one joint configuration.

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint angles in rad. Joint limits are not checked here.

        Returns
        -------
        numpy.ndarray, shape (4, 4)
            ``flange2base``, translation in mm.
        """
        q = self._check_vector(q, "q")
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self._flange_id).homogeneous

    def fk_many(self, Q) -> np.ndarray:
        """Flange poses ``flange2base`` ``(N, 4, 4)`` in mm for joint angles ``Q`` ``(N, n)``."""
        Q = self._check_many(Q, "Q")
        out = np.empty((Q.shape[0], 4, 4))
        model, data, fid = self.model, self.data, self._flange_id
        for k, q in enumerate(Q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, fid).homogeneous
        return out

    def jacobian(self, q) -> np.ndarray:
        """Geometric Jacobian of the flange, ``(6, n)``, in Pinocchio's LOCAL_WORLD_ALIGNED frame.

        Rows 0-2 are the velocity of the flange origin (mm/rad), rows 3-5 the angular velocity
        (rad/rad), both in base-frame axes: ``d(flange position)/dq_j = J[:3, j]`` and
        ``dR/dq_j R^T = skew(J[3:, j])``.
        """
        q = self._check_vector(q, "q")
        return pin.computeFrameJacobian(
            self.model, self.data, q, self._flange_id, pin.LOCAL_WORLD_ALIGNED
        )

    def ik(self, flange2base, q0, tol: float = IK_TOL, max_iter: int = 200) -> np.ndarray:
        """Joint angles that put the flange at ``flange2base``, by damped least squares.

        Levenberg-Marquardt on the SE(3) error ``log6(flange2base_current^-1 flange2base)``
        (``[v mm, w rad]``), starting from ``q0``; the damping falls after a step that reduces the
        error and rises after one that does not. Angles are then shifted by multiples of 2 pi,
        nearest to ``q0``, to fall inside the joint limits where possible. The search is local: from
        a far ``q0`` it may land on another solution branch (then usually outside the limits) and
        close to a singularity it may stall; both raise.

        Parameters
        ----------
        flange2base : array_like, shape (4, 4)
            Wanted flange pose, mm.
        q0 : array_like, shape (n,)
            Start configuration in rad; picks the solution branch.
        tol : float
            Convergence threshold on the norm of the error 6-vector (mm and rad mixed).
        max_iter : int
            Number of Jacobian evaluations allowed.

        Returns
        -------
        numpy.ndarray, shape (n,)
            Joint angles in rad, within the joint limits.

        Raises
        ------
        CalibrationError
            If the error has not fallen below ``tol`` after ``max_iter`` iterations, or the solution
            is outside the joint limits, or ``flange2base`` lies so far away (beyond about
            1e154 mm) that the error's square overflows.
        """
        target = check_transform("flange2base", flange2base)
        if target.shape != (4, 4):
            raise CalibrationError(f"flange2base has shape {target.shape}; expected (4, 4)")
        q = self._check_vector(q0, "q0").copy()
        q_start = q.copy()
        desired = _se3(target)
        err = self._ik_error(q, desired)
        cost = float(err @ err)
        if not math.isfinite(cost):  # |error| past 1e154: no step of the search is a number
            raise CalibrationError(
                f"flange2base: translation {target[:3, 3].tolist()} mm lies too far from the "
                "flange at q0 for any robot (the squared IK error overflows past 1e308)"
            )
        damping, iterations = 1e-6, 0
        eye = np.eye(self.nq)
        while math.sqrt(cost) > tol and iterations < max_iter:
            iterations += 1
            jac = self._ik_jacobian(q, desired)
            jt = jac.T
            jtj, jte = jt @ jac, jt @ err
            while True:
                try:
                    step = -np.linalg.solve(jtj + damping * eye, jte)
                except np.linalg.LinAlgError:  # numerically singular: damp more, or give up
                    trial_cost = cost
                    if damping > 1e12:
                        break
                    damping *= 10.0
                    continue
                step *= min(1.0, _MAX_IK_STEP / np.abs(step).max())
                q_trial = q + step
                trial_err = self._ik_error(q_trial, desired)
                trial_cost = float(trial_err @ trial_err)
                if trial_cost < cost or damping > 1e12:
                    break
                damping *= 10.0
            if trial_cost >= cost:
                break
            q, err, cost = q_trial, trial_err, trial_cost
            damping = max(damping / 10.0, 1e-12)
        residual = math.sqrt(cost)
        if residual > tol:
            stalled = "" if iterations == max_iter else "; stalled, try another q0"
            raise CalibrationError(
                f"IK did not converge after {iterations} iterations "
                f"(residual {residual:.1e} mm / rad, tolerance {tol:g}{stalled})"
            )
        return self._wrap_into_limits(q, q_start)

    def _ik_error(self, q: np.ndarray, desired: pin.SE3) -> np.ndarray:
        model, data, fid = self.model, self.data, self._flange_id
        pin.forwardKinematics(model, data, q)
        return pin.log6(pin.updateFramePlacement(model, data, fid).actInv(desired)).vector

    def _ik_jacobian(self, q: np.ndarray, desired: pin.SE3) -> np.ndarray:
        jac = pin.computeFrameJacobian(self.model, self.data, q, self._flange_id, pin.LOCAL)
        current_to_desired = self.data.oMf[self._flange_id].actInv(desired)
        return -pin.Jlog6(current_to_desired.inverse()) @ jac

    def _wrap_into_limits(self, q: np.ndarray, q_start: np.ndarray) -> np.ndarray:
        out = q.copy()
        for j, (qj, lo, hi, q0) in enumerate(
            zip(q.tolist(), self.qmin.tolist(), self.qmax.tolist(), q_start.tolist(), strict=True)
        ):
            first = math.ceil((lo - qj) / _TURN)
            last = math.floor((hi - qj) / _TURN)
            if first > last:
                raise CalibrationError(
                    f"IK solution is outside the joint limits: joint {j + 1} at "
                    f"{math.degrees(qj):.2f} deg, range {math.degrees(lo):.1f} to "
                    f"{math.degrees(hi):.1f} deg"
                )
            # the candidate nearest the start (the first one on a tie), in float arithmetic
            inside = [qj + _TURN * float(i) for i in range(first, last + 1)]
            dist = [abs(x - q0) for x in inside]
            out[j] = inside[dist.index(min(dist))]
        return out

    # ------------------------------------------------------------------ parameters

    def parameters(self) -> np.ndarray:
        """All link parameters as a flat vector ``(5 n,)``.

        Order: link by link, ``(a, alpha, d, theta, beta)`` per link; lengths in mm, angles in
        rad. :meth:`parameter_names` names the entries. ``base`` and ``tool`` are not included.
        """
        return np.array([[getattr(link, f) for f in LINK_FIELDS] for link in self.links]).ravel()

    def key(self) -> tuple:
        """Everything the robot's kinematics depend on (conventions, link parameters, base, tool,
        joint limits), as hashable bytes: two robots with the same key give the same FK and IK
        answers, so results can be kept by it."""
        return (
            tuple((link.convention, link.parallel) for link in self.links),
            self.parameters().tobytes(),
            self.base.tobytes(),
            self.tool.tobytes(),
            self.qmin.tobytes(),
            self.qmax.tobytes(),
        )

    def parameter_names(self) -> list[str]:
        """Names of :meth:`parameters`: ``"a1", "alpha1", "d1", "theta1", "beta1", "a2", ...``.

        For DH tables every name of row ``i`` carries index ``i``. For MDH tables the names follow
        Craig's indices: row ``i`` gives ``a{i-1}, alpha{i-1}, d{i}, theta{i}, beta{i-1}``.
        """
        shift = {"a": 1, "alpha": 1, "beta": 1} if self.convention == "mdh" else {}
        return [f"{f}{i - shift.get(f, 0)}" for i in range(1, self.nq + 1) for f in LINK_FIELDS]

    def parameter_is_length(self) -> np.ndarray:
        """Mask ``(5 n,)`` over :meth:`parameters`: True for lengths (mm), False for angles."""
        return np.tile([f in _LENGTH_FIELDS for f in LINK_FIELDS], self.nq)

    def with_parameters(self, vec) -> Robot:
        """A new Robot with the link parameters ``vec`` ``(5 n,)`` (order of :meth:`parameters`).

        Name, conventions, ``parallel`` flags, limits, ``base``, ``tool``, tolerances and source
        are kept.
        """
        v = np.asarray(vec, dtype=float)
        size = PARAMS_PER_LINK * self.nq
        if v.shape != (size,):
            raise CalibrationError(
                f"parameter vector has shape {v.shape}; the {self.name} has {size} parameters"
            )
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            k = int(bad[0])
            name = self.parameter_names()[k]
            raise CalibrationError(
                f"parameter vector holds a non-finite value ({float(v[k])!r}) at {name}"
            )
        rows = v.reshape(self.nq, PARAMS_PER_LINK)
        links = [
            replace(link, **dict(zip(LINK_FIELDS, (float(x) for x in row), strict=True)))
            for link, row in zip(self.links, rows, strict=True)
        ]
        return Robot(
            self.name,
            links,
            self.qmin,
            self.qmax,
            self.base,
            self.tool,
            self.tolerances,
            self.source,
        )

    def random_configurations(
        self, rng: np.random.Generator, n: int, margin: float = DEFAULT_MARGIN
    ) -> np.ndarray:
        """Joint configurations ``(n, nq)`` in rad, uniform within the limits shrunk by ``margin``.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of randomness.
        n : int
            Number of configurations.
        margin : float
            Distance in rad kept from each joint limit (5 degrees by default).
        """
        check_rng(rng)
        if int(n) != n or n < 0:
            raise CalibrationError(
                f"number of configurations must be a whole number >= 0 (got {n})"
            )
        lo, hi = self.qmin + margin, self.qmax - margin
        bad = np.flatnonzero(~(lo < hi))
        if bad.size:
            j = int(bad[0])
            raise CalibrationError(
                f"margin {math.degrees(margin):.1f} deg leaves no range for joint {j + 1} "
                f"(limits {math.degrees(self.qmin[j]):.1f} to {math.degrees(self.qmax[j]):.1f} deg)"
            )
        return rng.uniform(lo, hi, size=(int(n), self.nq))

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, {self.nq} joints, {self.convention})"


def check_rng(rng) -> None:
    """Raise unless ``rng`` is a :class:`numpy.random.Generator`."""
    if not isinstance(rng, np.random.Generator):
        raise CalibrationError(
            f"rng must be a numpy.random.Generator (got {type(rng).__name__}); "
            "use numpy.random.default_rng(seed)"
        )
