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
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import pinocchio as pin
from pydantic import Field, model_validator

from calstudy.core import paths, schema
from calstudy.core.errors import CalibrationError
from calstudy.core.geometry import check_transform, rotation_error, translation_error

CONVENTIONS = ("dh", "mdh")
LINK_FIELDS = ("a", "alpha", "d", "theta", "beta")
PARAMS_PER_LINK = len(LINK_FIELDS)
_LENGTH_FIELDS = ("a", "d")
FLANGE = "flange"
DEFAULT_MARGIN = math.radians(5.0)
_TURN = 2.0 * math.pi
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

    def ik(self, flange2base, q0, tol: float = 1e-10, max_iter: int = 200) -> np.ndarray:
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
            is outside the joint limits.
        """
        target = check_transform("flange2base", flange2base)
        if target.shape != (4, 4):
            raise CalibrationError(f"flange2base has shape {target.shape}; expected (4, 4)")
        q = self._check_vector(q0, "q0").copy()
        q_start = q.copy()
        desired = _se3(target)
        err = self._ik_error(q, desired)
        cost = float(err @ err)
        damping, iterations = 1e-6, 0
        while math.sqrt(cost) > tol and iterations < max_iter:
            iterations += 1
            jac = self._ik_jacobian(q, desired)
            jtj, jte = jac.T @ jac, jac.T @ err
            while True:
                try:
                    step = -np.linalg.solve(jtj + damping * np.eye(self.nq), jte)
                except np.linalg.LinAlgError:  # numerically singular: damp more, or give up
                    trial_cost = cost
                    if damping > 1e12:
                        break
                    damping *= 10.0
                    continue
                step *= min(1.0, _MAX_IK_STEP / np.abs(step).max())
                trial_err = self._ik_error(q + step, desired)
                trial_cost = float(trial_err @ trial_err)
                if trial_cost < cost or damping > 1e12:
                    break
                damping *= 10.0
            if trial_cost >= cost:
                break
            q, err, cost = q + step, trial_err, trial_cost
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
        pin.forwardKinematics(self.model, self.data, q)
        current = pin.updateFramePlacement(self.model, self.data, self._flange_id)
        return np.asarray(pin.log6(current.actInv(desired)).vector)

    def _ik_jacobian(self, q: np.ndarray, desired: pin.SE3) -> np.ndarray:
        jac = pin.computeFrameJacobian(self.model, self.data, q, self._flange_id, pin.LOCAL)
        current_to_desired = self.data.oMf[self._flange_id].actInv(desired)
        return -pin.Jlog6(current_to_desired.inverse()) @ jac

    def _wrap_into_limits(self, q: np.ndarray, q_start: np.ndarray) -> np.ndarray:
        out = q.copy()
        for j in range(self.nq):
            first = math.ceil((self.qmin[j] - q[j]) / _TURN)
            last = math.floor((self.qmax[j] - q[j]) / _TURN)
            inside = q[j] + _TURN * np.arange(first, last + 1)
            if inside.size == 0:
                raise CalibrationError(
                    f"IK solution is outside the joint limits: joint {j + 1} at "
                    f"{math.degrees(q[j]):.2f} deg, range {math.degrees(self.qmin[j]):.1f} to "
                    f"{math.degrees(self.qmax[j]):.1f} deg"
                )
            out[j] = inside[np.argmin(np.abs(inside - q_start[j]))]
        return out

    # ------------------------------------------------------------------ parameters

    def parameters(self) -> np.ndarray:
        """All link parameters as a flat vector ``(5 n,)``.

        Order: link by link, ``(a, alpha, d, theta, beta)`` per link; lengths in mm, angles in
        rad. :meth:`parameter_names` names the entries. ``base`` and ``tool`` are not included.
        """
        return np.array([[getattr(link, f) for f in LINK_FIELDS] for link in self.links]).ravel()

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
        _check_rng(rng)
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


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise CalibrationError(
            f"rng must be a numpy.random.Generator (got {type(rng).__name__}); "
            "use numpy.random.default_rng(seed)"
        )


# ----------------------------------------------------------------------------------------------
# loading


#: largest link length or offset accepted (mm): 10 m, beyond any serial robot
MAX_LINK_MM = 1e4
_Length = Annotated[float, Field(ge=-MAX_LINK_MM, le=MAX_LINK_MM, allow_inf_nan=False)]
_Angle = Annotated[float, Field(ge=-360.0, le=360.0, allow_inf_nan=False)]
_JointLimit = Annotated[float, Field(ge=-720.0, le=720.0, allow_inf_nan=False)]


class LinkEntry(schema.Schema):
    """One ``[[link]]`` of a robot table (mm and degrees)."""

    convention: Literal["dh", "mdh"]
    a_mm: _Length
    alpha_deg: _Angle
    d_mm: _Length
    theta_deg: _Angle
    beta_deg: _Angle = 0.0
    qmin_deg: _JointLimit
    qmax_deg: _JointLimit
    parallel: bool = False

    @model_validator(mode="after")
    def _range(self):
        if self.qmin_deg >= self.qmax_deg:
            raise ValueError(
                f"qmin_deg = {self.qmin_deg:g} must be below qmax_deg = {self.qmax_deg:g}"
            )
        return self


class RobotTolerances(schema.Schema):
    """The ``[tolerances]`` table: standard deviations of the link parameters."""

    sigma_length_mm: Annotated[float, Field(ge=0, le=100, allow_inf_nan=False)]
    sigma_angle_deg: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)]
    justification: str = ""


class RobotFile(schema.Schema):
    """A robot table ``data/robots/<name>.toml``."""

    name: str = Field(min_length=1)
    source: dict[str, str] = {}
    link: list[LinkEntry] = Field(min_length=1, max_length=12)
    tolerances: RobotTolerances | None = None

    @model_validator(mode="after")
    def _one_convention(self):
        conventions = sorted({entry.convention for entry in self.link})
        if len(conventions) > 1:
            raise ValueError(f"links mix conventions {conventions}; use one")
        return self


def _check_robot_units(path, table: RobotFile) -> None:
    """Refuse a table whose angles look like radians or lengths like metres."""
    for i, entry in enumerate(table.link):
        for key in ("alpha_deg", "theta_deg", "beta_deg"):
            value = getattr(entry, key)
            if value != 0 and min(abs(abs(value) - math.pi / 2), abs(abs(value) - math.pi)) < 1e-3:
                raise CalibrationError(
                    f"{path}: link #{i + 1}.{key} = {value:g} looks like radians (pi/2 or pi); the "
                    "table holds degrees"
                )
    lengths = [abs(v) for e in table.link for v in (e.a_mm, e.d_mm)]
    if max(lengths) < 10.0:
        raise CalibrationError(
            f"{path}: every a_mm and d_mm is below 10 (largest {max(lengths):g}): they look like "
            "metres; the table holds millimetres"
        )


def robot_file(name: str | Path) -> Path:
    """The path of robot table ``name``: a file stem of ``data/robots/`` or a path to a
    ``.toml`` file; FileNotFoundError naming it (and the stems available) if it is missing."""
    name_s = str(name)
    if isinstance(name, Path) or name_s.endswith(".toml") or "/" in name_s:
        path = Path(name_s)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such robot table")
        return path
    path = paths.DATA_DIR / "robots" / f"{name_s}.toml"
    if not path.is_file():
        have = sorted(p.stem for p in (paths.DATA_DIR / "robots").glob("*.toml"))
        raise FileNotFoundError(
            f"data/robots/{name_s}.toml: no such robot table; available: {', '.join(have)}"
        )
    return path


def load_robot(name: str | Path) -> Robot:
    """Read a robot table: ``data/robots/<name>.toml``, or a path to one's own ``.toml`` file.

    The file has a top-level ``name`` (display name), a ``[source]`` table, one ``[[link]]`` per
    joint with ``convention``, ``a_mm``, ``alpha_deg``, ``d_mm``, ``theta_deg``, ``beta_deg``,
    ``qmin_deg``, ``qmax_deg`` (and optionally ``parallel``), and a ``[tolerances]`` table with
    ``sigma_length_mm`` and ``sigma_angle_deg``. The schema (:class:`RobotFile`) checks every key
    (unknown keys are refused, so a misspelt key is not silently a default), every range
    (lengths within +-10 m, angles within +-360 deg, ``qmin_deg < qmax_deg``, tolerances >= 0)
    and the units (an angle of 1.5708 looks like radians, all lengths below 10 like metres).

    Parameters
    ----------
    name : str or pathlib.Path
        File stem, e.g. ``"kuka_kr16_2"``, or a path ending in ``.toml``.

    Returns
    -------
    Robot
        With joint limits in rad and ``tolerances`` / ``source`` taken from the file.

    Raises
    ------
    FileNotFoundError
        If the file does not exist (the message lists the tables available).
    CalibrationError
        If the file is not valid TOML or breaks the schema; the message names the file, the
        key (``link #2.a_mm``, entries counted from 1), the value and the allowed range.
    """
    path = robot_file(name)
    in_data = path.parent == paths.DATA_DIR / "robots"
    where = f"data/robots/{path.name}" if in_data else str(path)
    raw = schema.read_toml(path, "robot table")
    raw.setdefault("name", Path(str(name)).stem)
    table = schema.validate(RobotFile, raw, where)
    _check_robot_units(where, table)
    links = [
        Link(
            entry.convention,
            a=entry.a_mm,
            alpha=math.radians(entry.alpha_deg),
            d=entry.d_mm,
            theta=math.radians(entry.theta_deg),
            beta=math.radians(entry.beta_deg),
            parallel=entry.parallel,
        )
        for entry in table.link
    ]
    tolerances = None
    if table.tolerances is not None:
        tolerances = {
            "sigma_length_mm": table.tolerances.sigma_length_mm,
            "sigma_angle_deg": table.tolerances.sigma_angle_deg,
        }
    return Robot(
        table.name,
        links,
        [math.radians(e.qmin_deg) for e in table.link],
        [math.radians(e.qmax_deg) for e in table.link],
        tolerances=tolerances,
        source=dict(table.source),
    )


# ----------------------------------------------------------------------------------------------
# the "true" robot


def _check_sigma(value: float, label: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise CalibrationError(f"{label} must be finite and >= 0 (got {value!r})")
    return value


def perturb_robot(
    robot: Robot,
    rng: np.random.Generator,
    sigma_length_mm: float | None = None,
    sigma_angle_deg: float | None = None,
) -> Robot:
    """A "true" robot: the nominal link parameters plus independent normal manufacturing errors.

    Every ``a`` and ``d`` gets ``N(0, sigma_length_mm^2)`` mm, every ``alpha`` and ``theta`` gets
    ``N(0, sigma_angle_deg^2)`` deg (converted to rad). ``beta`` is perturbed only on links with
    ``parallel=True`` or a nonzero nominal ``beta``; elsewhere it stays as it is (a beta on a
    non-parallel link would duplicate the other parameters). One normal draw per parameter is
    taken in the order of :meth:`Robot.parameters` whatever the mask, so the draws of a seed do
    not depend on which betas are free.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    rng : numpy.random.Generator
        Source of randomness.
    sigma_length_mm, sigma_angle_deg : float, optional
        Standard deviations; by default those of ``robot.tolerances`` (the TOML file).

    Returns
    -------
    Robot
        Same joints, limits, base and tool; perturbed link parameters.
    """
    _check_rng(rng)
    defaults = robot.tolerances or {}
    sigmas = []
    for value, key in ((sigma_length_mm, "sigma_length_mm"), (sigma_angle_deg, "sigma_angle_deg")):
        if value is None:
            if key not in defaults:
                raise CalibrationError(
                    f"the {robot.name} has no tolerances table; pass {key} explicitly"
                )
            value = defaults[key]
        sigmas.append(_check_sigma(value, key))
    sigma_length, sigma_angle = sigmas[0], math.radians(sigmas[1])
    scale = np.where(robot.parameter_is_length(), sigma_length, sigma_angle).reshape(robot.nq, -1)
    beta_col = LINK_FIELDS.index("beta")
    for i, link in enumerate(robot.links):
        if not (link.parallel or link.beta != 0.0):
            scale[i, beta_col] = 0.0
    noise = rng.standard_normal(scale.size) * scale.ravel()
    return robot.with_parameters(robot.parameters() + noise)


def pose_errors(nominal: Robot, true: Robot, Q) -> tuple[np.ndarray, np.ndarray]:
    """Flange pose differences between two robots at the same joint angles.

    Parameters
    ----------
    nominal, true : Robot
        Two robots with the same number of joints.
    Q : array_like, shape (N, n)
        Joint angles in rad.

    Returns
    -------
    position_error_mm : numpy.ndarray, shape (N,)
        Distance between the two flange origins, mm.
    rotation_error_rad : numpy.ndarray, shape (N,)
        Angle of the relative rotation of the two flanges, rad.
    """
    if nominal.nq != true.nq:
        raise CalibrationError(
            f"the robots have {nominal.nq} and {true.nq} joints; pose errors need the same number"
        )
    nominal_poses = nominal.fk_many(Q)
    true_poses = true.fk_many(Q)
    return translation_error(nominal_poses, true_poses), rotation_error(nominal_poses, true_poses)
