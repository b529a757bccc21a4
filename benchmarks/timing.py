"""The one timing rule of the benchmarks: the best wall-clock time of several repeats."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_seconds(fn: Callable[[], object], repeats: int) -> float:
    """Shortest wall-clock time of ``repeats`` calls of ``fn``, in seconds (others add noise)."""
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def best_ms(fn: Callable[[], object], repeats: int) -> float:
    """:func:`best_seconds` in milliseconds."""
    return 1000.0 * best_seconds(fn, repeats)
