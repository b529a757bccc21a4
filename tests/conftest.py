"""Test-session settings and fixtures shared by every test module."""

from __future__ import annotations

import pytest
from booksite import CiRun, run_ci_notebooks


def pytest_collection_modifyitems(config, items):
    """Full notebook reruns (marker ``verify``) run only when asked for with ``-m verify``
    (``make verify``), whatever other ``-m`` expression a run passes."""
    if "verify" in (config.option.markexpr or ""):
        return
    skip = pytest.mark.skip(reason="full rerun at the defaults: make verify")
    for item in items:
        if "verify" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def ci_runs(tmp_path_factory) -> dict[str, CiRun]:
    """Every notebook executed once at its CI values, two at a time: ``{stem: CiRun}``.

    ``test_notebooks.py`` checks each run, ``test_book.py`` builds the book from them.
    """
    return run_ci_notebooks(tmp_path_factory.mktemp("ci-runs"))
