"""Pose-list CSV files: robot and camera poses with self-naming columns.

:func:`read_pose_list` reads a user's poses as stored (convention and unit named by the columns),
:func:`write_pose_list` writes them; :meth:`PoseList.arguments` passes them to
:func:`calstudy.handeye.calibrate.calibrate_handeye`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.userfile import (
    LENGTH_UNITS,
    check_ids,
    parse_number,
    read_csv_table,
    require_columns,
)
from calstudy.handeye.inputs import (
    CAMERA_CONVENTIONS,
    ROBOT_CONVENTIONS,
    check_pose_array,
    unit_factor,
)

#: rotation forms of a pose-list file: column suffixes after ``<prefix>_``
ROTATION_FORMS = {
    "quaternion": ("qw", "qx", "qy", "qz"),
    "rotvec_rad": ("rx_rad", "ry_rad", "rz_rad"),
    "zyx_deg": ("a_deg", "b_deg", "c_deg"),
    "matrix": ("r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"),
}


@dataclass
class PoseList:
    """Robot and camera poses read from a pose-list file, as stored (not yet converted).

    Attributes
    ----------
    ids : (N,) int array
    robot : (N, 4, 4) array
        Robot poses in the file's convention and unit.
    camera : (N, 4, 4) array
        Camera poses in the file's convention and unit.
    robot_convention, camera_convention : str
        Named by the column prefixes (e.g. ``flange2base``, ``target2camera``).
    robot_unit, camera_unit : str
        Named by the translation columns (e.g. ``_x_mm``).
    """

    ids: np.ndarray
    robot: np.ndarray
    camera: np.ndarray
    robot_convention: str
    camera_convention: str
    robot_unit: str
    camera_unit: str
    robot_form: str = "matrix"
    camera_form: str = "matrix"
    robot_rotation_columns: np.ndarray | None = None
    camera_rotation_columns: np.ndarray | None = None

    def rereadings(self) -> dict:
        """Other readings of the rotation columns, tried by the diagnosis of a failed fit check
        and never applied silently: quaternions in x, y, z, w order, rotation vectors in
        degrees, Euler angles of another order or in radians (:func:`alternative_rotations`).

        Returns
        -------
        dict
            ``{cause: (robot, camera)}``, each an array (N, 4, 4) as stored (mm or the file's
            unit).

        Raises
        ------
        None
        """
        out = {}
        sides = (
            ("robot", self.robot, self.robot_form, self.robot_rotation_columns),
            ("camera", self.camera, self.camera_form, self.camera_rotation_columns),
        )
        alts = {}
        for side, poses, form, cols in sides:
            if cols is None:
                continue
            for cause, rot in alternative_rotations(form, cols).items():
                alt = poses.copy()
                alt[:, :3, :3] = rot
                alts.setdefault(cause, {})[side] = alt
        for cause, found in alts.items():
            for side, alt in found.items():
                pair = (alt, self.camera) if side == "robot" else (self.robot, alt)
                out[f"the {side} {cause}"] = pair
            if len(found) == 2:
                out[f"both lists' {cause}"] = (found["robot"], found["camera"])
        return out

    def arguments(self) -> dict:
        """Keyword arguments for :func:`calibrate_handeye` and
        :func:`calibrate_robot_world_handeye`: the poses with their convention, units, ids and
        :meth:`rereadings`.

        Returns
        -------
        dict
            ``flange2base``, ``target2camera`` (N, 4, 4), ``convention``, ``robot_unit``,
            ``camera_unit``, ``ids`` and ``rereadings``.

        Raises
        ------
        None
        """
        return {
            "flange2base": self.robot,
            "target2camera": self.camera,
            "convention": (self.robot_convention, self.camera_convention),
            "robot_unit": self.robot_unit,
            "camera_unit": self.camera_unit,
            "ids": self.ids,
            "rereadings": self.rereadings,
        }

    def __len__(self) -> int:
        return len(self.ids)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of scalar-first quaternions, without normalising (a non-unit quaternion
    gives a scaled matrix that the orthonormality check then reports)."""
    w, x, y, z = q.T
    return np.stack(
        [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
    ).transpose(2, 0, 1)


def _find_prefix(path, header, names, what):
    found = [p for p in names if any(h.startswith(p + "_") for h in header)]
    if len(found) != 1:
        raise CalibrationError(
            f"{path}: header must name the {what} poses by exactly one prefix of "
            f"{', '.join(names)} (e.g. {names[0]}_x_mm); found {found or 'none'}"
        )
    return found[0]


def _pose_columns(path, header, prefix):
    units = [u for u in LENGTH_UNITS if f"{prefix}_x_{u}" in header]
    if len(units) != 1:
        raise CalibrationError(
            f"{path}: no translation columns {prefix}_x_<unit>, {prefix}_y_<unit>, "
            f"{prefix}_z_<unit> with one unit of {', '.join(LENGTH_UNITS)}"
        )
    unit = units[0]
    trans = [f"{prefix}_{c}_{unit}" for c in "xyz"]
    forms = [f for f, cols in ROTATION_FORMS.items() if f"{prefix}_{cols[0]}" in header]
    if len(forms) != 1:
        raise CalibrationError(
            f"{path}: the {prefix} rotation must be given in exactly one form, columns "
            + "; ".join(f"{prefix}_" + f", {prefix}_".join(c) for c in ROTATION_FORMS.values())
            + f"; found {forms or 'none'}"
        )
    rot = [f"{prefix}_{c}" for c in ROTATION_FORMS[forms[0]]]
    require_columns(path, header, trans + rot)
    return unit, forms[0], trans, rot


def _rotations(form: str, v: np.ndarray) -> np.ndarray:
    if form == "quaternion":
        return _quat_matrix(v)
    if form == "rotvec_rad":
        return geo.rotvec_to_matrix(v)
    if form == "zyx_deg":
        return geo.euler_zyx_to_matrix(v[:, 0], v[:, 1], v[:, 2])
    return v.reshape(-1, 3, 3)


#: Euler sequences tried against the declared ``Rz(a) Ry(b) Rx(c)`` (scipy's intrinsic names;
#: each also with the angles reversed, which is the fixed-axis reading of the same letters)
EULER_SEQUENCES = (
    "ZYX",
    "XYZ",
    "ZYZ",
    "ZXZ",
    "XZY",
    "YXZ",
    "YZX",
    "ZXY",
    "XYX",
    "XZX",
    "YXY",
    "YZY",
)


def _from_euler(seq: str, angles: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler(seq, angles, degrees=True).as_matrix()


def _euler_name(seq: str, angles: str) -> str:
    return "R = " + " ".join(
        f"R{axis.lower()}({ang})" for axis, ang in zip(seq, angles, strict=True)
    )


def alternative_rotations(form: str, columns: np.ndarray) -> dict:
    """Rotations ``{cause: (N, 3, 3)}`` of the rotation columns ``(N, k)`` of one side read in
    the common wrong ways of ``form``: quaternions stored x, y, z, w; rotation vectors in degrees;
    Euler angles in another order (or reversed, the fixed-axis reading: Fanuc W, P, R and ABB's
    Euler angles give ``R = Rz(c) Ry(b) Rx(a)``) or in radians. Matrices: none here (a
    transpose shows in the matrices themselves)."""
    v = np.asarray(columns, dtype=float)
    if form == "quaternion":
        q = v[:, [3, 0, 1, 2]]
        return {
            "quaternions stored x, y, z, w (scalar last) under qw, qx, qy, qz": _quat_matrix(
                q / np.linalg.norm(q, axis=1, keepdims=True)
            )
        }
    if form == "rotvec_rad":
        return {"rotation vectors in degrees under _rad": geo.rotvec_to_matrix(np.deg2rad(v))}
    if form != "zyx_deg":
        return {}
    out = {"Euler angles in radians under _deg": geo.euler_zyx_to_matrix(*np.rad2deg(v).T)}
    for seq in EULER_SEQUENCES:
        for angles, vv in (("abc", v), ("cba", v[:, ::-1])):
            if seq == "ZYX" and angles == "abc":
                continue
            out[f"Euler angles as {_euler_name(seq, angles)} instead of Rz(a) Ry(b) Rx(c)"] = (
                _from_euler(seq, vv)
            )
    return out


#: largest deviation of a stored quaternion's norm from 1 accepted (rounded files)
QUATERNION_NORM_TOL = 1e-3


def _values(path, rows, cols, index) -> np.ndarray:
    """The numbers ``(rows, cols)`` of a pose list; CalibrationError naming row and column."""
    values = np.zeros((len(rows), len(cols)))
    for i, (line, row) in enumerate(rows):
        for j, (col, k) in enumerate(zip(cols, index, strict=True)):
            values[i, j] = parse_number(path, line, col, row[k])
    return values


def _check_quaternions(path, rows, prefix: str, q: np.ndarray) -> None:
    norm = np.linalg.norm(q, axis=1)
    k = int(np.argmax(np.abs(norm - 1.0)))
    if abs(norm[k] - 1.0) > QUATERNION_NORM_TOL:
        raise CalibrationError(
            f"{path}: row {rows[k][0]}, columns {prefix}_qw..{prefix}_qz: the quaternion has norm "
            f"{norm[k]:.6g}, not 1 (tolerance {QUATERNION_NORM_TOL:g}); is it scalar first, "
            "and complete?"
        )


def read_pose_list(path) -> PoseList:
    """Read a pose-list CSV (schema in the README and :func:`write_pose_list`).

    One row per pose: ``id``; the robot pose as ``<robot>_x_<unit>, _y_<unit>, _z_<unit>`` and a
    rotation in one self-naming form; the camera pose likewise. ``<robot>`` is one of
    ``gripper2base, flange2base, base2gripper, base2flange`` and ``<camera>`` one of
    ``target2camera, camera2target``: the prefixes state the storage convention. ``<unit>`` is
    ``mm, cm, m`` or ``in``. Rotation forms (:data:`ROTATION_FORMS`): ``_qw, _qx, _qy, _qz``
    (unit quaternion, scalar first), ``_rx_rad, _ry_rad, _rz_rad`` (rotation vector),
    ``_a_deg, _b_deg, _c_deg`` (``R = Rz(a) Ry(b) Rx(c)``, KUKA) or ``_r11 ... _r33`` (matrix,
    row by row). Lines starting with ``#`` are comments; a UTF-8 byte-order mark and ``;`` as
    the separator (spreadsheet exports) are accepted. Quaternions must have norm 1 within
    :data:`QUATERNION_NORM_TOL`; other rotations are checked by the calibration (naming the pose).

    Parameters
    ----------
    path : str or pathlib.Path
        The pose-list CSV file.

    Returns
    -------
    PoseList
        The poses as stored; :meth:`PoseList.arguments` passes them with their convention and
        units to the calibration.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file.
    CalibrationError
        For a header that names no or two conventions, units or rotation forms, a missing
        column, no rows, a cell that is empty, not a number or not finite (naming the row, 1-based
        with the header as row 1, and the column), a non-integer or repeated id.
    """
    path = Path(path)
    header, rows = read_csv_table(path, "pose list")
    require_columns(path, header, ["id"])
    rprefix = _find_prefix(path, header, list(ROBOT_CONVENTIONS), "robot")
    cprefix = _find_prefix(path, header, list(CAMERA_CONVENTIONS), "camera")
    runit, rform, rtrans, rrot = _pose_columns(path, header, rprefix)
    cunit, cform, ctrans, crot = _pose_columns(path, header, cprefix)
    cols = ["id"] + rtrans + rrot + ctrans + crot
    index = [header.index(c) for c in cols]
    values = _values(path, rows, cols, index)
    ids = check_ids(path, values[:, 0], [n for n, _ in rows])
    nr = len(rrot)
    if rform == "quaternion":
        _check_quaternions(path, rows, rprefix, values[:, 4 : 4 + nr])
    if cform == "quaternion":
        _check_quaternions(path, rows, cprefix, values[:, 4 + nr + 3 : 4 + nr + 3 + 4])
    robot = geo.make_transform(_rotations(rform, values[:, 4 : 4 + nr]), values[:, 1:4])
    c0 = 4 + nr
    camera = geo.make_transform(_rotations(cform, values[:, c0 + 3 :]), values[:, c0 : c0 + 3])
    return PoseList(
        ids,
        robot,
        camera,
        rprefix,
        cprefix,
        runit,
        cunit,
        rform,
        cform,
        values[:, 4 : 4 + nr].copy(),
        values[:, c0 + 3 :].copy(),
    )


def _rotation_columns(rotation: str, rot: np.ndarray) -> np.ndarray:
    """Rotations ``(N, 3, 3)`` as the columns of the form ``rotation`` (:data:`ROTATION_FORMS`);
    quaternions scalar first with ``qw >= 0``."""
    if rotation == "quaternion":
        from scipy.spatial.transform import Rotation

        q = Rotation.from_matrix(rot).as_quat()  # scalar last
        r = np.concatenate([q[:, 3:], q[:, :3]], 1)
        r *= np.where(r[:, :1] < 0, -1.0, 1.0)
    elif rotation == "rotvec_rad":
        r = geo.matrix_to_rotvec(rot)
    elif rotation == "zyx_deg":
        r = geo.matrix_to_euler_zyx(rot)
    else:
        r = rot.reshape(-1, 9)
    return r


def write_pose_list(
    path,
    flange2base,
    target2camera,
    *,
    ids=None,
    rotation: str = "quaternion",
    robot_convention: str = "flange2base",
    camera_convention: str = "target2camera",
    unit: str = "mm",
    digits: int = 10,
    comment: str = "",
) -> Path:
    """Write poses as a pose-list CSV that :func:`read_pose_list` reads.

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write (its folder is created).
    flange2base, target2camera : array_like, shape (N, 4, 4)
        Poses in the study's convention (mm); written in ``robot_convention`` /
        ``camera_convention`` (inverted if those say so) and ``unit``.
    ids : array_like of int, shape (N,), optional
        Pose ids (default ``1 .. N``).
    rotation : str
        One of :data:`ROTATION_FORMS`.
    robot_convention : str
        ``"flange2base"``, ``"gripper2base"``, ``"base2flange"`` or ``"base2gripper"``.
    camera_convention : str
        ``"target2camera"`` or ``"camera2target"``.
    unit : {"mm", "cm", "m", "in"}
        Length unit of the written translations.
    digits : int
        Significant digits of every number.
    comment : str
        Written as ``#`` lines above the header.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    CalibrationError
        For an unknown rotation form, convention or unit, or poses that are not (N, 4, 4)
        rigid transforms.
    """
    if rotation not in ROTATION_FORMS:
        raise CalibrationError(
            f"unknown rotation form {rotation!r}; use one of {list(ROTATION_FORMS)}"
        )
    robot = check_pose_array("robot poses", flange2base)
    camera = check_pose_array("camera poses", target2camera)
    if ROBOT_CONVENTIONS.get(robot_convention) is None:
        raise CalibrationError(f"unknown robot convention {robot_convention!r}")
    if CAMERA_CONVENTIONS.get(camera_convention) is None:
        raise CalibrationError(f"unknown camera convention {camera_convention!r}")
    robot = geo.invert(robot) if ROBOT_CONVENTIONS[robot_convention] else robot
    camera = geo.invert(camera) if CAMERA_CONVENTIONS[camera_convention] else camera
    factor = unit_factor("file", unit)
    ids = np.arange(1, len(robot) + 1) if ids is None else np.asarray(ids, dtype=int)
    header = ["id"]
    blocks = [ids[:, None].astype(float)]
    for prefix, poses in ((robot_convention, robot), (camera_convention, camera)):
        header += [f"{prefix}_{c}_{unit}" for c in "xyz"]
        header += [f"{prefix}_{c}" for c in ROTATION_FORMS[rotation]]
        blocks += [poses[:, :3, 3] / factor, _rotation_columns(rotation, poses[:, :3, :3])]
    table = np.concatenate(blocks, 1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        for line in comment.splitlines():
            handle.write(f"# {line}\n")
        handle.write(",".join(header) + "\n")
        for row in table:
            cells = [str(int(row[0]))] + [f"{v:.{digits}g}" for v in row[1:]]
            handle.write(",".join(cells) + "\n")
    return path
