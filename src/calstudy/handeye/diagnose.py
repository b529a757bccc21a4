"""Diagnosis of an implausible hand-eye fit: the common reading mistakes, tried and ranked.

Run by :func:`calstudy.handeye.calibrate.calibrate_handeye` only after
:func:`calstudy.handeye.checks.check_cell` failed. Each candidate re-reads the
canonical poses (:func:`readings`) or the file's raw columns (``rereadings`` of
:meth:`calstudy.handeye.posefile.PoseList.rereadings`): storage inverted, rotations
transposed, unit factors 10, 25.4 and 1000 either way, camera rows shifted against the robot rows,
the target moved once during the series; from a pose-list file also quaternions in x, y, z, w
order, rotation vectors in degrees, Euler angles of another order. Each is fitted by a closed
form on the well-spread poses and scored by the robust noise level of its residuals against the
plausible one (:func:`calstudy.handeye.checks.noise_ratio`) and by the ranges; the
ranking names what fits. Nothing is corrected: the caller refuses (or warns) with the ranking.

Also independent of ``X``: the rotation angle of a motion is the same seen by the robot and by
the camera (``angle(inv(A_i) A_j) = angle(B_i inv(B_j))``); its median disagreement over the pairs
of :func:`~calstudy.handeye.inputs.motion_pairs` tells rotation trouble (pairing,
rotation format) from translation trouble (units, a moved target) when no reading fits.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.axxb import opencv_handeye
from calstudy.handeye.checks import CellLimits, noise_ratio, range_failures
from calstudy.handeye.inputs import motion_pairs
from calstudy.handeye.refine import (
    check_proper,
    pose_residuals,
    pose_scale,
    spread_subset,
    target_in_world,
)

#: a reading must fit this much better than the declared one to be named as the cause
BETTER_BY = 5.0
#: unit factors tried, either way (cm, inch, m against mm)
UNIT_FACTORS = {10.0: "cm", 25.4: "in", 1000.0: "m"}
#: row shifts of the camera list against the robot list tried
SHIFTS = (1, -1, 2, -2)


def _transposed(p: np.ndarray) -> np.ndarray:
    out = p.copy()
    out[:, :3, :3] = np.swapaxes(p[:, :3, :3], 1, 2)
    return out


def _scaled(p: np.ndarray, f: float) -> np.ndarray:
    out = p.copy()
    out[:, :3, 3] *= f
    return out


def readings(a: np.ndarray, b: np.ndarray) -> dict:
    """Alternative readings ``{cause: (a, b)}`` of canonical poses: inversions, transposes, unit
    factors and row shifts (the format mistakes that survive in the 4 x 4 matrices)."""
    out = {
        "the robot poses inverted (base-to-flange stored as flange-to-base?)": (geo.invert(a), b),
        "the camera poses inverted (camera-to-target stored as target-to-camera?)": (
            a,
            geo.invert(b),
        ),
        "the robot rotations transposed (column-major read as row-major?)": (_transposed(a), b),
        "the camera rotations transposed (column-major read as row-major?)": (a, _transposed(b)),
        "both lists' rotations transposed": (_transposed(a), _transposed(b)),
    }
    for f, unit in UNIT_FACTORS.items():
        out[f"the robot translations x{f:g} (robot in {unit}, camera in mm?)"] = (_scaled(a, f), b)
        out[f"the camera translations x{f:g} (camera in {unit}, robot in mm?)"] = (a, _scaled(b, f))
        out[f"the robot translations x{1 / f:.4g} (robot in mm declared as {unit}?)"] = (
            _scaled(a, 1 / f),
            b,
        )
        out[f"the camera translations x{1 / f:.4g} (camera in mm declared as {unit}?)"] = (
            a,
            _scaled(b, 1 / f),
        )
        out[f"both lists' translations x{f:g} (both in {unit}, declared mm?)"] = (
            _scaled(a, f),
            _scaled(b, f),
        )
        out[f"both lists' translations x{1 / f:.4g} (both in mm, declared {unit}?)"] = (
            _scaled(a, 1 / f),
            _scaled(b, 1 / f),
        )
    for k in SHIFTS:
        if len(a) - abs(k) >= 6:
            sa, sb = (a[:-k], b[k:]) if k > 0 else (a[-k:], b[:k])
            out[f"the camera rows shifted by {k:+d} against the robot rows (pairing)"] = (sa, sb)
    return out


def _closed_form(a, b) -> np.ndarray:
    """Park (then Tsai) on the well-spread poses: the start of a reading's score."""
    sub = spread_subset(a)
    for method in ("Park", "Tsai"):
        try:
            return check_proper(method, opencv_handeye(a[sub], b[sub], method))
        except (CalibrationError, cv2.error):
            continue
    raise CalibrationError("no closed form")


