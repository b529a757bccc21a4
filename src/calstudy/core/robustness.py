"""Robustness of a verdict: does it hold over the plausible range of every input it rests on?

A claim's verdict is computed at one point of its scenario. Each ``assumed`` input of the
ledger (:mod:`calstudy.core.ledger`) has a plausible range, and a ``calibrated`` one an
uncertainty from its calibration; :func:`robustness_map` asks, for every claim, which of them
the verdict depends on (rule 13 of the verdict rule,
*How a verdict is computed* on the book's claims page):

1. **Base.** The scenario as it is, ``n_sweep`` trials.
2. **Screen.** Each input at both ends of its range, ``n_screen`` trials, on paired seeds: the
   Monte Carlo engine keys a trial's random stream by (seed, experiment, trial) only
   (:func:`calstudy.core.montecarlo.trial_rng`), so trial ``t`` draws the same noise at every
   point and two points differ by the input alone. An input *matters* to a claim when an end
   changes the claim's verdict, or when the 95 % order-statistic interval of the median paired
   difference of the claim's per-trial statistic (end minus base, trial by trial) excludes 0
   and the median difference is at least ``min_shift`` of the base median.
3. **Sweep.** Every input that matters, over its whole range (``sweep_size`` values and the
   base value), ``n_sweep`` trials per value, the claim's own rule at each.
4. **Grid.** Where two or more inputs matter to a claim, the two that move it most, over
   ``{low, base, high}`` each: their interaction.

The verdict is *robust* when it is the same at every judged point (base, sweeps, grids),
otherwise *conditional*: :func:`claim_summary` gives the verdicts it takes, the inputs it
depends on, and the thresholds (the pair of swept values between which it changes), with where
the paper's own numbers put each input (:attr:`Input.paper`).

What the mechanism needs from a paper is a :class:`MapSpec`: the claims, the inputs (most from
:func:`ledger_inputs`), and three functions: ``experiment(group, setting, n_trials)`` (an
Experiment whose name is the same at every setting, so the seeds pair), ``statistics(group,
rows)`` (per-trial statistic of each claim of the group) and ``judge(group, rows)`` (each
claim's verdict by its own rule). Every point runs through the engine's trial cache, so an
interrupted map goes on where it stopped, and its rows do not depend on the number of workers.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from pydantic import BaseModel

from calstudy.core import montecarlo
from calstudy.core.errors import CalibrationError
from calstudy.core.labels import plain
from calstudy.core.ledger import tables
from calstudy.core.paths import REPO_ROOT
from calstudy.core.stats import median_interval

#: stages of a map row, in the order they run
STAGES = ("base", "screen", "sweep", "grid")
#: the verdict of a point where a trial cannot run (the chain raises)
FAILS = "chain fails"
#: trials per screened end and per judged point the rule asks for (verdict rule, rules 1, 13)
MIN_SCREEN, MIN_SWEEP = 10, 30
#: columns of the map (``robustness.csv``)
MAP_COLUMNS = (
    "claim",
    "stage",
    "input",
    "value",
    "input2",
    "value2",
    "n",
    "median",
    "ci_low",
    "ci_high",
    "verdict",
    "shift",
    "shift_low",
    "shift_high",
    "matters",
    "error",
)
#: columns of the per-claim summary (added to ``claims.csv``)
SUMMARY_COLUMNS = ("id", "robustness", "verdicts", "depends_on", "thresholds", "sentence")


@dataclass(frozen=True)
class Input:
    """One input screened for robustness.

    Attributes
    ----------
    key : str
        Dotted key of the scenario file (``"detection.sigma_px"``), or the keyword of a
        calibrated value the experiment takes (``"drift_scale"``).
    base, low, high : float
        Its value in the scenario and the ends of its range (``low <= base <= high``).
    kind : str
        ``"assumed"`` (range from the ledger) or ``"calibrated"`` (the calibration's
        uncertainty).
    integer : bool
        A count: values are rounded to integers.
    component : int or None
        For one component of a vector input: its index; ``vector`` holds the whole base value.
    vector : tuple
        The base value of a vector input (empty for a scalar).
    claims : tuple of str
        The claims whose computation reads the input (empty: all claims of the map).
    paper : float or None
        Where the paper's own numbers put the input, if they do.
    paper_note : str
        How (the derivation), one line.
    """

    key: str
    base: float
    low: float
    high: float
    kind: str = "assumed"
    integer: bool = False
    component: int | None = None
    vector: tuple = ()
    claims: tuple[str, ...] = ()
    paper: float | None = None
    paper_note: str = ""

    def __post_init__(self) -> None:
        if not self.low <= self.base <= self.high or not self.low < self.high:
            raise CalibrationError(
                f"input {self.label}: base {self.base!r} must lie in its range "
                f"[{self.low!r}, {self.high!r}], low < high"
            )

    @property
    def label(self) -> str:
        """The key, with ``[i]`` for a vector component."""
        return self.key if self.component is None else f"{self.key}[{self.component}]"

    def value(self, x: float) -> float | int:
        """``x`` as the input takes it (an int for a count)."""
        return round(x) if self.integer else float(x)

    def setting(self, x: float) -> dict[str, Any]:
        """The override that sets the input to ``x``: ``{key: value}``, the whole vector for a
        component."""
        if self.component is None:
            return {self.key: self.value(x)}
        vector = list(self.vector)
        vector[self.component] = self.value(x)
        return {self.key: vector}

    def sweep_values(self, size: int) -> list[float | int]:
        """``size`` values over the range (log-spaced when it spans a factor of 10 or more
        above 0), with the base value, sorted and distinct."""
        if self.low > 0 and self.high / self.low >= 10:
            grid = np.geomspace(self.low, self.high, size)
        else:
            grid = np.linspace(self.low, self.high, size)
        # the ends exactly (they are the screened points), the inside to 4 digits
        values = {self.value(float(f"{x:.4g}")) for x in grid[1:-1]}
        values |= {self.value(x) for x in (self.low, self.base, self.high)}
        return sorted(values)


def ledger_inputs(
    model: BaseModel, kinds: Sequence[str] = ("assumed",)
) -> tuple[list[Input], list[str]]:
    """The inputs of a validated scenario file whose provenance is one of ``kinds`` and has a
    range: a scalar is one :class:`Input`, a vector with a range per component one per
    component whose range is not a single value.

    Parameters
    ----------
    model : pydantic.BaseModel
        A validated scenario file (:class:`calstudy.core.ledger.Ledgered`).
    kinds : sequence of str
        The provenance kinds to take.

    Returns
    -------
    (list of Input, list of str)
        The inputs, in the file's order, and the ranged inputs not taken, each with the reason:
        a table of values (a boolean, or a range per entry of a table), a list of points under
        one range per coordinate, or a list of values under one range.
    """
    found, skipped = [], []
    for prefix, table in tables(model):
        prov = table.provenance or {}
        for name in table.input_names():
            entry = prov.get(name)
            if entry is None or entry.kind not in kinds or entry.range is None:
                continue
            key, value = f"{prefix}{name}", getattr(table, name)
            rng = entry.range
            if isinstance(value, bool) or isinstance(rng, dict):
                skipped.append(f"{key}: a table of values; not screened")
            elif isinstance(value, int | float):
                found.append(
                    Input(
                        key,
                        float(value),
                        float(rng[0]),
                        float(rng[1]),
                        entry.kind,
                        isinstance(value, int),
                    )
                )
            elif any(isinstance(v, list) for v in value):
                skipped.append(
                    f"{key}: {len(value)} points under one range per coordinate; not screened"
                )
            elif isinstance(rng[0], list) and len(rng) == len(value):
                for i, ((lo, hi), v) in enumerate(zip(rng, value, strict=True)):
                    if lo < hi:
                        found.append(
                            Input(
                                key,
                                float(v),
                                float(lo),
                                float(hi),
                                entry.kind,
                                isinstance(v, int),
                                i,
                                tuple(value),
                            )
                        )
            else:
                skipped.append(f"{key}: {len(value)} values under one range; not screened")
    return found, skipped


def matches(key: str, keys: Iterable[str]) -> bool:
    """Whether a dotted key is one of ``keys``: equal to one, or under one ending in ``"."``
    (a prefix: ``"poor_start."`` holds ``"poor_start.sigma"``).

    Parameters
    ----------
    key : str
        Dotted key of an input (or the keyword of a calibrated value).
    keys : iterable of str
        Dotted keys and prefixes.

    Returns
    -------
    bool
    """
    return any(key == s or (s.endswith(".") and key.startswith(s)) for s in keys)


def assign_claims(
    inputs: Iterable[Input],
    claims: Iterable[str],
    not_read: Mapping[str, Sequence[str]],
    skipped: list[str],
    only_read: Mapping[str, Sequence[str]] | None = None,
) -> list[Input]:
    """Each input with the claims whose computation reads it (:attr:`Input.claims`); an input
    read by no claim is not screened and goes to ``skipped`` with the reason.

    Parameters
    ----------
    inputs : iterable of Input
        The inputs (from :func:`ledger_inputs`).
    claims : iterable of str
        The claims of the map, in its order.
    not_read : mapping of str to sequence of str
        Claim -> the keys and prefixes (:func:`matches`) its computation does not read (a claim
        not in it reads every input).
    skipped : list of str
        The inputs not screened; appended to in place.
    only_read : mapping of str to sequence of str, optional
        Claim -> the only keys and prefixes it reads (over ``not_read``).

    Returns
    -------
    list of Input
        The inputs read by at least one claim, in their order.
    """
    claims, only_read = list(claims), only_read or {}

    def read(claim: str, key: str) -> bool:
        if claim in only_read:
            return matches(key, only_read[claim])
        return not matches(key, not_read.get(claim, ()))

    out = []
    for item in inputs:
        readers = tuple(c for c in claims if read(c, item.key))
        if not readers:
            skipped.append(f"{item.label}: read by no claim's computation")
            continue
        out.append(dataclasses.replace(item, claims=readers))
    return out


def calibrated_input(
    item: Input | str, value: float, u: float | None, sigmas: float = 2.0, bounds: str = "ledger"
) -> Input:
    """A calibrated input screened over its value +- ``sigmas`` standard uncertainties, with the
    value where the paper's figures put it (:attr:`Input.paper`); with no uncertainty, a ledger
    input over its ledger range around the value.

    Parameters
    ----------
    item : Input or str
        The ledger's input (``bounds="ledger"``), or the keyword of a calibrated value the
        experiment takes, which has no ledger range (``bounds="half"``).
    value : float
        The calibrated value (units of the input).
    u : float or None
        Its standard uncertainty (same units); None: unknown (``"ledger"`` only).
    sigmas : float, default 2.0
        Standard uncertainties on either side.
    bounds : {"ledger", "half"}
        ``"ledger"``: the ends to 4 digits (as a sweep's inside values), within the ledger
        range; ``"half"``: the low end no lower than half the value (a positive scale), the
        ends as computed.

    Returns
    -------
    Input
        Kind ``"calibrated"``, base ``value``.

    Raises
    ------
    CalibrationError
        If ``bounds`` is neither, ``"ledger"`` is asked of a keyword, or the value lies outside
        the ledger range.
    """
    s = sigmas
    note = f"calibrated; value ± {s:g} standard uncertainties ({u or 0:.2g})"
    if bounds == "half" and isinstance(item, str) and u is not None:
        low, high = max(value - s * u, value / 2), value + s * u
        return Input(item, value, low, high, "calibrated", paper=value, paper_note=note)
    if bounds != "ledger" or isinstance(item, str):
        raise CalibrationError(
            f"bounds {bounds!r} of calibrated input {item!r} (uncertainty {u!r}): use 'ledger' "
            "with a ledger input or 'half' with a keyword and its uncertainty"
        )
    if not item.low <= value <= item.high:
        raise CalibrationError(
            f"{item.key} calibrated to {value!r}: outside its ledger range "
            f"[{item.low:g}, {item.high:g}]"
        )
    if u is None:
        note = "calibrated, but not calibrated here: its ledger range"
        return dataclasses.replace(item, base=float(value), paper_note=note)
    return dataclasses.replace(
        item,
        base=float(value),
        paper=float(value),
        low=max(float(f"{value - s * u:.4g}"), item.low),
        high=min(float(f"{value + s * u:.4g}"), item.high),
        paper_note=note,
    )


def select_inputs(inputs: Sequence[Input], only: Sequence[str], scenario: str) -> list[Input]:
    """The inputs a map screens: those named in ``only`` (dotted keys or keywords, a vector's
    components all), every one when it is empty.

    Parameters
    ----------
    inputs : sequence of Input
        The map's inputs.
    only : sequence of str
        The keys to screen (empty: all).
    scenario : str
        What the inputs belong to, for the error (``"selfcal scenario"``).

    Returns
    -------
    list of Input

    Raises
    ------
    CalibrationError
        If ``only`` names an input not among ``inputs``.
    """
    unknown = sorted(set(only) - {item.key for item in inputs})
    if unknown:
        raise CalibrationError(
            f"robustness inputs {unknown} are not screened inputs of the {scenario}"
        )
    return [item for item in inputs if item.key in only] if only else list(inputs)


@dataclass(frozen=True)
class MapSpec:
    """What :func:`robustness_map` needs from a paper (module docstring).

    Attributes
    ----------
    claims : mapping of str to str
        Claim id -> the trial group that computes it (claims of one group share trials).
    inputs : sequence of Input
        The inputs to screen.
    experiment : callable
        ``experiment(group, setting, n_trials) -> Experiment``; ``setting`` maps input keys
        to values (``{}`` at the base). The experiment's name must not depend on ``setting``.
    statistics : callable
        ``statistics(group, rows) -> {claim: (n_trials,) array}``: each claim's per-trial
        statistic (its figure, or its paired effect) from the engine's rows.
    judge : callable
        ``judge(group, rows) -> {claim: Verdict}``: the claims' verdicts by their rule.
    """

    claims: Mapping[str, str]
    inputs: Sequence[Input]
    experiment: Callable[[str, Mapping[str, Any], int], montecarlo.Experiment]
    statistics: Callable[[str, pd.DataFrame], Mapping[str, np.ndarray]]
    judge: Callable[[str, pd.DataFrame], Mapping[str, Any]]
    skipped: Sequence[str] = field(default_factory=tuple)

    def claims_of(self, item: Input) -> list[str]:
        """The claims ``item`` is screened for."""
        return [c for c in self.claims if not item.claims or c in item.claims]

    def groups_of(self, claims: Sequence[str]) -> list[str]:
        """The trial groups that compute ``claims``, in first-seen order."""
        return list(dict.fromkeys(self.claims[c] for c in claims))


def screened_inputs(
    model: BaseModel,
    claims: Iterable[str],
    not_read: Mapping[str, Sequence[str]],
    *,
    kinds: Sequence[str] = ("assumed",),
    only_read: Mapping[str, Sequence[str]] | None = None,
    extra: Sequence[Input] = (),
    unused: Mapping[str, str] | None = None,
) -> tuple[list[Input], list[str]]:
    """The inputs a paper's map screens: the ranged inputs of its validated scenario file
    (:func:`ledger_inputs`) and ``extra``, each with the claims whose computation reads it
    (:func:`assign_claims`).

    Parameters
    ----------
    model : pydantic.BaseModel
        The paper's validated scenario file.
    claims : iterable of str
        The claims of the map, in its order.
    not_read, only_read : mapping of str to sequence of str
        As for :func:`assign_claims`.
    kinds : sequence of str, default ("assumed",)
        The provenance kinds screened.
    extra : sequence of Input
        Inputs the file does not hold (the keyword of a calibrated value), after its own.
    unused : mapping of str to str, optional
        Dotted key -> why no claim reads it in this scenario: not screened, named with the
        reason.

    Returns
    -------
    (list of Input, list of str)
        The inputs, in the file's order, and the ranged inputs not screened, with the reason.
    """
    found, skipped = ledger_inputs(model, kinds)
    unused = unused or {}
    skipped += [f"{item.label}: {unused[item.key]}" for item in found if item.key in unused]
    found = [item for item in [*found, *extra] if item.key not in unused]
    return assign_claims(found, claims, not_read, skipped, only_read), skipped


def paper_spec(
    claims: Mapping[str, str],
    inputs: tuple[Sequence[Input], Sequence[str]],
    experiment: Callable[[str, Mapping[str, Any], int], montecarlo.Experiment],
    statistics: Callable[[str, pd.DataFrame], Mapping[str, np.ndarray]],
    judge: Callable[[str, pd.DataFrame], Mapping[str, Any]],
    *,
    only: Sequence[str],
    scenario: str,
) -> MapSpec:
    """A paper's :class:`MapSpec`: its claims and trial functions, over the inputs ``only``
    names (:func:`select_inputs`; every input when it is empty).

    Parameters
    ----------
    claims : mapping of str to str
        Claim id -> the trial group that computes it.
    inputs : (sequence of Input, sequence of str)
        The inputs and the ranged inputs not screened (:func:`screened_inputs`).
    experiment, statistics, judge : callable
        As :class:`MapSpec` takes them.
    only, scenario
        As for :func:`select_inputs`, which raises when ``only`` names an input not among
        ``inputs``.

    Returns
    -------
    MapSpec
    """
    chosen = select_inputs(inputs[0], only, scenario)
    return MapSpec(claims, tuple(chosen), experiment, statistics, judge, tuple(inputs[1]))


class _Runner:
    """Runs and remembers the points of one map: (group, setting) -> (statistics, verdicts)."""

    def __init__(self, spec: MapSpec, seed: int, engine: Mapping[str, Any]):
        self.spec, self.seed = spec, seed
        # an empty scheduler or cache folder (a notebook parameter left "") means none
        self.engine = {
            k: (v or None) if k in ("scheduler", "cache_dir") else v for k, v in engine.items()
        }
        self.trials: list[pd.DataFrame] = []

    def point(
        self, group: str, setting: Mapping[str, Any], n: int, where: Mapping[str, Any] | None
    ):
        """``(statistics, verdicts, error)`` of one group at one setting, ``n`` trials; the
        per-trial statistics are kept under ``where`` (None: not kept)."""
        try:
            exp = self.spec.experiment(group, dict(setting), n)
            rows = montecarlo.run(exp, self.seed, **self.engine)
        except CalibrationError as exc:
            # the map is a result: a study file is named from the repository, not this machine
            text = str(exc).splitlines()[0].replace(f"{REPO_ROOT}{os.sep}", "")
            return {}, {}, text[:300]
        stats = self.spec.statistics(group, rows)
        stats = {c: np.asarray(s, dtype=float) for c, s in stats.items()}
        for claim, values in stats.items():
            if where is not None:
                frame = {**where, "claim": claim, "trial": np.arange(len(values))}
                self.trials.append(pd.DataFrame({**frame, "statistic": values}))
        return stats, dict(self.spec.judge(group, rows)), ""


def _shift(end: np.ndarray, base: np.ndarray) -> tuple[float, float, float]:
    """Median paired difference ``end - base`` over the common trials, with its 95 % interval,
    relative to the base median."""
    n = min(len(end), len(base))
    scale = abs(float(np.median(base[:n]))) or 1.0
    med, lo, hi = median_interval(end[:n] - base[:n])
    return med / scale, lo / scale, hi / scale


def _row(claim, stage, where, n, verdict=None, shift=None, matters=None, error="") -> dict:
    v = verdict
    row = {
        "claim": claim,
        "stage": stage,
        "input": "",
        "value": np.nan,
        "input2": "",
        "value2": np.nan,
        **where,
        "n": n,
    }
    row.update(
        median=getattr(v, "median", np.nan),
        ci_low=getattr(v, "ci_low", np.nan),
        ci_high=getattr(v, "ci_high", np.nan),
        verdict=getattr(v, "verdict", FAILS),
    )
    s = shift if shift is not None else (np.nan, np.nan, np.nan)
    row.update(shift=s[0], shift_low=s[1], shift_high=s[2])
    row.update(matters="" if matters is None else ("yes" if matters else "no"), error=error)
    return row


def robustness_map(
    spec: MapSpec,
    seed: int,
    *,
    n_screen: int = 10,
    n_sweep: int = 30,
    sweep_size: int = 5,
    min_shift: float = 0.05,
    engine: Mapping[str, Any] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Screen, sweep and grid the inputs of ``spec`` (module docstring).

    Parameters
    ----------
    spec : MapSpec
        The claims, inputs and functions.
    seed : int
        The run's seed (the same at every point: paired trials).
    n_screen : int, default 10
        Trials per end of the screen (the rule: at least 10; the 95 % interval of the median
        of 10 paired differences is ``[x_(2), x_(9)]``, so it excludes 0 only when 9 of the 10
        trials move the same way, and no single trial decides).
    n_sweep : int, default 30
        Trials per point of the base, the sweeps and the grids (rule 1: at least 30).
    sweep_size : int, default 5
        Values over the range of a swept input, besides its base value.
    min_shift : float, default 0.05
        Smallest relative median paired difference that makes an input matter (with paired
        seeds a change of the last digits is significant; this asks that it be material).
    engine : mapping, optional
        Keywords of :func:`calstudy.core.montecarlo.run` (``n_jobs``, ``cache_dir``,
        ``progress``, ``scheduler``).

    Returns
    -------
    (pandas.DataFrame, pandas.DataFrame)
        The map (columns :data:`MAP_COLUMNS`, one row per claim and point) and the per-trial
        statistics behind it (claim, stage, input, value, input2, value2, trial, statistic).

    Raises
    ------
    CalibrationError
        If ``n_screen`` or ``n_sweep`` is below 6 (no 95 % interval of the median) or
        ``sweep_size`` below 2, or the base point fails. Counts below the rule's 10 and 30 run
        (quick checks); the map records N and :func:`claim_summary` says so.
    """
    if min(n_screen, n_sweep) < 6 or sweep_size < 2:
        raise CalibrationError(
            f"n_screen {n_screen} and n_sweep {n_sweep} must be at least 6 (a 95 % interval "
            f"of the median), sweep_size {sweep_size} at least 2"
        )
    engine = engine or {}
    run = _Runner(spec, seed, engine)
    rows: list[dict] = []
    base: dict[str, tuple] = {}
    for group in spec.groups_of(list(spec.claims)):
        stats, verdicts, error = run.point(group, {}, n_sweep, {"stage": "base"})
        if error:
            raise CalibrationError(f"the base point of group {group!r} fails: {error}")
        base[group] = (stats, verdicts)
        rows += [_row(c, "base", {}, n_sweep, verdicts[c]) for c in stats]
    # the base judged on the screen's trials (the first n_screen of its own)
    base_screen = {g: run.point(g, {}, n_screen, None)[1] for g in base}
    shifts: dict[tuple[str, str], float] = {}
    for item in spec.inputs:
        claims = spec.claims_of(item)
        for end in (item.low, item.high):
            where = {"input": item.label, "value": item.value(end)}
            for group in spec.groups_of(claims):
                stats, verdicts, error = run.point(
                    group, item.setting(end), n_screen, {"stage": "screen", **where}
                )
                for c in (c for c in claims if spec.claims[c] == group):
                    if error:
                        rows.append(_row(c, "screen", where, n_screen, error=error, matters=True))
                        # swept (where does it fail?), ranked last for the grid
                        shifts.setdefault((c, item.label), -1.0)
                        continue
                    s = _shift(stats[c], base[group][0][c])
                    base_v = base_screen[group][c].verdict
                    moved = (s[1] > 0 or s[2] < 0) and abs(s[0]) >= min_shift
                    matters = verdicts[c].verdict != base_v or moved
                    rows.append(_row(c, "screen", where, n_screen, verdicts[c], s, matters))
                    if matters:
                        shifts[c, item.label] = max(shifts.get((c, item.label), 0), abs(s[0]))
    by_label = {item.label: item for item in spec.inputs}
    for label in dict.fromkeys(lab for _, lab in shifts):
        item = by_label[label]
        claims = [c for c in spec.claims_of(item) if (c, label) in shifts]
        for x in item.sweep_values(sweep_size):
            rows += _judged(
                spec,
                run,
                item.setting(x),
                claims,
                n_sweep,
                base,
                {"stage": "sweep", "input": label, "value": x},
            )
    for claim in spec.claims:
        ranked = sorted(((s, lab) for (c, lab), s in shifts.items() if c == claim), reverse=True)
        if len(ranked) < 2:
            continue
        a, b = by_label[ranked[0][1]], by_label[ranked[1][1]]
        for xa in dict.fromkeys(a.value(x) for x in (a.low, a.base, a.high)):
            for xb in dict.fromkeys(b.value(x) for x in (b.low, b.base, b.high)):
                setting = {**a.setting(xa), **b.setting(xb)} if a.key != b.key else None
                if setting is None:
                    continue
                where = {
                    "stage": "grid",
                    "input": a.label,
                    "value": xa,
                    "input2": b.label,
                    "value2": xb,
                }
                rows += _judged(spec, run, setting, [claim], n_sweep, base, where)
    table = pd.DataFrame(rows, columns=list(MAP_COLUMNS))
    trials = pd.concat(run.trials, ignore_index=True) if run.trials else pd.DataFrame()
    cols = ["claim", "stage", "input", "value", "input2", "value2", "trial", "statistic"]
    return table, trials.reindex(columns=cols)


def _judged(spec, run, setting, claims, n, base, where) -> list[dict]:
    out = []
    spot = {k: v for k, v in where.items() if k != "stage"}
    for group in spec.groups_of(claims):
        stats, verdicts, error = run.point(group, setting, n, where)
        for c in (c for c in claims if spec.claims[c] == group):
            if error:
                out.append(_row(c, where["stage"], spot, n, error=error))
            else:
                s = _shift(stats[c], base[group][0][c])
                out.append(_row(c, where["stage"], spot, n, verdicts[c], s))
    return out


# ----------------------------------------------------------------------------------------------
# where a verdict changes along a sweep


def verdict_runs(values: Sequence, verdicts: Sequence[str]) -> list[tuple[str, list]]:
    """Where a verdict changes along a sweep: the runs of equal verdicts in the order given.

    Parameters
    ----------
    values : sequence, length M
        The swept values, one per point.
    verdicts : sequence of str, length M
        The verdict at each point.

    Returns
    -------
    list of (str, list)
        ``(verdict, values of the run)`` per run of consecutive equal verdicts; one run when
        the verdict does not change.

    Raises
    ------
    CalibrationError
        If there are no points or the lengths differ.
    """
    values, verdicts = list(values), [str(v) for v in verdicts]
    if len(values) != len(verdicts) or not values:
        raise CalibrationError(f"{len(values)} values but {len(verdicts)} verdicts")
    runs: list[tuple[str, list]] = []
    for value, verdict in zip(values, verdicts, strict=True):
        if runs and runs[-1][0] == verdict:
            runs[-1][1].append(value)
        else:
            runs.append((verdict, [value]))
    return runs


def verdict_changes(
    values: Sequence,
    verdicts: Sequence[str],
    text: str = "from {a} at {x} to {b} at {y}",
    fmt: Callable[[Any], str] = "{:g}".format,
) -> list[str]:
    """Where a verdict changes along a sweep, one text per change (none when it holds).

    Parameters
    ----------
    values : sequence, length M
        The swept values, in the order of the sweep (ascending).
    verdicts : sequence of str, length M
        The verdict at each point.
    text : str, default "from {a} at {x} to {b} at {y}"
        The words of one change: ``{a}`` and ``{b}`` the verdicts before and after, ``{x}``
        the last value with ``{a}`` and ``{y}`` the first with ``{b}``, written by ``fmt``.
    fmt : callable, default ``"{:g}".format``
        Writes a value.

    Returns
    -------
    list of str
        One text per change; empty when the verdict holds or there are no points.

    Raises
    ------
    CalibrationError
        If the lengths differ (:func:`verdict_runs`).
    """
    if not len(values) and not len(verdicts):
        return []
    runs = verdict_runs(values, verdicts)
    pairs = zip(runs, runs[1:], strict=False)
    return [text.format(a=a, x=fmt(xa[-1]), b=b, y=fmt(xb[0])) for (a, xa), (b, xb) in pairs]


# ----------------------------------------------------------------------------------------------
# reading a map


def _number(x: float) -> str:
    return f"{x:.3g}"


def thresholds(table: pd.DataFrame, claim: str, label: str) -> list[str]:
    """Where the verdict of ``claim`` changes along the sweep of ``label``: one text per
    change, ``"not reproduced -> reproduced between 0.02 and 0.0283"``."""
    sweep = table[
        (table["claim"] == claim) & (table["stage"] == "sweep") & (table["input"] == label)
    ].sort_values("value")
    text = "{a} -> {b} between {x} and {y}"
    return verdict_changes(sweep["value"].tolist(), sweep["verdict"].tolist(), text, _number)


def claim_summary(
    table: pd.DataFrame,
    inputs: Sequence[Input],
    skipped=(),
    verdicts: Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """Per claim of a map: robust or conditional, the verdicts taken, the inputs its verdict
    depends on (a swept verdict changes along them), the thresholds of every input that
    matters (and where the chain cannot run) and one sentence for the chapter (columns
    :data:`SUMMARY_COLUMNS`).

    Parameters
    ----------
    table : pandas.DataFrame
        A map from :func:`robustness_map`.
    inputs : sequence of Input
        The map's inputs (for where the paper's numbers put them).
    skipped : sequence of str
        Ranged inputs the map did not screen, with the reason (named in the sentence).
    verdicts : mapping of str to str, optional
        Each claim's verdict on the notebook's own trials at the scenario's values (the claims
        table). Where it differs from the verdict of the map's base point (fewer trials), the
        scenario lies near a threshold: the claim takes both verdicts, so it is conditional,
        and the sentence gives both.
    """
    by_label = {item.label: item for item in inputs}
    rows = []
    for claim, t in table.groupby("claim", sort=False):
        judged = t[t["stage"].isin(["base", "sweep", "grid"]) & (t["error"] == "")]
        base = t[t["stage"] == "base"].iloc[0]
        base_v = base["verdict"]
        full_v = (verdicts or {}).get(claim, base_v)
        taken = list(dict.fromkeys([full_v, base_v, *judged["verdict"]]))
        screen = t[t["stage"] == "screen"]
        matter = list(dict.fromkeys(screen.loc[screen["matters"] == "yes", "input"]))
        screened = screen["input"].nunique()
        parts, sentences, moved, failing, depends = [], [], [], [], []
        for label in matter:
            item = by_label[label]
            own = t[(t["input"] == label) & t["stage"].isin(["screen", "sweep"])]
            changes = [c for c in thresholds(t, claim, label) if FAILS not in c]
            fails = sorted(set(own.loc[own["error"] != "", "value"]))
            if fails:
                failing.append(f"{label} {', '.join(_number(v) for v in fails)}")
            text = "; ".join(changes) or "the verdict holds over its range"
            paper = f"; paper {_number(item.paper)}" if item.paper is not None else ""
            fail = f"; {FAILS} at {_number(fails[0])}" if fails else ""
            parts.append(f"{label}: {text}{paper}{fail}")
            if not changes:
                moved.append(label)
                continue
            depends.append(label)
            where = f"; {item.paper_note}" if item.paper_note else ""
            if item.paper is not None:
                where = f"; the paper's numbers put it at {_number(item.paper)}" + (
                    f" ({item.paper_note})" if item.paper_note else ""
                )
            sentences.append(
                f"{label} (range {_number(item.low)}-{_number(item.high)}, here "
                f"{_number(item.base)}: {text}{where})"
            )
        robust = len(taken) == 1
        near = (
            ""
            if full_v == base_v
            else f" on its own trials, {base_v} on the {base['n']} trials of the map's point "
            "there (the scenario lies near a threshold),"
        )
        head = (
            f"{claim} is {full_v} at the scenario's values{near} and "
            f"{'robust' if robust else 'conditional'} over the {screened} inputs screened"
        )
        body = "; its verdict depends on " + "; ".join(sentences) if sentences else ""
        if moved:
            body += f"; its figure moves with {', '.join(moved)}, its verdict does not"
        if failing:
            body += f"; the simulated chain cannot run at {'; '.join(failing)}"
        body = body or ": no input moves it"
        tail = f" ({len(skipped)} ranged inputs not screened)" if len(skipped) else ""
        n_screen, n_judged = screen["n"].min(), t.loc[t["stage"] != "screen", "n"].min()
        if n_screen < MIN_SCREEN or n_judged < MIN_SWEEP:
            tail += (
                f" (N = {n_screen} per screened end, {n_judged} per judged point: below the rule)"
            )
        rows.append(
            {
                "id": claim,
                "robustness": "robust" if robust else "conditional",
                "verdicts": "; ".join(taken),
                "depends_on": "; ".join(depends),
                "thresholds": " | ".join(parts),
                "sentence": plain(head + body + tail + "."),
            }
        )
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


def point_setting(spec: MapSpec, labels: Sequence[str], values: Sequence[float]) -> dict:
    """The setting of a map row: its inputs (labels) at its values, for rebuilding a point."""
    by_label = {item.label: item for item in spec.inputs}
    setting: dict = {}
    for label, value in zip(labels, values, strict=True):
        if label:
            setting.update(by_label[label].setting(value))
    return setting


__all__ = [
    "assign_claims",
    "calibrated_input",
    "matches",
    "paper_spec",
    "point_setting",
    "screened_inputs",
    "select_inputs",
    "MAP_COLUMNS",
    "STAGES",
    "SUMMARY_COLUMNS",
    "Input",
    "MapSpec",
    "claim_summary",
    "ledger_inputs",
    "robustness_map",
    "thresholds",
    "verdict_changes",
    "verdict_runs",
]
