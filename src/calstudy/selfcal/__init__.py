"""Self-calibration of your own cell: a robot carrying a sensor that sees calibration spheres
(or a target) whose positions a tracker has measured.

One call from a measurement folder to the calibration::

    from calstudy.selfcal import identify_cell, read_cell

    cell = read_cell("my_cell")                         # checked, units converted
    result = identify_cell(cell, requirement_mm=0.42)   # or identify_cell("my_cell")
    result.parameters                 # nominal, identified, change, std per parameter
    result.part2base, result.sensor2flange, result.robot
    result.validation_summary["meets_requirement"]

Modules, lowest first (a module imports only those before it):

- :mod:`~calstudy.selfcal.model`: the 30-parameter global model of robot, sensor mounting and
  base on Pinocchio, from a DH table (``data/robots`` form, or a URDF through
  :func:`calstudy.models.urdf.robot_from_urdf`) and back;
- :mod:`~calstudy.selfcal.identify`: sphere fit, bad-input checks, one-step identification, its
  covariance and identifiability;
- :mod:`~calstudy.selfcal.design`: base parameters by column-pivoted QR with a noise-aware rank
  and D-optimal selection of poses;
- :mod:`~calstudy.selfcal.cellfile`: the schema of a folder's ``cell.toml``;
- :mod:`~calstudy.selfcal.measured`: the measurement folder (reader and writer), identification
  of measured rows with outliers flagged, the parameter and validation reports;
- :mod:`~calstudy.selfcal.cell`: :func:`identify_cell`, the one call;
- :mod:`~calstudy.selfcal.planning`: poses planned for your sensor, compared with yours and with
  random ones.

Lengths in mm, angles in rad (degrees in the tables a user reads).
"""

from calstudy.selfcal.cell import CellCalibration, identify_cell
from calstudy.selfcal.design import BaseParameters, base_parameters, select_poses
from calstudy.selfcal.identify import Measurements
from calstudy.selfcal.measured import (
    CellFit,
    MeasuredCell,
    identify_measurements,
    measurements_from_poses,
    parameter_report,
    read_cell,
    validation_report,
    write_cell,
)
from calstudy.selfcal.model import PARAM_NAMES, cell_from_parameters, parameters_from_robot
from calstudy.selfcal.planning import ViewGeometry, suggest_poses

__all__ = [
    "PARAM_NAMES",
    "BaseParameters",
    "CellCalibration",
    "CellFit",
    "MeasuredCell",
    "Measurements",
    "ViewGeometry",
    "base_parameters",
    "cell_from_parameters",
    "identify_cell",
    "identify_measurements",
    "measurements_from_poses",
    "parameter_report",
    "parameters_from_robot",
    "read_cell",
    "select_poses",
    "suggest_poses",
    "validation_report",
    "write_cell",
]
