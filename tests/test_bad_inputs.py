# ruff: noqa: E501  (the catalogue is a table: one case per line)
"""Catalogue of bad inputs: each raises CalibrationError (or an OSError naming the path)
whose message names the key number or name; and property tests of the shared layers on random
valid and invalid input (the table above the property tests says which function each covers).

Every case is one bad input through a public function or a user-data reader of core, models,
the shared estimators, io and claims. The ids read as "<function>-<what is wrong>".
"""

from __future__ import annotations

import atexit
import dataclasses
import shutil
import tempfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from hypothesis.extra import numpy as hnp

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.claims import claim_ids, claim_register
from calstudy.core import estimation, schema, stats, verdicts
from calstudy.core import geometry as geo
from calstudy.core.circles import fit_circle_2d
from calstudy.estimators import binocular as bino
from calstudy.estimators import bundle, coc, icp, sfm
from calstudy.estimators import fitting as ft
from calstudy.estimators import stereo_views as sv
from calstudy.estimators import workpiece as wp
from calstudy.handeye import refine as hr
from calstudy.handeye import sphere
from calstudy.handeye import sphere_csv as spc
from calstudy.handeye.calibrate import calibrate_handeye
from calstudy.handeye.posefile import read_pose_list, write_pose_list
from calstudy.io.params import check_parameters
from calstudy.io.results import aggregate_claims, write_table
from calstudy.io.runs import load_factory, rebuild
from calstudy.models import exposure, optics, reach
from calstudy.models.robots import load_robot
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import StereoRig, stereo_rig
from calstudy.models.targets import Sphere
from calstudy.papers.hybrid import compensation
from calstudy.papers.hybrid import handeye_experiments as hhe
from calstudy.papers.hybrid.scenario import load_scenario as load_production_scenario
from calstudy.selfcal.identify import identify

# hypothesis keeps a cache folder (.hypothesis/) even without an example database: put it in a
# temporary folder removed at exit, so no run leaves one in the checkout
_HOME = tempfile.mkdtemp(prefix="calstudy-hypothesis-")
set_hypothesis_home_dir(_HOME)
atexit.register(shutil.rmtree, _HOME, ignore_errors=True)
settings.register_profile(
    "bad_inputs",
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=40,
    suppress_health_check=[HealthCheck.too_slow],
)
PROFILE = settings.get_profile("bad_inputs")

# ----------------------------------------------------------------------------------------------
# fixtures of good data, made once

S2F = geo.make_transform(geo.euler_zyx_to_matrix(10.0, 50.0, -5.0), np.array([-46.0, -4.5, 413.0]))
X_B = np.array([1000.0, 350.0, 0.0])
K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
DATUMS_WORK = np.array([[1100.0, 250.0, 0.0], [300.0, 250.0, 0.0], [700.0, 1050.0, 0.0]])
NOMINAL = geo.invert(geo.make_transform(np.eye(3), [300.0, -500.0, 0.0]))


def _poses(n_trans=4, n_rot=6, seed=0):
    rng = np.random.default_rng(seed)
    base_rot = geo.euler_zyx_to_matrix(20.0, 170.0, 5.0)
    base_pos = np.array([900.0, 300.0, 700.0])
    trans = geo.make_transform(
        np.broadcast_to(base_rot, (n_trans, 3, 3)), base_pos + rng.uniform(-15, 15, (n_trans, 3))
    )
    rv = rng.normal(size=(n_rot, 3))
    rv *= np.deg2rad(rng.uniform(10, 30, n_rot))[:, None] / np.linalg.norm(rv, axis=1)[:, None]
    rot = geo.make_transform(
        base_rot @ geo.rotvec_to_matrix(rv), base_pos + rng.uniform(-15, 15, (n_rot, 3))
    )
    return trans, rot


def _centres(flange2base, x_b=X_B):
    s2b = flange2base @ S2F
    return np.einsum("nji,nj->ni", s2b[:, :3, :3], x_b - s2b[:, :3, 3])


TRANS, ROT = _poses()
ALL = np.concatenate([TRANS, ROT])
NOISE = np.random.default_rng(1).normal(0, 0.02, (len(ALL), 3))
CENTRES = _centres(ALL) + NOISE
MOVED = np.concatenate([_centres(TRANS), _centres(ROT, X_B + [5.0, 0, 0])]) + NOISE
ONLY_T, _ = _poses(n_trans=8, n_rot=1, seed=5)
SQUARE = np.array([[0.0, 0], [100, 0], [100, 100], [0, 100], [50, 30]])
UV = SQUARE * 2.0 + 50.0
CUBE = np.array(
    [[0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100], [100, 100, 0], [100, 0, 100.0]]
)

# the binocular calibrator (Table 2 distances), a stereo rig and a bright dot
TABLE2 = [162.085, 58.853, 55.181, 130.546, 64.765, 178.467, 43.745]
START = [0.0, 60.0, 180.0, 120.0, 300.0, 240.0]
LAYOUT, _ = bino.solve_calibrator_layout(TABLE2, START)
RIG = stereo_rig(PinholeCamera(fx=2000.0, fy=2000.0, cx=640.0, cy=512.0, width=1280, height=1024), 300.0, 850.0)
SEEN = RIG.project(LAYOUT[:3] + [0.0, 0.0, 850.0])
SIGMAS = {"focal_px": 0.5, "principal_point_px": 0.5, "k1": 0.0, "extrinsic_rotation_rad": 1e-5, "extrinsic_translation_mm": 0.01}
_YY, _XX = np.mgrid[:40, :40]
DOT = ((_YY - 20.0) ** 2 + (_XX - 20.0) ** 2 < 64).astype(float)


def _cell(n=8, seed=3):
    rng = np.random.default_rng(seed)
    a = geo.make_transform(
        geo.rotvec_to_matrix(rng.normal(0, 0.5, (n, 3))), rng.uniform(-300, 300, (n, 3))
    )
    z = geo.make_transform(np.eye(3), [800.0, 0, 0])
    b = geo.invert(a @ S2F) @ z  # target2camera = inv(X) inv(A) Z
    return a, b


CELL_A, CELL_B = _cell()
CELL_Z = geo.make_transform(np.eye(3), [800.0, 0, 0])


def _camera_poses(flange2base):
    """Target-to-camera poses of the cell of :func:`_cell` at the given flange poses."""
    return geo.invert(flange2base @ S2F) @ CELL_Z


def _degenerate(kind, n=6, seed=4):
    """Flange poses ``(n, 4, 4)`` whose motions are pure translations or turn about one axis."""
    rng = np.random.default_rng(seed)
    if kind == "translations":
        rot = np.broadcast_to(CELL_A[0, :3, :3], (n, 3, 3))
    else:
        rot = geo.rotvec_to_matrix(np.outer(np.deg2rad(rng.uniform(-40, 40, n)), [0.3, 0.4, 0.866]))
    return geo.make_transform(rot, rng.uniform(-300, 300, (n, 3)))


def _arc(deg, n=20, radius=100.0, noise=0.0, seed=2):
    a = np.deg2rad(np.linspace(-deg / 2, deg / 2, n))
    pts = radius * np.column_stack([np.cos(a), np.sin(a)])
    return pts + np.random.default_rng(seed).normal(0.0, noise, pts.shape)


def _stereo_rig(rotation, translation=(-200.0, 0.0, 0.0)):
    """The cameras of :data:`RIG` with the extrinsic ``left2right`` of ``rotation`` (3, 3) and
    ``translation`` (3,) mm."""
    return StereoRig.from_left2right(RIG.left, RIG.right, geo.make_transform(rotation, translation))


def _raise_refused(forms):
    """Raise the reasons of refused closed forms (they are reported, not raised)."""
    refused = [f"{f.method}: {f.refused}" for f in forms if f.refused]
    if refused:
        raise CalibrationError("; ".join(refused))
    return forms


def _register(tmp_path, text):
    path = tmp_path / "register.csv"
    path.write_text(text)
    return path


NB06 = {"seed": 6, "results_dir": "", "poses_csv": "", "setup": "eye_in_hand", "n_poses": 20, "n_duplicates": 3, "outlier_mm": 68.0, "outlier_deg": 1.8, "sigma_rot_rad": 0.0, "sigma_trans_mm": 0.0, "robust": "cauchy", "tool_point_mm": [0.0, 0.0, 500.0], "n_trials": 200, "n_jobs": None, "scheduler": "", "cache_dir": "", "progress": True}

# ----------------------------------------------------------------------------------------------
# user files

HEADER = "id,group,x,y,z,a,b,c,sx,sy,sz"


def _sphere_rows(header=HEADER, angle=1.0, length=1.0, sensor=1.0):
    meas = spc.SphereMeasurements(
        ids=np.arange(1, len(ALL) + 1),
        group=np.array(["translation"] * len(TRANS) + ["rotation"] * len(ROT)),
        flange2base=ALL,
        centres=CENTRES,
    )
    df = meas.to_frame()
    df[["a", "b", "c"]] *= angle
    df[["x", "y", "z"]] *= length
    df[["sx", "sy", "sz"]] *= sensor
    lines = [header]
    for row in df.itertuples(index=False):
        lines.append(",".join(str(v) if isinstance(v, str) else f"{v:.12g}" for v in row))
    return lines


def _csv(tmp_path, lines, name="m.csv", encoding="utf-8"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding=encoding)
    return path


def _edit(lines, row, col, text):
    """Cell ``col`` (0-based) of file row ``row`` (1-based, header row 1) replaced by text."""
    out = list(lines)
    cells = out[row - 1].split(",")
    cells[col] = text
    out[row - 1] = ",".join(cells)
    return out


