"""A strict reach bound of a serial robot: flange poses that no joint angles can reach.

:meth:`calstudy.models.kinematics.Robot.ik` is a local search; on a flange pose beyond the
arm's reach it iterates until it stalls, which costs far more than a converging solve. The
bound below tells such poses apart beforehand from the link geometry alone, whatever the joint
limits and the start, so a caller can refuse them without searching.

The bound (a theorem, no approximation). The robot's Pinocchio model (the placements its forward
and inverse kinematics use) is the chain

    flange2base(q) = M_0 Rz(q_1) M_1 Rz(q_2) M_2 ... Rz(q_n) M_n

of constant placements ``M_k`` (``M_0 = base @ pre_1``, ``M_k = post_k @ pre_{k+1}``,
``M_n = post_n @ tool``; see :meth:`~calstudy.models.kinematics.Link.split`). Let
``J_k = M_0 Rz(q_1) ... M_{k-1} Rz(q_k)`` be the frame of joint ``k`` after its turn, with
rotation ``R_k`` (``R_0 = I``) and origin ``o_k``, and write ``t(M)``, ``R(M)`` for the parts of
a placement.

1. The wrist point. ``J_n = flange2base @ M_n^-1``, so ``o_n = F c`` with
   ``c = -R(M_n)^T t(M_n)``: a point fixed in the flange frame, the same for every ``q``.
2. ``o_n = t(M_0) + sum_{k=1}^{n-1} R_k t(M_k)``.
3. ``Rz(q_k)`` leaves ``e_z`` fixed, so ``R_k e_z = R_{k-1} R(M_{k-1}) e_z``: the part of
   ``t(M_k) = x_k + z_k e_z`` along the axis of joint ``k`` does not turn with ``q_k`` and joins
   the previous term. Hence ``o_n = P + sum_{k=1}^{n-1} R_k g_k`` with
   ``P = t(M_0) + z_1 R(M_0) e_z``, ``g_k = x_k + z_{k+1} R(M_k) e_z`` for ``k < n - 1`` and
   ``g_{n-1} = x_{n-1}``: constant vectors of the robot, each turned by a rotation, so
   ``|R_k g_k| = |g_k|`` whatever ``q``.
4. The first term, ``R_1 g_1 = R(M_0) Rz(q_1) g_1``, puts the shoulder point
   ``S(q_1) = P + R(M_0) Rz(q_1) g_1`` on a circle about the axis ``a = R(M_0) e_z`` of joint 1:
   centre ``C = P + g_{1,z} a``, radius ``r = |(g_{1,x}, g_{1,y})|``.
5. By the triangle inequality ``|o_n - S(q_1)| <= L = sum_{k=2}^{n-1} |g_k|`` for every ``q``.
   The distance of a point ``w`` from that circle is ``sqrt((rho - r)^2 + h^2)``, with
   ``h = (w - C) . a`` and ``rho = |w - C - h a|``. So for every reachable pose ``F``,
   ``excess(F) = dist(F c, circle) - L <= 0``; a pose with ``excess > 0`` is reached by no joint
   angles at all.

For the KUKA KR 16-2 table ``r = 260`` mm at the height of axis 2 (675 mm), ``c`` is 158 mm
behind the flange on its z axis (the wrist centre) and ``L = 680 + sqrt(670^2 + 35^2)`` mm: the
bound is the arm stretched, and it is tight for the nominal table. For a drawn robot (link
offsets that the table leaves at zero) it stays strict and is looser by the small offsets.

The solver's tolerance. ``ik`` accepts a pose ``T`` when the error twist
``xi = log6(F(q)^-1 T)`` has ``|xi| <= tol``; then ``T c`` lies within
``|omega| |c| + |v| (1 + |omega|) <= tol (|c| + 1 + tol)`` of ``F(q) c``, so ``excess(T)`` is at
most that much above ``excess(F(q)) <= 0``. :meth:`ReachBound.margin_mm` adds twice that to one
micrometre, which covers the rounding of the few operations on millimetre numbers by orders of
magnitude: a pose with ``excess > margin_mm(tol)`` makes ``ik(pose, q0, tol)`` fail from every
``q0``.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.models.kinematics import IK_TOL, Robot

#: the margin beyond the rounding and the solver tolerance (mm)
ROUNDING_MARGIN_MM = 1e-3


class ReachBound:
    """The reach bound of one robot (module docstring); build it with :func:`reach_bound`.

    Attributes
    ----------
    wrist : numpy.ndarray, shape (3,)
        ``c``, the point fixed in the flange frame on the axis of the last joint (mm).
    centre, axis : numpy.ndarray, shape (3,)
        Centre of the shoulder circle and the unit axis of joint 1, base frame.
    radius, reach : float
        Radius ``r`` of the shoulder circle and ``L``, the longest distance from it to the
        wrist point (mm).
    """

    def __init__(self, robot: Robot) -> None:
        model = robot.model
        n = robot.nq
        flange = model.frames[model.getFrameId("flange")]
        placements = [model.jointPlacements[k + 1] for k in range(n)]  # M_0 ... M_{n-1}
        placements.append(flange.placement)  # M_n
        rot = [np.array(m.rotation) for m in placements]
        trans = [np.array(m.translation) for m in placements]
        e_z = np.array([0.0, 0.0, 1.0])
        self.wrist = -rot[n].T @ trans[n]
        if n < 2:  # one joint: no rotating term before the wrist point; never refuse
            self.axis = rot[0] @ e_z
            self.centre = trans[0].copy()
            self.radius, self.reach = 0.0, math.inf
            return

        def z_part(k: int) -> float:
            return float(trans[k][2])

        def g(k: int) -> np.ndarray:
            x = trans[k] - z_part(k) * e_z
            return x + z_part(k + 1) * (rot[k] @ e_z) if k < n - 1 else x

        g1 = g(1)
        self.axis = rot[0] @ e_z
        self.centre = trans[0] + z_part(1) * self.axis + float(g1[2]) * self.axis
        self.radius = math.hypot(float(g1[0]), float(g1[1]))
        self.reach = float(sum(np.linalg.norm(g(k)) for k in range(2, n)))

    def excess(self, flange2base) -> float:
        """How far (mm) the wrist point of ``flange2base`` lies beyond the arm's reach: > 0 for
        a pose that no joint angles reach, <= 0 for every pose :meth:`Robot.fk` gives.

        Parameters
        ----------
        flange2base : array_like, shape (4, 4)
            Flange pose, mm. Not checked for rigidity (callers check their poses once).

        Returns
        -------
        float
            The excess, mm; finite for every finite pose whose wrist point lies within about
            1e308 mm of the shoulder circle (``-inf`` for an arm of one joint, which reaches
            everywhere by this bound).

        Raises
        ------
        CalibrationError
            If the pose holds NaN or infinity, or its wrist point is too far away for a float.
        """
        pose = np.asarray(flange2base, dtype=float)
        d = pose[:3, :3] @ self.wrist + pose[:3, 3] - self.centre
        h = float(d @ self.axis)
        dd = float(d @ d)
        if math.isfinite(dd):
            rho = math.sqrt(max(dd - h * h, 0.0))
        else:  # past 1e154 mm the squares overflow: the same in units of the largest |d_i|
            scale = float(np.abs(d).max())
            u = d / scale
            hu = float(u @ self.axis)
            rho = scale * math.sqrt(max(float(u @ u) - hu * hu, 0.0))
        out = math.hypot(rho - self.radius, h) - self.reach
        if not out < math.inf:  # NaN or +inf (-inf is a one-joint arm's: never refused)
            raise CalibrationError(
                f"flange2base: translation {pose[:3, 3].tolist()} mm has no finite distance to "
                "the arm (NaN, infinity or beyond 1e308 mm)"
            )
        return out

    def margin_mm(self, tol: float = IK_TOL) -> float:
        """The excess above which ``Robot.ik(..., tol=tol)`` fails from every start (mm)."""
        return ROUNDING_MARGIN_MM + 2.0 * tol * (float(np.linalg.norm(self.wrist)) + 1.0 + tol)

    def unreachable(self, flange2base, tol: float = IK_TOL) -> bool:
        """True if no joint angles put the flange at ``flange2base`` within ``tol``: then
        ``Robot.ik(flange2base, q0, tol)`` raises CalibrationError from every ``q0``."""
        return self.excess(flange2base) > self.margin_mm(tol)


def reach_bound(robot: Robot) -> ReachBound:
    """The :class:`ReachBound` of ``robot``, computed once per Robot object (a Robot builds its
    Pinocchio model once, at construction, and the bound comes from that model)."""
    bound = _BOUNDS.get(robot)
    if bound is None:
        bound = _BOUNDS[robot] = ReachBound(robot)
    return bound


_BOUNDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
