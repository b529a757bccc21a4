"""Writing results: tables, figures, run records and claim verdicts, each file atomically.

Every file is written to a temporary name in its destination folder and renamed over the target
with :func:`os.replace`, so an interrupted run leaves either the old file or the new one, never
half a table. Outputs are byte-deterministic: the same inputs give the same bytes (fixed float
format, PNG without a software stamp, ``run.json`` without commit hash or time stamps).

A whole notebook run is published at once (:class:`ResultFolder`): its files go to a staging
folder that replaces the result folder in one step, so a folder never mixes two runs. The claim
rows (:mod:`calstudy.claims`) are checked against the register before they are written.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.metadata
import json
import math
import os
import platform
import re
import shutil
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from calstudy.claims import (
    CLAIM_COLUMNS,
    CONTROL_COLUMNS,
    VERDICTS,
    ClaimRow,
    claim_ids,
    claim_register,
)
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import DATA_DIR, REPO_ROOT, RESULTS_DIR, atomic_write
from calstudy.io.dependencies import label, notebook_inputs

NOTEBOOKS_DIR = REPO_ROOT / "notebooks"
SOURCE_DIR = Path(__file__).resolve().parents[1]
FLOAT_FORMAT = "%.6g"

#: Notebook parameters that say how a run was executed, not what it computed (workers, a Dask
#: scheduler, the resume cache, progress bars, where results go): ``run.json`` leaves them out,
#: so that the same seed gives the same bytes on one core, two, or a cluster.
EXECUTION_PARAMETERS = ("n_jobs", "scheduler", "cache_dir", "progress", "results_dir")

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

_CLAIM_TEXT_COLUMNS = (
    "id", "published", "unit", "verdict", "null_control", "oracle_control", "notebook", "note",
)
_CLAIM_FLOAT_COLUMNS = ("reproduced", "ci_low", "ci_high", "replication_rate")


# ----------------------------------------------------------------------------------------------
# atomic files


def write_table(df: pd.DataFrame, path: str | Path, float_format: str = FLOAT_FORMAT) -> Path:
    """Write ``df`` as CSV (no index, floats as ``%.6g``, ``\\n`` line ends), atomically.

    Non-finite numbers follow one rule: NaN (and None, ``pd.NA``) is a missing value and is
    written as an empty field, which :func:`pandas.read_csv` reads back as NaN; an infinity is
    refused, since no table of the study has one and ``inf`` in a CSV is usually a division by
    zero upstream. A quantity that may be unbounded is written as a missing value with a note.

    Parameters
    ----------
    df : pandas.DataFrame
        The table; its columns become the header.
    path : str or pathlib.Path
        Destination ``.csv`` file; missing parent folders are created.
    float_format : str, default ``"%.6g"``
        Format of floats (trial rows keep more digits).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    CalibrationError
        If ``df`` is not a DataFrame, or holds an infinity (the message names the column, the
        row and the file); nothing is written then.
    """
    if not isinstance(df, pd.DataFrame):
        raise CalibrationError(f"write_table needs a pandas DataFrame, got {type(df).__name__}")
    _check_no_infinity(df, path)
    return atomic_write(
        path,
        lambda tmp: df.to_csv(tmp, index=False, float_format=float_format, lineterminator="\n"),
    )


#: Smallest text of a saved figure, in points at the figure's size: a figure up to 8 in wide,
#: shown at 100 % in the book's column (about 700 px at a 1366 px window), writes it at 10 px
#: or more.
MIN_FONT_PT = 9.0
#: PNG text key holding the smallest font size of a figure (points), for the book's check.
FONT_KEY = "calstudy:min-font-pt"


def readable_text(fig, min_pt: float = MIN_FONT_PT) -> float:
    """Raise every visible text of ``fig`` smaller than ``min_pt`` to ``min_pt``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure (changed in place).
    min_pt : float, default :data:`MIN_FONT_PT`
        Smallest font size, in points.

    Returns
    -------
    float
        The smallest font size of a visible text afterwards (``min_pt`` if the figure has no
        text).
    """
    from matplotlib.text import Text

    sizes = []
    for text in fig.findobj(Text):
        if not text.get_visible() or not text.get_text().strip():
            continue
        if text.get_fontsize() < min_pt:
            text.set_fontsize(min_pt)
        sizes.append(float(text.get_fontsize()))
    return min(sizes, default=float(min_pt))


def _check_no_infinity(df: pd.DataFrame, path: str | Path) -> None:
    """Refuse a table holding +-inf in a numeric column or as a float in an object column."""
    for i, (name, column) in enumerate(df.items()):
        values = column.to_numpy()
        if values.dtype.kind == "f":
            bad = np.isinf(values)
        elif values.dtype.kind == "O":
            bad = np.array(
                [isinstance(v, float | np.floating) and math.isinf(v) for v in values], bool
            )
        else:
            continue
        if bad.any():
            row = int(np.argmax(bad))
            raise CalibrationError(
                f"{Path(path).name}: column {name!r} (#{i + 1}) holds {values[row]} at row "
                f"{row + 1}: tables are written without infinities (NaN is written as an empty "
                "field, a missing value); make it a missing value and say why in a note"
            )


def write_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Save ``fig`` as PNG with the Agg renderer, atomically, then close it.

    Text smaller than :data:`MIN_FONT_PT` is raised to it (:func:`readable_text`) and the
    smallest size is written into the PNG (text key :data:`FONT_KEY`), so that the book can
    tell the size of a figure's text on the page. The PNG carries no software or time stamp
    (``metadata={"Software": None}``), so the same figure gives the same bytes. Because the
    figure is closed, a notebook shows the saved file:
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
        smallest = readable_text(fig)
        metadata = {"Software": None, FONT_KEY: f"{smallest:g}"}
        atomic_write(
            path,
            lambda tmp: fig.savefig(
                tmp, format="png", dpi=dpi, metadata=metadata, backend="agg"
            ),
        )
    finally:
        plt.close(fig)
    return Path(path)


def notebook_writers(out_dir: str | Path):
    """The two writers every notebook uses, bound to its result folder ``out_dir``.

    Returns ``(save_table, show_figure)``: ``save_table(df, name)`` writes ``out_dir/name.csv``
    (:func:`write_table`) and returns ``df``; ``show_figure(fig, name, alt=...)`` writes
    ``out_dir/name.png`` (:func:`write_figure`) and displays the saved file with ``alt`` (a
    sentence describing the figure) as the image's alt text in the book
    (:func:`calstudy.io.display.show_png`); it returns None, so a notebook cell that ends with
    it shows the figure and no file path. Without ``alt`` the alt text is read from the
    figure's own titles and axis labels (:func:`calstudy.io.display.describe_figure`), never
    its path.
    """
    out = Path(out_dir)

    def save_table(df: pd.DataFrame, name: str) -> pd.DataFrame:
        write_table(df, out / f"{name}.csv")
        return df

    def show_figure(fig, name: str, alt: str | None = None) -> None:
        from calstudy.io.display import describe_figure, show_png

        alt = alt or describe_figure(fig, name)
        path = write_figure(fig, out / f"{name}.png")
        show_png(path, alt)

    return save_table, show_figure


# ----------------------------------------------------------------------------------------------
# atomic result folders


@contextlib.contextmanager
def staged_dir(final: str | os.PathLike[str]) -> Iterator[Path]:
    """Fill a result folder elsewhere and swap it in whole, or not at all.

    Yields an empty staging folder ``.<name>.staging-<pid>`` beside ``final``. When the block
    ends normally, the staging folder replaces ``final`` (the old ``final`` is renamed away to
    ``.<name>.old-<pid>``, the staging folder renamed to ``final``, the old one deleted). When
    the block raises, the staging folder is deleted and ``final`` is left as it was. Staging and
    old folders of processes that no longer run (a killed run) are removed on entry; if such a
    run died between its two renames, its old folder is renamed back to ``final``.

    Parameters
    ----------
    final : path-like
        The result folder; its parent is created if missing.

    Yields
    ------
    pathlib.Path
        The staging folder, to write the results into.
    """
    final = Path(final)
    staging = _begin_staging(final)
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    _publish_staging(final, staging)


class ResultFolder:
    """The result folder of one notebook run, filled in a staging folder and published whole.

    A notebook opens it at the start (``run = ResultFolder(results_path_of_its_stem)``), writes
    every file to ``run.path`` (the staging folder) and calls ``run.publish()`` in its last cell,
    which swaps the staging folder in place of the final one. A run that stops before (an
    error, a killed kernel) leaves the committed results untouched; its staging folder is
    removed by the next run. See :func:`staged_dir`.
    """

    def __init__(self, final: str | os.PathLike[str]):
        self.final = Path(final)
        self.path = _begin_staging(self.final)
        self.published = False

    def publish(self) -> None:
        """Swap the staging folder in as the final one (``self.final``). Returns None, so a
        notebook cell ending with it shows no path of the machine."""
        if self.published:
            raise CalibrationError(f"{self.final} is already published")
        _publish_staging(self.final, self.path)
        self.published = True


def _begin_staging(final: Path) -> Path:
    final.parent.mkdir(parents=True, exist_ok=True)
    _recover_staged(final)
    staging = final.parent / f".{final.name}.staging-{os.getpid()}"
    if staging.exists():
        _remove(staging)
    staging.mkdir()
    return staging


def _publish_staging(final: Path, staging: Path) -> None:
    old = final.parent / f".{final.name}.old-{os.getpid()}"
    if final.exists() or final.is_symlink():
        os.rename(final, old)
    try:
        os.rename(staging, final)
    except BaseException:
        if old.exists():
            os.rename(old, final)
        raise
    _remove(old)


def _recover_staged(final: Path) -> None:
    pattern = re.compile(rf"\.{re.escape(final.name)}\.(staging|old)-(\d+)")
    leftovers = []
    for entry in final.parent.iterdir():
        match = pattern.fullmatch(entry.name)
        if match and not _alive(int(match.group(2))):
            leftovers.append((match.group(1), entry))
    for kind, entry in sorted(leftovers, key=lambda item: item[0] != "old"):
        if kind == "old" and not (final.exists() or final.is_symlink()):
            os.rename(entry, final)  # the run died between its renames: keep the old results
        else:
            _remove(entry)


def _alive(pid: int) -> bool:
    if pid <= 0 or pid == os.getpid():
        return False  # our own leftovers are stale: this call is about to make a new one
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


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


def source_files(notebook: str | Path | None = None) -> list[Path]:
    """Files whose bytes define a run of ``notebook``: the notebook, its library modules and its
    data (:func:`calstudy.io.dependencies.notebook_inputs`, the list the Makefile reruns the
    notebook on). Without a notebook: every ``src/calstudy/**/*.py`` and every file under
    ``data/`` (hidden files and ``__pycache__`` folders skipped). Sorted by the path relative to
    the repository."""
    if notebook is not None:
        return notebook_inputs(_resolve_notebook(notebook))
    files = [p for p in SOURCE_DIR.rglob("*.py") if "__pycache__" not in p.parts]
    if DATA_DIR.is_dir():
        files += [
            p
            for p in DATA_DIR.rglob("*")
            if p.is_file()
            and not any(part.startswith(".") or part == "__pycache__" for part in p.parts)
        ]
    return sorted(files, key=label)


def source_digest(notebook: str | Path | None = None) -> str:
    """SHA-256 over the relative path and the bytes of every file of :func:`source_files`."""
    h = hashlib.sha256()
    for path in source_files(notebook):
        content = path.read_bytes()
        h.update(label(path).encode() + b"\0" + len(content).to_bytes(8, "big"))
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
        The notebook parameters (those of :data:`EXECUTION_PARAMETERS` are left out); values
        must be JSON serialisable (numpy scalars and arrays and
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
        "parameters": {k: v for k, v in parameters.items() if k not in EXECUTION_PARAMETERS},
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
    return atomic_write(Path(out_dir) / "run.json", lambda tmp: tmp.write_text(text))


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
    return write_table(claims_table(rows, register), Path(out_dir) / "claims.csv")


def claims_table(rows: Iterable[ClaimRow], register: str | Path | None = None) -> pd.DataFrame:
    """The rows of ``claims.csv`` (columns :data:`CLAIM_COLUMNS`) for claim rows, each with its
    ``criterion`` from the claims register, where it is declared once (a register of one's own
    may leave it out: the column is then empty)."""
    df = pd.DataFrame([dataclasses.asdict(r) for r in rows], columns=list(CLAIM_COLUMNS))
    reg = claim_register(register).set_index("id")
    df["criterion"] = df["id"].map(reg["criterion"]) if "criterion" in reg.columns else ""
    return df


def write_controls(out_dir: str | Path, rows: Iterable[Mapping]) -> Path:
    """Write ``out_dir/controls.csv``: the null and oracle control of each claim (v2 rule 8).

    ``rows`` come from :func:`calstudy.claims.control_rows`. Raises :class:`CalibrationError`
    on a missing column, an unknown control kind or verdict, or a null control that is not
    ``not reproduced`` (a null control that passes means the test is broken).
    """
    rows = [dict(r) for r in rows]
    if not rows:
        raise CalibrationError("no control rows to write (0 rows)")
    for row in rows:
        missing = [c for c in CONTROL_COLUMNS if c not in row]
        if missing:
            raise CalibrationError(f"control row of {row.get('id')!r} lacks columns {missing}")
        if row["control"] not in ("null", "oracle"):
            raise CalibrationError(
                f"control {row['control']!r} of {row['id']!r} is not 'null' or 'oracle'"
            )
        if row["verdict"] not in VERDICTS:
            raise CalibrationError(f"control verdict {row['verdict']!r} of {row['id']!r} unknown")
        if row["control"] == "null" and row["verdict"] != "not reproduced":
            raise CalibrationError(
                f"the null control of {row['id']!r} came out {row['verdict']!r}: the test is "
                "broken (doing nothing must not reproduce the claim)"
            )
    df = pd.DataFrame(rows, columns=list(CONTROL_COLUMNS))
    return write_table(df, Path(out_dir) / "controls.csv")


def read_claims(path: str | Path) -> pd.DataFrame:
    """Read a claims table written by :func:`write_claims` (text stays text, blanks are NaN)."""
    return pd.read_csv(
        path,
        dtype={c: str for c in _CLAIM_TEXT_COLUMNS},
        keep_default_na=False,
        na_values={c: [""] for c in _CLAIM_FLOAT_COLUMNS},
    )


#: Columns ``results/claims.csv`` adds from the notebooks' robustness summaries
#: (``<notebook>/robustness_claims.csv``): robust or conditional, the inputs the verdict
#: depends on, and where it changes; ``not mapped`` for a claim without a map.
ROBUSTNESS_COLUMNS = ("robustness", "depends_on", "thresholds")
ROBUSTNESS_SUMMARY = "robustness_claims.csv"


def notebook_files(root: Path, name: str) -> list[Path]:
    """Every ``<root>/<notebook>/<name>``, sorted, hidden folders skipped."""
    return sorted(p for p in root.glob(f"*/{name}") if not p.parent.name.startswith("."))


def _with_robustness(df: pd.DataFrame, root: Path) -> pd.DataFrame:
    """``df`` with the :data:`ROBUSTNESS_COLUMNS` of every claim that has a map."""
    found = notebook_files(root, ROBUSTNESS_SUMMARY)
    frames = [pd.read_csv(p, dtype=str, keep_default_na=False) for p in found]
    cols = ["id", *ROBUSTNESS_COLUMNS]
    maps = pd.concat(frames, ignore_index=True)[cols] if frames else pd.DataFrame(columns=cols)
    if df.empty:
        return df.assign(**{c: pd.Series(dtype=object) for c in ROBUSTNESS_COLUMNS})
    out = df.merge(maps, on="id", how="left")
    out["robustness"] = out["robustness"].fillna("not mapped")
    return out.fillna({"depends_on": "", "thresholds": ""})


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
        The aggregated table (columns :data:`CLAIM_COLUMNS`, then :data:`ROBUSTNESS_COLUMNS`).

    Raises
    ------
    CalibrationError
        If two notebooks report the same claim id.
    """
    root = RESULTS_DIR if results_root in (None, "") else Path(results_root)
    if not root.is_dir():
        raise FileNotFoundError(f"results folder not found: {root}")
    frames = [read_claims(p) for p in notebook_files(root, "claims.csv")]
    if frames:
        df = pd.concat(frames, ignore_index=True)[list(CLAIM_COLUMNS)]
    else:
        df = pd.DataFrame({c: pd.Series(dtype=float) for c in CLAIM_COLUMNS})
    dup = df["id"][df["id"].duplicated()]
    if len(dup):
        first = dup.iloc[0]
        where = ", ".join(df.loc[df["id"] == first, "notebook"])
        raise CalibrationError(f"claim id {first!r} is reported by more than one notebook: {where}")
    df = _with_robustness(df, root)
    df = df.sort_values("id", kind="stable").reset_index(drop=True)
    write_table(df, root / "claims.csv")
    return df