def sphere_csv(kind):
    def make(tmp_path):
        lines = _sphere_rows()
        if kind == "radians":
            lines = _sphere_rows(angle=np.pi / 180)
        elif kind == "flange_metres":
            lines = _sphere_rows(length=1e-3)
        elif kind == "sensor_metres":
            lines = _sphere_rows(sensor=1e-3)
        elif kind == "all_metres":
            lines = _sphere_rows(length=1e-3, sensor=1e-3)
        elif kind == "decimal_comma_quoted":
            lines = _edit(lines, 4, 2, '"12,5"')
        elif kind == "decimal_comma_split":
            lines = _edit(lines, 4, 2, "12,5")
        elif kind == "semicolon_decimal_comma":
            lines = [ln.replace(",", ";") for ln in lines]
            lines = _edit([ln.replace(";", ",") for ln in lines], 1, 0, "id")
            lines = [ln.replace(",", ";") for ln in lines]
            cells = lines[4].split(";")
            cells[8] = "3,25"
            lines[4] = ";".join(cells)
        elif kind == "empty_cell":
            lines = _edit(lines, 3, 9, "")
        elif kind == "nan_cell":
            lines = _edit(lines, 5, 5, "nan")
        elif kind == "bad_group":
            lines = _edit(lines, 6, 1, "rotate")
        elif kind == "duplicate_id":
            lines = _edit(lines, 7, 0, "1")
        elif kind == "fractional_id":
            lines = _edit(lines, 7, 0, "7.5")
        elif kind == "missing_column":
            lines = [",".join(ln.split(",")[:-1]) for ln in lines]
        elif kind == "header_only":
            lines = lines[:1]
        elif kind == "no_rotation_rows":
            lines = [ln for ln in lines if ",rotation," not in ln]
        elif kind == "empty":
            lines = []
        elif kind == "mixed_units":
            lines[0] = lines[0].replace("sx,sy", "sx_m,sy")
        elif kind == "two_units":
            lines = [ln + ",1.0" for ln in lines]
            lines[0] = HEADER + ",x_m"
        elif kind == "extra_cells":
            lines = _edit(lines, 8, 10, "1.0,2.0")
        elif kind == "latin1":
            return _csv(tmp_path, [*lines, "# caf\xe9"], encoding="latin-1")
        elif kind == "missing_file":
            return tmp_path / "no_such.csv"
        return _csv(tmp_path, lines)

    return make


POSE_OK = None


def pose_csv(kind):
    def make(tmp_path):
        path = write_pose_list(tmp_path / "p.csv", CELL_A, CELL_B)
        lines = path.read_text().splitlines()
        if kind == "missing_file":
            return tmp_path / "none.csv"
        if kind == "empty":
            lines = []
        elif kind == "no_id":
            lines[0] = lines[0].replace("id,", "nr,", 1)
        elif kind == "two_robot_prefixes":
            lines[0] = lines[0].replace("target2camera", "base2gripper")
        elif kind == "quaternion_norm":
            lines = _edit(lines, 3, 4, "0.5")
        elif kind == "decimal_comma":
            lines = _edit(lines, 2, 1, '"12,5"')
        elif kind == "short_row":
            lines[2] = ",".join(lines[2].split(",")[:-1])
        elif kind == "no_rows":
            lines = lines[:1]
        elif kind == "bad_unit":
            lines[0] = lines[0].replace("_mm", "_km")
        elif kind == "text_cell":
            lines = _edit(lines, 4, 6, "n/a")
        return _csv(tmp_path, lines, "p.csv")

    return make


ROBOT = """name = "test robot"
[[link]]
convention = "dh"
a_mm = 260.0
alpha_deg = -90.0
d_mm = 675.0
theta_deg = 0.0
beta_deg = 0.0
qmin_deg = -185.0
qmax_deg = 185.0
[[link]]
convention = "dh"
a_mm = 680.0
alpha_deg = 0.0
d_mm = 0.0
theta_deg = 0.0
beta_deg = 0.0
qmin_deg = -155.0
qmax_deg = 35.0
[tolerances]
sigma_length_mm = 0.5
sigma_angle_deg = 0.05
"""


def robot_toml(old, new):
    def make(tmp_path):
        path = tmp_path / "robot.toml"
        text = ROBOT.replace(old, new, 1) if old else new
        path.write_text(text)
        return path

    return make


# ----------------------------------------------------------------------------------------------
# the catalogue: (id, function of tmp_path, error type, match)

