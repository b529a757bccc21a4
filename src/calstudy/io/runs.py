"""Running a notebook's Monte Carlo experiments and storing their trial rows.

A notebook declares each experiment by a *factory*: a module-level function of the paper's
``experiments`` module that takes JSON-able keyword arguments (the notebook's parameters) and
returns a :class:`calstudy.core.montecarlo.Experiment`. :func:`run_experiments` builds and runs
them with the Monte Carlo engine, writes ``trials_<name>.csv`` per experiment into the result
folder and records in ``experiments.json`` how to build each one again: with it, the tests
recompute a few stored trials of every experiment (chosen by the seed) and compare them with the
committed rows, without rerunning the notebook.

``experiments.json`` is data, not code: :func:`rebuild` builds only the factories of
:data:`FACTORIES` (the study's own), looked up by name before anything is imported, with
keyword arguments the factory's signature accepts. Any other name is refused; a factory of
one's own is passed in as a function (``rebuild(entry, extra=[my_factory])``), never imported
from the name a file gives.
"""

from __future__ import annotations

import importlib
import inspect
import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from calstudy.core import montecarlo
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import RESULTS_DIR, atomic_write
from calstudy.io.results import write_table

#: Float format of the stored trial rows: enough digits to recompute every table from them.
TRIALS_FLOAT_FORMAT = "%.10g"
MANIFEST = "experiments.json"

Spec = tuple[Callable[..., montecarlo.Experiment], Mapping[str, Any]]


def factory_name(factory: Callable) -> str:
    """``module:qualname`` of a module-level function (what ``experiments.json`` stores)."""
    module, qualname = getattr(factory, "__module__", None), getattr(factory, "__qualname__", "")
    if not module or "<" in qualname or "." in qualname:
        raise CalibrationError(
            f"experiment factory {factory!r} must be a module-level function, so that it can be "
            "found again by name"
        )
    return f"{module}:{qualname}"


#: The study's own experiment factories, by :func:`factory_name`: the only names
#: :func:`load_factory` imports.
FACTORIES = frozenset(
    {
        "calstudy.io.handeye_report:tool_point_experiment",
        "calstudy.papers.binocular.robustness:robustness_experiment",
        *(
            f"calstudy.papers.binocular.experiments:{name}_experiment"
            for name in ("binocular", "field", "optics")
        ),
        *(
            f"calstudy.papers.dualarm.experiments:{name}_experiment"
            for name in ("budget", "drift", "plate", "robustness", "station", "survey")
        ),
        *(
            f"calstudy.papers.hybrid.experiments:{name}_experiment"
            for name in (
                "part_variation",
                "production",
                "robot_accuracy",
                "robot_error",
                "robustness",
                "rps_penalty",
                "sensitivity",
                "stationary",
                "stationary_pixel",
            )
        ),
        "calstudy.papers.hybrid.station_robustness:robustness_experiment",
        *(
            f"calstudy.papers.hybrid.handeye_experiments:{name}_experiment"
            for name in (
                "handeye",
                "handeye_moves",
                "handeye_noise",
                "handeye_noise_model",
                "handeye_pattern",
                "handeye_ranges",
            )
        ),
        *(
            f"calstudy.papers.selfcal.experiments:{name}_experiment"
            for name in (
                "arm_weight_sweep",
                "basin",
                "calibration",
                "compliance_sweep",
                "noise_sweep",
                "pose_selection",
                "robustness",
            )
        ),
    }
)


def load_factory(
    name: str, extra: Sequence[Callable[..., montecarlo.Experiment]] = ()
) -> Callable[..., montecarlo.Experiment]:
    """The experiment factory named ``module:qualname`` (:func:`factory_name`).

    Parameters
    ----------
    name : str
        The name, as ``experiments.json`` stores it.
    extra : sequence of callables, optional
        Factories of the caller's own, matched by their :func:`factory_name` (never imported).

    Returns
    -------
    callable
        A function of :data:`FACTORIES` (imported from the study's own modules) or of ``extra``.

    Raises
    ------
    CalibrationError
        If ``name`` is neither in :data:`FACTORIES` nor the name of a function of ``extra``;
        nothing is imported then.
    """
    if not isinstance(name, str):
        raise CalibrationError(f"experiment factory {name!r} must be a 'module:name' string")
    for factory in extra:
        if factory_name(factory) == name:
            return factory
    if name not in FACTORIES:
        raise CalibrationError(
            f"experiment factory {name!r} is not one of the study's factories "
            "(calstudy.io.runs.FACTORIES); a results folder may name only those. Nothing was "
            "imported or run"
        )
    module, _, qualname = name.partition(":")
    return getattr(importlib.import_module(module), qualname)


