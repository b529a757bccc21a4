"""Spot checks of the committed Monte Carlo trial rows, without rerunning the notebooks.

Every notebook stores the rows of its experiments in ``results/<notebook>/trials_<name>.csv``
and, in ``experiments.json``, how to build each experiment again (a named factory and its
arguments). Here a few (point, trial) pairs of every experiment, chosen by the seed, are
recomputed with the engine and compared with the committed rows. The full rerun of every
notebook is ``make verify``.
"""

from __future__ import annotations

import json
import zlib

import numpy as np
import pandas as pd
import pytest

from calstudy.core.montecarlo import trial_rows
from calstudy.core.paths import RESULTS_DIR
from calstudy.io.runs import rebuild

#: the rows are stored with 10 significant digits; another machine's floating point (or BLAS)
#: moves the last ones, and ill-conditioned solves (a hand-eye from few poses) amplify that to
#: about 1e-6: the tolerance of the tables, one unit in the sixth digit
RTOL, ATOL = 2e-5, 1e-9
PICKS = 2


def _cases() -> list:
    cases = []
    for manifest in sorted(RESULTS_DIR.glob("*/experiments.json")):
        record = json.loads(manifest.read_text())
        for name in record["experiments"]:
            stem = manifest.parent.name
            cases.append(pytest.param(stem, name, id=f"{stem}:{name}"))
    return cases


def _same(fresh: pd.Series, stored: pd.Series, what: str) -> None:
    if pd.api.types.is_numeric_dtype(fresh) and pd.api.types.is_numeric_dtype(stored):
        np.testing.assert_allclose(
            fresh.to_numpy(float), stored.to_numpy(float), rtol=RTOL, atol=ATOL,
            equal_nan=True, err_msg=what,
        )
    else:
        assert fresh.astype(str).tolist() == stored.astype(str).tolist(), what


@pytest.mark.parametrize(("stem", "name"), _cases())
def test_committed_trials_recompute(stem, name):
    record = json.loads((RESULTS_DIR / stem / "experiments.json").read_text())
    entry, seed = record["experiments"][name], record["seed"]
    exp = rebuild(entry)
    assert exp.name == name
    assert (exp.n_trials, len(exp.points)) == (entry["n_trials"], entry["points"])
    stored = pd.read_csv(RESULTS_DIR / stem / f"trials_{name}.csv")
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    for _ in range(PICKS):
        p, t = int(rng.integers(len(exp.points))), int(rng.integers(exp.n_trials))
        fresh = trial_rows(exp, seed, p, t)
        mask = stored["trial"] == t
        for key, value in exp.points[p].items():
            col = stored[key]
            mask &= np.isclose(col, value) if pd.api.types.is_numeric_dtype(col) else col == value
        rows = stored[mask].reset_index(drop=True)
        where = f"{stem} {name} point {exp.points[p]} trial {t}"
        assert len(rows) == len(fresh), f"{where}: {len(fresh)} rows now, {len(rows)} stored"
        assert list(fresh.columns) == list(stored.columns), f"{where}: columns differ"
        for col in fresh.columns:
            _same(fresh[col], rows[col], f"{where}: column {col!r}")
