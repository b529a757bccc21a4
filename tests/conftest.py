"""Session fixtures shared by test modules."""

from __future__ import annotations

import pytest
from booksite import CiRun, run_ci_notebooks


@pytest.fixture(scope="session")
def ci_runs(tmp_path_factory) -> dict[str, CiRun]:
    """Every notebook executed once at its CI values, two at a time: ``{stem: CiRun}``.

    ``test_notebooks.py`` checks each run, ``test_book.py`` builds the book from them.
    """
    return run_ci_notebooks(tmp_path_factory.mktemp("ci-runs"))
