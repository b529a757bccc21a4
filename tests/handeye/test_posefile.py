"""Pose-list CSV files: round trip in every rotation form, errors naming row and column."""

import numpy as np
import pytest
from support import handeye_cell as _cell

from calstudy import CalibrationError
from calstudy.handeye import calibrate as hp
from calstudy.handeye import posefile


@pytest.mark.parametrize("form", list(posefile.ROTATION_FORMS))
def test_pose_list_round_trip(tmp_path, form):
    cell = _cell(20)
    path = posefile.write_pose_list(
        tmp_path / "poses.csv",
        cell.flange2base,
        cell.target2camera,
        rotation=form,
        robot_convention="base2gripper",
        unit="m",
        comment="test cell",
    )
    poses = posefile.read_pose_list(path)
    assert poses.robot_convention == "base2gripper" and poses.robot_unit == "m"
    assert len(poses) == 15 and poses.ids[0] == 1
    res = hp.calibrate_handeye(**poses.arguments())
    ref = hp.calibrate_handeye(cell.flange2base, cell.target2camera)
    np.testing.assert_allclose(res.camera2flange, ref.camera2flange, atol=1e-6)


def test_pose_list_errors_name_row_and_column(tmp_path):
    cell = _cell(21)
    path = posefile.write_pose_list(tmp_path / "p.csv", cell.flange2base, cell.target2camera)
    lines = path.read_text().splitlines()
    cells = lines[3].split(",")
    cells[4] = "abc"
    lines[3] = ",".join(cells)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(CalibrationError, match=r"row 4, column 'flange2base_qw': 'abc'"):
        posefile.read_pose_list(tmp_path / "bad.csv")
    header = lines[0].replace("flange2base_x_mm", "flange2base_x_furlong")
    (tmp_path / "unit.csv").write_text("\n".join([header] + lines[1:]) + "\n")
    with pytest.raises(CalibrationError, match="no translation columns flange2base_x_<unit>"):
        posefile.read_pose_list(tmp_path / "unit.csv")
    header = lines[0].replace("target2camera", "camera2world")
    (tmp_path / "conv.csv").write_text("\n".join([header] + lines[1:]) + "\n")
    with pytest.raises(CalibrationError, match="camera poses by exactly one prefix"):
        posefile.read_pose_list(tmp_path / "conv.csv")
    # an id that is not an integer, named by its file line (below two comment lines)
    cells = lines[2].split(",")
    cells[0] = "2.5"
    text = "\n".join(["# a comment", "# another", lines[0], lines[1], ",".join(cells)])
    (tmp_path / "id.csv").write_text(text + "\n")
    with pytest.raises(CalibrationError, match=r"row 5, column 'id': 2\.5 is not an integer"):
        posefile.read_pose_list(tmp_path / "id.csv")


def test_example_pose_list_in_data_reads():
    from calstudy.core.paths import data_path

    poses = posefile.read_pose_list(data_path("handeye", "example_poses.csv"))
    res = hp.calibrate_handeye(**poses.arguments())
    assert len(res.flagged) == 1
