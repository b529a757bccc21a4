"""Spot checks of the committed Monte Carlo trial rows, without rerunning the notebooks.

Every notebook stores the rows of its experiments in ``results/<notebook>/trials_<name>.csv``
and, in ``experiments.json``, how to build each experiment again (a named factory and its
arguments). Here a few (point, trial) pairs of every experiment, chosen by the seed, are
recomputed with the engine and compared with the committed rows at the tolerances of
:mod:`calstudy.io.tolerance` (a nanometre, a nanoradian, a micro-pixel, plus ten parts per
million; counts, bins and verdicts exactly, a solver's step count within one). The full rerun
of every notebook is ``make verify``.

The second check moves what another machine moves: every calibrated value (a float argument of
a factory) by 1e-13 relative, and every random number a trial draws by 1e-13 relative (as a
last-bit difference of an intermediate number would), and asks for the same committed rows.
"""

from __future__ import annotations

import io
import json
import zlib

import numpy as np
import pandas as pd
import pytest

from calstudy.core.montecarlo import trial_rows
from calstudy.core.paths import RESULTS_DIR
from calstudy.io.runs import TRIALS_FLOAT_FORMAT, load_factory, rebuild
from calstudy.io.tolerance import TRIAL_RTOL, compare_tables

#: relative size of the last-bit perturbation: a few hundred ulps of a double
NUDGE = 1e-13


class NudgedGenerator(np.random.Generator):
    """A generator whose continuous draws are moved by ``NUDGE`` relative, alternately up and
    down (integers and choices stay exact: they are the discrete inputs of a trial)."""

    def _nudge(self, x):
        a = np.asarray(x)
        signs = np.where(np.arange(a.size).reshape(a.shape) % 2 == 0, 1.0, -1.0)
        out = (a * (1.0 + NUDGE * signs)).astype(a.dtype)  # float32 draws stay float32
        return float(out) if np.ndim(x) == 0 else out

    def normal(self, *args, **kwargs):
        return self._nudge(super().normal(*args, **kwargs))

    def standard_normal(self, *args, **kwargs):
        return self._nudge(super().standard_normal(*args, **kwargs))

    def uniform(self, *args, **kwargs):
        return self._nudge(super().uniform(*args, **kwargs))

    def random(self, *args, **kwargs):
        return self._nudge(super().random(*args, **kwargs))


def _cases() -> list:
    cases = []
    for manifest in sorted(RESULTS_DIR.glob("*/experiments.json")):
        record = json.loads(manifest.read_text())
        for name in record["experiments"]:
            stem = manifest.parent.name
            cases.append(pytest.param(stem, name, id=f"{stem}:{name}"))
    return cases


def _stored_rows(stem, name, exp, p, t) -> pd.DataFrame:
    stored = pd.read_csv(RESULTS_DIR / stem / f"trials_{name}.csv")
    mask = stored["trial"] == t
    for key, value in exp.points[p].items():
        col = stored[key]
        mask &= np.isclose(col, value) if pd.api.types.is_numeric_dtype(col) else col == value
    return stored[mask].reset_index(drop=True)


def _picks(seed: int, name: str, exp, n: int) -> list[tuple[int, int]]:
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    return [(int(rng.integers(len(exp.points))), int(rng.integers(exp.n_trials))) for _ in range(n)]


def _check(stem, name, exp, seed, p, t, generator=np.random.Generator, what="") -> None:
    fresh = trial_rows(exp, seed, p, t, generator=generator)
    stored = _stored_rows(stem, name, exp, p, t)
    # through the CSV format of the stored rows, as the notebook wrote them
    fresh = pd.read_csv(io.StringIO(fresh.to_csv(index=False, float_format=TRIALS_FLOAT_FORMAT)))
    where = f"{stem} {name} point {exp.points[p]} trial {t}{what}"
    bad = compare_tables(fresh, stored, TRIAL_RTOL)
    assert not bad, f"{where}: " + "; ".join(str(m) for m in bad)


@pytest.mark.parametrize(("stem", "name"), _cases())
def test_committed_trials_recompute(stem, name):
    record = json.loads((RESULTS_DIR / stem / "experiments.json").read_text())
    entry, seed = record["experiments"][name], record["seed"]
    exp = rebuild(entry)
    assert exp.name == name
    assert (exp.n_trials, len(exp.points)) == (entry["n_trials"], entry["points"])
    (p, t), *_ = _picks(seed, name, exp, 2)
    _check(stem, name, exp, seed, p, t)


@pytest.mark.parametrize(("stem", "name"), _cases())
def test_committed_trials_absorb_last_bit_changes(stem, name):
    record = json.loads((RESULTS_DIR / stem / "experiments.json").read_text())
    entry, seed = record["experiments"][name], record["seed"]
    kwargs = {
        k: v * (1.0 + NUDGE) if isinstance(v, float) else v for k, v in entry["kwargs"].items()
    }
    exp = load_factory(entry["factory"])(**kwargs)
    _, (p, t) = _picks(seed, name, exp, 2)
    moved = sorted(k for k, v in entry["kwargs"].items() if isinstance(v, float))
    what = f", draws and {moved} moved by {NUDGE:g}" if moved else f", draws moved by {NUDGE:g}"
    _check(stem, name, exp, seed, p, t, generator=NudgedGenerator, what=what)


def test_nudged_generator_moves_draws_by_a_few_ulps():
    a = np.random.Generator(np.random.PCG64(5)).normal(size=1000)
    b = NudgedGenerator(np.random.PCG64(5)).normal(size=1000)
    rel = np.abs(b / a - 1.0)
    assert np.all(rel > 0.5 * NUDGE) and np.all(rel < 2 * NUDGE)
    assert NudgedGenerator(np.random.PCG64(5)).integers(100, size=5).tolist() == (
        np.random.Generator(np.random.PCG64(5)).integers(100, size=5).tolist()
    )