E = CalibrationError
CASES = [
    # fit_rotation
    ("fit_rotation-shape", lambda p: ft.fit_rotation(np.ones((4, 2)), np.ones((4, 2))), E, r"shape \(4, 2\)"),
    ("fit_rotation-nan", lambda p: ft.fit_rotation([[np.nan, 0, 0]] * 3, np.eye(3)), E, "non-finite"),
    ("fit_rotation-one_vector", lambda p: ft.fit_rotation([[1.0, 0, 0]], [[1.0, 0, 0]]), E, "2"),
    ("fit_rotation-collinear", lambda p: ft.fit_rotation([[1.0, 0, 0], [2, 0, 0], [3, 0, 0]], [[1.0, 0, 0], [2, 0, 0], [3, 0, 0]]), E, "collinear"),
    ("fit_rotation-lengths", lambda p: ft.fit_rotation(np.eye(3), np.eye(3)[:2]), E, "3.*2|2.*3"),
    ("fit_rotation-text", lambda p: ft.fit_rotation([["a", "b", "c"]] * 3, np.eye(3)), E, "v_from"),
    # fit_rigid
    ("fit_rigid-two_points", lambda p: ft.fit_rigid(CUBE[:2], CUBE[:2]), E, "3"),
    ("fit_rigid-collinear", lambda p: ft.fit_rigid(CUBE[[0, 1]].tolist() + [[200, 0, 0]], CUBE[:3]), E, "line|collinear"),
    ("fit_rigid-lengths", lambda p: ft.fit_rigid(CUBE, CUBE[:4]), E, "6.*4|4.*6"),
    ("fit_rigid-inf", lambda p: ft.fit_rigid(CUBE, np.where(CUBE == 100, np.inf, CUBE)), E, "non-finite"),
    ("fit_rigid-ragged", lambda p: ft.fit_rigid([[0, 0, 0], [1, 2]], CUBE[:2]), E, "p_from"),
    # fit_sphere
    ("fit_sphere-three_points", lambda p: ft.fit_sphere(CUBE[:3]), E, "4"),
    ("fit_sphere-coplanar", lambda p: ft.fit_sphere(np.c_[SQUARE, np.zeros(5)]), E, "coplanar"),
    ("fit_sphere-coincident", lambda p: ft.fit_sphere(np.ones((5, 3))), E, "coincide"),
    ("fit_sphere-nan", lambda p: ft.fit_sphere(np.r_[CUBE, [[np.nan, 0, 0]]]), E, "non-finite"),
    # fit_circle_2d
    ("fit_circle_2d-two_points", lambda p: fit_circle_2d([[0.0, 0], [1, 1]]), E, "3"),
    ("fit_circle_2d-collinear", lambda p: fit_circle_2d([[0.0, 0], [1, 1], [2, 2], [3, 3]]), E, "line|collinear"),
    ("fit_circle_2d-method", lambda p: fit_circle_2d(SQUARE, method="hough"), E, "hough"),
    # fit_homography
    ("fit_homography-three_points", lambda p: ft.fit_homography(SQUARE[:3], UV[:3]), E, "at least 4 points; got 3"),
    ("fit_homography-3_of_4_collinear", lambda p: ft.fit_homography([[0, 0], [1, 0], [2, 0], [0, 1]], [[0, 0], [10, 0], [20, 0], [0, 10]]), E, "no 3 may lie on a line"),
    ("fit_homography-all_collinear", lambda p: ft.fit_homography([[0, 0], [1, 0], [2, 0], [3, 0]], UV[:4]), E, "line|collinear"),
    ("fit_homography-image_collinear", lambda p: ft.fit_homography(SQUARE, [[0, 0], [1, 1], [2, 2], [3, 3], [4, 4]]), E, "image points"),
    ("fit_homography-lengths", lambda p: ft.fit_homography(SQUARE, UV[:4]), E, "5.*4|4.*5"),
    # homography_to_pose
    ("homography_to_pose-rank_2", lambda p: ft.homography_to_pose(np.outer([1, 2, 1], [1, 1, 1]) + np.outer([0, 1, 0], [1, 0, 2]), K), E, "H is singular \\(rank 2"),
    ("homography_to_pose-zero", lambda p: ft.homography_to_pose(np.zeros((3, 3)), K), E, "singular"),
    ("homography_to_pose-k_lower", lambda p: ft.homography_to_pose(np.eye(3), [[800, 0, 320], [5, 800, 240], [0, 0, 1]]), E, "upper triangular"),
    ("homography_to_pose-k_negative_f", lambda p: ft.homography_to_pose(np.eye(3), np.diag([-800.0, 800, 1])), E, "fx > 0"),
    ("homography_to_pose-shape", lambda p: ft.homography_to_pose(np.eye(4), K), E, r"\(3, 3\)"),
    ("homography_to_pose-stretched", lambda p: ft.homography_to_pose(K @ np.diag([1.0, 10.0, 500.0]), K), E, r"\|r2\|/\|r1\| = 10"),
    # solve_pnp
    ("solve_pnp-three_points", lambda p: ft.solve_pnp(CUBE[:3], UV[:3], K), E, "4 points; got 3"),
    ("solve_pnp-skew", lambda p: ft.solve_pnp(CUBE, UV[:1].repeat(6, 0) + CUBE[:, :2], [[800, 2, 320], [0, 800, 240], [0, 0, 1]]), E, r"K\[0,1\] = 2"),
    ("solve_pnp-collinear", lambda p: ft.solve_pnp([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], UV[:4], K), E, "line|collinear"),
    ("solve_pnp-nonplanar_five", lambda p: ft.solve_pnp(CUBE[:5], UV[:5], K), E, "at least 6 points for SOLVEPNP_ITERATIVE; got 5"),
    ("solve_pnp-nan_pixels", lambda p: ft.solve_pnp(CUBE, np.full((6, 2), np.nan), K), E, "non-finite"),
    ("solve_pnp_ransac-threshold", lambda p: ft.solve_pnp_ransac(CUBE, UV[:1].repeat(6, 0), K, -1.0), E, "threshold_px"),
    ("solve_pnp_ransac-three", lambda p: ft.solve_pnp_ransac(CUBE[:3], UV[:3], K, 2.0), E, "4 points; got 3"),
    # sphere hand-eye
    ("rotation_from_translations-orientation", lambda p: sphere.rotation_from_translations(ROT[:4], CENTRES[4:8]), E, "not pure translations"),
    ("rotation_from_translations-three", lambda p: sphere.rotation_from_translations(TRANS[:3], CENTRES[:3]), E, "at least 4 positions; got 3"),
    ("rotation_from_translations-collinear", lambda p: sphere.rotation_from_translations(geo.make_transform(np.broadcast_to(TRANS[0, :3, :3], (4, 3, 3)), np.outer(np.arange(4.0), [10, 0, 0])), CENTRES[:4]), E, "one line"),
    ("translation_from_rotations-pure", lambda p: sphere.translation_from_rotations(TRANS, CENTRES[:4], S2F[:3, :3]), E, "pure translations"),
    ("translation_from_rotations-parallel", lambda p: sphere.translation_from_rotations(geo.make_transform(geo.rotvec_to_matrix(np.outer(np.deg2rad([0, 10, 20, 30]), [0, 0, 1])), np.zeros((4, 3))), CENTRES[:4], S2F[:3, :3]), E, "parallel \\(condition number"),
    ("sphere_handeye_ml-translation_only", lambda p: he.sphere_handeye_ml(ONLY_T, _centres(ONLY_T), 0.02, S2F), E, "condition number"),
    ("sphere_handeye_ml-sphere_moved", lambda p: he.sphere_handeye_ml(ALL, MOVED, 0.02, S2F, ids=np.arange(1, 11), misfit="raise"), E, "chi2/dof = .* id \\d+"),
    ("sphere_handeye_ml-sigma_zero", lambda p: he.sphere_handeye_ml(ALL, CENTRES, 0.0, S2F), E, "sigma must be positive"),
    ("sphere_handeye_ml-sigma_nan", lambda p: he.sphere_handeye_ml(ALL, CENTRES, [0.02, np.nan, 0.02], S2F), E, "sigma must be positive"),
    ("sphere_handeye_ml-sigma_shape", lambda p: he.sphere_handeye_ml(ALL, CENTRES, [0.1, 0.2], S2F), E, "one per sensor axis"),
    ("sphere_handeye_ml-two_poses", lambda p: he.sphere_handeye_ml(ALL[:2], CENTRES[:2], 0.02, S2F), E, "at least 3 poses; got 2"),
    ("sphere_handeye_ml-ids_length", lambda p: he.sphere_handeye_ml(ALL, CENTRES, 0.02, S2F, ids=[1, 2]), E, "2 ids for 10"),
    ("sphere_handeye_ml-policy", lambda p: he.sphere_handeye_ml(ALL, MOVED, 0.02, S2F, misfit="ignore"), E, "ignore"),
    ("sphere_handeye_ml-centres_shape", lambda p: he.sphere_handeye_ml(ALL, CENTRES[:, :2], 0.02, S2F), E, r"shape \(10, 2\)"),
    ("sphere_handeye_ml-not_rigid", lambda p: he.sphere_handeye_ml(ALL, CENTRES, 0.02, S2F * 1.01), E, "initial sensor2flange"),
    ("sphere_handeye_crb-sigma_zero", lambda p: he.sphere_handeye_crb(ALL, _centres(ALL), 0.0, S2F, X_B), E, "sigma must be positive"),
    ("sphere_handeye_crb-translation_only", lambda p: he.sphere_handeye_crb(ONLY_T, _centres(ONLY_T), 0.02, S2F, X_B), E, "condition number"),
    ("opencv_handeye-method", lambda p: he.opencv_handeye(CELL_A, CELL_B, "Tsay"), E, "Tsay"),
    ("opencv_handeye-two_poses", lambda p: he.opencv_handeye(CELL_A[:2], CELL_B[:2], "Tsai"), E, "at least 3 poses; got 2"),
    ("opencv_handeye-lengths", lambda p: he.opencv_handeye(CELL_A, CELL_B[:5], "Park"), E, r"\(8, 4, 4\).*\(5, 4, 4\)"),
    ("opencv_handeye-no_rotation", lambda p: he.opencv_handeye(CELL_A[[0, 0, 0]], CELL_B[[0, 0, 0]], "Tsai", min_pair_rotation=he.MIN_PAIR_ROTATION), E, "no pair of the 3 poses rotates"),
    # workpiece 3-2-1
    ("rps_frame_so3-datums_contradict_cad", lambda p: wp.rps_frame_so3([[0.0, 0, 0], [800, 0, 0], [400, 0, 0]], DATUMS_WORK, NOMINAL), E, "condition number"),
    ("rps_frame_so3-cad_a_equals_b", lambda p: wp.rps_frame_so3(DATUMS_WORK, DATUMS_WORK[[0, 0, 2]], NOMINAL), E, "A and B coincide"),
    ("rps_frame_so3-cad_c_on_line", lambda p: wp.rps_frame_so3(DATUMS_WORK, [[0, 0, 0], [100, 0, 0], [50, 0.5, 0]], NOMINAL), E, "0.5 mm from the line"),
    ("rps_frame_so3-shape", lambda p: wp.rps_frame_so3(DATUMS_WORK[:2], DATUMS_WORK, NOMINAL), E, r"\(2, 3\)"),
    ("rps_frame_penalty-penalty", lambda p: wp.rps_frame_penalty(DATUMS_WORK, DATUMS_WORK, NOMINAL, penalty=0.0), E, "penalty factor M"),
    ("rps_frame_penalty-max_nfev", lambda p: wp.rps_frame_penalty(DATUMS_WORK, DATUMS_WORK, NOMINAL, max_nfev=0), E, "max_nfev"),
    ("rps_frame_batch-shape", lambda p: wp.rps_frame_batch(DATUMS_WORK, DATUMS_WORK, NOMINAL), E, r"\(N, 3, 3\)"),
    ("rps_frame_batch-degenerate", lambda p: wp.rps_frame_batch(np.array([[[0.0, 0, 0], [800, 0, 0], [400, 0, 0]]]), DATUMS_WORK, NOMINAL), E, "panel 0"),
    # calibrate_handeye (pose lists)
    ("calibrate_handeye-lengths", lambda p: calibrate_handeye(CELL_A, CELL_B[:6]), E, "8 robot poses but 6 camera poses"),
    ("calibrate_handeye-method", lambda p: calibrate_handeye(CELL_A, CELL_B, method="Tsay"), E, "Tsay"),
    ("calibrate_handeye-convention", lambda p: calibrate_handeye(CELL_A, CELL_B, convention="world2camera"), E, "world2camera"),
    ("calibrate_handeye-one_sigma", lambda p: calibrate_handeye(CELL_A, CELL_B, sigma_rot=0.001), E, "both sigma_rot and sigma_trans"),
    ("calibrate_handeye-sigma_inf", lambda p: calibrate_handeye(CELL_A, CELL_B, sigma_rot=np.inf, sigma_trans=0.1), E, "positive and finite"),
    ("calibrate_handeye-bottom_row", lambda p: calibrate_handeye(CELL_A + np.eye(4)[3] * 0 + np.pad(np.ones((8, 1, 4)), ((0, 0), (3, 0), (0, 0))), CELL_B), E, "bottom row"),
    ("calibrate_handeye-unit", lambda p: calibrate_handeye(CELL_A, CELL_B, robot_unit="km"), E, "km"),
    ("calibrate_handeye-misfit_policy", lambda p: calibrate_handeye(CELL_A, CELL_B, misfit="warn"), E, "warn"),
    ("calibrate_handeye-misfit", lambda p: calibrate_handeye(CELL_A, np.concatenate([CELL_B[:4], geo.make_transform(CELL_B[4:, :3, :3], CELL_B[4:, :3, 3] + [5.0, 0, 0])]), sigma_rot=1e-4, sigma_trans=0.01, misfit="raise", check_convention="off"), E, "chi2/dof = .*pose \\d"),
    # the fixed-sphere CSV
    ("read_sphere_csv-missing_file", sphere_csv("missing_file"), FileNotFoundError, "no_such.csv"),
    ("read_sphere_csv-empty", sphere_csv("empty"), E, "empty"),
    ("read_sphere_csv-header_only", sphere_csv("header_only"), E, "no data rows"),
    ("read_sphere_csv-radians", sphere_csv("radians"), E, "look like radians.*a_rad"),
    ("read_sphere_csv-flange_in_metres", sphere_csv("flange_metres"), E, "flange positions x, y, z are all below 10.*metres"),
    ("read_sphere_csv-sensor_in_metres", sphere_csv("sensor_metres"), E, "sphere centres sx, sy, sz are all below 10.*metres"),
    ("read_sphere_csv-all_in_metres", sphere_csv("all_metres"), E, "below 10.*metres"),
    ("read_sphere_csv-decimal_comma_quoted", sphere_csv("decimal_comma_quoted"), E, r"row 4, column 'x': '12,5' .*write 12\.5"),
    ("read_sphere_csv-decimal_comma_split", sphere_csv("decimal_comma_split"), E, r"row 4 has 12 cells; the header has 11 \(a decimal comma"),
    ("read_sphere_csv-semicolon_decimal_comma", sphere_csv("semicolon_decimal_comma"), E, r"row 5, column 'sx': '3,25'.*write 3\.25"),
    ("read_sphere_csv-empty_cell", sphere_csv("empty_cell"), E, r"row 3, column 'sy': '' is not a number"),
    ("read_sphere_csv-nan_cell", sphere_csv("nan_cell"), E, r"row 5, column 'a': 'nan'"),
    ("read_sphere_csv-bad_group", sphere_csv("bad_group"), E, r"row 6, column 'group': 'rotate' is not one of"),
    ("read_sphere_csv-no_rotation_rows", sphere_csv("no_rotation_rows"), E, r"m\.csv: no rows of group 'rotation'"),
    ("read_sphere_csv-duplicate_id", sphere_csv("duplicate_id"), E, "id 1 appears more than once"),
    ("read_sphere_csv-fractional_id", sphere_csv("fractional_id"), E, "7.5 is not an integer"),
    ("read_sphere_csv-missing_column", sphere_csv("missing_column"), E, "missing column 'sz'"),
    ("read_sphere_csv-mixed_units", sphere_csv("mixed_units"), E, "mix declared and undeclared units"),
    ("read_sphere_csv-column_twice", sphere_csv("two_units"), E, "column 'x' is given twice"),
    ("read_sphere_csv-extra_cells", sphere_csv("extra_cells"), E, "row 8 has 12 cells"),
    ("read_sphere_csv-not_utf8", sphere_csv("latin1"), E, "not a UTF-8 text file"),
    # the pose-list CSV
    ("read_pose_list-missing_file", pose_csv("missing_file"), FileNotFoundError, "none.csv"),
    ("read_pose_list-empty", pose_csv("empty"), E, "empty"),
    ("read_pose_list-no_id", pose_csv("no_id"), E, r"missing column\(s\) id \(the header has nr, flange2base_x_mm"),
    ("read_pose_list-no_camera_prefix", pose_csv("two_robot_prefixes"), E, "exactly one prefix"),
    ("read_pose_list-quaternion_norm", pose_csv("quaternion_norm"), E, r"row 3, columns flange2base_qw..flange2base_qz: the quaternion has norm"),
    ("read_pose_list-decimal_comma", pose_csv("decimal_comma"), E, r"row 2, column 'flange2base_x_mm': '12,5'.*write 12\.5"),
    ("read_pose_list-short_row", pose_csv("short_row"), E, "row 3 has 14 cells; the header has 15"),
    ("read_pose_list-no_rows", pose_csv("no_rows"), E, r"no data rows \(the pose list has a header only\)"),
    ("read_pose_list-unit", pose_csv("bad_unit"), E, "one unit of mm, cm, m, in"),
    ("read_pose_list-text_cell", pose_csv("text_cell"), E, r"row 4, column 'flange2base_qy': 'n/a' is not a number"),
    # robot tables
    ("load_robot-unknown_name", lambda p: load_robot("kuka_kr16"), FileNotFoundError, "kuka_kr16.toml.*available: .*kuka_kr16_2"),
    ("load_robot-missing_path", lambda p: load_robot(p / "none.toml"), FileNotFoundError, "none.toml"),
    ("load_robot-not_toml", robot_toml(None, "name = \n"), E, "not valid TOML"),
    ("load_robot-missing_key", robot_toml("theta_deg = 0.0\nbeta_deg = 0.0\nqmin_deg = -155.0", "beta_deg = 0.0\nqmin_deg = -155.0"), E, r"link #2.theta_deg: missing"),
    ("load_robot-misspelt_key", robot_toml("d_mm = 675.0", "d_mn = 675.0"), E, r"link #1.d_mn = 675.0: unknown key"),
    ("load_robot-negative_range", robot_toml("qmax_deg = 35.0", "qmax_deg = -200.0"), E, r"link #2.*qmin_deg = -155 must be below qmax_deg = -200"),
    ("load_robot-huge_length", robot_toml("a_mm = 680.0", "a_mm = 68000.0"), E, r"link #2.a_mm = 68000.0: must be >= -10000.0 and <= 10000.0"),
    ("load_robot-angle_range", robot_toml("alpha_deg = -90.0", "alpha_deg = -900.0"), E, r"link #1.alpha_deg = -900.0: must be >= -360"),
    ("load_robot-radians", robot_toml("alpha_deg = -90.0", "alpha_deg = -1.5708"), E, r"link #1.alpha_deg = -1.5708 looks like radians"),
    ("load_robot-metres", lambda p: robot_toml(None, ROBOT.replace("260.0", "0.26").replace("675.0", "0.675").replace("680.0", "0.68"))(p), E, "below 10.*metres"),
    ("load_robot-convention", robot_toml('convention = "dh"', 'convention = "DH2"'), E, r"link #1.convention = 'DH2': is not one of"),
    ("load_robot-mixed_conventions", robot_toml('convention = "dh"', 'convention = "mdh"'), E, "mix conventions"),
    ("load_robot-no_links", robot_toml(None, 'name = "x"\n'), E, "link: missing"),
    ("load_robot-negative_tolerance", robot_toml("sigma_length_mm = 0.5", "sigma_length_mm = -0.5"), E, r"tolerances.sigma_length_mm = -0.5: must be >= 0"),
    ("load_robot-text_number", robot_toml("d_mm = 675.0", 'd_mm = "about 675"'), E, r"link #1.d_mm = 'about 675': is not a number"),
    ("load_robot-nan", robot_toml("d_mm = 675.0", "d_mm = nan"), E, r"link #1.d_mm = nan: must be a finite number"),
    # models
    ("robot.fk-length", lambda p: load_robot("kuka_kr16_2").fk(np.zeros(5)), E, "5 values; the KUKA KR 16-2 has 6 joints"),
    ("robot.fk-nan", lambda p: load_robot("kuka_kr16_2").fk([0, 0, np.nan, 0, 0, 0]), E, "joint 3"),
    ("robot.random_configurations-rng", lambda p: load_robot("kuka_kr16_2").random_configurations(7, 3), E, "numpy.random.Generator"),
    ("sphere-negative_radius", lambda p: Sphere(radius_mm=-12.7), E, "-12.7 mm"),
    ("sphere-centre_shape", lambda p: Sphere(centre=np.zeros(2)), E, r"centre has shape \(2,\)"),
    ("camera-negative_focal", lambda p: PinholeCamera(fx=-800, fy=800, cx=320, cy=240, width=640, height=480), E, "focal lengths must be positive"),
    ("camera-dist_length", lambda p: PinholeCamera(fx=800, fy=800, cx=320, cy=240, width=640, height=480, dist=(0.1, 0.2, 0.0)), E, r"0, 4, 5, 8, 12 or 14 .*got \(0.1, 0.2, 0.0\)"),
    # core
    ("levenberg_marquardt-underdetermined", lambda p: estimation.levenberg_marquardt(lambda x: x[:1], np.zeros(3)), E, "1 equations for 3 unknowns"),
    ("levenberg_marquardt-nan_start", lambda p: estimation.levenberg_marquardt(lambda x: x, np.array([np.nan, 0.0])), E, "starting point is not finite"),
    ("levenberg_marquardt-unobservable", lambda p: estimation.levenberg_marquardt(lambda x: np.array([x[0] + x[1] - 1, x[0] + x[1] - 1]), np.zeros(2), max_condition=1e8), E, "condition number"),
    ("schema.validate-range", lambda p: schema.validate(type("S", (schema.Schema,), {"__annotations__": {"rate": schema.Fraction}}), {"rate": 1.5}, "s.toml", "station."), E, r"s.toml: station.rate = 1.5: must be >= 0 and <= 1"),
    ("geometry.check_transform-empty", lambda p: geo.check_transform("rotation flange poses", np.zeros((0, 4, 4))), E, r"rotation flange poses holds no transforms \(shape \(0, 4, 4\)\)"),
    ("geometry.check_transform-not_rigid", lambda p: geo.check_transform("sensor2flange", np.diag([1.0, 1, 2, 1])), E, "sensor2flange"),
    ("aggregate_claims-misspelt_folder", lambda p: aggregate_claims(p / "reslts"), FileNotFoundError, "reslts"),
    # binocular calibrator, triangulation and hand-eye update
    ("solve_calibrator_layout-no_layout", lambda p: bino.solve_calibrator_layout(TABLE2[:4] + [364.765] + TABLE2[5:], START), E, r"P5P7 = 364\.765 admit no layout: .*\(P5P7 = 364\.765 > 114\.034\)"),
    ("solve_calibrator_layout-p8_beyond", lambda p: bino.solve_calibrator_layout(TABLE2[:6] + [200.0], START), E, r"P8P7 = 200 with .* lies between 0 and 157\.033 from P7"),
    ("solve_calibrator_layout-nan_angle", lambda p: bino.solve_calibrator_layout(TABLE2, [0, np.nan, 0, 0, 0, 0]), E, "6 finite start angles"),
    ("solve_calibrator_layout-five_angles", lambda p: bino.solve_calibrator_layout(TABLE2, START[:5]), E, "6 finite start angles"),
    ("distances_to_p7-six_points", lambda p: bino.distances_to_p7(LAYOUT[:6]), E, r"P1-P8 as \(\.\.\., 8, 3\) points; got \(6, 3\)"),
    ("with_virtual-nan", lambda p: bino.with_virtual(np.full((6, 3), np.nan)), E, "calibrator targets holds a non-finite value"),
    ("modify_observed_error-rcond", lambda p: bino.modify_observed_error(LAYOUT, bino.all_pairs(8), np.full(28, 50.0), rcond=-1), E, r"rcond = -1 must lie in \[0, 1\)"),
    ("modify_observed_error-negative_standard", lambda p: bino.modify_observed_error(LAYOUT, bino.all_pairs(8), -np.ones(28)), E, "standard distance #1 is -1 mm"),
    ("correct_transformation-same_pose", lambda p: bino.correct_transformation(np.stack([ROT[0]] * 3), S2F, np.stack([LAYOUT] * 3), np.stack([LAYOUT] * 3)), E, r"unobservable from these 3 poses and 8 targets \(condition number inf"),
    ("correct_transformation-one_target", lambda p: bino.correct_transformation(ROT, S2F, np.stack([LAYOUT[:1]] * 6), np.stack([LAYOUT[:1]] * 6)), E, "unobservable from these 6 poses and 1 targets"),
    ("triangulate-tol_nan", lambda p: bino.triangulate(RIG, *SEEN, tol_mm=float("nan")), E, "tol_mm = nan must be a finite number > 0"),
    ("triangulate-tol_negative", lambda p: bino.triangulate(RIG, *SEEN, tol_mm=-1.0), E, "tol_mm = -1.0 must be a finite number > 0"),
    # imaging: circle of confusion, exposures, dot centres, the stereo rig
    ("roi_around-negative_radius", lambda p: optics.roi_around([100.0, 100.0], -10.0, 5.0, 1280, 1024), E, r"dot radius -10\.0 px must be > 0"),
    ("defocus-nan_image", lambda p: optics.defocus(np.full((20, 20), np.nan), 1.0), E, "image to blur has NaN or inf pixels"),
    ("fuse_exposures-sigma_zero", lambda p: exposure.fuse_exposures([DOT, DOT * 0.5], 1.0, 1.0, 0.0), E, "well-exposedness sigma = 0.0"),
    ("fuse_exposures-negative_weight", lambda p: exposure.fuse_exposures([DOT, DOT * 0.5], -1.0, 1.0, 0.2), E, r"fusion weights -1\.0, 1\.0"),
    ("detect_centre-thresholds_reversed", lambda p: coc.detect_centre(DOT, low=0.6, high=0.3), E, r"low = 0\.6, high = 0\.3: need 0 < low < high <= 1"),
    ("stereorig.perturbed-negative_sigma", lambda p: RIG.perturbed(SIGMAS | {"focal_px": -1.0}, np.random.default_rng(0)), E, r"calibration sigma focal_px = -1\.0"),
    ("stereorig.perturbed-missing_sigma", lambda p: RIG.perturbed({"focal_px": 1.0}, np.random.default_rng(0)), E, "calibration sigma principal_point_px = None"),
    ("stereorig.aim_point-negative", lambda p: RIG.aim_point(-850.0), E, r"aim distance -850\.0 mm"),
    # silent NaN or inf in the shared layers, now refused at the entry
    ("fit_circle_2d-geometric_point_at_centre", lambda p: fit_circle_2d(np.r_[SQUARE[:4], [[50.0, 50.0]]], method="geometric"), E, r"geometric circle fit of 5 points gave no finite circle"),
    ("fit_circle_2d-2deg_arc", lambda p: fit_circle_2d(_arc(2.0)), E, r"span an arc of 2 deg .*radius 100\).*at least 10 deg"),
    ("fit_circle_2d-2deg_arc_noisy", lambda p: fit_circle_2d(_arc(2.0, noise=0.01)), E, r"the 20 points .*the radius (of a shorter arc )?is ill-conditioned"),
    ("euler_zyx_to_matrix-nan", lambda p: geo.euler_zyx_to_matrix(np.nan, 0.0, 0.0), E, r"Euler angles \(A, B, C\) in deg holds a non-finite value \(nan\)"),
    ("euler_zyx_to_matrix-text", lambda p: geo.euler_zyx_to_matrix("ten", 0.0, 0.0), E, "Euler angles A, B, C are not numbers"),
    ("matrix_to_euler_zyx-inf", lambda p: geo.matrix_to_euler_zyx(np.diag([1.0, 1.0, np.inf])), E, r"rotation holds a non-finite value \(inf\)"),
    ("look_at-nan_eye", lambda p: geo.look_at([0.0, 0.0, np.nan], [0.0, 0.0, 0.0]), E, r"look_at: eye \[ 0\.  0\. nan\], target .* must be finite"),
    ("perturb-negative_sigma", lambda p: geo.perturb(np.eye(4), -1.0, 0.1, np.random.default_rng(0)), E, r"perturb: sigma_rot = -1\.0 rad must be finite and >= 0"),
    ("perturb-nan_sigma", lambda p: geo.perturb(np.eye(4), 0.01, np.nan, np.random.default_rng(0)), E, r"perturb: sigma_trans = nan mm"),
    ("random_rotation-negative_size", lambda p: geo.random_rotation(np.random.default_rng(0), -1), E, r"random_rotation: size = -1 must be None or an integer >= 0"),
    ("project_to_so3-nan", lambda p: geo.project_to_so3(np.full((3, 3), np.nan)), E, "matrix to project to SO\\(3\\) holds a non-finite value"),
    ("compensate-nan_offset", lambda p: compensation.compensate(np.zeros((3, 2, 3)), [[np.nan, 0, 0], [0, 0, 0]]), E, r"offset holds a non-finite value \(nan\) at index \(0, 0\)"),
    ("coc_radius_far_mm-zero_distance", lambda p: optics.coc_radius_far_mm(0.0, 850.0, 16.0, 5.6), E, r"object distance d_B = 0\.0 mm must be a finite number > 0"),
    ("coc_radius_far_mm-zero_focus", lambda p: optics.coc_radius_far_mm(800.0, 0.0, 16.0, 5.6), E, r"focused distance d_A = 0\.0 mm"),
    ("coc_radius_far_mm-negative_f_number", lambda p: optics.coc_radius_far_mm(800.0, 850.0, 16.0, -5.6), E, r"F -5\.6 must be finite positive"),
    ("fuse_exposures-nan_pixel", lambda p: exposure.fuse_exposures([DOT, np.where(DOT > 0, np.nan, 0.0)]), E, r"image 1 holds nan at pixel \(13, 17\)"),
    ("fuse_exposures-above_one", lambda p: exposure.fuse_exposures([DOT * 1.5]), E, r"image 0 holds 1\.5 at pixel .*\[0, 1\]"),
    ("expose-negative_gain", lambda p: exposure.expose(DOT, 100.0, 1.3, 0.06, 1.5, -40.0, np.random.default_rng(0)), E, r"electrons_per_dn = -40\.0 must be > 0"),
    ("expose-zero_time", lambda p: exposure.expose(DOT, 0.0, 1.3, 0.06, 1.5, 40.0, np.random.default_rng(0)), E, r"exposure_ms = 0\.0 must be a finite number > 0"),
    ("expose-negative_read_noise", lambda p: exposure.expose(DOT, 100.0, 1.3, 0.06, -1.5, 40.0, np.random.default_rng(0)), E, r"read_noise_dn = -1\.5 must be a finite number >= 0"),
    ("expose-nan_radiance", lambda p: exposure.expose(DOT * np.nan, 100.0, 1.3, 0.06, 1.5, 40.0, np.random.default_rng(0)), E, r"radiance holds 1600 NaN or inf pixel"),
    ("expose-bits", lambda p: exposure.expose(DOT, 100.0, 1.3, 0.06, 1.5, 40.0, np.random.default_rng(0), bits=24), E, r"bits = 24 must be an integer from 1 to 16"),
    ("expose_and_fuse-negative_time", lambda p: exposure.expose_and_fuse(DOT, [100.0, -10.0], 1.3, 0.06, 1.5, 40.0, np.random.default_rng(0)), E, r"exposure_ms = -10\.0"),
    ("stereorig.from_left2right-scaled_rotation", lambda p: _stereo_rig(2 * np.eye(3)), E, r"left2right rotation is not orthonormal \(max \|R\^T R - I\| = 3"),
    ("stereorig.from_left2right-reflection", lambda p: _stereo_rig(np.diag([1.0, 1.0, -1.0])), E, r"left2right rotation is a reflection"),
    ("sphere_handeye-camera_in_metres", lambda p: he.sphere_handeye(TRANS, CENTRES[:4] * 1e-3, ROT, CENTRES[4:] * 1e-3), E, r"sphere centre moves 0\.001\d* times as far .*metres give 0\.001"),
    ("opencv_handeye-pure_translations", lambda p: he.opencv_handeye(_degenerate("translations"), _camera_poses(_degenerate("translations")), "Tsai"), E, r"no pair of the 6 poses rotates by 0\.01 deg or more \(largest 0 deg\): pure translations"),
    ("opencv_handeye-one_axis", lambda p: he.opencv_handeye(_degenerate("one_axis"), _camera_poses(_degenerate("one_axis")), "Daniilidis"), E, r"6 poses turn about one axis \(axes within [0-9.e-]+ deg, minimum 0\.01 deg\).*translation along it are undetermined"),
    ("opencv_handeye-repeated_pose", lambda p: he.opencv_handeye(CELL_A[[0, 1, 1]], CELL_B[[0, 1, 1]], "Horaud"), E, r"the 2 rotating motions of the 3 poses turn about one axis"),
    ("closed_forms-robot_world_one_axis", lambda p: _raise_refused(hr.closed_forms(_degenerate("one_axis"), _camera_poses(_degenerate("one_axis")), ["Shah", "Li"])), E, r"Shah: solver failed: the 15 rotating motions of the 6 poses turn about one axis"),
    ("opencv_handeye-min_pair_rotation_nan", lambda p: he.opencv_handeye(CELL_A, CELL_B, "Park", min_pair_rotation=np.nan), E, r"min_pair_rotation = nan"),
    # other exception types, now a CalibrationError naming the input
    ("calibrate_handeye_csv-two_sigmas", lambda p: hhe.sphere_station_calibration(str(_csv(p, _sphere_rows(), "mine.csv")), 1, [0.02, 0.03]), E, r"sensor_sigma_mm = \[0\.02, 0\.03\]: .*one per sensor axis \(3 values\)"),
    ("identify-29_parameters", lambda p: identify(None, np.zeros(29)), E, r"start \(the parameter vector\) has shape \(29,\); expected \(30\)"),
    ("refine_ml-zero_weights", lambda p: hr.refine_ml(CELL_A, CELL_B, S2F, CELL_Z, 1e-3, 0.1, weights=np.zeros(8)), E, r"weights leave 0 of the 8 poses with a weight > 0; AX = ZB needs at least 3"),
    ("calibrate_handeye-zero_weights", lambda p: calibrate_handeye(CELL_A, CELL_B, weights=np.zeros(8)), E, r"weights leave 0 of the 8 poses"),
    ("calibrate_handeye-negative_weight", lambda p: calibrate_handeye(CELL_A, CELL_B, weights=np.r_[np.ones(7), -1.0]), E, r"weight 7 is -1"),
    ("handeye_crb-two_weighted_poses", lambda p: hr.handeye_crb(CELL_A, CELL_B, S2F, CELL_Z, 1e-3, 0.1, weights=np.r_[np.zeros(6), 1.0, 1.0]), E, r"weights leave 2 of the 8 poses"),
    ("production_scenario-huge_count", lambda p: load_production_scenario(overrides={"production.protocol.n_compensation_max": 10**9}), E, r"production\.toml: protocol\.n_compensation_max = 1000000000: must be >= 3 and <= 1000"),
    ("production_scenario-fractional_count", lambda p: load_production_scenario(overrides={"production.protocol.n_follow_up": 12.5}), E, r"protocol\.n_follow_up = 12\.5: is not an integer"),
    ("claim_ids-no_id_column", lambda p: claim_ids(_register(p, "name,paper\nx,hybrid\n")), E, r"register\.csv lacks the column\(s\) \['id'\]"),
    ("claim_register-duplicate_id", lambda p: claim_register(_register(p, "id,paper\na.b,x\na.b,y\n")), E, r"id 'a\.b' appears more than once"),
    ("claim_register-empty_id", lambda p: claim_register(_register(p, "id,paper\na.b,x\n,y\n")), E, r"row 3 has an empty id"),
    # shared estimators: degenerate geometry and shapes, now refused at the entry
    ("rectify_coc-window_beyond_image", lambda p: coc.rectify_coc(DOT, 1e3), E, r"radius 1000\.0 px: its 3-delta window of radius 3000 px exceeds the 40 x 40 px image"),
    ("image_gradients-empty", lambda p: coc.image_gradients(np.zeros((0, 5))), E, r"non-empty 2-D image, got \(0, 5\)"),
    ("ray_gap-points_in_3d", lambda p: bino.ray_gap(CUBE, CUBE, np.eye(3), np.zeros(3)), E, r"x_left has shape \(6, 3\); expected \(N, 2\)"),
    ("pnp_pose-markers_on_one_point", lambda p: sfm.pnp_pose(np.zeros((5, 3)), UV, RIG.left), E, r"cv2\.solvePnP failed on the 5 markers"),
    ("weighted_icp-moving_cloud_on_a_line", lambda p: icp.weighted_icp(np.outer(np.arange(10.0), [1.0, 0, 0]), CUBE), E, r"the 10 points of the moving cloud are collinear \(singular values"),
    ("bundle_adjust-start_behind_cameras", lambda p: bundle.bundle_adjust(RIG, _views(BA_POSES, BA_POINTS, np.zeros((2, 6, 2))), BA_POSES, -BA_POINTS, fixed_view=0, sigma_px=1.0, sigma_mm=1.0), E, r"the start of marker 0 lies at depth -8\d\d\.?\d* mm in view 0"),
    ("refine_camera_pose-start_behind_cameras", lambda p: bundle.refine_camera_pose(RIG, _views(BA_POSES, BA_POINTS, np.zeros((2, 6, 2)))[1], -BA_POINTS, BA_POSES[1], sigma_px=1.0, sigma_mm=1.0), E, r"the start of marker 0 lies at depth -8"),
    # write paths
    ("write_table-inf", lambda p: write_table(__import__("pandas").DataFrame({"a": [1.0, np.inf]}), p / "t.csv"), E, r"t\.csv: column 'a' \(#1\) holds inf at row 2"),
    ("write_table-inf_in_object_column", lambda p: write_table(__import__("pandas").DataFrame({"a": ["x", -np.inf]}), p / "t.csv"), E, r"column 'a' \(#1\) holds -inf at row 2"),
    # data that names code
    ("load_factory-outside_registry", lambda p: load_factory("os:system"), E, r"'os:system' is not one of the study's factories.*Nothing was imported or run"),
    ("rebuild-malformed_entry", lambda p: rebuild({"factory": "calstudy.papers.selfcal.experiments:basin_experiment"}), E, r"must be an object with a 'factory' string and a 'kwargs' object"),
    ("rebuild-unknown_kwarg", lambda p: rebuild({"factory": "calstudy.papers.selfcal.experiments:basin_experiment", "kwargs": {"n_trial": 3}}), E, r"keyword arguments \['n_trial'\] do not fit its signature"),
    # notebook parameters
    ("check_parameters-06_n_trials_negative", lambda p: check_parameters("06_handeye_your_cell", NB06 | {"n_trials": -5}), E, r"notebook 06_handeye_your_cell parameters: n_trials = -5: must be >= 0"),
    ("check_parameters-06_sigma_negative", lambda p: check_parameters("06_handeye_your_cell", NB06 | {"sigma_rot_rad": -0.001}), E, r"sigma_rot_rad = -0\.001: must be >= 0"),
]


