"""Trial functions and scenarios of the Monte Carlo engine tests.

They live in a module of their own on pytest's ``pythonpath`` so that worker processes (loky,
Dask) can import them by name, as they would a notebook's trial functions from calstudy.
"""

from __future__ import annotations

import os
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.core.montecarlo import Experiment, trial_rng

SEED = 20240611
POINTS = ({"sigma": 0.05, "robot": "ur5"}, {"sigma": 0.2, "robot": "kuka"})


@dataclass(frozen=True)
class Scenario:
    """What the test trials read; ``state_dir`` records calls and one-off failures."""

    scale: float = 1.0
    state_dir: str | None = None
    fail_draw: int | None = None  # the trial whose first draw this is raises
    fail_once: bool = False
    extra: object = None  # anything else a scenario may hold


def stable_experiment(state_dir: str) -> Experiment:
    """An experiment whose scenario holds a set of strings (iteration order set by the hash
    seed), an array and a nested mapping: its cache key must not depend on the process."""
    extra = {"robots": {"ur5", "kuka", "abb", "fanuc"}, "grid": np.arange(6.0).reshape(2, 3)}
    scenario = Scenario(state_dir=state_dir, extra={"nested": extra, "tol": (0.1, 1e-9)})
    return Experiment("stable", noisy_solve, scenario, 3)


def first_draw(rng: np.random.Generator) -> int:
    return int(rng.integers(2**62))


def expected_first(seed, name, point, trial):
    return first_draw(trial_rng(seed, name, point, trial))


def noisy_solve(scenario, rng, sigma=0.1, robot="ur5"):
    """1 to 3 rows of a small noisy linear solve; sleeps a little so finish order varies."""
    first = first_draw(rng)
    if scenario.state_dir is not None:
        state = Path(scenario.state_dir)
        (state / "calls").mkdir(exist_ok=True)
        (state / "calls" / f"{first}-{uuid.uuid4().hex}").touch()
        if first == scenario.fail_draw:
            flag = state / "failed-once"
            if not (scenario.fail_once and flag.exists()):
                flag.touch()
                raise ValueError("kaboom")
    time.sleep(rng.uniform(0.0, 0.002))
    rows = []
    for k in range(int(rng.integers(1, 4))):
        a = rng.normal(size=(4, 4)) + 4.0 * np.eye(4)
        b = rng.normal(scale=sigma * scenario.scale, size=4)
        x = np.linalg.solve(a, b)
        rows.append(
            {"k": k, "err": float(np.linalg.norm(x)), "x0": x[0], "tag": robot, "first": first}
        )
    return rows


def one_row(scenario, rng, sigma=None):
    return {"u": rng.random()}


def pid_row(scenario, rng):
    blas = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    return {"pid": os.getpid(), "blas": ",".join(os.environ.get(name, "-") for name in blas)}


def opencv_threads_row(scenario, rng):
    import cv2

    return {"opencv_threads": cv2.getNumThreads()}


def blas_threads_row(scenario, rng):
    from threadpoolctl import threadpool_info

    threads = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
    return {"blas_threads": max(threads)}


def bad_return(scenario, rng):
    return 3.0


def clashing_row(scenario, rng, sigma=0.1):
    return {"sigma": 1.0}


def experiment(name="solve", n_trials=6, points=POINTS, **scenario):
    return Experiment(name, noisy_solve, Scenario(**scenario), n_trials, points)


def csv_bytes(df: pd.DataFrame) -> bytes:
    return df.to_csv(index=False, float_format="%.17g").encode()


def assert_same_bytes(got: pd.DataFrame, want: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(got, want, check_exact=True)
    assert csv_bytes(got) == csv_bytes(want)


def calls(state: Path) -> list[int]:
    """First draws of the trials called so far (one entry per call), then forget them."""
    folder = state / "calls"
    names = sorted(folder.iterdir()) if folder.exists() else []
    for name in names:
        name.unlink()
    return sorted(int(name.name.split("-")[0]) for name in names)


def firsts(name, point, trials, seed=SEED):
    return sorted(expected_first(seed, name, point, t) for t in trials)


def toy_experiment(n_trials: int = 4, scale: float = 1.0) -> Experiment:
    """A named experiment factory with JSON-able arguments (for calstudy.io.runs)."""
    return Experiment("toy", noisy_solve, Scenario(scale=scale), n_trials, POINTS)


def slow_first_failure(scenario, rng):
    """Fails always; half the trials (by their first draw) take 0.6 s to do so."""
    time.sleep(0.6 if rng.uniform() > 0.5 else 0.0)
    raise ValueError("this setting cannot run")
