"""Verdicts of the claims register by the v2 rule (rules 1-9 of *How a verdict is computed*,
the book's claims page, written by :mod:`calstudy.io.book`).

A *trial* is one simulated replication of a paper's experiment; its *figure* is what the paper
reports; its *effect* compares the figure with no effect (a paired ratio, no effect 1; a paired
difference, no effect 0; or the value itself against a stated reference). :func:`judge` computes
one claim's :class:`Verdict` from the per-trial figures:

- reproduced figure: the median over trials with the order-statistic 95 % interval of
  :func:`calstudy.core.stats.median_interval` (rule 2);
- significant: the interval of the median effect lies strictly on the claimed side of no effect
  (rule 3); magnitude: the median within a factor 1.5 of the published figure, or 10 percentage
  points for percentages (rule 4); verdict by rule 5; requirements (``kind="bound"``) by rule 7;
- replication rate: the share of trials whose own effect has the claimed direction (rule 6).

Controls (rule 8) are judged on the same trials by :func:`judge_controls`, then checked with
:func:`check_null_control` and :func:`oracle_gate`; :func:`not_testable` records rule 9.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.core.stats import (
    interval_level,
    median_interval,
    rms_ratio_interval,
    trial_values,
)

#: The four verdicts of the claims register.
VERDICTS = ("reproduced", "direction only", "not reproduced", "not testable")
#: How a claim's figure is compared: see :func:`judge`.
KINDS = ("ratio", "value", "percent", "bound")
#: The side of no effect (or of the bound) the paper claims.
DIRECTIONS = ("lower", "higher")
_OTHER = {"lower": "higher", "higher": "lower"}
_NAN = math.nan
_FIGURES = ("median", "ci_low", "ci_high", "effect_median", "effect_low", "effect_high", "null")
_FIGURES += ("replication_rate", "p95")


@dataclass(frozen=True)
class Verdict:
    """One claim's verdict with the figures behind it.

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`.
    kind : str
        One of :data:`KINDS`.
    n : int
        Number of trials (0 when nothing ran).
    median, ci_low, ci_high : float
        Reproduced figure: median over trials and its order-statistic confidence interval.
    effect_median, effect_low, effect_high : float
        The same for the effect (for ``"bound"``: the figure itself, compared with the bound).
    null : float
        No effect: 1 for a ratio, 0 for a paired difference, the stated reference, or the bound.
    significant : bool
        Effect interval strictly on the claimed side of ``null``; for ``"bound"``: the median
        meets the bound.
    in_band : bool
        Median within the magnitude band of the published figure (True when there is no
        published size: the band does not apply); for ``"bound"``: :attr:`p95` meets the bound.
    replication_rate : float
        Share of trials whose own effect has the claimed direction (for ``"bound"``: meets it).
    p95 : float
        ``"bound"`` only (NaN otherwise): the figure met in 95 % of trials, the 95th percentile
        for ``direction="lower"`` and the 5th for ``"higher"``.
    note : str
        One line saying why, numbers to 3 significant digits.
    """

    verdict: str
    kind: str
    n: int
    median: float
    ci_low: float
    ci_high: float
    effect_median: float
    effect_low: float
    effect_high: float
    null: float
    significant: bool
    in_band: bool
    replication_rate: float
    p95: float
    note: str

    def __post_init__(self) -> None:
        _check_choice("verdict", self.verdict, VERDICTS)
        _check_choice("kind", self.kind, KINDS)
        if "\n" in self.note or not self.note.strip():
            raise CalibrationError(f"a verdict note must be one non-empty line; got {self.note!r}")


# ----------------------------------------------------------------------------------------------
# input checks


def _check_choice(name: str, value: object, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise CalibrationError(f"{name} is {value!r}; expected one of {', '.join(allowed)}")


def _finite(name: str, value: object) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"{name} is {value!r}; expected a finite number") from exc
    if not math.isfinite(x):
        raise CalibrationError(f"{name} is {x!r}; expected a finite number")
    return x


# ----------------------------------------------------------------------------------------------
# statistics


def replication_rate(effect: object, null: float, direction: str) -> float:
    """Share of trials whose own effect lies strictly on the claimed side of ``null`` (rule 6).

    Parameters
    ----------
    effect : array_like, shape (N,)
        Per-trial effect (paired ratio, difference, or the value itself).
    null : float
        No effect; a trial exactly at ``null`` does not count.
    direction : {"lower", "higher"}
        The claimed side.
    """
    _check_choice("direction", direction, DIRECTIONS)
    e, null = trial_values("effect", effect), _finite("null", null)
    return float(np.mean(e < null if direction == "lower" else e > null))


# ----------------------------------------------------------------------------------------------
# the rule


def _rule5(significant: bool, in_band: bool) -> str:
    if not significant:
        return "not reproduced"
    return "reproduced" if in_band else "direction only"


def _fixed_null(null: object, value: float, what: str) -> None:
    if null is not None and _finite("null", null) != value:
        raise CalibrationError(f"null is {null!r} but no effect of {what} is {value:g}; omit null")


def _effect(
    kind: str, s: np.ndarray, baseline: object, null: object
) -> tuple[np.ndarray, np.ndarray, float]:
    """Figure, effect and no-effect value of a ratio, value or percent claim."""
    if baseline is not None:
        b = trial_values("baseline", baseline)
        if b.shape != s.shape:
            raise CalibrationError(
                f"baseline has {b.size} trials but samples {s.size}; pair them trial by trial"
            )
        if kind != "ratio":
            _fixed_null(null, 0.0, "a paired difference")
            return s, s - b, 0.0
        if np.any(b <= 0):
            i = int(np.flatnonzero(b <= 0)[0])
            raise CalibrationError(
                f"baseline is zero or negative in {int(np.sum(b <= 0))} of {b.size} trials "
                f"(first {b[i]:.3g} at trial {i}); a ratio needs a positive baseline"
            )
        _fixed_null(null, 1.0, "a ratio")
        ratio = s / b
        return ratio, ratio, 1.0
    if kind == "ratio":
        _fixed_null(null, 1.0, "a ratio")
        return s, s, 1.0
    if null is None:
        raise CalibrationError(f"a {kind} claim needs null (the stated reference) or a baseline")
    return s, s, _finite("null", null)


def _published(kind: str, published: object) -> float | None:
    if published is None:
        return None
    p = _finite("published", published)
    if kind == "ratio" and p <= 0:
        raise CalibrationError(f"published ratio is {p:.3g}; a ratio must be positive")
    if kind == "value" and p == 0:
        raise CalibrationError("published value is 0; a factor band around 0 is empty")
    return p


def _significance(
    emed: float, elo: float, ehi: float, null: float, direction: str
) -> tuple[bool, str]:
    """Rule 3, and the note's account of it (naming a wrong-side significance)."""
    below, above = ehi < null, elo > null
    significant, wrong = (below, above) if direction == "lower" else (above, below)
    text = f"effect {emed:.3g} [{elo:.3g}, {ehi:.3g}]"
    if significant:
        return True, f"{text} significantly {direction} than {null:.3g}"
    if wrong:
        return False, f"{text} significantly {_OTHER[direction]} than {null:.3g}: the wrong side"
    return False, f"{text} not significantly {direction} than {null:.3g}"


def _magnitude(
    kind: str, med: float, published: float | None, factor: float, band_pp: float
) -> tuple[bool, str]:
    """Rule 4, and the note's account of it; no published size: the band does not apply."""
    if published is None:
        return True, f"median {med:.3g}; no published size, significance alone decides"
    if kind == "percent":
        in_band, band = abs(med - published) <= band_pp, f"{band_pp:.3g} pp"
    else:
        in_band, band = 1.0 / factor <= med / published <= factor, f"factor {factor:.3g}"
    where = "within" if in_band else "outside"
    return bool(in_band), f"median {med:.3g} {where} {band} of published {published:.3g}"


def _tail(rate: float, n: int, min_trials: int) -> str:
    text = f"replication rate {rate:.3g}; N={n}"
    if n < min_trials:
        text += f"; only {n} trials (rule asks >= {min_trials})"
    return text


def _judge_effect(
    kind: str,
    direction: str,
    s: np.ndarray,
    baseline: object,
    null: object,
    published: object,
    band: tuple[float, float],
    level: float,
    min_trials: int,
) -> Verdict:
    figure, effect, null = _effect(kind, s, baseline, null)
    published = _published(kind, published)
    med, lo, hi = median_interval(figure, level)
    emed, elo, ehi = (med, lo, hi) if effect is figure else median_interval(effect, level)
    significant, why_effect = _significance(emed, elo, ehi, null, direction)
    in_band, why_size = _magnitude(kind, med, published, *band)
    rate = replication_rate(effect, null, direction)
    note = f"{why_effect}; {why_size}; {_tail(rate, s.size, min_trials)}"
    figures = (med, lo, hi, emed, elo, ehi, null)
    verdict = _rule5(significant, in_band)
    return Verdict(verdict, kind, s.size, *figures, significant, in_band, rate, _NAN, note)


def _judge_bound(
    direction: str, s: np.ndarray, bound: object, others: dict, level: float, min_trials: int
) -> Verdict:
    if bound is None:
        raise CalibrationError("a bound claim needs bound (the requirement, e.g. 0.42 for 0.42 mm)")
    bound = _finite("bound", bound)
    for name, value in others.items():
        if value is not None:
            raise CalibrationError(f"{name} does not apply to a bound claim (bound {bound:.3g})")
    med, lo, hi = median_interval(s, level)
    lower = direction == "lower"
    worst = float(np.quantile(s, 0.95 if lower else 0.05))
    sign = 1.0 if lower else -1.0  # meeting the bound: sign * (figure - bound) <= 0
    median_ok, worst_ok = sign * (med - bound) <= 0, sign * (worst - bound) <= 0
    rate = float(np.mean(sign * (s - bound) <= 0))
    op, quantile = ("<=", "95th") if lower else (">=", "5th")
    note = (
        f"median {med:.3g} [{lo:.3g}, {hi:.3g}] {'meets' if median_ok else 'misses'} the bound "
        f"{op} {bound:.3g}; {quantile} percentile {worst:.3g} "
        f"{'meets' if worst_ok else 'misses'} it; {_tail(rate, s.size, min_trials)}"
    )
    figures = (med, lo, hi, med, lo, hi, bound)
    verdict = _rule5(median_ok, worst_ok)
    return Verdict(verdict, "bound", s.size, *figures, median_ok, worst_ok, rate, worst, note)


#: Magnitude band of rule 4: the median within this factor of the published figure ...
FACTOR = 1.5
#: ... or within this many percentage points of a published percentage.
BAND_PP = 10.0


def judge(
    samples: object,
    *,
    kind: str,
    direction: str,
    published: float | None = None,
    baseline: object = None,
    null: float | None = None,
    bound: float | None = None,
    factor: float = FACTOR,
    band_pp: float = BAND_PP,
    level: float = 0.95,
    min_trials: int = 200,
) -> Verdict:
    """Verdict of one claim from its per-trial figures, by the v2 rule.

    Parameters
    ----------
    samples : array_like, shape (N,)
        One figure per trial (for ``"ratio"`` with a ``baseline``: the numerator, after).
    kind : {"ratio", "value", "percent", "bound"}
        ``"ratio"``: effect ``samples / baseline`` per trial (or ``samples`` are ratios already),
        no effect 1, the figure is the ratio, band a factor of ``published``. ``"value"``: the
        figure is ``samples``, effect ``samples - baseline`` (no effect 0) or ``samples`` against
        the stated reference ``null``, band a factor. ``"percent"``: as ``"value"``, band
        ``band_pp`` percentage points. ``"bound"``: a requirement (rule 7), see ``bound``.
    direction : {"lower", "higher"}
        Claimed side of no effect; for ``"bound"``, ``"lower"`` means the figure must be
        ``<= bound``, ``"higher"`` ``>= bound``.
    published : float, optional
        Published figure; None for a direction claim without size (significance alone decides
        and the note says so). Not for ``"bound"``.
    baseline : array_like, shape (N,), optional
        Paired figure of the same trials without the method (before); positive for a ratio.
    null : float, optional
        Stated reference of a ``"value"``/``"percent"`` claim without baseline (required there);
        otherwise fixed by the kind and best omitted.
    bound : float, optional
        The requirement of a ``"bound"`` claim (required there, refused elsewhere).
    factor : float, default 1.5
        Magnitude band of ``"ratio"`` and ``"value"``: ``published / factor <= median <=
        published * factor`` (same sign).
    band_pp : float, default 10
        Magnitude band of ``"percent"``, in percentage points.
    level : float, default 0.95
        Coverage of the order-statistic intervals (:func:`calstudy.core.stats.median_interval`).
    min_trials : int, default 200
        Rule 1: fewer trials do not change the verdict, but the note says so.

    Returns
    -------
    Verdict
        ``"reproduced"`` (significant and in band), ``"direction only"`` (significant, out of
        band), ``"not reproduced"`` (not significant, or significant on the wrong side). For
        ``"bound"``: ``"reproduced"`` when the 95th percentile (5th for ``"higher"``) meets the
        bound, ``"direction only"`` when only the median does, else ``"not reproduced"``.

    Raises
    ------
    CalibrationError
        On an unknown kind or direction, samples or baseline not (N,), of unequal N or not
        finite, too few trials for the interval, a zero or negative baseline in a ratio, a
        missing ``bound`` or ``null``, an argument that does not apply to the kind, a
        non-positive published ratio, a zero published value, or ``factor <= 1``.
    """
    _check_choice("kind", kind, KINDS)
    _check_choice("direction", direction, DIRECTIONS)
    level = interval_level(level)
    if not _finite("factor", factor) > 1.0 or not _finite("band_pp", band_pp) >= 0.0:
        raise CalibrationError(f"factor is {factor!r} (must exceed 1), band_pp {band_pp!r} (>= 0)")
    if int(min_trials) < 1:
        raise CalibrationError(f"min_trials is {min_trials!r}; expected at least 1")
    min_trials = int(min_trials)
    s = trial_values("samples", samples)
    if kind == "bound":
        others = {"published": published, "baseline": baseline, "null": null}
        return _judge_bound(direction, s, bound, others, level, min_trials)
    if bound is not None:
        raise CalibrationError(f"bound {bound!r} applies only to kind 'bound', not {kind!r}")
    band = (float(factor), float(band_pp))
    return _judge_effect(kind, direction, s, baseline, null, published, band, level, min_trials)


def judge_rms_ratio(
    after: object,
    before: object,
    *,
    bound: float,
    direction: str = "lower",
    level: float = 0.95,
    min_trials: int = 200,
) -> Verdict:
    """A requirement on a pooled, paired figure: the RMS of ``after`` over the RMS of ``before``
    on the same trials must meet ``bound`` (a ``"bound"`` verdict, rule 7 read for a pooled
    statistic).

    Rule 7 asks the 95th percentile of a per-trial figure to meet the bound. A per-trial ratio
    of two errors that share an error source has a tail set by its small denominators, which
    even a perfect method cannot meet; the pooled ratio has no such tail. It is ``reproduced``
    when its whole confidence interval (:func:`calstudy.core.stats.rms_ratio_interval`) meets
    the bound, ``direction only`` when the estimate does but the interval reaches beyond it,
    ``not reproduced`` when the estimate does not.

    Parameters
    ----------
    after, before : array_like, shape (N,)
        Per trial, the method's error and the rival's (or no method's) error on the same data.
    bound : float
        The largest (``"lower"``) or smallest (``"higher"``) RMS ratio that meets the
        requirement.
    direction : {"lower", "higher"}, default "lower"
    level : float, default 0.95
        Coverage of the interval.
    min_trials : int, default 200
        Rule 1: fewer trials do not change the verdict, but the note says so.

    Returns
    -------
    Verdict
        Kind ``"bound"``: ``median`` and ``effect_median`` hold the RMS ratio, the interval its
        confidence interval, ``null`` the bound, ``replication_rate`` the share of trials whose
        own ratio meets the bound, ``p95`` NaN (no per-trial figure is judged).

    Raises
    ------
    CalibrationError
        On a bad direction, level or bound, and as :func:`calstudy.core.stats.rms_ratio_interval`.
    """
    _check_choice("direction", direction, DIRECTIONS)
    bound = _finite("bound", bound)
    ratio, lo, hi = rms_ratio_interval(after, before, level)
    a, b = trial_values("after", after), trial_values("before", before)
    lower = direction == "lower"
    sign = 1.0 if lower else -1.0  # meeting the bound: sign * (figure - bound) <= 0
    far = hi if lower else lo
    estimate_ok, interval_ok = sign * (ratio - bound) <= 0, sign * (far - bound) <= 0
    rate = float(np.mean(sign * (a - bound * b) <= 0))
    op = "<=" if lower else ">="
    note = (
        f"RMS ratio {ratio:.3g} [{lo:.3g}, {hi:.3g}] (paired, pooled over trials): estimate "
        f"{'meets' if estimate_ok else 'misses'} the bound {op} {bound:.3g}, interval "
        f"{'meets' if interval_ok else 'reaches beyond'} it; {_tail(rate, a.size, min_trials)}"
    )
    figures = (ratio, lo, hi, ratio, lo, hi, bound)
    verdict = _rule5(estimate_ok, interval_ok)
    return Verdict(verdict, "bound", a.size, *figures, estimate_ok, interval_ok, rate, _NAN, note)


def not_testable(reason: str, *, kind: str = "value", n: int = 0) -> Verdict:
    """A ``"not testable"`` verdict (rule 9): NaN figures, ``reason`` as the note.

    Parameters
    ----------
    reason : str
        One line: hardware a simulation cannot stand in for, the missing mechanism, or the two
        sides identical by construction.
    kind : str, default "value"
        The comparison the claim would use (one of :data:`KINDS`).
    n : int, default 0
        Trials that ran (for example those of a failed oracle control).
    """
    if not isinstance(reason, str) or not reason.strip():
        raise CalibrationError(f"a not-testable verdict needs a reason; got {reason!r}")
    if int(n) < 0:
        raise CalibrationError(f"n is {n!r}; expected a trial count >= 0")
    flags = {"significant": False, "in_band": False, "note": reason.strip()}
    return Verdict("not testable", kind, int(n), **dict.fromkeys(_FIGURES, _NAN), **flags)


# ----------------------------------------------------------------------------------------------
# controls


def judge_controls(
    samples: object,
    null_samples: object,
    oracle_samples: object,
    *,
    published: float | None = None,
    **rule: Any,
) -> tuple[Verdict, Verdict, Verdict]:
    """Judge a claim and its two controls (rule 8) on the same trials.

    All three share ``rule``, including the paired ``baseline``; the controls have no published
    size, so significance decides. Then :func:`check_null_control` and :func:`oracle_gate`.

    Parameters
    ----------
    samples, null_samples, oracle_samples : array_like, shape (N,)
        Per trial: the method's figure; the figure with the method replaced by doing nothing
        (null control); the figure with the error source the method targets removed from the
        simulation, what a perfect correction would reach (oracle control).
    published : float, optional
        The claim's published figure (the claim only).
    **rule
        ``kind``, ``direction`` and the other keywords of :func:`judge`.

    Returns
    -------
    (Verdict, Verdict, Verdict)
        Claim, null control, oracle control.

    Examples
    --------
    >>> claim, null_v, oracle_v = judge_controls(after, before, oracle, baseline=before,
    ...                                          kind="ratio", direction="lower", published=0.84)
    >>> check_null_control(null_v)          # raises if the test is broken
    >>> final = oracle_gate(claim, oracle_v, mechanism="circle-of-confusion defocus")
    """
    n = trial_values("samples", samples).size
    for name, values in (("null control", null_samples), ("oracle control", oracle_samples)):
        m = trial_values(name, values).size
        if m != n:
            raise CalibrationError(f"{name} has {m} trials but the claim {n}; use the same trials")
    return (
        judge(samples, published=published, **rule),
        judge(null_samples, **rule),
        judge(oracle_samples, **rule),
    )


def check_null_control(v: Verdict) -> None:
    """Raise unless the null control came out ``"not reproduced"`` (rule 8).

    Raises
    ------
    CalibrationError
        If ``v.verdict`` is anything else: doing nothing reproduced the claim, so the test is
        broken.
    """
    if v.verdict != "not reproduced":
        raise CalibrationError(
            f"null control came out {v.verdict!r} over {v.n} trials ({v.note}); the test is "
            "broken: doing nothing must not reproduce the claim"
        )


def oracle_gate(claim: Verdict, oracle: Verdict, mechanism: str) -> Verdict:
    """The claim's verdict, or ``"not testable"`` if its oracle control is not significant.

    Parameters
    ----------
    claim, oracle : Verdict
        The claim and its oracle control from :func:`judge_controls`.
    mechanism : str
        The error source the paper corrects, named in the note if the model lacks it.

    Returns
    -------
    Verdict
        ``claim`` itself when ``oracle.significant``; else :func:`not_testable` with the claim's
        kind and N and a note naming ``mechanism``.
    """
    if not isinstance(mechanism, str) or not mechanism.strip():
        raise CalibrationError(f"oracle_gate needs the mechanism's name; got {mechanism!r}")
    if oracle.significant:
        return claim
    return not_testable(
        f"the model lacks {mechanism.strip()}: removing it gives effect {oracle.effect_median:.3g} "
        f"[{oracle.effect_low:.3g}, {oracle.effect_high:.3g}], not significant vs "
        f"{oracle.null:.3g} (the claim alone came out {claim.verdict}); N={oracle.n}",
        kind=claim.kind,
        n=claim.n,
    )