@pytest.mark.parametrize(("make", "error", "match"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_refused(tmp_path, make, error, match):
    from calstudy.handeye.sphere_csv import read_sphere_measurements

    with pytest.raises(error, match=match):
        out = make(tmp_path)
        # the file cases return the path of the broken file: read it with its reader
        if hasattr(out, "suffix") and out.name in ("m.csv", "no_such.csv"):
            read_sphere_measurements(out)
        elif hasattr(out, "suffix") and out.name in ("p.csv", "none.csv"):
            read_pose_list(out)
        elif hasattr(out, "suffix") and out.suffix == ".toml":
            load_robot(out)


def test_catalogue_size():
    assert len(CASES) >= 80 and len({c[0] for c in CASES}) == len(CASES)


# ----------------------------------------------------------------------------------------------
# good files still read: spreadsheet exports and declared units


def test_spreadsheet_exports_and_declared_units_read(tmp_path):
    ref = spc.read_sphere_measurements(_csv(tmp_path, _sphere_rows(), "ref.csv"))
    bom = spc.read_sphere_measurements(_csv(tmp_path, _sphere_rows(), "bom.csv", "utf-8-sig"))
    np.testing.assert_allclose(bom.flange2base, ref.flange2base)
    semi = _csv(tmp_path, [ln.replace(",", ";") for ln in _sphere_rows()], "semi.csv")
    np.testing.assert_allclose(spc.read_sphere_measurements(semi).centres, ref.centres)
    header = "id,group,x_m,y_m,z_m,a_rad,b_rad,c_rad,sx_mm,sy_mm,sz_mm"
    lines = _sphere_rows(header, angle=np.pi / 180, length=1e-3)
    declared = spc.read_sphere_measurements(_csv(tmp_path, lines, "declared.csv"))
    np.testing.assert_allclose(declared.flange2base, ref.flange2base, atol=1e-5)


def test_misfit_is_flagged_by_default():
    from calstudy import CalibrationWarning

    with pytest.warns(CalibrationWarning, match="chi2/dof"):
        est = he.sphere_handeye_ml(ALL, MOVED, 0.02, S2F)
    assert est.fit is not None and est.fit.too_large and est.flags
    good = he.sphere_handeye_ml(ALL, CENTRES, 0.02, S2F, misfit="raise")
    assert good.fit.ok and not good.flags


# ----------------------------------------------------------------------------------------------
# property test: random finite input of the right shapes gives finite output or CalibrationError
#
# Coverage of the public functions of core, models and estimators (function -> property test):
#   core.circles       fit_circle_2d ................................... point_fitters
#   core.geometry      euler_zyx_to_matrix, project_to_so3, matrix_to_euler_zyx  rotation_converters
#   core.stats         finite_samples, round_to_uncertainty, rmse, trial_values,
#                      interval_level, median_ranks, median_interval, median_and_spread,
#                      lilliefors_test(s) ................................... stats
#   core.verdicts      replication_rate, judge, judge_controls .............. verdicts
#   models.kinematics  Robot.fk, fk_many, jacobian, ik, parameters, with_parameters,
#                      random_configurations ................................ robot
#   models.reach       reach_bound, ReachBound.excess, margin_mm, unreachable .... robot
#   models.optics      coc_radius_mm, coc_radius_far_mm, coc_radius_px ..... circle_of_confusion
#   models.exposure    expose, fuse_exposures .............................. exposure, fusion
#   models.stereo      StereoRig.from_left2right ........................... stereo_rig
#   estimators.fitting fit_rigid, fit_rotation, fit_sphere .................. point_fitters
#                      fit_homography, homography_to_pose, solve_pnp ........ homography_and_pnp
#   handeye.sphere     sphere_handeye, sphere_handeye_ml, sphere_handeye_crb  sphere_handeye
#   estimators.axxb    opencv_handeye ....................................... opencv_handeye
#   handeye.calibrate  calibrate_handeye .................................... calibrate_handeye
#   estimators.workpiece rps_frame_so3, rps_frame_penalty, rps_frame_batch .. rps_frames
#                      check_datums, rps_equations, orthogonality ........... workpiece_equations
#   estimators.binocular triangulate, triangulate_sets, ray_gap ............. stereo_triangulation
#                      with_virtual, distances_to_p7, layout_problem, solve_calibrator_layout,
#                      modify_observed_error(s), motion_axes,
#                      preliminary_handeye, correct_transformation .......... binocular_calibrator
#   estimators.stereo_views make_view; StereoRig.triangulate ................ stereo_triangulation
#   estimators.sfm     pnp_pose ............................................. stereo_triangulation
#                      image_graph, cluster_images .......................... bundle
#   estimators.bundle  bundle_adjust, refine_camera_pose .................... bundle
#   estimators.icp     weighted_icp ......................................... weighted_icp
#   estimators.coc     rectify_coc, rectify_cocs, rectify_coc_reference, image_gradients,
#                      detect_centre, detect_centres ........................ coc
# Not in a property test (their bad inputs are in the catalogue above or in the module's tests):
#   sfm.reconstruct_cluster, splice_clusters, reconstruct_markers (need a simulated scene of many
#   views; tests/papers/dualarm); verdicts.not_testable, check_null_control, oracle_gate (take
#   verdicts and words, no numbers); models.robots.perturb_robot and pose_errors; and the
#   readers, schemas, caches and paths of core (files and names, not numbers). The remaining
#   geometry helpers, core.estimation's solvers, the other hand-eye helpers, models.sensors,
#   models.targets, the rendering of models.optics, models.urdf, the stereo triangulation and
#   the overflow of values near 1e300 are in tests/test_properties.py.

_FLOATS = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False, width=64)


def _arrays(shape):
    return hnp.arrays(np.float64, shape, elements=_FLOATS)


def _finite(out):
    """Every number in ``out`` (arrays, numbers, tuples, lists, dataclass fields) is finite."""
    if hasattr(out, "covariance") and hasattr(out, "camera2mount"):  # HandEyeResult
        parts = [out.camera2mount, out.target2mount, out.covariance]
    elif isinstance(out, estimation.Estimate):
        parts = [out.value, out.params] + ([out.covariance] if out.covariance is not None else [])
    elif isinstance(out, tuple | list):
        parts = list(out)
    elif dataclasses.is_dataclass(out) or isinstance(out, reach.ReachBound):
        parts = list(vars(out).values())
    else:
        parts = [out]
    nested = [v for v in parts if isinstance(v, tuple | list) or dataclasses.is_dataclass(v)]
    plain = [v for v in parts if not any(v is w for w in nested) and isinstance(v, float | int | np.ndarray | np.number)]
    return all(_finite(v) for v in nested) and all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in plain)


