"""The dualarm station of ``data/dualarm/scenario.toml``, noisy and noise-free."""

from __future__ import annotations

import pytest

from calstudy.papers.dualarm.scenario import load_scenario


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


@pytest.fixture(scope="module")
def quiet(scenario):
    return scenario.noise_free()
