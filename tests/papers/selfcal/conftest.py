"""Fixtures of the selfcal tests: the paper's scenario, a noise-free one and its measurements."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.papers.selfcal.simulate import draw_placements, draw_station, simulate


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


@pytest.fixture(scope="module")
def quiet(scenario):
    """The scenario without any noise (scanner, repeatability and tracker exact) and without the
    unmodelled joint compliance: the true system lies in the model class."""
    return scenario.with_(
        sigma_point_mm=0.0, repeatability_mm=0.0, tracker=(0.0, 0.0, 2.0), compliance_scale=0.0
    )


@pytest.fixture(scope="module")
def noise_free(quiet):
    rng = np.random.default_rng(5)
    station = draw_station(quiet, rng)
    meas = simulate(quiet, station, station.spheres_base, 6, rng)
    val = simulate(quiet, station, draw_placements(quiet, 10, rng), 1, rng)
    return station, meas, val
