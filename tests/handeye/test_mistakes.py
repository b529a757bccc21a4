"""A catalogue of the mistakes a user makes with hand-eye pose lists: each is refused with its
cause named (or warned about with ``check_convention="warn"``), none returns a plausible wrong
answer. The noise level is not given (the default, and notebook 06's) unless a test says so."""

import csv
import time

import numpy as np
import pytest
from support import handeye_cell as _cell

from calstudy import CalibrationError, CalibrationWarning
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp
from calstudy.handeye.checks import CellLimits
from calstudy.handeye.posefile import read_pose_list, write_pose_list

N = 20


def _transposed(p):
    out = p.copy()
    out[:, :3, :3] = np.swapaxes(p[:, :3, :3], 1, 2)
    return out


def _scaled(p, f):
    out = p.copy()
    out[:, :3, 3] *= f
    return out


def _moved(cell, mm=30.0):
    """The target knocked by ``mm`` halfway: the camera sees it moved in the base frame."""
    b = cell.target2camera.copy()
    shift = geo.make_transform(np.eye(3), np.array([mm, 0.0, 0.0]))
    half = len(b) // 2
    b[half:] = (
        geo.invert(cell.flange2base[half:] @ cell.camera2flange)
        @ shift
        @ (cell.flange2base[half:] @ cell.camera2flange @ b[half:])
    )
    return cell.flange2base, b


def _mistakes():
    cell = _cell(40, n=N)
    a, b = cell.flange2base, cell.target2camera
    perm = np.random.default_rng(0).permutation(N)
    return {
        "camera rotations transposed": (
            (a, _transposed(b)),
            r"1\. the camera rotations transposed",
        ),
        "robot rotations transposed": ((_transposed(a), b), r"1\. the robot rotations transposed"),
        "robot poses inverted": ((geo.invert(a), b), r"1\. the robot poses inverted"),
        "camera poses inverted": ((a, geo.invert(b)), r"1\. the camera poses inverted"),
        "rows shifted by one": (
            (a[1:], b[:-1]),
            r"1\. the camera rows shifted by \+1 against the robot rows",
        ),
        "rows shuffled": ((a, b[perm]), r"rotations disagree: .*mis-paired \(shuffled\)"),
        "target moved 30 mm halfway": (
            _moved(cell),
            r"steps by .* after row \d+.*1\. the target moved between rows 9 and 10",
        ),
        "robot in cm": ((_scaled(a, 0.1), b), r"1\. the robot translations x10 \(robot in cm"),
        "robot in inches": ((_scaled(a, 1 / 25.4), b), r"1\. the robot translations x25\.4"),
        "camera in m": ((a, _scaled(b, 1e-3)), r"1\. the camera translations x1000 \(camera in m"),
        "both in m under mm": (
            (_scaled(a, 1e-3), _scaled(b, 1e-3)),
            r"working range .*1\. both lists' translations x1000",
        ),
    }


MISTAKES = _mistakes()


@pytest.mark.parametrize("name", list(MISTAKES))
def test_mistake_is_refused_naming_its_cause(name):
    (a, b), match = MISTAKES[name]
    with pytest.raises(CalibrationError, match="implausible hand-eye fit: .*" + match):
        hp.calibrate_handeye(a, b)


@pytest.mark.parametrize("name", ["camera rotations transposed", "rows shifted by one"])
def test_mistake_is_refused_with_a_given_noise_level_and_by_the_ax_zb_form(name):
    (a, b), match = MISTAKES[name]
    with pytest.raises(CalibrationError, match=match):
        hp.calibrate_handeye(a, b, sigma_rot=1e-3, sigma_trans=0.2)
    with pytest.raises(CalibrationError, match=match):
        hp.calibrate_robot_world_handeye(a, b, robust="cauchy")


def test_warn_names_the_cause_and_keeps_the_fit():
    (a, b), _ = MISTAKES["robot in cm"]
    with pytest.warns(CalibrationWarning, match=r"1\. the robot translations x10"):
        res = hp.calibrate_handeye(a, b, check_convention="warn")
    assert res.check.failures and any("robot translations x10" in n for n in res.notes)
    assert res.check.diagnosis[0][0].startswith("the robot translations x10")


