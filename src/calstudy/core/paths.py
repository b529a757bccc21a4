"""Where calstudy's data and results live, in a checkout and in an installed package, and how
a file of them is written (atomically: :func:`atomic_write`).

``data/`` (robot tables, scenarios, published numbers, the claims register) ships inside the
package as ``calstudy/_data`` (in a checkout, a link to the repository's ``data/``), so
``pip install .`` gives a library that loads its scenarios from anywhere. Results go to the
repository's ``results/`` in a checkout, and to ``./results`` of the working folder otherwise.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1]
#: The package's data folder (the repository's ``data/`` in a checkout).
DATA_DIR = (PACKAGE_DIR / "_data").resolve()
_CHECKOUT = PACKAGE_DIR.parents[1]
#: True when calstudy runs from a source checkout (editable install or ``PYTHONPATH=src``).
IN_CHECKOUT = (_CHECKOUT / "pyproject.toml").is_file() and (_CHECKOUT / "notebooks").is_dir()
#: The repository root in a checkout; the working folder of an installed package.
REPO_ROOT = _CHECKOUT if IN_CHECKOUT else Path.cwd()
RESULTS_DIR = REPO_ROOT / "results"


def data_path(*parts: str) -> Path:
    """Path of a file under ``data/``; raises FileNotFoundError naming it if it is missing."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        raise FileNotFoundError(f"calstudy data file not found: data/{'/'.join(parts)}")
    return path


def scenario_file(paper: str, name: str, path: str | Path | None = None) -> Path:
    """``path`` if given, else ``data/<paper>/<name>`` (which must exist)."""
    return data_path(paper, name) if path in (None, "") else Path(path)


def results_path(stem: str, root: str | Path | None = None) -> Path:
    """Folder ``results/<stem>/`` (or ``<root>/<stem>/``), created if missing."""
    base = RESULTS_DIR if root in (None, "") else Path(root)
    out = base / stem
    out.mkdir(parents=True, exist_ok=True)
    return out


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it to ``path``.

    An interrupted or failing ``write`` leaves ``path`` as it was (old content or absent) and
    no temporary file behind; the written file is readable by all (mode 0644).

    Parameters
    ----------
    path : str or pathlib.Path
        Destination file; missing parent folders are created.
    write : callable
        ``write(tmp)`` writes the whole content to the file ``tmp`` (a pathlib.Path).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    Exception
        Whatever ``write`` raises (the temporary file is removed first).
    """
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