def _check(fn, *args, **kw):
    try:
        out = fn(*args, **kw)
    except CalibrationError:
        return
    assert _finite(out), f"{fn.__name__} returned a non-finite value"


def _pose(v):
    return geo.make_transform(geo.rotvec_to_matrix(np.clip(v[:3], -3, 3)), v[3:])


@PROFILE
@given(st.integers(1, 8).flatmap(lambda n: st.tuples(_arrays((n, 3)), _arrays((n, 3)))))
def test_property_point_fitters(data):
    a, b = data
    _check(ft.fit_rigid, a, b)
    _check(ft.fit_rotation, a, b)
    _check(ft.fit_sphere, a)
    _check(fit_circle_2d, a[:, :2])
    _check(fit_circle_2d, a[:, :2], method="geometric")
    if len(a) >= 4:  # the same points with the first one moved to the centroid of the others
        _check(fit_circle_2d, np.r_[a[1:, :2], a[1:, :2].mean(axis=0, keepdims=True)], "geometric")


@PROFILE
@given(st.integers(1, 7).flatmap(lambda n: st.tuples(_arrays((n, 2)), _arrays((n, 2)), _arrays((n, 3)))))
def test_property_homography_and_pnp(data):
    xy, uv, obj = data
    _check(ft.fit_homography, xy, uv + 320.0)
    try:
        h = ft.fit_homography(xy, uv + 320.0)
    except CalibrationError:
        h = np.eye(3) + np.diag(xy[0].tolist() + [0.0]) * 1e-3
    _check(ft.homography_to_pose, h, K)
    _check(ft.solve_pnp, obj, uv + 320.0, K)