def test_the_check_passes_clean_cells_and_its_limits_are_the_users():
    cell = _cell(41, n=N)
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert res.check.failures == [] and res.check.noise_ratio < 0.2
    assert res.check.break_after == -1
    strict = CellLimits(max_sigma_rot_deg=0.01, max_sigma_trans_fraction=1e-4)
    with pytest.raises(CalibrationError, match=r"pose noise of .* beyond any instrument"):
        hp.calibrate_handeye(cell.flange2base, cell.target2camera, limits=strict)
    with pytest.raises(CalibrationError, match="robot_reach_mm must be"):
        CellLimits(robot_reach_mm=(10.0, 5.0))


def test_diagnosis_takes_under_a_second():
    (a, b), _ = MISTAKES["rows shuffled"]
    start = time.perf_counter()
    with pytest.raises(CalibrationError):
        hp.calibrate_handeye(a, b)
    assert time.perf_counter() - start < 1.0


# ----------------------------------------------------------------------------------------------
# mistakes in a pose-list file: the diagnosis re-reads its columns


def _edit(path, prefix, fn):
    """Rewrite the columns ``<prefix>_*`` of the rotation of a pose-list file by ``fn``."""
    with open(path) as f:
        rows = list(csv.reader(f))
    head, body = rows[0], np.array(rows[1:], dtype=float)
    cols = [k for k, h in enumerate(head) if h.startswith(prefix + "_") and not h.endswith("_mm")]
    body[:, cols] = fn(body[:, cols])
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(head)
        for r in body:
            w.writerow([str(int(r[0]))] + [f"{v:.12g}" for v in r[1:]])
    return path


def _fanuc_wpr(rot):
    """W, P, R with ``R = Rz(R) Ry(P) Rx(W)`` in the a, b, c columns."""
    return geo.matrix_to_euler_zyx(rot)[:, ::-1]


FILE_MISTAKES = {
    "quaternion": (lambda q: q[:, [1, 2, 3, 0]], r"1\. the robot quaternions stored x, y, z, w"),
    "rotvec_rad": (np.rad2deg, r"1\. the robot rotation vectors in degrees under _rad"),
    "zyx_deg": (None, r"1\. the robot Euler angles as R = Rz\(c\) Ry\(b\) Rx\(a\)"),
}


@pytest.mark.parametrize("form", list(FILE_MISTAKES))
def test_file_rotation_format_mistakes_are_named(tmp_path, form):
    cell = _cell(42, n=N)
    path = write_pose_list(
        tmp_path / "poses.csv", cell.flange2base, cell.target2camera, rotation=form
    )
    fn, match = FILE_MISTAKES[form]
    if fn is None:  # the robot's angles written in Fanuc's W, P, R order
        wpr = _fanuc_wpr(cell.flange2base[:, :3, :3])
        fn = lambda cols: wpr  # noqa: E731
    _edit(path, "flange2base", fn)
    poses = read_pose_list(path)
    with pytest.raises(CalibrationError, match=match):
        hp.calibrate_handeye(**poses.arguments())


# ----------------------------------------------------------------------------------------------
# input handling


def test_no_poses_is_a_calibration_error():
    empty = np.zeros((0, 4, 4))
    with pytest.raises(CalibrationError, match="robot poses: no poses"):
        hp.calibrate_handeye(empty, empty)


def test_rotations_rounded_to_4_decimals_are_reprojected():
    cell = _cell(43, n=N, round_rotations=4)
    res = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    assert 1e-6 < res.prepared.max_correction < 1e-4
    assert np.rad2deg(geo.rotation_error(res.camera2flange, cell.camera2flange)) < 0.1


def test_opencv_logs_nothing_on_stderr(capfd):
    cell = _cell(3, n=3, noise=False)
    a, b = cell.flange2base[[0, 0, 1]], cell.target2camera[[0, 0, 1]]
    # OpenCV's Tsai logs "Hand-eye calibration failed!" and returns the identity; the motion
    # check refuses the repeated pose before OpenCV sees it
    with pytest.raises(CalibrationError, match="undetermined|not enough informative motions"):
        he.opencv_handeye(a, b, "Tsai")
    assert capfd.readouterr().err == ""
