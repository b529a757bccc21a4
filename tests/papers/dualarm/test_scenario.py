"""The dualarm station and the paper's numbers read from data/dualarm/."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.core.paths import data_path
from calstudy.papers.dualarm.scenario import load_published, load_scenario


def test_scenario_holds_the_paper_tables(scenario):
    assert scenario.markers.shape == (14, 3)
    assert np.bincount(scenario.marker_group).tolist() == [8, 6]
    # Table A2, base-to-base as rotation vector and translation
    rv = geo.matrix_to_rotvec(scenario.base2_to_base1[:3, :3])
    np.testing.assert_allclose(rv, [-7.582e-3, -3.056e-3, -0.746], atol=1e-12)
    np.testing.assert_allclose(scenario.base2_to_base1[:3, 3], [807.320, -1339.438, 20.040])
    # the two world-to-base transforms agree with base2_to_base1
    np.testing.assert_allclose(
        scenario.world2base[0], scenario.base2_to_base1 @ scenario.world2base[1], atol=1e-9
    )
    assert scenario.rig.left.width == 1280 and scenario.rig.left.height == 1024
    assert scenario.sphere_radius["A"] == pytest.approx(50.807 / 2)


def test_scenario_missing_key_names_file_and_key(tmp_path):
    good = data_path("dualarm", "scenario.toml").read_text()
    bad = tmp_path / "scenario.toml"
    bad.write_text(good.replace("loss_rate = 0.1\n", ""))
    with pytest.raises(
        CalibrationError, match=r"scenario\.toml: detection\.loss_rate: missing \(required\)"
    ):
        load_scenario(bad)
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_scenario(tmp_path / "absent.toml")


def test_published_numbers():
    pub = load_published()
    assert pub.table2_overall == 0.100
    assert pub.table3_methods[-1] == "coded markers"
    assert [r[:2] for r in pub.icp_rows] == [[1, "A"], [1, "B"], [2, "A"], [2, "B"]]
