"""Inputs derived from the paper's stated sensor accuracy: the scenario holds what the code
computes, and the derivations agree with the simulation they feed."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.estimators.fitting import fit_sphere
from calstudy.papers.dualarm import derived, simulate


def _entry(scn, key):
    table, name = key.split(".")
    return getattr(getattr(scn, table), name), getattr(scn, table).provenance[name]


def test_the_scenario_holds_the_derived_values_and_ranges(scenario):
    computed = derived.derived_inputs(scenario)
    assert set(computed) == {
        "detection.sigma_px",
        "detection.marker_sigma_mm",
        "sensor.sphere_fit_sigma_mm",
    }
    for key, entry in computed.items():
        value, prov = _entry(scenario, key)
        assert prov.kind == "derived", key
        assert value == entry["value"], key
        assert prov.range == entry["range"], key
        assert prov.range[0] < value < prov.range[1], key


def test_the_centre_noise_gives_the_stated_depth_error_by_triangulation(scenario):
    """sigma_px in all four image coordinates of a marker at the working distance gives back the
    stated 0.029 mm as the depth error of the rig's own triangulation."""
    rig = scenario.rig
    point = rig.aim_point(scenario.sensor.working_distance_mm)
    uv_l, uv_r = rig.project(point[None, :])
    rng = np.random.default_rng(4)
    n = 20000
    sigma = derived.marker_sigma_px(scenario, scenario.sensor.stated_accuracy_mm)
    xyz = rig.triangulate(
        uv_l + rng.normal(0, sigma, (n, 2)), uv_r + rng.normal(0, sigma, (n, 2))
    )
    assert np.std(xyz[:, 2]) == pytest.approx(scenario.sensor.stated_accuracy_mm, rel=0.1)


def test_the_view_error_gives_the_stated_diameter_error(scenario):
    """Scans of sphere A with the derived per-view error alone: the mean absolute error of the
    fitted diameters is the stated accuracy."""
    quiet = scenario.replace({"sensor.point_sigma_mm": 0.0})
    r = scenario.spheres.radius["A"]
    centre = np.array([0.0, 0.0, 0.0])
    cam = geo.look_at(np.array([0.0, 0.0, 500.0]), centre, up=np.array([0.0, 1.0, 0.0]))
    rng = np.random.default_rng(7)
    errors = [2.0 * (fit_sphere(simulate.scan_sphere(quiet, centre, r, cam, rng))[1] - r)
              for _ in range(400)]
    assert np.mean(np.abs(errors)) == pytest.approx(scenario.sensor.stated_accuracy_mm, rel=0.12)


def test_cap_points_counts_the_pixels_of_the_visible_cap(scenario):
    """Sphere B at 500 mm with f = 2000 px: a disc of radius r sin(70 deg) f / Z pixels."""
    r = scenario.spheres.radius["B"]
    expected = np.pi * (r * np.sin(np.radians(70.0)) * 2000.0 / 500.0) ** 2
    assert derived.cap_points(scenario, r) == pytest.approx(expected)
    assert derived.cap_points(scenario, 2 * r) == pytest.approx(4 * expected)


@pytest.mark.parametrize("bad", [0.0, -0.029, float("nan")])
def test_a_derivation_refuses_a_bad_accuracy(scenario, bad):
    with pytest.raises(CalibrationError, match="accuracy_mm"):
        derived.marker_sigma_px(scenario, bad)
    with pytest.raises(CalibrationError, match="diameter_error_mm"):
        derived.sphere_fit_sigma_mm(bad)
