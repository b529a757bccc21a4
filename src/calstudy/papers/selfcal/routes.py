"""The multi-step routes the one-step identification is compared with, on the same measurements.

A multi-step route calibrates the three transforms of the chain one after the other: hand-eye
(the sensor pose on the flange), robot (its 18 kinematic parameters) and exterior (the robot
base in the part frame). Each step fits its parameters with least squares; the hand-eye and
robot steps use the constraint that every sphere stays put (:func:`_fixed_sphere_fit`), the
exterior step fits the base pose to the tracker's readings (Kabsch). The routes:
:func:`three_step` (the paper's order), :func:`three_step_reordered` (hand-eye, exterior,
robot), :func:`three_step_alternated` (hand-eye and robot alternated, then exterior) and
:func:`two_step` (sensor and robot jointly, then exterior). The three-step routes begin with the
same hand-eye fit (:func:`hand_eye`): a caller that runs several computes it once and hands it
to each (``first``). :func:`refit` fits chosen groups of a route's result again on all the
equations of the one-step model (the base alone, or everything: a final joint refit).

Frames: ``part`` is the laser tracker's frame, ``sensor`` the scanner's. Millimetres and radians.
"""

from __future__ import annotations

import numpy as np

from calstudy.core.estimation import levenberg_marquardt
from calstudy.estimators.fitting import fit_rigid
from calstudy.models.kinematics import Robot
from calstudy.selfcal.identify import Measurements, identify
from calstudy.selfcal.model import (
    ANGLE_SCALE_MM,
    BASE,
    IS_LENGTH,
    N_PARAMS,
    ROBOT,
    SENSOR,
    GlobalModel,
    default_model,
    parameters_from_robot,
    params_to_pose,
    pose_to_params,
)


def _fixed_sphere_fit(meas: Measurements, start, free, model: GlobalModel, centres=None):
    """Fit free parameters and the sphere centres (in the frame of ``start``'s base) jointly.

    ``centres`` (k, 3) starts the sphere centres (a warm start when steps alternate); by default
    the mean of the points that ``start`` predicts for each sphere.
    """
    k = int(meas.sphere.max()) + 1
    mask = np.asarray(free, bool)
    nf = int(mask.sum())
    start = np.asarray(start, float)
    if centres is None:
        guess = model.points(start, meas.Q, meas.C)
        centres = np.array([guess[meas.sphere == s].mean(axis=0) for s in range(k)])
    x0 = np.concatenate([start[mask], np.asarray(centres, float).ravel()])
    select = np.zeros((3 * len(meas), 3 * k))
    for i, s in enumerate(meas.sphere):
        select[3 * i : 3 * i + 3, 3 * s : 3 * s + 3] = np.eye(3)
    minus_select = -select

    def split(x):
        p = start.copy()
        p[mask] = x[:nf]
        return p, x[nf:]

    def fun(x):
        p, centres = split(x)
        # with the Jacobian, which the model keeps for the request that follows at this point
        points, _ = model.points_and_jacobian(p, meas.Q, meas.C)
        return points.ravel() - select @ centres

    def jac(x):
        p, _ = split(x)
        _, j = model.points_and_jacobian(p, meas.Q, meas.C)
        return np.hstack([j[:, mask], minus_select])

    est = levenberg_marquardt(fun, x0, jac=jac, max_nfev=200, xtol=1e-10, label="fixed-sphere LM")
    p, centres = split(est.params)
    return p, centres.reshape(k, 3)


def _own_frame_start(robot: Robot, start) -> np.ndarray:
    """The nominal robot in its own base frame (as "part" frame), sensor from ``start``."""
    # the robot's own base frame as "part" frame: the base pose folds only d1 and theta1
    own = parameters_from_robot(robot, np.eye(4), np.eye(4))
    own[SENSOR] = np.asarray(start, float)[SENSOR]
    return own


def _mask(*groups: slice) -> np.ndarray:
    free = np.zeros(N_PARAMS, bool)
    for g in groups:
        free[g] = True
    return free


def _exterior(meas: Measurements, params: np.ndarray, centres_base: np.ndarray) -> np.ndarray:
    """Exterior step: the base pose from sphere centres in the robot frame and their tracker
    readings (Kabsch, :func:`calstudy.estimators.fitting.fit_rigid`)."""
    k = len(centres_base)
    readings = np.array([meas.P_ref[meas.sphere == s][0] for s in range(k)])
    base2part = fit_rigid(centres_base, readings)
    out = params.copy()
    out[BASE] = pose_to_params(base2part @ params_to_pose(params[BASE]))
    return out


