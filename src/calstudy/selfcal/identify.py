"""One-step identification of the ``selfcal`` global model from sphere-centre measurements.

What a cell's own data go through, simulated or measured: the bad-input checks of the sphere
layout and of each scanned cap, the sphere fit of Eq. 7-8 (:func:`fit_sphere_cap`), the
Levenberg-Marquardt identification of Eq. 10-11 (:func:`identify`, least squares as in the paper
or maximum likelihood with :func:`covariance`) and the identifiability of the 30 parameters
(:func:`identifiability`, :func:`scaled_jacobian`). The model is
:mod:`calstudy.selfcal.model`; the multi-step routes the paper argues against are in
:mod:`calstudy.papers.selfcal.routes`; nothing here knows the simulated scenario.

Frames: ``part`` is the laser tracker's frame, ``sensor`` the scanner's. Millimetres and radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.estimation import (
    Estimate,
    condition_number,
    covariance_from_jacobian,
    levenberg_marquardt,
)
from calstudy.core.geometry import check_shape
from calstudy.estimators.fitting import fit_sphere
from calstudy.selfcal.model import (
    ANGLE_SCALE_MM,
    GROUPS,
    IS_LENGTH,
    N_PARAMS,
    PARAM_NAMES,
    GlobalModel,
    default_model,
)

#: Relative singular value below which a direction of the identification Jacobian is a null
#: direction (round-off of a 72 x 30 matrix with condition 1e4 is about 1e-12).
RANK_RTOL = 1e-8


# ----------------------------------------------------------------------------------------------
# measurements and bad-input checks


@dataclass
class Measurements:
    """Sphere-centre measurements: what the identification sees, plus the truth for scoring.

    Attributes
    ----------
    Q : (m, 6) commanded joint angles, rad.
    C : (m, 3) fitted sphere centres in the sensor frame, mm (Eq. 7-8).
    P_ref : (m, 3) tracker reading of the sphere centre in the part frame, mm (``P^n``).
    sphere : (m,) index of the sphere placement.
    C_true : (m, 3) centre in the sensor frame as the sensor stood (no scanner noise); None for
        measured data (the design is then evaluated at ``C``).
    cov : (m, 3, 3) covariance of ``P - P_ref`` in the part frame: scanner fit, repeatability and
        tracker (the weights of the maximum-likelihood identification); None: noise not declared.
    tracker_cov : (m, 3, 3) the tracker's part of ``cov``: one reading per sphere placement, so
        this error is common to all measurements of the same sphere (see :func:`covariance`).
    Q_true : (m, 6) joint angles as the robot actually stood (commanded plus any unmodelled
        deflection), for scoring only; None means ``Q``. The identification never reads it.
    """

    Q: np.ndarray
    C: np.ndarray
    P_ref: np.ndarray
    sphere: np.ndarray
    C_true: np.ndarray | None = None
    cov: np.ndarray | None = None
    tracker_cov: np.ndarray | None = None
    Q_true: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.Q)

    @property
    def C_design(self) -> np.ndarray:
        """Sensor-frame centres for the design (Jacobian): ``C_true`` if known, else ``C``."""
        return self.C if self.C_true is None else self.C_true


def check_sphere_layout(centres, radius_mm: float) -> None:
    """Raise unless the sphere centres (k, 3) are distinct spheres and not on one line.

    Coincident: two centres closer than a sphere diameter (the spheres would overlap).
    Collinear: the second singular value of the centred set is below 1e-3 of the first (the
    ratio is in the message), which leaves the base rotation about that line undetermined.
    """
    c = np.asarray(centres, dtype=float)
    if c.ndim != 2 or c.shape[1] != 3 or len(c) < 3 or not np.all(np.isfinite(c)):
        raise CalibrationError(
            f"sphere centres have shape {c.shape}; need (k, 3) finite values with k >= 3"
        )
    d = np.linalg.norm(c[:, None] - c[None], axis=-1) + np.eye(len(c)) * 1e300
    i, j = np.unravel_index(np.argmin(d), d.shape)
    if d[i, j] < 2.0 * radius_mm:
        raise CalibrationError(
            f"spheres {i} and {j} coincide: centres {d[i, j]:.3g} mm apart, less than a "
            f"diameter ({2 * radius_mm:g} mm)"
        )
    s = np.linalg.svd(c - c.mean(axis=0), compute_uv=False)
    if s[1] < 1e-3 * s[0]:
        raise CalibrationError(
            f"the {len(c)} sphere placements are collinear (singular values {s[0]:.4g} and "
            f"{s[1]:.3g} mm, ratio {s[1] / s[0]:.2g}); place them off one line"
        )


def fit_sphere_cap(points, max_cond: float) -> tuple[np.ndarray, float, float]:
    """Centre of a scanned sphere cap by the linear least-squares fit of Eq. 7-8.

    :func:`calstudy.estimators.fitting.fit_sphere` with one more check: a cap so flat that its
    centre and radius are not fixed (condition number of the fit above ``max_cond``) raises.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        The scanned cap, sensor frame, mm.
    max_cond : float
        Largest condition number accepted (the scenario's ``max_cap_condition``).

    Returns
    -------
    centre (3,) mm, radius mm, condition number.
    """
    centre, radius, cond = fit_sphere(points)
    if cond > max_cond:
        raise CalibrationError(
            f"the scanned cap is too small to fix the radius: condition number {cond:.3g} of the "
            f"sphere fit exceeds {max_cond:g} (fitted radius {radius:.4g} mm); scan a larger cap"
        )
    return centre, radius, cond


def check_measurement_count(n_measurements: int, n_identifiable: int = N_PARAMS) -> None:
    """Raise if ``3 n_measurements`` equations cannot fix ``n_identifiable`` parameters."""
    if 3 * n_measurements < n_identifiable:
        raise CalibrationError(
            f"{n_measurements} sphere-centre measurements give {3 * n_measurements} equations "
            f"for {n_identifiable} identifiable parameters; need at least "
            f"{math.ceil(n_identifiable / 3)} measurements"
        )


# ----------------------------------------------------------------------------------------------
# identification (Eq. 10-11)


@dataclass
class Identification:
    """Result of one identification.

    Attributes
    ----------
    estimate : Estimate
        ``params`` (30,), covariance, residuals (mm, or whitened for ML), condition number.
    iterates : numpy.ndarray, shape (k + 1, 30)
        Parameters at the start and after each LM iteration (one Jacobian evaluation each).
    mean_error_mm : numpy.ndarray, shape (k + 1,)
        Mean position error ``|P_i - P_i^n|`` over the measurements at each iterate (Fig. 5).
    """

    estimate: Estimate
    iterates: np.ndarray
    mean_error_mm: np.ndarray

    @property
    def params(self) -> np.ndarray:
        return self.estimate.params

    @property
    def iterations(self) -> int:
        """LM iterations (Jacobian evaluations) until the solver stopped."""
        return len(self.iterates) - 1

    def iterations_to(self, rel: float = 0.01) -> int:
        """First iteration whose mean error is within ``rel`` of the final one (Fig. 5 reading)."""
        final = self.mean_error_mm[-1]
        ok = np.flatnonzero(self.mean_error_mm <= final * (1.0 + rel) + 1e-9)
        return int(ok[0])


def covariance(meas: Measurements) -> np.ndarray:
    """Covariance (3 m, 3 m) of the stacked residuals ``P_i - P_i^n`` at the true parameters, mm^2.

    ``meas.cov`` on the diagonal blocks; ``meas.tracker_cov`` between two measurements of the
    same sphere, whose tracker reading they share.
    """
    if meas.cov is None or meas.tracker_cov is None:
        raise CalibrationError(
            f"the {len(meas)} measurements declare no noise (cov is None); maximum-likelihood "
            "weights need the scanner, repeatability and tracker standard deviations"
        )
    same = meas.sphere[:, None] == meas.sphere[None, :]
    full = np.where(same[:, :, None, None], meas.tracker_cov[:, None], 0.0)
    idx = np.arange(len(meas))
    full[idx, idx] = meas.cov
    return full.transpose(0, 2, 1, 3).reshape(3 * len(meas), 3 * len(meas))


def _whitening(meas: Measurements) -> np.ndarray:
    """``L^-1`` (3 m, 3 m) with ``L L^T`` = :func:`covariance` of the measurements."""
    cov = covariance(meas)
    low = float(np.linalg.eigvalsh(cov)[0])
    if low <= 0:
        raise CalibrationError(
            f"the covariance of the {len(meas)} measurements is not positive definite (smallest "
            f"eigenvalue {low:.3g} mm^2); maximum-likelihood weights need noise that differs "
            "from one measurement to the next"
        )
    return np.linalg.inv(np.linalg.cholesky(cov))


@dataclass
class _Problem:
    """Residuals of Eq. 10-11 (whitened if ``white`` is given) and their Jacobian in the free
    parameters; ``iterates`` records the full parameter vector at each Jacobian evaluation.

    LM asks for the Jacobian at nearly every point where it evaluated the residuals, so the
    residuals come with the Jacobian (one kinematic pass, the same points to the bit), which
    :meth:`GlobalModel.points_and_jacobian` keeps for that request."""

    model: GlobalModel
    meas: Measurements
    start: np.ndarray
    mask: np.ndarray
    white: np.ndarray | None
    iterates: list[np.ndarray] = field(default_factory=list)
    mean_errors: dict[bytes, float] = field(default_factory=dict)

    def full(self, x) -> np.ndarray:
        p = self.start.copy()
        p[self.mask] = x
        return p

    def fun(self, x) -> np.ndarray:
        meas = self.meas
        points, _ = self.model.points_and_jacobian(self.full(x), meas.Q, meas.C)
        d = points - meas.P_ref
        key = np.asarray(x, float).tobytes()
        self.mean_errors[key] = float(np.sqrt(np.einsum("ij,ij->i", d, d)).mean())
        r = d.ravel()
        return r if self.white is None else self.white @ r

    def mean_error(self, p: np.ndarray) -> float:
        """Mean ``|P_i - P_i^n|`` at the full parameter vector ``p`` (cached from :meth:`fun`)."""
        key = p[self.mask].tobytes()
        if key not in self.mean_errors:
            self.fun(p[self.mask])
        return self.mean_errors[key]

    def jac(self, x) -> np.ndarray:
        self.iterates.append(self.full(x))
        _, j = self.model.points_and_jacobian(self.full(x), self.meas.Q, self.meas.C)
        j = j[:, self.mask]
        return j if self.white is None else self.white @ j


def _free_mask(free) -> np.ndarray:
    mask = np.ones(N_PARAMS, bool) if free is None else np.asarray(free, bool)
    if mask.shape != (N_PARAMS,):
        raise CalibrationError(f"free has shape {mask.shape}; expected ({N_PARAMS},) booleans")
    return mask


def _check_measurements(meas: Measurements, n_free: int) -> None:
    for name, width in (("Q", 6), ("C", 3), ("P_ref", 3)):
        check_shape(f"measurements {name}", getattr(meas, name), (len(meas), width))
    check_measurement_count(len(meas), n_free)


def _solve(problem: _Problem, max_evaluations: int) -> Estimate:
    """Levenberg-Marquardt on ``problem``; a run that does not converge raises, with its cost."""
    weighted = problem.white is not None
    mask, x_start = problem.mask, problem.start
    label = "maximum-likelihood LM" if weighted else "LM (Eq. 10-11)"
    try:
        return levenberg_marquardt(
            problem.fun,
            x_start[mask],
            jac=problem.jac,
            sigma=1.0 if weighted else None,
            names=[n for n, f in zip(PARAM_NAMES, mask, strict=True) if f],
            max_nfev=max_evaluations,
            xtol=1e-10,
            ftol=1e-12,
            gtol=1e-12,
            label=label,
        )
    except CalibrationError as err:
        iterates = problem.iterates
        r = problem.fun(iterates[-1][mask]) if iterates else problem.fun(x_start[mask])
        raise CalibrationError(
            f"{label} did not converge after {max(len(iterates) - 1, 0)} iterations "
            f"(cost {0.5 * float(r @ r):.6g} at the last one, {max_evaluations} residual "
            "evaluations allowed); start closer to the solution or allow more evaluations"
        ) from err


def _iteration_path(x_start: np.ndarray, iterates: list[np.ndarray], final: np.ndarray):
    """The start and one parameter vector per LM iteration, ending at ``final`` (k + 1, 30)."""
    # scipy evaluates the Jacobian once more at the solution; keep one entry per iteration
    path = [x_start] + [p for p in iterates if not np.array_equal(p, x_start)]
    dedup = [path[0]] + [
        p for a, p in zip(path, path[1:], strict=False) if not np.array_equal(a, p)
    ]
    if not np.array_equal(dedup[-1], final):
        dedup.append(final)
    return np.array(dedup)


def identify(
    meas: Measurements,
    start,
    *,
    weighted: bool = False,
    free=None,
    max_evaluations: int = 100,
    model: GlobalModel | None = None,
) -> Identification:
    """Identify the 30 parameters from sphere-centre measurements by LM (Eq. 10-11).

    Minimises ``sum |P_i - P_i^n|^2`` (the paper) or, with ``weighted=True``, the same residuals
    whitened by their covariance (:func:`covariance`: maximum likelihood for Gaussian scanner,
    repeatability and tracker errors, the tracker's shared by the views of one sphere).

    Parameters
    ----------
    meas : Measurements
        At least 10 measurements (30 equations).
    start : array_like, shape (30,)
        Initial estimate.
    weighted : bool
        Maximum-likelihood weighting.
    free : array_like of bool, shape (30,), optional
        Parameters to identify; the others stay at ``start``. All by default.
    max_evaluations : int
        Residual evaluations allowed (each iteration takes one or more); reaching it raises.

    Raises
    ------
    CalibrationError
        Measurements of the wrong shape or not finite, a start that is not 30 finite numbers,
        too few measurements, or LM not converged (the message gives the iterations and cost).
    """
    model = default_model() if model is None else model
    start = check_shape("start (the parameter vector)", start, (N_PARAMS,))
    mask = _free_mask(free)
    _check_measurements(meas, int(mask.sum()))
    white = _whitening(meas) if weighted else None
    problem = _Problem(model, meas, start.copy(), mask, white)
    est = _solve(problem, max_evaluations)
    est.params = problem.full(est.params)
    est.value = est.params
    arr = _iteration_path(problem.start, problem.iterates, est.params)
    errors = np.array([problem.mean_error(p) for p in arr])
    return Identification(est, arr, errors)


# ----------------------------------------------------------------------------------------------
# identifiability


def scaled_jacobian(jac: np.ndarray) -> np.ndarray:
    """Columns in mm per mm (lengths) and mm per ``1/ANGLE_SCALE_MM`` rad (angles).

    One unit of every parameter then moves a point by about one millimetre, so singular values
    and the condition number compare like with like.
    """
    return jac * np.where(IS_LENGTH, 1.0, 1.0 / ANGLE_SCALE_MM)


def _singular_table(s: np.ndarray, vt: np.ndarray) -> pd.DataFrame:
    main = []
    for v in vt:
        top = np.argsort(-np.abs(v))[:3]
        main.append(", ".join(f"{PARAM_NAMES[i]} {v[i]:+.2f}" for i in top))
    return pd.DataFrame(
        {
            "index": np.arange(1, len(s) + 1),
            "singular_value": s,
            "relative": s / s[0],
            "main_parameters": main,
        }
    )


def _separation(js: np.ndarray) -> np.ndarray:
    """Per column of ``js``: sine of the angle between it and the span of the other columns."""
    separation = np.empty(N_PARAMS)
    for i in range(N_PARAMS):
        others = np.delete(js, i, axis=1)
        coef, *_ = np.linalg.lstsq(others, js[:, i], rcond=None)
        separation[i] = np.linalg.norm(js[:, i] - others @ coef) / np.linalg.norm(js[:, i])
    return separation


def crb_covariance(meas: Measurements, params, model: GlobalModel | None = None) -> np.ndarray:
    """Cramer-Rao bound (30, 30) of the parameters: ``(J^T S^-1 J)^-1`` at ``params``.

    ``J`` is the identification Jacobian at the sensor-frame centres ``meas.C_true`` and ``S``
    the full measurement covariance (:func:`covariance`). Raises if ``S`` is singular (no noise).
    """
    model = default_model() if model is None else model
    _, jac = model.points_and_jacobian(params, meas.Q, meas.C_true)
    wj = _whitening(meas) @ jac
    return np.linalg.pinv(wj.T @ wj, rcond=1e-12, hermitian=True)


def _ml_std(meas: Measurements, jac: np.ndarray) -> np.ndarray:
    """Maximum-likelihood standard deviations (30,), mm and rad; NaN without noise."""
    try:
        white = _whitening(meas)
    except CalibrationError:  # noise-free measurements: no standard deviation to give
        return np.full(N_PARAMS, np.nan)
    cov, _ = covariance_from_jacobian(white @ jac, np.zeros(len(jac)), sigma=1.0)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def identifiability(meas: Measurements, params, model: GlobalModel | None = None):
    """Rank, singular values and per-parameter identifiability of the Jacobian at ``params``.

    Evaluated with the true sensor-frame centres ``meas.C_true`` (the design, not the noise), or
    the measured ``meas.C`` when the truth is unknown.

    Returns
    -------
    singular : pandas.DataFrame
        ``index``, ``singular_value`` (scaled Jacobian), ``relative`` (to the largest) and
        ``main_parameters`` (the right singular vector's three largest entries).
    parameters : pandas.DataFrame
        Per parameter: ``name``, ``group``, ``unit``, ``separation`` (sine of the angle between its
        scaled column and the span of the 29 others: 0 means not separately identifiable),
        ``std`` (maximum-likelihood standard deviation, mm or deg) and ``identifiable``.
    summary : dict
        ``rank``, ``n_params``, ``n_equations``, ``condition_number`` (scaled) and
        ``condition_number_raw`` (mm and rad columns).
    """
    model = default_model() if model is None else model
    _, jac = model.points_and_jacobian(params, meas.Q, meas.C_design)
    js = scaled_jacobian(jac)
    _, s, vt = np.linalg.svd(js, full_matrices=False)
    rank = int(np.sum(s > s[0] * RANK_RTOL))
    singular = _singular_table(s, vt)
    separation = _separation(js)
    std = _ml_std(meas, jac)
    ok = separation > math.sqrt(RANK_RTOL)  # a column in the span of the others: no std
    parameters = pd.DataFrame(
        {
            "name": PARAM_NAMES,
            "group": GROUPS,
            "unit": np.where(IS_LENGTH, "mm", "deg"),
            "separation": separation,
            "std": np.where(ok, np.where(IS_LENGTH, std, np.degrees(std)), np.nan),
            "identifiable": ok,
        }
    )
    summary = {
        "rank": rank,
        "n_params": N_PARAMS,
        "n_equations": int(jac.shape[0]),
        "condition_number": float(s[0] / s[-1]),
        "condition_number_raw": condition_number(jac),
    }
    return singular, parameters, summary
