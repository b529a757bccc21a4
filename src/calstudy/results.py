"""Writing results: tables, figures, run records and claim verdicts, each file atomically.

Every file is written to a temporary name in its destination folder and renamed over the target
with :func:`os.replace`, so an interrupted run leaves either the old file or the new one, never
half a table. Outputs are byte-deterministic: the same inputs give the same bytes (fixed float
format, PNG without a software stamp, ``run.json`` without commit hash or time stamps).

Verdicts follow the rule of the claims register (reproduced / direction only / not reproduced /
not testable) and are computed from Monte Carlo samples by :func:`verdict_vs_published` and
:func:`verdict_vs_ml`; notebooks never type a verdict in.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
import math
import os
import platform
import tempfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import CalibrationError
from .paths import DATA_DIR, REPO_ROOT, RESULTS_DIR
from .stats import bootstrap_interval, percentile_interval, rmse

NOTEBOOKS_DIR = REPO_ROOT / "notebooks"
SOURCE_DIR = Path(__file__).resolve().parent
FLOAT_FORMAT = "%.6g"

#: Distributions whose versions ``run.json`` records (the pinned runtime dependencies).
PINNED_PACKAGES = (
    "numpy",
    "scipy",
    "pandas",
    "matplotlib",
    "opencv-python-headless",
    "pin",
    "statsmodels",
)

#: The four verdicts of the claims register, in the order the book counts them.
VERDICTS = ("reproduced", "direction only", "not reproduced", "not testable")

CLAIM_COLUMNS = (
    "id",
    "published",
    "reproduced",
    "ci_low",
    "ci_high",
    "unit",
    "verdict",
    "notebook",
    "note",
)
_CLAIM_TEXT_COLUMNS = ("id", "published", "unit", "verdict", "notebook", "note")
_CLAIM_FLOAT_COLUMNS = ("reproduced", "ci_low", "ci_high")


# ----------------------------------------------------------------------------------------------
# atomic files


def _atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp = Path(name)
    try:
        write(tmp)
        # mkstemp creates 0600; results are ordinary readable files
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_table(df: pd.DataFrame, path: str | Path) -> Path:
    """Write ``df`` as CSV (no index, floats as ``%.6g``, ``\\n`` line ends), atomically.

    Parameters
    ----------
    df : pandas.DataFrame
        The table; its columns become the header.
    path : str or pathlib.Path
        Destination ``.csv`` file; missing parent folders are created.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    CalibrationError
        If ``df`` is not a DataFrame.
    """
    if not isinstance(df, pd.DataFrame):
        raise CalibrationError(f"write_table needs a pandas DataFrame, got {type(df).__name__}")
    return _atomic_write(
        path,
        lambda tmp: df.to_csv(tmp, index=False, float_format=FLOAT_FORMAT, lineterminator="\n"),
    )


def write_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Save ``fig`` as PNG with the Agg renderer, atomically, then close it.

    The PNG carries no software or time stamp (``metadata={"Software": None}``), so the same
    figure gives the same bytes. Because the figure is closed, a notebook shows the saved file:
    ``display(Image(filename=write_figure(fig, out / "name.png")))``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure to save.
    path : str or pathlib.Path
        Destination ``.png`` file; missing parent folders are created.
    dpi : int, default 120
        Resolution.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib.pyplot as plt

    try:
        _atomic_write(
            path,
            lambda tmp: fig.savefig(
                tmp, format="png", dpi=dpi, metadata={"Software": None}, backend="agg"
            ),
        )
    finally:
        plt.close(fig)
    return Path(path)


def notebook_writers(out_dir: str | Path):
    """The two writers every notebook uses, bound to its result folder ``out_dir``.

    Returns ``(save_table, show_figure)``: ``save_table(df, name)`` writes ``out_dir/name.csv``
    (:func:`write_table`) and returns ``df``; ``show_figure(fig, name)`` writes
    ``out_dir/name.png`` (:func:`write_figure`) and displays the saved file.
    """
    out = Path(out_dir)

    def save_table(df: pd.DataFrame, name: str) -> pd.DataFrame:
        write_table(df, out / f"{name}.csv")
        return df

    def show_figure(fig, name: str) -> Path:
        from IPython.display import Image, display

        path = write_figure(fig, out / f"{name}.png")
        display(Image(filename=str(path)))
        return path

    return save_table, show_figure


# ----------------------------------------------------------------------------------------------
# run.json


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _resolve_notebook(notebook: str | Path) -> Path:
    path = Path(notebook)
    if not path.is_absolute() and not path.exists():
        path = NOTEBOOKS_DIR / path
    if not path.is_file():
        raise FileNotFoundError(f"notebook not found: {notebook}")
    return path.resolve()


def _label(path: Path) -> str:
    try:
        return path.resolve().relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return path.name


def source_files(notebook: str | Path | None = None) -> list[Path]:
    """Files whose bytes define a run: ``src/calstudy/*.py``, ``data/**`` and the notebook.

    Hidden files and ``__pycache__`` folders under ``data/`` are skipped. The list is sorted by
    the path relative to the repository.
    """
    files = list(SOURCE_DIR.glob("*.py"))
    if DATA_DIR.is_dir():
        files += [
            p
            for p in DATA_DIR.rglob("*")
            if p.is_file()
            and not any(part.startswith(".") or part == "__pycache__" for part in p.parts)
        ]
    if notebook is not None:
        files.append(_resolve_notebook(notebook))
    return sorted(files, key=_label)


def source_digest(notebook: str | Path | None = None) -> str:
    """SHA-256 over the relative path and the bytes of every file of :func:`source_files`."""
    h = hashlib.sha256()
    for path in source_files(notebook):
        content = path.read_bytes()
        h.update(_label(path).encode() + b"\0" + len(content).to_bytes(8, "big"))
        h.update(content)
    return "sha256:" + h.hexdigest()


def package_versions() -> dict[str, str]:
    """Installed versions of :data:`PINNED_PACKAGES` (``"not installed"`` where missing)."""
    out = {}
    for name in PINNED_PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def write_run_json(
    out_dir: str | Path,
    parameters: Mapping,
    seed: int,
    notebook: str | Path | None = None,
) -> Path:
    """Write ``out_dir/run.json``: what produced the results in ``out_dir``, atomically.

    Recorded: the parameters, the seed, the versions of the pinned packages, the Python
    version, the notebook name and ``source_digest`` (see :func:`source_digest`). No git commit
    and no time stamp: results are committed in the same commit as the code, and two runs of the
    same code must give the same bytes.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Result folder (created if missing).
    parameters : mapping
        The notebook parameters; values must be JSON serialisable (numpy scalars and arrays and
        paths are converted).
    seed : int
        Seed of the run's ``numpy.random.Generator``.
    notebook : str or pathlib.Path, optional
        The notebook that ran; a bare name is looked up in ``notebooks/``. Its bytes enter the
        digest.

    Returns
    -------
    pathlib.Path
        Path of ``run.json``.

    Raises
    ------
    CalibrationError
        If ``seed`` is not an integer or a parameter cannot be written as JSON.
    FileNotFoundError
        If ``notebook`` is given and not found.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise CalibrationError(f"seed is {seed!r} ({type(seed).__name__}); expected an integer")
    record = {
        "notebook": None if notebook is None else _resolve_notebook(notebook).stem,
        "parameters": dict(parameters),
        "python": platform.python_version(),
        "seed": int(seed),
        "source_digest": source_digest(notebook),
        "source_files": len(source_files(notebook)),
        "versions": package_versions(),
    }
    try:
        text = json.dumps(record, indent=2, sort_keys=True, default=_json_default) + "\n"
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"run.json parameters cannot be written as JSON: {exc}") from exc
    return _atomic_write(Path(out_dir) / "run.json", lambda tmp: tmp.write_text(text))


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


def claim_ids(register: str | Path | None = None) -> list[str]:
    """Ids of the claims register ``data/claims.csv`` (or ``register``), in file order."""
    path = DATA_DIR / "claims.csv" if register is None else Path(register)
    if not path.is_file():
        raise FileNotFoundError(f"claims register not found: {_label(path)}")
    return pd.read_csv(path, dtype=str, keep_default_na=False)["id"].tolist()


def write_claims(
    out_dir: str | Path, rows: Iterable[ClaimRow], register: str | Path | None = None
) -> Path:
    """Write ``out_dir/claims.csv`` from claim rows, after checking them, atomically.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Result folder of the notebook (created if missing).
    rows : iterable of ClaimRow
        The verdicts the notebook computed.
    register : str or pathlib.Path, optional
        Claims register to check ids against; default ``data/claims.csv``.

    Returns
    -------
    pathlib.Path
        Path of the written ``claims.csv``.

    Raises
    ------
    CalibrationError
        If there are no rows, a verdict is not one of :data:`VERDICTS`, an id is not in the
        register or appears twice, or the notebook name is empty.
    """
    rows = list(rows)
    if not rows:
        raise CalibrationError("no claim rows to write (0 rows)")
    known = set(claim_ids(register))
    seen: set[str] = set()
    for row in rows:
        if not isinstance(row, ClaimRow):
            raise CalibrationError(f"claim row is a {type(row).__name__}; expected ClaimRow")
        if row.verdict not in VERDICTS:
            raise CalibrationError(
                f"verdict {row.verdict!r} of claim {row.id!r} is not one of {', '.join(VERDICTS)}"
            )
        if row.id not in known:
            raise CalibrationError(
                f"claim id {row.id!r} is not in the claims register ({len(known)} ids)"
            )
        if row.id in seen:
            raise CalibrationError(f"claim id {row.id!r} appears twice")
        if not row.notebook:
            raise CalibrationError(f"claim {row.id!r} names no notebook")
        seen.add(row.id)
    df = pd.DataFrame([dataclasses.asdict(r) for r in rows], columns=list(CLAIM_COLUMNS))
    return write_table(df, Path(out_dir) / "claims.csv")


def read_claims(path: str | Path) -> pd.DataFrame:
    """Read a claims table written by :func:`write_claims` (text stays text, blanks are NaN)."""
    return pd.read_csv(
        path,
        dtype={c: str for c in _CLAIM_TEXT_COLUMNS},
        keep_default_na=False,
        na_values={c: [""] for c in _CLAIM_FLOAT_COLUMNS},
    )


def aggregate_claims(results_root: str | Path | None = None) -> pd.DataFrame:
    """Collect every ``<root>/*/claims.csv`` into ``<root>/claims.csv``, sorted by id.

    Only computed rows are written; claims no notebook has computed yet are absent (the book
    shows them as pending).

    Parameters
    ----------
    results_root : str or pathlib.Path, optional
        Folder holding one sub-folder per notebook; default ``results/``.

    Returns
    -------
    pandas.DataFrame
        The aggregated table (columns :data:`CLAIM_COLUMNS`).

    Raises
    ------
    CalibrationError
        If two notebooks report the same claim id.
    """
    root = RESULTS_DIR if results_root in (None, "") else Path(results_root)
    frames = [read_claims(p) for p in sorted(root.glob("*/claims.csv"))]
    if frames:
        df = pd.concat(frames, ignore_index=True)[list(CLAIM_COLUMNS)]
    else:
        df = pd.DataFrame({c: pd.Series(dtype=float) for c in CLAIM_COLUMNS})
    dup = df["id"][df["id"].duplicated()]
    if len(dup):
        first = dup.iloc[0]
        where = ", ".join(df.loc[df["id"] == first, "notebook"])
        raise CalibrationError(f"claim id {first!r} is reported by more than one notebook: {where}")
    df = df.sort_values("id", kind="stable").reset_index(drop=True)
    write_table(df, root / "claims.csv")
    return df