def default_cache_dir(results_dir: str | Path | None = "") -> Path:
    """Where trial rows are cached while a run goes on: ``.cache/montecarlo`` beside the
    repository's ``results/`` (git-ignored), or inside a user's ``results_dir``."""
    root = RESULTS_DIR.parent if results_dir in (None, "") else Path(results_dir)
    return root / ".cache" / "montecarlo"


def run_experiments(
    out_dir: str | Path,
    seed: int,
    specs: Sequence[Spec],
    *,
    n_jobs: int | None = None,
    scheduler: str | None = None,
    cache_dir: str | Path | None = None,
    progress: bool = True,
) -> dict[str, pd.DataFrame]:
    """Build, run and store experiments; returns their trial rows by experiment name.

    Parameters
    ----------
    out_dir : path-like
        The notebook's result folder (usually its staging folder).
    seed : int
        The notebook's seed.
    specs : sequence of (factory, kwargs)
        ``factory(**kwargs)`` must return an Experiment; ``kwargs`` must be JSON-able.
    n_jobs, scheduler, cache_dir, progress
        As for :func:`calstudy.core.montecarlo.run` (an empty ``scheduler`` or ``cache_dir``
        means none).

    Returns
    -------
    dict of str to pandas.DataFrame
        The rows of every experiment, as the engine returned them (full precision).
    """
    out = Path(out_dir)
    manifest_path = out / MANIFEST
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    if manifest and manifest.get("seed") != seed:
        raise CalibrationError(f"{manifest_path} was written with seed {manifest.get('seed')}")
    entries = dict(manifest.get("experiments", {}))
    frames = {}
    for factory, kwargs in specs:
        name = factory_name(factory)
        try:
            text = json.dumps(dict(kwargs), sort_keys=True)
        except TypeError as exc:
            raise CalibrationError(f"arguments of {name} are not JSON-able: {exc}") from exc
        exp = factory(**kwargs)
        if exp.name in entries or exp.name in frames:
            raise CalibrationError(f"two experiments are named {exp.name!r}")
        frames[exp.name] = montecarlo.run(
            exp,
            seed,
            n_jobs=n_jobs,
            scheduler=scheduler or None,
            cache_dir=cache_dir or None,
            progress=progress,
        )
        write_table(frames[exp.name], out / f"trials_{exp.name}.csv", TRIALS_FLOAT_FORMAT)
        entries[exp.name] = {
            "factory": name,
            "kwargs": json.loads(text),
            "n_trials": exp.n_trials,
            "points": len(exp.points),
        }
    record = {"seed": seed, "experiments": dict(sorted(entries.items()))}
    body = json.dumps(record, indent=2, sort_keys=True) + "\n"
    atomic_write(manifest_path, lambda tmp: tmp.write_text(body))
    return frames


def rebuild(
    entry: Mapping[str, Any], extra: Sequence[Callable[..., montecarlo.Experiment]] = ()
) -> montecarlo.Experiment:
    """The Experiment of one ``experiments.json`` entry, built again from its factory.

    Parameters
    ----------
    entry : mapping
        ``{"factory": "module:name", "kwargs": {...}, ...}`` as :func:`run_experiments` wrote it.
    extra : sequence of callables, optional
        Factories of the caller's own (see :func:`load_factory`).

    Returns
    -------
    calstudy.core.montecarlo.Experiment

    Raises
    ------
    CalibrationError
        If the entry is malformed, names a factory outside :data:`FACTORIES` and ``extra``
        (refused before any import), or passes keyword arguments the factory does not take.
    """
    if not (
        isinstance(entry, Mapping)
        and isinstance(entry.get("factory"), str)
        and isinstance(entry.get("kwargs"), Mapping)
        and all(isinstance(key, str) for key in entry["kwargs"])
    ):
        raise CalibrationError(
            f"experiment entry {entry!r} must be an object with a 'factory' string and a "
            "'kwargs' object"
        )
    factory = load_factory(entry["factory"], extra)
    kwargs = dict(entry["kwargs"])
    try:
        inspect.signature(factory).bind(**kwargs)
    except TypeError as exc:
        raise CalibrationError(
            f"experiment factory {entry['factory']!r}: keyword arguments {sorted(kwargs)} do not "
            f"fit its signature {inspect.signature(factory)} ({exc})"
        ) from None
    return factory(**kwargs)
