"""The dualarm station and the paper's numbers read from data/dualarm/."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.core import geometry as geo
from calstudy.core.paths import data_path
from calstudy.papers.dualarm.scenario import load_published, load_scenario


def test_scenario_holds_the_paper_tables(scenario):
    assert scenario.markers.xyz.shape == (14, 3)
    assert np.bincount(scenario.markers.group_index).tolist() == [8, 6]
    # Table A2, base-to-base as rotation vector and translation
    rv = geo.matrix_to_rotvec(scenario.calibration.base2_to_base1[:3, :3])
    np.testing.assert_allclose(rv, [-7.582e-3, -3.056e-3, -0.746], atol=1e-12)
    np.testing.assert_allclose(
        scenario.calibration.base2_to_base1[:3, 3], [807.320, -1339.438, 20.040]
    )
    # the two world-to-base transforms agree with base2_to_base1
    np.testing.assert_allclose(
        scenario.world2base[0],
        scenario.calibration.base2_to_base1 @ scenario.world2base[1],
        atol=1e-9,
    )
    assert scenario.rig.left.width == 1280 and scenario.rig.left.height == 1024
    assert scenario.spheres.radius["A"] == pytest.approx(50.807 / 2)


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
    assert pub.table2.overall == 0.100
    assert pub.table3.methods[-1] == "coded markers"
    assert [r[:2] for r in pub.icp.rows] == [(1, "A"), (1, "B"), (2, "A"), (2, "B")]


def test_overrides_are_validated_as_the_file_would_be(scenario):
    own = load_scenario(overrides={"detection.sigma_px": 0.05, "camera.fx_px": 2400.0})
    assert own.detection.sigma_px == 0.05 and scenario.detection.sigma_px == 0.0328
    assert own.rig.left.fx == 2400.0 and scenario.rig.left.fx == 2000.0  # derived from it
    assert own.detection.provenance["sigma_px"].kind == "derived"  # the ledger stays beside it
    with pytest.raises(
        CalibrationError,
        match=r"scenario\.toml: detection\.sigma_px = 0\.5: outside its plausible range",
    ):
        load_scenario(overrides={"detection.sigma_px": 0.5})
    with pytest.raises(
        CalibrationError, match=r"override 'detection\.sigma': 'detection\.sigma' names no input"
    ):
        load_scenario(overrides={"detection.sigma": 0.05})


def test_oracle_and_drift_copies_change_what_they_say(scenario):
    quiet = scenario.noise_free()
    assert quiet.detection.sigma_px == 0.0 and quiet.robot.repeat_sigma_rad == 0.0
    assert quiet.robot.drift_step_mm == 0.0 and quiet.robot.drift_step_rad == 0.0
    assert scenario.rig is scenario.rig and quiet.rig is not scenario.rig  # built again
    assert quiet.markers is scenario.markers  # a table not changed is shared
    twice = scenario.with_drift_scale(2.0)
    assert twice.robot.drift_step_mm == 2.0 * scenario.robot.drift_step_mm == 0.1
    assert twice.robot.drift_step_rad == np.deg2rad(0.01) * 2.0
    assert twice.robot.repeat_sigma_mm == scenario.robot.repeat_sigma_mm
    assert twice.with_drift_scale(0.5).robot.drift_step_rad == np.deg2rad(0.01)
