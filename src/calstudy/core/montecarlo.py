"""Monte Carlo engine: trials over sweep points, the same rows whatever runs them.

An :class:`Experiment` names a trial function, the scenario it reads, a number of trials and the
sweep points; :func:`run` calls ``trial(scenario, rng, **point)`` for every (point, trial) pair
and returns the rows as one :class:`pandas.DataFrame`, with the point's keys and the ``trial``
index added to each row.

Reproducibility
---------------
Each trial draws from its own generator, derived from (seed, experiment name, trial index)
alone (see :func:`trial_rng`), and the rows are sorted by (point order, trial, row order within
the trial). Serial runs, ``n_jobs`` worker processes and a Dask cluster therefore give
byte-identical tables, whatever order the trials finish in.

The sweep point does not key the stream: trial ``t`` sees the same draws at every point of a
sweep (common random numbers), so that two points are compared on paired trials, and a computed
point value (a nuisance input calibrated to a baseline figure, whose last bits depend on the
machine) cannot reseed anything. A trial made of independent random components (a survey, the
scans, a drift) draws each from its own child stream, :func:`child_rng`, so that a
data-dependent number of draws in one component cannot shift the draws of another.

Cache
-----
With ``cache_dir``, every finished trial's rows are written at once as JSON (temporary file,
then :func:`os.replace`; scalars only, numpy scalars tagged with their dtype, read back without
building any object from a name: :mod:`calstudy.core.trialcache`) to::

    cache_dir/<experiment>/<point-slug>/<key>/trial-<trial:06d>.json

``<point-slug>`` is a readable form of the point (``sigma=0.05``, ``_`` for the single point
``{}``); ``<key>`` is the first 16 hex digits of the SHA-256 of the canonical JSON of the seed,
the experiment name, the point, the trial function (module and qualified name) and the scenario
fingerprint; ``<key>/key.json`` holds that JSON. A later run reuses a stored trial only if all of
these match, so an interrupted run resumes, a larger ``n_trials`` computes only the new trials
and a smaller one returns the first trials. Changing the *code* of a trial function does not
change its fingerprint: delete the cache, or put a version in ``Experiment.scenario_key``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import operator
import os
import pickle
import re
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from calstudy.core.errors import CalibrationError
from calstudy.core.trialcache import Rows, TrialCache

__all__ = [
    "Experiment",
    "child_rng",
    "one_opencv_thread",
    "run",
    "streams",
    "trial_rng",
    "trial_rows",
]

_NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_SCALARS = (type(None), bool, int, float, str, np.bool_, np.integer, np.floating)

# (point index, trial index, rows or None, exception or None)
Outcome = tuple[int, int, Rows | None, BaseException | None]


# ----------------------------------------------------------------------------------------------
# the experiment


@dataclass(frozen=True)
class Experiment:
    """A Monte Carlo experiment: ``n_trials`` calls of ``trial`` at each sweep point.

    Parameters
    ----------
    name : str
        Short identifier, e.g. ``"handeye"`` or ``"noise_sweep"``: letters, digits, ``_``, ``.``
        and ``-``, starting with a letter or digit. It keys the random streams and names the
        cache folder.
    trial : callable
        ``trial(scenario, rng, **point) -> dict | list[dict]``, a module-level function (workers
        import it by name). Each dict is one row: column name to scalar value. It must draw
        only from ``rng`` (a :class:`numpy.random.Generator`).
    scenario : object
        Whatever the trial reads (a dataclass, typically); picklable.
    n_trials : int
        Trials per sweep point, at least 1.
    points : sequence of mappings, optional
        Sweep points, each a mapping of keyword arguments of ``trial`` to scalar values (None,
        bool, int, float, str or a NumPy scalar). All points have the same keys; none is
        repeated. The default ``({},)`` is a single point without arguments.
    scenario_key : str, optional
        The scenario's cache fingerprint. By default it is the SHA-256 of a canonical JSON form
        of ``scenario`` (dataclass fields, mappings, sequences, array bytes); give a key when the
        scenario holds objects without a stable form (the cache then refuses to guess).

    Raises
    ------
    CalibrationError
        If any argument breaks the rules above.
    """

    name: str
    trial: Callable[..., Mapping[str, Any] | Sequence[Mapping[str, Any]]]
    scenario: Any
    n_trials: int
    points: Sequence[Mapping[str, Any]] = ({},)
    scenario_key: str | None = None

    def __post_init__(self) -> None:
        _check_name(self.name)
        if not callable(self.trial):
            raise CalibrationError(
                f"experiment {self.name!r}: trial must be callable, got {type(self.trial).__name__}"
            )
        object.__setattr__(self, "n_trials", _check_count(self.n_trials, self.name))
        object.__setattr__(self, "points", _check_points(self.points, self.name))
        if self.scenario_key is not None and not isinstance(self.scenario_key, str):
            raise CalibrationError(
                f"experiment {self.name!r}: scenario_key must be a str or None, "
                f"got {type(self.scenario_key).__name__}"
            )


def _check_name(name: object) -> str:
    if not isinstance(name, str) or not _NAME_PATTERN.fullmatch(name):
        raise CalibrationError(
            f"experiment name must be a non-empty string of letters, digits, '_', '.' and '-' "
            f"starting with a letter or digit, got {name!r}"
        )
    return name


def _check_count(n_trials: object, name: str) -> int:
    if isinstance(n_trials, bool | np.bool_) or not isinstance(n_trials, int | np.integer):
        raise CalibrationError(
            f"experiment {name!r}: n_trials must be an integer, got {n_trials!r}"
        )
    if n_trials < 1:
        raise CalibrationError(f"experiment {name!r}: n_trials must be at least 1, got {n_trials}")
    return int(n_trials)


def _check_points(points: object, name: str) -> tuple[dict[str, Any], ...]:
    if isinstance(points, Mapping):
        raise CalibrationError(
            f"experiment {name!r}: points must be a sequence of mappings, got one mapping "
            f"{dict(points)!r}; wrap it in a list"
        )
    if isinstance(points, str | bytes) or not isinstance(points, Sequence) or not points:
        raise CalibrationError(
            f"experiment {name!r}: points must be a non-empty sequence of mappings, got {points!r}"
        )
    checked: list[dict[str, Any]] = []
    seen: dict[str, int] = {}
    for i, point in enumerate(points):
        if not isinstance(point, Mapping):
            raise CalibrationError(
                f"experiment {name!r}: points[{i}] must be a mapping, got {type(point).__name__}"
            )
        point = dict(point)
        if "trial" in point:
            raise CalibrationError(
                f"experiment {name!r}: points[{i}] has the key 'trial', which the engine uses for "
                "the trial index; rename it"
            )
        if checked and point.keys() != checked[0].keys():
            raise CalibrationError(
                f"experiment {name!r}: points[{i}] has keys {sorted(point)}, points[0] has "
                f"{sorted(checked[0])}; every sweep point needs the same keys"
            )
        key = _point_json(point)
        if key in seen:
            raise CalibrationError(
                f"experiment {name!r}: points[{i}] repeats points[{seen[key]}] ({point!r})"
            )
        seen[key] = i
        checked.append(point)
    return tuple(checked)


# ----------------------------------------------------------------------------------------------
# random streams


def trial_rng(
    seed: int, experiment: str, point: Mapping[str, Any] | None, trial: int
) -> np.random.Generator:
    """The generator that the engine hands to one trial, to reproduce it by hand.

    The stream is ``Generator(PCG64(SeedSequence(entropy=seed, spawn_key=key)))`` with ``key``
    the 8 little-endian uint32 words of the SHA-256 of the UTF-8 ``experiment``, then
    ``trial``. It depends on nothing else: not on the sweep point (every point of a sweep sees
    the same draws), the worker, the order of trials, Python's ``hash`` or other points.

    Parameters
    ----------
    seed : int
        The run's seed, >= 0.
    experiment : str
        The experiment name.
    point : mapping or None
        The sweep point (``{}`` for an experiment without sweep). It is checked (scalar values,
        str keys) but does not key the stream.
    trial : int
        Trial index, >= 0.

    Returns
    -------
    numpy.random.Generator
        A fresh PCG64 generator.

    Raises
    ------
    CalibrationError
        On a negative or non-integer seed or trial, a bad name or a point value that is not a
        scalar.

    Examples
    --------
    >>> rng = trial_rng(7, "noise_sweep", {"sigma": 0.05}, 3)
    >>> rng.integers(10**6) == trial_rng(7, "noise_sweep", {"sigma": 0.2}, 3).integers(10**6)
    True
    """
    seed = _check_index(seed, "seed")
    _check_name(experiment)
    if point is not None:
        if not isinstance(point, Mapping):
            raise CalibrationError(f"point must be a mapping, got {type(point).__name__}")
        _point_json(point)
    return _rng(seed, _words(experiment), _check_index(trial, "trial"))


def child_rng(rng: np.random.Generator, component: str) -> np.random.Generator:
    """The stream of one random component of a trial, e.g. ``"survey"``, ``"scans"``, ``"drift"``.

    A child stream is derived from the seed sequence of ``rng`` (its entropy and spawn key) and
    the component's name alone, not from the state of ``rng``: however many numbers ``rng`` or
    another child has drawn, the child gives the same draws. Independent components of a trial
    take one child each, so that a data-dependent number of draws in one (a rejection sampler,
    a retried pose) cannot shift the draws of the others.

    Parameters
    ----------
    rng : numpy.random.Generator
        The trial's generator (from the engine, :func:`trial_rng`, or
        ``numpy.random.default_rng(seed)``): a PCG64 generator built from a ``SeedSequence``.
    component : str
        The component's name; different names give independent streams, the same name the same
        stream.

    Returns
    -------
    numpy.random.Generator
        A fresh PCG64 generator of the class of ``rng`` (a subclass of
        :class:`numpy.random.Generator` carries over to the children).

    Raises
    ------
    CalibrationError
        If ``rng`` was not built from a seed sequence or ``component`` is not a non-empty str.

    Examples
    --------
    >>> rng = trial_rng(7, "station", {}, 3)
    >>> a = child_rng(rng, "survey").normal()
    >>> _ = rng.normal(size=1000)  # draws from the parent do not move the child
    >>> a == child_rng(rng, "survey").normal()
    True
    """
    if not isinstance(component, str) or not component:
        raise CalibrationError(f"component must be a non-empty str, got {component!r}")
    seq = _seed_sequence(rng, "child_rng")
    sequence = np.random.SeedSequence(
        entropy=seq.entropy, spawn_key=(*seq.spawn_key, *_words("component:" + component))
    )
    return type(rng)(np.random.PCG64(sequence))


def _seed_sequence(rng: object, who: str) -> np.random.SeedSequence:
    seq = getattr(getattr(rng, "bit_generator", None), "seed_seq", None)
    if not isinstance(seq, np.random.SeedSequence):
        raise CalibrationError(
            f"{who} needs a generator built from a numpy SeedSequence (as the engine's and "
            f"numpy.random.default_rng(seed) are), got {type(rng).__name__}"
        )
    return seq


def streams(rng: np.random.Generator, *components: str) -> tuple[np.random.Generator, ...]:
    """New independent streams for the named random components of one call.

    ``rng`` spawns one child (:meth:`numpy.random.Generator.spawn`, which counts calls, not
    draws) and each component takes a named child of it (:func:`child_rng`). A function that
    draws several components (a station's robot, target and mounts) starts with this: every
    call on the same generator gives new draws, as a plain sequence of draws would, while the
    number of numbers one component draws cannot shift another's. To give a call the same draws
    again (a paired comparison), pass it a fresh ``child_rng(trial_rng, name)``.

    Parameters
    ----------
    rng : numpy.random.Generator
        The caller's generator, built from a ``SeedSequence``.
    *components : str
        Names of the components, at least one, distinct.

    Returns
    -------
    tuple of numpy.random.Generator
        One generator per component, in the order given.

    Raises
    ------
    CalibrationError
        If ``rng`` was not built from a seed sequence, no component is named or a name repeats.

    Examples
    --------
    >>> rng = trial_rng(7, "station", {}, 3)
    >>> robot, target = streams(rng, "robot", "target")
    >>> again, _ = streams(rng, "robot", "target")  # a second call: new draws
    >>> bool(robot.normal() != again.normal())
    True
    """
    if not components or len(set(components)) != len(components):
        raise CalibrationError(f"streams needs distinct component names, got {components!r}")
    _seed_sequence(rng, "streams")
    (base,) = rng.spawn(1)
    return tuple(child_rng(base, name) for name in components)


def _check_index(value: object, what: str) -> int:
    if isinstance(value, bool | np.bool_):
        raise CalibrationError(f"{what} must be a non-negative integer, got {value!r}")
    try:
        index = operator.index(value)
    except TypeError:
        raise CalibrationError(f"{what} must be a non-negative integer, got {value!r}") from None
    if index < 0:
        raise CalibrationError(f"{what} must be a non-negative integer, got {index}")
    return index


def _words(text: str) -> tuple[int, ...]:
    digest = hashlib.sha256(text.encode("utf-8")).digest()
    return tuple(int.from_bytes(digest[i : i + 4], "little") for i in range(0, 32, 4))


def _rng(
    seed: int, prefix: tuple[int, ...], trial: int, generator: type = np.random.Generator
) -> np.random.Generator:
    # PCG64 named explicitly: default_rng's bit generator may change between NumPy versions
    sequence = np.random.SeedSequence(entropy=seed, spawn_key=(*prefix, trial))
    return generator(np.random.PCG64(sequence))


def _point_json(point: Mapping[str, Any]) -> str:
    canonical = {}
    for key, value in point.items():
        if not isinstance(key, str):
            raise CalibrationError(f"sweep point keys must be str, got {key!r}")
        if not isinstance(value, _SCALARS):
            raise CalibrationError(
                f"sweep point value {key}={value!r} is a {type(value).__name__}; use a scalar "
                "(None, bool, int, float, str) and let the trial look the object up in the scenario"
            )
        canonical[key] = value.item() if isinstance(value, np.generic) else value
    return json.dumps(canonical, sort_keys=True, separators=(",", ":"))


def _label(point: Mapping[str, Any]) -> str:
    return " ".join(f"{key}={value}" for key, value in point.items())


# ----------------------------------------------------------------------------------------------
# one trial (runs in the worker)


@dataclass(frozen=True)
class _PointJob:
    """What a worker needs for the trials of one point (pickled once per batch of calls)."""

    trial: Callable[..., Any]
    scenario: Any
    seed: int
    prefix: tuple[int, ...]
    point: dict[str, Any]
    index: int


_worker_blas_limited = False


def _limit_worker_blas() -> None:
    # loky workers start with the BLAS variables at 1 (inner_max_num_threads) and Dask's nanny
    # sets them too; threadpoolctl also caps a library loaded before the variables were read.
    global _worker_blas_limited
    if not _worker_blas_limited:
        threadpool_limits(1)
    _worker_blas_limited = True


@contextlib.contextmanager
def one_opencv_thread() -> Iterator[None]:
    """OpenCV on one thread inside the block, the caller's setting restored after; also a
    decorator. Every trial runs under it.

    OpenCV takes as many threads as the machine has cores, and its DFT-based filters (large
    kernels: the binocular blur spots, the rectification's mean) round differently with another
    number of threads; on one thread the rows are those of any machine. A trial's images are
    small, so the helper threads only cost CPU time (0.14 s of 1.0 s per binocular trial on two
    cores), as BLAS threads would.
    """
    import cv2

    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(previous)


def _run_trial(
    job: _PointJob, trial: int, in_worker: bool, generator: type = np.random.Generator
) -> Outcome:
    if in_worker:
        _limit_worker_blas()
    rng = _rng(job.seed, job.prefix, trial, generator)
    try:
        with one_opencv_thread():
            rows = _as_rows(job.trial(job.scenario, rng, **job.point), job.point)
    except Exception as exc:  # reported by the caller with experiment, point and trial
        return job.index, trial, None, _portable(exc) if in_worker else exc
    return job.index, trial, rows, None


def _as_rows(out: object, point: Mapping[str, Any]) -> Rows:
    if isinstance(out, Mapping):
        out = [out]
    elif not isinstance(out, list | tuple):
        raise CalibrationError(
            f"the trial returned a {type(out).__name__}; return a dict or a list of dicts"
        )
    rows = []
    for i, row in enumerate(out):
        if not isinstance(row, Mapping):
            raise CalibrationError(f"row {i} of the trial is a {type(row).__name__}, not a dict")
        if not all(isinstance(key, str) for key in row):
            raise CalibrationError(f"row {i} of the trial has a column name that is not a str")
        clash = sorted(key for key in row if key == "trial" or key in point)
        if clash:
            raise CalibrationError(
                f"row {i} of the trial has column(s) {clash}, which the engine adds (trial index "
                "and sweep point keys); rename them"
            )
        rows.append(dict(row))
    return rows


def _portable(exc: Exception) -> BaseException:
    """``exc`` with the worker's traceback as a note, or a RuntimeError if it does not pickle."""
    text = traceback.format_exc()
    try:
        exc.add_note(f"traceback in the worker:\n{text}")
        pickle.loads(pickle.dumps(exc))
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}\ntraceback in the worker:\n{text}")
    return exc


# ----------------------------------------------------------------------------------------------
# where the trials run


@contextlib.contextmanager
def _outcomes(
    pending: Sequence[tuple[_PointJob, int]], n_jobs: int | None, scheduler: object
) -> Iterator[Iterator[Outcome]]:
    """Yield an iterator over the outcomes of ``pending`` trials, in the order they finish."""
    if scheduler is None and n_jobs != 1:
        import joblib

        # joblib reads n_jobs=None as 1; here it means all cores, as -1 does
        n_jobs = -1 if n_jobs is None else n_jobs
        n_jobs = 1 if joblib.effective_n_jobs(n_jobs) == 1 else n_jobs
    if not pending:
        yield iter(())
    elif scheduler is None and n_jobs == 1:
        with one_blas_thread():
            yield (_run_trial(job, trial, False) for job, trial in pending)
    else:
        import joblib

        tasks = (joblib.delayed(_run_trial)(job, trial, True) for job, trial in pending)
        with contextlib.ExitStack() as stack:
            if scheduler is None:
                stack.enter_context(joblib.parallel_config(backend="loky", inner_max_num_threads=1))
            else:
                client = stack.enter_context(_dask_client(scheduler))
                stack.enter_context(joblib.parallel_config(backend="dask", client=client))
                n_jobs = -1
            # batch_size="auto": joblib groups fast trials so dispatch does not dominate them
            results = joblib.Parallel(n_jobs=n_jobs, return_as="generator_unordered")(tasks)
            try:
                yield results
            finally:
                with warnings.catch_warnings():
                    # after a failed trial the engine drops the trials in flight on purpose
                    warnings.filterwarnings("ignore", "[0-9]+ tasks ", UserWarning)
                    results.close()


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS on one thread inside the block, the caller's limits restored after; also a
    decorator. The engine runs every trial under it (its workers start with one thread): a
    multi-threaded BLAS splits its sums otherwise and moves the last digits of the rows. A
    computation a notebook runs outside the engine takes it for the same reason."""
    with threadpool_limits(1):
        yield


@contextlib.contextmanager
def _dask_client(scheduler: object) -> Iterator[Any]:
    from distributed import Client

    if isinstance(scheduler, Client):
        yield scheduler
    elif isinstance(scheduler, str):
        client = Client(scheduler, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    else:
        raise CalibrationError(
            "scheduler must be a Dask scheduler address such as 'tcp://host:8786' or a "
            f"distributed.Client, got {type(scheduler).__name__}"
        )


# ----------------------------------------------------------------------------------------------
# running


def run(
    experiment: Experiment,
    seed: int,
    *,
    n_jobs: int | None = None,
    scheduler: str | Any | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    progress: bool = True,
) -> pd.DataFrame:
    """Run every trial of ``experiment`` and return their rows.

    Parameters
    ----------
    experiment : Experiment
        What to run.
    seed : int
        The run's seed, >= 0; with the experiment name, sweep point and trial index it fixes
        each trial's generator (:func:`trial_rng`).
    n_jobs : int, optional
        Local worker processes (joblib, loky backend, single-threaded BLAS in each): None or -1
        for all cores, 1 to run serially in this process. Ignored when ``scheduler`` is given.
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``"tcp://host:8786"``) or client to run the trials on, through
        joblib's Dask backend. Workers must be able to import the trial function.
    cache_dir : path-like, optional
        Folder of stored trial rows (see the module docstring). Stored trials with the same
        seed, experiment, point, trial function and scenario are reused, not recomputed.
    progress : bool, default True
        Show a progress bar on stderr.

    Returns
    -------
    pandas.DataFrame
        One row per row returned by a trial. Columns: the sweep point's keys, ``trial`` (int,
        0 to ``n_trials - 1``), then the trial's columns in order of first appearance. Rows are
        sorted by point (in ``experiment.points`` order), trial, then row order within the
        trial; the index is a RangeIndex. Identical bytes for any ``n_jobs`` or scheduler.

    Raises
    ------
    CalibrationError
        On bad arguments, and when a trial raises (the message names the experiment, point and
        trial: the first in order that fails, whatever the number of workers; the trial's
        exception is the ``__cause__``). Trials finished before are kept in
        the cache.
    """
    if not isinstance(experiment, Experiment):
        raise CalibrationError(f"experiment must be an Experiment, got {type(experiment).__name__}")
    seed = _check_index(seed, "seed")
    if n_jobs is not None and (
        isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or not n_jobs
    ):
        raise CalibrationError(f"n_jobs must be None, -1 or a positive integer, got {n_jobs!r}")
    started = time.time()
    exp = experiment
    point_jsons = [_point_json(point) for point in exp.points]
    jobs = [
        _PointJob(exp.trial, exp.scenario, seed, _words(exp.name), point, i)
        for i, (point, key) in enumerate(zip(exp.points, point_jsons, strict=True))
    ]
    cache = None if cache_dir is None else TrialCache(Path(cache_dir), exp, seed, point_jsons)
    done: dict[tuple[int, int], Rows] = {}
    if cache is not None:
        cache.remove_stale(started)
        done = cache.load_all(exp.n_trials)
    pending = [(job, t) for job in jobs for t in range(exp.n_trials) if (job.index, t) not in done]
    labels = [f"{exp.name} {_label(point)}".rstrip() for point in exp.points]
    total = len(jobs) * exp.n_trials
    bar = tqdm(
        total=total,
        initial=len(done),
        desc=labels[0],
        unit="trial",
        file=sys.stderr,
        disable=not progress,
    )
    with bar, _outcomes(pending, n_jobs, scheduler) as outcomes:
        for p, t, rows, error in outcomes:
            if error is not None:
                p, t, error = _first_failure(jobs, exp.n_trials, done, p, t, error)
                raise _trial_error(exp, seed, p, t, error) from error
            done[p, t] = rows
            if cache is not None:
                cache.save(p, t, rows)
            bar.set_description_str(labels[p], refresh=False)
            bar.update()
    return _frame(exp, done)


def _first_failure(
    jobs: Sequence[_PointJob],
    n_trials: int,
    done: Mapping[tuple[int, int], Rows],
    p: int,
    t: int,
    error: BaseException,
) -> tuple[int, int, BaseException]:
    """The failure to report: the first (point, trial), in order, that fails, whichever worker
    finished first. The trials before ``(p, t)`` that have not finished are run here, one by
    one, until one fails (an error path: a few trials at most when a setting cannot run)."""
    for job in jobs[: p + 1]:
        for trial in range(t if job.index == p else n_trials):
            if (job.index, trial) in done:
                continue
            with one_blas_thread():
                q, s, _, err = _run_trial(job, trial, False)
            if err is not None:
                return q, s, err
    return p, t, error


def _trial_error(exp: Experiment, seed: int, p: int, t: int, error: BaseException) -> Exception:
    point = exp.points[p]
    return CalibrationError(
        f"experiment {exp.name!r}, point {_label(point) or '(no sweep)'}, trial {t} failed: "
        f"{type(error).__name__}: {error} (its generator is "
        f"trial_rng({seed}, {exp.name!r}, {point!r}, {t}))"
    )


def _frame(exp: Experiment, done: Mapping[tuple[int, int], Rows]) -> pd.DataFrame:
    records = [
        {**point, "trial": t, **row}
        for p, point in enumerate(exp.points)
        for t in range(exp.n_trials)
        for row in done[p, t]
    ]
    if not records:
        return pd.DataFrame(columns=[*exp.points[0], "trial"])
    return pd.DataFrame.from_records(records)


def trial_rows(
    experiment: Experiment,
    seed: int,
    point: int,
    trial: int,
    *,
    generator: type[np.random.Generator] = np.random.Generator,
) -> pd.DataFrame:
    """The rows of one trial, computed here, as :func:`run` would return them.

    For spot checks of stored results: rebuild the experiment, pick a (point, trial) pair and
    compare these rows with the stored ones.

    Parameters
    ----------
    experiment : Experiment
        The experiment as run.
    seed : int
        The run's seed.
    point : int
        Index into ``experiment.points``.
    trial : int
        Trial index, 0 to ``n_trials - 1``.
    generator : type, optional
        The class of the trial's generator (and of its children, :func:`child_rng`): a subclass
        of :class:`numpy.random.Generator` whose draws are moved by a few ulps tests whether the
        trial absorbs the last-bit differences of another machine.
    """
    if not (isinstance(generator, type) and issubclass(generator, np.random.Generator)):
        raise CalibrationError(f"generator must be a numpy Generator class, got {generator!r}")
    if not isinstance(experiment, Experiment):
        raise CalibrationError(f"experiment must be an Experiment, got {type(experiment).__name__}")
    seed = _check_index(seed, "seed")
    if not 0 <= point < len(experiment.points) or not 0 <= trial < experiment.n_trials:
        raise CalibrationError(
            f"point {point} / trial {trial} out of range: {len(experiment.points)} points, "
            f"{experiment.n_trials} trials"
        )
    pt = experiment.points[point]
    job = _PointJob(
        experiment.trial,
        experiment.scenario,
        seed,
        _words(experiment.name),
        pt,
        point,
    )
    with one_blas_thread():
        _, _, rows, error = _run_trial(job, trial, in_worker=False, generator=generator)
    if error is not None:
        raise _trial_error(experiment, seed, point, trial, error) from error
    records = [{**pt, "trial": trial, **row} for row in rows]
    return pd.DataFrame.from_records(records)
