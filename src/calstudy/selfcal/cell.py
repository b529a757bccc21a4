"""A cell from its measurement folder to its calibration in one call.

:func:`identify_cell` reads the folder (:func:`calstudy.selfcal.measured.read_cell`), identifies
the 30 parameters from the calibration rows with the outlier rule
(:func:`calstudy.selfcal.measured.identify_measurements`), and judges the held-out rows against
a requirement (:func:`calstudy.selfcal.measured.validation_report`). The result names what a
user wants of it: the identified robot table, base placement and sensor mounting, the
parameter table with standard deviations, the base parameters of the kept poses, the residuals
and the validation.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.models.kinematics import Robot
from calstudy.selfcal.design import BaseParameters, base_parameters
from calstudy.selfcal.measured import (
    DEFAULT_REQUIREMENT_MM,
    CellFit,
    MeasuredCell,
    identify_measurements,
    parameter_report,
    read_cell,
    subset,
    validation_report,
)
from calstudy.selfcal.model import cell_from_parameters, default_model


@dataclass(frozen=True)
class CellCalibration:
    """The calibration of a cell (:func:`identify_cell`); lengths mm, angles rad.

    Attributes
    ----------
    cell : MeasuredCell
        The cell as read: nominal robot, start parameters, calibration and validation rows.
    fit : CellFit
        The identification: parameters (30,), covariance (30, 30), residuals with the outliers
        flagged, identifiability, notes.
    parameters : pandas.DataFrame
        Per parameter: nominal, identified, change and standard deviation (mm or deg), status
        (:func:`calstudy.selfcal.measured.parameter_report`).
    base : BaseParameters
        Base parameters of the kept poses at the identified parameters, with the noise-aware
        rank at the fit's residual scale: which parameters the poses identify alone, which only
        in combination (and the combination), which not at all.
    robot : Robot
        The identified robot table.
    part2base : numpy.ndarray, shape (4, 4)
        The identified robot base frame in the part (tracker) frame, mm.
    sensor2flange : numpy.ndarray, shape (4, 4)
        The identified sensor frame in the flange frame, mm.
    validation : pandas.DataFrame or None
        Per held-out row: ``sphere``, ``before_mm``, ``after_mm``, ``within``; None without
        validation rows.
    validation_summary : dict or None
        Count, mean, RMS and largest error before and after, the requirement and
        ``meets_requirement``; None without validation rows.
    """

    cell: MeasuredCell
    fit: CellFit
    parameters: pd.DataFrame
    base: BaseParameters
    robot: Robot
    part2base: np.ndarray
    sensor2flange: np.ndarray
    validation: pd.DataFrame | None
    validation_summary: dict | None


def identify_cell(
    cell: MeasuredCell | str | os.PathLike,
    requirement_mm: float = DEFAULT_REQUIREMENT_MM,
    fixed=None,
    reject: bool = True,
    max_rounds: int | None = None,
    check_columns: bool = True,
) -> CellCalibration:
    """Identify a cell from its measurement folder (or a cell already read) and validate it.

    The calibration rows are identified with the noise the cell declares (maximum likelihood)
    or without (least squares, covariance from the residuals), outliers set aside by the
    rejection rule; the held-out rows are compared before and after with ``requirement_mm``.

    Parameters
    ----------
    cell : MeasuredCell or path-like
        A measurement folder (format in :mod:`calstudy.selfcal.measured`) or a cell read by
        :func:`calstudy.selfcal.measured.read_cell`.
    requirement_mm : float
        The accuracy the held-out position errors must meet, mm.
    fixed : sequence of str, optional
        Parameters held at their nominal value (names of
        :data:`calstudy.selfcal.model.PARAM_NAMES`), e.g. ``["gamma1", "phi1", "eps1"]`` for a
        one-point probe.
    reject : bool
        Apply the outlier rule.
    max_rounds : int, optional
        Fits allowed for the outlier rule; default a quarter of the rows plus two.
    check_columns : bool
        Refuse sensor-frame columns that fit much better swapped or negated.

    Returns
    -------
    CellCalibration
        The cell, the identification and what it gives (see the class).

    Raises
    ------
    CalibrationError
        A folder that does not read (file, row and column named); an unknown fixed parameter;
        columns that look swapped or negated; poses that identify too few parameters; too many
        rows beyond the rejection threshold; no convergence; a requirement that is not a
        positive number.
    """
    if not (math.isfinite(requirement_mm) and requirement_mm > 0):
        raise CalibrationError(f"the requirement {requirement_mm} mm must be a positive number")
    cell = cell if isinstance(cell, MeasuredCell) else read_cell(cell)
    fit = identify_measurements(
        cell.calibration,
        cell.start,
        cell.noise,
        reject=reject,
        max_rounds=max_rounds,
        pose_ids=cell.pose_ids["calibration"],
        fixed=fixed,
        check_columns=check_columns,
    )
    robot, part2base, sensor2flange = cell_from_parameters(cell.robot, fit.params)
    kept = subset(cell.calibration, ~fit.outliers)
    _, jac = default_model().points_and_jacobian(fit.params, kept.Q, kept.C)
    validation = summary = None
    if len(cell.validation):
        validation, summary = validation_report(
            cell.validation, cell.start, fit.params, requirement_mm
        )
    return CellCalibration(
        cell,
        fit,
        parameter_report(fit, cell.start),
        base_parameters(jac, sigma_mm=fit.sigma_mm),
        robot,
        part2base,
        sensor2flange,
        validation,
        summary,
    )