@PROFILE
@given(_arrays((3, 3)), _arrays((6,)))
def test_property_rps_frames(datums, nominal):
    init = _pose(nominal * 1e-2)
    _check(wp.rps_frame_so3, datums, DATUMS_WORK, init)
    _check(wp.rps_frame_penalty, datums, DATUMS_WORK, init, max_nfev=200)
    _check(wp.rps_frame_batch, datums[None], DATUMS_WORK, init)


@PROFILE
@given(st.integers(2, 8).flatmap(lambda n: st.tuples(_arrays((n, 6)), _arrays((n, 3)))), st.floats(1e-3, 1.0))
def test_property_sphere_handeye(data, sigma):
    poses, centres = data
    flange = np.stack([_pose(v) for v in poses])
    _check(he.sphere_handeye_ml, flange, centres, sigma, S2F, misfit="off")
    _check(he.sphere_handeye_crb, flange, centres, sigma, S2F, X_B)
    half = max(len(flange) // 2, 1)
    _check(he.sphere_handeye, flange[:half], centres[:half], flange[half:], centres[half:])


@settings(PROFILE, max_examples=10)
@given(st.integers(3, 5).flatmap(lambda n: st.tuples(_arrays((n, 6)), _arrays((n, 6)))))
def test_property_calibrate_handeye(data):
    robot, camera = data
    _check(
        calibrate_handeye,
        np.stack([_pose(v) for v in robot]),
        np.stack([_pose(v) for v in camera]),
        check_convention="off",
    )


_ANY = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False, width=64)