def hand_eye(meas: Measurements, robot: Robot, start, model: GlobalModel | None = None):
    """The hand-eye step that the three-step routes begin with: the sensor pose (6) and the
    sphere centres in the robot base frame, with the nominal ``robot``, from the constraint
    that each sphere stays put; the sensor pose starts from ``start``. Returns the parameters
    (30,) and the centres (k, 3); the routes take it as ``first`` to share one fit."""
    model = default_model() if model is None else model
    return _fixed_sphere_fit(meas, _own_frame_start(robot, start), _mask(SENSOR), model)


def three_step(
    meas: Measurements, robot: Robot, start, model: GlobalModel | None = None, first=None
):
    """The route the paper argues against, on the same measurements, in its natural order.

    1. Hand-eye: the sensor pose (6) and the sphere centres in the robot base frame, with the
       nominal ``robot``, from the constraint that each sphere stays put; the sensor pose
       starts from ``start`` (the 30-vector of the good initial estimate).
    2. Robot: the 18 robot parameters and the sphere centres again, with the sensor of step 1
       held fixed (its error propagates here).
    3. Exterior: the base pose from the sphere centres of step 2 and their tracker readings
       (Kabsch, :func:`calstudy.estimators.fitting.fit_rigid`).

    ``first``: the result of :func:`hand_eye` on the same inputs, if already computed.

    Returns
    -------
    numpy.ndarray, shape (30,)
        The assembled parameters.
    """
    model = default_model() if model is None else model
    after_he, _ = hand_eye(meas, robot, start, model) if first is None else first
    after_robot, centres_base = _fixed_sphere_fit(meas, after_he, _mask(ROBOT), model)
    return _exterior(meas, after_robot, centres_base)


def three_step_reordered(
    meas: Measurements, robot: Robot, start, model: GlobalModel | None = None, first=None
) -> np.ndarray:
    """Hand-eye, then exterior, then robot: the robot step fits the 18 robot parameters to the
    tracker readings with the sensor (step 1) and base (step 2) held. ``first`` as in
    :func:`three_step`."""
    model = default_model() if model is None else model
    after_he, centres = hand_eye(meas, robot, start, model) if first is None else first
    placed = _exterior(meas, after_he, centres)
    fit = identify(meas, placed, free=_mask(ROBOT), model=model, max_evaluations=200)
    return fit.params


def three_step_alternated(
    meas: Measurements,
    robot: Robot,
    start,
    model: GlobalModel | None = None,
    max_rounds: int = 10,
    tol_mm: float = 1e-4,
    first=None,
) -> tuple[np.ndarray, int]:
    """Hand-eye and robot steps alternated until the parameters stop moving, then exterior.

    Each round refits the sensor with the robot held, then the robot with the sensor held
    (warm-started). Stops when a round moves no parameter by more than ``tol_mm`` (angles as
    mm at ``ANGLE_SCALE_MM``) or after ``max_rounds`` rounds. Returns the parameters and the
    rounds used. ``first`` as in :func:`three_step` (the first round's hand-eye step).
    """
    model = default_model() if model is None else model
    p, centres = _own_frame_start(robot, start), None
    done = 0
    while done < max_rounds:
        before = p
        if done == 0 and first is not None:
            p, centres = first
        else:
            p, centres = _fixed_sphere_fit(meas, p, _mask(SENSOR), model, centres)
        p, centres = _fixed_sphere_fit(meas, p, _mask(ROBOT), model, centres)
        done += 1
        step = np.where(IS_LENGTH, 1.0, ANGLE_SCALE_MM) * (p - before)
        if np.max(np.abs(step)) < tol_mm:
            break
    return _exterior(meas, p, centres), done


def two_step(meas: Measurements, robot: Robot, start, model: GlobalModel | None = None):
    """Sensor and robot fitted jointly (fixed-sphere constraint), then exterior (Kabsch)."""
    model = default_model() if model is None else model
    p, centres = _fixed_sphere_fit(
        meas, _own_frame_start(robot, start), _mask(SENSOR, ROBOT), model
    )
    return _exterior(meas, p, centres)


def refit(
    meas: Measurements, params, *groups: slice, model: GlobalModel | None = None
) -> np.ndarray:
    """``params`` with the parameter ``groups`` (slices such as ``BASE``) refitted on all the
    equations of the one-step model (tracker readings, the paper's unweighted LM), the others
    held; all 30 when no group is given (a final joint refit).

    Parameters
    ----------
    meas : Measurements
        The calibration measurements.
    params : array_like, shape (30,)
        The start, e.g. a route's result (mm, rad).
    *groups : slice
        Groups of the 30 parameters to refit (:data:`calstudy.selfcal.model.BASE`, ``ROBOT``,
        ``SENSOR``).

    Returns
    -------
    numpy.ndarray, shape (30,)

    Raises
    ------
    CalibrationError
        If LM does not converge (:func:`calstudy.selfcal.identify.identify`).
    """
    free = _mask(*groups) if groups else None
    return identify(meas, params, free=free, model=model, max_evaluations=200).params
