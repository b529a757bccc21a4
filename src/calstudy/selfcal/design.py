"""Design of a ``selfcal`` calibration: base parameters and the choice of measuring poses.

- :func:`base_parameters`: which parameters the poses identify alone, which only in combination
  (and the combination), which not at all, by a column-pivoted QR decomposition of the scaled
  identification Jacobian (the base-parameter analysis of FIGAROH and of Khalil and Dombre).
- :func:`select_poses`: from a set of candidate poses, the ``N`` that maximise D-optimality
  (``log det`` of the scaled information matrix), greedily, then improved by exchange
  (:func:`select_poses_sizes` for several ``N`` at once); :func:`observability` gives the
  indices of any selection.
- :func:`candidate_jacobians`: the scaled Jacobian rows of each candidate at the nominal
  parameters and the sphere readings (what is known before measuring).

Nothing here knows the simulation: the inputs are a model, parameters, joint angles and points.
Millimetres and radians; angles are scaled as in :func:`calstudy.selfcal.identify.
scaled_jacobian` (1 rad counts as ``ANGLE_SCALE_MM`` mm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.linalg

from calstudy.core.errors import CalibrationError
from calstudy.selfcal.identify import RANK_RTOL, scaled_jacobian
from calstudy.selfcal.model import (
    ANGLE_SCALE_MM,
    IS_LENGTH,
    PARAM_NAMES,
    GlobalModel,
    default_model,
)

#: a coefficient of a base-parameter combination smaller than this (scaled units) is dropped
COMBINATION_TOL = 1e-6
#: an entry of an unidentified direction (unit vector, scaled units) shown when above this
NULL_TERM = 0.1
#: noise-aware rank: a direction of the parameters that the data fix with a standard deviation
#: above this (scaled units: mm for lengths, mm at 1 m for angles, so 10 mrad = 0.57 deg) is not
#: identified; that is 20 times a robot's manufacturing tolerance of 0.5 mm and 0.05 deg, so the
#: data would fix it worse than the drawing does
STD_LIMIT_MM = 10.0

ALONE = "identifiable alone"
COMBINED = "only in combination"
NONE = "not identifiable"


# ----------------------------------------------------------------------------------------------
# base parameters


@dataclass
class BaseParameters:
    """Result of :func:`base_parameters`.

    Attributes
    ----------
    rank : int
        Numerical rank of the scaled Jacobian (relative tolerance ``rtol`` on the QR diagonal).
    base : list of str
        The base parameters (the first ``rank`` pivots), each written as its combination.
    table : pandas.DataFrame
        One row per parameter: ``name``, ``status`` (:data:`ALONE`, :data:`COMBINED` or
        :data:`NONE`), ``pivot`` (QR order), ``r_diag`` (relative ``|R_kk|`` at its pivot) and
        ``combination`` (the identifiable combination it enters, physical units).
    unidentified : list of str
        The ``n - rank`` directions the data do not fix: the weakest right singular vectors of
        the scaled Jacobian, each with its entries above :data:`NULL_TERM` (scaled units:
        lengths in mm, angles in mm at 1 m).
    """

    rank: int
    base: list[str]
    table: pd.DataFrame
    unidentified: list[str] = field(default_factory=list)


def _term(coef: float, name: str) -> str:
    sign = "-" if coef < 0 else "+"
    mag = abs(coef)
    return f"{sign} {name}" if math.isclose(mag, 1.0, rel_tol=1e-6) else f"{sign} {mag:.4g} {name}"


def base_parameters(
    jac,
    names=PARAM_NAMES,
    is_length=IS_LENGTH,
    rtol: float = RANK_RTOL,
    sigma_mm: float | None = None,
    std_limit_mm: float = STD_LIMIT_MM,
) -> BaseParameters:
    """Base parameters of an identification Jacobian by column-pivoted QR.

    The columns are scaled (angles by ``ANGLE_SCALE_MM``) and normalised, then ``J P = Q R``
    (:func:`scipy.linalg.qr` with pivoting). The first ``r`` pivots (``|R_kk| > rtol |R_00|``) are
    the base parameters; every other column is ``J_b beta`` with ``beta = R_11^-1 R_12``, so the
    data fix only ``theta_b + beta theta_d`` (written back in physical units). A parameter is
    *identifiable alone* if it is a pivot and no dependent parameter enters its combination,
    *only in combination* if it enters a combination with others, and *not identifiable* if its
    column is zero.

    Parameters
    ----------
    jac : array_like, shape (m, n)
        Identification Jacobian (mm per mm, mm per rad).
    names : sequence of str, length n
        The parameter of each column (default the 30 of the model).
    is_length : array_like of bool, length n
        Lengths stay as given, angles are multiplied by ``ANGLE_SCALE_MM``.
    rtol : float
        Round-off rank tolerance on the QR diagonal, relative to the largest.
    sigma_mm : float, optional
        Standard deviation per axis of the residuals (mm; the declared noise or the residual
        scale of a fit). Given, the rank is also noise-aware: the first ``r`` pivots are kept
        only while the smallest singular value of their scaled columns exceeds
        ``sigma_mm / std_limit_mm``, i.e. while every direction they span is fixed with a
        standard deviation within ``std_limit_mm`` (scaled units).
    std_limit_mm : float
        Largest standard deviation of an identified direction (scaled units).

    Returns
    -------
    BaseParameters
        The rank, the base parameters, the per-parameter table and the directions the data do
        not fix.

    Raises
    ------
    CalibrationError
        Shapes that disagree, a non-finite Jacobian, or a ``sigma_mm`` that is not a positive
        finite number.
    """
    jac = np.asarray(jac, float)
    length = np.asarray(is_length, bool)
    if jac.ndim != 2 or jac.shape[1] != len(names) or length.shape != (len(names),):
        raise CalibrationError(
            f"Jacobian of shape {jac.shape} for {len(names)} names and {length.shape} unit flags"
        )
    if not np.all(np.isfinite(jac)):
        raise CalibrationError("the identification Jacobian has non-finite entries")
    unit = np.where(length, 1.0, ANGLE_SCALE_MM)  # physical -> scaled parameter
    js = jac / unit
    norms = np.linalg.norm(js, axis=0)
    scale = float(norms.max()) if norms.size and norms.max() > 0 else 1.0
    zero = norms <= rtol * scale
    jn = js / np.where(zero, 1.0, norms)
    jn[:, zero] = 0.0
    _, r, piv = scipy.linalg.qr(jn, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > rtol * diag[0])) if diag.size and diag[0] > 0 else 0
    if sigma_mm is not None:
        piv, rank = _noise_pivots(js, piv, rank, sigma_mm, std_limit_mm)
        r = scipy.linalg.qr(jn[:, piv], mode="economic")[1]
        diag = np.abs(np.diag(r))
    beta = scipy.linalg.solve_triangular(r[:rank, :rank], r[:rank, rank:])
    # in normalised units; back to physical: theta_b + sum beta (s_d n_d / (s_b n_b)) theta_d
    beta[np.abs(beta) < COMBINATION_TOL] = 0.0
    out = _base_table(names, piv, rank, beta, diag / max(diag[0], 1e-300), zero, norms, unit)
    out.unidentified = _null_combinations(js, rank, names)
    return out


def _null_combinations(js: np.ndarray, rank: int, names) -> list[str]:
    """The ``n - rank`` weakest directions of the scaled columns (right singular vectors),
    each written with its entries above ``NULL_TERM`` (scaled units)."""
    if rank >= js.shape[1]:
        return []
    vt = np.linalg.svd(js, full_matrices=js.shape[0] < js.shape[1])[2]  # all n rows of V^T
    out = []
    for v in vt[rank:]:
        v = v * np.sign(v[np.argmax(np.abs(v))])
        terms = [(c, n) for c, n in zip(v, names, strict=True) if abs(c) > NULL_TERM]
        out.append(" ".join(f"{'-' if c < 0 else '+'} {abs(c):.2f} {n}" for c, n in terms)[2:])
    return out


def _noise_pivots(js, piv, rank: int, sigma_mm: float, std_limit_mm: float):
    """Column order and rank under the noise-aware tolerance.

    The rank is the number of singular values of the scaled columns above both the round-off
    rank and ``sigma_mm / std_limit_mm``; the base columns are taken in QR pivot order,
    skipping any that would bring the smallest singular value of those chosen below that
    floor, so that every direction they span is fixed within ``std_limit_mm``.
    """
    if not (math.isfinite(sigma_mm) and sigma_mm > 0):
        raise CalibrationError(f"the residual scale sigma_mm = {sigma_mm} must be positive")
    floor = sigma_mm / std_limit_mm
    s = np.linalg.svd(js, compute_uv=False)
    target = min(rank, int(np.sum(s > floor)))
    if target and np.linalg.svd(js[:, piv[:target]], compute_uv=False)[-1] > floor:
        return piv, target  # the QR pivots already span well-fixed directions
    chosen: list[int] = []
    for c in piv:
        if len(chosen) == target:
            break
        if np.linalg.svd(js[:, [*chosen, c]], compute_uv=False)[-1] > floor:
            chosen.append(int(c))
    rest = [int(c) for c in piv if c not in chosen]
    return np.array(chosen + rest, dtype=int), len(chosen)


def _base_table(names, piv, rank, beta, rel, zero, norms, unit) -> BaseParameters:
    n = len(names)
    status = [ALONE] * n
    combination = [""] * n
    base = []
    dep = piv[rank:]
    for i, b in enumerate(piv[:rank]):
        terms = [names[b]]
        for j, d in enumerate(dep):
            if beta[i, j] != 0.0 and not zero[d]:
                coef = beta[i, j] * (unit[d] * norms[d]) / (unit[b] * norms[b])
                terms.append(_term(coef, names[d]))
        text = " ".join(terms)
        base.append(text)
        if len(terms) > 1:
            status[b] = COMBINED
            combination[b] = text
            for j, d in enumerate(dep):
                if beta[i, j] != 0.0 and not zero[d]:
                    combination[d] = "; ".join(filter(None, [combination[d], text]))
    for d in dep:
        status[d] = NONE if zero[d] or not combination[d] else COMBINED
    order = np.empty(n, int)
    order[piv] = np.arange(n)
    r_diag = np.zeros(n)
    r_diag[piv[: len(rel)]] = rel
    table = pd.DataFrame(
        {
            "name": list(names),
            "status": status,
            "pivot": order + 1,
            "r_diag": r_diag,
            "combination": combination,
        }
    )
    return BaseParameters(rank, base, table)


# ----------------------------------------------------------------------------------------------
# pose selection


def candidate_jacobians(params, Q, sphere_part, sphere, model: GlobalModel | None = None):
    """Scaled Jacobian blocks (k, 3, 30) of candidate poses, before anything is measured.

    Each candidate ``i`` is a joint vector ``Q[i]`` aimed at the sphere ``sphere[i]`` whose
    tracker reading is ``sphere_part[sphere[i]]``; its sensor-frame centre is predicted by the
    model at ``params`` (the nominal estimate), which is where the Jacobian is evaluated.
    """
    model = default_model() if model is None else model
    Q = np.asarray(Q, float)
    target = np.asarray(sphere_part, float)[np.asarray(sphere, int)]
    C = model.sensor_centres(params, Q, target)
    _, jac = model.points_and_jacobian(params, Q, C)
    return scaled_jacobian(jac).reshape(len(Q), 3, -1), C


def observability(blocks) -> dict:
    """Indices of a selection of scaled Jacobian blocks (k, 3, n).

    ``log_det``: ``log det(J^T J) / n`` (D-optimality per parameter); ``min_sv``: smallest
    singular value of ``J`` (O1 of Sun and Hollerbach); ``condition``: largest over smallest.
    """
    b = np.asarray(blocks, float)
    j = b.reshape(-1, b.shape[-1])
    s = np.linalg.svd(j, compute_uv=False)
    if len(s) < b.shape[-1] or s[-1] <= 0:
        return {"log_det": -math.inf, "min_sv": 0.0, "condition": math.inf}
    return {
        "log_det": float(2.0 * np.log(s).sum() / b.shape[-1]),
        "min_sv": float(s[-1]),
        "condition": float(s[0] / s[-1]),
    }


def _gains(blocks: np.ndarray, info_inv: np.ndarray) -> np.ndarray:
    """``log det(I_3 + J_i M^-1 J_i^T)`` for every candidate block ``J_i`` (rank-3 update)."""
    k, _, p = blocks.shape
    weighted = (blocks.reshape(-1, p) @ info_inv).reshape(k, 3, p)
    g = np.matmul(weighted, blocks.transpose(0, 2, 1))
    g += np.eye(3)
    sign, logdet = np.linalg.slogdet(g)
    return np.where(sign > 0, logdet, -np.inf)


def select_poses(blocks, n: int, exchange_rounds: int = 2, ridge: float = 1e-6) -> np.ndarray:
    """Indices of ``n`` candidate poses maximising ``det(J^T J)`` of their scaled Jacobian.

    Greedy: each step adds the candidate with the largest gain ``log det(I + J_i M^-1 J_i^T)``
    (``M`` the information so far plus ``ridge`` times its mean diagonal). Exchange: then, up to
    ``exchange_rounds`` times, each chosen pose is swapped for the best unchosen one if that
    raises ``log det``.

    Parameters
    ----------
    blocks : array_like, shape (k, 3, p)
        Scaled Jacobian blocks of the candidates (:func:`candidate_jacobians`).
    n : int
        Poses to choose, ``3 n >= p`` and ``n <= k``.
    exchange_rounds : int
        Rounds of the exchange after the greedy steps.
    ridge : float
        Regularisation of the information for the greedy gains, relative to its mean diagonal.

    Returns
    -------
    numpy.ndarray of int, shape (n,)
        Indices of the chosen candidates.

    Raises
    ------
    CalibrationError
        Blocks of the wrong shape, a block with non-finite entries or all zero (its index in
        the message), or a size that cannot be chosen.
    """
    return select_poses_sizes(blocks, [n], exchange_rounds, ridge)[n]


def select_poses_sizes(
    blocks, sizes, exchange_rounds: int = 2, ridge: float = 1e-6
) -> dict[int, np.ndarray]:
    """:func:`select_poses` for several ``n`` at once: ``{n: indices}``.

    The greedy steps do not depend on ``n`` (the first ``n`` of a longer greedy run are the
    greedy choice of ``n``), so they run once, to the largest ``n``; each ``n`` then gets its
    own exchange rounds. The result is the one of separate calls.
    """
    b = np.asarray(blocks, float)
    if b.ndim != 3 or b.shape[1] != 3:
        raise CalibrationError(f"candidate blocks have shape {b.shape}; expected (k, 3, p)")
    k, _, p = b.shape
    sizes = [int(n) for n in sizes]
    for n in sizes:
        if not 3 * n >= p or n > k:
            raise CalibrationError(
                f"cannot choose {n} poses from {k} candidates for {p} parameters "
                f"(need {math.ceil(p / 3)} <= n <= {k})"
            )
    bad = np.flatnonzero(~np.isfinite(b).all(axis=(1, 2)))
    if bad.size:
        raise CalibrationError(
            f"candidate block {int(bad[0])} (of {k}) has non-finite entries ({bad.size} such "
            "blocks): a pose the model cannot evaluate; drop it from the candidates"
        )
    zero = np.flatnonzero(~b.any(axis=(1, 2)))
    if zero.size:
        raise CalibrationError(
            f"candidate block {int(zero[0])} (of {k}) is all zero ({zero.size} such blocks): "
            "a pose that moves no measured point with any parameter; drop it"
        )
    full = np.einsum("kap,kaq->pq", b, b)
    reg = ridge * max(float(np.trace(full)) / p / k, 1e-300) * np.eye(p)
    info = reg.copy()
    chosen: list[int] = []
    free = np.ones(k, bool)
    greedy = {}
    for step in range(max(sizes, default=0)):
        gain = _gains(b, np.linalg.inv(info))
        gain[~free] = -np.inf
        best = int(np.argmax(gain))
        chosen.append(best)
        free[best] = False
        info += b[best].T @ b[best]
        if step + 1 in sizes:
            greedy[step + 1] = (list(chosen), free.copy(), info.copy())
    out = {}
    for n in sizes:
        # copies: the exchange works in place, and a size may be asked for twice
        picked, unpicked, information = (list(greedy[n][0]), *(a.copy() for a in greedy[n][1:]))
        for _ in range(exchange_rounds):
            if not _exchange_round(b, picked, unpicked, information, reg):
                break
        out[n] = np.array(sorted(picked))
    return out


def _exchange_round(b, chosen, free, info, reg) -> bool:
    """One pass of single swaps (in place); True if any swap improved ``log det``."""
    improved = False
    current = None  # log det of info, recomputed only after a swap changed it
    for slot in range(len(chosen)):
        out = chosen[slot]
        without = info - b[out].T @ b[out]
        _, base = np.linalg.slogdet(without)
        gain = _gains(b, np.linalg.inv(without))
        gain[~free] = -np.inf
        best = int(np.argmax(gain))
        if current is None:
            _, current = np.linalg.slogdet(info)
        if base + gain[best] > current + 1e-9:
            info += b[best].T @ b[best] - b[out].T @ b[out]
            chosen[slot] = best
            free[best], free[out] = False, True
            improved = True
            current = None
    return improved
