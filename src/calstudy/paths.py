"""Where the repository's data and results live."""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
DATA_DIR = REPO_ROOT / "data"
RESULTS_DIR = REPO_ROOT / "results"


def data_path(*parts: str) -> Path:
    """Path of a file under ``data/``; raises FileNotFoundError naming it if it is missing."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        raise FileNotFoundError(f"calstudy data file not found: {path.relative_to(REPO_ROOT)}")
    return path


def results_path(stem: str, root: str | Path | None = None) -> Path:
    """Folder ``results/<stem>/`` (or ``<root>/<stem>/``), created if missing."""
    base = RESULTS_DIR if root in (None, "") else Path(root)
    out = base / stem
    out.mkdir(parents=True, exist_ok=True)
    return out