def reading_score(a, b, limits: CellLimits, z_split: int | None = None) -> float:
    """Noise ratio (:func:`noise_ratio`) of a closed-form fit of one reading; ``inf`` if no
    closed form solves it or its ranges fail; ``z_split`` fits one target before that row and
    another from it on (a target moved once)."""
    try:
        if range_failures(a, b, limits)[2]:
            return np.inf
        if z_split is None:
            x = _closed_form(a, b)
            res = pose_residuals(a, b, x, target_in_world(a, b, x))
        else:
            first = slice(0, z_split) if z_split >= len(a) - z_split else slice(z_split, None)
            x = _closed_form(a[first], b[first])
            res = np.concatenate(
                [
                    pose_residuals(a[s], b[s], x, target_in_world(a[s], b[s], x))
                    for s in (slice(0, z_split), slice(z_split, None))
                ]
            )
    except (CalibrationError, cv2.error, np.linalg.LinAlgError):
        return np.inf
    if not np.all(np.isfinite(res)):
        return np.inf
    return noise_ratio(res, pose_scale(b), limits)[2]


def motion_angle_disagreement(a: np.ndarray, b: np.ndarray) -> float:
    """Median ``|angle(inv(A_i) A_j) - angle(B_i inv(B_j))|`` over the pairs of
    :func:`motion_pairs`, deg: about the rotation noise when robot and camera rows pair up, tens of
    degrees when they do not (or a rotation format is wrong); independent of ``X`` and of the
    translations."""
    i, j = motion_pairs(len(a))
    ra, rb = a[:, :3, :3], b[:, :3, :3]
    ang_a = geo.rotation_angle(np.einsum("nji,njk->nik", ra[i], ra[j]))
    ang_b = geo.rotation_angle(np.einsum("nij,nkj->nik", rb[i], rb[j]))
    return float(np.rad2deg(np.median(np.abs(ang_a - ang_b))))


def diagnose(
    a: np.ndarray,
    b: np.ndarray,
    limits: CellLimits,
    rereadings: Callable[[], dict] | None = None,
    break_after: int = -1,
) -> tuple[list, str]:
    """Try the readings and rank them.

    Parameters
    ----------
    a, b : (N, 4, 4) arrays
        Canonical poses as declared, mm.
    limits : CellLimits
    rereadings : callable, optional
        Returns ``{cause: (a, b)}`` of canonical poses re-read from the raw file columns.
    break_after : int
        Row after which :func:`~calstudy.handeye.checks.series_break` saw the largest
        step (-1: none); a target moved there is tried.

    Returns
    -------
    (list of (str, float), str)
        Every reading with its noise ratio, best first (the declared one included, as
        ``"as declared"``), and a sentence naming the likely causes.
    """
    cands = {"as declared": (a, b)}
    if rereadings is not None:
        cands.update(rereadings())
    cands.update(readings(a, b))
    scores = [(name, reading_score(ra, rb, limits)) for name, (ra, rb) in cands.items()]
    if break_after >= 0:
        # the step is located on a fit that the move itself spoils: try the rows around it
        moved = [
            (
                f"the target moved between rows {k - 1} and {k}",
                reading_score(a, b, limits, z_split=k),
            )
            for k in range(max(break_after - 2, 3), min(break_after + 5, len(a) - 2))
        ]
        if moved:
            scores.append(min(moved, key=lambda m: m[1]))
    scores.sort(key=lambda s: s[1])
    declared = dict(scores)["as declared"]
    fits = [
        (n, s) for n, s in scores if n != "as declared" and s <= 1.0 and s * BETTER_BY < declared
    ]
    if fits:
        ranked = "; ".join(
            f"{k + 1}. {n} (noise ratio {s:.3g})" for k, (n, s) in enumerate(fits[:3])
        )
        return scores, (
            f"the data fit with {ranked}, against a noise ratio of {declared:.3g} as declared "
            "(1 = the plausible limit); fix the input (convention=, robot_unit=, camera_unit=, "
            "the columns or the pairing) to what the data are: nothing was corrected"
        )
    dis = motion_angle_disagreement(a, b)
    tried = ", ".join([n for n, _ in scores if n != "as declared"][:3])
    where = (
        "the rotations disagree: robot and camera rows are mis-paired (shuffled) or a "
        "rotation format is wrong"
        if dis > 1.0
        else "the rotations agree: the translations are at fault (units, a moved target, a "
        "wrong tool or camera frame)"
    )
    return scores, (
        f"no reading tried fits (best: {tried}); the rotation angles of the robot and camera "
        f"motions differ by a median {dis:.3g} deg, so {where}"
    )
