"""The workpiece frame from three datum features by the 3-2-1 rule (hybrid paper, section 2.2).

Sensor A measures a slot (its y and z fix the workpiece), sensor B a hole (x, y, z), sensor C a
point on a plane (z): six coordinates for six degrees of freedom. With the datum points measured in
the robot base frame, ``P_B``, and their CAD coordinates in the workpiece frame, ``P_W``, the
transform ``base2work = [R | T]`` satisfies the six equations of Eq. 3.

Two solvers:

* :func:`rps_frame_penalty`, the paper's: the twelve entries of ``[R | T]`` by Levenberg-Marquardt
  on Eq. 5, ``E = sum F_i^2 + M sum f_i^2`` with the orthogonality conditions ``f_i`` of Eq. 4
  weighted by the penalty factor ``M``.
* :func:`rps_frame_so3`, the constrained solution: six parameters (translation and rotation
  vector), so ``R`` is a rotation by construction, solving Eq. 3 alone.

:func:`rps_frame_batch` solves Eq. 3 on SO(3) for many panels at once (vectorised Newton steps),
for production runs where every panel gets its own frame.
"""

from __future__ import annotations

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.estimation import Estimate, check_condition, levenberg_marquardt

#: (datum index, workpiece axis) of the six equations F1..F6 of Eq. 3: A:y,z  B:x,y,z  C:z
RPS_EQUATIONS = ((0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 2))
DATUM_NAMES = ("A (slot)", "B (hole)", "C (plane)")
#: condition number of the 3-2-1 Jacobian above which the frame is undetermined (a fixture
#: of a few hundred mm gives about 1e3)
MAX_RPS_CONDITION = 1e8
#: largest residual (mm) of Eq. 3 accepted at the solution: six equations in six unknowns are
#: solved exactly unless the measured datums contradict the CAD coordinates
MAX_RPS_RESIDUAL = 1e-6
_RPS_ADVICE = (
    "the measured datums contradict the CAD coordinates (datum C measured on the line through "
    "A and B, or datums swapped); check which datum is which"
)


def _check_solution(est: Estimate, p_b, p_w, label: str, condition: bool = True) -> Estimate:
    """Refuse an unobservable frame (condition number) or equations left unsatisfied.

    ``condition=False`` skips the condition number: the penalty problem's 12-entry Jacobian is
    conditioned by the penalty weight ``M``, not by the datums (whose geometry the SO(3)
    solution and :func:`check_datums` judge).
    """
    if condition:
        check_condition(
            est.condition_number, MAX_RPS_CONDITION, f"{label}: the frame", _RPS_ADVICE
        )
    res = rps_equations(est.value, p_b, p_w)
    k = int(np.argmax(np.abs(res)))
    if abs(res[k]) > MAX_RPS_RESIDUAL * max(1.0, np.abs(p_w).max()):
        datum, axis = RPS_EQUATIONS[k]
        raise CalibrationError(
            f"{label}: equation F{k + 1} (datum {DATUM_NAMES[datum]}, workpiece "
            f"{'xyz'[axis]}) is left at {res[k]:.3g} mm: no rigid frame maps the measured "
            "datums onto the CAD coordinates; " + _RPS_ADVICE
        )
    return est


def check_datums(datums_base, datums_work) -> tuple[np.ndarray, np.ndarray]:
    p_b = geo.check_shape("datums in base", datums_base, (3, 3))
    p_w = geo.check_shape("datums in workpiece (CAD)", datums_work, (3, 3))
    # A and B fix the line of rotation about z and y; C must lie off that line for rotation about x
    ab = p_w[1] - p_w[0]
    ac = p_w[2] - p_w[0]
    ab_yz = np.linalg.norm(ab)
    if ab_yz < 1e-6:
        raise CalibrationError(
            "datums A and B coincide in the CAD frame; the 3-2-1 rule needs a line"
        )
    off = np.linalg.norm(np.cross(ab, ac)) / ab_yz
    if off < 1.0:
        raise CalibrationError(
            f"datum C lies {off:.3g} mm from the line through A and B; the rotation about that "
            "line is undetermined (move C at least 1 mm off the line)"
        )
    return p_b, p_w


