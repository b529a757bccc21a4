"""Build the book for the browser check: a temporary copy of ``book/`` with every notebook
executed at its small CI values (``notebooks/ci-params.yml``).

Nothing in the repository is written: the executed notebooks go to ``<dest>/book/notebooks``,
their results to ``<dest>/results``, the build to ``<dest>/book/_build/html``. The claims page is
rendered from the committed ``results/claims.csv``, the page a reader of the book sees.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import nbformat
import yaml
from support import CI_PARAMS, NOTEBOOK_DIR, REPRODUCIBLE_ENV

from calstudy.core.paths import REPO_ROOT, RESULTS_DIR
from calstudy.io.book import render_claims_page

BOOK_DIR = REPO_ROOT / "book"
BIN = Path(sys.executable).parent
# Generated files of book/ that the copy makes afresh (see the Makefile's clean target).
GENERATED = ("_build", "notebooks", "claims.md", "claims-verdicts.png")


def _env() -> dict[str, str]:
    env = {**os.environ, **REPRODUCIBLE_ENV, "PYDEVD_DISABLE_FILE_VALIDATION": "1"}
    src = str(REPO_ROOT / "src")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    return env


def _execute(notebook: Path, out_dir: Path, results_dir: Path, params: dict) -> None:
    """Run one notebook with papermill at ``params`` (plus ``results_dir``)."""
    params_file = out_dir / f".{notebook.stem}.params.yml"
    params_file.write_text(yaml.safe_dump({**params, "results_dir": str(results_dir)}))
    done = subprocess.run(
        [
            str(BIN / "papermill"), "--cwd", str(NOTEBOOK_DIR), "--no-progress-bar",
            "-f", str(params_file), str(notebook), str(out_dir / notebook.name),
        ],
        env=_env(), capture_output=True, text=True,
    )
    params_file.unlink()
    if done.returncode:
        raise RuntimeError(f"{notebook.name} failed with the CI values:\n{done.stderr[-3000:]}")
    # The cell papermill adds holds the CI values and the temporary results folder; the book
    # built by make reproduce (default parameters) has none.
    executed = out_dir / notebook.name
    nb = nbformat.read(executed, as_version=4)
    nb.cells = [c for c in nb.cells if "injected-parameters" not in c.metadata.get("tags", [])]
    nbformat.write(nb, executed)


def build_ci_book(dest: Path, jobs: int = 2) -> Path:
    """Build the book under ``dest`` from notebooks run at their CI values.

    Parameters
    ----------
    dest : pathlib.Path
        An empty temporary folder.
    jobs : int, default 2
        Notebooks executed at once.

    Returns
    -------
    pathlib.Path
        The HTML folder ``<dest>/book/_build/html``.
    """
    book = dest / "book"
    shutil.copytree(BOOK_DIR, book, ignore=lambda d, names: GENERATED if d == str(BOOK_DIR) else ())
    (book / "notebooks").mkdir()
    ci = yaml.safe_load(CI_PARAMS.read_text()) or {}
    notebooks = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))
    with ThreadPoolExecutor(jobs) as pool:
        runs = [
            pool.submit(_execute, nb, book / "notebooks", dest / "results", ci.get(nb.stem, {}))
            for nb in notebooks
        ]
        for run in runs:
            run.result()
    render_claims_page(book / "claims.md", results=RESULTS_DIR / "claims.csv")
    done = subprocess.run(
        [
            str(BIN / "jupyter-book"), "build", str(book), "--all",
            "--warningiserror", "--nitpick", "--keep-going",
        ],
        env=_env(), capture_output=True, text=True,
    )
    if done.returncode:
        log = done.stdout[-4000:] + done.stderr[-2000:]
        raise RuntimeError(f"jupyter-book build failed:\n{log}")
    return book / "_build" / "html"


def pages(html: Path) -> list[Path]:
    """Every HTML page of a build: not the copies of sources or static files, nor a page that
    only redirects (``index.html`` to the root page, which is itself checked)."""
    skip = ("_static", "_sources", "_images")
    return sorted(
        p
        for p in html.rglob("*.html")
        if p.relative_to(html).parts[0] not in skip
        and 'http-equiv="Refresh"' not in p.read_text(encoding="utf-8")[:2000]
    )
