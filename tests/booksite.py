"""Notebooks run at their small CI values (``notebooks/ci-params.yml``) and the book built from
them into a temporary copy of ``book/``, for the notebook smoke runs and the browser check.

:func:`run_ci_notebooks` executes every notebook once per test session (the ``ci_runs``
fixture of ``conftest.py``, shared by ``test_notebooks.py`` and ``test_book.py``);
:func:`build_ci_book` builds the book from those copies. Nothing in the repository is written:
executed notebooks, results and the build all go to a temporary folder. The claims page is
rendered from the committed ``results/claims.csv``, the page a reader of the book sees.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import nbformat
import yaml
from support import CI_PARAMS, NOTEBOOK_DIR, REPRODUCIBLE_ENV

from calstudy.core.paths import REPO_ROOT, RESULTS_DIR
from calstudy.io.book import PAPERS, render_claims_page
from calstudy.io.ledger import render_ledger_page

BOOK_DIR = REPO_ROOT / "book"
BIN = Path(sys.executable).parent
# Generated files of book/ that the copy makes afresh (see the Makefile's clean target).
GENERATED = (
    "_build", "notebooks", "claims.md", "claims-verdicts.png", "claims-headline.md", "ledger.md",
    *(f"{kind}-{paper}.{ext}" for paper in PAPERS for kind, ext in
      (("verdicts", "md"), ("key", "png"))),
)


def _env() -> dict[str, str]:
    env = {**os.environ, **REPRODUCIBLE_ENV, "PYDEVD_DISABLE_FILE_VALIDATION": "1"}
    src = str(REPO_ROOT / "src")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    return env


@dataclass
class CiRun:
    """One notebook executed at its CI values.

    Attributes
    ----------
    executed : pathlib.Path
        The executed copy (without papermill's injected parameters cell).
    results : pathlib.Path
        Its results folder ``<results_dir>/<stem>``.
    error : str
        Why the run failed ("" if it did not).
    touched_repository_results : bool
        The run changed the repository's own ``results/<stem>/`` (it must not).
    """

    executed: Path
    results: Path
    error: str = ""
    touched_repository_results: bool = False


def _snapshot(folder: Path) -> dict:
    return {p.name: p.stat().st_mtime_ns for p in folder.glob("*")} if folder.is_dir() else {}


def _execute(notebook: Path, out_dir: Path, results_dir: Path, params: dict) -> CiRun:
    """Run one notebook with papermill at ``params`` (plus ``results_dir``)."""
    params_file = out_dir / f".{notebook.stem}.params.yml"
    params_file.write_text(yaml.safe_dump({**params, "results_dir": str(results_dir)}))
    executed = out_dir / notebook.name
    before = _snapshot(RESULTS_DIR / notebook.stem)
    done = subprocess.run(
        [
            str(BIN / "papermill"), "--cwd", str(NOTEBOOK_DIR), "--no-progress-bar",
            "-f", str(params_file), str(notebook), str(executed),
        ],
        env=_env(), capture_output=True, text=True,
    )
    params_file.unlink()
    run = CiRun(
        executed, results_dir / notebook.stem,
        touched_repository_results=_snapshot(RESULTS_DIR / notebook.stem) != before,
    )
    if done.returncode:
        run.error = f"{notebook.name} failed with the CI values:\n{done.stderr[-3000:]}"
        return run
    # The cell papermill adds holds the CI values and the temporary results folder; the book
    # built by make reproduce (default parameters) has none.
    nb = nbformat.read(executed, as_version=4)
    nb.cells = [c for c in nb.cells if "injected-parameters" not in c.metadata.get("tags", [])]
    nbformat.write(nb, executed)
    return run


def run_ci_notebooks(dest: Path, jobs: int = 2) -> dict[str, CiRun]:
    """Execute every ``notebooks/NN_*.ipynb`` at its CI values, ``jobs`` at a time.

    The executed copies go to ``<dest>/executed``, the results to ``<dest>/results``. A
    notebook without a mapping in ``ci-params.yml`` runs at its defaults (its contract test
    fails on it).

    Returns
    -------
    dict
        ``{stem: CiRun}`` in notebook order.
    """
    out_dir, results_dir = dest / "executed", dest / "results"
    out_dir.mkdir(parents=True)
    ci = yaml.safe_load(CI_PARAMS.read_text()) or {}
    notebooks = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))
    with ThreadPoolExecutor(jobs) as pool:
        runs = {
            nb.stem: pool.submit(_execute, nb, out_dir, results_dir, ci.get(nb.stem, {}))
            for nb in notebooks
        }
        return {stem: future.result() for stem, future in runs.items()}


def build_ci_book(dest: Path, runs: dict[str, CiRun]) -> Path:
    """Build the book under ``<dest>/book`` from the executed notebooks ``runs``.

    Parameters
    ----------
    dest : pathlib.Path
        An empty temporary folder.
    runs : dict
        :func:`run_ci_notebooks` of every notebook.

    Returns
    -------
    pathlib.Path
        The HTML folder ``<dest>/book/_build/html``.
    """
    failed = [run.error for run in runs.values() if run.error]
    if failed:
        raise RuntimeError("the book needs every notebook:\n" + "\n".join(failed))
    book = dest / "book"
    shutil.copytree(BOOK_DIR, book, ignore=lambda d, names: GENERATED if d == str(BOOK_DIR) else ())
    (book / "notebooks").mkdir()
    for run in runs.values():
        shutil.copyfile(run.executed, book / "notebooks" / run.executed.name)
    # the claims and verdicts of the committed results; the chapters' key figures of these runs
    results = {run.results.parent for run in runs.values()}
    render_claims_page(book / "claims.md", results=RESULTS_DIR / "claims.csv",
                       figures=results.pop() if len(results) == 1 else None)
    (book / "ledger.md").write_text(render_ledger_page())
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