def rps_equations(base2work, datums_base, datums_work) -> np.ndarray:
    """The six residuals ``F1..F6`` of Eq. 3 (mm) for a 3 x 4 or 4 x 4 ``[R | T]``."""
    m = np.asarray(base2work, dtype=float)
    mapped = datums_base @ m[:3, :3].T + m[:3, 3]
    return np.array([mapped[i, ax] - datums_work[i, ax] for i, ax in RPS_EQUATIONS])


def orthogonality(rotation) -> np.ndarray:
    """The six conditions ``f1..f6`` of Eq. 4 (column norms minus one, row dot products)."""
    r = np.asarray(rotation, dtype=float)
    return np.array(
        [
            r[:, 0] @ r[:, 0] - 1.0,
            r[:, 1] @ r[:, 1] - 1.0,
            r[:, 2] @ r[:, 2] - 1.0,
            r[0] @ r[1],
            r[0] @ r[2],
            r[1] @ r[2],
        ]
    )


def rps_frame_penalty(
    datums_base, datums_work, initial, penalty: float = 1e4, max_nfev: int = 2000
) -> Estimate:
    """``base2work`` by Levenberg-Marquardt on Eq. 5 with orthogonality penalty ``M``.

    Parameters
    ----------
    datums_base : (3, 3) array
        Measured datum points A (slot), B (hole), C (plane) in the robot base frame, mm.
    datums_work : (3, 3) array
        The same datums in the workpiece frame (CAD), mm. Only the coordinates of Eq. 3 are used.
    initial : (4, 4) array
        Starting ``base2work`` (the nominal placement of the part on the fixture).
    penalty : float
        The penalty factor ``M`` (mm^2 per unit of squared orthogonality defect).
    max_nfev : int
        Evaluation budget of the solver.

    Returns
    -------
    Estimate
        ``value`` the 4 x 4 ``[R | T]`` as solved (``R`` orthonormal only as far as the penalty
        enforces it); ``params`` the 12 entries (R row-major, then T); covariance from the
        Jacobian with the residual scale estimated; ``condition_number`` of the Jacobian.

    Raises
    ------
    CalibrationError
        On bad input, a non-positive penalty, non-convergence, or a reflection (det R < 0).
    """
    p_b, p_w = check_datums(datums_base, datums_work)
    init = geo.check_transform("initial base2work", initial)
    if not isinstance(max_nfev, int | np.integer) or max_nfev < 1:
        raise CalibrationError(f"max_nfev must be a positive integer; got {max_nfev!r}")
    if not np.isfinite(penalty) or penalty <= 0:
        raise CalibrationError(f"penalty factor M must be positive and finite; got {penalty}")
    weight = np.sqrt(penalty)

    def unpack(x):
        return geo.make_transform(x[:9].reshape(3, 3), x[9:])

    def residuals(x):
        r = x[:9].reshape(3, 3)
        return np.concatenate([rps_equations(unpack(x), p_b, p_w), weight * orthogonality(r)])

    x0 = np.concatenate([init[:3, :3].ravel(), init[:3, 3]])
    est = levenberg_marquardt(
        residuals,
        x0,
        names=[f"r{i}{j}" for i in range(1, 4) for j in range(1, 4)] + ["t1", "t2", "t3"],
        max_nfev=max_nfev,
        label=f"RPS penalty LM (M = {penalty:g})",
        to_value=unpack,
        sigma=1.0,
    )
    det = np.linalg.det(est.value[:3, :3])
    if det < 0:
        raise CalibrationError(f"the penalty solution is a reflection (det R = {det:.4f})")
    return _check_solution(est, p_b, p_w, f"RPS penalty LM (M = {penalty:g})", condition=False)


