"""Fixtures of the selfcal tests: the paper's scenario, a noise-free one and its measurements."""

from __future__ import annotations

import numpy as np
import pytest

from calstudy.core.schema import with_inputs
from calstudy.papers.selfcal.scenario import load_scenario
from calstudy.papers.selfcal.simulate import draw_placements, draw_station, simulate


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


@pytest.fixture(scope="module")
def quiet(scenario):
    """The scenario without any noise (scanner, repeatability and tracker exact) and without the
    unmodelled joint compliance: the true system lies in the model class."""
    zero = ("scanner.sigma_point_mm", "repeatability.sigma_mm", "tracker.u0_mm")
    zero += ("tracker.u1_mm_per_m", "compliance.scale")
    return with_inputs(scenario, dict.fromkeys(zero, 0.0))


@pytest.fixture(scope="module")
def noise_free(quiet):
    rng = np.random.default_rng(5)
    station = draw_station(quiet, rng)
    meas = simulate(quiet, station, station.spheres_base, 6, rng)
    val = simulate(quiet, station, draw_placements(quiet, 10, rng), 1, rng)
    return station, meas, val