@PROFILE
@given(_arrays((5,)), _arrays((5,)), _arrays((5,)), _arrays((3, 3)))
def test_property_rotation_converters(a, b, c, m):
    _check(geo.euler_zyx_to_matrix, a, b, c)
    _check(geo.euler_zyx_to_matrix, float(a[0]), float(b[0]), float(c[0]))
    _check(geo.project_to_so3, m)
    try:
        r = geo.project_to_so3(m)
    except CalibrationError:
        r = np.eye(3)
    _check(geo.matrix_to_euler_zyx, r)


@PROFILE
@given(_arrays((4,)) , _ANY, _ANY, _ANY, _ANY)
def test_property_circle_of_confusion(d_b, d_a, focal, f_number, pitch):
    _check(optics.coc_radius_far_mm, d_b, d_a, focal, f_number)
    _check(optics.coc_radius_mm, d_b, d_a, focal, f_number)
    _check(optics.coc_radius_px, d_b, d_a, focal, f_number, pitch)


@PROFILE
@given(
    st.lists(hnp.arrays(np.float64, (6, 6), elements=st.floats(-0.5, 1.5, width=64)), min_size=1, max_size=3),
    st.floats(-1.0, 3.0),
    st.floats(-1.0, 3.0),
    st.floats(-0.1, 1.0),
)
def test_property_fusion(images, wc, we, sigma):
    _check(exposure.fuse_exposures, images, wc, we, sigma)


@PROFILE
@given(_ANY, _ANY, _ANY, _ANY, st.floats(-100.0, 1e3), st.integers(0, 17))
def test_property_exposure(time_ms, peak, background, read_noise, gain, bits):
    """An exposure is an image of integers in [0, 2**bits - 1], or refused."""
    try:
        out = exposure.expose(DOT, time_ms, peak, background, read_noise, gain, np.random.default_rng(0), bits)
    except CalibrationError:
        return
    assert out.min() >= 0 and out.max() <= 2**bits - 1


@settings(PROFILE, max_examples=20)
@given(st.integers(3, 6).flatmap(lambda n: st.tuples(_arrays((n, 6)), _arrays((n, 6)))), st.sampled_from(sorted(he.OPENCV_METHODS)))
def test_property_opencv_handeye(data, method):
    robot, camera = data
    _check(he.opencv_handeye, np.stack([_pose(v) for v in robot]), np.stack([_pose(v) for v in camera]), method)
    # the same poses as pure translations and as rotations about one axis are always refused
    flange = np.stack([_pose(v) for v in robot])
    for poses in (
        geo.make_transform(np.broadcast_to(flange[0, :3, :3], flange[:, :3, :3].shape), flange[:, :3, 3]),
        geo.make_transform(geo.rotvec_to_matrix(np.outer(np.clip(robot[:, 0], -3, 3), [0.0, 0.6, 0.8])), flange[:, :3, 3]),
    ):
        with pytest.raises(CalibrationError, match="pure translations|turn about one axis"):
            he.opencv_handeye(poses, _camera_poses(poses), method)


@PROFILE
@given(st.integers(1, 4).flatmap(lambda n: st.tuples(_arrays((n, 2, 3)), _arrays((2, 3)))))
def test_property_compensation(data):
    readings, offset = data
    _check(compensation.compensate, readings, offset)


@PROFILE
@given(_arrays((3, 3)), _arrays((3,)))
def test_property_stereo_rig(rotation, translation):
    """A stereo rig with any finite extrinsic is one of finite rigid transforms, or is
    refused."""
    try:
        rig = _stereo_rig(rotation, translation)
    except CalibrationError:
        return
    geo.check_transform("left2right", rig.left2right)
    geo.check_transform("right2left", rig.right2left)


@PROFILE
@given(st.integers(0, 8).flatmap(lambda n: st.tuples(_arrays((n,)), _arrays((n, 3)))), st.sampled_from([0.95, 0.5, 0.0, 1.0, -1.0, 2.0]), _ANY)
def test_property_stats(data, level, x):
    s, m = data
    _check(stats.finite_samples, "x", s)
    _check(stats.round_to_uncertainty, x, float(s[0]) if len(s) else 0.0)
    _check(stats.rmse, s)
    _check(stats.rmse, m, axis=0)
    _check(stats.trial_values, "s", s)
    _check(stats.interval_level, level)
    _check(stats.median_ranks, len(s), level)
    _check(stats.median_interval, s, level)
    _check(stats.median_and_spread, s, level)
    _check(stats.lilliefors_test, s)
    _check(stats.lilliefors_tests, m)
    _check(stats.lilliefors_test, np.zeros(len(s)))  # no spread


@PROFILE
@given(
    st.integers(0, 40).flatmap(lambda n: st.tuples(_arrays((n,)), _arrays((n,)), _arrays((n,)))),
    st.sampled_from(verdicts.KINDS), st.sampled_from(verdicts.DIRECTIONS), _ANY, _ANY,
    st.sampled_from([0.95, 0.0, 1.0, -1.0]),
)
def test_property_verdicts(data, kind, direction, published, null, level):
    """A verdict's figures are finite (or NaN where the verdict says untestable), or refused."""
    s, base, oracle = data
    _check(verdicts.replication_rate, s, null, direction)
    rule = {"kind": kind, "direction": direction, "null": null, "bound": published, "min_trials": 1}
    for fn, args in ((verdicts.judge, (s,)), (verdicts.judge_controls, (s, base, oracle))):
        try:
            v = fn(*args, published=published, **({"baseline": base} | rule if fn is verdicts.judge else rule))
        except CalibrationError:
            continue
        v = v[0] if isinstance(v, tuple) else v
        assert v.verdict in verdicts.VERDICTS, v
        if v.verdict != "not testable":
            assert np.isfinite([v.median, v.ci_low, v.ci_high, v.effect_median, v.replication_rate]).all(), v


@PROFILE
@given(st.integers(1, 6).flatmap(lambda n: st.tuples(_arrays((n, 2)), _arrays((n, 2)), _arrays((n, 3)), _arrays((n, 3)))))
def test_property_stereo_triangulation(data):
    ul, ur, p, q = data
    for uv_l, uv_r in ((ul + 640.0, ur + 512.0), (ul, ul), (np.zeros_like(ul), np.zeros_like(ur))):
        _check(bino.triangulate, RIG, uv_l, uv_r, 1e9)
        _check(bino.triangulate_sets, RIG, uv_l[None], uv_r[None], 1e9)
        _check(bino.ray_gap, uv_l * 1e-3, uv_r * 1e-3, RIG.rotation, RIG.translation)
        _check(RIG.triangulate, uv_l, uv_r)
        _check(sv.make_view, np.arange(len(ul)), uv_l, uv_r)
        _check(sfm.pnp_pose, p, uv_l, RIG.left)
    _check(bino.ray_gap, p, q, RIG.rotation, RIG.translation)  # wrong shapes


