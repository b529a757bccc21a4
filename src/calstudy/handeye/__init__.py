"""Hand-eye calibration of your own cell: the door to the hand-eye tools.

Everything a user calls is importable from here::

    from calstudy.handeye import read_pose_list, calibrate_handeye

- pose lists: :func:`read_pose_list`, :func:`write_pose_list` (:class:`PoseList`);
- AX = XB and AX = ZB with maximum-likelihood refinement, robust options and a plausibility
  check: :func:`calibrate_handeye`, :func:`calibrate_robot_world_handeye`
  (:class:`HandEyeResult`, :class:`CellLimits`; the outlier flag's limit
  :func:`outlier_limit`);
- OpenCV's closed forms alone: :func:`opencv_handeye`, with the motion check
  :func:`check_rotation_diversity`;
- a simulated cell and a plan of the next calibration's poses: :func:`simulate_cell`,
  :func:`plan_poses`;
- the fixed-sphere method and its CSV: :func:`read_sphere_measurements`,
  :func:`write_sphere_measurements`, :func:`sphere_handeye`, :func:`sphere_handeye_ml`,
  :func:`sphere_handeye_crb`.
"""

from calstudy.estimators.axxb import (
    MIN_PAIR_ROTATION,
    OPENCV_METHODS,
    check_rotation_diversity,
    opencv_handeye,
)
from calstudy.handeye.calibrate import (
    SETUP_FRAMES,
    HandEyeResult,
    calibrate_handeye,
    calibrate_robot_world_handeye,
)
from calstudy.handeye.checks import CellCheck, CellLimits
from calstudy.handeye.plan import PosePlan, plan_poses
from calstudy.handeye.posefile import PoseList, read_pose_list, write_pose_list
from calstudy.handeye.robust import outlier_limit
from calstudy.handeye.simulate import SimulatedCell, simulate_cell
from calstudy.handeye.sphere import sphere_handeye, sphere_handeye_crb, sphere_handeye_ml
from calstudy.handeye.sphere_csv import (
    SphereMeasurements,
    read_sphere_measurements,
    write_sphere_measurements,
)

__all__ = [
    "MIN_PAIR_ROTATION",
    "OPENCV_METHODS",
    "SETUP_FRAMES",
    "CellCheck",
    "CellLimits",
    "HandEyeResult",
    "PoseList",
    "PosePlan",
    "SimulatedCell",
    "SphereMeasurements",
    "calibrate_handeye",
    "calibrate_robot_world_handeye",
    "check_rotation_diversity",
    "opencv_handeye",
    "outlier_limit",
    "plan_poses",
    "read_pose_list",
    "read_sphere_measurements",
    "simulate_cell",
    "sphere_handeye",
    "sphere_handeye_crb",
    "sphere_handeye_ml",
    "write_pose_list",
    "write_sphere_measurements",
]