def rps_frame_so3(datums_base, datums_work, initial) -> Estimate:
    """``base2work`` with ``R`` constrained to SO(3): six parameters, six equations (Eq. 3).

    Parameters are as in :func:`rps_frame_penalty`. ``params`` is ``[T, rotvec]`` of the
    correction ``base2work = [R_init exp(w) | T]``; the covariance is that of unit-variance
    datum coordinates (scale it by the datum measurement variance).

    Raises
    ------
    CalibrationError
        On bad shapes or degenerate CAD datums, non-convergence, a frame the measured datums
        leave undetermined (condition number above :data:`MAX_RPS_CONDITION`) or equations the
        solution cannot satisfy (measured datums contradicting the CAD).
    """
    p_b, p_w = check_datums(datums_base, datums_work)
    init = geo.check_transform("initial base2work", initial)

    def unpack(x):
        return geo.make_transform(init[:3, :3] @ geo.rotvec_to_matrix(x[3:]), x[:3])

    est = levenberg_marquardt(
        lambda x: rps_equations(unpack(x), p_b, p_w),
        np.concatenate([init[:3, 3], np.zeros(3)]),
        names=["t1", "t2", "t3", "w1", "w2", "w3"],
        label="RPS on SO(3)",
        to_value=unpack,
        sigma=1.0,
    )
    return _check_solution(est, p_b, p_w, "RPS on SO(3)")


def rps_frame_batch(
    datums_base, datums_work, initial, tol: float = 1e-9, max_iter: int = 30
) -> np.ndarray:
    """``base2work (N, 4, 4)`` of N panels by the 3-2-1 rule (Eq. 3), R on SO(3), vectorised.

    Solves the six equations of Eq. 3 exactly for every panel at once by Newton steps
    on ``(T, rotation vector)`` (the same solution as :func:`rps_frame_so3`).

    Parameters
    ----------
    datums_base : (N, 3, 3) array
        Measured datums A, B, C of each panel in the base frame, mm.
    datums_work : (3, 3) array
        The datums in the workpiece frame (CAD), mm.
    initial : (4, 4) array
        Starting ``base2work`` (the nominal fixture pose).
    tol : float
        Largest residual (mm) accepted.
    max_iter : int
        Newton steps allowed.

    Returns
    -------
    numpy.ndarray, shape (N, 4, 4)
        ``base2work`` of each panel, ``R`` a rotation.

    Raises
    ------
    CalibrationError
        On bad shapes, degenerate CAD datums, a singular system or no convergence.
    """
    p = np.asarray(datums_base, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (3, 3):
        raise CalibrationError(f"datums_base has shape {p.shape}; expected (N, 3, 3)")
    geo.check_finite("datums_base", p)
    _, w = check_datums(p[0], datums_work)
    init = geo.check_transform("initial base2work", initial)
    n = p.shape[0]
    di = np.array([d for d, _ in RPS_EQUATIONS])
    ai = np.array([a for _, a in RPS_EQUATIONS])
    rot = np.broadcast_to(init[:3, :3], (n, 3, 3)).copy()
    trans = np.broadcast_to(init[:3, 3], (n, 3)).copy()
    jac = np.zeros((n, 6, 6))
    jac[:, np.arange(6), ai] = 1.0
    for _ in range(max_iter):
        rp = np.einsum("nij,nkj->nki", rot, p)  # R p_k, (n, 3 datums, 3)
        res = (rp + trans[:, None, :])[:, di, ai] - w[di, ai]
        if np.abs(res).max() < tol:
            break
        # left perturbation R <- exp(w) R moves R p by w x (R p) = -[R p]x w
        v = rp[:, di, :]
        jac[:, :, 3:] = -geo.skew(v)[:, np.arange(6), ai, :]
        cond = np.linalg.cond(jac)
        if not np.all(np.isfinite(cond)) or cond.max() > MAX_RPS_CONDITION:
            k = int(np.argmax(np.where(np.isfinite(cond), cond, np.inf)))
            where = f"the frame of panel {k}"
            check_condition(float(cond[k]), MAX_RPS_CONDITION, where, _RPS_ADVICE)
        try:
            step = np.linalg.solve(jac, -res[..., None])[..., 0]
        except np.linalg.LinAlgError as exc:
            raise CalibrationError(f"3-2-1 system is singular for some panel: {exc}") from exc
        trans += step[:, :3]
        rot = geo.rotvec_to_matrix(step[:, 3:]) @ rot
    else:
        raise CalibrationError(
            f"3-2-1 frame did not converge in {max_iter} steps (largest residual "
            f"{np.abs(res).max():.3g} mm)"
        )
    return geo.make_transform(rot, trans)