@PROFILE
@given(_arrays((6, 3)), _arrays((7,)), _arrays((6,)), st.integers(2, 4).flatmap(lambda n: st.tuples(_arrays((n, 6)), _arrays((n, 6)))))
def test_property_binocular_calibrator(points, distances, start, poses):
    _check(bino.with_virtual, points)
    _check(bino.distances_to_p7, bino.with_virtual(points))
    _check(bino.distances_to_p7, np.zeros((8, 3)))
    assert isinstance(bino.layout_problem(distances), str)
    _check(bino.solve_calibrator_layout, np.abs(distances), start)
    pairs = bino.all_pairs(6)
    _check(bino.modify_observed_error, points, pairs, np.abs(distances[0]) * np.ones(len(pairs)))
    _check(bino.modify_observed_errors, points[None], pairs, distances[0] * np.ones(len(pairs)))
    _check(bino.modify_observed_error, np.zeros((6, 3)), pairs, np.ones(len(pairs)))
    robot, sensor = (np.stack([_pose(v) for v in x]) for x in poses)
    _check(bino.motion_axes, robot)
    _check(bino.preliminary_handeye, robot, sensor)
    layout = bino.with_virtual(points)
    seen = np.broadcast_to(layout, (len(robot), 8, 3))
    _check(bino.correct_transformation, robot, S2F, seen, seen + points[0] * 1e-3)
    try:
        he.check_rotation_diversity(robot, bino.MIN_MOVE_ROTATION)
    except CalibrationError:
        pass


@PROFILE
@given(_arrays((3, 3)), _arrays((3, 3)), _arrays((6,)))
def test_property_workpiece_equations(datums, rotation, pose):
    _check(wp.check_datums, datums, DATUMS_WORK)
    _check(wp.rps_equations, _pose(pose), datums, DATUMS_WORK)
    _check(wp.orthogonality, rotation)


@PROFILE
@given(st.integers(0, 8).flatmap(lambda n: st.tuples(_arrays((n, 3)), _arrays((n, 3)))), st.sampled_from([20.0, 0.0, -1.0]), st.sampled_from([2.0, 0.0, -1.0]))
def test_property_weighted_icp(data, z_weight, max_pair):
    moving, reference = data
    for a, b in ((moving * 1e-2, reference * 1e-2), (moving * 1e-2, moving * 1e-2 + 0.01), (np.zeros_like(moving), np.zeros_like(moving))):
        try:
            out = icp.weighted_icp(a, b, z_weight=z_weight, max_pair_mm=max_pair, max_iterations=20)
        except CalibrationError:
            continue
        assert np.isfinite(out.transform).all() and np.isfinite(out.rms_mm)


@PROFILE
@given(
    hnp.arrays(np.float64, st.tuples(st.integers(0, 24), st.integers(0, 24)), elements=st.floats(0.0, 1.0, width=64)),
    st.sampled_from([0.0, 0.34, 1.0, 2.5, 1e3, 1e8, -1.0]),
    st.sampled_from([(0.25, 0.5), (0.5, 0.25), (-1.0, 2.0), (0.0, 0.0)]),
)
def test_property_coc(image, delta, thresholds):
    """Rectification and centre detection on any small image: a finite image or centre, or
    refused (an oversized window is refused before its allocation)."""
    _check(coc.rectify_coc, image, delta)
    _check(coc.rectify_coc_reference, image, delta)
    _check(coc.rectify_cocs, [image], [delta])
    _check(coc.image_gradients, image)
    for img in (image, DOT, np.zeros_like(DOT)):
        _check(coc.detect_centre, img, (0, 0), *thresholds)
        _check(coc.detect_centres, [img], [(0, 0)], *thresholds)


KR16 = load_robot("kuka_kr16_2")


@settings(PROFILE, max_examples=20)
@given(_arrays((6,)), st.integers(0, 4).flatmap(lambda n: _arrays((n, 6))), _arrays((30,)), _arrays((6,)), st.sampled_from([0.1, 0.0, -1.0, 10.0]))
def test_property_robot(q, many, dp, pose, margin):
    q, many = q * 1e-2, many * 1e-2
    _check(KR16.fk, q)
    _check(KR16.fk_many, many)
    _check(KR16.jacobian, q)
    _check(KR16.ik, KR16.fk(q), q * 0.9)
    _check(KR16.ik, _pose(pose), q, max_iter=20)
    _check(KR16.with_parameters, KR16.parameters() + dp * 1e-2)
    _check(KR16.random_configurations, np.random.default_rng(0), len(many), margin)
    for vec in (KR16.parameters() + dp, KR16.parameters() * 0.0):
        try:
            robot = KR16.with_parameters(vec)
        except CalibrationError:
            continue
        _check(reach.reach_bound, robot)
        bound = reach.reach_bound(robot)
        _check(bound.excess, _pose(pose))
        _check(bound.margin_mm)
        assert isinstance(bound.unreachable(_pose(pose)), bool)


BA_POINTS = CUBE[:, [0, 1, 2]] * 0.5 + [0.0, 0.0, 850.0]
BA_POSES = np.stack([np.eye(4), geo.make_transform(geo.euler_zyx_to_matrix(1.0, 0.5, 0.0), [5.0, 0.0, 0.0])])


def _views(world2cam, points, noise):
    """Views of every marker from each left-camera pose, with pixel noise ``noise`` ``(2, M, 2)``."""
    views = []
    for w in world2cam:
        uv_left, uv_right = RIG.project(geo.apply(w, points))
        views.append(sv.make_view(np.arange(len(points)), uv_left + noise[0], uv_right + noise[1]))
    return views


@settings(PROFILE, max_examples=15)
@given(_arrays((6, 3)), _arrays((2, 6)), _arrays((2, 6, 2)), st.sampled_from([1.0, 0.0, -1.0]))
def test_property_bundle(points, poses, noise, sigma):
    """Bundle adjustment and pose refinement of random markers in front of the rig: finite
    poses, points and residuals, or refused."""
    pts = points * [0.2, 0.2, 0.05] + [0.0, 0.0, 850.0]
    w2c = np.stack([_pose(v * 1e-3) for v in poses])
    try:
        views = _views(w2c, pts, noise * 1e-3)
    except CalibrationError:
        return
    kw = {"sigma_px": sigma, "sigma_mm": sigma}
    _check(bundle.bundle_adjust, RIG, views, w2c, pts + noise[0, :, :1] * 1e-3, fixed_view=0, max_nfev=20, **kw)
    _check(bundle.bundle_adjust, RIG, views, w2c, np.zeros_like(pts), fixed_view=0, max_nfev=20, **kw)
    _check(bundle.refine_camera_pose, RIG, views[1], pts, w2c[1], **kw)
    _check(sfm.cluster_images, sfm.image_graph(views), 3)


# ----------------------------------------------------------------------------------------------
# data stays data: a tampered results folder or trial cache runs nothing


class _Command:
    """Pickles as a call of ``os.system(command)``: what a hostile pickle file holds."""

    def __init__(self, command):
        self.command = command

    def __reduce__(self):
        import os

        return (os.system, (self.command,))


def test_tampered_experiments_json_runs_nothing(tmp_path, monkeypatch):
    """An experiments.json naming a function outside the registry is refused before any import:
    the command it names does not run, whatever module it names."""
    import json
    import sys

    marker = tmp_path / "marker"
    monkeypatch.chdir(tmp_path)
    entries = [
        {"factory": "subprocess:run", "kwargs": {"args": ["touch", str(marker)]}},
        {"factory": "os:system", "kwargs": {"command": f"touch {marker}"}},
        {"factory": "calstudy_not_a_module:run", "kwargs": {}},
        {"factory": "calstudy.papers.selfcal.experiments:os", "kwargs": {}},
    ]
    (tmp_path / "experiments.json").write_text(json.dumps({"seed": 1, "experiments": {"x": entries[0]}}))
    record = json.loads((tmp_path / "experiments.json").read_text())
    with pytest.raises(CalibrationError, match="'subprocess:run' is not one of the study's factories"):
        rebuild(record["experiments"]["x"])
    for entry in entries[1:]:
        with pytest.raises(CalibrationError, match="is not one of the study's factories"):
            rebuild(entry)
    assert not marker.exists()
    assert "calstudy_not_a_module" not in sys.modules


def test_tampered_trial_cache_runs_nothing(tmp_path):
    """A cache file replaced by a hostile pickle, or by JSON naming a type, is refused naming the
    file; a pickle left beside the JSON records is never read; nothing runs."""
    import pickle

    from mc_trials import experiment

    from calstudy.core.montecarlo import run

    marker = tmp_path / "marker"
    cache = tmp_path / "cache"
    exp = experiment("tamper", n_trials=2, points=[{"sigma": 0.1}])
    first = run(exp, 3, n_jobs=1, cache_dir=cache, progress=False)
    files = sorted(cache.rglob("trial-*.json"))
    assert len(files) == 2
    # a pickle beside the records (the former format) is ignored
    (files[0].parent / "trial-000000.pkl").write_bytes(pickle.dumps(_Command(f"touch {marker}")))
    again = run(exp, 3, n_jobs=1, cache_dir=cache, progress=False)
    assert again.equals(first) and not marker.exists()
    # a record replaced by a pickle, or by JSON asking for another type, is refused
    original = files[0].read_bytes()
    assert b'"numpy":"<f8"' in original
    for payload, match in (
        (pickle.dumps(_Command(f"touch {marker}")), "is not a JSON trial record"),
        (original.replace(b'"numpy":"<f8"', b'"numpy":"|O"', 1), "is not a scalar the trial cache stores"),
        (b'{"key": {}, "trial": 0}', "is not a trial record"),
    ):
        files[0].write_bytes(payload)
        with pytest.raises(CalibrationError, match=f"trial cache file .*{files[0].name}.* {match}"):
            run(exp, 3, n_jobs=1, cache_dir=cache, progress=False)
    assert not marker.exists()


def test_degenerate_handeye_is_refused_before_opencv_prints(capfd):
    """OpenCV's Tsai prints its failure on a repeated pose to stderr and returns a pose; the
    wrapper refuses the motions first, so nothing reaches stderr."""
    for method in sorted(he.OPENCV_METHODS):
        with pytest.raises(CalibrationError, match="no pair of the 3 poses rotates"):
            he.opencv_handeye(CELL_A[[0, 0, 0]], CELL_B[[0, 0, 0]], method)
    assert capfd.readouterr().err == ""
