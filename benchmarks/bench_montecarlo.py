"""Time the Monte Carlo engine's dispatch overhead (budget: a 1 ms trial not dominated by it).

A trial here burns a fixed CPU time (``time.thread_time``, so a busy machine stretches the wall
clock but not the work). Prints the best of several repeats of N trials called in a bare loop,
through ``run(n_jobs=1)`` and through ``run(n_jobs=2)`` (worker pool already started), and the
overhead per trial: engine minus bare loop, in wall time for the serial run and in worker time
(``n_jobs x`` wall) for the parallel one.
"""

from __future__ import annotations

import time

import numpy as np
from timing import best_seconds

from calstudy.core.montecarlo import Experiment, run

REPEATS = 3
CASES = ((1.0, 1000), (5.0, 200))  # (trial CPU time in ms, trials)


def busy_trial(scenario: None, rng: np.random.Generator, ms: float) -> dict[str, float]:
    """Draw three normals and burn ``ms`` milliseconds of this thread's CPU time."""
    x = rng.normal(size=3)
    end = time.thread_time() + ms / 1000.0
    while time.thread_time() < end:
        pass
    return {"x": float(x[0]), "y": float(x[1])}


def time_case(ms: float, n: int) -> tuple[float, float, float]:
    """Best seconds of ``n`` trials of ``ms`` ms: bare loop, ``n_jobs=1``, ``n_jobs=2``."""
    exp = Experiment("bench", busy_trial, None, n, points=[{"ms": ms}])
    rng = np.random.default_rng(0)
    bare = best_seconds(lambda: [busy_trial(None, rng, ms) for _ in range(n)], REPEATS)
    serial = best_seconds(lambda: run(exp, 1, n_jobs=1, progress=False), REPEATS)
    run(exp, 1, n_jobs=2, progress=False)  # start the workers
    parallel = best_seconds(lambda: run(exp, 1, n_jobs=2, progress=False), REPEATS)
    return bare, serial, parallel


def main() -> None:
    print(f"montecarlo: best of {REPEATS}, per-trial overhead of the engine")
    for ms, n in CASES:
        bare, serial, parallel = time_case(ms, n)
        print(
            f"  {ms:g} ms trial x {n}: bare {bare:.3f} s, n_jobs=1 {serial:.3f} s, "
            f"n_jobs=2 {parallel:.3f} s (speed-up {serial / parallel:.2f})"
        )
        print(
            f"    overhead per trial: n_jobs=1 {1e3 * (serial - bare) / n:.3f} ms, "
            f"n_jobs=2 {1e3 * (2 * parallel - bare) / n:.3f} ms of worker time"
        )


if __name__ == "__main__":
    main()
