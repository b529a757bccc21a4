"""A simulated eye-in-hand cell: synthetic hand-eye pose lists with the truth.

The study's standard hand-eye scenario (:func:`simulate_cell`), drawn with the noise model of
:func:`calstudy.handeye.refine.refine_ml`; used by the tests, the benchmark and the
example cell of notebook 06.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError


@dataclass
class SimulatedCell:
    """Synthetic hand-eye data with the truth, as :func:`simulate_cell` draws them.

    Attributes
    ----------
    flange2base : (N, 4, 4) array
        Robot poses as the controller reports them (gripper-to-base, mm).
    target2camera : (N, 4, 4) array
        Measured target poses (noisy), mm.
    target2camera_true : (N, 4, 4) array
        Noise-free target poses.
    camera2flange, target2base : (4, 4) arrays
        The truth (eye-in-hand).
    outliers : (N,) bool array
        Poses made gross outliers.
    """

    flange2base: np.ndarray
    target2camera: np.ndarray
    target2camera_true: np.ndarray
    camera2flange: np.ndarray
    target2base: np.ndarray
    outliers: np.ndarray


def _cell_truth() -> tuple[np.ndarray, np.ndarray]:
    """The simulated cell's true ``camera2flange`` (camera 120 mm ahead of the flange, tilted
    15 deg) and ``target2base`` (a target on the table 800 mm in front of the robot); built
    when a cell is drawn, so that importing the door does not load scipy's rotations."""
    camera2flange = geo.make_transform(
        geo.euler_zyx_to_matrix(90.0, 15.0, 0.0), np.array([40.0, -25.0, 120.0])
    )
    target2base = geo.make_transform(
        geo.euler_zyx_to_matrix(30.0, 0.0, 180.0), np.array([800.0, 100.0, 20.0])
    )
    return camera2flange, target2base


def _camera_poses(rng, z, n_poses, distance_mm, max_tilt_deg, max_roll_deg) -> np.ndarray:
    """``camera2base`` (N, 4, 4) of cameras looking at the target ``z`` (target2base): the
    viewing geometry of :func:`simulate_cell`."""
    centre = z[:3, 3]
    normal = z[:3, :3] @ np.array([0.0, 0.0, -1.0])  # the target's z points into the table
    tilt = np.deg2rad(max_tilt_deg) * np.sqrt(rng.uniform(0, 1, n_poses))
    azim = rng.uniform(0, 2 * np.pi, n_poses)
    axis = np.stack([np.cos(azim), np.sin(azim), np.zeros(n_poses)], 1)
    dirs = geo.rotvec_to_matrix(axis * tilt[:, None]) @ np.array([0.0, 0.0, 1.0])
    frame = geo.look_at(np.zeros(3), normal)[:3, :3]
    dirs = dirs @ frame.T
    dist = distance_mm * rng.uniform(0.9, 1.1, n_poses)
    cams = []
    for d, r, roll in zip(dirs, dist, rng.uniform(-1, 1, n_poses) * max_roll_deg, strict=True):
        cam = geo.look_at(centre + r * d, centre + rng.normal(0, 20, 3))
        cams.append(cam @ geo.make_transform(geo.euler_zyx_to_matrix(roll, 0, 0), np.zeros(3)))
    cam2base = np.array(cams)
    return cam2base


def simulate_cell(
    rng: np.random.Generator,
    n_poses: int = 15,
    sigma_rot: float = 1e-3,
    sigma_trans: float = 0.2,
    *,
    distance_mm: float = 500.0,
    max_tilt_deg: float = 30.0,
    max_roll_deg: float = 45.0,
    n_duplicate_orientations: int = 0,
    outlier: tuple[float, float] | None = None,
    round_rotations: int | None = None,
) -> SimulatedCell:
    """Draw an eye-in-hand cell: a camera on the flange looking at a fixed target.

    The camera looks at the target centre from ``distance_mm`` (+-10 %), from directions within
    ``max_tilt_deg`` of the target normal, rolled by up to ``max_roll_deg``. The measured target
    poses are the true ones times ``exp(xi)`` with a rotation ``N(0, sigma_rot^2 I)`` (rad) and
    a translation ``N(0, sigma_trans^2 I)`` (mm): the noise model of :func:`refine_ml`. This is
    the study's standard hand-eye scenario (15 poses, 1e-3 rad, 0.2 mm) at its defaults.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of every random draw.
    n_poses : int
        Poses drawn (before ``n_duplicate_orientations``).
    sigma_rot, sigma_trans : float
        Camera pose noise, rad and mm per axis.
    distance_mm, max_tilt_deg, max_roll_deg : float
        Viewing geometry: mm, deg, deg.
    n_duplicate_orientations : int
        That many extra poses repeat the orientation of earlier ones with the flange moved by up to
        50 mm (common in taught pose lists).
    outlier : (translation_mm, rotation_deg), optional
        Make the last pose a gross outlier: its measured target pose is moved by this much.
    round_rotations : int, optional
        Round rotation-matrix entries of both lists to this many decimals (as files do).

    Returns
    -------
    SimulatedCell
        The true ``camera2flange`` and ``target2base`` and the pose lists (mm).

    Raises
    ------
    CalibrationError
        For fewer than 3 poses.
    """
    if n_poses < 3:
        raise CalibrationError(f"a simulated cell needs at least 3 poses; got {n_poses}")
    x, z = _cell_truth()
    cam2base = _camera_poses(rng, z, n_poses, distance_mm, max_tilt_deg, max_roll_deg)
    flange = cam2base @ geo.invert(x)
    if n_duplicate_orientations:
        src = rng.choice(n_poses, n_duplicate_orientations, replace=True)
        dup = flange[src].copy()
        dup[:, :3, 3] += rng.uniform(-50, 50, (len(src), 3))
        flange = np.concatenate([flange, dup])
    b_true = geo.invert(flange @ x) @ z
    b = geo.perturb(b_true, sigma_rot, sigma_trans, rng)
    out = np.zeros(len(b), dtype=bool)
    if outlier is not None:
        d = rng.normal(size=(2, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        b[-1] = b[-1] @ geo.make_transform(
            geo.rotvec_to_matrix(d[1] * np.deg2rad(outlier[1])), d[0] * outlier[0]
        )
        out[-1] = True
    if round_rotations is not None:
        flange[:, :3, :3] = np.round(flange[:, :3, :3], round_rotations)
        b[:, :3, :3] = np.round(b[:, :3, :3], round_rotations)
    return SimulatedCell(flange, b, b_true, x, z, out)


# ----------------------------------------------------------------------------------------------
# pose-list files
