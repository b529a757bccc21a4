"""Verdicts of the claims register and the rows that carry them.

Verdicts follow the rule of the claims register (reproduced / direction only / not reproduced /
not testable) and are computed from Monte Carlo samples by :func:`verdict_vs_published`,
:func:`verdict_direction` and :func:`verdict_vs_ml`; notebooks never type a verdict in. Writing
the rows to files is :mod:`calstudy.io.results`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import DATA_DIR
from calstudy.core.stats import bootstrap_interval, percentile_interval, rmse
from calstudy.core.verdicts import Verdict as RuleVerdict
from calstudy.core.verdicts import check_null_control

#: The four verdicts of the claims register, in the order the book counts them.
VERDICTS = ("reproduced", "direction only", "not reproduced", "not testable")

CLAIM_COLUMNS = (
    "id",
    "published",
    "reproduced",
    "ci_low",
    "ci_high",
    "unit",
    "n",
    "replication_rate",
    "verdict",
    "null_control",
    "oracle_control",
    "notebook",
    "note",
)

#: Columns of ``results/<notebook>/controls.csv``: the null and oracle control of each claim.
CONTROL_COLUMNS = (
    "id",
    "control",
    "definition",
    "reproduced",
    "ci_low",
    "ci_high",
    "n",
    "replication_rate",
    "verdict",
    "note",
)

# ----------------------------------------------------------------------------------------------
# verdicts


@dataclass(frozen=True)
class Verdict:
    """A computed verdict with the figures behind it.

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`.
    reproduced : float
        The reproduced figure in the unit of the published one (median over trials, or the
        RMS error ratio for :func:`verdict_vs_ml`).
    ci_low, ci_high : float
        Its 95 % interval (percentile over trials, or bootstrap for :func:`verdict_vs_ml`).
    effect_low, effect_high : float
        Interval of the effect that is tested against ``null`` (no effect).
    null : float
        The no-effect value of the effect (1 for a ratio, 0 for a difference).
    significant : bool
        The effect interval lies entirely on the claimed side of ``null``.
    in_band : bool
        The reproduced figure is within the magnitude band around the published one.
    note : str
        One line saying why, for the claims table.
    """

    verdict: str
    reproduced: float
    ci_low: float
    ci_high: float
    effect_low: float
    effect_high: float
    null: float
    significant: bool
    in_band: bool
    note: str

    def row(self, claim_id: str, published: str, unit: str, notebook: str) -> ClaimRow:
        """This verdict as a :class:`ClaimRow` for :func:`write_claims`."""
        return ClaimRow(
            id=claim_id,
            published=published,
            reproduced=self.reproduced,
            ci_low=self.ci_low,
            ci_high=self.ci_high,
            unit=unit,
            verdict=self.verdict,
            notebook=notebook,
            note=self.note,
        )


def _check_direction(direction: str) -> None:
    if direction not in ("lower", "higher"):
        raise CalibrationError(f"direction is {direction!r}; expected 'lower' or 'higher'")


def _in_factor_band(value: float, published: float, factor: float) -> bool:
    if value == 0.0 or np.sign(value) != np.sign(published):
        return False
    q = value / published
    return 1.0 / factor <= q <= factor


def verdict_vs_published(
    published: float,
    samples,
    baseline=None,
    *,
    kind: str,
    direction: str,
    factor: float = 1.5,
    band_pp: float = 10.0,
    level: float = 0.95,
) -> Verdict:
    """Verdict of a claim that has a published number, from Monte Carlo samples.

    The rule of the claims register, read as follows. The *effect* is tested against *no
    effect* with the central ``level`` percentile interval over the trials (the spread of the
    result from one simulated replication of the paper's experiment to the next, not the
    standard error of a mean, which any number of trials would make small):

    - ``"reproduced"``: the whole effect interval lies on the claimed side of no effect
      (``direction``), and the reproduced figure, the median over trials, is within a factor
      ``factor`` of ``published`` (``published / factor <= figure <= published * factor``, same
      sign), or for ``kind="percent"`` within ``band_pp`` percentage points.
    - ``"direction only"``: significant in the claimed direction, magnitude outside the band.
    - ``"not reproduced"``: the effect interval touches or crosses no effect, or lies on the
      wrong side.

    Parameters
    ----------
    published : float
        The paper's figure: a ratio (``kind="ratio"``, for example 0.041 / 0.049), a value in
        the claim's unit (``"value"``), or a percentage 0-100 (``"percent"``).
    samples : array_like, shape (N,)
        One value per Monte Carlo trial: the method's figure (for ``"ratio"`` with a baseline
        array, the numerator; without one, the ratio itself).
    baseline : array_like of shape (N,), float or None
        An array holds the paired baseline figure of each trial (the same simulated data
        processed the old way); the effect is then ``samples / baseline`` for ``"ratio"`` (no
        effect: 1) and ``samples - baseline`` otherwise (no effect: 0). A float is the no-effect
        value of ``samples`` itself. ``None`` means 1 for ``"ratio"``, 0 otherwise.
    kind : {"ratio", "value", "percent"}
        How the reproduced figure is compared with ``published``.
    direction : {"lower", "higher"}
        The side of no effect the paper claims (``"lower"``: the method lowers the error).
    factor : float, default 1.5
        Magnitude band for ``"ratio"`` and ``"value"``.
    band_pp : float, default 10
        Magnitude band for ``"percent"``, in percentage points.
    level : float, default 0.95
        Interval level.

    Returns
    -------
    Verdict
        ``reproduced``/``ci_low``/``ci_high`` are the median and interval of the reproduced
        figure (the ratio for ``"ratio"``, ``samples`` otherwise).

    Raises
    ------
    CalibrationError
        On an unknown ``kind`` or ``direction``, fewer than 2 or non-finite samples, a baseline
        of another length, a zero baseline in a ratio, a non-positive published ratio, or a zero
        published value (a factor band around 0 is empty).
    """
    if kind not in ("ratio", "value", "percent"):
        raise CalibrationError(f"kind is {kind!r}; expected 'ratio', 'value' or 'percent'")
    _check_direction(direction)
    if not math.isfinite(published):
        raise CalibrationError(f"published value is {published!r}; expected a finite number")
    if kind == "ratio" and published <= 0:
        raise CalibrationError(f"published ratio is {published!r}; a ratio must be positive")
    if kind == "value" and published == 0:
        raise CalibrationError("published value is 0; a factor band around 0 is empty")
    if factor <= 1.0 or band_pp < 0.0:
        raise CalibrationError(f"factor {factor!r} must exceed 1 and band_pp {band_pp!r} be >= 0")

    s = np.asarray(samples, dtype=float)
    if s.ndim != 1:
        raise CalibrationError(f"samples has shape {s.shape}; expected (N,) over trials")
    percentile_interval(s, level)  # checks count and finiteness
    if baseline is None or np.ndim(baseline) == 0:
        null = (1.0 if kind == "ratio" else 0.0) if baseline is None else float(baseline)
        effect = s
        figure = s
    else:
        b = np.asarray(baseline, dtype=float)
        if b.shape != s.shape:
            raise CalibrationError(
                f"baseline has shape {b.shape} but samples {s.shape}; pair them trial by trial"
            )
        percentile_interval(b, level)
        if kind == "ratio":
            if np.any(b == 0):
                raise CalibrationError(
                    f"baseline is 0 in {int(np.sum(b == 0))} trial(s); a ratio is undefined"
                )
            null, effect = 1.0, s / b
            figure = effect
        else:
            null, effect = 0.0, s - b
            figure = s

    value = float(np.median(figure))
    lo, hi = percentile_interval(figure, level)
    elo, ehi = percentile_interval(effect, level)
    significant = ehi < null if direction == "lower" else elo > null
    if kind == "percent":
        in_band = abs(value - published) <= band_pp
        band = f"within {band_pp:g} pp"
    else:
        in_band = _in_factor_band(value, published, factor)
        band = f"within factor {factor:g}"
    if significant:
        verdict = "reproduced" if in_band else "direction only"
    else:
        verdict = "not reproduced"
    effect_text = f"effect [{elo:.3g}, {ehi:.3g}] {'' if significant else 'not '}{direction}"
    note = (
        f"{kind} {value:.3g} [{lo:.3g}, {hi:.3g}] over {s.size} trials vs published "
        f"{published:.4g}; {effect_text} than {null:g}; {'' if in_band else 'not '}{band}"
    )
    return Verdict(verdict, value, lo, hi, elo, ehi, null, bool(significant), bool(in_band), note)


def verdict_direction(samples, baseline, *, level: float = 0.95) -> Verdict:
    """Verdict of a claim with a direction but no published size: is ``samples`` lower?

    The figure is the paired ratio ``samples / baseline`` per trial (median and percentile
    interval). ``reproduced`` when the whole interval lies below 1 (significant and in the
    paper's direction; with no published size the magnitude band does not apply),
    ``not reproduced`` otherwise.
    """
    s = np.asarray(samples, dtype=float)
    b = np.asarray(baseline, dtype=float)
    if s.shape != b.shape or s.ndim != 1 or len(s) < 2 or np.any(b <= 0):
        raise CalibrationError(
            f"samples {s.shape} and baseline {b.shape} must be equal (N,) arrays, N >= 2, "
            "with a positive baseline"
        )
    ratio = s / b
    value = float(np.median(ratio))
    lo, hi = (float(v) for v in np.percentile(ratio, [50 * (1 - level), 50 * (1 + level)]))
    significant = hi < 1.0
    note = (
        f"ratio {value:.3g} [{lo:.3g}, {hi:.3g}] over {len(s)} trials; "
        f"{'significantly' if significant else 'not significantly'} below 1; no published size"
    )
    verdict = "reproduced" if significant else "not reproduced"
    return Verdict(verdict, value, lo, hi, lo, hi, 1.0, significant, True, note)


def verdict_vs_ml(
    method_error_samples,
    ml_error_samples,
    works: bool,
    factor: float = 1.5,
    *,
    rng: np.random.Generator,
    n_boot: int = 2000,
    level: float = 0.95,
) -> Verdict:
    """Verdict of a claim with no published number, against maximum likelihood on the same data.

    The figure is the ratio of RMS errors over trials, ``rmse(method) / rmse(ml)``, where both
    estimators ran on the same simulated data in each trial; its interval is a paired
    percentile bootstrap over trials.

    - ``"reproduced"``: the method works and its RMS error is at most ``factor`` times the
      maximum-likelihood RMS error (ratio <= ``factor``).
    - ``"direction only"``: it works but the ratio exceeds ``factor``.
    - ``"not reproduced"``: it does not work (``works`` is False: no convergence, a degenerate
      result, an error above the notebook's stated tolerance).

    Parameters
    ----------
    method_error_samples, ml_error_samples : array_like, shape (N,)
        Error of the method and of the maximum-likelihood estimate in each trial (same unit).
    works : bool
        Whether the method does what the paper says at all (the notebook's criterion).
    factor : float, default 1.5
        Largest RMS ratio still counted as reproduced.
    rng : numpy.random.Generator
        For the bootstrap resampling.
    n_boot : int, default 2000
        Bootstrap resamples.
    level : float, default 0.95
        Interval level.

    Returns
    -------
    Verdict
        ``reproduced`` is the RMS ratio, ``ci_low``/``ci_high`` its bootstrap interval; when
        ``works`` is False and the errors are not finite, these are NaN and the note says so.

    Raises
    ------
    CalibrationError
        If the arrays differ in shape or have fewer than 2 trials, hold non-finite values while
        ``works`` is True, or the maximum-likelihood RMS error is 0.
    """
    if factor <= 1.0:
        raise CalibrationError(f"factor is {factor!r}; it must exceed 1")
    m = np.asarray(method_error_samples, dtype=float)
    ml = np.asarray(ml_error_samples, dtype=float)
    if m.ndim != 1 or m.shape != ml.shape:
        raise CalibrationError(
            f"method errors have shape {m.shape} and ML errors {ml.shape}; expected equal (N,)"
        )
    if not works and not (np.all(np.isfinite(m)) and np.all(np.isfinite(ml))):
        nan = float("nan")
        note = "method failed; its errors are not finite"
        return Verdict("not reproduced", nan, nan, nan, nan, nan, 1.0, False, False, note)
    ml_rms = rmse(ml)
    if ml_rms == 0:
        raise CalibrationError("maximum-likelihood RMS error is 0; the ratio is undefined")

    def ratio(pairs: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(pairs[..., 0] ** 2, axis=1) / np.mean(pairs[..., 1] ** 2, axis=1))

    value, lo, hi = bootstrap_interval(np.stack([m, ml], axis=1), ratio, rng, n_boot, level)
    in_band = value <= factor
    if not works:
        verdict = "not reproduced"
    else:
        verdict = "reproduced" if in_band else "direction only"
    note = (
        f"RMS error {rmse(m):.3g} vs maximum likelihood {ml_rms:.3g} over {m.size} trials: "
        f"ratio {value:.3g} [{lo:.3g}, {hi:.3g}]; {'works' if works else 'fails'}, "
        f"{'within' if in_band else 'beyond'} factor {factor:g}"
    )
    return Verdict(verdict, value, lo, hi, lo, hi, 1.0, bool(lo > 1.0), bool(in_band), note)


# ----------------------------------------------------------------------------------------------
# claim rows


@dataclass
class ClaimRow:
    """One row of ``results/<notebook>/claims.csv``.

    Attributes
    ----------
    id : str
        Claim id, exactly as in ``data/claims.csv``.
    published : str
        The paper's figure as text (``""`` if the paper gives none).
    reproduced : float
        The reproduced figure (NaN for ``"not testable"``).
    ci_low, ci_high : float
        Its 95 % interval over Monte Carlo trials.
    unit : str
        Unit of ``published`` and ``reproduced`` (``"ratio"``, ``"mm"``, ``"%"``, ...).
    verdict : str
        One of :data:`VERDICTS`.
    notebook : str
        Stem of the notebook that computed it.
    note : str
        One short line: why this verdict.
    n : int
        Trials the verdict rests on (0: not computed from trials).
    replication_rate : float
        Share of trials whose own effect has the claimed direction (NaN if not applicable).
    null_control, oracle_control : str
        Verdicts of the two controls of the v2 rule (empty where the claim has none).
    """

    id: str
    published: str
    reproduced: float
    ci_low: float
    ci_high: float
    unit: str
    verdict: str
    notebook: str
    note: str = ""
    n: int = 0
    replication_rate: float = float("nan")
    null_control: str = ""
    oracle_control: str = ""


def claim_row(
    claim_id: str,
    verdict: RuleVerdict,
    *,
    published: str,
    unit: str,
    notebook: str,
    null: RuleVerdict | None = None,
    oracle: RuleVerdict | None = None,
) -> ClaimRow:
    """The claims-table row of a verdict of the v2 rule (:func:`calstudy.core.verdicts.judge`).

    ``reproduced``/``ci_low``/``ci_high`` are the median over trials and its 95 % confidence
    interval; ``null``/``oracle`` are the controls judged on the same trials (their verdicts go
    in the row, their figures in ``controls.csv``, see :func:`control_rows`).
    """
    return ClaimRow(
        id=claim_id,
        published=published,
        reproduced=verdict.median,
        ci_low=verdict.ci_low,
        ci_high=verdict.ci_high,
        unit=unit,
        verdict=verdict.verdict,
        notebook=notebook,
        note=verdict.note,
        n=verdict.n,
        replication_rate=verdict.replication_rate,
        null_control="" if null is None else null.verdict,
        oracle_control="" if oracle is None else oracle.verdict,
    )


def control_rows(claim_id: str, null: RuleVerdict, oracle: RuleVerdict) -> list[dict]:
    """The two rows of ``controls.csv`` for a claim, with the control definitions of the claims
    register (columns ``null_control`` and ``oracle_control`` of ``data/claims.csv``).

    Raises
    ------
    CalibrationError
        If the null control is anything but ``not reproduced`` (the test is broken), or the
        register defines no control for the claim.
    """
    check_null_control(null)
    register = claim_register().set_index("id")
    if claim_id not in register.index:
        raise CalibrationError(f"claim id {claim_id!r} is not in the claims register")
    rows = []
    for control, v in (("null", null), ("oracle", oracle)):
        definition = register.at[claim_id, f"{control}_control"]
        if not definition:
            raise CalibrationError(
                f"data/claims.csv defines no {control} control for {claim_id!r}; describe it in "
                f"the column {control}_control"
            )
        rows.append(
            {
                "id": claim_id,
                "control": control,
                "definition": definition,
                "reproduced": v.median,
                "ci_low": v.ci_low,
                "ci_high": v.ci_high,
                "n": v.n,
                "replication_rate": v.replication_rate,
                "verdict": v.verdict,
                "note": v.note,
            }
        )
    return rows


def claim_register(register: str | Path | None = None) -> pd.DataFrame:
    """The claims register ``data/claims.csv`` (or ``register``) as text, blanks as ``""``."""
    path = DATA_DIR / "claims.csv" if register is None else Path(register)
    if not path.is_file():
        raise FileNotFoundError(f"claims register not found: {path.name}")
    return pd.read_csv(path, dtype=str, keep_default_na=False)


def claim_ids(register: str | Path | None = None) -> list[str]:
    """Ids of the claims register ``data/claims.csv`` (or ``register``), in file order."""
    return claim_register(register)["id"].tolist()
